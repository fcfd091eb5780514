//! How far one linear image is from another (`tessera compare`).
//!
//! This is how a user checks our EXR against another renderer's, and how `tessera accuracy`
//! measures every rung of its ladders, so both use the same [`Metrics`]. The per-pixel metrics
//! work on the linear floats as stored; only FLIP, which models a viewer looking at a display,
//! sees 8-bit sRGB: both images go through the one tone mapping every preview uses
//! ([`tracer::output::tone_map`]) at a fixed exposure, so FLIP says nothing about values above 1.
//!
//! The second image is the reference: relative MSE divides by it, and FLIP treats it as the truth.

use crate::LabError;
use serde::Serialize;
use std::path::Path;
use tracer::output::RgbImage;

/// The exposure both images are multiplied by before FLIP's 8-bit sRGB tone mapping.
pub const FLIP_EXPOSURE: f32 = 1.0;

/// Added to the reference in relative MSE's denominator, as pbrt's `imgtool diff` does, so that
/// black reference pixels do not divide by zero.
pub const REL_MSE_EPSILON: f64 = 0.01;

const CHANNELS: [&str; 3] = ["R", "G", "B"];

/// The per-pixel metrics of a test image against a reference, over all pixels and RGB channels.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Metrics {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Mean of (a - b)^2.
    pub mse: f64,
    /// The square root of `mse`.
    pub rmse: f64,
    /// Mean of (a - b)^2 / (b + 0.01)^2.
    pub rel_mse: f64,
    /// Mean of |a - b|.
    pub mae: f64,
    /// The largest |a - b| of any channel of any pixel, and where.
    pub max_difference: MaxDifference,
    /// Mean of each channel of the test image.
    pub mean_test: [f64; 3],
    /// Mean of each channel of the reference.
    pub mean_reference: [f64; 3],
    /// Channel values left out of every metric because either image has a NaN or an infinity
    /// there (a renderer bug worth knowing about, but one that should not hide everything else).
    pub non_finite: u64,
}

/// The largest difference between the images, where it is, and the two values there.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MaxDifference {
    /// The absolute difference.
    pub value: f64,
    /// Its column.
    pub x: u32,
    /// Its row.
    pub y: u32,
    /// Its channel: R, G or B.
    pub channel: &'static str,
    /// The test image's value there.
    pub test: f32,
    /// The reference's value there.
    pub reference: f32,
}

/// Everything `tessera compare` reports.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// The test image's path.
    pub test: String,
    /// The reference's path.
    pub reference: String,
    /// Both images' channel names, sorted.
    pub channels: Vec<String>,
    /// The per-pixel metrics (flattened into this object in JSON).
    #[serde(flatten)]
    pub metrics: Metrics,
    /// Mean FLIP and its conditions.
    pub flip: Flip,
}

/// Mean FLIP, with the conditions it was measured under.
#[derive(Clone, Debug, Serialize)]
pub struct Flip {
    /// Mean FLIP error over the pixels, 0 (identical) to 1.
    pub mean: f64,
    /// The exposure both images were multiplied by.
    pub exposure: f32,
    /// FLIP's viewing condition.
    pub pixels_per_degree: f32,
    /// How linear values became 8-bit sRGB for FLIP.
    pub tone_mapping: &'static str,
}

/// Reads both files, checks that they have the same channels and size, and measures.
pub fn compare_files(test: &Path, reference: &Path) -> Result<Comparison, LabError> {
    let test_channels = channel_names(test)?;
    let reference_channels = channel_names(reference)?;
    if test_channels != reference_channels {
        return Err(LabError::Invalid(format!(
            "the images have different channel sets: {} has {}, {} has {}",
            test.display(),
            test_channels.join(","),
            reference.display(),
            reference_channels.join(","),
        )));
    }
    let a = tracer::output::read_exr(test)?;
    let b = tracer::output::read_exr(reference)?;
    let metrics = Metrics::between(&a, &b).map_err(|e| {
        e.context(format!(
            "cannot compare {} with {}",
            test.display(),
            reference.display()
        ))
    })?;
    Ok(Comparison {
        test: test.display().to_string(),
        reference: reference.display().to_string(),
        channels: test_channels,
        metrics,
        flip: Flip {
            mean: mean_flip(&a, &b),
            exposure: FLIP_EXPOSURE,
            pixels_per_degree: nv_flip::DEFAULT_PIXELS_PER_DEGREE,
            tone_mapping: "linear x exposure, clamped to [0, 1], sRGB-encoded to 8 bits",
        },
    })
}

