//! The media knob: how free flights and shadow rays are sampled through participating media
//! ([`tracer::medium::MediaSampling`]), each choice a rung at the knob's samples per pixel.
//!
//! Every choice is unbiased, so the rungs differ in noise and in time, which is the point: the
//! analytic default against a per-flight channel mixture, delta tracking with null collisions
//! and ratio-tracked shadow rays, the trackers being what a renderer ready for heterogeneous
//! media pays. In a scene without media every rung is the same bits (no flight or shadow ray
//! meets a medium), and the notes say so.
//!
//! Cost: the tracer's counted work ([`tracer::PathStats::work`]) counts rays and BVH work, not
//! the trackers' tentative collisions, so `--cost work` hides what tracking costs beyond its
//! rays; read this ladder's seconds, or run it with `--cost time`.

use super::Knob;
use super::bench::{Bench, Row};
use tracer::medium::MediaSampling;
use tracer::scene::RenderSettings;

impl Bench<'_> {
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
