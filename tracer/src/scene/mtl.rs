//! MTL material libraries: our own line-aware parser and the mapping to [`Material`].
//!
//! tobj's MTL parser is not used: it panics on `Kd 0.5` (one component, which the MTL format
//! allows), keeps `# comments` and option flags in texture names, and reports no line numbers.
//! The parser here keeps each value's line, so a value that makes no sense as a material is
//! reported at its line. Only used materials are converted, so a bad value in an unused material
//! (or one replaced by a TOML `[materials.NAME]`) is harmless.
//!
//! The mapping, in order (documented in `scenes/README.md`):
//! 1. `Ke` with a component > 0 is the emission (any BSDF may emit);
//! 2. `illum 5` is a mirror with reflectance `Ks` (1 when absent);
//! 3. `illum 4`, `6` or `7`, or `d` < 1 with `Ni` given, is glass with index `Ni` (1.5 when
//!    absent) and tint `Tf` (1 when absent);
//! 4. `Ks` brighter than `Kd` with `Ns` given is a GGX conductor, `f0 = Ks`,
//!    `alpha = sqrt(2 / (Ns + 2))` (the Beckmann-Phong correspondence);
//! 5. otherwise diffuse: `map_Kd` when given (and then `Kd` is ignored, as Blender's importer
//!    does), else `Kd` (0.8 when absent).

use super::error::SceneError;
use super::obj::statements;
use crate::material::{Bsdf, Material, check_relative_ior};
use glam::Vec3;

/// A value and the 1-based line it was read from.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct At<T> {
    pub value: T,
    pub line: usize,
}

/// One `newmtl` block, as written.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct MtlMaterial {
    pub name: String,
    /// The MTL file (relative to the scene's folder) and the `newmtl` line.
    pub file: String,
    pub line: usize,
    kd: Option<At<Vec3>>,
    ks: Option<At<Vec3>>,
    ke: Option<At<Vec3>>,
    tf: Option<At<Vec3>>,
    ns: Option<At<f32>>,
    ni: Option<At<f32>>,
    d: Option<At<f32>>,
    illum: Option<At<u32>>,
    map_kd: Option<At<String>>,
}

/// Parses an MTL file.
pub(crate) fn parse(file: &str, bytes: &[u8]) -> Result<Vec<MtlMaterial>, SceneError> {
    let mut materials: Vec<MtlMaterial> = Vec::new();
    for statement in statements(file, bytes) {
        let (line, text) = statement?;
        let (keyword, rest) = text.split_once(char::is_whitespace).unwrap_or((text, ""));
        let rest = rest.trim();
        let err = |detail: String| SceneError::at_line(file, line, detail);
        if keyword == "newmtl" {
            if rest.is_empty() {
                return Err(err("`newmtl` without a name".into()));
            }
            if let Some(first) = materials.iter().find(|m| m.name == rest) {
                return Err(err(format!(
                    "material `{rest}` is defined twice (first at line {})",
                    first.line
                )));
            }
            let name = rest.to_owned();
            materials.push(MtlMaterial {
                name,
                file: file.to_owned(),
                line,
                ..Default::default()
            });
            continue;
        }
        let Some(current) = materials.last_mut() else {
            return Err(err(format!("`{keyword}` before any `newmtl`")));
        };
        let at = |value| At { value, line };
        match keyword {
            "Kd" => current.kd = Some(at(color(rest).map_err(err)?)),
            "Ks" => current.ks = Some(at(color(rest).map_err(err)?)),
            "Ke" => current.ke = Some(at(color(rest).map_err(err)?)),
            "Tf" => current.tf = Some(at(color(rest).map_err(err)?)),
            "Ns" => {
                current.ns = Some(At {
                    value: number(rest).map_err(err)?,
                    line,
                })
            }
            "Ni" => {
                current.ni = Some(At {
                    value: number(rest).map_err(err)?,
                    line,
                })
            }
            "d" => {
                current.d = Some(At {
                    value: number(rest).map_err(err)?,
                    line,
                })
            }
            // `Tr` is transparency, 1 - `d`; some exporters write it inverted, so `d` wins.
            "Tr" if current.d.is_none() => {
                current.d = Some(At {
                    value: 1.0 - number(rest).map_err(err)?,
                    line,
                })
            }
            "illum" => match rest.parse::<u32>() {
                Ok(model) if model <= 10 => current.illum = Some(At { value: model, line }),
                _ => {
                    return Err(err(format!(
                        "`illum {rest}`: expected an integer from 0 to 10"
                    )));
                }
            },
            "map_Kd" => {
                current.map_kd = Some(At {
                    value: texture_name(rest).map_err(err)?,
                    line,
                })
            }
            // Ambient colour, bump/normal maps and the rest have no counterpart in our materials.
            _ => {}
        }
    }
    Ok(materials)
}

impl MtlMaterial {
    /// A material known only by name: a `usemtl` that names a material of the scene's TOML,
    /// which replaces it, so its values are never read.
    pub(crate) fn named(name: &str, file: &str, line: usize) -> Self {
        MtlMaterial {
            name: name.to_owned(),
            file: file.to_owned(),
            line,
            ..Default::default()
        }
    }

