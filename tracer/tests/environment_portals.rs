//! Portals (`[environment] portals`): the sampling of directions through a rectangle against
//! the closed form of a rectangle's solid angle (not the sampler's own), over rectangles of every
//! size, seen from near and far, off-centre and far from the origin; renders of a room lit
//! through its window with portals right, half right and wrong, which must all have the same
//! mean as the render without them (every strategy is unbiased), and less noise when right; and
//! the loader's refusals.

mod common;

use common::{assert_refused, exr_bytes, load_with, render_with};
use glam::Vec3;
use tracer::environment::{MIN_SOLID_ANGLE, Portal, PortalSampler};
use tracer::lights::EnvironmentSampling;

/// The solid angle of the rectangle `[x0, x1] x [y0, y1]` in the plane at distance `z > 0`
/// from the viewer, by the closed form of the corner rectangles' solid angles,
/// `atan(x y / (z sqrt(x^2 + y^2 + z^2)))`, added and taken away.
fn closed_form(x0: f64, x1: f64, y0: f64, y1: f64, z: f64) -> f64 {
    let f = |x: f64, y: f64| (x * y / (z * (x * x + y * y + z * z).sqrt())).atan();
    f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0)
}

/// A deterministic stream in [0, 1).
struct Stream(u64);

impl Stream {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A portal in the plane z = `offset.z` with one corner at `offset`, `a` by `b`, and viewers
/// at height `h` above it at `(sx, sy)` in units of the sides (inside, on an edge's line and
/// outside the rectangle's shadow), on both sides of the plane.
#[test]
fn solid_angles_and_samples_match_the_closed_form_at_every_scale_and_distance() {
    let mut stream = Stream(3);
    let mut checked = 0;
    for size in [1e-3f32, 0.25, 1.0, 48.0, 1e4] {
        for offset in [
            Vec3::ZERO,
            Vec3::new(1024.0, -512.0, 4096.0),
            Vec3::splat(-65536.0),
        ] {
            let (a, b) = (size, size * 0.75);
            let corner = offset;
            let portal = Portal {
                corner,
                edge_u: Vec3::new(a, 0.0, 0.0),
                edge_v: Vec3::new(0.0, b, 0.0),
            };
            let sampler = PortalSampler::new(&portal);
            for h_ratio in [1e-2f32, 0.3, 1.0, 7.0, 300.0] {
                for (sx, sy) in [(0.5f32, 0.5f32), (0.0, 0.3), (1.7, -0.4), (-3.0, 2.0)] {
                    for side in [1.0f32, -1.0] {
                        let p = corner + Vec3::new(sx * a, sy * b, side * h_ratio * size);
                        // The exact geometry in f64 from the f32 values the sampler got.
                        let (px, py, pz) = (p.x as f64, p.y as f64, p.z as f64);
                        let x0 = corner.x as f64 - px;
                        let x1 = x0 + a as f64;
                        let y0 = corner.y as f64 - py;
                        let y1 = y0 + b as f64;
                        let z = (pz - corner.z as f64).abs();
                        if z == 0.0 {
                            continue;
                        }
                        let exact = closed_form(x0, x1, y0, y1, z);
                        let got = sampler.solid_angle(p);
                        if exact < 2.0 * MIN_SOLID_ANGLE {
                            continue;
                        }
                        let relative = (got - exact).abs() / exact;
                        assert!(
                            relative < 1e-4,
                            "size {size}, offset {offset}, h {h_ratio}, at ({sx}, {sy}): \
                             {got} against {exact}"
                        );
                        check_samples(&sampler, p, (x0, x1, y0, y1, z), exact, &mut stream);
                        checked += 1;
                    }
                }
            }
        }
    }
    assert!(checked > 400, "only {checked} viewpoints checked");
}

/// Samples from `p` all cross the rectangle with density one over its solid angle, and fall in
/// each of its four quarters as often as that quarter's share of the solid angle says (within
/// five standard deviations).
fn check_samples(
    sampler: &PortalSampler,
    p: Vec3,
    (x0, x1, y0, y1, z): (f64, f64, f64, f64, f64),
    solid_angle: f64,
    stream: &mut Stream,
) {
    let n = 400;
    let (xm, ym) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let mut counts = [0u32; 4];
    let mut drawn = 0;
    for _ in 0..n {
        let Some((wi, pdf)) = sampler.sample(p, (stream.next(), stream.next())) else {
            continue;
        };
        drawn += 1;
        let expected_pdf = 1.0 / solid_angle;
        assert!(
            (f64::from(pdf) - expected_pdf).abs() <= 1e-4 * expected_pdf,
            "pdf {pdf} against {expected_pdf}"
        );
        assert_eq!(sampler.pdf(p, wi), pdf, "sample and density disagree");
        // Where the direction meets the plane, relative to the viewer.
        let w = wi.as_dvec3();
        let t = z / w.z.abs();
        let (x, y) = (w.x * t, w.y * t);
        counts[usize::from(x >= xm) + 2 * usize::from(y >= ym)] += 1;
    }
    // Rounding may put a sample just off an edge, which is left out; never more than a few.
    assert!(drawn >= n - 2, "only {drawn} of {n} samples drawn");
    let quarters = [
        closed_form(x0, xm, y0, ym, z),
        closed_form(xm, x1, y0, ym, z),
        closed_form(x0, xm, ym, y1, z),
        closed_form(xm, x1, ym, y1, z),
    ];
    for (count, quarter) in counts.iter().zip(quarters) {
        let share = quarter / solid_angle;
        let expected = share * f64::from(drawn);
        let sigma = (f64::from(drawn) * share * (1.0 - share)).sqrt();
        assert!(
            (f64::from(*count) - expected).abs() <= 5.0 * sigma + 1.0,
            "{counts:?} against shares {quarters:?} of {solid_angle}"
        );
    }
}

/// The room of `scenes/fog-window` without its fog, prism or ball: 4 x 3 x 5 m, a window in the
/// left wall (x = 0, y 0.9 to 2.6, z 2.0 to 4.2), lit only through it by `environment`.
fn room(environment: &str) -> String {
    let quad =
        |c: &str| format!("[[object]]\nshape = \"quad\"\ncorners = {c}\nmaterial = \"wall\"\n");
    let walls = [
        "[[0, 0, 0], [0, 0, 5], [4, 0, 5], [4, 0, 0]]",
        "[[0, 3, 0], [4, 3, 0], [4, 3, 5], [0, 3, 5]]",
        "[[0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0]]",
        "[[0, 0, 5], [0, 3, 5], [4, 3, 5], [4, 0, 5]]",
        "[[4, 0, 0], [4, 0, 5], [4, 3, 5], [4, 3, 0]]",
        "[[0, 0, 0], [0, 0.9, 0], [0, 0.9, 5], [0, 0, 5]]",
        "[[0, 2.6, 0], [0, 3, 0], [0, 3, 5], [0, 2.6, 5]]",
        "[[0, 0.9, 0], [0, 2.6, 0], [0, 2.6, 2.0], [0, 0.9, 2.0]]",
        "[[0, 0.9, 4.2], [0, 2.6, 4.2], [0, 2.6, 5], [0, 0.9, 5]]",
    ];
    format!(
        "[render]\nwidth = 12\nheight = 12\nspp = 48\nmax_depth = 3\n\n\
         [camera]\nposition = [3.5, 1.4, 0.3]\nlook_at = [1.0, 0.8, 3.0]\nvfov = 70\n\n\
         [environment]\n{environment}\n\n\
         [materials.wall]\ntype = \"diffuse\"\nalbedo = 0.7\n\n{}",
        walls.map(quad).concat()
    )
}

const WINDOW: &str = "[[0, 0.9, 2.0], [0, 2.6, 2.0], [0, 2.6, 4.2], [0, 0.9, 4.2]]";
const HALF_WINDOW: &str = "[[0, 0.9, 2.0], [0, 1.75, 2.0], [0, 1.75, 4.2], [0, 0.9, 4.2]]";
/// On the right wall, where there is no opening.
const NO_WINDOW: &str = "[[4, 1, 1], [4, 1, 2], [4, 2, 2], [4, 2, 1]]";

/// A sky with a sun low in the left (-x) part of the map, so that it shines in through the
/// window onto the floor: 32 x 16 texels.
fn sky(x: usize, y: usize) -> [f32; 3] {
    if y >= 8 {
        [0.2, 0.2, 0.2]
    } else if (x, y) == (8, 6) {
        [400.0, 380.0, 300.0]
    } else {
        [0.4, 0.6, 1.0 + 0.05 * y as f32]
    }
}

/// The mean of `scene`'s renders with two seeds over every pixel and channel, its standard
/// error, and their noise: the root of half the mean squared difference between the two, per
/// pixel and channel (the image's own structure cancels in the difference, not in a spread).
fn measure(scene: &tracer::scene::Scene, sampling: EnvironmentSampling) -> (f64, f64, f64) {
    let render = |seed: u64| {
        let mut scene = scene.clone();
        scene.settings.seed = seed;
        render_with(&scene, None, 0, sampling).pixels
    };
    let (a, b) = (render(11), render(12));
    let values = 3.0 * a.len() as f64;
    let (mut sum, mut squares) = (0.0, 0.0);
    for (a, b) in a.iter().zip(&b) {
        for c in 0..3 {
            sum += f64::from(a[c]) + f64::from(b[c]);
            squares += f64::from(a[c] - b[c]).powi(2);
        }
    }
    let noise = (squares / (2.0 * values)).sqrt();
    (sum / (2.0 * values), noise / (2.0 * values).sqrt(), noise)
}

#[test]
fn portals_right_half_right_or_wrong_keep_the_mean_and_the_right_one_cuts_the_noise() {
    let exr = exr_bytes(32, 16, sky);
    // An even sky lights the room only through the window, which the portal finds every time:
    // much less noise. Under the sun, most of the noise is its light bounced off the floor,
    // which no light sample finds; the portal must not cost the sun's beam its samples (a
    // one-sample mixture of the two strategies did, 15 % more noise here).
    for (environment, most) in [
        ("radiance = [0.5, 0.7, 1.0]", 0.8),
        ("map = \"sky.exr\"", 1.0),
    ] {
        let scene = |portals: Option<&str>| {
            let extra = portals.map_or(String::new(), |p| format!("\nportals = [{p}]"));
            let toml = room(&format!("{environment}{extra}"));
            load_with(&toml, &[("sky.exr", exr.clone())]).expect("the room loads")
        };
        let without = scene(None);
        let ignored = scene(Some(WINDOW));
        // The portal ignored by the knob is the render without portals, bit for bit.
        let bits = |scene, sampling| {
            let out = render_with(scene, None, 0, sampling);
            out.pixels
                .iter()
                .flat_map(|p| p.map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        assert_eq!(
            bits(&ignored, EnvironmentSampling::WithoutPortals),
            bits(&without, EnvironmentSampling::default()),
            "{environment}"
        );
        let (reference, reference_error, reference_noise) =
            measure(&without, EnvironmentSampling::default());
        for portals in [
            WINDOW,
            HALF_WINDOW,
            NO_WINDOW,
            &format!("{WINDOW}, {NO_WINDOW}"),
        ] {
            let (mean, error, noise) =
                measure(&scene(Some(portals)), EnvironmentSampling::default());
            let tolerance = 4.0 * error.hypot(reference_error);
            assert!(
                (mean - reference).abs() <= tolerance,
                "{environment}, portals {portals}: mean {mean} against {reference} (+- {tolerance})"
            );
            if portals == WINDOW {
                assert!(
                    noise < most * reference_noise,
                    "{environment}: the window's portal left the noise at {noise}, against \
                     {reference_noise}"
                );
            }
        }
    }
}

#[test]
fn portals_that_are_not_rectangles_are_refused_at_their_line() {
    for (portal, says) in [
        (
            "[[0, 0, 0], [1, 0, 0], [1.5, 1, 0], [0, 1, 0]]",
            "fourth corner",
        ),
        (
            "[[0, 0, 0], [1, 0, 0], [1.5, 1, 0], [0.5, 1, 0]]",
            "right angles",
        ),
        ("[[0, 0, 0], [0, 0, 0], [0, 1, 0], [0, 1, 0]]", "no area"),
        (
            "[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]",
            "right angles",
        ),
    ] {
        let toml = room(&format!("radiance = 1\nportals = [{WINDOW}, {portal}]"));
        let line = toml
            .lines()
            .position(|l| l.starts_with("portals"))
            .expect("the room has the key")
            + 1;
        let error = assert_refused(&toml, line, says);
        assert!(error.contains("portal 2"), "{error}");
    }
}
