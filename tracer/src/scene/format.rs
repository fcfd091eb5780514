//! The TOML scene format: its serde types, and the conversion of TOML errors to file:line:key.
//!
//! Every table denies unknown keys, so a typo is an error rather than a silently ignored setting.
//! Value checks that need no context (finite numbers, reflectances within [0, 1], positive
//! counts) run inside deserialisation, so the toml crate attaches the value's span and key path
//! to them; checks across keys (which keys a shape takes, whether a material exists) run in the
//! loader with the spans kept here. The format is documented key by key in `scenes/README.md`.

use super::error::{SceneError, line_of};
use crate::material::{Dispersion, GLASSES};
use glam::Vec3;
use serde::Deserialize;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use std::collections::BTreeMap;
use std::fmt;
use toml::Spanned;

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
    pub frames: Option<Count>,
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
    pub corners: Option<[Point; 4]>,
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
    pub emission: Option<Radiance>,
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
    pub intensity: Radiance,
}

#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum LightKind {
    Point,
}

/// `[environment]`: a constant `radiance`, or a `map` with its `scale` and `rotate`. Which keys
/// go together is checked by the loader.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct EnvironmentSpec {
    pub radiance: Option<Radiance>,
    pub map: Option<Spanned<String>>,
    pub scale: Option<Radiance>,
    pub rotate: Option<Finite>,
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

/// An integer of at least 1.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Count(pub u32);

/// A depth limit: an integer of at least `W::MIN` or the word `W::WORD` (no limit).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Limit<W> {
    pub value: Option<u32>,
    word: std::marker::PhantomData<W>,
}

pub(crate) trait Word {
    const WORD: &'static str;
    const MIN: u32;
}
#[derive(Clone, Copy, Debug)]
pub(crate) struct Unlimited;
#[derive(Clone, Copy, Debug)]
pub(crate) struct Off;
/// `max_depth` counts scattering events (pbrt's convention): 0 shows emitters only.
impl Word for Unlimited {
    const WORD: &'static str = "unlimited";
    const MIN: u32 = 0;
}
impl Word for Off {
    const WORD: &'static str = "off";
    const MIN: u32 = 1;
}

impl<W> Limit<W> {
    fn new(value: Option<u32>) -> Self {
        Limit {
            value,
            word: std::marker::PhantomData,
        }
    }
}

/// A finite point or vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Point(pub Vec3);
/// A finite number.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Finite(pub f32);
/// A finite number greater than 0.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Positive(pub f32);
/// A finite number of at least 0.
#[derive(Clone, Copy, Debug)]
pub(crate) struct NonNegative(pub f32);
/// A number in [0, 0.5).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Fraction(pub f32);
/// A vertical field of view in degrees, in (0, 180).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Fov(pub f32);
/// An index of refraction, at least 1.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ior(pub f32);
/// Cauchy's `[A, B]` (B in um^2): an index of at least 1 over the rendered wavelengths.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Cauchy(pub Dispersion);
/// Sellmeier's `[B1, B2, B3, C1, C2, C3]` (C in um^2): not negative, no pole among the rendered
/// wavelengths, an index of at least 1 over them.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sellmeier(pub Dispersion);
/// The name of a catalogue glass ([`GLASSES`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct GlassName(pub Dispersion);
/// A Henyey-Greenstein asymmetry in (-1, 1).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Anisotropy(pub f32);
/// A GGX roughness (alpha) in (0, 1].
#[derive(Clone, Copy, Debug)]
pub(crate) struct Roughness(pub f32);
/// A colour with every component in [0, 1]: a number (grey) or `[r, g, b]`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Reflectance(pub Vec3);
/// A colour with finite, non-negative components: a number (grey) or `[r, g, b]`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Radiance(pub Vec3);
/// A scale: a number (uniform) or `[x, y, z]`, every component finite and non-zero.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scale(pub Vec3);
/// A shutter interval `[open, close]` in frames around the frame: finite, `open <= close`, both
/// within one frame of it, open for one frame at most (`[0, 1]`: a 360-degree shutter).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ShutterSpec(pub [f32; 2]);

/// Deserialises a value of type `T` with `check`, whose error message the toml crate places at
/// the value's line and key.
fn checked<'de, D, T, O>(d: D, check: impl FnOnce(T) -> Result<O, String>) -> Result<O, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    check(T::deserialize(d)?).map_err(de::Error::custom)
}

macro_rules! checked_type {
    ($name:ident, $raw:ty, |$v:ident| $body:expr) => {
        impl<'de> Deserialize<'de> for $name {
            fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                checked(d, |$v: $raw| $body.map($name))
            }
        }
    };
}

