#!/usr/bin/env python3
"""Where each renderer's time goes in the same render: tessera's profile and Mitsuba 3's, side by
side, each split into its closest-hit walks, its any-hit walks and the rest (shading, sampling,
making camera rays, the film).

Why this script exists: `scripts/mitsuba_compare.py` gives each render's total, and
`scripts/traversal_compare.py` times both renderers' walks on the same rays outside a render.
Neither says in which part of a render the difference lies, and the walks outside a render are
not the walks inside one: the order rays come in changes what a walk costs (Mitsuba hands Embree
sixteen samples of a pixel at one bounce at a time; our lanes walk eight paths at whatever
bounce each is at). So this script profiles both renders themselves, at mitsuba_compare's
settings:

1. `perf record -F 1000` of `tessera bench SCENE --json` (the paths pass, `--max-depth` one less
   than the segments, two threads as the machine has); the samples before the paths pass (the
   scene's loading, the tree's build and bench's pass of camera rays alone) are left out by time
   (`perf report --time`), from the wall seconds bench reports for them;
2. `perf record -F 1000` of Mitsuba's render in a worker process of `mitsuba_compare.py` (its
   scene built the same way, at the roulette depth bench reported), its own JSON giving the
   render's CPU-seconds;
3. each sample is put in a class by its function: ours, the walks proper (`traverse_*`, whose
   instance the debug information names, `traverse_avx<false, false>` being the closest-hit
   walk and those with `true` the shadow queries; the camera packets' `packet_*`; the triangle
   pairs' `intersect_pair_avx`, which both walks call, counted with the closest-hit walk), and
   everything else of the binary as the rest; Mitsuba's, Embree's `intersect` and `occluded`
   functions, and the code its LLVM backend compiled (the anonymous `perf-PID.map` region) as
   the rest; Python, the EXR writer and the kernel are outside the render and left out;
4. `--repeats N` times over, ours then Mitsuba's, scene by scene; each renderer's run of fewest
   CPU-seconds is reported (this machine's speed drifts by a third within minutes), as a table
   printed and written to OUT/profile.md, every run's classes to OUT/profile.json.

Needs `perf` (sampling works without hardware counters, by the CPU clock), and `nm`, `readelf`
and `llvm-dwarfdump` to tell the walks' instances apart (without them, all of `traverse_*` is
one class).

Usage (from the repository root, after `cargo build --release`):
    python3 scripts/profile_split.py --repeats 3 --out out/bench/profile scenes/shared/cornell-box-original.toml
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mitsuba_compare import DEFAULT_SCENES, fmt_load, processor, scene_files_present, worker_command  # noqa: E402

CLASSES = ("closest-hit walks", "any-hit walks", "the rest")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", default=DEFAULT_SCENES, help="tessera scene TOMLs")
    parser.add_argument("--tessera", default="target/release/tessera")
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--segments", type=int, default=8, help="path segments (Mitsuba's max_depth)")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default="out/bench/profile", type=Path)
    args = parser.parse_args()
    if not shutil.which("perf"):
        sys.exit("perf is needed (apt install linux-perf)")
    load_before = os.getloadavg()
    rows = []
    runs = {}
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        for toml in map(Path, args.scenes):
            if not scene_files_present(toml):
                print(f"{toml}: skipped, its OBJ (under ../shared/scenes) is absent", file=sys.stderr)
                continue
            ours, theirs = [], []
            for r in range(args.repeats):
                ours.append(profile_tessera(toml, args, scratch / f"tessera-{r}.data"))
                theirs.append(profile_mitsuba(toml, args, ours[-1]["roulette_depth"], scratch / f"mitsuba-{r}.data"))
                print(f"{toml.stem}, run {r + 1}: tessera {describe(ours[-1])}; Mitsuba {describe(theirs[-1])}",
                      file=sys.stderr)
            rows.append((toml.stem, min(ours, key=lambda p: p["cpu_seconds"]),
                         min(theirs, key=lambda p: p["cpu_seconds"])))
            runs[toml.stem] = {"tessera": ours, "mitsuba": theirs}
    load_after = os.getloadavg()
    lines = [
        f"{processor()}, load {fmt_load(load_before)} before, {fmt_load(load_after)} after; "
        f"{args.size}x{args.size}, {args.spp} spp, {args.segments} segments, Mitsuba `{args.variant}`; "
        f"each renderer's fastest of {args.repeats} runs, CPU-seconds of the render",
        "",
        "| scene | renderer | render | " + " | ".join(CLASSES) + " |",
        "|---|---|---:|" + "---:|" * len(CLASSES),
    ]
    for scene, our, their in rows:
        for name, p in (("tessera", our), ("Mitsuba (Embree, LLVM)", their)):
            lines.append(f"| {scene} | {name} | {p['cpu_seconds']:.2f} | "
                         + " | ".join(f"{p['classes'][c]:.2f}" for c in CLASSES) + " |")
        lines.append(f"| {scene} | ratio | {our['cpu_seconds'] / their['cpu_seconds']:.2f}x | "
                     + " | ".join(ratio(our['classes'][c], their['classes'][c]) for c in CLASSES) + " |")
    table = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "profile.md").write_text(table)
    report = {"processor": processor(), "load_before": load_before, "load_after": load_after,
              "settings": {"size": args.size, "spp": args.spp, "segments": args.segments,
                           "variant": args.variant, "repeats": args.repeats},
              "runs": runs}
    (args.out / "profile.json").write_text(json.dumps(report, indent=2) + "\n")
    print(table, end="")


def ratio(a, b):
    return f"{a / b:.2f}x" if b > 0 else "-"


def describe(p):
    return f"{p['cpu_seconds']:.2f} CPU-s (" + ", ".join(f"{c} {p['classes'][c]:.2f}" for c in CLASSES) + ")"


def profile_tessera(toml, args, data):
    """`tessera bench` under perf; the classes of its paths pass's samples."""
    command = [args.tessera, "bench", str(toml), "--json", "--width", str(args.size), "--height", str(args.size),
               "--spp", str(args.spp), "--max-depth", str(args.segments - 1)]
    done = subprocess.run(["perf", "record", "-q", "-F", "1000", "-o", str(data), *command],
                          capture_output=True, text=True, check=True)
    scene = json.loads(done.stdout[done.stdout.index("{"):])["scenes"][0]
    # The paths pass starts after the loading, the build and the camera-only pass (wall time).
    before = scene["load_seconds"] + scene["build_seconds"] + scene["primary"]["seconds"]
    classes = classify(data, skip=before, ours=True)
    return {"cpu_seconds": scene["paths"]["cpu_seconds"], "classes": classes,
            "roulette_depth": scene["paths"]["russian_roulette_depth"]}


