//! The scene's `[media.NAME]` tables: each resolved by name where a material's `medium` or
//! `outside_medium` key or the camera's `medium` first names it, entering the scene then, and a
//! table that nothing uses is an error.

use super::error::{SceneError, line_of};
use super::format::MediumSpec;
use super::materials::unused_table;
use crate::medium::Medium;
use glam::Vec3;
use std::collections::{BTreeMap, BTreeSet};
use toml::Spanned;

/// The `[media.NAME]` tables, resolved by name where a `medium` key uses them; each enters
/// `Scene::media` once, when first used, in first-use order.
pub(crate) struct MediumTable<'a> {
    toml: &'a str,
    text: &'a str,
    defined: &'a BTreeMap<Spanned<String>, MediumSpec>,
    used: BTreeSet<String>,
    pub media: Vec<Medium>,
    ids: BTreeMap<String, u32>,
}

impl<'a> MediumTable<'a> {
    pub(crate) fn new(
        toml: &'a str,
        text: &'a str,
        defined: &'a BTreeMap<Spanned<String>, MediumSpec>,
    ) -> Self {
        MediumTable {
            toml,
            text,
            defined,
            used: BTreeSet::new(),
            media: Vec::new(),
            ids: BTreeMap::new(),
        }
    }

    /// The name medium `id` has in the TOML.
    pub(crate) fn name(&self, id: u32) -> &str {
        self.ids
            .iter()
            .find_map(|(name, &i)| (i == id).then_some(name.as_str()))
            .expect("every medium id was handed out by `medium` under a name")
    }

    /// The id of the medium `name`, referenced where `name`'s span says (`key` names the
    /// referencing key in messages).
    pub(crate) fn medium(&mut self, key: &str, name: &Spanned<String>) -> Result<u32, SceneError> {
        if let Some(&id) = self.ids.get(name.get_ref()) {
            return Ok(id);
        }
        let Some((definition, spec)) = self.defined.get_key_value(name.get_ref().as_str()) else {
            let line = line_of(self.text, name.span().start);
            let name = name.get_ref();
            let detail =
                format!("{key}: medium `{name}` is not defined: add a [media.{name}] table");
            return Err(SceneError::at_line(self.toml, line, detail));
        };
        let line = line_of(self.text, definition.span().start);
        let medium = medium_of(spec).map_err(|detail| {
            let detail = format!("[media.{}]: {detail}", definition.get_ref());
            SceneError::at_line(self.toml, line, detail)
        })?;
        let id = self.media.len() as u32;
        self.media.push(medium);
        self.ids.insert(name.get_ref().clone(), id);
        self.used.insert(name.get_ref().clone());
        Ok(id)
    }

    /// A `[media.NAME]` table that nothing used.
    pub(crate) fn unused_definition(&self) -> Option<SceneError> {
        unused_table(self.toml, self.text, self.defined, &self.used, |name| {
            format!(
                "[media.{name}] is used by no material's `medium` or `outside_medium` and not by the camera's `medium`"
            )
        })
    }
}

/// The medium a table describes: `sigma_a` and `sigma_s` (either may be left out, as 0), or
/// `albedo` and `density` (`sigma_s = albedo * density`, `sigma_a = density - sigma_s`). The
/// value checks (no negative coefficient, albedo in [0, 1], |g| < 1) ran when parsing.
fn medium_of(spec: &MediumSpec) -> Result<Medium, String> {
    let coefficients = spec.sigma_a.is_some() || spec.sigma_s.is_some();
    let albedo_form = spec.albedo.is_some() || spec.density.is_some();
    let (sigma_a, sigma_s) = match (coefficients, albedo_form) {
        (true, true) => {
            return Err(
                "give `sigma_a` and `sigma_s`, or `albedo` and `density`, not keys of both".into(),
            );
        }
        (false, false) => {
            return Err("needs `sigma_a` and `sigma_s`, or `albedo` and `density`".into());
        }
        (true, false) => (
            spec.sigma_a.map_or(Vec3::ZERO, |s| s.0),
            spec.sigma_s.map_or(Vec3::ZERO, |s| s.0),
        ),
        (false, true) => {
            let (Some(albedo), Some(density)) = (spec.albedo, spec.density) else {
                return Err("`albedo` and `density` go together: give both".into());
            };
            let sigma_s = albedo.0 * density.0;
            // Clamped: rounding must not leave a negative absorption at albedo 1.
            ((density.0 - sigma_s).max(Vec3::ZERO), sigma_s)
        }
    };
    if !(sigma_a + sigma_s).is_finite() {
        return Err("`sigma_a + sigma_s` overflows 32-bit floats".into());
    }
    Ok(Medium {
        sigma_a,
        sigma_s,
        g: spec.g.map_or(0.0, |g| g.0),
    })
}
