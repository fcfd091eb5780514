//! A prism's deviation, wavelength by wavelength, against Snell's law in closed form.
//!
//! The camera looks through a prism (apex angle `A`, extruded along y, apex towards +x) at an
//! emitter so far away that only directions matter: it lights every direction whose angle in the
//! xz-plane is beyond `edge`. A camera ray at angle `alpha` (`atan2(x, z)`) meets the first face
//! at incidence `t1 = alpha + A/2`, goes on inside at `t2 = asin(sin t1 / n)`, meets the second
//! face at `t3 = t2 - A` and leaves at `t4 = asin(n sin t3)`, along the angle
//! `beta = A/2 + t4`. So the emitter's edge shows in the image where `beta(alpha, n) = edge`,
//! and since `n` depends on the wavelength, each wavelength shows it in another column. The
//! render follows one wavelength at a time (`SpectralSampling::Monochrome`) and finds the
//! column where the row's brightness falls to half; the closed form, solved for `alpha` by
//! bisection, says where that must be. Four glasses (two catalogue ones, a Cauchy and a
//! Sellmeier index given in the file), three wavelengths each.

use tracer::spectrum::SpectralSampling;
use tracer::{FrameConfig, World};

/// The prism's apex angle, in degrees.
const APEX: f64 = 45.0;
/// Where the camera looks, in degrees from +z towards +x: about the minimum deviation.
const LOOK: f64 = 20.0;
/// The image: a strip `WIDTH` pixels wide covering `HFOV` degrees.
const WIDTH: u32 = 400;
const HEIGHT: u32 = 2;
const HFOV: f64 = 8.0;

/// The index of `glass` at `nm`, from its published formula (`TOML`'s values, in f64).
fn index(glass: &Glass, nm: f64) -> f64 {
    let l2 = (nm * 1e-3) * (nm * 1e-3);
    match glass.formula {
        Formula::Cauchy(a, b) => a + b / l2,
        Formula::Sellmeier(b, c) => {
            (1.0 + (0..3).map(|i| b[i] * l2 / (l2 - c[i])).sum::<f64>()).sqrt()
        }
    }
}

enum Formula {
    Cauchy(f64, f64),
    Sellmeier([f64; 3], [f64; 3]),
}

struct Glass {
    /// The material's index keys, as the scene file gives them.
    toml: &'static str,
    formula: Formula,
}

/// The exit angle of a ray at angle `alpha` through the prism of index `n` (radians).
fn exit_angle(alpha: f64, n: f64) -> f64 {
    let a = APEX.to_radians();
    let t1 = alpha + a / 2.0;
    let t2 = (t1.sin() / n).asin();
    let t3 = t2 - a;
    let t4 = (n * t3.sin()).asin();
    a / 2.0 + t4
}

