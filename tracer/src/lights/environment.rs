//! The environment as next-event estimation sees it: its density for a direction a BSDF sampled,
//! and, where the scene declares portals, the second sample taken through them beside its own
//! ([`crate::environment::PortalSampler`] says why).

use super::{LightSample, Lights};
use crate::environment::{PortalSampler, SkyLook};
use crate::geometry::SurfacePoint;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

impl Lights {
    /// Whether next-event estimation takes a second sample through the scene's portals each
    /// time it samples the environment ([`Lights::portal_sample`]).
    pub fn has_portals(&self) -> bool {
        !self.portals.is_empty()
    }

    /// The environment's second sample, through a portal, from `p`, for the numbers `sample`
    /// was given when it chose the environment: the light choice's number past the choice
    /// (uniform in [0, 1) again) picks the portal, and `u` with its coordinates swapped the
    /// direction, uniformly in solid angle. Its density includes the environment's choice, as
    /// the sample is taken whenever the environment is chosen; `other_pdf` is the environment's
    /// own sampling's density. Both samples are weighed against each other and the BSDF by the
    /// power heuristic (Veach's multi-sample estimator), so that neither strategy's samples are
    /// halved: a one-sample mixture would turn the sun's steady beam into a coin toss.
    pub fn portal_sample(
        &self,
        scene: &Scene,
        p: Vec3,
        u_choice: f32,
        u: Vec2,
    ) -> Option<LightSample> {
        let (k, u) = self.portal_pick(scene, u_choice, u)?;
        let drawn = self.portals[k].sample(p, u)?;
        self.through_portals(scene, p, drawn)
    }

    /// [`Lights::portal_sample`]'s portal (its index, [`Lights::portal`]) for the light
    /// choice's number `u_choice`, and the numbers its direction is drawn for; `None` where no
    /// sample is taken through portals.
    #[inline(always)]
    pub(crate) fn portal_pick(
        &self,
        scene: &Scene,
        u_choice: f32,
        u: Vec2,
    ) -> Option<(usize, (f64, f64))> {
        let choice = self.environment_choice;
        if scene.environment.is_none() || self.portals.is_empty() || choice <= 0.0 {
            return None;
        }
        let below = self.cdf_below(self.environment_index);
        let rest = ((u_choice - below) / choice).clamp(0.0, 1.0);
        let n = self.portals.len();
        let k = ((rest * n as f32) as usize).min(n - 1);
        Some((k, (f64::from(u.y), f64::from(u.x))))
    }

    /// Portal `k`, as [`Lights::portal_pick`] names it.
    #[inline(always)]
    pub(crate) fn portal(&self, k: usize) -> &PortalSampler {
        &self.portals[k]
    }

    /// [`Lights::portal_sample`]'s light sample for the direction `wi` its portal drew from
    /// `p`, with that portal's density `sampled`.
    #[inline(always)]
    pub(crate) fn through_portals(
        &self,
        scene: &Scene,
        p: Vec3,
        (wi, sampled): (Vec3, f32),
    ) -> Option<LightSample> {
        let look = scene.environment.as_ref()?.look(wi);
        let choice = self.environment_choice;
        let pdf = choice * self.portals_density(p, wi, || sampled);
        (pdf > 0.0).then(|| LightSample {
            wi,
            distance: f32::INFINITY,
            at: SurfacePoint::exact(Vec3::ZERO),
            radiance: look.radiance,
            pdf,
            other_pdf: choice * self.own_environment_pdf(&look),
            delta: false,
        })
    }

    /// The environment's own light sample from `p` (chosen with probability `choice`) for the
    /// numbers `u`: [`Lights::environment_sample`]'s, with the density by which the portals
    /// would have produced the same direction where the scene has them: the scalar path's
    /// (the lanes, where the scene has portals, take its two parts apart, the direction
    /// before the portals' density of it, which they find with their draws through them).
    #[inline]
    pub(crate) fn environment_light_sample(
        &self,
        scene: &Scene,
        p: Vec3,
        u: Vec2,
        choice: f32,
    ) -> Option<LightSample> {
        let environment = scene
            .environment
            .as_ref()
            .expect("the environment is listed only when the scene has one");
        let (wi, radiance, pdf) = self.environment_sample(environment, u, choice)?;
        // With portals, the same direction might have come through one.
        let other_pdf = if self.portals.is_empty() {
            0.0
        } else {
            choice * self.portals_pdf(p, wi)
        };
        Some(LightSample {
            wi,
            distance: f32::INFINITY,
            at: SurfacePoint::exact(Vec3::ZERO),
            radiance,
            pdf,
            other_pdf,
            delta: false,
        })
    }

    /// The density with which `sample` would have produced the escaped direction `dir` from
    /// `p`, `look` being the environment's look along `dir` ([`Environment::look`]), which the
    /// caller has for its radiance.
    ///
    /// [`Environment::look`]: crate::environment::Environment::look
    pub fn environment_pdf(&self, p: Vec3, dir: Vec3, look: &SkyLook) -> f32 {
        if self.environment_choice == 0.0 {
            return 0.0;
        }
        if !self.portals.is_empty() {
            // Two light strategies: the power heuristic weighs BSDF sampling against the root
            // of the sum of their squared densities (see `LightSample::other_pdf`).
            let own = f64::from(self.environment_choice * self.own_environment_pdf(look));
            let portals = f64::from(self.environment_choice * self.portals_pdf(p, dir));
            return (own * own + portals * portals).sqrt() as f32;
        }
        match self.map_density(look) {
            Some(pdf) => self.environment_choice * pdf,
            None => super::uniform_density(self.environment_choice),
        }
    }

    /// The solid-angle density of the environment's own sampling (its map by importance, or the
    /// sphere uniformly) of the direction `look` was made for, without the choice of the
    /// environment among lights.
    pub(super) fn own_environment_pdf(&self, look: &SkyLook) -> f32 {
        self.map_density(look).unwrap_or(1.0 / (4.0 * PI))
    }

    /// The map's density of the direction `look` was made for, where the environment is a map
    /// sampled by its importance.
    fn map_density(&self, look: &SkyLook) -> Option<f32> {
        self.map_sampler.as_ref()?.pdf_of(look)
    }

    /// [`Lights::portals_pdf`] of `wi` from `p`, where the caller may have the one portal's own
    /// density of it already (`one`): with one portal, that density is the portals' mean, the
    /// same bits (`x / 1` is `x`), without its solid angle worked out a second time; with
    /// more, every portal the direction crosses counts. For the scalar path's sample through
    /// the portals and the lanes', which find the own sample's density with their draws.
    #[inline(always)]
    pub(crate) fn portals_density(&self, p: Vec3, wi: Vec3, one: impl FnOnce() -> f32) -> f32 {
        if self.portals.len() == 1 {
            one()
        } else {
            self.portals_pdf(p, wi)
        }
    }

    /// The solid-angle density of a sample through the portals from `p` (one picked uniformly):
    /// their densities' mean.
    pub(crate) fn portals_pdf(&self, p: Vec3, wi: Vec3) -> f32 {
        let sum: f32 = self.portals.iter().map(|portal| portal.pdf(p, wi)).sum();
        sum / self.portals.len() as f32
    }
}
