//! An emissive sphere: sampled in the cone of directions it subtends from outside it (where
//! light sampling allows), else uniformly by area.

use super::sample::{LightSample, LightSampling, area_sample};
use super::solid_angle;
use super::tree::LightBounds;
use crate::color::luminance;
use crate::sampling::warp::square_to_uniform_sphere;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

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

impl SphereLight {
    /// Emitted power (luminance).
    pub fn power(&self) -> f32 {
        let sides = if self.two_sided { 2.0 } else { 1.0 };
        PI * 4.0 * PI * self.radius * self.radius * sides * luminance(self.mean_radiance)
    }

    /// A point of the sphere seen from `p`, with its solid-angle density.
    #[inline]
    pub fn sample(&self, p: Vec3, sampling: LightSampling, u: Vec2) -> Option<LightSample> {
        let sp = self;
        if sampling.spheres_by_cone()
            && let Some(one_minus_cos) = solid_angle::sphere_cone(p, sp.centre, sp.radius)
        {
            let n = solid_angle::sample_sphere_cone(p, sp.centre, sp.radius, one_minus_cos, u);
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

    /// Solid-angle density with which [`SphereLight::sample`] from `p` produces the point
    /// found at distance `dist` along unit direction `wi`.
    #[inline]
    pub fn pdf(&self, p: Vec3, wi: Vec3, dist: f32, sampling: LightSampling) -> f32 {
        let sp = self;
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

    /// What the light tree knows of it: its box, emitting in every direction.
    pub fn bounds(&self, phi: f32) -> LightBounds {
        LightBounds {
            min: self.centre - self.radius,
            max: self.centre + self.radius,
            phi,
            w: Vec3::Y,
            cos_theta_o: -1.0,
            cos_theta_e: 0.0,
            two_sided: self.two_sided,
        }
    }
}
