//! Lights in render space and their sampling: emissive triangles and spheres (area lights,
//! sampled by area or by solid angle), disks and cylinders (sampled by area), point, spot
//! and directional lights, distant lights with an angular size, and the environment. Which
//! light to sample is `selection`'s job.

pub mod emission_texture;
pub mod environment;
pub mod groups;
#[cfg(target_arch = "x86_64")]
pub(crate) mod lanes;
pub mod selection;
pub mod solid_angle;
pub mod tree;

use crate::color::luminance;
use crate::geometry::frame::Frame;
use crate::geometry::quadric::Quadric;
use crate::geometry::ray::offset_ray_origin;
use crate::integrator::LightSampling;
use crate::sampling::warp::{
    square_to_uniform_cone, square_to_uniform_sphere, square_to_uniform_triangle, uniform_cone_pdf,
};
use emission_texture::TriangleEmission;
use environment::Environment;
use glam::{Vec2, Vec3};
pub use selection::LightSet;
use std::f32::consts::PI;
use std::sync::Arc;

/// One light.
#[derive(Clone, Debug)]
pub enum Light {
    Triangle(TriangleLight),
    Sphere(SphereLight),
    Quadric(QuadricLight),
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
    /// A light at infinity seen as a disc of directions (the sun with its angular size):
    /// uniform radiance inside a cone, sampled uniformly in it, and reached by escaping rays
    /// as the environment is.
    DistantCone {
        /// Unit direction towards the light (the cone's axis).
        to_light: Vec3,
        radiance: Vec3,
        /// 1 - cos of the cone's half-angle.
        one_minus_cos: f32,
    },
    Environment,
}

/// An emissive triangle.
#[derive(Clone, Debug)]
pub struct TriangleLight {
    /// The BVH primitive it is.
    pub prim: u32,
    pub p: [Vec3; 3],
    /// Unit normal of the front (counter-clockwise) side.
    pub n: Vec3,
    pub area: f32,
    pub two_sided: bool,
    /// Mean emitted radiance, for selection by power.
    pub mean_radiance: Vec3,
    /// Where its emissive texture varies over many texels: the distribution of its light
    /// samples over the triangle (`emission_texture`), used unless light sampling is
    /// [`LightSampling::Area`] (uniform by area).
    pub emission: Option<Arc<TriangleEmission>>,
}

impl TriangleLight {
    /// The distribution of light samples over the triangle under `sampling`, where it
    /// follows the emissive texture.
    #[inline]
    pub fn textured_sampling(&self, sampling: LightSampling) -> Option<&TriangleEmission> {
        self.emission
            .as_deref()
            .filter(|_| sampling != LightSampling::Area)
    }

    /// Barycentrics (b1, b2) of point `y` of the triangle's plane, from the sub-triangles'
    /// areas (cross products against the normal: accurate to rounding wherever `y` is,
    /// unlike the normal equations), clamped into the triangle.
    #[inline]
    fn barycentrics(&self, y: Vec3) -> Vec2 {
        let [p0, p1, p2] = self.p;
        let (e1, e2, d) = (p1 - p0, p2 - p0, y - p0);
        let twice_area = self.n.dot(e1.cross(e2));
        if !(twice_area != 0.0) {
            return Vec2::splat(1.0 / 3.0);
        }
        let b1 = (self.n.dot(d.cross(e2)) / twice_area).max(0.0);
        let b2 = (self.n.dot(e1.cross(d)) / twice_area).max(0.0);
        let sum = b1 + b2;
        if sum > 1.0 {
            Vec2::new(b1, b2) / sum
        } else {
            Vec2::new(b1, b2)
        }
    }
}

/// An emissive sphere, emitting outwards (and inwards when two-sided).
#[derive(Clone, Debug)]
pub struct SphereLight {
    /// The BVH primitive it is.
    pub prim: u32,
    pub centre: Vec3,
    pub radius: f32,
    pub two_sided: bool,
    /// Whether its emission is textured: only then does a sample need its point's uv.
    pub textured: bool,
    /// Mean emitted radiance, for selection by power.
    pub mean_radiance: Vec3,
}

