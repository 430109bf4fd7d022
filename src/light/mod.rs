//! Lights in render space and their sampling: emissive triangles (area lights), point,
//! spot and directional lights, and the environment. Light selection by power.

pub mod environment;

use crate::color::luminance;
use crate::geometry::ray::offset_ray_origin;
use crate::sampling::distribution::AliasTable;
use crate::sampling::warp::square_to_uniform_triangle;
use environment::Environment;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// One light.
#[derive(Clone, Debug)]
pub enum Light {
    /// An emissive triangle of mesh `mesh`.
    Triangle(TriangleLight),
    Point {
        position: Vec3,
        intensity: Vec3,
    },
    Spot {
        position: Vec3,
        /// Unit direction the cone points to.
        axis: Vec3,
        intensity: Vec3,
        cos_inner: f32,
        cos_outer: f32,
    },
    Directional {
        /// Unit direction the light travels in.
        direction: Vec3,
        irradiance: Vec3,
    },
    Environment,
}

/// An emissive triangle.
#[derive(Clone, Debug)]
pub struct TriangleLight {
    pub mesh: u32,
    pub tri: u32,
    pub p: [Vec3; 3],
    /// Unit normal of the front (counter-clockwise) side.
    pub n: Vec3,
    pub area: f32,
    pub two_sided: bool,
    /// Mean emitted radiance, for selection by power.
    pub mean_radiance: Vec3,
}

/// A point on a light as seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point towards the light.
    pub wi: Vec3,
    /// Where a shadow ray must end (already offset off the light's surface), or `None` for
    /// lights at infinity.
    pub target: Option<Vec3>,
    /// For area lights: the triangle and the barycentrics of the sampled point, so the
    /// caller can evaluate textured emission.
    pub area_point: Option<(u32, u32, Vec2)>,
    /// Radiance (area, environment) or irradiance-like quantity (delta lights) arriving.
    pub radiance: Vec3,
    /// Solid-angle density of the sample, excluding the light selection probability; for
    /// delta lights 1.
    pub pdf: f32,
    pub delta: bool,
}

/// The glTF spot cone falloff (KHR_lights_punctual): a squared linear ramp in cos angle.
#[inline]
pub fn spot_falloff(cos_angle: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    let scale = 1.0 / (cos_inner - cos_outer).max(0.001);
    let a = ((cos_angle - cos_outer) * scale).clamp(0.0, 1.0);
    a * a
}

impl Light {
    /// Emitted power (luminance-weighted), the weight for selection by power. `radius` is
    /// the scene's bounding radius, which scales infinite lights as in pbrt.
    pub fn power(&self, environment: Option<&Environment>, radius: f32) -> f32 {
        match self {
            Self::Triangle(t) => {
                let sides = if t.two_sided { 2.0 } else { 1.0 };
                PI * t.area * sides * luminance(t.mean_radiance)
            }
            Self::Point { intensity, .. } => 4.0 * PI * luminance(*intensity),
            Self::Spot {
                intensity,
                cos_inner,
                cos_outer,
                ..
            } => 2.0 * PI * luminance(*intensity) * (1.0 - 0.5 * (cos_inner + cos_outer)),
            Self::Directional { irradiance, .. } => PI * radius * radius * luminance(*irradiance),
            Self::Environment => {
                environment.map_or(0.0, |e| PI * radius * radius * e.luminance_integral())
            }
        }
    }

    /// True for lights only light sampling can reach.
    pub fn is_delta(&self) -> bool {
        matches!(
            self,
            Self::Point { .. } | Self::Spot { .. } | Self::Directional { .. }
        )
    }