    /// The material this MTL entry maps to. `load_texture` gets the `map_Kd` name as written
    /// and its line, and returns the texture's index in the scene.
    pub(crate) fn to_material(
        &self,
        load_texture: impl FnOnce(&str, usize) -> Result<u32, SceneError>,
    ) -> Result<Material, SceneError> {
        let emission = match &self.ke {
            Some(ke) if ke.value.max_element() > 0.0 => ke.value,
            _ => Vec3::ZERO,
        };
        let illum = self.illum.as_ref().map(|i| i.value);
        let glassy = self.d.as_ref().is_some_and(|d| d.value < 1.0) && self.ni.is_some();
        let bsdf = if illum == Some(5) {
            Bsdf::Mirror {
                reflectance: self.reflectance(&self.ks, Vec3::ONE, "Ks")?,
            }
        } else if matches!(illum, Some(4 | 6 | 7)) || glassy {
            let ior = match &self.ni {
                Some(ni) if ni.value < 1.0 => {
                    return Err(self.bad(
                        ni.line,
                        format!("`Ni {}` must be at least 1 for glass", ni.value),
                    ));
                }
                // Glass in MTL has air outside: `Ni` is the relative index itself.
                Some(ni) => check_relative_ior(ni.value)
                    .map_err(|e| self.bad(ni.line, format!("`Ni {}` {e}", ni.value)))?,
                None => 1.5,
            };
            Bsdf::Dielectric {
                ior,
                tint: self.reflectance(&self.tf, Vec3::ONE, "Tf")?,
            }
        } else if let Some(ns) = self.ns.as_ref().filter(|_| self.specular_dominates()) {
            if ns.value < 0.0 {
                return Err(self.bad(ns.line, format!("`Ns {}` must not be negative", ns.value)));
            }
            let alpha = (2.0 / (ns.value + 2.0)).sqrt().clamp(1e-3, 1.0);
            Bsdf::Conductor {
                f0: self.reflectance(&self.ks, Vec3::ONE, "Ks")?,
                alpha,
            }
        } else if let Some(map) = &self.map_kd {
            Bsdf::Diffuse {
                albedo: Vec3::ONE,
                texture: Some(load_texture(&map.value, map.line)?),
            }
        } else {
            Bsdf::Diffuse {
                albedo: self.reflectance(&self.kd, Vec3::splat(0.8), "Kd")?,
                texture: None,
            }
        };
        Ok(Material {
            name: self.name.clone(),
            bsdf,
            emission,
            // MTL has no media; a TOML material of the same name can bind one.
            interior: None,
            // The loader puts every MTL material in the camera's medium
            // (`MaterialTable::place_outside`).
            exterior: None,
        })
    }

    fn specular_dominates(&self) -> bool {
        let max = |c: &Option<At<Vec3>>| c.as_ref().map_or(0.0, |c| c.value.max_element());
        max(&self.ks) > max(&self.kd)
    }

    /// A colour used as a reflectance: components above 1 would create energy.
    fn reflectance(
        &self,
        c: &Option<At<Vec3>>,
        default: Vec3,
        key: &str,
    ) -> Result<Vec3, SceneError> {
        match c {
            Some(c) if c.value.max_element() > 1.0 => Err(self.bad(
                c.line,
                format!(
                    "`{key}` {} exceeds 1 (it would create energy); fix the file or replace the \
                     material with a [materials.{}] table in the scene",
                    c.value, self.name
                ),
            )),
            Some(c) => Ok(c.value),
            None => Ok(default),
        }
    }

    fn bad(&self, line: usize, detail: String) -> SceneError {
        SceneError::at_line(
            &self.file,
            line,
            format!("material `{}`: {detail}", self.name),
        )
    }
}

/// `r [g b]`: one number is grey. Finite and non-negative.
fn color(rest: &str) -> Result<Vec3, String> {
    if rest.starts_with("spectral") || rest.starts_with("xyz") {
        return Err(format!("`{rest}`: only RGB colours are supported"));
    }
    let values = rest
        .split_whitespace()
        .map(parse_number)
        .collect::<Result<Vec<_>, _>>()?;
    let c = match values[..] {
        [v] => Vec3::splat(v),
        [r, g, b] => Vec3::new(r, g, b),
        _ => return Err(format!("`{rest}`: expected 1 or 3 numbers")),
    };
    if c.min_element() < 0.0 {
        return Err(format!("`{rest}`: colour components must not be negative"));
    }
    Ok(c)
}

fn number(rest: &str) -> Result<f32, String> {
    match rest.split_whitespace().collect::<Vec<_>>()[..] {
        [v] => parse_number(v),
        _ => Err(format!("`{rest}`: expected one number")),
    }
}

