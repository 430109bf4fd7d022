//! Lights at infinity other than the environment: a directional light (parallel rays,
//! reached by light sampling alone) and a distant light with an angular size (the sun as a
//! disc of directions: uniform radiance inside a cone, sampled uniformly in it, and reached
//! by escaping rays as the environment is).

use super::sample::LightSample;
use crate::color::luminance;
use crate::geometry::frame::Frame;
use crate::sampling::warp::{square_to_uniform_cone, uniform_cone_pdf};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Parallel light (KHR_lights_punctual `directional`, UsdLux `DistantLight` of angle 0).
#[derive(Clone, Debug)]
pub struct DirectionalLight {
    /// Unit direction the light travels in.
    pub direction: Vec3,
    pub irradiance: Vec3,
}

/// A distant light seen as a disc of directions (UsdLux `DistantLight` with an angle).
#[derive(Clone, Debug)]
pub struct DistantCone {
    /// Unit direction towards the light (the cone's axis).
    pub to_light: Vec3,
    pub radiance: Vec3,
    /// 1 - cos of the cone's half-angle.
    pub one_minus_cos: f32,
}

impl DirectionalLight {
    /// Emitted power (luminance) through a disc of the scene's bounding `radius`, as pbrt
    /// scales infinite lights.
    pub fn power(&self, radius: f32) -> f32 {
        PI * radius * radius * luminance(self.irradiance)
    }

    /// The delta sample along the light's direction.
    #[inline]
    pub fn sample(&self) -> LightSample {
        LightSample {
            wi: -self.direction,
            target: None,
            area_point: None,
            radiance: self.irradiance,
            pdf: 1.0,
            delta: true,
        }
    }
}

impl DistantCone {
    /// Emitted power (luminance) through a disc of the scene's bounding `radius`.
    pub fn power(&self, radius: f32) -> f32 {
        let irradiance =
            PI * self.one_minus_cos * (2.0 - self.one_minus_cos) * luminance(self.radiance);
        PI * radius * radius * irradiance
    }

    /// A direction uniformly in the cone.
    #[inline]
    pub fn sample(&self, u: Vec2) -> LightSample {
        LightSample {
            wi: Frame::from_normal(self.to_light)
                .to_world(square_to_uniform_cone(u, self.one_minus_cos)),
            target: None,
            area_point: None,
            radiance: self.radiance,
            pdf: uniform_cone_pdf(self.one_minus_cos),
            delta: false,
        }
    }

    /// Whether unit direction `wi` lies in the cone.
    #[inline]
    fn contains(&self, wi: Vec3) -> bool {
        wi.dot(self.to_light) >= 1.0 - self.one_minus_cos
    }

    /// Solid-angle density of direction `wi` under [`DistantCone::sample`].
    #[inline]
    pub fn pdf(&self, wi: Vec3) -> f32 {
        if self.contains(wi) {
            uniform_cone_pdf(self.one_minus_cos)
        } else {
            0.0
        }
    }

    /// Radiance a ray escaping along unit direction `dir` receives from the light.
    #[inline]
    pub fn radiance_at_infinity(&self, dir: Vec3) -> Vec3 {
        if self.contains(dir) {
            self.radiance
        } else {
            Vec3::ZERO
        }
    }
}