    /// Samples the light from shading point `p`. Textured area emission is left to the
    /// caller: `radiance` then holds the factor to multiply (see [`LightSample::area_point`]).
    pub fn sample(
        &self,
        p: Vec3,
        environment: Option<&Environment>,
        u: Vec2,
    ) -> Option<LightSample> {
        match self {
            Self::Triangle(t) => {
                let b = square_to_uniform_triangle(u);
                let y = t.p[0] * (1.0 - b.x - b.y) + t.p[1] * b.x + t.p[2] * b.y;
                let to_light = y - p;
                let d2 = to_light.length_squared();
                if !(d2 > 0.0) {
                    return None;
                }
                let wi = to_light / d2.sqrt();
                let cos_light = -t.n.dot(wi);
                if cos_light <= 0.0 && !t.two_sided || cos_light == 0.0 {
                    return None;
                }
                let facing = if cos_light > 0.0 { t.n } else { -t.n };
                Some(LightSample {
                    wi,
                    target: Some(offset_ray_origin(y, facing)),
                    area_point: Some((t.mesh, t.tri, b)),
                    radiance: Vec3::ONE,
                    pdf: d2 / (cos_light.abs() * t.area),
                    delta: false,
                })
            }
            Self::Point {
                position,
                intensity,
            } => {
                let to_light = *position - p;
                let d2 = to_light.length_squared();
                (d2 > 0.0).then(|| LightSample {
                    wi: to_light / d2.sqrt(),
                    target: Some(*position),
                    area_point: None,
                    radiance: *intensity / d2,
                    pdf: 1.0,
                    delta: true,
                })
            }
            Self::Spot {
                position,
                axis,
                intensity,
                cos_inner,
                cos_outer,
            } => {
                let to_light = *position - p;
                let d2 = to_light.length_squared();
                if !(d2 > 0.0) {
                    return None;
                }
                let wi = to_light / d2.sqrt();
                let falloff = spot_falloff(axis.dot(-wi), *cos_inner, *cos_outer);
                (falloff > 0.0).then(|| LightSample {
                    wi,
                    target: Some(*position),
                    area_point: None,
                    radiance: *intensity * falloff / d2,
                    pdf: 1.0,
                    delta: true,
                })
            }
            Self::Directional {
                direction,
                irradiance,
            } => Some(LightSample {
                wi: -*direction,
                target: None,
                area_point: None,
                radiance: *irradiance,
                pdf: 1.0,
                delta: true,
            }),
            Self::Environment => {
                let s = environment?.sample(u)?;
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
    }
}

impl TriangleLight {
    /// Solid-angle density with which [`Light::sample`] reaches this triangle at distance
    /// `dist` along unit direction `wi`.
    #[inline]
    pub fn pdf(&self, wi: Vec3, dist: f32) -> f32 {
        let cos_light = self.n.dot(wi).abs();
        if cos_light > 0.0 {
            dist * dist / (cos_light * self.area)
        } else {
            0.0
        }
    }
}

/// All lights with their selection distribution.
#[derive(Clone, Debug, Default)]
pub struct LightSet {
    pub lights: Vec<Light>,
    pub environment: Option<Environment>,
    /// Index of the environment in `lights`, if any.
    pub environment_index: Option<u32>,
    selection: Option<AliasTable>,
}

impl LightSet {
    /// Builds the set and its selection-by-power table.
    pub fn new(mut lights: Vec<Light>, environment: Option<Environment>, radius: f32) -> Self {
        let environment_index = environment.as_ref().map(|_| {
            lights.push(Light::Environment);
            (lights.len() - 1) as u32
        });
        let powers: Vec<f32> = lights
            .iter()
            .map(|l| l.power(environment.as_ref(), radius))
            .collect();
        Self {
            selection: AliasTable::new(&powers),
            lights,
            environment,
            environment_index,
        }
    }

    /// Picks a light with probability proportional to its power: (index, probability).
    #[inline]
    pub fn select(&self, u: f32) -> Option<(usize, f32)> {
        self.selection.as_ref().map(|t| t.sample(u))
    }

    /// Probability that [`LightSet::select`] picks light `i`.
    #[inline]
    pub fn selection_probability(&self, i: usize) -> f32 {
        self.selection.as_ref().map_or(0.0, |t| t.pmf(i))
    }

    /// True if there is nothing to sample.
    pub fn is_empty(&self) -> bool {
        self.selection.is_none()
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
    }

    #[test]
    fn triangle_light_pdf_agrees_with_sampling() {
        let t = TriangleLight {
            mesh: 0,
            tri: 0,
            p: [
                Vec3::new(-1.0, 2.0, -1.0),
                Vec3::new(1.0, 2.0, -1.0),
                Vec3::new(0.0, 2.0, 1.0),
            ],
            n: -Vec3::Y,
            area: 2.0,
            two_sided: false,
            mean_radiance: Vec3::ONE,
        };
        let light = Light::Triangle(t.clone());
        let s = light.sample(Vec3::ZERO, None, Vec2::new(0.3, 0.6)).unwrap();
        let dist = (s.target.unwrap() - Vec3::ZERO).length();
        assert!((t.pdf(s.wi, dist) - s.pdf).abs() < 1e-3 * s.pdf);
        // Seen from above, a one-sided light facing down gives nothing.
        assert!(
            light
                .sample(Vec3::new(0.0, 3.0, 0.0), None, Vec2::new(0.3, 0.6))
                .is_none()
        );
    }
}
