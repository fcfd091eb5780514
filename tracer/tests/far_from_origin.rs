//! Closed scenes moved far from the world's origin and scaled render as they do at home.
//!
//! Each family has an answer that does not depend on where the scene is: every sample exactly
//! 1.0 where every path must end on the same emitter, or an analytic mean checked within four
//! standard errors (plus the tessellation's own slack). The same scenes rendered with the
//! fixed-ULP offset show that the checks can fail: its offset grows with the coordinates, and
//! from 1e4 or 1e5 radii away it starts rays outside the geometry they leave.

mod exact;

use glam::Vec3;
use tracer::geometry::{Accel, BuildQuality, OffsetMethod};
use tracer::{Effects, Rect, TileOutput, World, render_tile};

fn render(toml: &str, offset: OffsetMethod) -> TileOutput {
    let scene = tracer::scene::load_str(toml).expect("test scene loads");
    let accel = Accel::build(&scene.triangles, BuildQuality::default());
    let effects = Effects::of(&scene);
    let (w, h) = (scene.settings.width, scene.settings.height);
    let mut world = World::new(scene, accel, effects);
    world.offset = offset;
    let out = render_tile(&world, 0, Rect { x: 0, y: 0, w, h });
    assert_eq!(out.stats.invalid_samples, 0, "no sample may be NaN");
    out
}

/// The mean of the first channel and its standard error, from the pixels (independent).
fn mean(out: &TileOutput) -> (f64, f64) {
    let n = out.pixels.len() as f64;
    let sum: f64 = out.pixels.iter().map(|p| f64::from(p[0])).sum();
    let sq: f64 = out.pixels.iter().map(|p| f64::from(p[0]).powi(2)).sum();
    let m = sum / n;
    (m, ((sq / n - m * m).max(0.0) / n).sqrt())
}

/// A camera at `c` looking along +z (at a point `s` away), and the render settings.
fn camera(c: Vec3, s: f32, size: u32, spp: u32, depth: &str, roulette: &str) -> String {
    format!(
        "[render]\nwidth = {size}\nheight = {size}\nspp = {spp}\nmax_depth = {depth}\n\
         russian_roulette_depth = {roulette}\n\
         [camera]\nposition = [{x}, {y}, {z}]\nlook_at = [{x}, {y}, {z1}]\nvfov = 100\n",
        x = c.x,
        y = c.y,
        z = c.z,
        z1 = c.z + s,
    )
}

fn sphere(c: Vec3, radius: f32, extra: &str) -> String {
    format!(
        "[[object]]\nshape = \"sphere\"\ncenter = [{}, {}, {}]\nradius = {radius:e}\n{extra}\n",
        c.x, c.y, c.z
    )
}

/// Where each family is moved to: along a direction that mixes the three axes.
fn place(d: f32) -> Vec3 {
    Vec3::new(1.0, -0.6, 0.3) * d
}

/// Nested glass shells (index 1: every crossing transmits with weight exactly 1) and a thin
/// glass slab, all inside a closed emissive sphere: every path crosses surfaces until it meets
/// the emitter, so every sample is exactly 1.0, unless a ray leaks out between surfaces or is
/// spawned on the wrong side of one.
fn shells(d: f32, s: f32) -> String {
    let c = place(d);
    let slab = (
        c + Vec3::new(-0.4, -0.4, 0.66) * s,
        c + Vec3::new(0.4, 0.4, 0.68) * s,
    );
    let mut toml = camera(c, s, 12, 4, "64", "\"off\"");
    toml += "[materials.light]\ntype = \"emissive\"\nemission = 1\n";
    toml += "[materials.glass]\ntype = \"glass\"\nior = 1\n";
    toml += &sphere(
        c,
        s,
        "subdivisions = 3\ninward = true\nmaterial = \"light\"",
    );
    for (radius, level) in [(0.8, 2), (0.6, 1)] {
        let extra = format!("subdivisions = {level}\nperturb = 0.1\nmaterial = \"glass\"");
        toml += &sphere(c, radius * s, &extra);
    }
    toml += &format!(
        "[[object]]\nshape = \"box\"\nmin = [{}, {}, {}]\nmax = [{}, {}, {}]\nmaterial = \"glass\"\n",
        slab.0.x, slab.0.y, slab.0.z, slab.1.x, slab.1.y, slab.1.z
    );
    toml
}

#[test]
fn nested_shells_and_a_thin_slab_give_exactly_one_at_every_scale_and_distance() {
    for s in [1e-5f32, 1.0, 1e6] {
        for k in [0.0f32, 1e2, 1e3, 1e4, 1e5] {
            let out = render(&shells(k * s, s), OffsetMethod::ErrorBound);
            assert!(out.stats.refractions > 0, "the rays cross the shells");
            let wrong = out.pixels.iter().filter(|p| p[0] != 1.0).count();
            assert_eq!(wrong, 0, "scale {s}, {k} radii away: {wrong} pixels not 1");
        }
    }
    // 256 ULPs of 1e5 are 2 radii: rays leaving the inner shells start outside the emitter.
    let fixed = render(&shells(1e5, 1.0), OffsetMethod::FixedUlp);
    assert!(
        fixed.pixels.iter().any(|p| p[0] != 1.0),
        "the check can fail"
    );
}

/// `scenes/point-in-sphere` with one bounce, moved by `(d, 0, 0)` as in issue 13: a point
/// light of intensity pi at the centre of a diffuse (0.5) unit sphere gives radiance 0.5
/// everywhere on a true sphere.
fn point_in_sphere(d: f32) -> String {
    let c = Vec3::X * d;
    let mut toml = camera(c, 1.0, 24, 4, "1", "3");
    toml += "[materials.inside]\ntype = \"diffuse\"\nalbedo = 0.5\n";
    toml += &sphere(
        c,
        1.0,
        "subdivisions = 5\ninward = true\nmaterial = \"inside\"",
    );
    toml += &format!(
        "[[light]]\ntype = \"point\"\nposition = [{}, {}, {}]\nintensity = 3.14159265\n",
        c.x, c.y, c.z
    );
    toml
}

