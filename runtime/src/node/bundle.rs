//! What crosses the wire besides scheduling: the scene's files, and tiles' pixels and costs.
//!
//! A peer shares no filesystem with the frame owner, so the owner sends every file the scene was
//! read from, each with its blake3 hash; the peer checks every hash and loads the scene from
//! memory with the same loader the owner used. Pixels travel as little-endian `f32` triples and
//! costs as little-endian `u64` block counts, so a tile's bits arrive unchanged.

use runtime_core::wire::{RenderParams, SceneFile, TileResult};
use std::path::Path;
use tracer::scene::{MemoryFiles, SceneError, normalize};
use tracer::{Scene, TileCost, TileOutput};

/// Why a scene could not be shipped or received.
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// A scene file could not be read.
    #[error("{path}: {source}")]
    Read {
        /// The file, as the scene names it.
        path: String,
        /// What the system said.
        source: std::io::Error,
    },
    /// A received scene file is not what its hash says, so the peer refuses to render it.
    #[error("scene file {name} does not match its hash")]
    HashMismatch {
        /// The file, as the scene names it.
        name: String,
    },
    /// A scene was shipped without any file.
    #[error("the scene has no files")]
    Empty,
    /// The scene's files do not load (the tracer's error names file and line).
    #[error(transparent)]
    Scene(#[from] SceneError),
}

/// Reads every file `scene` was loaded from, hashed, the TOML first (as in `Scene::files`).
///
/// Names are relative to the TOML's folder and may climb out of it (`../meshes/a.obj`; the
/// shipped `scenes/shared/*.toml` reach `../shared/scenes`), which the wire refuses. So they are
/// re-rooted at the lowest folder that holds them all: the TOML's path gains that many of its
/// own parent folders' names, and the loader's lexical normalisation resolves the references
/// to the same names on the peer.
pub fn scene_files(toml_path: &Path, scene: &Scene) -> Result<Vec<SceneFile>, BundleError> {
    let folder = toml_path.parent().unwrap_or(Path::new(""));
    let climb = scene
        .files
        .iter()
        .map(|name| {
            normalize(name)
                .unwrap_or_default()
                .split('/')
                .take_while(|part| *part == "..")
                .count()
        })
        .max()
        .unwrap_or(0);
    let absolute = std::fs::canonicalize(if folder.as_os_str().is_empty() {
        Path::new(".")
    } else {
        folder
    })
    .map_err(|source| BundleError::Read {
        path: folder.display().to_string(),
        source,
    })?;
    let parts: Vec<String> = absolute
        .iter()
        .skip(1)
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let prefix = parts[parts.len().saturating_sub(climb)..].join("/");
    scene
        .files
        .iter()
        .map(|name| {
            let path = folder.join(name);
            let bytes = std::fs::read(&path).map_err(|source| BundleError::Read {
                path: path.display().to_string(),
                source,
            })?;
            let rooted = if prefix.is_empty() {
                name.clone()
            } else {
                format!("{prefix}/{name}")
            };
            Ok(scene_file(normalize(&rooted).unwrap_or(rooted), bytes))
        })
        .collect()
}

/// Checks every file's hash and loads the scene from them (the first file is the TOML), then
/// applies the owner's render parameters.
pub fn load_scene(files: Vec<SceneFile>, params: &RenderParams) -> Result<Scene, BundleError> {
    let toml = files.first().ok_or(BundleError::Empty)?.name.clone();
    let mut memory = MemoryFiles::new();
    for file in files {
        if *blake3::hash(&file.bytes).as_bytes() != file.hash {
            return Err(BundleError::HashMismatch { name: file.name });
        }
        memory.insert(&file.name, file.bytes);
    }
    let mut scene = tracer::scene::load_from(&memory, &toml)?;
    apply(&mut scene, params);
    Ok(scene)
}

/// The parameters of a scene as it will be rendered.
pub fn params(scene: &Scene, all_effects: bool) -> RenderParams {
    let s = &scene.settings;
    RenderParams {
        width: s.width,
        height: s.height,
        samples_per_pixel: s.samples_per_pixel,
        max_depth: s.max_depth,
        russian_roulette_depth: s.russian_roulette_depth,
        seed: s.seed,
        all_effects,
    }
}

