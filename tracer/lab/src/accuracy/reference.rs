//! The reference every rung is measured against: an exact value, or a cached high-sample render.
//!
//! A rendered reference is itself noisy, and its noise adds to every rung's measured error. So it
//! is rendered as two independent halves (two seeds of its own), and half their squared
//! difference estimates the noise of their mean: E[(A - B)^2] = 2 var(half) and
//! var((A + B) / 2) = var(half) / 2, so the reference's own MSE is about mean((A - B)^2) / 4. The
//! report states that floor, so nobody reads a rung limited by the reference as a property of the
//! knob.
//!
//! The cache (`reference.exr` plus `reference.json`) is keyed by everything the image depends on
//! that this command can see: the scene's file contents, the size, samples, seeds, depth and
//! roulette settings, effects and the tessera version. A change to the renderer's code under the
//! same version is invisible to it: delete the cache after such a change.

use super::bench;
use crate::LabError;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::Path;
use tracer::World;
use tracer::output::RgbImage;
use tracer::scene::RenderSettings;

/// Mixed into the scene's seed to give the reference samples no rung shares.
const REFERENCE_SEED_SALT: u64 = 0x7265_6665_7265_6e63;

/// Where the reference came from.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// A constant image of the scene's known exact radiance.
    Analytic([f32; 3]),
    /// Read from the output folder, its sidecar matching the current settings.
    Cached,
    /// Rendered now.
    Rendered {
        /// Why the cached one could not be used, if there was one.
        stale: Option<String>,
    },
}

/// The image every rung is measured against, and how it was obtained.
pub struct Reference {
    image: RgbImage,
    /// Where the image came from.
    pub source: Source,
    /// Samples per pixel of a rendered reference (0 for an analytic one).
    pub spp: u32,
    /// The estimated MSE of the reference itself (0 for an analytic one).
    pub noise_mse: f64,
    /// The reference's own estimated relative MSE (0 for an analytic one).
    pub noise_rel_mse: f64,
    /// How long the render took (when it was made, for a cached one).
    pub render_seconds: f64,
}

/// What the cached image depends on; a cache whose key differs is stale.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Key {
    scene_files_blake3: String,
    width: u32,
    height: u32,
    spp: u32,
    seeds: [u64; 2],
    max_depth: Option<u32>,
    russian_roulette_depth: Option<u32>,
    effects: String,
    tessera_version: String,
}

#[derive(Debug, Serialize, Deserialize)]
struct Sidecar {
    /// The scene as it was named on the command line; informative only (the key has its hash).
    scene: String,
    key: Key,
    render_seconds: f64,
    noise_mse: f64,
    noise_rel_mse: f64,
}

impl Reference {
    /// A constant image of `mean` radiance at every pixel: the exact answer of a furnace.
    pub fn analytic(width: u32, height: u32, mean: [f32; 3]) -> Self {
        Reference {
            image: RgbImage {
                width,
                height,
                pixels: vec![mean; width as usize * height as usize],
            },
            source: Source::Analytic(mean),
            spp: 0,
            noise_mse: 0.0,
            noise_rel_mse: 0.0,
            render_seconds: 0.0,
        }
    }