#[test]
fn a_point_in_a_sphere_far_away_keeps_its_analytic_radiance() {
    for d in [0.0, 1e2, 1e3, 1e4, 1e5] {
        let (m, se) = mean(&render(&point_in_sphere(d), OffsetMethod::ErrorBound));
        // The facets' irradiance spans 0.9997 to 1.0006 of a true sphere's; far away the
        // vertices round by half an ULP too (0.004 of the radius at 1e5), which moves it more.
        let ulp = (d.max(1.0) * f32::EPSILON) as f64;
        let tolerance = 4.0 * se + 0.5 * (1e-3 + 4.0 * ulp);
        assert!((m - 0.5).abs() <= tolerance, "d = {d}: {m} (se {se})");
    }
    let (m, _) = mean(&render(&point_in_sphere(1e5), OffsetMethod::FixedUlp));
    assert!(m < 0.45, "the fixed-ULP offset loses the light at 1e5: {m}");
}

/// An inward, closed, diffuse furnace of radius 1 (albedo 0.5, emission 0.5, unlimited depth)
/// moved by `(d, 0, 0)`: radiance exactly 1 in expectation for any closed shape whose every
/// facet faces the inside. `perturb` moves vertices radially, which makes creases sharp.
fn furnace(d: f32, perturb: f32) -> String {
    let c = Vec3::X * d;
    let mut toml = camera(c, 1.0, 16, 8, "\"unlimited\"", "3");
    toml += "[materials.f]\ntype = \"diffuse\"\nalbedo = 0.5\nemission = 0.5\n";
    let extra = format!("subdivisions = 3\ninward = true\nperturb = {perturb}\nseed = 1");
    toml += &sphere(
        c,
        1.0,
        &format!("{extra}\nsmooth = false\nmaterial = \"f\""),
    );
    toml
}

/// Renders the furnace at each distance until rounding folds a facet over (its emitting side
/// facing out: no longer a furnace); returns the last distance that held.
fn furnace_family(perturb: f32, distances: &[f32]) -> f32 {
    let mut reached = 0.0;
    for &d in distances {
        let scene = tracer::scene::load_str(&furnace(d, perturb)).expect("the furnace loads");
        let v: Vec<_> = scene.triangles.iter().map(|t| t.p).collect();
        if !exact::faces_centre(&v, Vec3::X * d, true) {
            break;
        }
        reached = d;
        let (m, se) = mean(&render(&furnace(d, perturb), OffsetMethod::ErrorBound));
        assert!(
            (m - 1.0).abs() <= 4.0 * se,
            "perturb {perturb}, d = {d}: {m} (se {se})"
        );
    }
    reached
}

#[test]
fn a_furnace_far_away_gives_one_while_its_facets_are_large_beside_an_ulp() {
    // A computed hit point lies within its error bound of its plane, but may also lie that far
    // beyond an edge of its triangle, and near a crease sharper than 45 degrees no offset along
    // the normal keeps such a point inside the neighbour's plane. So rays leak at a rate that
    // grows with the ULP beside the facets (0.13 of the radius here): on the perturbed sphere
    // 2e-4 of bounces at 1e4, 2e-3 at 1e5 and 1e-2 at 3e5 (measured), where the mean falls to
    // 0.94; the plain sphere moved along x, whose vertices then round on x alone into sharp
    // steps, gives 0.975 at 3e5. Up to 1e5 radii both hold within four standard errors of
    // this small render (about 0.007); a larger one shows the perturbed sphere's loss there,
    // 0.990 +- 0.0015 (scenes/README.md).
    let distances = [0.0, 1e2, 1e3, 1e4, 1e5];
    for perturb in [0.0, 0.1] {
        assert_eq!(
            furnace_family(perturb, &distances),
            1e5,
            "perturb {perturb} folds"
        );
    }
    let (m, se) = mean(&render(&furnace(1e5, 0.1), OffsetMethod::FixedUlp));
    assert!(
        m < 1.0 - 4.0 * se,
        "the fixed-ULP offset loses light at 1e5: {m}"
    );
}

#[test]
fn the_loader_flags_objects_past_the_ratio_f32_keeps_closed() {
    let too_far = |d: f32| {
        let mut files = tracer::scene::MemoryFiles::new();
        files.insert("scene.toml", furnace(d, 0.0));
        let (_, report) = tracer::scene::load_with_report(&files, "scene.toml").unwrap();
        report.objects[0].too_far
    };
    // The facets' longest edges are about 0.15: 1e5 away is 7e5 of them, 3e5 away 2e6, past
    // the 2^20 where the furnace above stops holding.
    assert_eq!((too_far(0.0), too_far(1e5)), (None, None));
    let ratio = too_far(3e5).expect("3e5 radii away is past the limit");
    assert!(ratio > 1 << 20 && ratio < 4_000_000, "{ratio}");
}

#[test]
fn no_shipped_scene_is_past_the_limit() {
    let scenes = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes");
    for name in [
        "cornell-box",
        "furnace",
        "point-in-sphere",
        "glass-cluster-pan",
        "prism",
    ] {
        let files = tracer::scene::DiskFiles {
            root: std::path::Path::new(scenes).join(name),
        };
        let toml = format!("{name}.toml");
        let (_, report) = tracer::scene::load_with_report(&files, &toml).expect("shipped scene");
        for object in &report.objects {
            assert_eq!(object.too_far, None, "{name}: {}", object.source);
        }
    }
}
