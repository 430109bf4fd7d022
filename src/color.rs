//! Colour helpers. Colours are linear Rec.709/sRGB-primaries RGB held in `glam::Vec3`.

use glam::{Vec3, Vec4};
use std::sync::LazyLock;

/// Rec.709 luminance of a linear RGB colour.
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// sRGB electro-optical transfer: encoded value in [0, 1] to linear.
#[inline]
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Inverse of [`srgb_to_linear`]: linear value to sRGB-encoded value (not clamped).
#[inline]
pub fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.0031308 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// 8-bit sRGB code value to linear, tabulated: texture lookups decode every texel they touch.
pub static SRGB8_TO_LINEAR: LazyLock<[f32; 256]> =
    LazyLock::new(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)));

/// An 8-bit RGBA texel, linear (colour channels sRGB-decoded where `srgb` is set).
#[inline(always)]
pub fn rgba8_to_linear([r, g, b, a]: [u8; 4], srgb: bool) -> Vec4 {
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

/// A 16-bit RGBA texel, linear (colour channels sRGB-decoded where `srgb` is set).
#[inline(always)]
pub fn rgba16_to_linear(t: [u16; 4], srgb: bool) -> Vec4 {
    let [r, g, b, a] = t.map(|v| v as f32 / 65535.0);
    if srgb {
        Vec4::new(srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b), a)
    } else {
        Vec4::new(r, g, b, a)
    }
}
