#!/usr/bin/env python3
"""CPU-seconds of `tessera render` with the effect set a scene calls for and with every effect
forced on (`--effects all`), side by side in one run, interleaved, for the participating-media
benchmark of docs/bench.md.

Why not `tessera bench`: it renders with the scene's own effect set and has no option to force
effects on, and its code is not ours to change here; `tessera render` has `--effects`. Each run
is a fresh process; its CPU-seconds (user + system, from the kernel's accounting of the child)
include loading the scene and building the BVH, which both modes do alike, and the frame's wall
time from stats.json is reported beside them.

Usage (from the repository root, after `cargo build --release`):
    python3 scripts/media_bench.py --repeats 3 --size 256 --spp 16 SCENE.toml...
"""

import argparse
import json
import os
import resource
import statistics
import subprocess
import tempfile
import time


def run(tessera, scene, mode, args, out):
    command = [tessera, "render", scene, "--effects", mode, "--threads", str(args.threads),
               "--width", str(args.size), "--height", str(args.size), "--spp", str(args.spp),
               "--frames", "1", "--out", out]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(command, check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    stats = json.load(open(os.path.join(out, "stats.json")))
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    frame = stats["frames"][0]
    return {"cpu": cpu, "frame_seconds": frame["seconds"], "effects": stats["effects"],
            "exr": os.path.join(out, "frame-0000.exr")}


def same_pixels(tessera, a, b):
    """Whether two EXRs hold the same pixels (`tessera compare`: zero RMSE and equal means)."""
    done = subprocess.run([tessera, "compare", a, b, "--json"], check=True, capture_output=True, text=True)
    metrics = json.loads(done.stdout)
    return metrics["rmse"] == 0 and metrics["mean_test"] == metrics["mean_reference"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--tessera", default=os.environ.get("CARGO_TARGET_DIR", "target") + "/release/tessera")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    print(f"date {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load before {os.getloadavg()}")
    print(f"{args.size}x{args.size}, {args.spp} spp, {args.threads} thread(s), median of {args.repeats}, "
          f"CPU-seconds of the whole process (frame wall seconds in brackets)\n")
    print("| scene | effects (auto) | auto | all | all / auto | same bits |")
    print("|---|---|---|---|---|---|")
    for scene in args.scenes:
        runs = {"auto": [], "all": []}
        scratch = tempfile.TemporaryDirectory()
        for repeat in range(args.repeats):
            for mode in ("auto", "all"):
                out = os.path.join(scratch.name, f"{mode}-{repeat}")
                runs[mode].append(run(args.tessera, scene, mode, args, out))
        med = {m: statistics.median(r["cpu"] for r in runs[m]) for m in runs}
        frame = {m: statistics.median(r["frame_seconds"] for r in runs[m]) for m in runs}
        same = same_pixels(args.tessera, runs["all"][0]["exr"], runs["auto"][0]["exr"])
        scratch.cleanup()
        effects = runs["auto"][0]["effects"]
        effects = ",".join(effects) if isinstance(effects, list) else str(effects)
        print(f"| {os.path.basename(scene)} | {effects} | {med['auto']:.2f} ({frame['auto']:.2f}) | "
              f"{med['all']:.2f} ({frame['all']:.2f}) | {med['all'] / med['auto']:.2f}x | {'yes' if same else 'NO'} |",
              flush=True)
    print(f"\nload after {os.getloadavg()}")


if __name__ == "__main__":
    main()