impl Metrics {
    /// Measures `test` against `reference`; an error when their sizes differ.
    pub fn between(test: &RgbImage, reference: &RgbImage) -> Result<Metrics, LabError> {
        if (test.width, test.height) != (reference.width, reference.height) {
            return Err(LabError::Invalid(format!(
                "the images have different sizes: {}x{} and {}x{} (reference)",
                test.width, test.height, reference.width, reference.height,
            )));
        }
        let expected = test.width as usize * test.height as usize;
        if test.pixels.len() != expected || reference.pixels.len() != expected {
            return Err(LabError::Invalid(
                "an image holds a different number of pixels than its size says".into(),
            ));
        }
        let mut sums = Sums::default();
        // The first finite pair's, then any larger: never a place the images do not hold.
        let mut max: Option<MaxDifference> = None;
        for (index, (a, b)) in test.pixels.iter().zip(&reference.pixels).enumerate() {
            for c in 0..3 {
                let (ta, tb) = (a[c], b[c]);
                if !ta.is_finite() || !tb.is_finite() {
                    sums.non_finite += 1;
                    continue;
                }
                let (fa, fb) = (f64::from(ta), f64::from(tb));
                let d = fa - fb;
                sums.count += 1;
                sums.squared += d * d;
                sums.relative += d * d / ((fb + REL_MSE_EPSILON) * (fb + REL_MSE_EPSILON));
                sums.absolute += d.abs();
                sums.test[c] += fa;
                sums.reference[c] += fb;
                sums.per_channel[c] += 1;
                if max.as_ref().is_none_or(|m| d.abs() > m.value) {
                    let (x, y) = (
                        (index % test.width as usize) as u32,
                        (index / test.width as usize) as u32,
                    );
                    max = Some(MaxDifference {
                        value: d.abs(),
                        x,
                        y,
                        channel: CHANNELS[c],
                        test: ta,
                        reference: tb,
                    });
                }
            }
        }
        let Some(max) = max else {
            return Err(LabError::Invalid(format!(
                "no channel value is finite in both images ({} are NaN or infinite): nothing \
                 to compare",
                sums.non_finite
            )));
        };
        let n = sums.count as f64;
        let mean = |sum: [f64; 3]| std::array::from_fn(|c| sum[c] / sums.per_channel[c] as f64);
        Ok(Metrics {
            width: test.width,
            height: test.height,
            mse: sums.squared / n,
            rmse: (sums.squared / n).sqrt(),
            rel_mse: sums.relative / n,
            mae: sums.absolute / n,
            max_difference: max,
            mean_test: mean(sums.test),
            mean_reference: mean(sums.reference),
            non_finite: sums.non_finite,
        })
    }

    /// How much brighter (positive) or darker the test image is on average, relative to the
    /// reference: the bias that noise cannot explain once many pixels are averaged.
    pub fn mean_bias(&self) -> f64 {
        let sum = |m: [f64; 3]| m.iter().sum::<f64>();
        let reference = sum(self.mean_reference);
        if reference == 0.0 {
            0.0
        } else {
            sum(self.mean_test) / reference - 1.0
        }
    }
}

#[derive(Default)]
struct Sums {
    count: u64,
    non_finite: u64,
    squared: f64,
    relative: f64,
    absolute: f64,
    test: [f64; 3],
    reference: [f64; 3],
    per_channel: [u64; 3],
}

