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
use super::bench::{Bench, Row, difference_note};
use tracer::medium::MediaSampling;
use tracer::scene::RenderSettings;

impl Bench<'_> {
    /// Each of [`MediaSampling::LADDER`] at `spp`; each image is compared with the default's.
    pub fn media_ladder(&mut self, spp: u32) -> Vec<Row> {
        let mut rows = Vec::new();
        let mut first_image = None;
        for media in MediaSampling::LADDER {
            let settings = RenderSettings {
                samples_per_pixel: spp,
                media,
                ..self.baseline.clone()
            };
            let (mut row, image) = self.measure(Knob::Media, media.name(), settings);
            match &first_image {
                None => first_image = Some(image),
                Some(first) => {
                    let note = difference_note(&image, first, "the analytic default's image");
                    row.note = if row.note.is_empty() {
                        note
                    } else {
                        format!("{note}; {}", row.note)
                    };
                }
            }
            rows.push(row);
        }
        rows
    }
}
