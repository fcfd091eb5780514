//! What arrives from outside the scene: a constant radiance, or an HDR lat-long map, and how the
//! map is importance-sampled.
//!
//! The map is equirectangular about the world's +y axis: row 0 (the top) looks straight up, the
//! bottom row straight down, and along a row the azimuth turns from -z (the left edge) through
//! +x (three quarters across) with the centre column looking along +z, before `rotate` turns the
//! whole map right-handedly about +y. Texels are looked up nearest, not filtered, so the radiance
//! is piecewise constant over the (u, v) cells, exactly like the distribution that samples it:
//! cells are chosen by luminance times sin(theta) (the solid angle a cell covers shrinks towards
//! the poles), so the estimate's variance comes from colour and from sin(theta) varying within a
//! cell only. The density in solid angle is the (u, v) density over `2 pi^2 sin(theta)`.
//!
//! `portal`: the windows a scene may declare for its environment, and the sampling of the
//! directions through them.

pub(crate) use portal::PortalDraws;
pub use portal::{MIN_SOLID_ANGLE, Portal, PortalSampler};

use crate::distribution::Distribution2D;
use crate::lights::luminance;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

mod portal;

/// Radiance arriving along every direction that escapes the scene.
#[derive(Clone, Debug, PartialEq)]
pub enum Environment {
    /// The same radiance from everywhere.
    Constant(Vec3),
    /// An HDR lat-long image.
    Map(EnvironmentMap),
}

/// A lat-long environment map, already multiplied by its scale.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvironmentMap {
    /// Texels around the horizon, a full turn of azimuth; the middle column looks along +z
    /// before the map's rotation, the first and last along -z.
    pub width: u32,
    /// Texels from the top (+y) to the bottom (-y) pole, each row a band of equal polar angle.
    pub height: u32,
    /// Linear RGB radiance, row-major, top row (+y) first; finite and non-negative.
    pub texels: Vec<Vec3>,
    /// The turn of the map about +y, as (sin, cos) of its angle.
    pub rotation: (f32, f32),
}

/// Where a direction meets the environment: what arrives along it, and on a map the cell it
/// falls in with its `sin(theta)`, from which the map's sampling density of the direction is
/// found ([`MapSampler::pdf_of`]). Worked out once for both: a map's cell takes two arc
/// tangents, which a ray that escapes, and a sample drawn through a portal, both need for
/// the radiance and again for the density (some 7 % of a render under a sky map).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkyLook {
    /// The radiance arriving along the direction.
    pub radiance: Vec3,
    /// On a map: the map coordinates of the direction and its `sin(theta)`.
    map: Option<(Vec2, f32)>,
}

impl Environment {
    /// The radiance arriving along the unit direction `dir` (pointing away from the scene).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        match self {
            Environment::Constant(radiance) => *radiance,
            Environment::Map(map) => map.radiance(dir),
        }
    }

    /// [`Environment::radiance`] along `dir`, with what the map's density of `dir` is found
    /// from: the same values as asking for each apart.
    pub fn look(&self, dir: Vec3) -> SkyLook {
        match self {
            Environment::Constant(radiance) => SkyLook {
                radiance: *radiance,
                map: None,
            },
            Environment::Map(map) => {
                let uv = map.to_uv(dir);
                SkyLook {
                    radiance: map.texel(uv),
                    map: Some((uv, sin_theta(dir))),
                }
            }
        }
    }

    /// Whether nothing at all arrives (then the environment is no effect of the scene's).
    pub fn is_black(&self) -> bool {
        match self {
            Environment::Constant(radiance) => *radiance == Vec3::ZERO,
            Environment::Map(map) => map.texels.iter().all(|&t| t == Vec3::ZERO),
        }
    }

    /// The luminance of the radiance averaged over all directions.
    pub fn mean_luminance(&self) -> f32 {
        match self {
            Environment::Constant(radiance) => luminance(*radiance),
            Environment::Map(map) => map.mean_luminance(),
        }
    }
}