fn apply(scene: &mut Scene, params: &RenderParams) {
    let s = &mut scene.settings;
    s.width = params.width;
    s.height = params.height;
    s.samples_per_pixel = params.samples_per_pixel;
    s.max_depth = params.max_depth;
    s.russian_roulette_depth = params.russian_roulette_depth;
    s.seed = params.seed;
}

/// The content hash of a whole scene: BLAKE3 over every file's name (length-prefixed, so names
/// cannot run into each other) and its own content hash, in order, as 64 hex digits. The one
/// scene hash: peers log it (first 16 digits, [`scene_digest`]) so a user can see they agree,
/// and `tessera accuracy` keys its cached references by it.
pub fn scene_hash(files: &[SceneFile]) -> String {
    let mut hasher = blake3::Hasher::new();
    for file in files {
        hasher.update(&(file.name.len() as u64).to_le_bytes());
        hasher.update(file.name.as_bytes());
        hasher.update(&file.hash);
    }
    hasher.finalize().to_hex().to_string()
}

/// The identity of a render's frames: BLAKE3 over [`scene_hash`] and every render parameter, as
/// 64 hex digits. A frame's pixels are a pure function of the scene, these parameters and the
/// frame number (ARCHITECTURE.md), so two renders of one render hash give every frame the same
/// bits, and `--resume` keeps a frame whose EXR carries it. The frame count is left out on
/// purpose: a camera key sits at an absolute frame, so frame `k` is the same in a longer render.
pub fn render_hash(files: &[SceneFile], params: &RenderParams) -> String {
    // Destructured so that a parameter added to RenderParams cannot be forgotten here.
    let RenderParams {
        width,
        height,
        samples_per_pixel,
        max_depth,
        russian_roulette_depth,
        seed,
        all_effects,
    } = *params;
    let depth = |d: Option<u32>| d.map_or(u64::MAX, u64::from);
    let mut hasher = blake3::Hasher::new();
    hasher.update(b"tessera render 1\0");
    hasher.update(scene_hash(files).as_bytes());
    for value in [
        u64::from(width),
        u64::from(height),
        u64::from(samples_per_pixel),
        depth(max_depth),
        depth(russian_roulette_depth),
        seed,
        u64::from(all_effects),
    ] {
        hasher.update(&value.to_le_bytes());
    }
    hasher.finalize().to_hex().to_string()
}

/// The first 16 hex digits of [`scene_hash`], for logs.
pub fn scene_digest(files: &[SceneFile]) -> String {
    scene_hash(files)[..16].to_owned()
}

/// `name` with `bytes`, hashed as the wire carries it.
pub fn scene_file(name: String, bytes: Vec<u8>) -> SceneFile {
    SceneFile {
        name,
        hash: *blake3::hash(&bytes).as_bytes(),
        bytes,
    }
}

/// Pixels as little-endian `f32` triples.
pub fn encode_pixels(pixels: &[[f32; 3]]) -> Vec<u8> {
    pixels
        .iter()
        .flatten()
        .flat_map(|c| c.to_le_bytes())
        .collect()
}

/// The inverse of [`encode_pixels`]; `None` when the length is not a whole number of pixels.
pub fn decode_pixels(bytes: &[u8]) -> Option<Vec<[f32; 3]>> {
    if !bytes.len().is_multiple_of(12) {
        return None;
    }
    Some(
        bytes
            .chunks_exact(12)
            .map(|p| {
                std::array::from_fn(|c| {
                    f32::from_le_bytes(
                        p[4 * c..4 * c + 4]
                            .try_into()
                            .expect("chunks of 12 hold three 4-byte floats"),
                    )
                })
            })
            .collect(),
    )
}

