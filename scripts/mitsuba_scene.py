#!/usr/bin/env python3
"""A tessera scene as a Mitsuba 3 scene: what `scripts/mitsuba_compare.py` renders with Mitsuba and
`scripts/traversal_compare.py` traces with Embree through it.

Why a module of its own: the translation is the comparisons' one account of how tessera's scene
format maps onto Mitsuba's plugins (MTL_MAPPING, MEDIA_MAPPING, EFFECTS_MAPPING below); both
scripts build their Mitsuba scenes through `mitsuba_description` here, and neither repeats it.

What is translated: a fixed camera (a pinhole, or a thin lens), still objects with diffuse
materials (textured or not, emitting or not), procedural spheres bounding media, global fog, and
the environment (a constant radiance, or a lat-long map with its `scale` and `rotate`). Anything
else is refused with a message naming it, rather than rendered differently.

The geometry is never read here: `tessera meshes` writes the triangles tessera's loader made
(its OBJ reading, its spheres' tessellation and normals, its transforms) and the materials it
resolved, and `mitsuba_shapes` hands exactly those to Mitsuba, so a second loader in this script
cannot drift from the first.
"""

import json
import math
import tempfile
import tomllib
from pathlib import Path

# Each texel of an environment map repeated this many times along both axes for Mitsuba
# (EFFECTS_MAPPING): the band where its bilinear lookup and tessera's nearest one differ shrinks
# to 1 / ENVMAP_REPEAT of a texel.
ENVMAP_REPEAT = 32

# How the script maps materials onto Mitsuba. Mitsuba's own OBJ loader ignores MTL files
# entirely, so the mapping is ours, from what tessera resolved (`tessera meshes`' index, after
# its MTL rules, scenes/README.md, "MTL"): every material of the shared Cornell scenes is
# `illum 2` with `Ks 0`, which tessera reads as diffuse with reflectance Kd. Mitsuba's `diffuse`
# is black from behind, tessera's reflection-only BSDFs are two-sided, so the diffuse goes in a
# `twosided` wrapper. `Ke` > 0 adds an `area`
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
    "emitter (radiance = Ke) on the same mesh; Ns/Ni/Ka/illum/bump unused (Ks below Kd everywhere); "
    "an OBJ's vertex normals, where tessera keeps them, are the mesh's in both (the shared OBJs have "
    "none but the water and sphere variants'); [environment] radiance -> constant emitter"
)

# How the script maps tessera's media onto Mitsuba (scenes/README.md, "Participating media"): a
# `[media.NAME]` table becomes a `homogeneous` medium with `sigma_t = sigma_a + sigma_s`,
# `albedo = sigma_s / sigma_t` (RGB) and an `hg` phase function of the same `g` (both renderers
# take g > 0 as forward scattering); a sphere whose material is `interface` becomes a mesh of
# tessera's own triangles with a `null` BSDF and that medium as `interior`, `glass` a `dielectric`
# (int_ior = ior, ext_ior = outside_ior, 1 when left out: both renderers refract by their ratio);
# its `outside_medium` (the camera's medium when left out, as in tessera) becomes the sphere's
# `exterior`, so media nest alike in both renderers (`scenes/shared/cornell-box-nested.toml`).
# The sphere is tessera's icosphere in both (20,480 faces at subdivisions 5), with its smooth
# normals. `[camera] medium` (global fog)
# becomes the sensor's `medium`: both renderers start camera rays in it, and since the meshes
# name no media, a ray that reflects stays in it (Mitsuba changes a ray's medium only at shapes
# with an interior or exterior medium, tessera only at glass and interfaces).
MEDIA_MAPPING = (
    "[media] -> homogeneous(sigma_t = sigma_a + sigma_s, albedo = sigma_s / sigma_t, phase hg(g)); "
    "sphere -> a mesh of tessera's own triangles and normals (`tessera meshes`), with interface -> "
    "null BSDF, interior = medium, exterior = outside_medium or the camera's; "
    "with glass -> dielectric(int_ior = ior, ext_ior = outside_ior), interior, exterior; "
    "[camera] medium -> the sensor's medium"
)

