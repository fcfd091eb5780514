//! Image files: OpenEXR (linear float RGB, readable by OpenImageIO and the OpenEXR bindings) for
//! comparison with other renderers, and a tone-mapped sRGB PNG preview for people.
//!
//! Files are written to a temporary name and renamed, so a reader never sees half a frame.

use std::path::{Path, PathBuf};

/// An image of linear RGB pixels, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    /// The width in pixels.
    pub width: u32,
    /// The height in pixels.
    pub height: u32,
    /// `width` x `height` pixels, linear RGB, unscaled (as the EXR file holds them).
    pub pixels: Vec<[f32; 3]>,
}

/// Why an image could not be written or read; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The file system refused: renaming the finished temporary file over the real name.
    #[error("{path}: {source}")]
    Io {
        /// The file the image was meant for.
        path: PathBuf,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// The OpenEXR library could not write or read the file, or a header attribute was not
    /// plain text.
    #[error("{path}: {message}")]
    Exr {
        /// The EXR file written or read.
        path: PathBuf,
        /// The OpenEXR library's message, or ours for an attribute it cannot hold.
        message: String,
    },
    /// The image library could not encode or save a PNG.
    #[error("{path}: {message}")]
    Png {
        /// The PNG file meant.
        path: PathBuf,
        /// The image library's message.
        message: String,
    },
}

/// Writes `pixels` (`width` x `height`, linear RGB) as a 32-bit float RGB OpenEXR file.
pub fn write_exr(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 3]],
) -> Result<(), OutputError> {
    write_exr_with_text(path, width, height, pixels, &[])
}

/// Writes like [`write_exr`], with `(name, value)` text attributes in the header, which
/// [`read_exr_with_text`] reads back (names and values in ASCII; names up to 31 bytes).
pub fn write_exr_with_text(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 3]],
    text: &[(&str, &str)],
) -> Result<(), OutputError> {
    assert_eq!(
        pixels.len(),
        width as usize * height as usize,
        "pixel count must match the size"
    );
    use exr::prelude::*;
    let channels = SpecificChannels::rgb(|position: Vec2<usize>| {
        let p = pixels[position.y() * width as usize + position.x()];
        (p[0], p[1], p[2])
    });
    let exr_error = |message: String| OutputError::Exr {
        path: path.to_owned(),
        message,
    };
    let mut image = Image::from_channels((width as usize, height as usize), channels);
    for (name, value) in text {
        let (Some(name), Some(value)) = (Text::new_or_none(*name), Text::new_or_none(*value))
        else {
            return Err(exr_error(format!(
                "the header attribute {name:?} = {value:?} is not plain text"
            )));
        };
        image
            .layer_data
            .attributes
            .other
            .insert(name, AttributeValue::Text(value));
    }
    // Written on one thread: parallel compression stores chunks in the order they finish, so
    // the same pixels would give different bytes from run to run.
    write_then_rename(path, |tmp| {
        image
            .write()
            .non_parallel()
            .to_file(tmp)
            .map_err(|e| exr_error(e.to_string()))
    })
}

/// Reads the first RGB(A) layer of an OpenEXR file as linear RGB (alpha ignored).
pub fn read_exr(path: &Path) -> Result<RgbImage, OutputError> {
    read_exr_with_text(path, "").map(|(image, _)| image)
}

/// Reads like [`read_exr`], and the value of the layer's text attribute `name`, if it has one.
/// Every pixel is read, so a file cut short or corrupt is an error, not an image.
pub fn read_exr_with_text(
    path: &Path,
    name: &str,
) -> Result<(RgbImage, Option<String>), OutputError> {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        path,
        |resolution, _| RgbImage {
            width: resolution.width() as u32,
            height: resolution.height() as u32,
            pixels: vec![[0.0; 3]; resolution.width() * resolution.height()],
        },
        |image: &mut RgbImage, position, (r, g, b, _a): (f32, f32, f32, f32)| {
            let index = position.y() * image.width as usize + position.x();
            image.pixels[index] = [r, g, b];
        },
    )
    .map_err(|e| OutputError::Exr {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    let text = Text::new_or_none(name)
        .and_then(|name| image.layer_data.attributes.other.get(&name))
        .and_then(|value| match value {
            AttributeValue::Text(text) => Some(text.to_string()),
            _ => None,
        });
    Ok((image.layer_data.channel_data.pixels, text))
}

/// Writes a preview PNG: linear RGB times `exposure`, clamped, sRGB-encoded, 8 bits.
pub fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 3]],
    exposure: f32,
) -> Result<(), OutputError> {
    let bytes = tone_map(pixels, exposure);
    let image = image::RgbImage::from_raw(width, height, bytes)
        .expect("tone_map returns three bytes per pixel of a width x height image");
    write_png_rgb8(path, &image)
}