/// An emissive disk or open cylinder, sampled uniformly by area (as pbrt-v4 does: neither
/// has a closed-form solid-angle sampling).
#[derive(Clone, Debug)]
pub struct QuadricLight {
    /// The BVH primitive it is.
    pub prim: u32,
    pub quadric: Quadric,
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
    /// For area lights: the primitive and its surface coordinates at the sampled point
    /// (triangle barycentrics b1 b2, sphere lat-long uv), so the caller can evaluate
    /// textured emission.
    pub area_point: Option<(u32, Vec2)>,
    /// Radiance (area, environment) or irradiance-like quantity (delta lights) arriving;
    /// for area lights the factor that multiplies the emission at `area_point`.
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

/// An area-light sample from a point `y` with unit normal `n` on the light, seen from `p`.
/// `None` when `p` is behind a one-sided emitter.
#[inline]
fn area_sample(
    p: Vec3,
    y: Vec3,
    n: Vec3,
    two_sided: bool,
    prim: u32,
    coords: Vec2,
) -> Option<(LightSample, f32)> {
    let to_light = y - p;
    let d2 = to_light.length_squared();
    if !(d2 > 0.0) {
        return None;
    }
    let wi = to_light / d2.sqrt();
    let cos_light = -n.dot(wi);
    if cos_light <= 0.0 && !two_sided || cos_light == 0.0 {
        return None;
    }
    let facing = if cos_light > 0.0 { n } else { -n };
    let sample = LightSample {
        wi,
        target: Some(offset_ray_origin(y, facing)),
        area_point: Some((prim, coords)),
        radiance: Vec3::ONE,
        pdf: 0.0,
        delta: false,
    };
    // The conversion from area to solid angle density.
    Some((sample, d2 / cos_light.abs()))
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
            Self::Sphere(s) => {
                let sides = if s.two_sided { 2.0 } else { 1.0 };
                PI * 4.0 * PI * s.radius * s.radius * sides * luminance(s.mean_radiance)
            }
            Self::Quadric(q) => {
                let sides = if q.two_sided { 2.0 } else { 1.0 };
                PI * q.quadric.area() * sides * luminance(q.mean_radiance)
            }
            Self::Point { intensity, .. } => 4.0 * PI * luminance(*intensity),
            Self::Spot {
                intensity,
                cos_inner,
                cos_outer,
                ..
            } => 2.0 * PI * luminance(*intensity) * (1.0 - 0.5 * (cos_inner + cos_outer)),
            Self::Directional { irradiance, .. } => PI * radius * radius * luminance(*irradiance),
            Self::DistantCone {
                radiance,
                one_minus_cos,
                ..
            } => {
                let irradiance = PI * one_minus_cos * (2.0 - one_minus_cos) * luminance(*radiance);
                PI * radius * radius * irradiance
            }
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
    /// caller (see [`LightSample::area_point`]).
    pub fn sample(
        &self,
        p: Vec3,
        environment: Option<&Environment>,
        sampling: LightSampling,
        u: Vec2,
    ) -> Option<LightSample> {
        match self {
            Self::Triangle(t) => {
                if let Some(tree) = t.textured_sampling(sampling) {
                    let (b, density) = tree.sample(u);
                    let y = t.p[0] * (1.0 - b.x - b.y) + t.p[1] * b.x + t.p[2] * b.y;
                    let (mut s, to_solid_angle) = area_sample(p, y, t.n, t.two_sided, t.prim, b)?;
                    s.pdf = to_solid_angle * density / t.area;
                    return Some(s);
                }
                if sampling.triangles_by_solid_angle()
                    && let Some(omega) = solid_angle::triangle_uses_solid_angle(p, &t.p)
                {
                    let wi = solid_angle::sample_spherical_triangle(p, &t.p, u)?;
                    // Where wi meets the triangle's plane; directions on the spherical
                    // triangle's edges may land a rounding error outside the triangle, so
                    // the barycentrics are clamped rather than the sample dropped.
                    let along = wi.dot(t.n);
                    let dist = (t.p[0] - p).dot(t.n) / along;
                    if !(dist > 0.0 && dist.is_finite()) {
                        return None;
                    }
                    let b = solid_angle::barycentrics(&t.p, p + wi * dist);
                    let y = t.p[0] * (1.0 - b.x - b.y) + t.p[1] * b.x + t.p[2] * b.y;
                    let (mut s, _) = area_sample(p, y, t.n, t.two_sided, t.prim, b)?;
                    s.pdf = 1.0 / omega;
                    return Some(s);
                }
                let b = square_to_uniform_triangle(u);
                let y = t.p[0] * (1.0 - b.x - b.y) + t.p[1] * b.x + t.p[2] * b.y;
                let (mut s, to_solid_angle) = area_sample(p, y, t.n, t.two_sided, t.prim, b)?;
                s.pdf = to_solid_angle / t.area;
                Some(s)
            }
            Self::Sphere(sp) => {
                if sampling.spheres_by_cone()
                    && let Some(one_minus_cos) = solid_angle::sphere_cone(p, sp.centre, sp.radius)
                {
                    let n =
                        solid_angle::sample_sphere_cone(p, sp.centre, sp.radius, one_minus_cos, u);
                    let y = sp.centre + sp.radius * n;
                    let uv = if sp.textured {
                        crate::geometry::sphere::uv(n)
                    } else {
                        Vec2::ZERO
                    };
                    let (mut s, _) = area_sample(p, y, n, sp.two_sided, sp.prim, uv)?;
                    s.pdf = solid_angle::sphere_cone_pdf(one_minus_cos);
                    return Some(s);
                }
                let n = square_to_uniform_sphere(u);
                let y = sp.centre + sp.radius * n;
                let uv = if sp.textured {
                    crate::geometry::sphere::uv(n)
                } else {
                    Vec2::ZERO
                };
                let (mut s, to_solid_angle) = area_sample(p, y, n, sp.two_sided, sp.prim, uv)?;
                s.pdf = to_solid_angle / (4.0 * PI * sp.radius * sp.radius);
                Some(s)
            }
            Self::Quadric(q) => {
                let (y, n, uv) = q.quadric.sample(u);
                let (mut s, to_solid_angle) = area_sample(p, y, n, q.two_sided, q.prim, uv)?;
                s.pdf = to_solid_angle / q.quadric.area();
                Some(s)
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
            Self::DistantCone {
                to_light,
                radiance,
                one_minus_cos,
            } => Some(LightSample {
                wi: Frame::from_normal(*to_light)
                    .to_world(square_to_uniform_cone(u, *one_minus_cos)),
                target: None,
                area_point: None,
                radiance: *radiance,
                pdf: uniform_cone_pdf(*one_minus_cos),
                delta: false,
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

    /// Solid-angle density with which [`Light::sample`] from `p` produces the point of this
    /// area light found at distance `dist` along unit direction `wi` (excluding selection);
    /// for a distant cone, the density of direction `wi`.
    /// The same rules as sampling decide the measure.
    #[inline]
    pub fn pdf(&self, p: Vec3, wi: Vec3, dist: f32, sampling: LightSampling) -> f32 {
        match self {
            Self::Triangle(t) => {
                let tree = t.textured_sampling(sampling);
                if tree.is_none()
                    && sampling.triangles_by_solid_angle()
                    && let Some(omega) = solid_angle::triangle_uses_solid_angle(p, &t.p)
                {
                    return 1.0 / omega;
                }
                let cos_light = t.n.dot(wi).abs();
                if !(cos_light > 0.0) {
                    return 0.0;
                }
                let density = tree.map_or(1.0, |tree| tree.density(t.barycentrics(p + wi * dist)));
                density * dist * dist / (cos_light * t.area)
            }
            Self::Sphere(sp) => {
                if sampling.spheres_by_cone()
                    && let Some(one_minus_cos) = solid_angle::sphere_cone(p, sp.centre, sp.radius)
                {
                    return solid_angle::sphere_cone_pdf(one_minus_cos);
                }
                let n = (p + wi * dist - sp.centre).normalize_or_zero();
                let cos_light = n.dot(wi).abs();
                if cos_light > 0.0 {
                    dist * dist / (cos_light * 4.0 * PI * sp.radius * sp.radius)
                } else {
                    0.0
                }
            }
            Self::Quadric(q) => {
                let (_, n) = q.quadric.surface(p + wi * dist);
                let cos_light = n.dot(wi).abs();
                if cos_light > 0.0 {
                    dist * dist / (cos_light * q.quadric.area())
                } else {
                    0.0
                }
            }
            Self::DistantCone {
                to_light,
                one_minus_cos,
                ..
            } if wi.dot(*to_light) >= 1.0 - one_minus_cos => uniform_cone_pdf(*one_minus_cos),
            _ => 0.0,
        }
    }

    /// Radiance a ray escaping the scene along unit direction `dir` receives from this
    /// light, for lights at infinity other than the environment.
    #[inline]
    pub fn radiance_at_infinity(&self, dir: Vec3) -> Vec3 {
        match self {
            Self::DistantCone {
                to_light,
                radiance,
                one_minus_cos,
            } if dir.dot(*to_light) >= 1.0 - one_minus_cos => *radiance,
            _ => Vec3::ZERO,
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
    }

    #[test]
    fn area_light_pdfs_agree_with_sampling() {
        let tri = Light::Triangle(TriangleLight {
            prim: 0,
            p: [
                Vec3::new(-1.0, 2.0, -1.0),
                Vec3::new(1.0, 2.0, -1.0),
                Vec3::new(0.0, 2.0, 1.0),
            ],
            n: -Vec3::Y,
            area: 2.0,
            two_sided: false,
            mean_radiance: Vec3::ONE,
            emission: None,
        });
        let sphere = Light::Sphere(SphereLight {
            prim: 1,
            centre: Vec3::new(0.5, 3.0, 0.2),
            radius: 0.7,
            two_sided: false,
            textured: false,
            mean_radiance: Vec3::ONE,
        });
        for light in [tri.clone(), sphere] {
            for sampling in [
                LightSampling::Area,
                LightSampling::SolidAngle,
                LightSampling::Auto,
            ] {
                for u in [Vec2::new(0.3, 0.6), Vec2::new(0.9, 0.1)] {
                    let Some(s) = light.sample(Vec3::ZERO, None, sampling, u) else {
                        continue;
                    };
                    let dist = s.target.unwrap().length();
                    let pdf = light.pdf(Vec3::ZERO, s.wi, dist, sampling);
                    assert!(
                        (pdf - s.pdf).abs() < 2e-3 * s.pdf,
                        "{sampling:?}: {pdf} vs {}",
                        s.pdf
                    );
                }
            }
        }
        // Seen from above, a one-sided light facing down gives nothing.
        assert!(
            tri.sample(
                Vec3::new(0.0, 3.0, 0.0),
                None,
                LightSampling::Area,
                Vec2::new(0.3, 0.6)
            )
            .is_none()
        );
    }
}
