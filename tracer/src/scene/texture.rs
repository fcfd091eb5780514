//! Decoded textures: sRGB bytes, decoded to linear RGB through a 256-entry table at lookup,
//! looked up with wrap-around.
//!
//! Why bytes and not linear floats: a hit on a textured surface reads one texel, at random
//! across textures that on Sponza add up to 6 MB as bytes and 25 MB as three f32 per texel.
//! As floats the read missed the caches so often that it took 62% of the shading's samples
//! there; as bytes the textures take a quarter of the memory. The table holds
//! `srgb_to_linear(v / 255)` for every byte `v`, the very expression the loader used to apply
//! to each texel once, so a lookup returns the same f32 bits as before.

use glam::{Vec2, Vec3};

/// A texture of sRGB-encoded bytes, read as linear RGB.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Texels per row.
    pub width: u32,
    /// Rows of texels.
    pub height: u32,
    /// Row-major, top row first, three sRGB bytes (red, green, blue) per texel.
    srgb: Vec<u8>,
    /// The linear value of each sRGB byte.
    to_linear: [f32; 256],
}

impl Texture {
    /// A texture of `width` x `height` texels from `srgb`, three sRGB-encoded bytes per texel
    /// (row-major, top row first), as 8-bit PNG and JPEG files store them.
    ///
    /// # Panics
    /// When `srgb` does not hold exactly `3 * width * height` bytes.
    pub fn from_srgb8(width: u32, height: u32, srgb: Vec<u8>) -> Self {
        assert_eq!(
            srgb.len() as u64,
            3 * u64::from(width) * u64::from(height),
            "three bytes per texel"
        );
        let to_linear =
            std::array::from_fn(|v| crate::output::srgb_to_linear(f32::from(v as u8) / 255.0));
        Texture {
            width,
            height,
            srgb,
            to_linear,
        }
    }

    /// Nearest-texel lookup with repeat wrapping; `v` = 0 is the bottom row, as in OBJ.
    #[inline]
    pub fn lookup(&self, uv: Vec2) -> Vec3 {
        self.texel(self.nearest(uv))
    }

    /// Asks for the memory of texel `index` ([`Texture::nearest`]). On scenes whose textures
    /// outgrow a core's caches (Sponza's), a texel read by a bounce lands anywhere in them and
    /// waits long on memory; the integrator asks for it as soon as it knows the coordinates and
    /// reads it once other work has overlapped the wait. A hint only: it reads nothing.
    #[inline]
    pub fn prefetch(&self, index: usize) {
        crate::geometry::prefetch(self.srgb.as_ptr().wrapping_add(3 * index));
    }

    /// The index of the texel nearest `uv`, wrapping around: what [`Texture::lookup`] reads.
    #[inline]
    pub fn nearest(&self, uv: Vec2) -> usize {
        let u = uv.x - uv.x.floor();
        let v = uv.y - uv.y.floor();
        let x = ((u * self.width as f32) as u32).min(self.width - 1);
        let y = (((1.0 - v) * self.height as f32) as u32).min(self.height - 1);
        (y * self.width + x) as usize
    }

    /// Texel `index` (row-major, top row first) in linear RGB.
    #[inline]
    pub fn texel(&self, index: usize) -> Vec3 {
        let [r, g, b]: [u8; 3] = self.srgb[3 * index..3 * index + 3]
            .try_into()
            .expect("a texel is three bytes");
        Vec3::new(
            self.to_linear[usize::from(r)],
            self.to_linear[usize::from(g)],
            self.to_linear[usize::from(b)],
        )
    }

    /// Every texel in linear RGB, row-major, top row first.
    pub fn texels(&self) -> impl Iterator<Item = Vec3> + '_ {
        (0..self.srgb.len() / 3).map(|i| self.texel(i))
    }

    /// The texels' bytes moved onto huge pages where the texture is large enough
    /// (`geometry/memory.rs`): a texel read at random then rarely pays a page-table walk.
    pub(crate) fn on_huge_pages(&mut self) {
        self.srgb = crate::geometry::on_huge_pages(std::mem::take(&mut self.srgb));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texels_decode_each_byte_as_the_loader_did_and_wrap() {
        // Two by two: top row (0, 1), bottom row (2, 3); each texel's bytes differ.
        let bytes: Vec<u8> = vec![0, 1, 2, 64, 128, 191, 200, 254, 255, 7, 77, 177];
        let texture = Texture::from_srgb8(2, 2, bytes.clone());
        let linear = |v: u8| crate::output::srgb_to_linear(f32::from(v) / 255.0);
        for (i, texel) in texture.texels().enumerate() {
            let want = Vec3::new(
                linear(bytes[3 * i]),
                linear(bytes[3 * i + 1]),
                linear(bytes[3 * i + 2]),
            );
            assert_eq!(
                texel.to_array().map(f32::to_bits),
                want.to_array().map(f32::to_bits)
            );
        }
        assert_eq!(texture.texel(0).x, 0.0);
        assert_eq!(texture.texel(2).z, 1.0);
        // v = 0 is the bottom row; u and v wrap.
        assert_eq!(texture.lookup(Vec2::new(0.25, 0.25)), texture.texel(2));
        assert_eq!(texture.lookup(Vec2::new(0.75, 0.75)), texture.texel(1));
        assert_eq!(texture.lookup(Vec2::new(-0.25, 1.75)), texture.texel(1));
        assert_eq!(texture.lookup(Vec2::new(1.0, 0.0)), texture.texel(2));
    }
}
