//! Energy through spectral paths: closed forms that hold at every wavelength, so the spectral
//! pipeline must give them back in every channel.
//!
//! - A furnace: a closed glass object under a uniform white sky shows radiance exactly 1 in
//!   every direction (radiance over n^2 is invariant along a path through clear glass, and
//!   outside n = 1), whatever the index, so whatever the wavelength. For dispersive glasses
//!   (catalogue, Cauchy, Sellmeier), with paths that turn spectral at the glass (the default)
//!   and with paths spectral from the camera (three hero wavelengths, and one); and with a
//!   medium inside that scatters without absorbing, which keeps the furnace at 1.
//! - The round trip from RGB to spectra and back: a coloured emitter seen directly, and a
//!   coloured diffuse floor under a white sky (its radiance is its albedo), rendered by the
//!   always-spectral pipeline, have their RGB values as means: the bands sum to one and the
//!   sensor undoes their overlap (`tracer::spectrum`).

mod common;

use common::{assert_close, mean_and_error, render_world};
use glam::Vec3;
use tracer::spectrum::SpectralSampling;
use tracer::{TileOutput, World};

fn render(toml: &str, sampling: SpectralSampling) -> TileOutput {
    let scene = tracer::scene::load_str(toml).expect("test scene loads");
    let mut world = World::prepare(scene, None);
    world.spectral = sampling;
    render_world(&world, 0)
}

/// A glass sphere of `index` (the material's index keys) under a white sky, filling most of
/// the view.
fn furnace(index: &str) -> String {
    format!(
        r#"
render = {{ width = 24, height = 24, spp = 64, max_depth = "unlimited", russian_roulette_depth = 4 }}
camera = {{ position = [0, 0, -3], look_at = [0, 0, 0], vfov = 45 }}
object = [{{ shape = "sphere", radius = 1, subdivisions = 3, material = "glass" }}]
[materials.glass]
type = "glass"
{index}
[environment]
radiance = 1
"#
    )
}

#[test]
fn dispersive_glass_in_a_white_furnace_is_white() {
    for index in [
        "glass = \"sf11\"",
        "glass = \"bk7\"",
        "cauchy = [1.7, 0.03]",
        "sellmeier = [0.6961663, 0.4079426, 0.8974794, 0.004679148, 0.01351206, 97.934]",
    ] {
        for sampling in [
            SpectralSampling::Auto,
            SpectralSampling::Hero,
            SpectralSampling::Single,
        ] {
            let out = render(&furnace(index), sampling);
            assert!(
                out.stats.spectral_paths > 0,
                "{index}: no path turned spectral"
            );
            let what = format!("{index}, {}", sampling.name());
            assert_close(&what, mean_and_error(&out), Vec3::ONE, 0.01);
        }
    }
}

#[test]
fn a_chromatic_medium_that_only_scatters_inside_dispersive_glass_stays_white() {
    // Scattering without absorption keeps the furnace at 1; the medium differs per channel, so
    // each wavelength sees its band's coefficient and the flights' spectral MIS mixes them.
    let toml = furnace("glass = \"sf11\"\nmedium = \"fog\"")
        + "[media.fog]\nsigma_s = [0.4, 1.0, 2.0]\ng = 0.3\n";
    for sampling in [SpectralSampling::Auto, SpectralSampling::Hero] {
        let out = render(&toml, sampling);
        assert!(out.stats.medium_scatters > 0 && out.stats.spectral_paths > 0);
        let what = format!("fog in flint, {}", sampling.name());
        assert_close(&what, mean_and_error(&out), Vec3::ONE, 0.01);
    }
}

#[test]
fn plain_glass_stays_white_spectral_or_not() {
    for sampling in [SpectralSampling::Hero, SpectralSampling::Single] {
        let out = render(&furnace("ior = 1.5"), sampling);
        assert_close(sampling.name(), mean_and_error(&out), Vec3::ONE, 0.01);
    }
    // RGB paths through plain glass never turn: they stay the RGB renderer's paths.
    let rgb = render(&furnace("ior = 1.5"), SpectralSampling::Auto);
    assert_eq!(rgb.stats.spectral_paths, 0);
}

#[test]
fn rgb_values_come_back_from_spectral_paths() {
    for colour in [
        [0.9, 0.3, 0.1],
        [0.1, 0.8, 0.2],
        [0.05, 0.2, 0.9],
        [0.5, 0.5, 0.5],
    ] {
        let c = Vec3::from(colour);
        let [r, g, b] = colour;
        // An emitter filling the view: the camera sees its emission.
        let lamp = format!(
            r#"
render = {{ width = 16, height = 16, spp = 64 }}
camera = {{ position = [0, 0, -1], look_at = [0, 0, 0], vfov = 30 }}
object = [{{ shape = "quad", corners = [[5, -5, 0], [-5, -5, 0], [-5, 5, 0], [5, 5, 0]], material = "lamp" }}]
[materials.lamp]
type = "emissive"
emission = [{r}, {g}, {b}]
"#
        );
        // A floor under a white sky, seen from just above: its radiance is its albedo.
        let floor = format!(
            r#"
render = {{ width = 16, height = 16, spp = 64, max_depth = 1 }}
camera = {{ position = [0, 0.1, 0], look_at = [0, 0, 0.05], up = [0, 0, 1], vfov = 40 }}
object = [{{ shape = "quad", corners = [[-1e3, 0, -1e3], [-1e3, 0, 1e3], [1e3, 0, 1e3], [1e3, 0, -1e3]], material = "floor" }}]
[materials.floor]
type = "diffuse"
albedo = [{r}, {g}, {b}]
[environment]
radiance = 1
"#
        );
        for (what, toml) in [("emitter", lamp), ("floor", floor)] {
            for sampling in [SpectralSampling::Hero, SpectralSampling::Single] {
                let out = render(&toml, sampling);
                assert_eq!(out.stats.spectral_paths, 16 * 16 * 64);
                let what = format!("{what} {colour:?}, {}", sampling.name());
                assert_close(&what, mean_and_error(&out), c, 0.01);
            }
            // The RGB render of the same: exact for the emitter, noisy for the floor.
            let rgb = render(&toml, SpectralSampling::Auto);
            assert_close(what, mean_and_error(&rgb), c, 0.01);
        }
    }
}
