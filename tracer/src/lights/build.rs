//! How a scene's lights are listed: which emitters count, their power-proportional choice
//! distribution, and the per-triangle shapes and per-kind indices that sampling reads.

use super::{EnvironmentSampling, Light, Lights, luminance, moving};
use crate::effects::Effects;
use crate::environment::{Environment, MapSampler, PortalSampler};
use crate::geometry::plane_normal;
use crate::scene::Scene;
use glam::Vec3;
use moving::{locate, moving_first};
use std::f32::consts::PI;

impl Lights {
    /// [`Lights::new`] with the environment sampled as `sampling` says.
    pub fn with_sampling(scene: &Scene, effects: &Effects, sampling: EnvironmentSampling) -> Self {
        let radius = bounding_radius(scene);
        let mut lights = Vec::new();
        let mut power = Vec::new();
        let mut add = |light: Light, p: f32| {
            if p.is_finite() && p > 0.0 {
                lights.push(light);
                power.push(p);
            }
        };
        let moving_first = moving_first(scene);
        if effects.area_lights {
            for (index, triangle) in scene.emissive_triangles() {
                let emission = scene.materials[triangle.material as usize].emission;
                let (light, area) = match locate(&moving_first, scene, index) {
                    None => (Light::Triangle(index), triangle.area()),
                    Some((object, local)) => {
                        let light = Light::Moving {
                            object,
                            triangle: local,
                        };
                        (light, moving::mean_area(scene, object, &triangle.p))
                    }
                };
                add(light, area * luminance(emission) * PI);
            }
        }
        if effects.point_lights {
            for light in &scene.point_lights {
                let point = Light::Point {
                    position: light.position,
                    intensity: light.intensity,
                };
                add(point, 4.0 * PI * luminance(light.intensity));
            }
        }
        let mut map_sampler = None;
        let mut portals = Vec::new();
        if effects.environment
            && sampling != EnvironmentSampling::Bsdf
            && let Some(environment) = &scene.environment
        {
            // The power the environment sends through the scene's bounding sphere.
            let p = environment.mean_luminance() * PI * 4.0 * PI * radius * radius;
            let by_importance = matches!(
                sampling,
                EnvironmentSampling::Importance | EnvironmentSampling::WithoutPortals
            );
            if by_importance && let Environment::Map(map) = environment {
                map_sampler = MapSampler::new(map);
            }
            if sampling == EnvironmentSampling::Importance {
                portals = scene.portals.iter().map(PortalSampler::new).collect();
            }
            // A map too faint for its distribution (every weight rounded to zero) is not listed.
            let sampleable = map_sampler.is_some()
                || sampling == EnvironmentSampling::Uniform
                || matches!(environment, Environment::Constant(_));
            if sampleable {
                add(Light::Environment, p);
            }
        }
        let bounds = choice_bounds(&lights, &power);
        let moving_triangles: usize = scene.moving.iter().map(|o| o.triangles.len()).sum();
        let mut triangle_light = vec![u32::MAX; scene.triangles.len() + moving_triangles];
        let mut environment_light = None;
        for (index, light) in lights.iter().enumerate() {
            match light {
                Light::Triangle(t) => triangle_light[*t as usize] = index as u32,
                Light::Moving { object, triangle } => {
                    let global = moving_first[*object as usize] + triangle;
                    triangle_light[global as usize] = index as u32;
                }
                Light::Environment => environment_light = Some(index as u32),
                Light::Point { .. } => {}
            }
        }
        let shapes = lights
            .iter()
            .map(|light| match light {
                Light::Triangle(t) => TriangleShape::of(&scene.triangles[*t as usize]),
                _ => TriangleShape::default(),
            })
            .collect();
        let mut result = Self {
            shapes,
            lights,
            bounds,
            triangle_light,
            environment_choice: 0.0,
            environment_index: environment_light.map_or(0, |i| i as usize),
            map_sampler,
            portals,
            scene_radius: radius,
        };
        result.environment_choice =
            environment_light.map_or(0.0, |i| result.choice_pdf(i as usize));
        result
    }
}

/// The per-triangle values light sampling needs, computed once, by the same expressions the
/// sampling used to evaluate each time, so they are the same bits.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct TriangleShape {
    /// Half the length of `(p1 - p0) x (p2 - p0)`.
    pub(crate) area: f32,
    /// That cross product normalised in f32, zero without area.
    pub(crate) normal: Vec3,
    /// The f64 plane normal that spawning shadow rays off the light uses
    /// ([`crate::geometry::plane_normal`]).
    pub(crate) plane_normal: Vec3,
}

impl TriangleShape {
    pub(super) fn of(triangle: &crate::scene::Triangle) -> Self {
        let area_vector = triangle.area_vector();
        TriangleShape {
            area: 0.5 * area_vector.length(),
            normal: area_vector.normalize_or_zero(),
            plane_normal: plane_normal(&triangle.p),
        }
    }
}

/// The bounds of the lights' shares of the choice's number ([`Lights`]'s `bounds`): 0, then
/// the cumulative choice probabilities, each kind of light with positive total power equally
/// likely, lights within a kind by power, the last set to 1. Empty when there is no light;
/// every power is positive.
fn choice_bounds(lights: &[Light], power: &[f32]) -> Vec<f32> {
    let kind = |light: &Light| match light {
        Light::Triangle(_) | Light::Moving { .. } => 0,
        Light::Point { .. } => 1,
        Light::Environment => 2,
    };
    let mut kind_power = [0.0f64; 3];
    for (light, &p) in lights.iter().zip(power) {
        kind_power[kind(light)] += f64::from(p);
    }
    let kinds = kind_power.iter().filter(|&&p| p > 0.0).count();
    if kinds == 0 {
        return Vec::new();
    }
    let mut running = 0.0f64;
    let cumulative = lights.iter().zip(power).map(|(light, &p)| {
        let total = kind_power[kind(light)];
        if total > 0.0 {
            running += f64::from(p) / total / kinds as f64;
        }
        running as f32
    });
    let mut bounds: Vec<f32> = std::iter::once(0.0).chain(cumulative).collect();
    if let Some(last) = bounds.last_mut() {
        *last = 1.0;
    }
    bounds
}

/// The radius of a sphere around every triangle: half the diagonal of their bounding box.
fn bounding_radius(scene: &Scene) -> f32 {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for t in &scene.triangles {
        for p in t.p {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    if lo.x > hi.x {
        return 1.0;
    }
    (0.5 * (hi - lo).length()).max(f32::MIN_POSITIVE)
}
