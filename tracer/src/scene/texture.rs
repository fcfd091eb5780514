//! Decoded textures: linear RGB texels, looked up with wrap-around.

use glam::{Vec2, Vec3};

/// A texture in linear RGB (sRGB-encoded files are decoded to linear at load time).
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    /// Row-major, top row first.
    pub texels: Vec<Vec3>,
}

impl Texture {
    /// Nearest-texel lookup with repeat wrapping; `v` = 0 is the bottom row, as in OBJ.
    pub fn lookup(&self, uv: Vec2) -> Vec3 {
        let u = uv.x - uv.x.floor();
        let v = uv.y - uv.y.floor();
        let x = ((u * self.width as f32) as u32).min(self.width - 1);
        let y = (((1.0 - v) * self.height as f32) as u32).min(self.height - 1);
        self.texels[(y * self.width + x) as usize]
    }
}