def profile_mitsuba(toml, args, roulette_depth, data):
    """Mitsuba's render of `toml` in a worker under perf; the classes of its samples."""
    command = worker_command(args.variant, toml, data.with_suffix(".exr"), args.size, args.spp, args.segments,
                             args.tessera, roulette_depth)
    done = subprocess.run(["perf", "record", "-q", "-F", "1000", "-o", str(data), *command],
                          capture_output=True, text=True, check=True)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    return {"cpu_seconds": result["render_cpu_seconds"], "classes": classify(data, skip=0.0, ours=False)}


def classify(data, skip, ours):
    """Seconds of samples per class, leaving out those in the first `skip` seconds of wall time."""
    command = ["perf", "report", "-i", str(data), "--no-children", "--sort", "dso,sym", "-v", "--stdio"]
    if skip > 0:
        first = subprocess.run(["perf", "script", "-i", str(data), "-F", "time"], capture_output=True, text=True)
        start = float(first.stdout.split()[0].rstrip(":"))
        command += ["--time", f"{start + skip:.6f},"]
    report = subprocess.run(command, capture_output=True, text=True, check=True).stdout
    total = int(re.search(r"Event count \(approx\.\): (\d+)", report).group(1)) / 1e9
    classes = dict.fromkeys(CLASSES, 0.0)
    names = WalkNames()
    for line in report.splitlines():
        m = re.match(r"\s+([\d.]+)%\s+(\S+)\s+(0x[0-9a-f]+)\s+\S+\s+\[.\]\s+(.*)", line)
        if not m:
            continue
        seconds = float(m.group(1)) / 100 * total
        dso, address, symbol = m.group(2), int(m.group(3), 16), m.group(4).strip()
        kind = our_class(dso, address, symbol, names) if ours else their_class(dso, symbol)
        if kind:
            classes[kind] += seconds
    return classes


def our_class(dso, address, symbol, names):
    if "tessera" not in Path(dso).name:
        return None
    if re.search(r"::traverse_(avx|portable|robust)$", symbol):
        return "any-hit walks" if "true" in names.instance(dso, address) else "closest-hit walks"
    if re.search(r"::(packet_avx|packet_portable|intersect_packet|intersect_pair_avx)$", symbol):
        return "closest-hit walks"
    return "the rest"


def their_class(dso, symbol):
    if "Intersector" in symbol and "::occluded" in symbol:
        return "any-hit walks"
    if "Intersector" in symbol and "::intersect" in symbol:
        return "closest-hit walks"
    if re.search(r"perf-\d+\.map", dso):
        return "the rest"
    return None


class WalkNames:
    """The generic instance (`traverse_avx<false, false>`) a walk's address lies in, by the
    symbol table and the debug information; '' where the tools are missing."""

    def __init__(self):
        self.starts, self.shift, self.names = {}, {}, {}
        self.tools = all(shutil.which(tool) for tool in ("nm", "readelf", "llvm-dwarfdump"))

    def instance(self, dso, address):
        if not self.tools:
            return ""
        if dso not in self.starts:
            table = subprocess.run(["nm", dso], capture_output=True, text=True).stdout
            self.starts[dso] = sorted(int(line.split()[0], 16) for line in table.splitlines()
                                      if re.search(r"traverse_(avx|portable|robust)", line))
            # perf reports offsets into the file; the symbols are at virtual addresses.
            segments = subprocess.run(["readelf", "-lW", dso], capture_output=True, text=True).stdout
            code = next(line.split() for line in segments.splitlines() if "LOAD" in line and "R E" in line)
            self.shift[dso] = int(code[2], 16) - int(code[1], 16)
        address += self.shift[dso]
        start = max((s for s in self.starts[dso] if s <= address), default=None)
        if start is None:
            return ""
        if (dso, start) not in self.names:
            info = subprocess.run(["llvm-dwarfdump", f"--lookup={start:#x}", dso], capture_output=True, text=True)
            m = re.search(r'DW_AT_name\s+\("(traverse_\w+<[^"]*>)"\)', info.stdout)
            self.names[(dso, start)] = m.group(1) if m else ""
        return self.names[(dso, start)]


if __name__ == "__main__":
    main()