/// A tile's cost: rays, then work, then the block counts, all little-endian `u64`.
pub fn encode_cost(cost: &TileCost) -> Vec<u8> {
    [cost.rays, cost.work]
        .iter()
        .chain(&cost.blocks)
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

/// The inverse of [`encode_cost`]; `None` when malformed.
pub fn decode_cost(bytes: &[u8]) -> Option<TileCost> {
    if !bytes.len().is_multiple_of(8) || bytes.len() < 16 {
        return None;
    }
    let mut values = bytes
        .chunks_exact(8)
        .map(|v| u64::from_le_bytes(v.try_into().expect("chunks of 8 are 8 bytes")));
    let rays = values.next()?;
    let work = values.next()?;
    Some(TileCost {
        rays,
        work,
        blocks: values.collect(),
    })
}

/// A rendered tile as the wire carries it.
pub fn tile_result(
    frame: runtime_core::wire::FrameId,
    spec: &runtime_core::wire::TileSpec,
    output: &TileOutput,
) -> TileResult {
    TileResult {
        frame,
        tile: spec.id,
        piece: spec.piece,
        rect: balancer_rect(output.rect),
        pixels: encode_pixels(&output.pixels),
        costs: encode_cost(&output.cost),
    }
}

/// The tracer's rectangle for a balancer's. The two crates do not know each other; this and
/// [`balancer_rect`] are the runtime's only conversions between them.
pub fn tracer_rect(rect: balancer::Rect) -> tracer::Rect {
    tracer::Rect {
        x: rect.x,
        y: rect.y,
        w: rect.w,
        h: rect.h,
    }
}

/// The balancer's rectangle for a tracer's; the inverse of [`tracer_rect`].
pub fn balancer_rect(rect: tracer::Rect) -> balancer::Rect {
    balancer::Rect::new(rect.x, rect.y, rect.w, rect.h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_and_costs_round_trip_bit_for_bit() {
        let pixels = vec![[0.1, -0.0, f32::MIN_POSITIVE], [1e30, 3.5, 0.0]];
        let back = decode_pixels(&encode_pixels(&pixels)).unwrap();
        let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|c| c.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back), bits(&pixels));
        let cost = TileCost {
            rays: 7,
            work: 99,
            blocks: vec![1, u64::MAX, 0],
        };
        assert_eq!(decode_cost(&encode_cost(&cost)), Some(cost));
        assert_eq!(decode_pixels(&[0; 13]), None);
        assert_eq!(decode_cost(&[0; 12]), None);
    }

    /// Every parameter and every file is part of the render hash; nothing else is.
    #[test]
    fn the_render_hash_changes_with_every_parameter_and_file() {
        let files = vec![scene_file("a.toml".into(), b"x".to_vec())];
        let params = RenderParams {
            width: 8,
            height: 4,
            samples_per_pixel: 2,
            max_depth: None,
            russian_roulette_depth: Some(3),
            seed: 1,
            all_effects: false,
        };
        let base = render_hash(&files, &params);
        assert_eq!(base, render_hash(&files.clone(), &params));
        let changed = [
            RenderParams { width: 9, ..params },
            RenderParams {
                height: 5,
                ..params
            },
            RenderParams {
                samples_per_pixel: 3,
                ..params
            },
            RenderParams {
                max_depth: Some(8),
                ..params
            },
            RenderParams {
                russian_roulette_depth: None,
                ..params
            },
            RenderParams { seed: 2, ..params },
            RenderParams {
                all_effects: true,
                ..params
            },
        ];
        for other in &changed {
            assert_ne!(render_hash(&files, other), base, "{other:?}");
        }
        let edited = vec![scene_file("a.toml".into(), b"y".to_vec())];
        assert_ne!(render_hash(&edited, &params), base);
    }

    #[test]
    fn a_tampered_scene_file_is_refused() {
        let toml = b"[camera]\nposition = [0, 0, -1]\nlook_at = [0, 0, 0]\n[[object]]\nshape = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"m\"\n[materials.m]\ntype = \"diffuse\"\n".to_vec();
        let mut file = SceneFile {
            name: "s.toml".into(),
            hash: *blake3::hash(&toml).as_bytes(),
            bytes: toml,
        };
        let params = RenderParams {
            width: 8,
            height: 6,
            samples_per_pixel: 1,
            seed: 3,
            ..RenderParams::default()
        };
        let scene = load_scene(vec![file.clone()], &params).unwrap();
        assert_eq!(
            (
                scene.settings.width,
                scene.settings.height,
                scene.settings.seed
            ),
            (8, 6, 3)
        );
        file.bytes.push(b'\n');
        assert!(matches!(
            load_scene(vec![file], &params),
            Err(BundleError::HashMismatch { .. })
        ));
    }
}