# How the script maps the effects of issue 16 that Mitsuba checks (scenes/README.md, "Depth of
# field", "Environment maps"). A camera with `aperture_radius` above 0 becomes Mitsuba's
# `thinlens` (pbrt's thin lens, as ours: the lens point uniform on the disk, the ray aimed where
# the pinhole ray through the same image point meets the focus plane), focused at our
# `focus_distance` or, left out, at `look_at`'s distance, as tessera focuses. A lat-long map
# becomes an `envmap` of the same texels, mirrored left to right (mitsuba_environment says why),
# times our `scale` (which may be RGB, Mitsuba's only a number), each texel repeated
# ENVMAP_REPEAT times each way (Mitsuba's lookup is bilinear, ours nearest), turned about +y by
# our `rotate`. Portals are dropped: they only guide our sampling, the image they converge to is
# the same. An OBJ object's `material` (a plain diffuse) is the two-sided diffuse of the faces
# before any `usemtl`, as tessera applies it.
EFFECTS_MAPPING = (
    "aperture_radius > 0 -> thinlens(aperture_radius, focus_distance, or look_at's distance); map -> "
    f"envmap(texels mirrored left to right, times scale, each repeated {ENVMAP_REPEAT}x{ENVMAP_REPEAT}, "
    "to_world = rotate(+y, rotate)); portals dropped (sampling only); [[object]] material (plain diffuse) "
    "-> twosided(diffuse(albedo)) for faces before any usemtl"
)


def mitsuba_description(toml, size, spp, segments, integrator="auto", seed=0, roulette_depth=None,
                        tessera="target/release/tessera"):
    """The Mitsuba scene dictionary of a tessera TOML (MTL_MAPPING, MEDIA_MAPPING,
    EFFECTS_MAPPING) and its triangle count; the variant must be set. `seed` is the sampler's;
    `roulette_depth` the depth from which Russian roulette may end paths, as tessera counts it
    (scattering events; `None`: off), which is Mitsuba's `rr_depth` too (both count the events
    before the roulette, both survive with the throughput's largest channel, at most 0.95).
    `tessera` is the binary whose loader gives the triangles (`mitsuba_shapes`)."""
    import mitsuba as mi

    scene_toml = tomllib.loads(toml.read_text())
    camera = scene_toml["camera"]
    unsupported = set(camera) - {"position", "look_at", "up", "vfov", "medium", "aperture_radius", "focus_distance"}
    environment = scene_toml.get("environment", {})
    if unsupported or scene_toml.get("lights") or set(environment) - {"radiance", "map", "scale", "rotate", "portals"}:
        raise SystemExit(
            f"{toml}: only a fixed camera, OBJ objects and an environment (constant or a map) are translated for Mitsuba"
        )
    media = {name: mitsuba_medium(spec) for name, spec in scene_toml.get("media", {}).items()}
    shapes, triangles = mitsuba_shapes(toml, tessera, scene_toml, media, camera.get("medium"))
    description = {
        "type": "scene",
        "integrator": {"type": integrator if integrator != "auto" else "volpath" if media else "path",
                       "max_depth": segments,
                       # Off: a depth no path reaches (a path has fewer than `segments` events).
                       "rr_depth": segments if roulette_depth is None else roulette_depth},
        "sensor": mitsuba_sensor(camera, size, spp, seed),
        **shapes,
    }
    if "medium" in camera:
        description["sensor"]["medium"] = media[camera["medium"]]
    emitter = mitsuba_environment(toml, environment)
    if emitter is not None:
        description["environment"] = emitter
    return description, triangles


