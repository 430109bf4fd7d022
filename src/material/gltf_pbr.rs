//! The glTF 2.0 metallic-roughness BRDF exactly as the specification's appendix B defines it:
//!
//! ```text
//! metal      = F_m(v·h) · V · D,            F_m = base + (1 - base)(1 - |v·h|)^5
//! dielectric = mix(base / π, V · D, F_d),    F_d = f0 + (1 - f0)(1 - |v·h|)^5, f0 = 0.04
//! material   = mix(dielectric, metal, metallic)
//! ```
//!
//! with GGX D, the height-correlated Smith visibility V and alpha = roughness². `f0` follows
//! KHR_materials_ior when present ((ior - 1) / (ior + 1))², 0.04 for the default 1.5).
//! Below [`SMOOTH_ALPHA`] the specular lobe is a perfect mirror (a delta lobe) with the
//! same Fresnel weights at h = n, so roughness 0 is exact rather than NaN.
//!
//! Sampling picks the diffuse lobe (cosine) or the specular lobe (GGX visible normals) with
//! probabilities proportional to their albedo estimates at `wo`; the density is the mixture.

use super::microfacet::{Ggx, SMOOTH_ALPHA, reflect, schlick};
use super::{BsdfSample, Lobe};
use crate::color::luminance;
use crate::sampling::warp::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// The glTF metallic-roughness BRDF at one surface point.
#[derive(Clone, Copy, Debug)]
pub struct GltfPbr {
    base: Vec3,
    metallic: f32,
    ggx: Ggx,
    f0: f32,
}

impl GltfPbr {
    /// A BRDF from base colour, metallic, perceptual roughness and dielectric ior.
    pub fn new(base: Vec3, metallic: f32, roughness: f32, ior: f32) -> Self {
        let r = roughness.clamp(0.0, 1.0);
        let f0 = ((ior - 1.0) / (ior + 1.0)).powi(2);
        Self {
            base: base.clamp(Vec3::ZERO, Vec3::ONE),
            metallic: metallic.clamp(0.0, 1.0),
            ggx: Ggx { alpha: r * r },
            f0: if f0.is_finite() {
                f0.clamp(0.0, 1.0)
            } else {
                0.04
            },
        }
    }

    fn smooth(&self) -> bool {
        self.ggx.alpha < SMOOTH_ALPHA
    }

    /// Specular reflectance (dielectric and metal Fresnel, mixed by metallic) at `cos`.
    #[inline]
    fn specular_fresnel(&self, cos: f32) -> Vec3 {
        let fd = schlick(Vec3::splat(self.f0), cos);
        let fm = schlick(self.base, cos);
        fd * (1.0 - self.metallic) + fm * self.metallic
    }

    /// Diffuse weight (1 - metallic)(1 - F_d(cos)) base.
    #[inline]
    fn diffuse_weight(&self, cos: f32) -> Vec3 {
        let fd = schlick(Vec3::splat(self.f0), cos).x;
        self.base * ((1.0 - self.metallic) * (1.0 - fd))
    }

    /// Probability of sampling the specular lobe from `wo`.
    #[inline]
    fn specular_probability(&self, wo: Vec3) -> f32 {
        let s = luminance(self.specular_fresnel(wo.z));
        let d = luminance(self.diffuse_weight(wo.z));
        if s + d > 0.0 { s / (s + d) } else { 1.0 }
    }

    /// f · cos θi of the non-delta lobes.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Vec3::ZERO;
        }
        let h = (wo + wi).normalize();
        let v_h = wo.dot(h);
        let mut f = self.diffuse_weight(v_h) * FRAC_1_PI;
        if !self.smooth() {
            let vd = self.ggx.visibility(wi.z, wo.z) * self.ggx.d(h);
            f += self.specular_fresnel(v_h) * vd;
        }
        f * wi.z
    }

    /// Density of [`GltfPbr::sample`] for the non-delta lobes.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let ps = self.specular_probability(wo);
        let mut pdf = (1.0 - ps) * cosine_hemisphere_pdf(wi);
        if !self.smooth() {
            let h = (wo + wi).normalize();
            pdf += ps * self.ggx.reflection_pdf(wo, h);
        }
        pdf
    }

    /// Samples a lobe with `u_lobe`, then a direction with `u`.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let ps = self.specular_probability(wo);
        if u_lobe < ps {
            if self.smooth() {
                let wi = Vec3::new(-wo.x, -wo.y, wo.z);
                return Some(BsdfSample {
                    wi,
                    weight: self.specular_fresnel(wo.z) / ps,
                    pdf: ps,
                    lobe: Lobe::Specular,
                });
            }
            let h = self.ggx.sample_visible_normal(wo, u);
            let wi = reflect(wo, h);
            if wi.z <= 0.0 {
                return None;
            }
            self.finish(wo, wi, Lobe::Glossy)
        } else {
            let wi = square_to_cosine_hemisphere(u);
            self.finish(wo, wi, Lobe::Diffuse)
        }
    }

    fn finish(&self, wo: Vec3, wi: Vec3, lobe: Lobe) -> Option<BsdfSample> {
        BsdfSample::from_mixture(wi, self.eval(wo, wi), self.pdf(wo, wi), lobe)
    }

    /// True if some lobe is not a delta: false only for a smooth pure metal.
    pub fn has_non_delta(&self) -> bool {
        !self.smooth() || self.metallic < 1.0
    }

    /// Directional albedo estimate at `wo` (Fresnel at n·v, no microfacet energy loss):
    /// the denoising albedo.
    pub fn albedo(&self, wo: Vec3) -> Vec3 {
        let c = wo.z.clamp(0.0, 1.0);
        self.diffuse_weight(c) + self.specular_fresnel(c)
    }
}
