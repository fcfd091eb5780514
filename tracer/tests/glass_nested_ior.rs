//! Glass inside glass (`outside_ior`, Mitsuba 3's `ext_ior`): scenes loaded from TOML, checked
//! against Snell's law and the Fresnel equations for the real indices on each side.
//!
//! - A ray through a slab of index n2 inside a slab of index n1, followed surface by surface
//!   through the loaded scene, crosses each slab at the angle Snell's law gives for the two
//!   real indices, so its sideways shift through the inner slab follows `n2` (not `n1 n2`, as
//!   when the inner glass ignores what surrounds it), and it leaves parallel to where it came in.
//! - An index-matched glass inside water (`ior` and `outside_ior` both the water's) reflects
//!   nothing: the render equals the one without it, while a denser glass in the same water
//!   visibly darkens it, and the same glass without `outside_ior` (index 1 around it inside
//!   the water) is refused by the loader's nesting check.
//! - Glass, dispersive glass and an air bubble inside a glass ball, in a white furnace with no
//!   absorption, render 1 (energy; this alone would not notice a wrong relative index).
//! - Bad `outside_ior` values, and the key on a material that is not glass, are refused with
//!   the file, the line and the key; so is any glass whose relative index (its own over
//!   `outside_ior`, at every rendered wavelength for a dispersive one) leaves
//!   [`tracer::material::RELATIVE_IOR`], while the range's ends load.

mod common;

use common::{assert_close, assert_refused, load_with, mean_and_error, render};
use glam::{Vec2, Vec3};
use tracer::geometry::{Ray, intersect_triangle};
use tracer::material::Frame;
use tracer::scene::{Scene, load_str};

fn load(toml: &str) -> Scene {
    load_str(toml).unwrap_or_else(|e| panic!("test scene loads: {e}\n{toml}"))
}

/// What a traced ray did at one surface.
#[derive(Debug)]
struct Crossing {
    point: Vec3,
    /// The direction it went on in.
    dir: Vec3,
    /// The Fresnel reflectance it passed (1 minus the refraction's probability).
    reflectance: f32,
}

/// Follows the ray from `origin` along `dir` through the scene's surfaces as the renderer does
/// (the triangle's winding normal as the shading normal, the loaded BSDF sampled with
/// `u_choice = 1`, which refracts whenever refraction exists), until it escapes.
fn trace(scene: &Scene, mut origin: Vec3, mut dir: Vec3) -> Vec<Crossing> {
    let mut crossings = Vec::new();
    for _ in 0..16 {
        let ray = Ray {
            origin,
            dir,
            t_max: f32::INFINITY,
        };
        let nearest = scene
            .triangles
            .iter()
            .filter_map(|t| intersect_triangle(&ray, &t.p).map(|h| (h.t, t)))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let Some((t, triangle)) = nearest else {
            return crossings;
        };
        let point = origin + t * dir;
        let frame = Frame::from_normal(triangle.area_vector().normalize());
        let bsdf = scene.materials[triangle.material as usize].bsdf;
        let s = bsdf
            .sample(frame.to_local(-dir), 1.0, Vec2::splat(0.5))
            .expect("glass scatters");
        assert!(s.transmission, "reflected at {point}: {s:?}");
        dir = frame.to_world(s.wi);
        origin = point + 1e-4 * dir;
        crossings.push(Crossing {
            point,
            dir,
            reflectance: 1.0 - s.pdf,
        });
    }
    panic!("the ray never escaped");
}

/// The unpolarised Fresnel reflectance from index `n1` into `n2` at incidence `theta`.
fn fresnel(n1: f64, n2: f64, theta: f64) -> f64 {
    let sin_t = n1 / n2 * theta.sin();
    let (ci, ct) = (theta.cos(), (1.0 - sin_t * sin_t).sqrt());
    let rs = (n1 * ci - n2 * ct) / (n1 * ci + n2 * ct);
    let rp = (n2 * ci - n1 * ct) / (n2 * ci + n1 * ct);
    0.5 * (rs * rs + rp * rp)
}

