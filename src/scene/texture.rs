//! Textures: decoded images with their sampler state, looked up bilinearly.

use crate::color::{SRGB8_TO_LINEAR, srgb_to_linear};
use glam::{Vec2, Vec4};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Texel storage. Integer images keep their stored values (8 or 16 bits a channel) and are
/// sRGB-decoded per lookup where the material slot says so, because one image may serve
/// both colour and data slots. Float images (OpenEXR, Radiance HDR, float TIFF) hold linear
/// values and are read as they are in every slot, as OpenImageIO-based renderers do.
#[derive(Clone, Debug)]
pub enum Texels {
    Rgba8(Vec<[u8; 4]>),
    Rgba16(Vec<[u16; 4]>),
    RgbaF32(Vec<[f32; 4]>),
}

/// How coordinates outside [0, 1) map into the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Wrap {
    Repeat,
    MirroredRepeat,
    ClampToEdge,
}

/// A 2D image with its sampler.
#[derive(Clone, Debug)]
pub struct Texture {
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Shared: several textures (sampler variants) and the environment may use one image.
    pub texels: Arc<Texels>,
    pub wrap_u: Wrap,
    pub wrap_v: Wrap,
    /// Nearest-texel lookups instead of bilinear (glTF magFilter NEAREST).
    pub nearest: bool,
}

#[inline]
fn wrap(i: i64, n: u32, mode: Wrap) -> usize {
    let n = n as i64;
    (match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let period = i.rem_euclid(2 * n);
            if period < n {
                period
            } else {
                2 * n - 1 - period
            }
        }
    }) as usize
}

impl Texture {
    #[inline]
    fn texel(&self, x: usize, y: usize, srgb: bool) -> Vec4 {
        let i = y * self.width as usize + x;
        match &*self.texels {
            Texels::Rgba8(t) => {
                let [r, g, b, a] = t[i];
                if srgb {
                    let lut = &*SRGB8_TO_LINEAR;
                    Vec4::new(
                        lut[r as usize],
                        lut[g as usize],
                        lut[b as usize],
                        a as f32 / 255.0,
                    )
                } else {
                    Vec4::new(r as f32, g as f32, b as f32, a as f32) / 255.0
                }
            }
            Texels::Rgba16(t) => {
                let [r, g, b, a] = t[i].map(|v| v as f32 / 65535.0);
                if srgb {
                    Vec4::new(srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b), a)
                } else {
                    Vec4::new(r, g, b, a)
                }
            }
            Texels::RgbaF32(t) => Vec4::from_array(t[i]),
        }
    }

    /// Looks up `uv` (glTF convention: (0, 0) is the image's top-left corner), decoding sRGB
    /// 8-bit texels to linear when `srgb` is set. Bilinear unless the sampler says nearest.
    pub fn sample(&self, uv: Vec2, srgb: bool) -> Vec4 {
        if !uv.is_finite() {
            return self.texel(0, 0, srgb);
        }
        let x = uv.x as f64 * self.width as f64 - 0.5;
        let y = uv.y as f64 * self.height as f64 - 0.5;
        if self.nearest {
            let xi = wrap((x + 0.5).floor() as i64, self.width, self.wrap_u);
            let yi = wrap((y + 0.5).floor() as i64, self.height, self.wrap_v);
            return self.texel(xi, yi, srgb);
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let xa = wrap(x0, self.width, self.wrap_u);
        let xb = wrap(x0 + 1, self.width, self.wrap_u);
        let ya = wrap(y0, self.height, self.wrap_v);
        let yb = wrap(y0 + 1, self.height, self.wrap_v);
        let top = self.texel(xa, ya, srgb).lerp(self.texel(xb, ya, srgb), fx);
        let bottom = self.texel(xa, yb, srgb).lerp(self.texel(xb, yb, srgb), fx);
        top.lerp(bottom, fy)
    }

    /// Mean linear value over the image (for light power estimates).
    pub fn mean(&self, srgb: bool) -> Vec4 {
        let n = (self.width as usize * self.height as usize).max(1);
        let mut sum = glam::DVec4::ZERO;
        for y in 0..self.height as usize {
            for x in 0..self.width as usize {
                sum += self.texel(x, y, srgb).as_dvec4();
            }
        }
        (sum / n as f64).as_vec4()
    }

    /// Bytes held by the texels.
    pub fn memory_bytes(&self) -> usize {
        match &*self.texels {
            Texels::Rgba8(t) => t.len() * 4,
            Texels::Rgba16(t) => t.len() * 8,
            Texels::RgbaF32(t) => t.len() * 16,
        }
    }

    /// Linear value of texel (`x`, `y`) without filtering (for building sampling tables).
    pub fn texel_linear(&self, x: u32, y: u32, srgb: bool) -> Vec4 {
        self.texel(x as usize, y as usize, srgb)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_modes() {
        assert_eq!(wrap(-1, 4, Wrap::Repeat), 3);
        assert_eq!(wrap(5, 4, Wrap::Repeat), 1);
        assert_eq!(wrap(-1, 4, Wrap::ClampToEdge), 0);
        assert_eq!(wrap(9, 4, Wrap::ClampToEdge), 3);
        assert_eq!(wrap(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(-1, 4, Wrap::MirroredRepeat), 0);
        assert_eq!(wrap(8, 4, Wrap::MirroredRepeat), 0);
    }

    #[test]
    fn bilinear_lookup_interpolates_between_texel_centres() {
        let t = Texture {
            name: String::new(),
            width: 2,
            height: 1,
            texels: Arc::new(Texels::RgbaF32(vec![[0.0; 4], [1.0; 4]])),
            wrap_u: Wrap::ClampToEdge,
            wrap_v: Wrap::ClampToEdge,
            nearest: false,
        };
        assert!((t.sample(Vec2::new(0.25, 0.5), false).x - 0.0).abs() < 1e-6);
        assert!((t.sample(Vec2::new(0.5, 0.5), false).x - 0.5).abs() < 1e-6);
        assert!((t.sample(Vec2::new(0.75, 0.5), false).x - 1.0).abs() < 1e-6);
    }
}