/// Writes an image already in 8-bit sRGB (a drawn chart or tile map) as a PNG, through the same
/// temporary name and rename as every other image, so a reader never sees half of it.
pub fn write_png_rgb8(path: &Path, image: &image::RgbImage) -> Result<(), OutputError> {
    write_then_rename(path, |tmp| {
        image
            .save_with_format(tmp, image::ImageFormat::Png)
            .map_err(|e| OutputError::Png {
                path: path.to_owned(),
                message: e.to_string(),
            })
    })
}

/// Linear RGB to 8-bit sRGB with a fixed exposure: the one tone mapping every preview and every
/// perceptual comparison uses.
pub fn tone_map(pixels: &[[f32; 3]], exposure: f32) -> Vec<u8> {
    pixels
        .iter()
        .flat_map(|p| p.map(|c| (linear_to_srgb(c * exposure) * 255.0 + 0.5) as u8))
        .collect()
}

/// The sRGB transfer function; NaN and negatives map to 0, anything above 1 to 1.
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * crate::math::powf(c, 1.0 / 2.4) - 0.055
    }
}

/// The sRGB decoding function, for textures.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        crate::math::powf((c + 0.055) / 1.055, 2.4)
    }
}

/// Writes `path` by having `write` fill a temporary file beside it, then renaming that over
/// `path`: a reader never sees half a file.
fn write_then_rename(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), OutputError>,
) -> Result<(), OutputError> {
    let tmp = temporary(path);
    write(&tmp)?;
    std::fs::rename(&tmp, path).map_err(|source| OutputError::Io {
        path: path.to_owned(),
        source,
    })
}

/// What a file being written is called until it is renamed: its name plus this. A writer killed
/// midway leaves such a file and nothing under the real name.
pub const TEMPORARY_SUFFIX: &str = ".partial";

fn temporary(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(TEMPORARY_SUFFIX);
    path.with_file_name(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trips_bits_and_png_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let pixels: Vec<[f32; 3]> = (0..12)
            .map(|i| [i as f32 * 0.1, 1.0 / (i as f32 + 1.0), 1e-30 * i as f32])
            .collect();
        let path = dir.path().join("a.exr");
        write_exr(&path, 4, 3, &pixels).unwrap();
        let back = read_exr(&path).unwrap();
        assert_eq!((back.width, back.height), (4, 3));
        let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|c| c.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.pixels), bits(&pixels));
        let (_, none) = read_exr_with_text(&path, "tessera.render").unwrap();
        assert_eq!(none, None);
        let tagged = dir.path().join("tagged.exr");
        write_exr_with_text(&tagged, 4, 3, &pixels, &[("tessera.render", "abc123")]).unwrap();
        let (back, text) = read_exr_with_text(&tagged, "tessera.render").unwrap();
        assert_eq!(text.as_deref(), Some("abc123"));
        assert_eq!(bits(&back.pixels), bits(&pixels));
        // A file cut short is an error, whatever its header says.
        let bytes = std::fs::read(&tagged).unwrap();
        let cut = dir.path().join("cut.exr");
        std::fs::write(&cut, &bytes[..bytes.len() - 8]).unwrap();
        assert!(read_exr_with_text(&cut, "tessera.render").is_err());
        let png = dir.path().join("a.png");
        write_png(&png, 4, 3, &pixels, 1.0).unwrap();
        let decoded = image::open(&png).unwrap().to_rgb8();
        assert_eq!(decoded.get_pixel(0, 0).0, [0, 255, 0]);
    }

    #[test]
    fn srgb_round_trip() {
        for i in 0..=100 {
            let c = i as f32 / 100.0;
            assert!((srgb_to_linear(linear_to_srgb(c)) - c).abs() < 1e-5);
        }
        assert_eq!(linear_to_srgb(f32::NAN), 0.0);
    }
}