/// The camera angle whose ray leaves the prism along `edge`, by bisection (the exit angle grows
/// with `alpha` over the strip's angles).
fn alpha_at_edge(edge: f64, n: f64) -> f64 {
    let (mut lo, mut hi) = ((LOOK - 6.0).to_radians(), (LOOK + 6.0).to_radians());
    assert!(
        exit_angle(lo, n) < edge && exit_angle(hi, n) > edge,
        "the edge is outside"
    );
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if exit_angle(mid, n) < edge {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The scene: the prism, and the emitter beyond `edge` (radians) at distance 1e5, so far that
/// where a ray leaves the prism moves the edge by 0.002 degrees at most: only directions matter.
fn scene_toml(glass: &Glass, edge: f64) -> String {
    let (d, s) = (1e5, 6e4);
    let (ux, uz) = (edge.sin(), edge.cos());
    let (px, pz) = (edge.cos(), -edge.sin());
    let near = (d * ux, d * uz);
    let far = (d * ux + s * px, d * uz + s * pz);
    let (look_x, look_z) = (LOOK.to_radians().sin(), LOOK.to_radians().cos());
    // The pixel strip: vfov from the horizontal field and the aspect ratio.
    let half_h = (HFOV / 2.0).to_radians().tan() * f64::from(HEIGHT) / f64::from(WIDTH);
    let vfov = 2.0 * half_h.atan().to_degrees();
    format!(
        r#"
render = {{ width = {WIDTH}, height = {HEIGHT}, spp = 32, max_depth = 2, russian_roulette_depth = "off" }}
camera = {{ position = [0, 0, 0], look_at = [{look_x}, 0, {look_z}], vfov = {vfov} }}
[materials.prism]
type = "glass"
{toml}
[materials.lamp]
type = "emissive"
emission = 1
[[object]]
obj = "prism.obj"
material = "prism"
[[object]]
shape = "quad"
corners = [[{nx}, 100, {nz}], [{fx}, 100, {fz}], [{fx}, -100, {fz}], [{nx}, -100, {nz}]]
material = "lamp"
"#,
        toml = glass.toml,
        nx = near.0,
        nz = near.1,
        fx = far.0,
        fz = far.1,
    )
}

/// The prism as an OBJ: the apex at (2.305, 4), where the central ray crosses it about 1 below
/// the apex, faces 3 long, extruded over y in [-1, 1], every triangle wound outwards.
fn prism_obj() -> String {
    let half = (APEX / 2.0).to_radians();
    let (ax, az) = (2.305f64, 4.0f64);
    let side = 3.0;
    let corners = [
        (ax, az),
        (ax - side * half.cos(), az - side * half.sin()),
        (ax - side * half.cos(), az + side * half.sin()),
    ];
    let v: Vec<[f64; 3]> = [-1.0, 1.0]
        .into_iter()
        .flat_map(|y| corners.map(|(x, z)| [x, y, z]))
        .collect();
    let centre = [(ax + 2.0 * corners[1].0) / 3.0, 0.0, az];
    let mut obj: String = v
        .iter()
        .map(|p| format!("v {} {} {}\n", p[0], p[1], p[2]))
        .collect();
    let triangles = [
        [0, 1, 2],
        [3, 4, 5],
        [0, 1, 4],
        [0, 4, 3],
        [1, 2, 5],
        [1, 5, 4],
        [2, 0, 3],
        [2, 3, 5],
    ];
    for [i, j, k] in triangles {
        let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let (e1, e2) = (sub(v[j], v[i]), sub(v[k], v[i]));
        let n = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        let out = sub(v[i], centre);
        let outwards = n[0] * out[0] + n[1] * out[1] + n[2] * out[2] > 0.0;
        let (j, k) = if outwards { (j, k) } else { (k, j) };
        obj += &format!("f {} {} {}\n", i + 1, j + 1, k + 1);
    }
    obj
}

/// The fractional column where the image's brightness (mean over rows) falls from the lit side
/// to half the lit level, and the lit level.
fn edge_column(pixels: &[[f32; 3]]) -> (f64, f64) {
    let column = |x: usize| -> f64 {
        (0..HEIGHT as usize)
            .map(|y| f64::from(pixels[y * WIDTH as usize + x][0]))
            .sum::<f64>()
            / f64::from(HEIGHT)
    };
    let values: Vec<f64> = (0..WIDTH as usize).map(column).collect();
    // Columns grow towards -x, so smaller camera angles: the lit side is on the left.
    let lit = values[..20].iter().sum::<f64>() / 20.0;
    let dark = values[WIDTH as usize - 20..].iter().sum::<f64>() / 20.0;
    assert!(
        lit > 0.5 && dark < 0.05,
        "lit {lit}, dark {dark}: no edge in view"
    );
    let half = 0.5 * lit;
    // The first run of three columns below half marks the edge (a noisy column alone does not).
    let x = (1..WIDTH as usize - 3)
        .find(|&x| values[x..x + 3].iter().all(|&v| v < half))
        .expect("the brightness falls somewhere");
    let (a, b) = (values[x - 1], values[x]);
    // Pixel x - 1 covers [x - 1, x); interpolate between their centres.
    (x as f64 - 0.5 + (a - half) / (a - b), lit)
}

/// The camera angle of the centre of fractional column `c`, from the camera's own model.
fn column_angle(c: f64) -> f64 {
    let half_w = (HFOV / 2.0).to_radians().tan();
    let t = 2.0 * c / f64::from(WIDTH) - 1.0;
    // right = forward x up = (-cos, 0, sin) for a forward of angle LOOK.
    let (s, co) = (LOOK.to_radians().sin(), LOOK.to_radians().cos());
    let (x, z) = (s - co * half_w * t, co + s * half_w * t);
    x.atan2(z)
}

#[test]
fn each_wavelength_leaves_the_prism_where_snell_says() {
    let glasses = [
        Glass {
            toml: "glass = \"sf11\"",
            formula: Formula::Sellmeier(
                [1.73759695, 0.313747346, 1.898781010],
                [0.013188707, 0.0623068142, 155.23629],
            ),
        },
        Glass {
            toml: "glass = \"bk7\"",
            formula: Formula::Sellmeier(
                [1.03961212, 0.231792344, 1.01046945],
                [0.00600069867, 0.0200179144, 103.560653],
            ),
        },
        Glass {
            toml: "cauchy = [1.6, 0.02]",
            formula: Formula::Cauchy(1.6, 0.02),
        },
        Glass {
            toml: "sellmeier = [0.6961663, 0.4079426, 0.8974794, 0.004679148, 0.01351206, 97.934]",
            formula: Formula::Sellmeier(
                [0.6961663, 0.4079426, 0.8974794],
                [0.004679148, 0.01351206, 97.934],
            ),
        },
    ];
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool");
    let pixel = HFOV / f64::from(WIDTH);
    for glass in &glasses {
        // The edge where the central ray leaves at 550 nm: the wavelengths spread around it.
        let edge = exit_angle(LOOK.to_radians(), index(glass, 550.0));
        let mut files = tracer::scene::MemoryFiles::new();
        files.insert("scene.toml", scene_toml(glass, edge));
        files.insert("prism.obj", prism_obj());
        let scene = tracer::scene::load_from(&files, "scene.toml").expect("the prism loads");
        let mut world = World::prepare(scene, None);
        assert!(world.effects.dispersion, "{}", glass.toml);
        let mut measured = Vec::new();
        for nm in [450.0, 550.0, 650.0] {
            world.spectral = SpectralSampling::Monochrome(nm as f32);
            let film = tracer::render_frame(&world, 0, &pool, FrameConfig { tile: 32 });
            let (column, lit) = edge_column(&film.pixels);
            let seen = column_angle(column).to_degrees();
            let expected = alpha_at_edge(edge, index(glass, nm)).to_degrees();
            // Half a degree of error would be 25 pixels; allow a pixel and a half.
            assert!(
                (seen - expected).abs() < 1.5 * pixel,
                "{} at {nm} nm: the edge shows at {seen:.4} degrees, Snell says {expected:.4} \
                 (lit level {lit:.3})",
                glass.toml
            );
            measured.push((seen, expected));
        }
        // The spread between blue and red, the dispersion itself, to within two pixels.
        let spread = measured[0].0 - measured[2].0;
        let snell = measured[0].1 - measured[2].1;
        assert!(
            (spread - snell).abs() < 2.0 * pixel && snell.abs() > 10.0 * pixel,
            "{}: 450 to 650 nm spread {spread:.4} degrees, Snell {snell:.4}",
            glass.toml
        );
    }
}
