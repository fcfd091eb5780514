#!/usr/bin/env python3
"""Mitsuba 3 and tessera on the same OBJ scenes, at the same settings, side by side in one run.

Why this script exists: the tracer issue sets a target of being faster than the renderer a user
would otherwise pick, at equal settings and with the same mean image (within 1% per channel). A
speed figure means nothing unless both renderers drew the same picture, so this script

1. reads each scene's tessera TOML (camera, environment), takes its triangles and materials as
   tessera's loader made them (`tessera meshes`), and builds the same scene for Mitsuba from them
   (`scripts/mitsuba_scene.py`, with its mappings): one mesh per object and material, the
   albedo (or its texture) as a two-sided diffuse reflectance, the emission
   as a one-sided area light, `[environment] radiance` as a `constant` emitter and a lat-long
   `map` as an `envmap`, a camera with an open aperture as a `thinlens`;
2. runs `tessera bench` on the same TOML at the size, samples and depth given, which writes our
   EXR and our timings (CPU-seconds of the whole process, BVH build and render) and reports the
   depth from which the scene's Russian roulette may end paths;
3. renders it with Mitsuba at the same settings, that roulette depth included (each variant in a
   fresh process, so that its CPU-seconds are its own), and writes an EXR; scene by scene, our run
   then Mitsuba's, `--repeats N` times over, each renderer's fastest run reported (a machine
   shared with others disturbs single runs by up to a third);
4. runs `tessera compare OURS.exr MITSUBA.exr --json` and checks the per-channel means, and
   compares the images' means over 8x8-pixel blocks (`block_difference`), which see a picture
   mirrored, shifted or blurred that the means cannot;
5. prints one table and writes OUT/compare.json and OUT/compare.md.

Participating media: a scene may also hold procedural spheres (`shape = "sphere"`) whose
material is an `interface` or `glass` with a `medium` (MEDIA_MAPPING below); such scenes are
rendered by Mitsuba's `volpath` instead of `path`. `scenes/shared/cornell-box-smoke.toml` is one.
Global fog (`[camera] medium`) becomes the medium of Mitsuba's sensor, where its camera rays start
(`scenes/shared/cornell-box-fog.toml`).

Depth of field and environment maps (issue 16): `scenes/shared/cornell-box-focus.toml` and
`scenes/shared/stanford-bunny-sky.toml`. Mitsuba's time on a map scene is not a speed comparison:
it reads the map with each texel repeated 32 times each way (EFFECTS_MAPPING in
`scripts/mitsuba_scene.py` says why), which costs its render more than the map would.

Depth: Mitsuba's `max_depth` counts path segments (1 shows emitters only), ours counts bounces as
pbrt does (0 shows emitters only), so Mitsuba `max_depth = 8` is our `--max-depth 7`. Russian
roulette: both count the scattering events before it alike, so Mitsuba's `rr_depth` is the
scene's `russian_roulette_depth` (scenes/README.md has its default) as `tessera bench` reports
it. Until 2026-12-06 this script left Mitsuba at its own default of 5, so that Mitsuba traced
about a quarter more segments per path than tessera on the Cornell box for the same mean image
(docs/bench.md, issue 12, twenty-eighth round): every speed ratio before then favours tessera.

Usage (from the repository root, after `cargo build --release`):
    pip install mitsuba            # llvm_ad_rgb also needs Debian's libllvm19
    python3 scripts/mitsuba_compare.py --out out/bench/mitsuba
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time
import tomllib
from pathlib import Path

from mitsuba_scene import EFFECTS_MAPPING, MEDIA_MAPPING, MTL_MAPPING, mitsuba_description

DEFAULT_SCENES = [
    "scenes/shared/cornell-box-original.toml",
    "scenes/shared/cornell-bunny.toml",
    "scenes/shared/cornell-dragon.toml",
    "scenes/shared/sponza.toml",
]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", default=DEFAULT_SCENES, help="tessera scene TOMLs")
    parser.add_argument("--out", default="out/bench/mitsuba", type=Path)
    parser.add_argument("--tessera", default="target/release/tessera", help="the tessera binary")
    parser.add_argument("--size", type=int, default=512, help="image width and height")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument(
        "--segments", type=int, default=8, help="path segments (Mitsuba max_depth; ours is one less)"
    )
    parser.add_argument("--variants", default="llvm_ad_rgb,scalar_rgb")
    parser.add_argument("--tolerance", type=float, default=0.01, help="allowed relative difference of channel means")
    parser.add_argument(
        "--integrator",
        choices=["auto", "path", "volpath"],
        default="auto",
        help="Mitsuba's integrator: auto is volpath where the scene has media, else path; forcing volpath "
        "on a scene without media measures what a renderer that always tracks media pays",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=1,
        help="runs of each renderer on each scene, alternated scene by scene (tessera, then Mitsuba); the "
        "table shows each renderer's fastest run and lists every run's CPU-seconds below it: on a shared "
        "machine the fastest is the one others disturbed least, and alternating exposes both renderers "
        "to the same disturbances",
    )
    parser.add_argument(
        "--mitsuba-lanes",
        type=int,
        choices=[4, 8, 16],
        help="paths per instruction in Mitsuba's llvm variants (Dr.Jit's LLVM vector width, by default 16 "
        "where the processor has AVX-512 and 8 where it has AVX2): 8 on an AVX-512 machine shows how much "
        "of Mitsuba's time there is its wider vectors; the processor and its features stay the host's",
    )
    parser.add_argument(
        "--floor",
        action="store_true",
        help="render each scene once more with each renderer at another sampler seed and report how each one's "
        "two images differ over blocks: the noise floors that tessera's difference from Mitsuba is read against",
    )
    parser.add_argument("--seed", type=int, default=0, help=argparse.SUPPRESS)
    # The worker's roulette depth, as tessera reported it for the scene ("off" where none).
    parser.add_argument("--roulette-depth", default="off", help=argparse.SUPPRESS)
    parser.add_argument("--worker", nargs=3, metavar=("VARIANT", "TOML", "EXR"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        variant, toml, exr = args.worker
        roulette = None if args.roulette_depth == "off" else int(args.roulette_depth)
        print(json.dumps(render_mitsuba(variant, Path(toml), Path(exr), args.size, args.spp, args.segments,
                                        args.integrator, args.mitsuba_lanes, args.seed, roulette, args.tessera)))
        return

    present = [Path(s) for s in args.scenes if scene_files_present(Path(s))]
    for s in args.scenes:
        if Path(s) not in present:
            print(f"{s}: skipped, its OBJ (under ../shared/scenes) is absent", file=sys.stderr)
    if not present:
        sys.exit("no scene to compare")
    if args.repeats < 1:
        sys.exit("--repeats must be at least 1")
    args.out.mkdir(parents=True, exist_ok=True)
    load_before = os.getloadavg()
    variants = [v for v in args.variants.split(",") if v]
    # Every run, scene by scene, ours then Mitsuba's variants at the roulette depth ours
    # reported, so that a disturbance of the machine falls on both renderers alike; both are
    # deterministic, so each repeat writes the same images over the last.
    mitsuba_runs = {}
    our_runs = {}
    for _ in range(args.repeats):
        for toml in present:
            ours = run_tessera([toml], args)[str(toml)]
            our_runs.setdefault(str(toml), []).append(ours)
            for variant in variants:
                exr = args.out / f"mitsuba-{variant}" / f"{toml.stem}.exr"
                exr.parent.mkdir(parents=True, exist_ok=True)
                result = run_worker(variant, toml, exr, args, ours["roulette_depth"])
                mitsuba_runs.setdefault((variant, toml.stem), []).append(result)
                print(f"mitsuba {variant} {toml.stem}: {describe(result)}", file=sys.stderr)
    rows = []
    for toml in present:
        our = fastest(our_runs[str(toml)])
        # Our own noise floor is the same whichever Mitsuba variant it is read beside: one render.
        our_floor = None
        if args.floor:
            our_again = run_tessera([toml], args, seed=1)[str(toml)]["image"]
            our_floor = block_difference(our_again, our["image"])
        for variant in variants:
            theirs = fastest(mitsuba_runs[(variant, toml.stem)])
            row = {
                "scene": toml.stem,
                "variant": variant,
                "mitsuba": theirs,
                "tessera": our,
                "runs": {
                    "tessera": [r["cpu_seconds"] for r in our_runs[str(toml)]],
                    "mitsuba": [r["cpu_seconds"] for r in mitsuba_runs[(variant, toml.stem)] if "error" not in r],
                },
            }
            if "error" not in theirs:
                row["comparison"] = compare(args.tessera, our["image"], theirs["exr"], args.tolerance)
                if args.floor:
                    again = Path(theirs["exr"]).with_suffix(".seed1.exr")
                    if "error" not in run_worker(variant, toml, again, args, our["roulette_depth"], seed=1):
                        row["floor"] = block_difference(again, theirs["exr"])
                    row["our_floor"] = our_floor
            rows.append(row)
    report = {
        "settings": {"size": args.size, "spp": args.spp, "segments": args.segments, "tessera_max_depth": args.segments - 1,
                     "tolerance": args.tolerance, "mitsuba_integrator": args.integrator, "repeats": args.repeats},
        "mtl_mapping": MTL_MAPPING,
        "media_mapping": MEDIA_MAPPING,
        "effects_mapping": EFFECTS_MAPPING,
        "cores": os.cpu_count(),
        "processor": processor(),
        "load_before": load_before,
        "load_after": os.getloadavg(),
        "rows": rows,
    }
    (args.out / "compare.json").write_text(json.dumps(report, indent=2) + "\n")
    table = markdown(report)
    (args.out / "compare.md").write_text(table)
    print(table)


def fastest(runs):
    """The run of least CPU-seconds, or the first failure where every run failed."""
    done = [r for r in runs if "error" not in r]
    return min(done, key=lambda r: r["cpu_seconds"]) if done else runs[0]


def scene_files_present(toml):
    scene = tomllib.loads(toml.read_text())
    return all((toml.parent / o["obj"]).exists() for o in scene.get("object", []) if "obj" in o)


def worker_command(variant, toml, exr, size, spp, segments, tessera, roulette_depth, integrator="auto",
                   lanes=None, seed=0):
    """The command that renders `toml` with Mitsuba in a process of its own, with Russian
    roulette from `roulette_depth` (tessera's, as `tessera bench` reported it; `None`: off);
    its last line of output is the render's JSON (`render_mitsuba`)."""
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", variant, str(toml), str(exr)]
    command += ["--size", str(size), "--spp", str(spp), "--segments", str(segments)]
    command += ["--integrator", integrator, "--seed", str(seed), "--tessera", tessera]
    command += ["--roulette-depth", "off" if roulette_depth is None else str(roulette_depth)]
    if lanes:
        command += ["--mitsuba-lanes", str(lanes)]
    return command


def run_worker(variant, toml, exr, args, roulette_depth, seed=0):
    """Mitsuba's render of `toml` in a process of its own (`worker_command`)."""
    command = worker_command(variant, toml, exr, args.size, args.spp, args.segments, args.tessera, roulette_depth,
                             args.integrator, args.mitsuba_lanes, seed)
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        return {"error": done.stderr.strip().splitlines()[-1] if done.stderr.strip() else f"exit {done.returncode}"}
    return json.loads(done.stdout.strip().splitlines()[-1])


def run_tessera(tomls, args, seed=0):
    """One `tessera bench` over every scene: its JSON has our timings and the EXR paths."""
    out = args.out / ("tessera" if seed == 0 else f"tessera-seed{seed}")
    command = [args.tessera, "bench", *map(str, tomls), "--spp", str(args.spp), "--width", str(args.size)]
    command += ["--height", str(args.size), "--max-depth", str(args.segments - 1), "--out", str(out), "--json"]
    command += ["--seed", str(seed)]
    print("running: " + " ".join(command), file=sys.stderr)
    done = subprocess.run(command, capture_output=True, text=True, check=True)
    report = json.loads(done.stdout)
    results = {}
    for s in report["scenes"]:
        paths = s["paths"]
        results[s["scene"]] = {
            "triangles": s["triangles"],
            "build_seconds": s["build_seconds"],
            "build_cpu_seconds": s["build_cpu_seconds"],
            "render_seconds": paths["seconds"],
            "render_cpu_seconds": paths["cpu_seconds"],
            "cpu_seconds": (s["build_cpu_seconds"] or 0) + (paths["cpu_seconds"] or 0),
            "wall_seconds": s["build_seconds"] + paths["seconds"],
            "rays": paths["rays"],
            "roulette_depth": paths["russian_roulette_depth"],
            "mrays_per_second": paths["rays_per_second"] / 1e6,
            "image": s["image"],
            # Resident memory of the whole process (KiB), as Mitsuba's worker reports its own.
            "memory": s.get("memory"),
        }
        print(f"tessera {Path(s['scene']).stem}: {describe(results[s['scene']])}", file=sys.stderr)
    return results


def compare(tessera, ours, theirs, tolerance):
    done = subprocess.run([tessera, "compare", ours, theirs, "--json"], capture_output=True, text=True, check=True)
    metrics = json.loads(done.stdout)
    test, reference = metrics["mean_test"], metrics["mean_reference"]
    relative = [(t - r) / r if r else float("nan") for t, r in zip(test, reference)]
    return {
        "mean_tessera": test,
        "mean_mitsuba": reference,
        "relative_difference": relative,
        "within_tolerance": all(abs(d) <= tolerance for d in relative),
        "rmse": metrics["rmse"],
        "rel_mse": metrics["rel_mse"],
        "flip": metrics.get("flip", {}).get("mean") if isinstance(metrics.get("flip"), dict) else metrics.get("flip"),
        "blocks": block_difference(ours, theirs),
    }


# The side of the square blocks whose means `block_difference` compares, in pixels.
BLOCK = 8


def block_difference(ours, theirs):
    """Where in the image the two renderers differ, not only by how much on the whole: the
    luminance of each BLOCK x BLOCK block of pixels, ours relative to Mitsuba's, as the root mean
    square and the largest magnitude over the blocks. The image means cannot see a picture
    mirrored, or sharp where the other is blurred; block means can, while the blocks' thousands
    of samples average most of the noise away (what remains of it sets the floor, which `--floor`
    measures: two renders of each renderer at different seeds). Blocks darker than a thousandth of the
    image's mean are left out, as a relative difference there is noise over nothing."""
    import mitsuba as mi
    import numpy as np

    mi.set_variant("scalar_rgb")
    luminance = np.array([0.2126, 0.7152, 0.0722])
    blocks = []
    for path in (ours, theirs):
        pixels = np.array(mi.Bitmap(str(path)).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False))
        height, width = (pixels.shape[0] // BLOCK) * BLOCK, (pixels.shape[1] // BLOCK) * BLOCK
        y = pixels[:height, :width] @ luminance
        blocks.append(y.reshape(height // BLOCK, BLOCK, width // BLOCK, BLOCK).mean(axis=(1, 3)))
    test, reference = blocks
    lit = reference > 1e-3 * reference.mean()
    relative = (test[lit] - reference[lit]) / reference[lit]
    return {"size": BLOCK, "rms": float(np.sqrt(np.mean(relative**2))), "max": float(np.abs(relative).max())}


def processor():
    """The processor's model name and the SIMD features that decide speed here: drjit's LLVM
    backend compiles for the machine it runs on (AVX-512 where present), tessera picks AVX at
    run time, so figures from machines with different features must not be read side by side."""
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return "unknown processor"
    model = next((l.split(":", 1)[1].strip() for l in info.splitlines() if l.startswith("model name")), "unknown")
    flags = next((l.split(":", 1)[1].split() for l in info.splitlines() if l.startswith("flags")), [])
    simd = [f for f in ("avx", "avx2", "fma", "avx512f", "avx512vl") if f in flags]
    return f"{model}; {' '.join(simd) or 'no AVX'}"


def describe(r):
    if "error" in r:
        return "error: " + r["error"]
    return f"{r['cpu_seconds']:.2f} CPU-s, {r['wall_seconds']:.2f} s wall"


def markdown(report):
    s = report["settings"]
    lines = [
        f"{s['size']}x{s['size']}, {s['spp']} spp, at most {s['segments']} path segments "
        f"(Mitsuba max_depth {s['segments']}, tessera --max-depth {s['tessera_max_depth']}); "
        f"{report['cores']} cores ({report.get('processor', 'processor not recorded')}), "
        f"load average {fmt_load(report['load_before'])} before, "
        f"{fmt_load(report['load_after'])} after. Russian roulette from the scene's depth in both renderers: "
        + ", ".join(sorted({f"{r['scene']} {fmt_roulette(r['tessera'].get('roulette_depth'))}" for r in report["rows"]}))
        + ".",
        "",
        "| scene | triangles | renderer | build + render CPU-s | wall s | mean R / G / B | tessera vs Mitsuba, per channel |",
        "|---|---|---|---|---|---|---|",
    ]
    seen = set()
    for row in report["rows"]:
        our = row["tessera"]
        if row["scene"] not in seen:
            seen.add(row["scene"])
            means = next((r["comparison"]["mean_tessera"] for r in report["rows"] if r["scene"] == row["scene"] and "comparison" in r), None)
            lines.append(
                f"| {row['scene']} | {our['triangles']} | tessera | {our['cpu_seconds']:.2f} "
                f"({our['build_cpu_seconds']:.2f} + {our['render_cpu_seconds']:.2f}) | {our['wall_seconds']:.2f} | "
                f"{fmt_means(means)} | |"
            )
        m = row["mitsuba"]
        name = f"{row['variant']} ({m['llvm_lanes']} lanes)" if m.get("llvm_lanes") else row["variant"]
        if "error" in m:
            lines.append(f"| {row['scene']} | | Mitsuba {name} | failed: {m['error']} | | | |")
            continue
        c = row["comparison"]
        diff = " / ".join(f"{d * 100:+.2f}%" for d in c["relative_difference"])
        verdict = "within" if c["within_tolerance"] else "OUTSIDE"
        tolerance = f"{s['tolerance'] * 100:g}%"
        lines.append(
            f"| {row['scene']} | | Mitsuba {name} | {m['cpu_seconds']:.2f} "
            f"({m['load_cpu_seconds']:.2f} + {m['render_cpu_seconds']:.2f}) | {m['wall_seconds']:.2f} | "
            f"{fmt_means(c['mean_mitsuba'])} | {diff} ({verdict} {tolerance}; RMSE {c['rmse']:.4f}; "
            f"{c['blocks']['size']}-pixel blocks {c['blocks']['rms'] * 100:.1f}% RMS, {c['blocks']['max'] * 100:.1f}% at most"
            f"{fmt_floor(row)}) |"
        )
    lines += memory_table(report)
    if s.get("repeats", 1) > 1:
        lines += ["", f"Each renderer's fastest of {s['repeats']} runs, alternated scene by scene; every run's CPU-s:", ""]
        for row in report["rows"]:
            if "error" in row["mitsuba"]:
                continue
            ratio = row["tessera"]["cpu_seconds"] / row["mitsuba"]["cpu_seconds"]
            ours = ", ".join(f"{v:.2f}" for v in row["runs"]["tessera"])
            theirs = ", ".join(f"{v:.2f}" for v in row["runs"]["mitsuba"])
            lines.append(f"- {row['scene']}: tessera {ours}; Mitsuba {row['variant']} {theirs}; fastest against fastest {ratio:.2f}x")
    for title, key in (("MTL", "mtl_mapping"), ("Media", "media_mapping"), ("Effects", "effects_mapping")):
        lines += ["", f"{title} mapping: {report[key]}."]
    lines.append("")
    return "\n".join(lines)


def memory_table(report):
    """Each renderer's whole process, resident, in MB: one process per scene on both sides
    (Mitsuba's includes the Python interpreter and its libraries, its 'before' column)."""
    mb = lambda kib: f"{kib / 1024:.1f}" if kib is not None else "?"
    lines = ["", "Memory, the whole process resident, MB (the fastest runs'):", "",
             "| scene | renderer | before the scene | after the scene | after the render | peak |",
             "|---|---|---:|---:|---:|---:|"]
    seen = set()
    for row in report["rows"]:
        memory = row["tessera"].get("memory")
        if row["scene"] not in seen and memory:
            seen.add(row["scene"])
            lines.append(f"| {row['scene']} | tessera | | {mb(memory['resident_after_build_kib'])} | "
                         f"{mb(memory['resident_after_render_kib'])} | {mb(memory['peak_resident_kib'])} |")
        m = row["mitsuba"]
        if "error" not in m and m.get("peak_rss_kib") is not None:
            lines.append(f"| {row['scene']} | Mitsuba {row['variant']} | {mb(m.get('rss_before_scene_kib'))} | "
                         f"{mb(m.get('rss_after_scene_kib'))} | {mb(m.get('rss_after_render_kib'))} | "
                         f"{mb(m['peak_rss_kib'])} |")
    return lines if len(lines) > 5 else []


def fmt_floor(row):
    """The noise floors `--floor` measured: each renderer against itself at another seed."""
    text = ""
    for key, who in (("floor", "Mitsuba"), ("our_floor", "tessera")):
        if row.get(key):
            floor = row[key]
            text += f"; {who} against itself at another seed {floor['rms'] * 100:.1f}% RMS, {floor['max'] * 100:.1f}% at most"
    return text


def fmt_roulette(depth):
    return "off" if depth is None else f"from {depth}"


def fmt_means(means):
    return " / ".join(f"{v:.4f}" for v in means) if means else ""


def fmt_load(load):
    return " ".join(f"{v:.2f}" for v in load)


# --- The Mitsuba side, run in a process of its own per (variant, scene). ---


def llvm_lanes(lanes=None):
    """Dr.Jit's LLVM vector width (paths per instruction in the llvm variants), set to `lanes`
    first where given, the host's processor and features kept. Dr.Jit's Python interface exposes
    neither `jit_llvm_set_target` nor `jit_llvm_vector_width`, so both are called in its library
    by their (C++) names."""
    import ctypes

    import drjit as dr

    lib = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
    cpu, features = lib._Z19jit_llvm_target_cpuv, lib._Z24jit_llvm_target_featuresv
    width = lib._Z21jit_llvm_vector_widthv
    cpu.restype = features.restype = ctypes.c_char_p
    width.restype = ctypes.c_uint32
    if lanes:
        lib._Z19jit_llvm_set_targetPKcS0_j(cpu(), features(), ctypes.c_uint32(lanes))
    return width()


def render_mitsuba(variant, toml, exr, size, spp, segments, integrator="auto", lanes=None, seed=0, roulette_depth=None,
                   tessera="target/release/tessera"):
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(variant)
    lanes = llvm_lanes(lanes) if variant.startswith("llvm") else None
    description, triangles = mitsuba_description(toml, size, spp, segments, integrator, seed, roulette_depth, tessera)
    # Resident memory (KiB) before Mitsuba builds its scene (the meshes already handed over from
    # `tessera meshes`' files), and after the scene and the render: the
    # growth is about what Mitsuba's scene (meshes and BVH) and render took.
    rss_before_scene = resident_kib()
    cpu, wall = time.process_time(), time.perf_counter()
    scene = mi.load_dict(description)
    dr.eval(scene)
    dr.sync_thread()
    rss_after_scene = resident_kib()
    load_cpu, load_wall = time.process_time() - cpu, time.perf_counter() - wall
    cpu, wall = time.process_time(), time.perf_counter()
    image = mi.render(scene, spp=spp)
    dr.eval(image)
    dr.sync_thread()
    render_cpu, render_wall = time.process_time() - cpu, time.perf_counter() - wall
    mi.util.write_bitmap(str(exr), image)
    return {
        "variant": variant,
        "mitsuba": mi.__version__,
        "llvm_lanes": lanes,
        "triangles": triangles,
        "load_cpu_seconds": load_cpu,
        "render_cpu_seconds": render_cpu,
        "cpu_seconds": load_cpu + render_cpu,
        "load_seconds": load_wall,
        "render_seconds": render_wall,
        "wall_seconds": load_wall + render_wall,
        "rss_before_scene_kib": rss_before_scene,
        "rss_after_scene_kib": rss_after_scene,
        "rss_after_render_kib": resident_kib(),
        "peak_rss_kib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
        "exr": str(exr),
    }


def resident_kib():
    """This process's resident memory now, in KiB (Linux's /proc; None elsewhere)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None



if __name__ == "__main__":
    main()
