//! The GGX (Trowbridge-Reitz) microfacet distribution, isotropic ([`Ggx`]) and anisotropic
//! ([`AnisotropicGgx`]), with Smith masking and sampling of its visible normals. Local
//! frame: +z is the macro-surface normal. [`Microfacet`] is what the dielectric lobes need of
//! a distribution, so that one implementation serves both.

use glam::{Vec2, Vec3};
use std::f32::consts::PI;

pub use crate::scene::material::SMOOTH_ALPHA;

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

/// What the microfacet lobes of `dielectric` and `layered` need of a normal distribution:
/// its density, Smith's Λ, and sampling of the normals visible from a direction above the
/// surface.
pub trait Microfacet {
    /// Normal distribution D(h); zero below the surface.
    fn d(&self, h: Vec3) -> f32;
    /// Smith Λ(w) (of |cos θ|: the same from either side).
    fn lambda(&self, w: Vec3) -> f32;
    /// Samples a normal visible from `wo` (wo.z > 0).
    fn sample_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3;
    /// True below [`SMOOTH_ALPHA`] (in every direction): a delta lobe.
    fn is_smooth(&self) -> bool;

    /// Smith masking G1(w).
    #[inline]
    fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Separable Smith masking-shadowing G1(wo) G1(wi), as Walter et al. 2007 and
    /// Mitsuba 3 use for reflection and transmission alike.
    #[inline]
    fn g_separable(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.g1(wo) * self.g1(wi)
    }

    /// Height-correlated Smith masking-shadowing 1 / (1 + Λ(wo) + Λ(wi)) (reflection).
    #[inline]
    fn g_correlated(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// Density of [`Microfacet::sample_visible_normal`] over normals:
    /// G1(wo) max(0, wo·h) D(h) / wo.z.
    #[inline]
    fn visible_normal_pdf(&self, wo: Vec3, h: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        self.g1(wo) * wo.dot(h).max(0.0) * self.d(h) / wo.z
    }
}

impl Microfacet for Ggx {
    #[inline]
    fn d(&self, h: Vec3) -> f32 {
        Ggx::d(self, h)
    }
    #[inline]
    fn lambda(&self, w: Vec3) -> f32 {
        Ggx::lambda(self, w)
    }
    #[inline]
    fn sample_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
        Ggx::sample_visible_normal(self, wo, u)
    }
    #[inline]
    fn is_smooth(&self) -> bool {
        self.alpha < SMOOTH_ALPHA
    }
}

/// Anisotropic GGX (Burley 2012's extension; KHR_materials_anisotropy): roughness `alpha_x`
/// along the local x axis (the tangent), `alpha_y` along y.
#[derive(Clone, Copy, Debug)]
pub struct AnisotropicGgx {
    pub alpha_x: f32,
    pub alpha_y: f32,
}

impl Microfacet for AnisotropicGgx {
    #[inline]
    fn d(&self, h: Vec3) -> f32 {
        if h.z <= 0.0 {
            return 0.0;
        }
        let (ax, ay) = (self.alpha_x, self.alpha_y);
        let t = (h.x / ax).powi(2) + (h.y / ay).powi(2) + h.z * h.z;
        1.0 / (PI * ax * ay * t * t)
    }

    #[inline]
    fn lambda(&self, w: Vec3) -> f32 {
        let cos2 = w.z * w.z;
        if cos2 <= 0.0 {
            return f32::INFINITY;
        }
        let a2_tan2 = ((self.alpha_x * w.x).powi(2) + (self.alpha_y * w.y).powi(2)).max(0.0) / cos2;
        0.5 * ((1.0 + a2_tan2).sqrt() - 1.0)
    }

    #[inline]
    fn sample_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
        let (ax, ay) = (self.alpha_x, self.alpha_y);
        let wo_std = Vec3::new(wo.x * ax, wo.y * ay, wo.z).normalize();
        let phi = 2.0 * PI * u.x;
        let z = (1.0 - u.y) * (1.0 + wo_std.z) - wo_std.z;
        let sin_theta = (1.0 - z * z).clamp(0.0, 1.0).sqrt();
        let (sin_phi, cos_phi) = crate::sampling::warp::sin_cos(phi);
        let h_std = Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, z) + wo_std;
        Vec3::new(h_std.x * ax, h_std.y * ay, h_std.z.max(0.0)).normalize()
    }

    #[inline]
    fn is_smooth(&self) -> bool {
        self.alpha_x.max(self.alpha_y) < SMOOTH_ALPHA
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

    /// The anisotropic distribution with equal alphas is the isotropic one, and its
    /// visible normals integrate to one (the weak white furnace) when stretched.
    #[test]
    fn anisotropic_ggx_reduces_to_isotropic_and_is_normalised() {
        let iso = Ggx { alpha: 0.3 };
        let aniso = AnisotropicGgx {
            alpha_x: 0.3,
            alpha_y: 0.3,
        };
        let h = Vec3::new(0.2, -0.1, 0.97).normalize();
        let w = Vec3::new(0.5, 0.3, 0.81).normalize();
        assert!((Microfacet::d(&aniso, h) - iso.d(h)).abs() < 1e-4 * iso.d(h));
        assert!((Microfacet::lambda(&aniso, w) - iso.lambda(w)).abs() < 1e-5);
        let u = Vec2::new(0.3, 0.7);
        assert!(
            (aniso.sample_visible_normal(w, u) - iso.sample_visible_normal(w, u)).length() < 1e-5
        );
        let ggx = AnisotropicGgx {
            alpha_x: 0.6,
            alpha_y: 0.1,
        };
        for theta in [0.0f32, 0.7, 1.3] {
            let wo = Vec3::new(theta.sin() * 0.6, theta.sin() * 0.8, theta.cos());
            // ∫ D_wo(h) dh over the hemisphere, by uniform sampling of normals.
            let mut rng = Pcg32::new(3, theta.to_bits() as u64);
            let n = 400_000;
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for _ in 0..n {
                let h = crate::sampling::warp::square_to_uniform_hemisphere(Vec2::new(
                    rng.next_f32(),
                    rng.next_f32(),
                ));
                let x = (ggx.visible_normal_pdf(wo, h) * 2.0 * PI) as f64;
                sum += x;
                sum2 += x * x;
            }
            let mean = sum / n as f64;
            let se = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
            assert!(
                (mean - 1.0).abs() < 4.5 * se + 1e-3,
                "{theta}: {mean} ± {se}"
            );
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
