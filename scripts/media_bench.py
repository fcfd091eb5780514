#!/usr/bin/env python3
"""What specialising saves scenes without media: `tessera bench` with the effect set a scene
calls for against every effect forced on (`--effects all`, the generic pipeline that tracks
media along every ray), side by side in one run, interleaved, for the participating-media
benchmark of docs/bench.md.

The figure is the median of the full-path pass's CPU-seconds, as `scripts/spectral_bench.py`
measures the always-spectral pipeline: the render alone, since loading the scene and building
its BVH are the same work in both modes. Beside it, the median of each repeat's own ratio
(its two runs back to back): on a machine whose speed drifts by a tenth or more within
minutes, the two modes' medians can come from different spells, while a pair's runs share
one, so the pairs' ratios leave the drift out. In brackets, the whole process's CPU-seconds
(user + system, from the kernel's accounting of the child), which include that shared work
and `tessera bench`'s pass of camera rays alone (depth 0); the rounds of docs/bench.md before
the thirty-second reported only whole processes, of `tessera render`, which has no such pass,
so their figures are not these.

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
    command = [tessera, "bench", scene, "--json", "--effects", mode, "--threads", str(args.threads),
               "--width", str(args.size), "--height", str(args.size), "--spp", str(args.spp),
               "--out", out]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{done.stderr.strip()}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    report = json.loads(done.stdout[done.stdout.index("{"):])
    if not report["scenes"]:
        reasons = "; ".join(s["reason"] for s in report["skipped"])
        raise SystemExit(f"{scene}: skipped by tessera bench: {reasons}")
    bench = report["scenes"][0]
    if bench["paths"]["cpu_seconds"] is None:
        raise SystemExit("tessera bench could not read CPU-seconds here (no procfs?)")
    process = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"paths": bench["paths"]["cpu_seconds"], "process": process, "effects": bench["effects"],
            "exr": bench["image"]}


def ratio_of(auto, all_):
    """The generic pipeline's time over the specialised one's, or `None` where the latter is too
    short to measure."""
    return all_ / auto if auto > 0 else None


def shown(ratio):
    """A ratio as the table prints it."""
    return f"{ratio:.2f}x" if ratio is not None else "n/a (too short to time)"


def ratio(seconds):
    """`ratio_of` the two modes' seconds, as the table prints it."""
    return shown(ratio_of(seconds["auto"], seconds["all"]))


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
    print(f"{args.size}x{args.size}, {args.spp} spp, {args.threads} thread(s), median of {args.repeats}: "
          f"the full-path pass's CPU-seconds (the whole process's in brackets)\n")
    print("| scene | effects (auto) | auto | all | all / auto | each pair's all / auto, median | same bits |")
    print("|---|---|---|---|---|---|---|")
    for scene in args.scenes:
        runs = {"auto": [], "all": []}
        scratch = tempfile.TemporaryDirectory()
        for repeat in range(args.repeats):
            for mode in ("auto", "all"):
                out = os.path.join(scratch.name, f"{mode}-{repeat}")
                runs[mode].append(run(args.tessera, scene, mode, args, out))
        paths = {m: statistics.median(r["paths"] for r in runs[m]) for m in runs}
        process = {m: statistics.median(r["process"] for r in runs[m]) for m in runs}
        pairs = [ratio_of(auto["paths"], all_["paths"]) for auto, all_ in zip(runs["auto"], runs["all"])]
        pairs = [r for r in pairs if r is not None]
        paired = shown(statistics.median(pairs) if pairs else None)
        same = same_pixels(args.tessera, runs["all"][0]["exr"], runs["auto"][0]["exr"])
        scratch.cleanup()
        print(f"| {os.path.basename(scene)} | {runs['auto'][0]['effects']} | "
              f"{paths['auto']:.2f} ({process['auto']:.2f}) | {paths['all']:.2f} ({process['all']:.2f}) | "
              f"{ratio(paths)} ({ratio(process)}) | {paired} | "
              f"{'yes' if same else 'NO'} |", flush=True)
    print(f"\nload after {os.getloadavg()}")


if __name__ == "__main__":
    main()
