#!/usr/bin/env python3
"""A tessera scene as a Mitsuba 3 scene: what `scripts/mitsuba_compare.py` renders with Mitsuba and
`scripts/traversal_compare.py` traces with Embree through it.

Why a module of its own: the translation is the comparisons' one account of how tessera's scene
format maps onto Mitsuba's plugins (MTL_MAPPING, MEDIA_MAPPING, EFFECTS_MAPPING below); both
scripts build their Mitsuba scenes through `mitsuba_description` here, and neither repeats it.

What is translated: a fixed camera (a pinhole, or a thin lens), OBJ objects with their MTL
materials or one diffuse `material` of the TOML's, procedural spheres bounding media, global
fog, and the environment (a constant radiance, or a lat-long map with its `scale` and `rotate`).
Anything else is refused with a message naming it, rather than rendered differently.
"""

import math
import tempfile
import tomllib
from pathlib import Path

# Each texel of an environment map repeated this many times along both axes for Mitsuba
# (EFFECTS_MAPPING): the band where its bilinear lookup and tessera's nearest one differ shrinks
# to 1 / ENVMAP_REPEAT of a texel.
ENVMAP_REPEAT = 32

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
    "sphere -> a mesh of tessera's own icosphere (20 * 4^subdivisions triangles, radial normals), with interface -> "
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


def mitsuba_description(toml, size, spp, segments, integrator="auto", seed=0, roulette_depth=None):
    """The Mitsuba scene dictionary of a tessera TOML (MTL_MAPPING, MEDIA_MAPPING,
    EFFECTS_MAPPING) and its triangle count; the variant must be set. `seed` is the sampler's;
    `roulette_depth` the depth from which Russian roulette may end paths, as tessera counts it
    (scattering events; `None`: off), which is Mitsuba's `rr_depth` too (both count the events
    before the roulette, both survive with the throughput's largest channel, at most 0.95)."""
    import mitsuba as mi

    scene_toml = tomllib.loads(toml.read_text())
    camera = scene_toml["camera"]
    unsupported = set(camera) - {"position", "look_at", "up", "vfov", "medium", "aperture_radius", "focus_distance"}
    environment = scene_toml.get("environment", {})
    if unsupported or scene_toml.get("lights") or set(environment) - {"radiance", "map", "scale", "rotate", "portals"}:
        raise SystemExit(
            f"{toml}: only a fixed camera, OBJ objects and an environment (constant or a map) are translated for Mitsuba"
        )
    materials = scene_toml.get("materials", {})
    media = {name: mitsuba_medium(spec) for name, spec in scene_toml.get("media", {}).items()}
    shapes = {}
    triangles = 0
    for index, obj in enumerate(scene_toml.get("object", [])):
        if obj.get("shape") == "sphere":
            shapes[f"shape-{index}-sphere"] = mitsuba_sphere(toml, obj, materials, media, camera.get("medium"))
            continue
        if set(obj) - {"obj", "material"}:
            raise SystemExit(f"{toml}: object {index} has keys other than obj and material, which this script does not translate")
        default = diffuse_material(toml, materials, obj["material"]) if "material" in obj else None
        for name, (positions, texcoords, faces, kd, ke, texture) in read_obj(toml.parent / obj["obj"], default).items():
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


def diffuse_material(toml, materials, name):
    """An object's `material` (what tessera gives an OBJ's faces before any `usemtl`) as the
    (Kd, Ke, texture) of `read_obj`: only a plain `diffuse` with an `albedo` is translated."""
    material = materials.get(name, {})
    if material.get("type") != "diffuse" or set(material) - {"type", "albedo"}:
        raise SystemExit(f"{toml}: material {name} is not a plain diffuse (type and albedo), which this script translates")
    return (rgb(material.get("albedo", 0.5)), [0.0, 0.0, 0.0], None)


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


def mitsuba_sphere(toml, obj, materials, media, camera_medium):
    """A procedural sphere bounded by an `interface` or `glass` material with a medium, and with
    the medium outside it: its `outside_medium`, or the camera's medium when left out (tessera's
    rule; Mitsuba's own default, no exterior, would be vacuum); as a mesh of tessera's own
    triangles (`icosphere`)."""
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
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    if "medium" in material:
        props["interior"] = mi.load_dict(media[material["medium"]])
    outside = material.get("outside_medium", camera_medium)
    if outside is not None:
        props["exterior"] = mi.load_dict(media[outside])
    # The triangles tessera traces (scenes/README.md, `shape = "sphere"`), not Mitsuba's
    # analytic sphere: a speed comparison must give both renderers the same geometry to trace.
    positions, normals, faces = icosphere(
        obj.get("center", [0, 0, 0]), float(obj.get("radius", 1.0)), int(obj.get("subdivisions", 3))
    )
    mesh = mi.Mesh(f"sphere-{obj['material']}", len(positions) // 3, len(faces) // 3, props=props,
                   has_vertex_normals=True, has_vertex_texcoords=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = type(params["vertex_positions"])(positions)
    params["vertex_normals"] = type(params["vertex_normals"])(normals)
    params["faces"] = type(params["faces"])(faces)
    params.update()
    return mesh


def icosphere(center, radius, subdivisions):
    """The sphere tessera tessellates (`tracer/src/scene/shapes.rs`): the icosahedron with every
    triangle split in four `subdivisions` times and its vertices put on the sphere, wound with
    the outside in front, with smooth normals (tessera's default, `smooth = true`; here the
    radial direction, which tessera's area-weighted average approaches). Flat lists of
    positions, normals and vertex indices."""
    import numpy as np

    t = (1.0 + 5.0**0.5) / 2.0
    vertices = [np.array(v) / np.linalg.norm(v) for v in (
        (-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
        (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1))]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        midpoints = {}

        def midpoint(a, b):
            key = (min(a, b), max(a, b))
            if key not in midpoints:
                m = vertices[a] + vertices[b]
                vertices.append(m / np.linalg.norm(m))
                midpoints[key] = len(vertices) - 1
            return midpoints[key]

        next_faces = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            next_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = next_faces
    unit = np.array(vertices)
    positions = np.asarray(center, dtype=float) + radius * unit
    return (positions.astype(np.float32).ravel().tolist(), unit.astype(np.float32).ravel().tolist(),
            np.array(faces, dtype=np.uint32).ravel().tolist())


def read_obj(path, default=None):
    """Triangles per `usemtl` material: {name: (flat positions, flat uvs or None, flat indices, Kd, Ke,
    texture path or None)}; faces before any `usemtl` under the name None, with `default`'s (Kd,
    Ke, texture), the object's own `material` (without one such faces are refused, as tessera
    refuses them).

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
    materials = {} if default is None else {None: default}
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