/// A finite `f32`; Rust parses out-of-range values (`1e39`) as infinity, which is refused here.
pub(crate) fn parse_number(word: &str) -> Result<f32, String> {
    match word.parse::<f32>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("`{word}` is not a finite 32-bit number")),
        Err(_) => Err(format!("`{word}` is not a number")),
    }
}

/// The file name of a `map_Kd` statement. Options (`-s 1 1 1 name`) come before the name; they
/// are dropped with a warning and the last word is taken as the name.
fn texture_name(rest: &str) -> Result<String, String> {
    if rest.is_empty() {
        return Err("`map_Kd` without a file name".into());
    }
    if rest.starts_with('-') {
        let name = rest.split_whitespace().last().unwrap_or_default();
        tracing::warn!("map_Kd options ignored in `map_Kd {rest}`; using `{name}`");
        return Ok(name.to_owned());
    }
    Ok(rest.to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(text: &str) -> Result<Material, SceneError> {
        parse("a.mtl", text.as_bytes())?
            .remove(0)
            .to_material(|_, _| Ok(7))
    }

    #[test]
    fn the_mapping_follows_the_documented_order() {
        let light = one("newmtl l\nKd 0.78 0.78 0.78\nKe 17 12 4 # warm\n").unwrap();
        assert_eq!(light.emission, Vec3::new(17.0, 12.0, 4.0));
        assert_eq!(
            light.bsdf,
            Bsdf::Diffuse {
                albedo: Vec3::splat(0.78),
                texture: None
            }
        );
        let mirror = one("newmtl m\nKd 0.01\nKs 0.95 0.95 0.95\nillum 5\n").unwrap();
        assert_eq!(
            mirror.bsdf,
            Bsdf::Mirror {
                reflectance: Vec3::splat(0.95)
            }
        );
        let glass =
            one("newmtl g\r\nKs 0.3 0.3 0.3\r\nTf 0.1 0.1 0.1\r\nNi 2.5\r\nillum 7\r\n").unwrap();
        assert_eq!(
            glass.bsdf,
            Bsdf::Dielectric {
                ior: 2.5,
                tint: Vec3::splat(0.1)
            }
        );
        let dissolved = one("newmtl g\nd 0.5\nNi 1.33\n").unwrap();
        assert_eq!(
            dissolved.bsdf,
            Bsdf::Dielectric {
                ior: 1.33,
                tint: Vec3::ONE
            }
        );
        let metal = one("newmtl c\nKd 0.1\nKs 0.9 0.6 0.2\nNs 98\n").unwrap();
        assert_eq!(
            metal.bsdf,
            Bsdf::Conductor {
                f0: Vec3::new(0.9, 0.6, 0.2),
                alpha: (0.02f32).sqrt()
            }
        );
        let textured = one("newmtl t\nKd 0.5 0.5 0.5\nmap_Kd tex/A B.jpg # note\n").unwrap();
        assert_eq!(
            textured.bsdf,
            Bsdf::Diffuse {
                albedo: Vec3::ONE,
                texture: Some(7)
            }
        );
        let opaque_with_ni = one("newmtl w\nNs 10\nNi 1.5\nd 1\nTr 0\nKs 0 0 0\nKd 0.5\n").unwrap();
        assert_eq!(
            opaque_with_ni.bsdf,
            Bsdf::Diffuse {
                albedo: Vec3::splat(0.5),
                texture: None
            }
        );
    }

    #[test]
    fn names_are_trimmed_and_values_checked_at_their_line() {
        let mats = parse("a.mtl", b"newmtl tallBox \r\nKd 0.5\r\n").unwrap();
        assert_eq!(mats[0].name, "tallBox");
        let e = one("newmtl x\nKd 1.5 0.2 0.2\n").unwrap_err();
        assert_eq!((e.file(), e.line()), ("a.mtl", Some(2)));
        assert!(e.to_string().contains("exceeds 1"), "{e}");
        let e = parse("a.mtl", b"newmtl x\n\nKe 1 nan 2\n").unwrap_err();
        assert_eq!(e.line(), Some(3));
        let e = parse("a.mtl", b"Kd 1 1 1\n").unwrap_err();
        assert!(e.to_string().contains("before any `newmtl`"), "{e}");
        let e = parse("a.mtl", b"newmtl x\nnewmtl y\nnewmtl x\n").unwrap_err();
        assert_eq!(e.line(), Some(3));
    }

    #[test]
    fn glass_indices_are_held_to_the_relative_range() {
        // MTL glass has air outside, so `Ni` is the relative index: refused above the range's
        // top, at its line; the top itself and real glasses load.
        for ni in ["1000.5", "1e6", "3e38"] {
            let e = one(&format!("newmtl g\nillum 7\nNi {ni}\n")).unwrap_err();
            assert_eq!((e.file(), e.line()), ("a.mtl", Some(3)), "{e}");
            assert!(
                e.to_string().contains("relative index of refraction"),
                "{e}"
            );
        }
        for ni in ["1", "1.5", "2.42", "1000"] {
            one(&format!("newmtl g\nillum 7\nNi {ni}\n")).unwrap();
        }
    }
}