/// A slab of glass `n1` (`z` in [0, 4]) around a slab of glass `n2` (`z` in [1, 2]) whose
/// outside is `n1`, both far wider than any traced ray strays.
fn nested_slabs(n1: f32, n2: f32) -> String {
    format!(
        r#"
        camera = {{ position = [0, 0, -5], look_at = [0, 0, 0] }}
        object = [
            {{ shape = "box", min = [-50, -50, 0], max = [50, 50, 4], material = "outer" }},
            {{ shape = "box", min = [-40, -40, 1], max = [40, 40, 2], material = "inner" }},
        ]
        [materials.outer]
        type = "glass"
        ior = {n1}
        [materials.inner]
        type = "glass"
        ior = {n2}
        outside_ior = {n1}
        "#
    )
}

#[test]
fn a_ray_through_nested_slabs_bends_by_both_real_indices() {
    // Glass in water, an air bubble in water, water in glass, index-matched, diamond in a
    // light glass.
    let pairs = [
        (1.33f32, 1.5f32),
        (1.33, 1.0),
        (1.5, 1.33),
        (1.33, 1.33),
        (1.2, 2.4),
    ];
    for (n1, n2) in pairs {
        let scene = load(&nested_slabs(n1, n2));
        for theta0 in [0.0f64, 0.15, 0.5, 0.9, 1.2] {
            let what = format!("{n2} inside {n1}, theta {theta0}");
            let dir0 = Vec3::new(theta0.sin() as f32, 0.0, theta0.cos() as f32);
            let origin = Vec3::new(0.0, 0.0, -1.0);
            let crossings = trace(&scene, origin, dir0);
            assert_eq!(crossings.len(), 4, "{what}: {crossings:?}");
            // n sin(theta) is the same in every layer: air, n1, n2, n1, air.
            let angle = |n: f32| (theta0.sin() / f64::from(n)).asin();
            let (theta1, theta2) = (angle(n1), angle(n2));
            let widths = [(1.0, theta0), (1.0, theta1), (1.0, theta2), (2.0, theta1)];
            let mut x = 0.0f64;
            for (i, ((width, theta), c)) in widths.iter().zip(&crossings).enumerate() {
                x += width * theta.tan();
                let got = f64::from(c.point.x);
                assert!(
                    (got - x).abs() < 1e-4 * (1.0 + x.abs()),
                    "{what}: crossing {i} at x = {got}, Snell says {x}"
                );
            }
            let out = crossings[3].dir;
            assert!((out - dir0).length() < 1e-5, "{what}: leaves along {out}");
            // Entering the inner slab: the reflectance of the n1 | n2 interface.
            let f = fresnel(f64::from(n1), f64::from(n2), theta1);
            let got = f64::from(crossings[1].reflectance);
            assert!((got - f).abs() < 2e-6, "{what}: F = {got}, expected {f}");
            if n1 == n2 {
                assert_eq!(crossings[1].reflectance, 0.0, "{what}");
                assert_eq!(crossings[2].reflectance, 0.0, "{what}");
            }
        }
    }
}

/// A slab of glass of index `n` filled with a weakly absorbing medium (`z` in [0, 2]), in
/// front of an emitter of radiance 1 facing the camera, with `inner` (a material table's
/// body, or `None` for no inner object) a slab inside it (`z` in [0.5, 1.5]) filled with the
/// same medium.
fn slab_before_a_lamp(n: f32, inner: Option<&str>) -> String {
    let inner_object = if inner.is_some() {
        r#"{ shape = "box", min = [-2, -2, 0.5], max = [2, 2, 1.5], material = "inner" },"#
    } else {
        ""
    };
    let inner_material = inner.map_or(String::new(), |keys| {
        format!("[materials.inner]\n{keys}\nmedium = \"liquid\"\noutside_medium = \"liquid\"")
    });
    format!(
        r#"
        render = {{ width = 32, height = 32, spp = 32, max_depth = "unlimited", russian_roulette_depth = "off" }}
        camera = {{ position = [0, 0, -5], look_at = [0, 0, 0], vfov = 10 }}
        object = [
            {{ shape = "box", min = [-3, -3, 0], max = [3, 3, 2], material = "outer" }},
            {inner_object}
            {{ shape = "quad", corners = [[-3, -3, 5], [-3, 3, 5], [3, 3, 5], [3, -3, 5]], material = "lamp" }},
        ]
        [materials.lamp]
        type = "emissive"
        emission = 1
        [materials.outer]
        type = "glass"
        ior = {n}
        medium = "liquid"
        {inner_material}
        [media.liquid]
        sigma_a = 0.1
        "#
    )
}

