#!/usr/bin/env python3
"""Our traversal against Embree's, as Mitsuba 3 calls it, on the same rays: tracing alone.

Why this script exists: `scripts/mitsuba_compare.py` times whole renders, where tracing and
shading are mixed and Mitsuba runs eight or sixteen paths per instruction. Whether a gap between
the renderers is in the tree and its walk or in the shading around it, only the same rays traced
by both can say. So this script

1. builds each scene for Mitsuba as the comparison script does (`mitsuba_description`: the same
   triangles, in world space);
2. draws rays with Mitsuba: camera rays (eight per pixel, a pixel's eight in a row, the order a
   render traces them in), then rays leaving each camera hit in a cosine-distributed direction
   (`bounce-1`, incoherent, as the first diffuse bounce of a path is), then the same from those
   rays' hits (`bounce-2`), and uses `bounce-1` once more for an any-hit query (`shadow`: what a
   shadow ray toward the sky asks);
3. times Mitsuba's `ray_intersect_preliminary` (closest hit, no surface interaction built) and
   `ray_test` (any hit) on each set, one thread (`dr.set_thread_count`), the best of `--rounds`
   process-CPU times, with the JIT's kernels compiled in a first untimed call;
4. writes each set and Mitsuba's answers to OUT/SET.rays, and runs our
   `tracer/examples/trace_rays.rs` on them (one thread, thread-CPU time, the best of the same
   rounds), which also counts the answers that differ; the camera rays twice, one by one and
   a pixel's eight at a time as the renderer traces them (`packets`), since Mitsuba marks
   them coherent and traces them as packets;
5. prints a table and writes OUT/traversal.json.

Mitsuba's times include what its JIT adds around Embree's call (reading the rays from its arrays,
writing the answers), a few nanoseconds a ray; ours read the rays from a vector in memory. With
Embree's build settings Mitsuba's, ours our default (`BuildQuality::Medium`).

Usage (from the repository root):
    pip install mitsuba numpy      # llvm_ad_rgb also needs Debian's libllvm19
    cargo build --release -p tracer --example trace_rays
    python3 scripts/traversal_compare.py scenes/shared/sponza.toml --out out/bench/traversal
"""

import argparse
import json
import os
import struct
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mitsuba_compare import DEFAULT_SCENES, fmt_load, processor  # noqa: E402
from mitsuba_scene import mitsuba_description  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", default=DEFAULT_SCENES, help="tessera scene TOMLs")
    parser.add_argument("--out", default="out/bench/traversal", type=Path)
    parser.add_argument("--example", default="target/release/examples/trace_rays")
    parser.add_argument("--tessera", default="target/release/tessera", help="the binary whose loader gives Mitsuba the triangles")
    parser.add_argument("--size", type=int, default=512, help="the film's width and height")
    parser.add_argument("--per-pixel", type=int, default=8, help="camera rays per pixel")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--keep", action="store_true", help="keep the ray files (OUT/SCENE-SET.rays) for profiling")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(args.variant)
    dr.set_thread_count(1)
    report = {"processor": processor(), "load_before": os.getloadavg(), "variant": args.variant,
              "mitsuba": mi.__version__, "scenes": []}
    for toml in map(Path, args.scenes):
        description, triangles = mitsuba_description(toml, args.size, 1, 8, tessera=args.tessera)
        scene = mi.load_dict(description)
        sets = draw_rays(mi, dr, scene, args.size, args.per_pixel)
        stem = args.out / toml.stem
        command = [args.example, str(toml), str(args.rounds)]
        # (set, Mitsuba's CPU-s) for each of our runs, in the order the example prints them.
        runs = []
        for name, (ray, query) in sets.items():
            coherent = name == "camera"
            seconds, answers = time_mitsuba(mi, dr, scene, ray, query, coherent, args.rounds)
            path = Path(f"{stem}-{name}.rays")
            write_rays(path, ray, answers)
            command += [str(path), query]
            runs.append((name, seconds))
            if coherent:
                # Mitsuba traces them as packets; so does our renderer, a pixel's eight at a
                # time: both ways of ours against its one.
                command += [str(path), "packets"]
                runs.append((name, seconds))
        ours = [json.loads(line) for line in subprocess.run(
            command, check=True, capture_output=True, text=True).stdout.splitlines()]
        rows = []
        for (name, seconds), line in zip(runs, ours[1:]):
            rows.append({"set": name, "query": line["query"], "rays": line["rays"],
                         "tessera_cpu_seconds": line["cpu_seconds"], "mitsuba_cpu_seconds": seconds,
                         "ratio": line["cpu_seconds"] / seconds, "differ": line["differ"],
                         "boxes_per_ray": line["boxes_per_ray"], "triangles_per_ray": line["triangles_per_ray"]})
        report["scenes"].append({"scene": str(toml), "triangles": triangles, "sets": rows,
                                 "tessera_build": ours[0]})
        if not args.keep:
            for path in args.out.glob(f"{toml.stem}-*.rays"):
                path.unlink()
    report["load_after"] = os.getloadavg()
    (args.out / "traversal.json").write_text(json.dumps(report, indent=2))
    print(markdown(report))