checked_type!(Count, u32, |v| if v >= 1 {
    Ok(v)
} else {
    Err("must be at least 1".to_owned())
});
checked_type!(Point, Triple<3>, |v| finite(v.0));
checked_type!(Finite, f32, |v| if v.is_finite() {
    Ok(v)
} else {
    Err(not_finite())
});
checked_type!(Positive, f32, |v| in_range(
    v,
    |v| v > 0.0,
    "must be greater than 0"
));
checked_type!(NonNegative, f32, |v| in_range(
    v,
    |v| v >= 0.0,
    "must not be negative"
));
checked_type!(Fraction, f32, |v| in_range(
    v,
    |v| (0.0..0.5).contains(&v),
    "must be in [0, 0.5)"
));
checked_type!(Fov, f32, |v| in_range(
    v,
    |v| v > 0.0 && v < 180.0,
    "must be in (0, 180) degrees"
));
checked_type!(Ior, f32, |v| in_range(
    v,
    |v| v >= 1.0,
    "must be at least 1"
));
checked_type!(Cauchy, Vec<f32>, |v| Dispersion::cauchy(&v));
checked_type!(Sellmeier, Vec<f32>, |v| Dispersion::sellmeier(&v));
checked_type!(GlassName, String, |v| Dispersion::named(&v).ok_or_else(
    || {
        let names: Vec<_> = GLASSES.iter().map(|(n, _)| format!("\"{n}\"")).collect();
        format!("unknown glass \"{v}\": use one of {}", names.join(", "))
    }
));
checked_type!(Anisotropy, f32, |v| in_range(
    v,
    |v| v > -1.0 && v < 1.0,
    "must be in (-1, 1): |g| = 1 is a delta, not a phase function"
));
checked_type!(Roughness, f32, |v| in_range(
    v,
    |v| v > 0.0 && v <= 1.0,
    "must be in (0, 1]"
));
checked_type!(Reflectance, Triple<1>, |v| {
    finite(v.0).and_then(|c| {
        let ok = c.cmpge(Vec3::ZERO).all() && c.cmple(Vec3::ONE).all();
        if ok {
            Ok(c)
        } else {
            Err("every component must be in [0, 1]".to_owned())
        }
    })
});
checked_type!(Radiance, Triple<1>, |v| {
    finite(v.0).and_then(|c| {
        if c.cmpge(Vec3::ZERO).all() {
            Ok(c)
        } else {
            Err("must not be negative".to_owned())
        }
    })
});
checked_type!(Scale, Triple<1>, |v| {
    finite(v.0).and_then(|c| {
        if c.cmpne(Vec3::ZERO).all() {
            Ok(c)
        } else {
            Err("must not be 0".to_owned())
        }
    })
});

checked_type!(ShutterSpec, Vec<f32>, |v| {
    // A Vec rather than `[f32; 2]`: serde's arrays ignore elements beyond their length.
    let &[open, close] = v.as_slice() else {
        return Err(format!(
            "must be two numbers `[open, close]`, not {}",
            v.len()
        ));
    };
    if !open.is_finite() || !close.is_finite() {
        Err(not_finite())
    } else if open > close {
        Err(format!(
            "[{open}, {close}] closes before it opens (give `[open, close]`)"
        ))
    } else if open.abs() > 1.0 || close.abs() > 1.0 {
        Err(format!(
            "[{open}, {close}] must lie within one frame of the frame, in [-1, 1]"
        ))
    } else if close - open > 1.0 {
        Err(format!(
            "[{open}, {close}] stays open {} frames, more than one",
            close - open
        ))
    } else {
        Ok([open, close])
    }
});

fn not_finite() -> String {
    "must be a finite number (it overflows 32-bit floats or is nan/inf)".to_owned()
}

fn finite(v: Vec3) -> Result<Vec3, String> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(not_finite())
    }
}

fn in_range(v: f32, ok: impl Fn(f32) -> bool, what: &str) -> Result<f32, String> {
    if !v.is_finite() {
        Err(not_finite())
    } else if ok(v) {
        Ok(v)
    } else {
        Err(format!("{v} {what}"))
    }
}

/// `[x, y, z]`, or when `SINGLE` is 1 also a single number standing for `[x, x, x]`.
struct Triple<const SINGLE: usize>(Vec3);

impl<'de, const SINGLE: usize> Deserialize<'de> for Triple<SINGLE> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<const S: usize>;
        impl<'de, const S: usize> Visitor<'de> for V<S> {
            type Value = Triple<S>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str(if S == 1 {
                    "a number or an array of 3 numbers"
                } else {
                    "an array of 3 numbers"
                })
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
                if S == 1 {
                    Ok(Triple(Vec3::splat(v as f32)))
                } else {
                    Err(E::invalid_type(de::Unexpected::Float(v), &self))
                }
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
                self.visit_f64(v as f64)
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
                self.visit_f64(v as f64)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
                let mut c = [0.0f32; 3];
                for (i, slot) in c.iter_mut().enumerate() {
                    *slot = seq
                        .next_element()?
                        .ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                if seq.next_element::<f32>()?.is_some() {
                    return Err(de::Error::invalid_length(4, &self));
                }
                Ok(Triple(Vec3::from(c)))
            }
        }
        d.deserialize_any(V::<SINGLE>)
    }
}

impl<'de, W: Word> Deserialize<'de> for Limit<W> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<W>(std::marker::PhantomData<W>);
        impl<'de, W: Word> Visitor<'de> for V<W> {
            type Value = Limit<W>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                write!(f, "an integer of at least {} or \"{}\"", W::MIN, W::WORD)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
                match u64::try_from(v) {
                    Ok(v) => self.visit_u64(v),
                    Err(_) => Err(limit_error(v, W::MIN, W::WORD)),
                }
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
                match u32::try_from(v) {
                    Ok(v) if v >= W::MIN => Ok(Limit::new(Some(v))),
                    _ => Err(limit_error(v, W::MIN, W::WORD)),
                }
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<Self::Value, E> {
                if v == W::WORD {
                    Ok(Limit::new(None))
                } else {
                    Err(E::invalid_value(de::Unexpected::Str(v), &self))
                }
            }
        }
        d.deserialize_any(V(std::marker::PhantomData))
    }
}

fn limit_error<E: de::Error>(v: impl fmt::Display, min: u32, word: &str) -> E {
    E::custom(format!(
        "{v} is not allowed: use an integer from {min} to {}, or \"{word}\"",
        u32::MAX
    ))
}