#[test]
fn an_index_matched_glass_inside_water_lets_light_through_unchanged() {
    for n in [1.33f32, 1.7] {
        let (without, without_se) =
            mean_and_error(&render(&load(&slab_before_a_lamp(n, None)), None, 0));
        assert!(without.x > 0.5, "{n}: the lamp is hidden: {without}");
        let matched = format!("type = \"glass\"\nior = {n}\noutside_ior = {n}");
        let with = render(&load(&slab_before_a_lamp(n, Some(&matched))), None, 0);
        let (mean, se) = mean_and_error(&with);
        let what = format!("an index-matched {n} glass in {n} water");
        // Both images are noisy: four standard errors of their difference.
        let combined = Vec3::new(
            se.x.hypot(without_se.x),
            se.y.hypot(without_se.y),
            se.z.hypot(without_se.z),
        );
        assert_close(&what, (mean, combined), without, 0.0);
        // Guard: a glass of another index in the same water reflects at its two faces, and
        // this scene sees it, so the equality above is not vacuous. (The same glass with
        // `outside_ior` left out, index 1 around it in the water, is refused by the loader.)
        let denser = format!("type = \"glass\"\nior = {}\noutside_ior = {n}", 1.5 * n);
        let (darker, darker_se) = mean_and_error(&render(
            &load(&slab_before_a_lamp(n, Some(&denser))),
            None,
            0,
        ));
        let gap = without.x - darker.x;
        assert!(
            gap > 8.0 * darker_se.x.hypot(without_se.x),
            "{n}: a denser glass renders {darker}, without the glass {without}"
        );
        let old_rule = format!("type = \"glass\"\nior = {n}");
        let refused = load_with(&slab_before_a_lamp(n, Some(&old_rule)), &[])
            .expect_err("index 1 around a glass inside water contradicts the geometry");
        assert!(refused.to_string().contains("`outside_ior`"), "{refused}");
    }
}

#[test]
fn glass_and_bubbles_inside_glass_in_a_white_furnace_render_one() {
    let cores = [
        "ior = 1.5\noutside_ior = 1.33",
        "ior = 1\noutside_ior = 1.33",
        "ior = 2.4\noutside_ior = 1.33",
        "glass = \"sf11\"\noutside_ior = 1.33",
    ];
    for core in cores {
        let toml = format!(
            r#"
            render = {{ width = 16, height = 16, spp = 16, max_depth = "unlimited", russian_roulette_depth = "off" }}
            camera = {{ position = [0, 0, -3], look_at = [0, 0, 0], vfov = 40 }}
            object = [
                {{ shape = "sphere", radius = 1, subdivisions = 3, material = "water" }},
                {{ shape = "sphere", radius = 0.5, subdivisions = 3, material = "core" }},
            ]
            environment = {{ radiance = 1 }}
            [materials.water]
            type = "glass"
            ior = 1.33
            [materials.core]
            type = "glass"
            {core}
            "#
        );
        let out = render(&load(&toml), None, 0);
        let what = format!("furnace: {core:?} inside water");
        assert_close(&what, mean_and_error(&out), Vec3::ONE, 0.005);
    }
}

