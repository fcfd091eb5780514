#!/usr/bin/env python3
"""What specialising to a scene's effects saves: `--effects auto` against `--effects all`.

Why: the tracer skips the code paths of effects a scene lacks (tracer/src/effects.rs), and promises
that skipping changes no bit. This script times both modes on every shipped scene and, when
../shared/scenes is present, on every scene of scenes/shared/, and checks the promise on the way:
the two modes' EXR files must be byte-identical (tessera writes them deterministically).

Each scene is rendered at one size and sample count (flags below) with one peer and every core,
frame 0 only; runs are interleaved (auto, all, auto, all, ...) so that a change in the machine's
load hits both alike, and each figure is the median over the repeats. The time is the sum of the
per-frame times in stats.json (from the first tile handed out to the last received, so without
loading the scene or building the BVH). `rays` counts camera, bounce and shadow rays (stats.json).

Usage (from the repository root, after `cargo build --release`):
    python3 scripts/bench_effects.py --out out/bench/effects
"""

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

MODES = ["auto", "all"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tessera", default="target/release/tessera")
    parser.add_argument("--out", default="out/bench/effects")
    parser.add_argument("--width", type=int, default=192)
    parser.add_argument("--height", type=int, default=192)
    parser.add_argument("--spp", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("scenes", nargs="*", help="scene files (default: all shipped and shared)")
    args = parser.parse_args()

    scenes = [Path(s) for s in args.scenes] or default_scenes()
    out = Path(args.out)
    rows = []
    for scene in scenes:
        times = {mode: [] for mode in MODES}
        rays = {}
        effects = {}
        for _ in range(args.repeats):
            for mode in MODES:
                stats = render(args, scene, mode, out / scene.stem / mode)
                times[mode].append(sum(f["seconds"] for f in stats["frames"]))
                rays[mode] = sum(f["rays"] for f in stats["frames"])
                effects[mode] = stats["effects"]
        exr = [(out / scene.stem / mode / "frame-0000.exr").read_bytes() for mode in MODES]
        auto, all_ = (statistics.median(times[m]) for m in MODES)
        rows.append((scene, effects["auto"], auto, all_, rays["auto"], rays["all"], exr[0] == exr[1]))
        print_row(rows[-1])
    if not all(row[-1] for row in rows):
        sys.exit("specialised and forced renders differ: the effect set skipped work that mattered")


def default_scenes():
    scenes = sorted(p for p in Path("scenes").glob("*/*.toml") if p.parent.name != "shared")
    if Path("../shared/scenes").is_dir():
        scenes += sorted(Path("scenes/shared").glob("*.toml"))
    else:
        print("../shared/scenes is absent: shipped scenes only", file=sys.stderr)
    return scenes


def render(args, scene, mode, out):
    command = [
        args.tessera, "render", str(scene), "--out", str(out), "--effects", mode,
        "--peers", "1", "--frames", "1", "--width", str(args.width), "--height",
        str(args.height), "--spp", str(args.spp),
    ]
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return json.loads((out / "stats.json").read_text())


def print_row(row):
    scene, effects, auto, all_, rays_auto, rays_all, same = row
    print(
        f"{scene.stem:24} auto {auto:7.3f} s  all {all_:7.3f} s  saved {100 * (1 - auto / all_):5.1f} %  "
        f"rays {rays_auto / 1e6:7.3f}M / {rays_all / 1e6:7.3f}M  "
        f"{'same bits' if same else 'BITS DIFFER'}  effects {effects}",
        flush=True,
    )


if __name__ == "__main__":
    main()
