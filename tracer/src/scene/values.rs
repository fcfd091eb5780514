//! The scene format's checked values: the types `format.rs`'s tables hold where a TOML value
//! must be more than its TOML type says (a finite number, a reflectance within [0, 1], a count
//! of at least 1, a depth or the word that means none, an index of refraction, a dispersion
//! formula), each checked as it is deserialised, so that the toml crate attaches the value's
//! span and key path to a refusal (the file, the line and the key a user sees).

use crate::material::{Dispersion, GLASSES};
use glam::Vec3;
use serde::Deserialize;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use std::fmt;

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
    /// A limit of `value` (`None`: the word, no limit), for the format's defaults.
    pub(super) fn new(value: Option<u32>) -> Self {
        Limit {
            value,
            word: std::marker::PhantomData,
        }
    }
}

/// A number of frames, 1 to [`super::MAX_FRAMES`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct FrameCount(pub u32);
/// An emitted radiance or intensity, or a factor on one: from 0 to [`super::MAX_RADIANCE`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct Emitted(pub Vec3);
/// A finite point or vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Point(pub Vec3);
/// Four finite corners, of a quad or a portal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Corners(pub [Vec3; 4]);
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
checked_type!(
    FrameCount,
    u32,
    |v| if (1..=super::MAX_FRAMES).contains(&v) {
        Ok(v)
    } else {
        Err(format!("must be from 1 to {} (2^24)", super::MAX_FRAMES))
    }
);
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
checked_type!(Emitted, Triple<1>, |v| {
    finite(v.0).and_then(|c| {
        if !c.cmpge(Vec3::ZERO).all() {
            Err("must not be negative".to_owned())
        } else if !c.cmple(Vec3::splat(super::MAX_RADIANCE)).all() {
            Err(format!("must be at most {:e}", super::MAX_RADIANCE))
        } else {
            Ok(c)
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

checked_type!(Corners, Vec<Point>, |v| {
    // A Vec rather than `[Point; 4]`: serde's arrays ignore elements beyond their length.
    match v.as_slice() {
        &[a, b, c, d] => Ok([a.0, b.0, c.0, d.0]),
        _ => Err(format!(
            "must be four corners `[[x, y, z], ...]`, not {}",
            v.len()
        )),
    }
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
