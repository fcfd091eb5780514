#!/usr/bin/env python3
"""Mitsuba 3 and tessera on the same OBJ scenes, at the same settings, side by side in one run.

Why this script exists: the tracer issue sets a target of being faster than the renderer a user
would otherwise pick, at equal settings and with the same mean image (within 1% per channel). A
speed figure means nothing unless both renderers drew the same picture, so this script

1. reads each scene's tessera TOML (camera, OBJ file, a constant environment) and the OBJ/MTL
   it names, and builds the same scene for Mitsuba from them: one mesh per MTL material, Kd (or
   its `map_Kd` texture) as a two-sided diffuse reflectance, Ke as a one-sided area light (see
   MTL_MAPPING below), `[environment] radiance` as a `constant` emitter;
2. renders it with Mitsuba (each variant in a fresh process, so that its CPU-seconds are its
   own) and writes an EXR;
3. runs `tessera bench` on the same TOML at the same size, samples and depth, which writes our EXR
   and our timings (CPU-seconds of the whole process, BVH build and render); scene by scene, after
   Mitsuba's run of it, and `--repeats N` times over, each renderer's fastest run reported (a
   machine shared with others disturbs single runs by up to a third);
4. runs `tessera compare OURS.exr MITSUBA.exr --json` and checks the per-channel means;
5. prints one table and writes OUT/compare.json and OUT/compare.md.

Participating media: a scene may also hold procedural spheres (`shape = "sphere"`) whose
material is an `interface` or `glass` with a `medium` (MEDIA_MAPPING below); such scenes are
rendered by Mitsuba's `volpath` instead of `path`. `scenes/shared/cornell-box-smoke.toml` is one.
Global fog (`[camera] medium`) becomes the medium of Mitsuba's sensor, where its camera rays start
(`scenes/shared/cornell-box-fog.toml`).

Depth: Mitsuba's `max_depth` counts path segments (1 shows emitters only), ours counts bounces as
pbrt does (0 shows emitters only), so Mitsuba `max_depth = 8` is our `--max-depth 7`.

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

# How the script maps MTL onto Mitsuba. Mitsuba's own OBJ loader ignores MTL files entirely, so
# the mapping is ours; it is the one tessera applies to these files (scenes/README.md, "MTL"):
# every material of the shared Cornell scenes is `illum 2` with `Ks 0`, which tessera reads as
# diffuse with reflectance Kd. Mitsuba's `diffuse` is black from behind, tessera's reflection-only
# BSDFs are two-sided, so the diffuse goes in a `twosided` wrapper. `Ke` > 0 adds an `area`
# emitter, which, like tessera's, emits on the winding normal's side only. Ns, Ni, Ka and illum
# play no part for these materials in either renderer.
#
# Textures (Sponza): tessera's diffuse with `map_Kd` is the texture alone (albedo 1, Kd ignored),
# decoded from sRGB to linear, looked up nearest with repeat wrapping, v = 0 the bottom row
# (tracer/src/scene/texture.rs). Mitsuba's `bitmap` with `filter_type = nearest`,
# `wrap_mode = repeat` and `raw = false` (sRGB decoded) does the same, with v = 0 the *top* row,
# so the script hands Mitsuba (u, 1 - v). What cannot be matched exactly: the JPEG decoders
# (Mitsuba's libjpeg against the `image` crate's) may round chroma upsampling differently, and a
# texel boundary may fall one texel apart where `1 - v` rounds; both move means by far less than
# the noise of a 64-spp Sponza.
MTL_MAPPING = (
    "Kd -> twosided(diffuse(reflectance = Kd)); map_Kd -> twosided(diffuse(reflectance = bitmap(nearest, "
    "repeat, sRGB-decoded, uv = (u, 1 - v)))), Kd ignored, as tessera does; Ke > 0 -> one-sided area "
    "emitter (radiance = Ke) on the same mesh; Ns/Ni/Ka/illum/bump unused (Ks below Kd everywhere); no "
    "vertex normals in these OBJs, so both renderers shade with face normals; [environment] radiance -> "
    "constant emitter"
)

# How the script maps tessera's media onto Mitsuba (scenes/README.md, "Participating media"): a
# `[media.NAME]` table becomes a `homogeneous` medium with `sigma_t = sigma_a + sigma_s`,
# `albedo = sigma_s / sigma_t` (RGB) and an `hg` phase function of the same `g` (both renderers
# take g > 0 as forward scattering); a sphere whose material is `interface` becomes Mitsuba's
# analytic `sphere` with a `null` BSDF and that medium as `interior`, `glass` a `dielectric`
# (int_ior = ior, ext_ior = outside_ior, 1 when left out: both renderers refract by their ratio);
# its `outside_medium` (the camera's medium when left out, as in tessera) becomes the sphere's
# `exterior`, so media nest alike in both renderers (`scenes/shared/cornell-box-nested.toml`).
# Our sphere is an icosphere (20,480 faces at subdivisions 5, 0.03 % less area than the sphere),
# Mitsuba's the exact sphere. `[camera] medium` (global fog)
# becomes the sensor's `medium`: both renderers start camera rays in it, and since the meshes
# name no media, a ray that reflects stays in it (Mitsuba changes a ray's medium only at shapes
# with an interior or exterior medium, tessera only at glass and interfaces).
MEDIA_MAPPING = (
    "[media] -> homogeneous(sigma_t = sigma_a + sigma_s, albedo = sigma_s / sigma_t, phase hg(g)); "
    "sphere with interface -> sphere(null BSDF, interior = medium, exterior = outside_medium or the camera's); "
    "with glass -> sphere(dielectric(int_ior = ior, ext_ior = outside_ior), interior, exterior); "
    "[camera] medium -> the sensor's medium"
)

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
        help="runs of each renderer on each scene, alternated scene by scene (Mitsuba, then tessera); the "
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
    parser.add_argument("--worker", nargs=3, metavar=("VARIANT", "TOML", "EXR"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        variant, toml, exr = args.worker
        print(json.dumps(render_mitsuba(variant, Path(toml), Path(exr), args.size, args.spp, args.segments,
                                        args.integrator, args.mitsuba_lanes)))
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
    # Every run, scene by scene, Mitsuba's variants then ours, so that a disturbance of the
    # machine falls on both renderers alike; both are deterministic, so each repeat writes the
    # same images over the last.
    mitsuba_runs = {}
    our_runs = {}
    for _ in range(args.repeats):
        for toml in present:
            for variant in variants:
                exr = args.out / f"mitsuba-{variant}" / f"{toml.stem}.exr"
                exr.parent.mkdir(parents=True, exist_ok=True)
                result = run_worker(variant, toml, exr, args)
                mitsuba_runs.setdefault((variant, toml.stem), []).append(result)
                print(f"mitsuba {variant} {toml.stem}: {describe(result)}", file=sys.stderr)
            our_runs.setdefault(str(toml), []).append(run_tessera([toml], args)[str(toml)])
    rows = []
    for toml in present:
        our = fastest(our_runs[str(toml)])
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
            rows.append(row)
    report = {
        "settings": {"size": args.size, "spp": args.spp, "segments": args.segments, "tessera_max_depth": args.segments - 1,
                     "tolerance": args.tolerance, "mitsuba_integrator": args.integrator, "repeats": args.repeats},
        "mtl_mapping": MTL_MAPPING,
        "media_mapping": MEDIA_MAPPING,
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


def run_worker(variant, toml, exr, args):
    command = [sys.executable, __file__, "--worker", variant, str(toml), str(exr)]
    command += ["--size", str(args.size), "--spp", str(args.spp), "--segments", str(args.segments)]
    command += ["--integrator", args.integrator]
    if args.mitsuba_lanes:
        command += ["--mitsuba-lanes", str(args.mitsuba_lanes)]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        return {"error": done.stderr.strip().splitlines()[-1] if done.stderr.strip() else f"exit {done.returncode}"}
    return json.loads(done.stdout.strip().splitlines()[-1])


def run_tessera(tomls, args):
    """One `tessera bench` over every scene: its JSON has our timings and the EXR paths."""
    out = args.out / "tessera"
    command = [args.tessera, "bench", *map(str, tomls), "--spp", str(args.spp), "--width", str(args.size)]
    command += ["--height", str(args.size), "--max-depth", str(args.segments - 1), "--out", str(out), "--json"]
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
            "mrays_per_second": paths["rays_per_second"] / 1e6,
            "image": s["image"],
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
    }


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
        f"{fmt_load(report['load_after'])} after.",
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
            f"{fmt_means(c['mean_mitsuba'])} | {diff} ({verdict} {tolerance}; RMSE {c['rmse']:.4f}) |"
        )
    if s.get("repeats", 1) > 1:
        lines += ["", f"Each renderer's fastest of {s['repeats']} runs, alternated scene by scene; every run's CPU-s:", ""]
        for row in report["rows"]:
            if "error" in row["mitsuba"]:
                continue
            ratio = row["tessera"]["cpu_seconds"] / row["mitsuba"]["cpu_seconds"]
            ours = ", ".join(f"{v:.2f}" for v in row["runs"]["tessera"])
            theirs = ", ".join(f"{v:.2f}" for v in row["runs"]["mitsuba"])
            lines.append(f"- {row['scene']}: tessera {ours}; Mitsuba {row['variant']} {theirs}; fastest against fastest {ratio:.2f}x")
    lines += ["", "MTL mapping: " + report["mtl_mapping"] + ".", "", "Media mapping: " + report["media_mapping"] + ".", ""]
    return "\n".join(lines)


def fmt_means(means):
    return " / ".join(f"{v:.4f}" for v in means) if means else ""


def fmt_load(load):
    return " ".join(f"{v:.2f}" for v in load)


# --- The Mitsuba side, run in a process of its own per (variant, scene). ---


def mitsuba_description(toml, size, spp, segments, integrator="auto"):
    """The Mitsuba scene dictionary of a tessera TOML (MTL_MAPPING, MEDIA_MAPPING) and its
    triangle count; the variant must be set. Shared with scripts/traversal_compare.py."""
    import mitsuba as mi

    scene_toml = tomllib.loads(toml.read_text())
    camera = scene_toml["camera"]
    unsupported = set(camera) - {"position", "look_at", "up", "vfov", "medium"}
    environment = scene_toml.get("environment", {})
    if unsupported or scene_toml.get("lights") or set(environment) - {"radiance"}:
        raise SystemExit(
            f"{toml}: only a fixed camera, plain OBJ objects and a constant environment are translated for Mitsuba"
        )
    media = {name: mitsuba_medium(spec) for name, spec in scene_toml.get("media", {}).items()}
    shapes = {}
    triangles = 0
    for index, obj in enumerate(scene_toml.get("object", [])):
        if obj.get("shape") == "sphere":
            shapes[f"shape-{index}-sphere"] = mitsuba_sphere(
                toml, obj, scene_toml.get("materials", {}), media, camera.get("medium")
            )
            continue
        if set(obj) != {"obj"}:
            raise SystemExit(f"{toml}: object {index} has keys other than obj, which this script does not translate")
        for name, (positions, texcoords, faces, kd, ke, texture) in read_obj(toml.parent / obj["obj"]).items():
            triangles += len(faces) // 3
            props = mi.Properties()
            if texture is not None:
                reflectance = {"type": "bitmap", "filename": str(texture), "filter_type": "nearest",
                               "wrap_mode": "repeat", "raw": False}
            else:
                reflectance = {"type": "rgb", "value": kd}
            props["bsdf"] = mi.load_dict({"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": reflectance}})
            if any(v > 0 for v in ke):
                props["emitter"] = mi.load_dict({"type": "area", "radiance": {"type": "rgb", "value": ke}})
            textured = texcoords is not None
            mesh = mi.Mesh(f"{index}-{name}", len(positions) // 3, len(faces) // 3, props=props,
                           has_vertex_normals=False, has_vertex_texcoords=textured)
            params = mi.traverse(mesh)
            # The buffers' own types: drjit arrays in the llvm variants, scalar arrays in scalar_rgb.
            params["vertex_positions"] = type(params["vertex_positions"])(positions)
            params["faces"] = type(params["faces"])(faces)
            if textured:
                params["vertex_texcoords"] = type(params["vertex_texcoords"])(texcoords)
            params.update()
            shapes[f"shape-{index}-{name}"] = mesh
    description = {
        "type": "scene",
        "integrator": {"type": integrator if integrator != "auto" else "volpath" if media else "path",
                       "max_depth": segments},
        "sensor": {
            "type": "perspective",
            "fov": camera.get("vfov", 40.0),
            "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=camera["position"], target=camera["look_at"], up=camera.get("up", [0, 1, 0])
            ),
            "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"},
                     "pixel_format": "rgb", "component_format": "float32"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        **shapes,
    }
    if "medium" in camera:
        description["sensor"]["medium"] = media[camera["medium"]]
    if "radiance" in environment:
        radiance = environment["radiance"]
        radiance = [float(radiance)] * 3 if isinstance(radiance, (int, float)) else [float(c) for c in radiance]
        description["environment"] = {"type": "constant", "radiance": {"type": "rgb", "value": radiance}}
    return description, triangles


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


def render_mitsuba(variant, toml, exr, size, spp, segments, integrator="auto", lanes=None):
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(variant)
    lanes = llvm_lanes(lanes) if variant.startswith("llvm") else None
    description, triangles = mitsuba_description(toml, size, spp, segments, integrator)
    # Resident memory (KiB) before Mitsuba builds its scene, which holds this script's own
    # Python lists of the OBJ's vertices and faces, and after the scene and the render: the
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


def mitsuba_medium(spec):
    """A `[media.NAME]` table as a Mitsuba `homogeneous` medium (MEDIA_MAPPING)."""
    rgb = lambda v: [float(v)] * 3 if isinstance(v, (int, float)) else [float(c) for c in v]
    if "albedo" in spec:
        albedo, sigma_t = rgb(spec["albedo"]), rgb(spec["density"])
    else:
        sigma_a, sigma_s = rgb(spec.get("sigma_a", 0)), rgb(spec.get("sigma_s", 0))
        sigma_t = [a + s for a, s in zip(sigma_a, sigma_s)]
        albedo = [s / t if t > 0 else 0.0 for s, t in zip(sigma_s, sigma_t)]
    # Mitsuba reads an RGB `sigma_t` as a reflectance, in [0, 1]: it takes the largest channel
    # as its `scale` and the rest relative to it.
    scale = max(sigma_t) or 1.0
    return {
        "type": "homogeneous",
        "scale": scale,
        "sigma_t": {"type": "rgb", "value": [t / scale for t in sigma_t]},
        "albedo": {"type": "rgb", "value": albedo},
        "phase": {"type": "hg", "g": float(spec.get("g", 0.0))},
    }


def mitsuba_sphere(toml, obj, materials, media, camera_medium):
    """A procedural sphere bounded by an `interface` or `glass` material with a medium, and with
    the medium outside it: its `outside_medium`, or the camera's medium when left out (tessera's
    rule; Mitsuba's own default, no exterior, would be vacuum)."""
    import mitsuba as mi

    if set(obj) - {"shape", "center", "radius", "subdivisions", "material"}:
        raise SystemExit(f"{toml}: a sphere with keys this script does not translate: {sorted(obj)}")
    material = materials[obj["material"]]
    if material.get("type") == "interface" and set(material) <= {"type", "medium", "outside_medium"}:
        bsdf = {"type": "null"}
    elif material.get("type") == "glass" and set(material) <= {"type", "ior", "outside_ior", "medium", "outside_medium"}:
        bsdf = {
            "type": "dielectric",
            "int_ior": float(material.get("ior", 1.5)),
            "ext_ior": float(material.get("outside_ior", 1.0)),
        }
    else:
        raise SystemExit(f"{toml}: sphere material {obj['material']} is neither a plain interface nor a plain glass")
    sphere = {
        "type": "sphere",
        "to_world": mi.ScalarTransform4f().translate(obj.get("center", [0, 0, 0])).scale(float(obj.get("radius", 1.0))),
        "bsdf": bsdf,
    }
    if "medium" in material:
        sphere["interior"] = mi.load_dict(media[material["medium"]])
    outside = material.get("outside_medium", camera_medium)
    if outside is not None:
        sphere["exterior"] = mi.load_dict(media[outside])
    return mi.load_dict(sphere)


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


