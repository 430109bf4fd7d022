//! An emissive triangle: sampled uniformly by area, as a spherical triangle (uniform in the
//! solid angle it subtends, where that is numerically sound), or, where its emissive texture
//! varies over many texels, in proportion to the texture (`emission_texture`).

use super::emission_texture::TriangleEmission;
use super::sample::{LightSample, LightSampling, area_sample};
use super::solid_angle;
use super::tree::LightBounds;
use crate::color::luminance;
use crate::sampling::warp::square_to_uniform_triangle;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::Arc;

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

    /// Emitted power (luminance).
    pub fn power(&self) -> f32 {
        let sides = if self.two_sided { 2.0 } else { 1.0 };
        PI * self.area * sides * luminance(self.mean_radiance)
    }

    /// A point of the triangle seen from `p`, with its solid-angle density.
    #[inline]
    pub fn sample(&self, p: Vec3, sampling: LightSampling, u: Vec2) -> Option<LightSample> {
        let t = self;
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
            // Where wi meets the triangle's plane; directions on the spherical triangle's
            // edges may land a rounding error outside the triangle, so the barycentrics are
            // clamped rather than the sample dropped.
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

    /// Solid-angle density with which [`TriangleLight::sample`] from `p` produces the point
    /// found at distance `dist` along unit direction `wi`.
    #[inline]
    pub fn pdf(&self, p: Vec3, wi: Vec3, dist: f32, sampling: LightSampling) -> f32 {
        let t = self;
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

    /// What the light tree knows of it: its box and the cone of its normal.
    pub fn bounds(&self, phi: f32) -> LightBounds {
        let t = self;
        LightBounds {
            min: t.p[0].min(t.p[1]).min(t.p[2]),
            max: t.p[0].max(t.p[1]).max(t.p[2]),
            phi,
            w: t.n,
            cos_theta_o: 1.0,
            cos_theta_e: 0.0,
            two_sided: t.two_sided,
        }
    }
}