    /// The cached reference in `out` if its sidecar matches, else a new render, cached.
    /// `world` renders with its baseline settings at `spp`; its settings are restored after.
    pub fn cached_or_rendered(
        out: &Path,
        scene: &Path,
        files_hash: String,
        spp: u32,
        world: &mut World,
        pool: &rayon::ThreadPool,
    ) -> Result<Self, LabError> {
        let baseline = world.scene.settings.clone();
        let seed = baseline.seed ^ REFERENCE_SEED_SALT;
        let key = Key {
            scene_files_blake3: files_hash,
            width: baseline.width,
            height: baseline.height,
            spp,
            seeds: [seed, seed.wrapping_add(1)],
            max_depth: baseline.max_depth,
            russian_roulette_depth: baseline.russian_roulette_depth,
            effects: world.effects.to_string(),
            tessera_version: env!("CARGO_PKG_VERSION").to_owned(),
        };
        let (exr_path, sidecar_path) = (out.join("reference.exr"), out.join("reference.json"));
        let stale = match read_cache(&exr_path, &sidecar_path, &key) {
            Ok(reference) => return Ok(reference),
            Err(reason) => reason,
        };
        println!("rendering the reference: {spp} spp in two halves with seeds of its own ...");
        let half = |seed: u64, samples: u32, world: &mut World| {
            world.scene.settings = RenderSettings {
                samples_per_pixel: samples,
                seed,
                ..baseline.clone()
            };
            // Timed once: a reference takes long enough, and its time is only informative.
            bench::render_with(world, pool, bench::Timing::ONCE)
        };
        let a = half(key.seeds[0], spp / 2, world);
        let b = half(key.seeds[1], spp - spp / 2, world);
        world.scene.settings = baseline;
        // Weighted by sample count, so an odd `spp` still gives the mean of all its samples.
        let (wa, wb) = (
            (spp / 2) as f32 / spp as f32,
            (spp - spp / 2) as f32 / spp as f32,
        );
        let pixels: Vec<[f32; 3]> = a
            .image
            .pixels
            .iter()
            .zip(&b.image.pixels)
            .map(|(p, q)| std::array::from_fn(|c| wa * p[c] + wb * q[c]))
            .collect();
        let (noise_mse, noise_rel_mse) =
            half_difference_noise(&a.image.pixels, &b.image.pixels, &pixels);
        let image = RgbImage {
            width: key.width,
            height: key.height,
            pixels,
        };
        let render_seconds = a.seconds + b.seconds;
        // The old sidecar goes first: a crash before the new one is written leaves no cache.
        let _ = std::fs::remove_file(&sidecar_path);
        tracer::output::write_exr(&exr_path, image.width, image.height, &image.pixels)?;
        let sidecar = Sidecar {
            scene: scene.display().to_string(),
            key,
            render_seconds,
            noise_mse,
            noise_rel_mse,
        };
        std::fs::write(
            &sidecar_path,
            serde_json::to_string_pretty(&sidecar)? + "\n",
        )
        .map_err(LabError::io("write", &sidecar_path))?;
        Ok(Reference {
            image,
            source: Source::Rendered { stale },
            spp,
            noise_mse,
            noise_rel_mse,
            render_seconds,
        })
    }

    /// The reference image.
    pub fn image(&self) -> &RgbImage {
        &self.image
    }

    /// The root of the reference's own estimated MSE.
    pub fn noise_rmse(&self) -> f64 {
        self.noise_mse.sqrt()
    }

    /// One line for the terminal and the report.
    pub fn describe(&self) -> String {
        let rendered = || {
            format!(
                "{} spp, unlimited depth with roulette, {:.1} s to render; its own noise is about RMSE {:.3e}, relMSE {:.3e}",
                self.spp,
                self.render_seconds,
                self.noise_rmse(),
                self.noise_rel_mse
            )
        };
        match &self.source {
            Source::Analytic(m) => format!(
                "analytic, every pixel ({}, {}, {}) exactly",
                m[0], m[1], m[2]
            ),
            Source::Cached => format!("cached ({})", rendered()),
            Source::Rendered { stale: None } => format!("rendered ({})", rendered()),
            Source::Rendered { stale: Some(why) } => {
                format!("rendered, the cache was stale: {why} ({})", rendered())
            }
        }
    }
}

/// The estimated MSE and relative MSE of the mean of two independent halves `a` and `b`.
fn half_difference_noise(a: &[[f32; 3]], b: &[[f32; 3]], mean: &[[f32; 3]]) -> (f64, f64) {
    let (mut mse, mut rel, mut n) = (0.0f64, 0.0f64, 0u64);
    for ((p, q), m) in a.iter().zip(b).zip(mean) {
        for c in 0..3 {
            let d = f64::from(p[c]) - f64::from(q[c]);
            if d.is_finite() {
                mse += d * d / 4.0;
                rel += d * d / 4.0 / (f64::from(m[c]) + crate::compare::REL_MSE_EPSILON).powi(2);
                n += 1;
            }
        }
    }
    (mse / n.max(1) as f64, rel / n.max(1) as f64)
}

