//! The TOML scene format: its serde types, and the conversion of TOML errors to file:line:key.
//!
//! Every table denies unknown keys, so a typo is an error rather than a silently ignored setting.
//! Value checks that need no context (finite numbers, reflectances within [0, 1], positive
//! counts) run inside deserialisation, so the toml crate attaches the value's span and key path
//! to them; checks across keys (which keys a shape takes, whether a material exists) run in the
//! loader with the spans kept here. The format is documented key by key in `scenes/README.md`;
//! the checked value types are in `values.rs`.

use super::error::{SceneError, line_of};
use serde::Deserialize;
use std::collections::BTreeMap;
use toml::Spanned;

// The checked values the tables hold, here too, where the loader has always looked for them.
pub(crate) use super::values::*;

/// The whole scene file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct SceneSpec {
    #[serde(default)]
    pub render: RenderSpec,
    pub camera: Spanned<CameraSpec>,
    #[serde(default, rename = "object")]
    pub objects: Vec<Spanned<ObjectSpec>>,
    #[serde(default)]
    pub materials: BTreeMap<Spanned<String>, MaterialSpec>,
    #[serde(default, rename = "light")]
    pub lights: Vec<LightSpec>,
    #[serde(default)]
    pub media: BTreeMap<Spanned<String>, MediumSpec>,
    pub environment: Option<Spanned<EnvironmentSpec>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(crate) struct RenderSpec {
    pub width: Count,
    pub height: Count,
    pub spp: Count,
    pub max_depth: Limit<Unlimited>,
    pub russian_roulette_depth: Limit<Off>,
    pub seed: u64,
    pub frames: Option<FrameCount>,
}

impl Default for RenderSpec {
    fn default() -> Self {
        RenderSpec {
            width: Count(512),
            height: Count(512),
            spp: Count(16),
            max_depth: Limit::new(Some(8)),
            russian_roulette_depth: Limit::new(Some(3)),
            seed: 0,
            frames: None,
        }
    }
}

/// A fixed camera (`position`, `look_at`, ...) or keyframes (`[[camera.keys]]`), whose missing
/// fields default to the ones given here.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CameraSpec {
    pub position: Option<Point>,
    pub look_at: Option<Point>,
    pub up: Option<Point>,
    pub vfov: Option<Fov>,
    pub aperture_radius: Option<NonNegative>,
    pub focus_distance: Option<Positive>,
    /// The medium outside every object, where the camera starts: global fog.
    pub medium: Option<Spanned<String>>,
    /// When the shutter opens and closes around each frame, in frames.
    pub shutter: Option<ShutterSpec>,
    #[serde(default)]
    pub keys: Vec<Spanned<CameraKeySpec>>,
}

/// One `[[camera.keys]]` entry; `serde(flatten)` would lose spans and `deny_unknown_fields`, so
/// the pose keys are spelled out twice.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CameraKeySpec {
    pub frame: u32,
    pub position: Option<Point>,
    pub look_at: Option<Point>,
    pub up: Option<Point>,
    pub vfov: Option<Fov>,
    pub aperture_radius: Option<NonNegative>,
    pub focus_distance: Option<Positive>,
}

/// The pose keys of `[camera]` or of one of its keys; missing ones are `None`.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Pose {
    pub position: Option<Point>,
    pub look_at: Option<Point>,
    pub up: Option<Point>,
    pub vfov: Option<Fov>,
    pub aperture_radius: Option<NonNegative>,
    pub focus_distance: Option<Positive>,
}

impl Pose {
    /// This pose with its missing keys taken from `fallback`.
    pub(crate) fn or(self, fallback: Pose) -> Pose {
        Pose {
            position: self.position.or(fallback.position),
            look_at: self.look_at.or(fallback.look_at),
            up: self.up.or(fallback.up),
            vfov: self.vfov.or(fallback.vfov),
            aperture_radius: self.aperture_radius.or(fallback.aperture_radius),
            focus_distance: self.focus_distance.or(fallback.focus_distance),
        }
    }
}

impl CameraSpec {
    pub(crate) fn pose(&self) -> Pose {
        Pose {
            position: self.position,
            look_at: self.look_at,
            up: self.up,
            vfov: self.vfov,
            aperture_radius: self.aperture_radius,
            focus_distance: self.focus_distance,
        }
    }
}

impl CameraKeySpec {
    pub(crate) fn pose(&self) -> Pose {
        Pose {
            position: self.position,
            look_at: self.look_at,
            up: self.up,
            vfov: self.vfov,
            aperture_radius: self.aperture_radius,
            focus_distance: self.focus_distance,
        }
    }
}

