//! Light from infinitely far away: constant, or a latitude-longitude map importance-sampled
//! by luminance × sin θ.
//!
//! Lat-long convention: v = θ / π from +Y (top row) to -Y; u = 0.5 + φ / 2π with
//! φ = atan2(x, -z), so the image's centre column looks along -Z and u grows towards +X.

use super::sample::LightSample;
use crate::color::luminance;
use crate::sampling::distribution::Distribution2D;
use crate::sampling::warp::{UNIFORM_SPHERE_PDF, square_to_uniform_sphere};
use crate::scene::{self, Scene, Texels, Texture};
use glam::{DMat3, Mat3, Vec2, Vec3};
use std::f32::consts::PI;

/// An environment light in render space.
#[derive(Clone, Debug)]
pub enum Environment {
    Constant(Vec3),
    Map(Box<EnvironmentMap>),
}

/// A lat-long radiance map with its sampling distribution.
#[derive(Clone, Debug)]
pub struct EnvironmentMap {
    texture: Texture,
    scale: Vec3,
    /// World (render-space) direction to map direction.
    to_map: Mat3,
    to_world: Mat3,
    distribution: Distribution2D,
    /// ∫ luminance(L) dω over the sphere.
    luminance_integral: f32,
}

/// Map direction to lat-long coordinates.
#[inline]
pub fn direction_to_latlong(d: Vec3) -> Vec2 {
    let u = 0.5 + d.x.atan2(-d.z) / (2.0 * PI);
    let v = d.y.clamp(-1.0, 1.0).acos() / PI;
    Vec2::new(u.rem_euclid(1.0), v)
}

/// Lat-long coordinates to a map direction.
#[inline]
pub fn latlong_to_direction(uv: Vec2) -> Vec3 {
    let phi = (uv.x - 0.5) * 2.0 * PI;
    let theta = uv.y * PI;
    let s = theta.sin();
    Vec3::new(s * phi.sin(), theta.cos(), -s * phi.cos())
}

impl EnvironmentMap {
    /// A map from a linear texture, a radiance scale and a map-to-world rotation.
    pub fn new(texture: Texture, scale: Vec3, to_world: Mat3) -> Self {
        let (w, h) = (texture.width, texture.height);
        let mut func = Vec::with_capacity((w * h) as usize);
        for y in 0..h {
            let sin_theta = ((y as f32 + 0.5) / h as f32 * PI).sin();
            for x in 0..w {
                let l = luminance(texture.texel_linear(x, y, false).truncate() * scale);
                func.push(l.max(0.0) * sin_theta);
            }
        }
        let distribution = Distribution2D::new(&func, w as usize, h as usize);
        // ∫ f(u, v) du dv with dω = 2π² sin θ du dv.
        let luminance_integral = distribution.integral() * 2.0 * PI * PI;
        Self {
            texture,
            scale,
            to_map: to_world.transpose(),
            to_world,
            distribution,
            luminance_integral,
        }
    }

    fn radiance(&self, dir: Vec3) -> Vec3 {
        let uv = direction_to_latlong(self.to_map * dir);
        self.texture.sample(uv, false).truncate() * self.scale
    }
}

/// A direction towards the environment with its radiance and density.
#[derive(Clone, Copy, Debug)]
pub struct EnvironmentSample {
    pub wi: Vec3,
    pub radiance: Vec3,
    pub pdf: f32,
}

