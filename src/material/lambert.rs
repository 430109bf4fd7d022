//! The Lambertian reflector: f = albedo / π.

use super::{BsdfSample, Lobe};
use crate::sampling::warp::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Diffuse reflection with the given albedo.
#[derive(Clone, Copy, Debug)]
pub struct Lambert {
    pub albedo: Vec3,
}

impl Lambert {
    /// f · cos θi.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Vec3::ZERO;
        }
        self.albedo * (FRAC_1_PI * wi.z)
    }

    /// Cosine-weighted density.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        cosine_hemisphere_pdf(wi)
    }

    /// Cosine-weighted sample: the weight is the albedo.
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = square_to_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wi);
        (pdf > 0.0).then_some(BsdfSample {
            wi,
            weight: self.albedo,
            pdf,
            lobe: Lobe::Diffuse,
        })
    }
}