impl EnvironmentMap {
    /// A map of `width` x `height` texels (row-major, top first) turned by `rotate_degrees`
    /// about +y.
    pub fn new(width: u32, height: u32, texels: Vec<Vec3>, rotate_degrees: f32) -> Self {
        assert_eq!(
            texels.len(),
            width as usize * height as usize,
            "texel count must match the size"
        );
        Self {
            width,
            height,
            texels,
            rotation: crate::math::sin_cos(rotate_degrees.to_radians()),
        }
    }

    /// The radiance along world direction `dir`.
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        self.texel(self.to_uv(dir))
    }

    fn texel(&self, uv: Vec2) -> Vec3 {
        let x = ((uv.x * self.width as f32) as u32).min(self.width - 1);
        let y = ((uv.y * self.height as f32) as u32).min(self.height - 1);
        self.texels[(y * self.width + x) as usize]
    }

    /// The map coordinates of world direction `dir`, each in [0, 1].
    pub fn to_uv(&self, dir: Vec3) -> Vec2 {
        let (sin, cos) = self.rotation;
        // Undo the map's turn: world to map space.
        let x = dir.x * cos - dir.z * sin;
        let z = dir.x * sin + dir.z * cos;
        // atan2 rather than acos: it keeps its precision near the poles.
        let theta = crate::math::atan2(sin_theta(dir), dir.y);
        let phi = crate::math::atan2(x, z);
        Vec2::new(0.5 + phi * (0.5 / PI), theta * (1.0 / PI))
    }

    /// The world direction at map coordinates `uv`, with sin(theta) (for the density).
    pub fn direction(&self, uv: Vec2) -> (Vec3, f32) {
        let theta = PI * uv.y;
        let phi = 2.0 * PI * (uv.x - 0.5);
        let (sin_theta, cos_theta) = crate::math::sin_cos(theta);
        let (sin_phi, cos_phi) = crate::math::sin_cos(phi);
        let (x, z) = (sin_theta * sin_phi, sin_theta * cos_phi);
        let (sin, cos) = self.rotation;
        let dir = Vec3::new(x * cos + z * sin, cos_theta, z * cos - x * sin);
        (dir, sin_theta)
    }

    /// Each texel's luminance times the sine of its row's centre: the weights of the sampling
    /// distribution, proportional to each texel's share of the arriving power.
    fn weights(&self) -> Vec<f32> {
        let h = self.height as f32;
        self.texels
            .chunks(self.width as usize)
            .enumerate()
            .flat_map(|(row, texels)| {
                let sin_theta = crate::math::sin(PI * (row as f32 + 0.5) / h);
                texels.iter().map(move |&t| luminance(t) * sin_theta)
            })
            .collect()
    }

    /// The luminance averaged over the sphere: each row weighted by the exact solid angle of
    /// its band, `2 pi (cos theta_top - cos theta_bottom)`.
    fn mean_luminance(&self) -> f32 {
        let h = f64::from(self.height);
        let mut sum = 0.0f64;
        for (row, texels) in self.texels.chunks(self.width as usize).enumerate() {
            let top = crate::math::sin_cos_f64(std::f64::consts::PI * row as f64 / h).1;
            let bottom = crate::math::sin_cos_f64(std::f64::consts::PI * (row + 1) as f64 / h).1;
            let row_sum: f64 = texels.iter().map(|&t| f64::from(luminance(t))).sum();
            sum += row_sum / f64::from(self.width) * 0.5 * (top - bottom);
        }
        sum as f32
    }
}

/// The sine of the angle between `dir` and +y, from the components across the axis: near the
/// poles `sqrt(1 - y^2)` would cancel away most of its digits.
fn sin_theta(dir: Vec3) -> f32 {
    (dir.x * dir.x + dir.z * dir.z).sqrt()
}

/// A sampled direction towards the environment.
#[derive(Clone, Copy, Debug)]
pub struct EnvironmentSample {
    /// The direction towards the environment, unit length, in world space.
    pub wi: Vec3,
    /// The environment's radiance arriving along `-wi`, per RGB channel.
    pub radiance: Vec3,
    /// Density in solid angle (not including the choice of the environment among lights).
    pub pdf: f32,
}