def mitsuba_sensor(camera, size, spp, seed=0):
    """The camera as a Mitsuba sensor: `perspective`, or `thinlens` where the aperture is open
    (EFFECTS_MAPPING), with a box-filtered film of `size` squared and `spp` independent samples
    seeded by `seed`."""
    import mitsuba as mi

    position, look_at = camera["position"], camera["look_at"]
    sensor = {
        "type": "perspective",
        "fov": camera.get("vfov", 40.0),
        "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=position, target=look_at, up=camera.get("up", [0, 1, 0])),
        "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"},
                 "pixel_format": "rgb", "component_format": "float32"},
        "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
    }
    aperture = float(camera.get("aperture_radius", 0.0))
    if aperture > 0.0:
        # tessera focuses on `look_at` unless told otherwise (scenes/README.md, "Depth of field").
        focus = float(camera.get("focus_distance", math.dist(position, look_at)))
        sensor.update(type="thinlens", aperture_radius=aperture, focus_distance=focus)
    return sensor


def mitsuba_environment(toml, environment):
    """`[environment]` as a loaded Mitsuba emitter (EFFECTS_MAPPING), or None without one."""
    import mitsuba as mi
    import numpy as np

    if "radiance" in environment:
        return mi.load_dict({"type": "constant", "radiance": {"type": "rgb", "value": rgb(environment["radiance"])}})
    if "map" not in environment:
        return None
    bitmap = mi.Bitmap(str(toml.parent / environment["map"]))
    texels = np.array(bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False))
    # Mirrored left to right: tessera's map looks along +x three quarters across, Mitsuba's a
    # quarter across (its u is atan2(x, -z) / 2 pi); both look along +z in the centre column
    # and along -z at the edges, and both put straight up in the top row.
    texels = texels[:, ::-1, :] * np.array(rgb(environment.get("scale", 1.0)), dtype=np.float32)
    # Mitsuba interpolates a map bilinearly between texel centres; tessera looks texels up
    # nearest. Each texel repeated ENVMAP_REPEAT times along both axes is the same piecewise
    # constant radiance for a nearest lookup, and for a bilinear one the same but within half a
    # repeated texel of the original texels' edges.
    texels = np.repeat(np.repeat(texels, ENVMAP_REPEAT, axis=0), ENVMAP_REPEAT, axis=1)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "environment.exr"
        mi.Bitmap(np.ascontiguousarray(texels)).write(str(path))
        # Loaded here, while the file exists: the plugin reads it when it is made.
        return mi.load_dict({
            "type": "envmap",
            "filename": str(path),
            # tessera turns the map about +y, right-handed, by `rotate` degrees, as this does.
            "to_world": mi.ScalarTransform4f().rotate([0, 1, 0], float(environment.get("rotate", 0.0))),
        })


def rgb(value):
    """A number or `[r, g, b]` of a TOML as three floats."""
    return [float(value)] * 3 if isinstance(value, (int, float)) else [float(c) for c in value]


def mitsuba_medium(spec):
    """A `[media.NAME]` table as a Mitsuba `homogeneous` medium (MEDIA_MAPPING)."""
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


def mitsuba_shapes(toml, tessera, scene_toml, media, camera_medium):
    """Every object of the scene as Mitsuba meshes, and their triangle count. The triangles are
    the ones tessera's loader made (`tessera meshes`: its OBJ reading, its spheres' tessellation
    and normals, its transforms, to the bit), so that the two renderers trace the same geometry
    and this script holds no second loader; the materials as MTL_MAPPING and MEDIA_MAPPING say."""
    import subprocess

    objects = scene_toml.get("object", [])
    with tempfile.TemporaryDirectory() as folder:
        done = subprocess.run([str(tessera), "meshes", str(toml), "--out", folder], capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"{toml}: `tessera meshes` failed: {done.stderr.strip()}")
        index = json.loads((Path(folder) / "meshes.json").read_text())
        # Only moving objects have no file: their triangles are placed per time.
        moving = sorted(set(range(len(objects))) - {entry["object"] for entry in index})
        if moving:
            raise SystemExit(f"{toml}: object {moving[0]} moves, which this script does not translate")
        shapes = {}
        for entry in index:
            obj = objects[entry["object"]]
            if obj.get("shape") == "sphere":
                props = sphere_properties(toml, obj, scene_toml.get("materials", {}), media, camera_medium)
            else:
                props = surface_properties(toml, entry)
            shapes[f"shape-{Path(entry['file']).stem}"] = mitsuba_mesh(Path(folder) / entry["file"], entry, props)
    return shapes, sum(entry["triangles"] for entry in index)


