//! The sheen of KHR_materials_sheen: a layer of fibres (velvet, cloth) that scatters light
//! back and to grazing angles. The BRDF is the extension's: Conty & Kulla 2017's "Charlie"
//! distribution D(h) = (2 + 1/α) sin(θh)^(1/α) / 2π, α = roughness², with their fitted
//! visibility V = 1 / ((1 + Λ(wo) + Λ(wi)) 4 cos θo cos θi), times the sheen colour. The
//! layer below is scaled by 1 - max(colour) E(cos θ) (the extension's albedo scaling,
//! taken at both directions and the smaller kept, which keeps the layering reciprocal),
//! where E is the sheen's directional albedo, tabulated by `tools/generate/sheen_albedo.py`.
//! Sampled by the cosine-weighted hemisphere: the lobe is broad.
//!
//! Roughness is clamped below at [`MIN_ROUGHNESS`]: the distribution collapses onto the
//! horizon as α goes to 0, and the fitted visibility there is not meant for it.

use super::sheen_albedo::ALBEDO;
use glam::Vec3;
use std::f32::consts::PI;

/// The smallest sheen roughness used (smaller ones are taken as this).
pub const MIN_ROUGHNESS: f32 = 0.07;

/// The sheen layer at a surface point.
#[derive(Clone, Copy, Debug)]
pub struct Sheen {
    pub color: Vec3,
    /// Perceptual roughness, clamped to [`MIN_ROUGHNESS`, 1].
    roughness: f32,
    alpha: f32,
}

/// Conty & Kulla's fit L(x) of the Charlie masking's exponent.
#[inline]
fn fit(x: f32, alpha: f32) -> f32 {
    let t = (1.0 - alpha) * (1.0 - alpha);
    let mix = |a: f32, b: f32| a * (1.0 - t) + b * t;
    mix(21.5473, 25.3245) / (1.0 + mix(3.82987, 3.32435) * x.powf(mix(0.19823, 0.16801)))
        + mix(-1.97760, -1.27393) * x
        + mix(-4.32054, -4.85967)
}

/// The Charlie masking's Λ at |cos θ| = `cos`.
#[inline]
fn lambda(cos: f32, alpha: f32) -> f32 {
    let cos = cos.abs();
    if cos < 0.5 {
        fit(cos, alpha).exp()
    } else {
        (2.0 * fit(0.5, alpha) - fit(1.0 - cos, alpha)).exp()
    }
}

impl Sheen {
    /// A sheen of `color` and perceptual `roughness`.
    pub fn new(color: Vec3, roughness: f32) -> Self {
        let roughness = if roughness.is_finite() {
            roughness.clamp(MIN_ROUGHNESS, 1.0)
        } else {
            1.0
        };
        Self {
            color: color.clamp(Vec3::ZERO, Vec3::ONE),
            roughness,
            alpha: roughness * roughness,
        }
    }

    /// The Charlie distribution at the half vector `h`.
    #[inline]
    fn d(&self, h: Vec3) -> f32 {
        let inv = 1.0 / self.alpha;
        let sin2 = (1.0 - h.z * h.z).max(0.0);
        (2.0 + inv) * sin2.powf(0.5 * inv) / (2.0 * PI)
    }

    /// f · cos θi for `wo`, `wi` above the surface (zero otherwise).
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Vec3::ZERO;
        }
        let h = (wo + wi).normalize();
        let v = 1.0 / ((1.0 + lambda(wo.z, self.alpha) + lambda(wi.z, self.alpha)) * 4.0 * wo.z);
        self.color * (self.d(h) * v)
    }

    /// The sheen's directional albedo at `cos` (white sheen): a bilinear lookup of the
    /// table.
    #[inline]
    pub fn albedo(&self, cos: f32) -> f32 {
        super::table::bilinear(&ALBEDO, self.roughness, cos)
    }

    /// The share of the layer below that shows through, for light arriving along `wi` and
    /// leaving along `wo`: 1 - max(colour) E, the smaller of the two directions'.
    #[inline]
    pub fn scaling(&self, cos_o: f32, cos_i: f32) -> f32 {
        let m = self.color.max_element();
        let e = self.albedo(cos_o.abs()).max(self.albedo(cos_i.abs()));
        (1.0 - m * e).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::pcg::Pcg32;
    use crate::sampling::warp::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
    use glam::Vec2;

    /// The generated table is the integral of the BRDF as evaluated here (so the generator
    /// and the renderer agree on the model): Monte Carlo within 4.5 standard errors and 1 %.
    #[test]
    fn albedo_table_integrates_the_brdf() {
        for (roughness, cos) in [(0.3f32, 0.8f32), (0.6, 0.4), (1.0, 0.95), (0.15, 0.2)] {
            let sheen = Sheen::new(Vec3::ONE, roughness);
            let wo = Vec3::new((1.0 - cos * cos).sqrt(), 0.0, cos);
            let mut rng = Pcg32::new(21, roughness.to_bits() as u64);
            let n = 400_000;
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for _ in 0..n {
                let wi = square_to_cosine_hemisphere(Vec2::new(rng.next_f32(), rng.next_f32()));
                let pdf = cosine_hemisphere_pdf(wi);
                if pdf <= 0.0 {
                    continue;
                }
                let x = (sheen.eval(wo, wi).x / pdf) as f64;
                sum += x;
                sum2 += x * x;
            }
            let mean = sum / n as f64;
            let se = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
            // The table's bilinear interpolation between its 32 × 32 points adds a little.
            let table = sheen.albedo(cos) as f64;
            assert!(
                (mean - table).abs() < 4.5 * se + 0.01 * table,
                "roughness {roughness} cos {cos}: integral {mean} ± {se}, table {table}"
            );
        }
    }

    #[test]
    fn the_distribution_is_normalised() {
        // ∫ D(h) cos θh dω = 1 for every roughness.
        for roughness in [0.1f32, 0.5, 1.0] {
            let sheen = Sheen::new(Vec3::ONE, roughness);
            let n = 4096;
            let total: f64 = (0..n)
                .map(|i| {
                    let cos = (i as f32 + 0.5) / n as f32;
                    let h = Vec3::new((1.0 - cos * cos).sqrt(), 0.0, cos);
                    (sheen.d(h) * cos * 2.0 * PI / n as f32) as f64
                })
                .sum();
            assert!((total - 1.0).abs() < 2e-3, "{roughness}: {total}");
        }
    }
}