/// Importance sampling of a map: its texels by luminance times sin(theta).
#[derive(Clone, Debug)]
pub struct MapSampler {
    distribution: Distribution2D,
}

impl MapSampler {
    /// `None` when the map is black everywhere (nothing to sample).
    pub fn new(map: &EnvironmentMap) -> Option<Self> {
        let distribution = Distribution2D::new(&map.weights(), map.width as usize)?;
        Some(Self { distribution })
    }

    /// A direction for `u` in [0, 1)^2; `None` at a pole, where the density is infinite.
    pub fn sample(&self, map: &EnvironmentMap, u: Vec2) -> Option<EnvironmentSample> {
        let (uv, pdf_uv) = self.distribution.sample(u);
        let (wi, sin_theta) = map.direction(uv);
        if sin_theta <= 0.0 || pdf_uv <= 0.0 {
            return None;
        }
        Some(EnvironmentSample {
            wi,
            radiance: map.texel(uv),
            pdf: pdf_uv / (2.0 * PI * PI * sin_theta),
        })
    }

    /// The solid-angle density with which [`MapSampler::sample`] produces `dir`.
    pub fn pdf(&self, map: &EnvironmentMap, dir: Vec3) -> f32 {
        self.density(map.to_uv(dir), sin_theta(dir))
    }

    /// [`MapSampler::pdf`] of the direction `look` was made for (by [`Environment::look`] of
    /// this sampler's map): the same bits, without its cell found again; `None` for a look at
    /// a constant environment, which no map sampler samples.
    pub fn pdf_of(&self, look: &SkyLook) -> Option<f32> {
        look.map.map(|(uv, sin_theta)| self.density(uv, sin_theta))
    }

    /// The density of the direction at map coordinates `uv`, with its `sin(theta)`.
    fn density(&self, uv: Vec2, sin_theta: f32) -> f32 {
        if sin_theta <= 0.0 {
            return 0.0;
        }
        self.distribution.pdf(uv) / (2.0 * PI * PI * sin_theta)
    }
}

/// The largest map the loader accepts, in texels (16384 x 8192): 1.5 GB of radiance, so that a
/// corrupt or hostile header cannot ask for unbounded memory.
pub const MAX_MAP_TEXELS: u64 = 1 << 27;

