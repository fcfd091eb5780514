//! What scatters light at a path's vertex, as next-event estimation sees it: a BSDF at a
//! surface or the phase function in a medium; and the random numbers every bounce draws.

use crate::material::{Bsdf, Frame};
use crate::medium::henyey_greenstein;
use crate::sampler::PixelSampler;
use glam::{Vec2, Vec3};

/// A scatterer seen from a fixed outgoing direction: the value and the sampling density of an
/// incident world direction `wi`.
pub(super) trait Scatterer {
    /// `f * |cos|` for a surface, the phase function's value in a medium.
    fn f(&self, wi: Vec3) -> Vec3;
    /// The solid-angle density with which the scatterer's own sampling draws `wi`.
    fn pdf(&self, wi: Vec3) -> f32;
}

/// A BSDF in its shading frame, seen from `wo` (local).
pub(super) struct SurfaceScatter<'a> {
    pub bsdf: &'a Bsdf,
    pub frame: &'a Frame,
    pub wo: Vec3,
}

impl Scatterer for SurfaceScatter<'_> {
    fn f(&self, wi: Vec3) -> Vec3 {
        self.bsdf.eval(self.wo, self.frame.to_local(wi))
    }

    fn pdf(&self, wi: Vec3) -> f32 {
        self.bsdf.pdf(self.wo, self.frame.to_local(wi))
    }
}

/// A Henyey-Greenstein phase function of asymmetry `g`, seen from `wo` (world, unit length).
pub(super) struct Phase {
    pub wo: Vec3,
    pub g: f32,
}

impl Scatterer for Phase {
    fn f(&self, wi: Vec3) -> Vec3 {
        Vec3::splat(henyey_greenstein(self.wo.dot(wi), self.g))
    }

    fn pdf(&self, wi: Vec3) -> f32 {
        henyey_greenstein(self.wo.dot(wi), self.g)
    }
}

/// The random numbers of one bounce, all drawn whether used or not, in this fixed order (see
/// [`crate::sampler::DIMENSIONS_PER_BOUNCE`]). A scattering in a medium draws the same block:
/// its phase direction takes the BSDF's pair and leaves `choice` unused.
pub(super) struct BounceNumbers {
    pub light_choice: f32,
    pub light: Vec2,
    pub choice: f32,
    pub scatter: Vec2,
    pub roulette: f32,
}

impl BounceNumbers {
    pub(super) fn draw(sampler: &mut PixelSampler) -> Self {
        let light_choice = sampler.next_1d();
        let light = sampler.next_2d();
        let choice = sampler.next_1d();
        let scatter = sampler.next_2d();
        let roulette = sampler.next_1d();
        BounceNumbers {
            light_choice,
            light,
            choice,
            scatter,
            roulette,
        }
    }
}
