//! Motion blur: moving edges against the exact blur of linear motion, a spinning square against
//! its closed-form radial profile, determinism, specialisation and the scene format's errors.
//!
//! The moving-edge scenes are emitters only (`max_depth = 0`): a black square in front of a
//! constant sky, so a sample is 0 or 1, and a pixel's expected value is the fraction of its area
//! and of the exposure during which the sky shows there. With the square's image edges moving
//! linearly in time (a translation or a scale of the object, or the camera moving sideways, all
//! seen on a plane facing the camera, which the camera maps affinely), the covered fraction at
//! image position `x` is the length of the interval of times with `l(u) <= x <= r(u)`,
//! integrated here over each pixel: the exact expected image. A blurred edge is a linear ramp as
//! wide as the edge moves, which is also checked by fitting a line to the ramp's interior.

mod common;

use common::render;
use tracer::Effects;
use tracer::scene::load_str;

/// The field of view of the edge scenes: narrow, so that an edge moves many pixels.
const VFOV: f64 = 10.0;

/// Pixels per scene unit on a plane facing the camera at distance `z`, for an image `height`
/// pixels high.
fn pixels_per_unit(z: f64, height: u32) -> f64 {
    f64::from(height) / (2.0 * z * (VFOV / 2.0).to_radians().tan())
}

/// The fraction of times `u` in [0, 1) at which `l0 + u dl <= x <= r0 + u dr`.
fn covered(x: f64, (l0, dl): (f64, f64), (r0, dr): (f64, f64)) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    // The lower edge: u dl <= x - l0.
    if dl > 0.0 {
        hi = hi.min((x - l0) / dl);
    } else if dl < 0.0 {
        lo = lo.max((x - l0) / dl);
    } else if x < l0 {
        return 0.0;
    }
    // The upper edge: u dr >= x - r0.
    if dr > 0.0 {
        lo = lo.max((x - r0) / dr);
    } else if dr < 0.0 {
        hi = hi.min((x - r0) / dr);
    } else if x > r0 {
        return 0.0;
    }
    (hi - lo).max(0.0)
}

/// The exact expected value of pixel `i` along the measured axis (sky 1, square 0): the sky's
/// share of the pixel and the exposure, by the midpoint rule on 512 steps (the integrand is
/// piecewise linear, so that is exact to about 1e-6).
fn expected(i: u32, left: (f64, f64), right: (f64, f64)) -> f64 {
    let n = 512;
    let sum: f64 = (0..n)
        .map(|k| {
            covered(
                f64::from(i) + (f64::from(k) + 0.5) / f64::from(n),
                left,
                right,
            )
        })
        .sum();
    1.0 - sum / f64::from(n)
}

/// The image position of scene coordinate `c` (relative to the camera, along the measured axis,
/// on the plane at distance `z`) in an image `size` pixels long on that axis and `height` high.
fn image_position(c: f64, z: f64, size: u32, height: u32) -> f64 {
    // Image x grows to the camera's right, which is -x for a camera looking down +z with +y
    // up; image y grows downwards.
    f64::from(size) / 2.0 - c * pixels_per_unit(z, height)
}

/// One moving-edge case, in scene units before `scale`.
#[derive(Clone, Copy, Debug)]
struct Case {
    /// Measure along y (the square moves vertically) rather than x.
    vertical: bool,
    /// The square's half-width along the measured axis, and its centre at the exposure's start.
    half: f64,
    start: f64,
    /// How far its centre moves during the exposure, and how much its half-width grows.
    shift: f64,
    grow: f64,
    /// Whether the camera moves (by `-shift`) instead of the square.
    camera: bool,
    /// Every length is multiplied by this, and the scene is moved this far from the origin
    /// (times `scale`).
    scale: f64,
    away: [f64; 3],
}

