//! The sampling knobs: how area lights, the environment, wavelengths and participating media
//! are sampled, each choice a rung at the knob's samples per pixel, its image compared with
//! the default's.
//!
//! Every choice of each is unbiased, so the rungs differ in noise and in time, which is the
//! point: what multiple importance sampling buys over either strategy alone (area lights),
//! what importance sampling a map buys (environment), what an always-spectral renderer pays in
//! a scene without dispersion (wavelengths). In a scene without the effect a knob is about,
//! every rung is the same bits, and the notes say so.
//!
//! **Media** ([`tracer::medium::MediaSampling`]): the analytic default against a per-flight
//! channel mixture, delta tracking with null collisions and ratio-tracked shadow rays, the
//! trackers being what a renderer ready for heterogeneous media pays. Cost: the tracer's
//! counted work ([`tracer::PathStats::work`]) counts rays and BVH work, not the trackers'
//! tentative collisions, so `--cost work` hides what tracking costs beyond its rays; read
//! that ladder's seconds, or run it with `--cost time`.

use super::Knob;
use super::bench::{Bench, Row};
use tracer::integrator::AreaLightSampling;
use tracer::lights::{EnvironmentSampling, Lights};
use tracer::medium::MediaSampling;
use tracer::scene::RenderSettings;
use tracer::spectrum::SpectralSampling;

impl Bench<'_> {
    /// The environment sampled by importance (through the scene's portals too), by importance
    /// without them, uniformly and not at all (BSDF sampling alone), at `spp`. All four are
    /// unbiased: the images differ by noise, which is the point; in a
    /// scene without an environment they are the same bits.
    pub fn environment_ladder(&mut self, spp: u32) -> Vec<Row> {
        let settings = self.at_spp(spp);
        let rows = self.compared_ladder(
            Knob::Environment,
            EnvironmentSampling::ALL,
            "importance sampling's image",
            |bench, sampling| {
                bench.world.lights =
                    Lights::with_sampling(&bench.world.scene, &bench.world.effects, sampling);
                (sampling.name().to_owned(), settings.clone())
            },
        );
        self.world.lights = Lights::new(&self.world.scene, &self.world.effects);
        rows
    }

    /// Area lights found by both strategies weighted, by light sampling alone and by BSDF
    /// sampling alone, at `spp`. All three are unbiased: the images differ by noise, and the
    /// times by what the weighting costs (a density per emitter hit and per light sample).
    pub fn lights_ladder(&mut self, spp: u32) -> Vec<Row> {
        let settings = self.at_spp(spp);
        let rows = self.compared_ladder(
            Knob::Lights,
            AreaLightSampling::ALL,
            "the weighted strategies' image",
            |bench, sampling| {
                bench.world.area_lights = sampling;
                (sampling.name().to_owned(), settings.clone())
            },
        );
        self.world.area_lights = AreaLightSampling::default();
        rows
    }

    /// Wavelengths sampled as each [`SpectralSampling`] choice says, at `spp`: RGB until
    /// dispersive glass (the default), spectral from the camera with three hero wavelengths,
    /// with one. All unbiased for the same image; they differ in noise and time.
    pub fn spectral_ladder(&mut self, spp: u32) -> Vec<Row> {
        let settings = self.at_spp(spp);
        let rows = self.compared_ladder(
            Knob::Spectral,
            SpectralSampling::ALL,
            "the RGB render's image",
            |bench, sampling| {
                bench.world.spectral = sampling;
                (sampling.name().to_owned(), settings.clone())
            },
        );
        self.world.spectral = SpectralSampling::default();
        rows
    }

    /// Each of [`MediaSampling::LADDER`] at `spp`; each image is compared with the default's.
    pub fn media_ladder(&mut self, spp: u32) -> Vec<Row> {
        let at_spp = self.at_spp(spp);
        self.compared_ladder(
            Knob::Media,
            MediaSampling::LADDER,
            "the analytic default's image",
            |_, media| {
                let settings = RenderSettings {
                    media,
                    ..at_spp.clone()
                };
                (media.name(), settings)
            },
        )
    }
}
