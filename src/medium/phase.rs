//! The Henyey-Greenstein phase function: the angular distribution of light scattered in a
//! medium, one parameter `g` (the mean cosine of the scattering angle: 0 isotropic, towards
//! 1 forward, towards −1 backward), as Mitsuba's `hg`, pbrt-v4, Cycles and OpenPBR use it.
//!
//! Angles are measured from the direction light travels along before scattering (the ray's
//! direction), so `g > 0` keeps light going the way it went. The phase function is
//! normalised over the sphere and sampled exactly (its inverse CDF in cos θ), so a sample's
//! weight is one and its density is the function's value.

use crate::geometry::frame::Frame;
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// Below this |g| the phase function is isotropic to float precision, and its inverse CDF
/// (which divides by g) is replaced by the uniform sphere's.
const ISOTROPIC_G: f32 = 1e-3;

/// `g` is kept inside (−1, 1): at ±1 the distribution is a delta.
pub const MAX_G: f32 = 0.99;

/// A Henyey-Greenstein phase function of mean cosine `g`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HenyeyGreenstein {
    g: f32,
}

impl HenyeyGreenstein {
    /// The phase function of mean cosine `g`, clamped to [−[`MAX_G`], [`MAX_G`]].
    pub fn new(g: f32) -> Self {
        Self {
            g: g.clamp(-MAX_G, MAX_G),
        }
    }

    /// Its mean cosine.
    pub fn g(&self) -> f32 {
        self.g
    }

    /// Density per steradian of scattering by angle θ, `cos_theta` = cos θ between the
    /// direction travelled and the direction scattered into.
    #[inline]
    pub fn eval(&self, cos_theta: f32) -> f32 {
        let g = self.g;
        let denom = (1.0 + g * g - 2.0 * g * cos_theta).max(1e-12);
        0.25 * FRAC_1_PI * (1.0 - g * g) / (denom * denom.sqrt())
    }

    /// A direction scattered into from travel direction `dir` (unit), drawn in proportion
    /// to the phase function from `u`, with its density.
    #[inline]
    pub fn sample(&self, dir: Vec3, u: Vec2) -> (Vec3, f32) {
        let g = self.g;
        let cos_theta = if g.abs() < ISOTROPIC_G {
            1.0 - 2.0 * u.x
        } else {
            let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
            (1.0 + g * g - s * s) / (2.0 * g)
        }
        .clamp(-1.0, 1.0);
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        let local = Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta);
        let wi = Frame::from_normal(dir).to_world(local);
        (wi, self.eval(cos_theta))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_cosine_is_g_and_density_integrates_to_one() {
        for g in [-0.9f32, -0.3, 0.0, 0.5, 0.95] {
            let hg = HenyeyGreenstein::new(g);
            // Integrate over cos θ (2π from φ) with the midpoint rule.
            let n = 200_000;
            let (mut total, mut mean) = (0.0f64, 0.0f64);
            for i in 0..n {
                let c = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                let p = hg.eval(c as f32) as f64 * 2.0 * std::f64::consts::PI * 2.0 / n as f64;
                total += p;
                mean += p * c;
            }
            assert!((total - 1.0).abs() < 2e-3, "g={g}: integral {total}");
            assert!((mean - g as f64).abs() < 2e-3, "g={g}: mean cosine {mean}");
        }
    }

    #[test]
    fn sampled_directions_follow_the_travel_direction() {
        let dir = Vec3::new(0.3, -0.5, 0.8).normalize();
        let hg = HenyeyGreenstein::new(0.8);
        let (wi, pdf) = hg.sample(dir, Vec2::new(0.999, 0.3));
        assert!((wi.length() - 1.0).abs() < 1e-5);
        assert!(
            wi.dot(dir) > 0.9,
            "forward scattering goes forward: {}",
            wi.dot(dir)
        );
        assert!((pdf - hg.eval(wi.dot(dir))).abs() < 1e-3 * pdf);
    }
}
