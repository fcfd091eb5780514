#!/usr/bin/env python3
"""What specialising to RGB saves: `tessera bench` with `--spectral rgb` against `spectral-hero`.

Why: paths turn spectral only where they meet dispersive glass (tracer/src/spectrum.rs); a
renderer without that specialisation carries hero wavelengths on every path. `tessera bench
--spectral spectral-hero` is that always-spectral pipeline. Each scene is benched once per mode
per repeat, the modes interleaved so that the machine's load hits both alike; the figure is the
median of the full-path pass's CPU-seconds (user + system of the whole process during the render).

Usage (from the repository root, after `cargo build --release`):
    python3 scripts/spectral_bench.py --repeats 3 SCENE.toml...
"""

import argparse
import json
import os
import statistics
import subprocess

MODES = ["rgb", "spectral-hero"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tessera", default="target/release/tessera")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("scenes", nargs="+")
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()}")
    print("| scene | rgb paths CPU-s | spectral-hero paths CPU-s | hero / rgb | rgb primary CPU-s | hero primary CPU-s |")
    print("|---|---|---|---|---|---|")
    for scene in args.scenes:
        paths = {m: [] for m in MODES}
        primary = {m: [] for m in MODES}
        for _ in range(args.repeats):
            for mode in MODES:
                out = subprocess.run(
                    [args.tessera, "bench", scene, "--json", "--threads", "1", "--spectral", mode,
                     "--width", str(args.size), "--height", str(args.size), "--spp", str(args.spp)],
                    check=True, capture_output=True, text=True).stdout
                bench = json.loads(out[out.index("{"):])["scenes"][0]
                paths[mode].append(bench["paths"]["cpu_seconds"])
                primary[mode].append(bench["primary"]["cpu_seconds"])
        rgb, hero = (statistics.median(paths[m]) for m in MODES)
        p_rgb, p_hero = (statistics.median(primary[m]) for m in MODES)
        print(f"| {scene} | {rgb:.2f} | {hero:.2f} | {hero / rgb:.2f}x | {p_rgb:.2f} | {p_hero:.2f} |", flush=True)
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