/// One `[[object]]`: an OBJ file or a procedural shape, plus an optional transform. Which keys
/// apply to which kind is checked by the loader, which knows the table's span.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ObjectSpec {
    pub obj: Option<Spanned<String>>,
    pub shape: Option<ShapeKind>,
    pub material: Option<Spanned<String>>,
    pub center: Option<Point>,
    pub radius: Option<Positive>,
    pub subdivisions: Option<u32>,
    pub inward: Option<bool>,
    pub perturb: Option<Fraction>,
    pub seed: Option<u64>,
    pub smooth: Option<bool>,
    pub corners: Option<Corners>,
    pub min: Option<Point>,
    pub max: Option<Point>,
    pub translate: Option<Point>,
    pub scale: Option<Scale>,
    pub rotate_x: Option<Finite>,
    pub rotate_y: Option<Finite>,
    pub rotate_z: Option<Finite>,
    /// Keyframed transforms (`[[object.keys]]`): the object moves.
    #[serde(default)]
    pub keys: Vec<Spanned<ObjectKeySpec>>,
}

/// One `[[object.keys]]` entry: a frame and any of the object's transform keys, the rest taken
/// from the object.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ObjectKeySpec {
    pub frame: u32,
    pub translate: Option<Point>,
    pub scale: Option<Scale>,
    pub rotate_x: Option<Finite>,
    pub rotate_y: Option<Finite>,
    pub rotate_z: Option<Finite>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum ShapeKind {
    Sphere,
    Quad,
    Box,
}

/// A `[materials.NAME]` table.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct MaterialSpec {
    #[serde(rename = "type")]
    pub kind: Option<MaterialKind>,
    pub albedo: Option<Reflectance>,
    pub texture: Option<Spanned<String>>,
    pub reflectance: Option<Reflectance>,
    pub ior: Option<Ior>,
    /// The index of what surrounds a glass (any finite number above 0); index 1 when left out.
    pub outside_ior: Option<Positive>,
    /// A dispersive glass's index: Cauchy's `[A, B]`, Sellmeier's six coefficients, or a name.
    pub cauchy: Option<Cauchy>,
    pub sellmeier: Option<Sellmeier>,
    pub glass: Option<GlassName>,
    pub tint: Option<Reflectance>,
    pub roughness: Option<Roughness>,
    pub emission: Option<Emitted>,
    /// The medium inside the object (glass and interfaces only).
    pub medium: Option<Spanned<String>>,
    /// The medium outside the object (glass and interfaces only); the camera's when left out.
    pub outside_medium: Option<Spanned<String>>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum MaterialKind {
    Diffuse,
    Mirror,
    Glass,
    Metal,
    Emissive,
    Interface,
}

/// A `[media.NAME]` table: `sigma_a` and `sigma_s`, or `albedo` and `density`, and `g`. Which
/// keys go together is checked by the loader.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct MediumSpec {
    pub sigma_a: Option<Radiance>,
    pub sigma_s: Option<Radiance>,
    pub albedo: Option<Reflectance>,
    pub density: Option<Radiance>,
    pub g: Option<Anisotropy>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct LightSpec {
    #[serde(rename = "type")]
    pub kind: LightKind,
    pub position: Point,
    pub intensity: Emitted,
}

#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum LightKind {
    Point,
}

/// `[environment]`: a constant `radiance`, or a `map` with its `scale` and `rotate`, and either
/// with `portals`. Which keys
/// go together is checked by the loader.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct EnvironmentSpec {
    pub radiance: Option<Emitted>,
    pub map: Option<Spanned<String>>,
    pub scale: Option<Emitted>,
    pub rotate: Option<Finite>,
    pub portals: Option<Spanned<Vec<Corners>>>,
}

/// Parses a scene file; errors name `file`, the line and the key path.
pub(crate) fn parse(file: &str, text: &str) -> Result<SceneSpec, SceneError> {
    toml::from_str(text).map_err(|mut e| {
        let line = e.span().map_or(1, |span| line_of(text, span.start));
        // The key path is only printed when the error has no source text attached.
        e.set_input(None);
        let rendered = e.to_string();
        let detail = match rendered.lines().find_map(|l| l.strip_prefix("in `")) {
            Some(keys) => format!("{} (key `{}`)", e.message(), keys.trim_end_matches('`')),
            None => e.message().to_owned(),
        };
        SceneError::at_line(file, line, detail)
    })
}