impl Environment {
    /// Radiance arriving from direction `dir` (pointing away from the scene).
    #[inline]
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        match self {
            Self::Constant(l) => *l,
            Self::Map(m) => m.radiance(dir),
        }
    }

    /// Samples a direction proportionally to luminance (maps) or uniformly (constant).
    #[inline]
    pub fn sample(&self, u: Vec2) -> Option<EnvironmentSample> {
        match self {
            Self::Constant(l) => Some(EnvironmentSample {
                wi: square_to_uniform_sphere(u),
                radiance: *l,
                pdf: UNIFORM_SPHERE_PDF,
            }),
            Self::Map(m) => {
                let (uv, pdf_uv) = m.distribution.sample(u);
                let sin_theta = (uv.y * PI).sin();
                if !(pdf_uv > 0.0 && sin_theta > 0.0) {
                    return None;
                }
                let wi = m.to_world * latlong_to_direction(uv);
                Some(EnvironmentSample {
                    wi,
                    radiance: m.radiance(wi),
                    pdf: pdf_uv / (2.0 * PI * PI * sin_theta),
                })
            }
        }
    }

    /// Solid-angle density of [`Environment::sample`] for direction `dir`.
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        match self {
            Self::Constant(_) => UNIFORM_SPHERE_PDF,
            Self::Map(m) => {
                let uv = direction_to_latlong(m.to_map * dir);
                let sin_theta = (uv.y * PI).sin();
                if sin_theta <= 0.0 {
                    return 0.0;
                }
                m.distribution.pdf(uv) / (2.0 * PI * PI * sin_theta)
            }
        }
    }

    /// ∫ luminance(L(ω)) dω over the sphere (for light selection by power).
    pub fn luminance_integral(&self) -> f32 {
        match self {
            Self::Constant(l) => luminance(*l) * 4.0 * PI,
            Self::Map(m) => m.luminance_integral,
        }
    }
}

impl Environment {
    /// Emitted power (luminance) through a disc of the scene's bounding `radius`, as pbrt
    /// scales infinite lights.
    pub fn power(&self, radius: f32) -> f32 {
        PI * radius * radius * self.luminance_integral()
    }

    /// [`Environment::sample`] as a light sample.
    #[inline]
    pub fn light_sample(&self, u: Vec2) -> Option<LightSample> {
        let s = self.sample(u)?;
        Some(LightSample {
            wi: s.wi,
            target: None,
            area_point: None,
            radiance: s.radiance,
            pdf: s.pdf,
            delta: false,
        })
    }
}

impl Environment {
    /// The environment of `scene` in render space, if it has one. A map's texels that are
    /// not radiance (NaN, infinite or negative in some channel) are made black, with a
    /// warning that says how many: one such texel would otherwise poison the map's sampling
    /// distribution and every path that escapes towards it.
    pub fn of_scene(scene: &Scene) -> Option<Self> {
        match scene.environment.as_ref()? {
            scene::Environment::Constant(l) => Some(Self::Constant(*l)),
            scene::Environment::LatLong {
                texture,
                scale,
                rotation,
            } => {
                let to_world = DMat3::from_mat4(*rotation).as_mat3();
                Some(Self::Map(Box::new(EnvironmentMap::new(
                    finite_radiance(&scene.textures[*texture as usize]),
                    *scale,
                    to_world,
                ))))
            }
        }
    }
}

/// `texture` with every texel that is not radiance made black, warning how many there were.
fn finite_radiance(texture: &Texture) -> Texture {
    let Texels::RgbaF32(texels) = texture.texels.as_ref() else {
        return texture.clone(); // Integer texels are always finite.
    };
    let bad = |t: &[f32; 4]| !t[..3].iter().all(|c| c.is_finite() && *c >= 0.0);
    let count = texels.iter().filter(|t| bad(t)).count();
    if count == 0 {
        return texture.clone();
    }
    log::warn!(
        "{}: environment map: {count} of {} texels are NaN, infinite or negative: rendered as black",
        texture.name,
        texels.len()
    );
    let fixed = texels
        .iter()
        .map(|t| if bad(t) { [0.0, 0.0, 0.0, 1.0] } else { *t })
        .collect();
    Texture {
        texels: std::sync::Arc::new(Texels::RgbaF32(fixed)),
        mips: Default::default(),
        ..texture.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latlong_round_trip_and_orientation() {
        assert!(
            (latlong_to_direction(Vec2::new(0.5, 0.5)) - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6
        );
        assert!((latlong_to_direction(Vec2::new(0.75, 0.5)) - Vec3::X).length() < 1e-6);
        assert!((latlong_to_direction(Vec2::new(0.3, 0.0)) - Vec3::Y).length() < 1e-6);
        for uv in [
            Vec2::new(0.1, 0.2),
            Vec2::new(0.9, 0.7),
            Vec2::new(0.5, 0.99),
        ] {
            let back = direction_to_latlong(latlong_to_direction(uv));
            assert!((back - uv).length() < 1e-5, "{uv} -> {back}");
        }
    }
}