def read_obj(path):
    """Triangles per `usemtl` material: {name: (flat positions, flat uvs or None, flat indices, Kd, Ke,
    texture path or None)}.

    Handles what the shared scenes use: CRLF endings, negative (relative) indices, `v/vt/vn`
    references, and polygons, which are cut into fans as tessera's loader cuts them. A vertex is
    a (position, texture coordinate) pair, as in tessera's loader (tobj's single index), so that
    faces meeting at a position with different `vt` keep their own; texture coordinates are kept
    for a material only when it has a texture and every corner of its faces has one.
    """
    vertices = []
    uvs = []
    groups = {}
    material = None
    materials = {}
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            words = line.split()
            if not words:
                continue
            if words[0] == "v":
                vertices.append((float(words[1]), float(words[2]), float(words[3])))
            elif words[0] == "vt":
                # `vt u [v [w]]`: a missing v is 0, as tessera reads it.
                uvs.append((float(words[1]), float(words[2]) if len(words) > 2 else 0.0))
            elif words[0] == "f":
                corners = [w.split("/") for w in words[1:]]
                resolve = lambda i, count: i - 1 if i > 0 else count + i
                ids = [
                    (resolve(int(c[0]), len(vertices)), resolve(int(c[1]), len(uvs)) if len(c) > 1 and c[1] else None)
                    for c in corners
                ]
                tris = groups.setdefault(material, [])
                for k in range(1, len(ids) - 1):
                    tris.extend((ids[0], ids[k], ids[k + 1]))
            elif words[0] == "usemtl":
                material = " ".join(words[1:])
            elif words[0] == "mtllib":
                materials.update(read_mtl(path.parent / " ".join(words[1:])))
    meshes = {}
    for name, tris in groups.items():
        if name not in materials:
            raise SystemExit(f"{path}: material {name!r} is not in its MTL files")
        kd, ke, texture = materials[name]
        textured = texture is not None and all(t is not None for _, t in tris)
        # Each material's mesh keeps only the vertices it uses.
        remap = {}
        positions = []
        texcoords = [] if textured else None
        faces = []
        for i, t in tris:
            key = (i, t) if textured else i
            j = remap.get(key)
            if j is None:
                j = remap[key] = len(remap)
                positions.extend(vertices[i])
                if textured:
                    u, v = uvs[t]
                    # Mitsuba's bitmap has v = 0 at the top row, tessera's at the bottom.
                    texcoords.extend((u, 1.0 - v))
            faces.append(j)
        meshes[name] = (positions, texcoords, faces, kd, ke, texture if textured else None)
    return meshes