/// The cached reference, or why it cannot be used (missing, unreadable, or made differently).
fn read_cache(exr: &Path, sidecar: &Path, key: &Key) -> Result<Reference, Option<String>> {
    let text = std::fs::read_to_string(sidecar).map_err(|_| None)?;
    let cached: Sidecar =
        serde_json::from_str(&text).map_err(|e| Some(format!("{}: {e}", sidecar.display())))?;
    if cached.key != *key {
        return Err(Some(key_differences(&cached.key, key)));
    }
    let image = tracer::output::read_exr(exr).map_err(|e| Some(e.to_string()))?;
    if (image.width, image.height) != (key.width, key.height) {
        return Err(Some(format!(
            "{} is {}x{}, not {}x{}",
            exr.display(),
            image.width,
            image.height,
            key.width,
            key.height
        )));
    }
    Ok(Reference {
        image,
        source: Source::Cached,
        spp: key.spp,
        noise_mse: cached.noise_mse,
        noise_rel_mse: cached.noise_rel_mse,
        render_seconds: cached.render_seconds,
    })
}

/// "width 64 -> 128, spp 256 -> 4096": the fields of the key that changed.
fn key_differences(cached: &Key, wanted: &Key) -> String {
    let (old, new) = (serde_json::to_value(cached), serde_json::to_value(wanted));
    let (Ok(serde_json::Value::Object(old)), Ok(serde_json::Value::Object(new))) = (old, new)
    else {
        return "its settings differ".to_owned();
    };
    let mut out = String::new();
    for (name, value) in &new {
        let before = old.get(name).cloned().unwrap_or(serde_json::Value::Null);
        if before != *value {
            let _ = write!(
                out,
                "{}{name} {before} -> {value}",
                if out.is_empty() { "" } else { ", " }
            );
        }
    }
    out
}

/// The scene's content hash ([`runtime::node::bundle::scene_hash`], the one the peers log),
/// over every file it was read from in the loader's order, named as the loader names them.
pub fn hash_scene_files(scene: &Path, files: &[String]) -> Result<String, LabError> {
    let root = scene.parent().unwrap_or(Path::new(""));
    let files = files
        .iter()
        .map(|name| {
            let path = root.join(name);
            let bytes = std::fs::read(&path).map_err(LabError::io("read", &path))?;
            Ok(runtime::node::bundle::scene_file(name.clone(), bytes))
        })
        .collect::<Result<Vec<_>, LabError>>()?;
    Ok(runtime::node::bundle::scene_hash(&files))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_half_difference_estimates_the_noise_of_the_mean() {
        // Two halves that differ by exactly 2 everywhere: (A - B)^2 / 4 = 1.
        let a = vec![[3.0f32; 3]; 4];
        let b = vec![[1.0f32; 3]; 4];
        let mean = vec![[2.0f32; 3]; 4];
        let (mse, rel) = half_difference_noise(&a, &b, &mean);
        assert_eq!(mse, 1.0);
        assert!((rel - 1.0 / (2.01f64 * 2.01)).abs() < 1e-15, "{rel}");
    }

    #[test]
    fn key_differences_name_the_changed_fields() {
        let key = Key {
            scene_files_blake3: "abc".into(),
            width: 64,
            height: 64,
            spp: 256,
            seeds: [1, 2],
            max_depth: None,
            russian_roulette_depth: Some(3),
            effects: "diffuse".into(),
            tessera_version: "0.1.0".into(),
        };
        let other = Key {
            width: 128,
            spp: 4096,
            ..key.clone()
        };
        let differences = key_differences(&key, &other);
        let mut parts: Vec<&str> = differences.split(", ").collect();
        parts.sort();
        assert_eq!(parts, ["spp 256 -> 4096", "width 64 -> 128"]);
        assert_eq!(key_differences(&key, &key), "");
    }
}