/// The scene of `case` as TOML: the shutter `[0.25, 0.75]` of frame 1 between keys at frames 0
/// and 2, so the exposure is a quarter of the keys' span, starting a quarter in.
fn case_toml(case: &Case, spp: u32) -> String {
    let (size, across) = (160u32, 24u32);
    let (width, height) = if case.vertical {
        (across, size)
    } else {
        (size, across)
    };
    let k = case.scale;
    let [ox, oy, oz] = case.away.map(|a| a * k);
    let z = k;
    // Keys at frames 0 and 2; the exposure runs from time 1.25 to 1.75, a quarter of the span,
    // starting at 0.625 of it: the pose at time t is key0 + (t / 2) (key2 - key0).
    let at = |fraction: f64| (fraction - 0.625) / 0.25;
    let (c0, c2) = (
        case.start + at(0.0) * case.shift,
        case.start + at(1.0) * case.shift,
    );
    let (g0, g2) = (1.0 + at(0.0) * case.grow, 1.0 + at(1.0) * case.grow);
    let axis = |c: f64| if case.vertical { [0.0, c] } else { [c, 0.0] };
    let (h, long) = (case.half * k, 4.0 * k);
    let (hx, hy) = if case.vertical { (long, h) } else { (h, long) };
    let corners = format!(
        "[[{}, {}, 0], [{}, {}, 0], [{}, {}, 0], [{}, {}, 0]]",
        -hx, -hy, -hx, hy, hx, hy, hx, -hy
    );
    let scale = |g: f64| {
        if case.vertical {
            format!("[1, {g}, 1]")
        } else {
            format!("[{g}, 1, 1]")
        }
    };
    let (object_keys, camera_keys) = if case.camera {
        let eye = |frame: u32, c: f64| {
            let [x, y] = axis(-c * k);
            let (x, y) = (ox + x, oy + y);
            format!(
                "[[camera.keys]]\nframe = {frame}\nposition = [{x}, {y}, {oz}]\n\
                 look_at = [{x}, {y}, {}]\n",
                oz + k
            )
        };
        let [sx, sy] = axis(case.start * k);
        (
            format!("translate = [{}, {}, {}]\n", ox + sx, oy + sy, oz + z),
            eye(0, c0 - case.start) + &eye(2, c2 - case.start),
        )
    } else {
        let key = |frame: u32, c: f64, g: f64| {
            let [x, y] = axis(c * k);
            format!(
                "[[object.keys]]\nframe = {frame}\ntranslate = [{}, {}, {}]\nscale = {}\n",
                ox + x,
                oy + y,
                oz + z,
                scale(g)
            )
        };
        (key(0, c0, g0) + &key(2, c2, g2), String::new())
    };
    format!(
        "[render]\nwidth = {width}\nheight = {height}\nspp = {spp}\nmax_depth = 0\n\
         [camera]\nposition = [{ox}, {oy}, {oz}]\nlook_at = [{ox}, {oy}, {}]\nvfov = {VFOV}\n\
         shutter = [0.25, 0.75]\n{camera_keys}\
         [environment]\nradiance = 1\n\
         [materials.black]\ntype = \"diffuse\"\nalbedo = 0\n\
         [[object]]\nshape = \"quad\"\ncorners = {corners}\nmaterial = \"black\"\n{object_keys}",
        oz + k
    )
}

/// The measured profile along the case's axis: the mean over the other axis of every line.
fn profile(case: &Case, spp: u32) -> (Vec<f64>, u32) {
    let scene = load_str(&case_toml(case, spp)).expect("the edge scene loads");
    assert!(Effects::of(&scene).motion_blur, "{case:?}");
    let out = render(&scene, None, 1);
    let (w, h) = (scene.settings.width, scene.settings.height);
    let (length, lines) = if case.vertical { (h, w) } else { (w, h) };
    let value = |i: u32, j: u32| {
        let index = if case.vertical { i * w + j } else { j * w + i };
        f64::from(out.pixels[index as usize][1])
    };
    let mean = (0..length)
        .map(|i| (0..lines).map(|j| value(i, j)).sum::<f64>() / f64::from(lines))
        .collect();
    (mean, lines * spp)
}

/// The case's square edges in the image: `(position at the exposure's start, shift over it)`
/// for the lower and the upper edge along the measured axis (image coordinates grow the other
/// way from scene coordinates, so the scene's upper edge is the image's lower one).
fn image_edges(case: &Case) -> ((f64, f64), (f64, f64)) {
    let height = if case.vertical { 160 } else { 24 };
    let at = |c: f64| image_position(c, 1.0, 160, height);
    let (lo0, hi0) = (case.start - case.half, case.start + case.half);
    let (lo1, hi1) = (
        case.start + case.shift - case.half * (1.0 + case.grow),
        case.start + case.shift + case.half * (1.0 + case.grow),
    );
    ((at(hi0), at(hi1) - at(hi0)), (at(lo0), at(lo1) - at(lo0)))
}