def read_mtl(path):
    """{name: (Kd, Ke, map_Kd path or None)}; the texture's file name is matched ignoring ASCII case
    when it does not exist as written, as tessera's loader matches it (Sponza's MTL says
    `00_SKAP.JPG` for `00_skap.JPG`)."""
    materials = {}
    name = None
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            words = line.split("#")[0].split()
            if not words:
                continue
            if words[0] == "newmtl":
                name = " ".join(words[1:])
                materials[name] = [[0.8, 0.8, 0.8], [0.0, 0.0, 0.0], None]
            elif words[0] in ("Kd", "Ke") and name is not None:
                values = [float(w) for w in words[1:4]]
                values = values * 3 if len(values) == 1 else values
                materials[name][0 if words[0] == "Kd" else 1] = values
            elif words[0] == "map_Kd" and name is not None:
                # With leading `-options` tessera takes the last word; `\` is read as `/`.
                file = (words[-1] if words[1].startswith("-") else " ".join(words[1:])).replace("\\", "/")
                materials[name][2] = find_ignoring_case(path.parent / file)
    return {k: tuple(v) for k, v in materials.items()}


def find_ignoring_case(path):
    if path.exists():
        return path
    matches = [p for p in path.parent.iterdir() if p.name.lower() == path.name.lower()]
    if not matches:
        raise SystemExit(f"{path}: texture not found")
    return sorted(matches)[0]


if __name__ == "__main__":
    main()