/// Mean FLIP of `test` against `reference` after tone mapping both to 8-bit sRGB at
/// [`FLIP_EXPOSURE`]. The sizes must match (checked by [`Metrics::between`] first).
pub fn mean_flip(test: &RgbImage, reference: &RgbImage) -> f64 {
    assert_eq!(
        (test.width, test.height),
        (reference.width, reference.height),
        "sizes checked by the caller"
    );
    let eight_bit = |image: &RgbImage| {
        let bytes = tracer::output::tone_map(&image.pixels, FLIP_EXPOSURE);
        nv_flip::FlipImageRgb8::with_data(image.width, image.height, &bytes)
    };
    let error = nv_flip::flip(
        eight_bit(reference),
        eight_bit(test),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    // The mean of the error map itself, in f64: exact, where FLIP's pool keeps a histogram.
    let values = error.to_vec();
    values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len().max(1) as f64
}

/// The names of every channel of every layer of an OpenEXR file, sorted (layer-qualified names
/// like `diffuse.R` for named layers).
pub fn channel_names(path: &Path) -> Result<Vec<String>, LabError> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| {
        LabError::Invalid(e.to_string()).context(format!(
            "{}: cannot read the OpenEXR header",
            path.display()
        ))
    })?;
    let mut names: Vec<String> = meta
        .headers
        .iter()
        .flat_map(|header| {
            let layer = header
                .own_attributes
                .layer_name
                .as_ref()
                .map(|n| n.to_string());
            header
                .channels
                .list
                .iter()
                .map(move |channel| match &layer {
                    Some(layer) => format!("{layer}.{}", channel.name),
                    None => channel.name.to_string(),
                })
        })
        .collect();
    names.sort();
    Ok(names)
}