/// Checks a case: every pixel against the exact expected value, and each ramp's interior
/// against a line whose width is how far that edge moved.
fn check(case: Case) {
    let spp = 256;
    let (measured, draws) = profile(&case, spp);
    let (left, right) = image_edges(&case);
    let mut worst = 0.0f64;
    for (i, &m) in measured.iter().enumerate() {
        let e = expected(i as u32, left, right);
        // Each sample is 0 or 1: the mean of `draws` has variance e (1 - e) / draws.
        let sigma = (e * (1.0 - e) / f64::from(draws)).sqrt();
        let off = (m - e).abs() / (sigma + 1e-3);
        worst = worst.max(off);
        assert!(
            off < 5.0,
            "{case:?}: pixel {i} is {m}, exactly {e} (sigma {sigma})"
        );
    }
    for (edge, (start, shift)) in [left, right].into_iter().enumerate() {
        let width = shift.abs();
        if width < 6.0 {
            continue;
        }
        let (lo, hi) = (start.min(start + shift), start.max(start + shift));
        // Pixels whose whole area lies in the ramp's interior: there the box average of a line
        // is the line at the pixel's centre.
        let inside: Vec<(f64, f64)> = (0..measured.len())
            .map(|i| (i as f64 + 0.5, measured[i]))
            .filter(|(c, _)| *c - 0.5 >= lo + 0.5 && *c + 0.5 <= hi - 0.5)
            .collect();
        let n = inside.len() as f64;
        let (mx, my) = (
            inside.iter().map(|p| p.0).sum::<f64>() / n,
            inside.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let sxx: f64 = inside.iter().map(|p| (p.0 - mx).powi(2)).sum();
        let slope = inside.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / sxx;
        let fitted = 1.0 / slope.abs();
        let residual = inside
            .iter()
            .map(|p| (p.1 - (my + slope * (p.0 - mx))).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "{case:?} edge {edge}: ramp {fitted:.3} px wide, moved {width:.3} px; worst pixel \
             {worst:.2} sigma, worst residual {residual:.4}"
        );
        assert!(
            (fitted / width - 1.0).abs() < 0.04,
            "{case:?} edge {edge}: {fitted} vs {width}"
        );
        assert!(
            residual < 5.0 * (0.25 / f64::from(draws)).sqrt() + 1e-3,
            "{case:?}: not a line"
        );
    }
}

fn base() -> Case {
    Case {
        vertical: false,
        half: 0.3,
        start: 0.0,
        shift: 0.1,
        grow: 0.0,
        camera: false,
        scale: 1.0,
        away: [0.0; 3],
    }
}

#[test]
fn a_moving_edge_blurs_into_a_ramp_as_wide_as_it_moves_at_several_speeds_and_directions() {
    for shift in [0.02, 0.08, 0.2, -0.12] {
        for vertical in [false, true] {
            let half = if vertical { 0.05 } else { 0.3 };
            check(Case {
                vertical,
                half,
                shift: if vertical { shift / 6.0 } else { shift },
                ..base()
            });
        }
    }
}

#[test]
fn a_growing_square_and_a_moving_camera_blur_the_same_way() {
    // The half-width at the keys is 1 - 2.5 grow and 1 + 1.5 grow: both positive.
    check(Case {
        grow: 0.3,
        shift: 0.0,
        ..base()
    });
    check(Case {
        grow: -0.2,
        shift: 0.05,
        ..base()
    });
    for shift in [0.1, -0.05] {
        check(Case {
            camera: true,
            shift,
            ..base()
        });
    }
}

#[test]
fn the_blur_is_the_same_at_every_scale_and_far_from_the_origin() {
    for scale in [1e-3, 1.0, 1e3] {
        for away in [[0.0; 3], [300.0, -120.0, 45.0]] {
            for camera in [false, true] {
                check(Case {
                    scale,
                    away,
                    camera,
                    ..base()
                });
            }
        }
    }
}
