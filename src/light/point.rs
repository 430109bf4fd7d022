//! A point light: radiant intensity from one point, reached by light sampling alone.

use super::sample::LightSample;
use super::tree::LightBounds;
use crate::color::luminance;
use glam::Vec3;
use std::f32::consts::PI;

/// A point light (KHR_lights_punctual `point`, UsdLux `SphereLight` of radius 0).
#[derive(Clone, Debug)]
pub struct PointLight {
    pub position: Vec3,
    /// Radiant intensity, W/sr.
    pub intensity: Vec3,
}

impl PointLight {
    /// Emitted power (luminance).
    pub fn power(&self) -> f32 {
        4.0 * PI * luminance(self.intensity)
    }

    /// The delta sample towards the light from `p`.
    #[inline]
    pub fn sample(&self, p: Vec3) -> Option<LightSample> {
        let to_light = self.position - p;
        let d2 = to_light.length_squared();
        (d2 > 0.0).then(|| LightSample {
            wi: to_light / d2.sqrt(),
            target: Some(self.position),
            area_point: None,
            radiance: self.intensity / d2,
            pdf: 1.0,
            delta: true,
        })
    }

    /// What the light tree knows of it: a point emitting in every direction.
    pub fn bounds(&self, phi: f32) -> LightBounds {
        LightBounds {
            min: self.position,
            max: self.position,
            phi,
            w: Vec3::Y,
            cos_theta_o: -1.0,
            cos_theta_e: 0.0,
            two_sided: false,
        }
    }
}
