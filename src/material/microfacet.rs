//! The GGX (Trowbridge-Reitz) microfacet distribution with height-correlated Smith masking,
//! and sampling of its visible normals. Local frame: +z is the macro-surface normal.

use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Below this alpha (roughness²) a surface is treated as perfectly smooth (a delta lobe),
/// as pbrt-v4 does: the distribution is too peaked for floats to evaluate reliably.
pub const SMOOTH_ALPHA: f32 = 1e-3;

/// Isotropic GGX with alpha = roughness².
#[derive(Clone, Copy, Debug)]
pub struct Ggx {
    pub alpha: f32,
}

impl Ggx {
    /// Normal distribution D(h); zero below the surface.
    #[inline]
    pub fn d(&self, h: Vec3) -> f32 {
        if h.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let t = h.z * h.z * (a2 - 1.0) + 1.0;
        a2 / (PI * t * t)
    }

    /// Smith Λ(w) for GGX.
    #[inline]
    pub fn lambda(&self, w: Vec3) -> f32 {
        let cos2 = w.z * w.z;
        if cos2 <= 0.0 {
            return f32::INFINITY;
        }
        let tan2 = ((1.0 - cos2) / cos2).max(0.0);
        0.5 * ((1.0 + self.alpha * self.alpha * tan2).sqrt() - 1.0)
    }

    /// Smith masking G1(w).
    #[inline]
    pub fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// The glTF specification's visibility term V = G2 / (4 |n·l| |n·v|) with
    /// height-correlated Smith G2, in the specification's own closed form.
    #[inline]
    pub fn visibility(&self, n_dot_l: f32, n_dot_v: f32) -> f32 {
        let a2 = self.alpha * self.alpha;
        let gv = n_dot_l * (n_dot_v * n_dot_v * (1.0 - a2) + a2).sqrt();
        let gl = n_dot_v * (n_dot_l * n_dot_l * (1.0 - a2) + a2).sqrt();
        let s = gv + gl;
        if s > 0.0 { 0.5 / s } else { 0.0 }
    }

    /// Samples a normal visible from `wo` (wo.z > 0) with density
    /// D_wo(h) = G1(wo) max(0, wo·h) D(h) / wo.z, by the spherical-cap method
    /// (Dupuy & Benyoub 2023, equivalent to Heitz 2018's visible-normal sampling).
    #[inline]
    pub fn sample_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
        let a = self.alpha;
        let wo_std = Vec3::new(wo.x * a, wo.y * a, wo.z).normalize();
        let phi = 2.0 * PI * u.x;
        let z = (1.0 - u.y) * (1.0 + wo_std.z) - wo_std.z;
        let sin_theta = (1.0 - z * z).clamp(0.0, 1.0).sqrt();
        let (sin_phi, cos_phi) = crate::sampling::warp::sin_cos(phi);
        let cap = Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, z);
        let h_std = cap + wo_std;
        Vec3::new(h_std.x * a, h_std.y * a, h_std.z.max(0.0)).normalize()
    }

    /// Density of [`Ggx::sample_visible_normal`] over normals.
    #[inline]
    pub fn visible_normal_pdf(&self, wo: Vec3, h: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        self.g1(wo) * wo.dot(h).max(0.0) * self.d(h) / wo.z
    }

    /// Density of the reflected direction `wi` when `h` is sampled by
    /// [`Ggx::sample_visible_normal`]: D_wo(h) / (4 |wo·h|) = G1(wo) D(h) / (4 wo.z).
    #[inline]
    pub fn reflection_pdf(&self, wo: Vec3, h: Vec3) -> f32 {
        let wo_h = wo.dot(h);
        if wo_h <= 0.0 {
            return 0.0;
        }
        self.visible_normal_pdf(wo, h) / (4.0 * wo_h)
    }
}

/// Mirror reflection of `w` about `n`.
#[inline]
pub fn reflect(w: Vec3, n: Vec3) -> Vec3 {
    2.0 * w.dot(n) * n - w
}

/// Schlick's Fresnel approximation F0 + (1 - F0)(1 - cos)^5.
#[inline]
pub fn schlick(f0: Vec3, cos: f32) -> Vec3 {
    let m = (1.0 - cos.abs()).clamp(0.0, 1.0);
    let m2 = m * m;
    f0 + (Vec3::ONE - f0) * (m2 * m2 * m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::pcg::Pcg32;

    /// Weak white furnace (Heitz 2014): ∫ G1(wo) max(0, wo·h) D(h) / wo.z dh = 1 for every
    /// wo and alpha, which checks D's normalisation and G1 together.
    #[test]
    fn weak_white_furnace() {
        for alpha in [0.01f32, 0.1, 0.5, 1.0] {
            let ggx = Ggx { alpha };
            for theta in [0.0f32, 0.7, 1.2, 1.5] {
                let wo = Vec3::new(theta.sin(), 0.0, theta.cos());
                // Integrate over the hemisphere of normals by importance sampling D(h) cosθ_h.
                let mut rng = Pcg32::new(alpha.to_bits() as u64, theta.to_bits() as u64);
                let n = 200_000;
                let (mut sum, mut sum2) = (0.0f64, 0.0f64);
                for _ in 0..n {
                    let (u1, u2) = (rng.next_f32(), rng.next_f32());
                    // D(h) cos θh sampling: tan²θ = α² u / (1 - u).
                    let tan2 = alpha * alpha * u1 / (1.0 - u1);
                    let cos = 1.0 / (1.0 + tan2).sqrt();
                    let sin = (1.0 - cos * cos).max(0.0).sqrt();
                    let phi = 2.0 * PI * u2;
                    let h = Vec3::new(sin * phi.cos(), sin * phi.sin(), cos);
                    let pdf = ggx.d(h) * cos;
                    let x = (ggx.visible_normal_pdf(wo, h) / pdf) as f64;
                    sum += x;
                    sum2 += x * x;
                }
                let mean = sum / n as f64;
                let standard_error = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
                // 4.5 standard errors: a false alarm about once in 150,000 runs per case.
                assert!(
                    (mean - 1.0).abs() < 4.5 * standard_error + 1e-4,
                    "alpha {alpha} theta {theta}: {mean} ± {standard_error}"
                );
            }
        }
    }

    #[test]
    fn visibility_matches_smith_g2() {
        let ggx = Ggx { alpha: 0.3 };
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let wi = Vec3::new(-0.28, 0.0, 0.96);
        let g2 = 1.0 / (1.0 + ggx.lambda(wo) + ggx.lambda(wi));
        let v = g2 / (4.0 * wo.z * wi.z);
        assert!((ggx.visibility(wi.z, wo.z) - v).abs() < 1e-5 * v);
    }
}
