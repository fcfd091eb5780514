//! Dispersive glass in the scene format: each way of giving an index loads into the glass it
//! names, and every bad value is refused with the file, the line and the key.

mod common;

use common::{assert_refused, load_with};
use tracer::material::{Bsdf, Dispersion};

const CAMERA: &str = "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n\
[[object]]\nshape = \"sphere\"\nmaterial = \"g\"\n";

/// Loads a scene whose material `g` is `material` (starting on line 1).
fn load(material: &str) -> Result<tracer::Scene, tracer::SceneError> {
    load_with(&format!("{material}\n{CAMERA}"), &[])
}

#[test]
fn every_way_of_giving_an_index_loads() {
    let sf11 = Dispersion::named("sf11").expect("a catalogue glass");
    for (keys, n_d) in [
        ("glass = \"sf11\"", sf11.ior_d()),
        ("cauchy = [1.5, 0.004]", 1.5 + 0.004 / (0.58756 * 0.58756)),
        (
            "sellmeier = [1.03961212, 0.231792344, 1.01046945, 0.00600069867, 0.0200179144, 103.560653]",
            1.5168,
        ),
    ] {
        let scene = load(&format!(
            "[materials.g]\ntype = \"glass\"\n{keys}\ntint = 0.9"
        ))
        .unwrap_or_else(|e| panic!("{keys}: {e}"));
        let Bsdf::DispersiveGlass {
            dispersion,
            outside_ior,
            tint,
        } = scene.materials[0].bsdf
        else {
            panic!("{keys} gave {:?}", scene.materials[0].bsdf)
        };
        // Left out, the outside is vacuum.
        assert_eq!(outside_ior, 1.0, "{keys}");
        assert!(
            (dispersion.ior_d() - n_d).abs() < 2e-4,
            "{keys}: n_d {}",
            dispersion.ior_d()
        );
        assert!(
            dispersion.ior(450.0) > dispersion.ior(650.0),
            "{keys}: blue bends more"
        );
        assert_eq!(tint, glam::Vec3::splat(0.9));
    }
    // A plain index stays plain glass, with no dispersion to pay for.
    let plain = load("[materials.g]\ntype = \"glass\"\nior = 1.5").expect("plain glass");
    assert!(matches!(
        plain.materials[0].bsdf,
        Bsdf::Dielectric { ior: 1.5, .. }
    ));
}

#[test]
fn bad_indices_are_refused_at_their_line_and_key() {
    #[rustfmt::skip]
    let cases = [
        ("type = \"glass\"\ncauchy = [0.9, 0.01]", 3, "at least 1 over 380-780 nm (key `materials.g.cauchy`)"),
        ("type = \"glass\"\ncauchy = [1.5]", 3, "two numbers `[A, B]`, not 1 (key `materials.g.cauchy`)"),
        ("type = \"glass\"\ncauchy = [1.5, -0.01]", 3, "must not be negative"),
        ("type = \"glass\"\ncauchy = [1.5, nan]", 3, "finite"),
        ("type = \"glass\"\nsellmeier = [1, 0, 0, 0.25, 0, 0]", 3, "pole at 500 nm, inside the rendered range 380-780 nm (key `materials.g.sellmeier`)"),
        ("type = \"glass\"\nsellmeier = [1, 0, 0]", 3, "six numbers"),
        ("type = \"glass\"\nsellmeier = [-1, 0, 0, 0.01, 0, 0]", 3, "no coefficient may be negative"),
        ("type = \"glass\"\nsellmeier = [0, 0, 1, 0, 0, 1.0]", 3, "at least 1"),
        ("type = \"glass\"\nglass = \"crown\"", 3, "unknown glass \"crown\": use one of \"bk7\""),
        ("type = \"glass\"\nior = 1.5\nglass = \"bk7\"", 1, "not both `ior` and `glass`"),
        ("type = \"glass\"\ncauchy = [1.5, 0.01]\nsellmeier = [1, 0, 0, 0.01, 0, 0]", 1, "not both `cauchy` and `sellmeier`"),
        ("type = \"diffuse\"\ncauchy = [1.5, 0.01]", 1, "key `cauchy` does not apply to type diffuse"),
        ("type = \"metal\"\nglass = \"bk7\"", 1, "key `glass` does not apply to type metal"),
    ];
    for (keys, line, says) in cases {
        assert_refused(&format!("[materials.g]\n{keys}\n{CAMERA}"), line, says);
    }
}