def draw_rays(mi, dr, scene, size, per_pixel):
    """{name: (Ray3f, "closest" | "any")}: camera rays in a render's order, and two diffuse bounces."""
    n = size * size * per_pixel
    index = dr.arange(mi.UInt32, n)
    pixel = index // per_pixel
    rng = mi.PCG32(size=n, initstate=index)
    film = mi.Point2f((mi.Float(pixel % size) + rng.next_float32()) / size,
                      (mi.Float(pixel // size) + rng.next_float32()) / size)
    camera, _ = scene.sensors()[0].sample_ray(0.0, 0.5, film, mi.Point2f(0.5, 0.5))
    sets = {"camera": (camera, "closest")}
    ray = camera
    for bounce in (1, 2):
        si = scene.ray_intersect(ray)
        # Both sides of a surface reflect (the scenes' diffuse is two-sided): turn the normal
        # toward where the ray came from, and leave in a cosine-distributed direction about it.
        normal = dr.select(dr.dot(si.n, ray.d) < 0, si.n, -si.n)
        rng = mi.PCG32(size=dr.width(ray), initstate=dr.arange(mi.UInt32, dr.width(ray)), initseq=bounce)
        local = mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
        leaving = si.spawn_ray(mi.Frame3f(normal).to_world(local))
        keep = dr.compress(si.is_valid())
        ray = dr.gather(mi.Ray3f, leaving, keep)
        sets[f"bounce-{bounce}"] = (ray, "closest")
    sets["shadow"] = (sets["bounce-1"][0], "any")
    for r, _ in sets.values():
        dr.eval(r)
    return sets


def time_mitsuba(mi, dr, scene, ray, query, coherent, rounds):
    """The best process-CPU seconds of Mitsuba's query over `rounds`, and its answers."""
    def once():
        if query == "closest":
            pi = scene.ray_intersect_preliminary(ray, coherent=coherent)
            answer = dr.select(pi.is_valid(), pi.t, dr.inf)
        else:
            answer = mi.Float(scene.ray_test(ray, coherent=coherent))
        dr.eval(answer)
        dr.sync_thread()
        return answer
    answer = once()
    best = float("inf")
    for _ in range(rounds):
        cpu = time.process_time()
        once()
        best = min(best, time.process_time() - cpu)
    return best, answer


def write_rays(path, ray, answers):
    """The ray file `trace_rays` reads: a u64 count, then o, d, t_max and the answer, 8 f32 each."""
    import numpy as np

    n = len(answers)
    columns = [np.array(ray.o), np.array(ray.d), np.array(ray.maxt)[None, :], np.array(answers)[None, :]]
    records = np.concatenate(columns).astype("<f4").T.copy()
    with open(path, "wb") as f:
        f.write(struct.pack("<Q", n))
        f.write(records.tobytes())


def markdown(report):
    lines = [
        f"{report['processor']}, load {fmt_load(report['load_before'])} before, "
        f"{fmt_load(report['load_after'])} after; Mitsuba {report['mitsuba']} `{report['variant']}`, one thread",
        "",
        "| scene | set | query | rays | tessera CPU-s | Mitsuba (Embree) CPU-s | ratio | answers differing | "
        "our boxes / triangles per ray |",
        "|---|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for s in report["scenes"]:
        for r in s["sets"]:
            lines.append(
                f"| {Path(s['scene']).stem} | {r['set']} | {r['query']} | {r['rays']} | "
                f"{r['tessera_cpu_seconds']:.3f} | {r['mitsuba_cpu_seconds']:.3f} | {r['ratio']:.2f}x | "
                f"{r['differ']} | {r['boxes_per_ray']:.1f} / {r['triangles_per_ray']:.1f} |"
            )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
