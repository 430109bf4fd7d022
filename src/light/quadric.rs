//! An emissive disk or open cylinder, sampled uniformly by area (as pbrt-v4 does: neither
//! has a closed-form solid-angle sampling).

use super::sample::{LightSample, area_sample};
use super::tree::LightBounds;
use crate::color::luminance;
use crate::geometry::quadric::Quadric;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// An emissive disk or open cylinder.
#[derive(Clone, Debug)]
pub struct QuadricLight {
    /// The BVH primitive it is.
    pub prim: u32,
    pub quadric: Quadric,
    pub two_sided: bool,
    /// Mean emitted radiance, for selection by power.
    pub mean_radiance: Vec3,
}

impl QuadricLight {
    /// Emitted power (luminance).
    pub fn power(&self) -> f32 {
        let sides = if self.two_sided { 2.0 } else { 1.0 };
        PI * self.quadric.area() * sides * luminance(self.mean_radiance)
    }

    /// A point of the surface seen from `p`, with its solid-angle density.
    #[inline]
    pub fn sample(&self, p: Vec3, u: Vec2) -> Option<LightSample> {
        let (y, n, uv) = self.quadric.sample(u);
        let (mut s, to_solid_angle) = area_sample(p, y, n, self.two_sided, self.prim, uv)?;
        s.pdf = to_solid_angle / self.quadric.area();
        Some(s)
    }

    /// Solid-angle density with which [`QuadricLight::sample`] from `p` produces the point
    /// found at distance `dist` along unit direction `wi`.
    #[inline]
    pub fn pdf(&self, p: Vec3, wi: Vec3, dist: f32) -> f32 {
        let (_, n) = self.quadric.surface(p + wi * dist);
        let cos_light = n.dot(wi).abs();
        if cos_light > 0.0 {
            dist * dist / (cos_light * self.quadric.area())
        } else {
            0.0
        }
    }

    /// What the light tree knows of it: its box; a disk's normals are its normal, a
    /// cylinder's lie at 90 degrees to its axis.
    pub fn bounds(&self, phi: f32) -> LightBounds {
        let (min, max) = self.quadric.bounds();
        let (w, cos_theta_o) = match self.quadric {
            Quadric::Disk(d) => (d.normal, 1.0),
            Quadric::Cylinder(c) => (c.axis, 0.0),
        };
        LightBounds {
            min,
            max,
            phi,
            w,
            cos_theta_o,
            cos_theta_e: 0.0,
            two_sided: self.two_sided,
        }
    }
}