/// Decodes an OpenEXR image (its first layer with R, G and B channels, any sample type) into
/// linear RGB texels, row-major, top first. The error is said in words.
pub fn decode_exr(bytes: &[u8]) -> Result<(u32, u32, Vec<Vec3>), String> {
    use exr::prelude::*;
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| format!("not a readable OpenEXR image: {e}"))?;
    for header in &meta.headers {
        let size = header.layer_size;
        if size.area() as u64 > MAX_MAP_TEXELS {
            return Err(format!(
                "{}x{} texels is more than the {MAX_MAP_TEXELS} an environment map may have",
                size.width(),
                size.height()
            ));
        }
    }
    // Decoded on this thread: loading never spawns work of its own.
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgb_channels(
            |resolution, _| {
                (
                    resolution.width(),
                    vec![Vec3::ZERO; resolution.width() * resolution.height()],
                )
            },
            |(width, texels): &mut (usize, Vec<Vec3>), position, (r, g, b): (f32, f32, f32)| {
                texels[position.y() * *width + position.x()] = Vec3::new(r, g, b);
            },
        )
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| format!("not a readable OpenEXR RGB image: {e}"))?;
    let size = image.layer_data.size;
    let (_, texels) = image.layer_data.channel_data.pixels;
    if let Some(i) = texels
        .iter()
        .position(|t| !t.is_finite() || t.cmplt(Vec3::ZERO).any())
    {
        return Err(format!(
            "texel ({}, {}) is {} (radiance must be finite and not negative)",
            i % size.width(),
            i / size.width(),
            texels[i]
        ));
    }
    Ok((size.width() as u32, size.height() as u32, texels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_and_map_coordinates_invert_each_other_under_rotation() {
        for rotate in [0.0, 37.0, -90.0, 180.0] {
            let map = EnvironmentMap::new(1, 1, vec![Vec3::ONE], rotate);
            for uv in [
                Vec2::new(0.1, 0.2),
                Vec2::new(0.5, 0.5),
                Vec2::new(0.9, 0.7),
            ] {
                let (dir, sin_theta) = map.direction(uv);
                assert!((dir.length() - 1.0).abs() < 1e-6);
                assert!((sin_theta - (1.0 - dir.y * dir.y).sqrt()).abs() < 1e-6);
                let back = map.to_uv(dir);
                assert!(
                    (back - uv).abs().max_element() < 1e-5,
                    "{rotate}: {uv} {back}"
                );
            }
        }
        // The documented orientation: centre column +z, three quarters +x, top row +y; a turn of
        // 90 degrees brings the centre to +x.
        let map = EnvironmentMap::new(1, 1, vec![Vec3::ONE], 0.0);
        assert!((map.direction(Vec2::new(0.5, 0.5)).0 - Vec3::Z).length() < 1e-6);
        assert!((map.direction(Vec2::new(0.75, 0.5)).0 - Vec3::X).length() < 1e-6);
        assert!((map.direction(Vec2::new(0.5, 0.0)).0 - Vec3::Y).length() < 1e-6);
        let turned = EnvironmentMap::new(1, 1, vec![Vec3::ONE], 90.0);
        assert!((turned.direction(Vec2::new(0.5, 0.5)).0 - Vec3::X).length() < 1e-6);
    }

    #[test]
    fn a_look_gives_the_radiance_and_density_asked_for_apart_to_the_bit() {
        // A map of distinct texels, so that a cell off by one reads another radiance and
        // another density.
        let (width, height) = (16u32, 9u32);
        let texels: Vec<Vec3> = (0..width * height)
            .map(|i| Vec3::new(1.0 + i as f32, 0.5 * (i % 7) as f32, 0.01 * (i % 5) as f32))
            .collect();
        let mut directions = vec![Vec3::Y, -Vec3::Y, Vec3::X, -Vec3::Z];
        // Directions over the sphere, and the poles approached a power of ten at a time, until
        // sin(theta) rounds to zero (its square underflows past about 1e-23): the density's
        // zero there too.
        for i in 0..2000 {
            let (z, phi) = (1.0 - 2.0 * (i as f32 + 0.5) / 2000.0, i as f32 * 2.399_963);
            let r = (1.0 - z * z).max(0.0).sqrt();
            directions.push(Vec3::new(r * phi.cos(), z, r * phi.sin()).normalize());
        }
        for e in 1..=30 {
            let tiny = 10f32.powi(-e);
            directions.extend([Vec3::new(tiny, 1.0, tiny), Vec3::new(-tiny, -1.0, 0.0)]);
        }
        for rotate in [0.0, 37.0, -90.0] {
            let map = EnvironmentMap::new(width, height, texels.clone(), rotate);
            let sampler = MapSampler::new(&map).expect("a map that is not black");
            let environment = Environment::Map(map.clone());
            for &dir in &directions {
                let look = environment.look(dir);
                assert_eq!(look.radiance, map.radiance(dir), "{rotate} {dir}");
                let apart = sampler.pdf(&map, dir);
                let shared = sampler.pdf_of(&look).expect("a look at a map");
                assert_eq!(shared.to_bits(), apart.to_bits(), "{rotate} {dir}");
            }
        }
        let constant = Environment::Constant(Vec3::new(0.3, 0.2, 0.1));
        let look = constant.look(Vec3::X);
        assert_eq!(look.radiance, Vec3::new(0.3, 0.2, 0.1));
        let map = EnvironmentMap::new(width, height, texels.clone(), 0.0);
        let sampler = MapSampler::new(&map).expect("a map that is not black");
        assert_eq!(
            sampler.pdf_of(&look),
            None,
            "a constant sky has no map density"
        );
    }

    #[test]
    fn a_constant_map_has_the_constant_mean() {
        let map = EnvironmentMap::new(7, 5, vec![Vec3::splat(2.0); 35], 0.0);
        assert!((Environment::Map(map).mean_luminance() - 2.0).abs() < 1e-5);
    }
}
