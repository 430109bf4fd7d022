//! The modified Phong BRDF (Lafortune & Willems 1994, in the normalised form of pbrt and
//! Veach's thesis):
//!
//! ```text
//! f = kd / π + ks (n + 2) / (2π) cos^n α_r
//! ```
//!
//! with α_r the angle between wi and the mirror direction of wo. Energy-conserving when
//! kd + ks ≤ 1. Sampling picks the diffuse lobe (cosine) or the specular lobe (density
//! (n + 1)/(2π) cos^n α_r about the mirror direction) in proportion to kd and ks; specular
//! directions below the surface are rejected.

use super::{BsdfSample, Lobe};
use crate::color::luminance;
use crate::geometry::frame::Frame;
use crate::sampling::warp::{
    cosine_hemisphere_pdf, phong_lobe_pdf, square_to_cosine_hemisphere, square_to_phong_lobe,
};
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// The Phong BRDF at one surface point.
#[derive(Clone, Copy, Debug)]
pub struct Phong {
    pub kd: Vec3,
    pub ks: Vec3,
    pub exponent: f32,
}

impl Phong {
    #[inline]
    fn mirror(wo: Vec3) -> Vec3 {
        Vec3::new(-wo.x, -wo.y, wo.z)
    }

    #[inline]
    fn specular_probability(&self) -> f32 {
        let (d, s) = (luminance(self.kd), luminance(self.ks));
        if d + s > 0.0 { s / (d + s) } else { 0.0 }
    }

    /// f · cos θi.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let [diffuse, glossy] = self.eval_lobes(wo, wi);
        diffuse + glossy
    }

    /// f · cos θi of the diffuse and the glossy lobe.
    #[inline]
    pub fn eval_lobes(&self, wo: Vec3, wi: Vec3) -> [Vec3; 2] {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return [Vec3::ZERO; 2];
        }
        let cos_r = Self::mirror(wo).dot(wi).max(0.0);
        let spec = (self.exponent + 2.0) / (2.0 * PI) * cos_r.powf(self.exponent);
        [self.kd * (FRAC_1_PI * wi.z), self.ks * (spec * wi.z)]
    }

    /// Density of [`Phong::sample`].
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let ps = self.specular_probability();
        let cos_r = Self::mirror(wo).dot(wi);
        (1.0 - ps) * cosine_hemisphere_pdf(wi) + ps * phong_lobe_pdf(cos_r, self.exponent)
    }

    /// Samples a lobe with `u_lobe`, then a direction with `u`.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let ps = self.specular_probability();
        let (wi, lobe) = if u_lobe < ps {
            let lobe_frame = Frame::from_normal(Self::mirror(wo));
            (
                lobe_frame.to_world(square_to_phong_lobe(u, self.exponent)),
                Lobe::Glossy,
            )
        } else {
            (square_to_cosine_hemisphere(u), Lobe::Diffuse)
        };
        if wi.z <= 0.0 {
            return None;
        }
        BsdfSample::from_mixture(wi, self.eval(wo, wi), self.pdf(wo, wi), lobe)
    }
}