impl Comparison {
    /// The human-readable report.
    pub fn text(&self) -> String {
        let m = &self.metrics;
        let d = &m.max_difference;
        let triple = |v: [f64; 3]| format!("{:.6} {:.6} {:.6}", v[0], v[1], v[2]);
        let mut out = format!(
            "test {} against reference {}: {}x{}, channels {}\n",
            self.test,
            self.reference,
            m.width,
            m.height,
            self.channels.join(",")
        );
        out += &format!("  RMSE                 {:.6e}\n", m.rmse);
        out += &format!(
            "  relative MSE         {:.6e}   mean of (a-b)^2/(b+0.01)^2, as pbrt's imgtool\n",
            m.rel_mse
        );
        out += &format!("  mean abs. error      {:.6e}\n", m.mae);
        out += &format!(
            "  largest difference   {:.6e}   pixel ({}, {}) channel {}: test {}, reference {}\n",
            d.value, d.x, d.y, d.channel, d.test, d.reference
        );
        out += &format!("  mean R G B, test     {}\n", triple(m.mean_test));
        out += &format!("  mean R G B, ref.     {}\n", triple(m.mean_reference));
        out += &format!(
            "  mean FLIP            {:.6}   after tone mapping both to 8-bit sRGB at exposure {} (values above 1 clip), {} pixels per degree\n",
            self.flip.mean, self.flip.exposure, self.flip.pixels_per_degree
        );
        if m.non_finite > 0 {
            out += &format!(
                "  warning: {} channel values are NaN or infinite: left out of every metric \
                 but FLIP, which sees them as the previews do (NaN black, infinity white)\n",
                m.non_finite
            );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(width: u32, height: u32, f: impl Fn(usize) -> [f32; 3]) -> RgbImage {
        RgbImage {
            width,
            height,
            pixels: (0..(width * height) as usize).map(f).collect(),
        }
    }

    fn ramp(width: u32, height: u32) -> RgbImage {
        image(width, height, |i| {
            [i as f32 * 0.125, 0.5, 2.0 - i as f32 * 0.25]
        })
    }

    #[test]
    fn an_image_against_itself_is_zero_on_every_metric() {
        let a = ramp(4, 3);
        let m = Metrics::between(&a, &a).unwrap();
        assert_eq!(
            (m.mse, m.rmse, m.rel_mse, m.mae, m.max_difference.value),
            (0.0, 0.0, 0.0, 0.0, 0.0)
        );
        assert_eq!(m.mean_bias(), 0.0);
        assert_eq!(mean_flip(&a, &a), 0.0);
    }

    #[test]
    fn one_changed_channel_gives_the_hand_computed_values() {
        // 2x2 pixels, 12 channel values, all 0.5 in the reference; the test has 0.75 in the green
        // channel of pixel (1, 1). Every number below is exact in binary floating point.
        let reference = image(2, 2, |_| [0.5; 3]);
        let test = image(2, 2, |i| if i == 3 { [0.5, 0.75, 0.5] } else { [0.5; 3] });
        let m = Metrics::between(&test, &reference).unwrap();
        let n = 12.0;
        assert_eq!(m.mse, 0.0625 / n);
        assert_eq!(m.rmse, (0.0625f64 / n).sqrt());
        assert_eq!(m.rel_mse, 0.0625 / (0.51 * 0.51) / n);
        assert_eq!(m.mae, 0.25 / n);
        let d = &m.max_difference;
        assert_eq!(
            (d.value, d.x, d.y, d.channel, d.test, d.reference),
            (0.25, 1, 1, "G", 0.75, 0.5)
        );
        assert_eq!(m.mean_test, [0.5, 0.5 + 0.25 / 4.0, 0.5]);
        assert_eq!(m.mean_reference, [0.5; 3]);
        assert!(mean_flip(&test, &reference) > 0.0);
    }

    #[test]
    fn a_uniform_offset_gives_the_offset() {
        let reference = ramp(3, 3);
        let test = image(3, 3, |i| reference.pixels[i].map(|c| c + 0.25));
        let m = Metrics::between(&test, &reference).unwrap();
        assert_eq!((m.rmse, m.mae, m.max_difference.value), (0.25, 0.25, 0.25));
        let expected: f64 = reference
            .pixels
            .iter()
            .flatten()
            .map(|&b| 0.0625 / (f64::from(b) + 0.01).powi(2))
            .sum();
        assert!((m.rel_mse - expected / 27.0).abs() < 1e-12 * expected);
    }

    #[test]
    fn non_finite_values_are_counted_and_left_out() {
        let reference = image(2, 1, |_| [1.0; 3]);
        let test = image(2, 1, |i| {
            if i == 0 {
                [f32::NAN, 1.0, 1.0]
            } else {
                [1.0, 1.0, 2.0]
            }
        });
        let m = Metrics::between(&test, &reference).unwrap();
        assert_eq!(m.non_finite, 1);
        assert_eq!(m.mae, 1.0 / 5.0);
        assert_eq!(m.mean_test, [1.0, 1.0, 1.5]);
    }

    #[test]
    fn the_largest_difference_is_a_place_the_images_hold_and_nothing_finite_is_an_error() {
        // Equal images: the largest difference, 0, is reported at the first pixel with its
        // true values, not made-up zeros.
        let same = image(2, 1, |i| [1.0 + i as f32, 2.0, 3.0]);
        let d = Metrics::between(&same, &same).unwrap().max_difference;
        assert_eq!((d.value, d.x, d.test, d.reference), (0.0, 0, 1.0, 1.0));
        // A NaN in the first place: the largest difference is found among the finite ones.
        let test = image(2, 1, |i| {
            if i == 0 {
                [f32::NAN; 3]
            } else {
                [5.0, 2.0, 3.0]
            }
        });
        let d = Metrics::between(&test, &same).unwrap().max_difference;
        assert_eq!(
            (d.value, d.x, d.channel, d.test, d.reference),
            (3.0, 1, "R", 5.0, 2.0)
        );
        let nothing = image(2, 1, |_| [f32::NAN; 3]);
        let error = Metrics::between(&nothing, &same).unwrap_err().to_string();
        assert!(
            error.contains("no channel value is finite in both"),
            "{error}"
        );
    }

    #[test]
    fn different_sizes_are_an_error_naming_both() {
        let error = Metrics::between(&ramp(4, 3), &ramp(3, 4))
            .unwrap_err()
            .to_string();
        assert!(error.contains("4x3") && error.contains("3x4"), "{error}");
    }
}