def surface_properties(toml, entry):
    """The Mitsuba BSDF and emitter of a mesh of `tessera meshes` (MTL_MAPPING): only diffuse
    materials are translated, a texture only as the whole reflectance (tessera's albedo 1). Faces
    without texture coordinates read a texture as white in tessera (`scatter.rs`), so theirs is
    the albedo alone."""
    import mitsuba as mi

    material, bsdf = entry["material"], entry["material"]["bsdf"]
    if bsdf["type"] != "diffuse":
        raise SystemExit(f"{toml}: material {material['name']} is {bsdf['type']}, which this script does not translate")
    if bsdf["texture"] is not None and entry["texcoords"]:
        if bsdf["albedo"] != [1.0, 1.0, 1.0]:
            raise SystemExit(f"{toml}: material {material['name']} scales its texture, which this script does not translate")
        reflectance = {"type": "bitmap", "filename": str(toml.parent / bsdf["texture"]), "filter_type": "nearest",
                       "wrap_mode": "repeat", "raw": False}
    else:
        reflectance = {"type": "rgb", "value": bsdf["albedo"]}
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": reflectance}})
    if any(v > 0 for v in material["emission"]):
        props["emitter"] = mi.load_dict({"type": "area", "radiance": {"type": "rgb", "value": material["emission"]}})
    return props


def mitsuba_mesh(path, entry, props):
    """The PLY file `path` of `tessera meshes` (described by its index `entry`) as a Mitsuba mesh
    with `props`; texture coordinates as Mitsuba's bitmap reads them, v = 0 at the top (ours at the
    bottom, so (u, 1 - v)), and kept only where the BSDF has a texture."""
    import mitsuba as mi
    import numpy as np

    data = path.read_bytes()
    body = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:body].decode().splitlines()
    vertices = int(next(line.split()[2] for line in header if line.startswith("element vertex")))
    faces = int(next(line.split()[2] for line in header if line.startswith("element face")))
    names = [line.split()[2] for line in header if line.startswith("property float")]
    table = np.frombuffer(data, dtype="<f4", count=vertices * len(names), offset=body).reshape(vertices, len(names))
    records = np.frombuffer(data, dtype=[("count", "u1"), ("corners", "<u4", 3)], count=faces,
                            offset=body + table.nbytes)
    if np.any(records["count"] != 3):
        raise SystemExit(f"{path}: a face that is not a triangle")
    column = {name: table[:, k] for k, name in enumerate(names)}
    textured = entry["texcoords"] and entry["material"]["bsdf"].get("texture") is not None
    mesh = mi.Mesh(f"{path.stem}-{entry['material']['name']}", vertices, faces, props=props,
                   has_vertex_normals=entry["normals"], has_vertex_texcoords=textured)
    params = mi.traverse(mesh)
    # The buffers' own types: drjit arrays in the llvm variants, scalar arrays in scalar_rgb.
    flat = lambda *columns: np.stack([column[c] for c in columns], axis=1).ravel()
    params["vertex_positions"] = type(params["vertex_positions"])(flat("x", "y", "z"))
    params["faces"] = type(params["faces"])(records["corners"].ravel())
    if entry["normals"]:
        params["vertex_normals"] = type(params["vertex_normals"])(flat("nx", "ny", "nz"))
    if textured:
        column["v"] = 1.0 - column["v"]
        params["vertex_texcoords"] = type(params["vertex_texcoords"])(flat("u", "v"))
    params.update()
    return mesh


def sphere_properties(toml, obj, materials, media, camera_medium):
    """The BSDF and media of a procedural sphere bounded by an `interface` or `glass` material
    with a medium, and with the medium outside it: its `outside_medium`, or the camera's medium
    when left out (tessera's rule; Mitsuba's own default, no exterior, would be vacuum)."""
    import mitsuba as mi

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
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    if "medium" in material:
        props["interior"] = mi.load_dict(media[material["medium"]])
    outside = material.get("outside_medium", camera_medium)
    if outside is not None:
        props["exterior"] = mi.load_dict(media[outside])
    return props
