//! A spot light: a point light whose intensity falls off over a cone (the glTF ramp).

use super::sample::LightSample;
use super::tree::LightBounds;
use crate::color::luminance;
use glam::Vec3;
use std::f32::consts::PI;

/// A spot light (KHR_lights_punctual `spot`, UsdLux `ShapingAPI` cones).
#[derive(Clone, Debug)]
pub struct SpotLight {
    pub position: Vec3,
    /// Unit direction the cone points to.
    pub axis: Vec3,
    /// Radiant intensity on the axis, W/sr.
    pub intensity: Vec3,
    pub cos_inner: f32,
    pub cos_outer: f32,
}

/// The glTF spot cone falloff (KHR_lights_punctual): a squared linear ramp in cos angle;
/// a hard edge where the inner cone is as wide as the outer (the ramp's limit, as Mitsuba's
/// spot with `beam_width` = `cutoff_angle`).
#[inline]
pub fn spot_falloff(cos_angle: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    if cos_inner <= cos_outer {
        return if cos_angle >= cos_outer { 1.0 } else { 0.0 };
    }
    let scale = 1.0 / (cos_inner - cos_outer).max(0.001);
    let a = ((cos_angle - cos_outer) * scale).clamp(0.0, 1.0);
    a * a
}

impl SpotLight {
    /// Emitted power (luminance).
    pub fn power(&self) -> f32 {
        2.0 * PI * luminance(self.intensity) * (1.0 - 0.5 * (self.cos_inner + self.cos_outer))
    }

    /// The delta sample towards the light from `p`; `None` outside the cone.
    #[inline]
    pub fn sample(&self, p: Vec3) -> Option<LightSample> {
        let to_light = self.position - p;
        let d2 = to_light.length_squared();
        if !(d2 > 0.0) {
            return None;
        }
        let wi = to_light / d2.sqrt();
        let falloff = spot_falloff(self.axis.dot(-wi), self.cos_inner, self.cos_outer);
        (falloff > 0.0).then(|| LightSample {
            wi,
            target: Some(self.position),
            area_point: None,
            radiance: self.intensity * falloff / d2,
            pdf: 1.0,
            delta: true,
        })
    }

    /// What the light tree knows of it: full power inside the inner cone, falling off to
    /// nothing at the outer one.
    pub fn bounds(&self, phi: f32) -> LightBounds {
        let cos_e =
            (self.cos_outer.clamp(-1.0, 1.0).acos() - self.cos_inner.clamp(-1.0, 1.0).acos()).cos();
        LightBounds {
            min: self.position,
            max: self.position,
            phi,
            w: self.axis,
            cos_theta_o: self.cos_inner,
            cos_theta_e: cos_e,
            two_sided: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spot_falloff_follows_the_gltf_ramp() {
        let (ci, co) = (0.9f32, 0.7f32);
        assert_eq!(spot_falloff(0.95, ci, co), 1.0);
        assert_eq!(spot_falloff(0.6, ci, co), 0.0);
        assert!((spot_falloff(0.8, ci, co) - 0.25).abs() < 1e-5);
        // Equal cones: a hard edge.
        assert_eq!(spot_falloff(0.7001, 0.7, 0.7), 1.0);
        assert_eq!(spot_falloff(0.6999, 0.7, 0.7), 0.0);
    }
}