#[test]
fn bad_outside_indices_are_refused_at_their_line_and_key() {
    const CAMERA: &str = "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n\
        [[object]]\nshape = \"sphere\"\nmaterial = \"g\"\n";
    let key = "(key `materials.g.outside_ior`)";
    #[rustfmt::skip]
    let cases = [
        ("type = \"glass\"\noutside_ior = 0", 3, "0 must be greater than 0"),
        ("type = \"glass\"\nior = 1.5\noutside_ior = -1.33", 4, "-1.33 must be greater than 0"),
        ("type = \"glass\"\noutside_ior = nan", 3, "must be a finite number"),
        ("type = \"glass\"\noutside_ior = inf", 3, "must be a finite number"),
        ("type = \"glass\"\noutside_ior = 1e39", 3, "must be a finite number"),
        ("type = \"glass\"\noutside_ior = \"water\"", 3, "invalid type"),
        ("type = \"diffuse\"\noutside_ior = 1.33", 1, "key `outside_ior` does not apply to type diffuse"),
        ("type = \"interface\"\noutside_ior = 1.33", 1, "key `outside_ior` does not apply to type interface"),
        ("type = \"mirror\"\noutside_ior = 1.33", 1, "key `outside_ior` does not apply to type mirror"),
    ];
    for (keys, line, says) in cases {
        let message = assert_refused(&format!("[materials.g]\n{keys}\n{CAMERA}"), line, says);
        if line > 1 {
            assert!(
                message.contains(key),
                "{keys}: `{message}` should name the key"
            );
        }
    }
    // Any finite index above 0 passes the key's own check: below the glass's own (glass in a
    // denser glass) and below 1 alike; the glass around the ball makes it true.
    for (keys, around) in [
        ("outside_ior = 0.5", "type = \"interface\"\nmedium = \"m\""),
        ("ior = 1.2\noutside_ior = 3", "type = \"glass\"\nior = 3"),
        (
            "glass = \"bk7\"\noutside_ior = 2",
            "type = \"glass\"\nior = 2",
        ),
    ] {
        load_with(&inside_a_ball(keys, around), &[]).unwrap_or_else(|e| panic!("{keys}: {e}"));
    }
}

/// A glass ball whose table's keys are `keys` inside a ball of radius 3 of the material whose
/// table's body is `around` (with a medium `m` inside, if it names one, which the inner ball
/// then has outside).
fn inside_a_ball(keys: &str, around: &str) -> String {
    let outside_medium = if around.contains("medium") {
        "outside_medium = \"m\"\n[media.m]\nsigma_a = 0.1"
    } else {
        ""
    };
    format!(
        "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n\
         [[object]]\nshape = \"sphere\"\nmaterial = \"g\"\n\
         [[object]]\nshape = \"sphere\"\nradius = 3\nmaterial = \"around\"\n\
         [materials.around]\n{around}\n\
         [materials.g]\ntype = \"glass\"\n{keys}\n{outside_medium}\n"
    )
}

#[test]
fn relative_indices_outside_the_accepted_range_are_refused() {
    const CAMERA: &str = "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n\
        [[object]]\nshape = \"sphere\"\nmaterial = \"g\"\n";
    let (low, high) = (
        *tracer::material::RELATIVE_IOR.start(),
        *tracer::material::RELATIVE_IOR.end(),
    );
    let scene = |keys: &str| format!("[materials.g]\ntype = \"glass\"\n{keys}\n{CAMERA}");
    // Too dense a glass on its own, in air; a glass in a far denser or far thinner
    // surround; a dispersive glass whose index at some wavelength leaves the range.
    #[rustfmt::skip]
    let refused = [
        format!("ior = {}", high * 1.01),
        "ior = 1e30".to_string(),
        "ior = 3e38".to_string(),
        format!("ior = 1.5\noutside_ior = {}", 1.5 / (low * 0.99)),
        "ior = 1\noutside_ior = 1e30".to_string(),
        "ior = 2\noutside_ior = 1e-30".to_string(),
        "ior = 1e20\noutside_ior = 1e-20".to_string(),
        "glass = \"bk7\"\noutside_ior = 1e-3".to_string(),
        "glass = \"sf11\"\noutside_ior = 1e4".to_string(),
        "cauchy = [1.5, 0.004]\noutside_ior = 1e-20".to_string(),
        "sellmeier = [1.03961212, 0.231792344, 1.01046945, 0.00600069867, 0.0200179144, 103.560653]\noutside_ior = 1e5".to_string(),
    ];
    for keys in &refused {
        assert_refused(&scene(keys), 1, "relative index of refraction");
    }
    // The range's ends themselves load, as do extreme but physical pairs, each inside a ball
    // of its outside index.
    for (keys, outside) in [
        (format!("ior = {high}"), None),
        (
            format!("ior = 1\noutside_ior = {}", 1.0 / low),
            Some(1.0 / low),
        ),
        ("ior = 1\noutside_ior = 4".to_string(), Some(4.0)),
        (
            "glass = \"sf11\"\noutside_ior = 100".to_string(),
            Some(100.0),
        ),
    ] {
        let toml = match outside {
            None => scene(&keys),
            Some(n) => inside_a_ball(&keys, &format!("type = \"glass\"\nior = {n}")),
        };
        load_with(&toml, &[]).unwrap_or_else(|e| panic!("{keys}: {e}"));
    }
}
