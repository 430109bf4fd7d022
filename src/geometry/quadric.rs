//! Analytic disks and open cylinders (the shapes of disk and cylinder lights): ray
//! intersection, the surface point and normal of a hit, texture coordinates, and uniform
//! points by area for light sampling.

use super::frame::Frame;
use super::hit::PrimitiveHit;
use super::ray::Ray;
use crate::sampling::warp::square_to_uniform_disk;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A disk of `radius` around `centre`, front towards unit `normal`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disk {
    pub centre: Vec3,
    pub normal: Vec3,
    pub radius: f32,
}

/// An open cylinder (no caps) of `radius` around unit `axis` through `centre`, reaching
/// `half_length` along the axis either side; front outwards.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cylinder {
    pub centre: Vec3,
    pub axis: Vec3,
    pub radius: f32,
    pub half_length: f32,
}

/// A disk or an open cylinder.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Quadric {
    Disk(Disk),
    Cylinder(Cylinder),
}

impl Quadric {
    /// Nearest intersection in `(0, tmax)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<PrimitiveHit> {
        match self {
            Self::Disk(d) => d.intersect(ray, tmax),
            Self::Cylinder(c) => c.intersect(ray, tmax),
        }
    }

    /// A hit point moved onto the surface (it carries the rounding of t), and the unit
    /// normal of the front side there.
    #[inline]
    pub fn surface(&self, p: Vec3) -> (Vec3, Vec3) {
        match self {
            Self::Disk(d) => (d.surface_point(p), d.normal),
            Self::Cylinder(c) => (c.surface_point(p), c.normal(p)),
        }
    }

    /// Texture coordinates of surface point `p`.
    #[inline]
    pub fn uv(&self, p: Vec3) -> Vec2 {
        match self {
            Self::Disk(d) => d.uv(p),
            Self::Cylinder(c) => c.uv(p),
        }
    }

    /// Surface area (one side).
    pub fn area(&self) -> f32 {
        match self {
            Self::Disk(d) => d.area(),
            Self::Cylinder(c) => c.area(),
        }
    }

    /// A point uniform by area, the front normal there, and its texture coordinates.
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec3, Vec3, Vec2) {
        match self {
            Self::Disk(d) => {
                let (p, uv) = d.sample(u);
                (p, d.normal, uv)
            }
            Self::Cylinder(c) => c.sample(u),
        }
    }

    /// Render-space bounding box.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        match self {
            Self::Disk(d) => d.bounds(),
            Self::Cylinder(c) => c.bounds(),
        }
    }
}

impl Disk {
    /// Nearest intersection in `(0, tmax)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<PrimitiveHit> {
        let along = ray.dir.dot(self.normal);
        let t = (self.centre - ray.origin).dot(self.normal) / along;
        if !(t > 0.0 && t < tmax) {
            return None;
        }
        let offset = ray.at(t) - self.centre;
        let in_plane = offset - offset.dot(self.normal) * self.normal;
        (in_plane.length_squared() <= self.radius * self.radius).then_some(PrimitiveHit {
            t,
            b1: 0.0,
            b2: 0.0,
            front: along < 0.0,
        })
    }

    /// The point of the disk nearest to `p` (a hit point moved back into the plane).
    #[inline]
    pub fn surface_point(&self, p: Vec3) -> Vec3 {
        p - (p - self.centre).dot(self.normal) * self.normal
    }

    /// Texture coordinates: (distance from the centre / radius, angle / 2π) in the disk's
    /// branchless frame.
    #[inline]
    pub fn uv(&self, p: Vec3) -> Vec2 {
        let local = Frame::from_normal(self.normal).to_local(p - self.centre);
        let phi = local.y.atan2(local.x);
        Vec2::new(
            (local.truncate().length() / self.radius).min(1.0),
            (phi / (2.0 * PI)).rem_euclid(1.0),
        )
    }

    /// Surface area (one side).
    pub fn area(&self) -> f32 {
        PI * self.radius * self.radius
    }

    /// A point uniform by area and its texture coordinates (those of [`Disk::uv`], from
    /// the sample's own disk coordinates in the same frame).
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec3, Vec2) {
        let d = square_to_uniform_disk(u) * self.radius;
        let frame = Frame::from_normal(self.normal);
        let p = self.centre + frame.s * d.x + frame.t * d.y;
        let uv = Vec2::new(
            (d.length() / self.radius).min(1.0),
            (d.y.atan2(d.x) / (2.0 * PI)).rem_euclid(1.0),
        );
        (p, uv)
    }

    /// Render-space bounds: the disk's extent along each axis is radius · sin(angle between
    /// the axis and the normal).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let n2 = self.normal * self.normal;
        let extent = self.radius * (Vec3::ONE - n2).max(Vec3::ZERO).sqrt();
        (self.centre - extent, self.centre + extent)
    }
}

impl Cylinder {
    /// Nearest intersection in `(0, tmax)`, from outside (front) or inside.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<PrimitiveHit> {
        let o = ray.origin - self.centre;
        // Components across the axis; the quadratic is solved as the sphere's is (Haines
        // et al.), from the closest approach so that a thin distant cylinder keeps its digits.
        let d_perp = ray.dir - ray.dir.dot(self.axis) * self.axis;
        let o_perp = o - o.dot(self.axis) * self.axis;
        let a = d_perp.length_squared();
        if !(a > 0.0) {
            return None;
        }
        let b = -o_perp.dot(d_perp) / a;
        let closest = o_perp + b * d_perp;
        let discriminant = (self.radius * self.radius - closest.length_squared()) / a;
        if !(discriminant >= 0.0) {
            return None;
        }
        let root = discriminant.sqrt();
        for t in [b - root, b + root] {
            if !(t > 0.0 && t < tmax) {
                continue;
            }
            if (o + t * ray.dir).dot(self.axis).abs() <= self.half_length {
                let outward = o_perp + t * d_perp;
                return Some(PrimitiveHit {
                    t,
                    b1: 0.0,
                    b2: 0.0,
                    front: outward.dot(ray.dir) < 0.0,
                });
            }
        }
        None
    }

    /// Outward unit normal at (or near) surface point `p`.
    #[inline]
    pub fn normal(&self, p: Vec3) -> Vec3 {
        let o = p - self.centre;
        let across = o - o.dot(self.axis) * self.axis;
        across.normalize_or(Frame::from_normal(self.axis).s)
    }

    /// `p` moved onto the surface along the normal.
    #[inline]
    pub fn surface_point(&self, p: Vec3) -> Vec3 {
        let along = (p - self.centre).dot(self.axis);
        self.centre + along * self.axis + self.radius * self.normal(p)
    }

    /// Texture coordinates: (angle around the axis / 2π, position along it from 0 to 1).
    #[inline]
    pub fn uv(&self, p: Vec3) -> Vec2 {
        let local = Frame::from_normal(self.axis).to_local(p - self.centre);
        Vec2::new(
            (local.y.atan2(local.x) / (2.0 * PI)).rem_euclid(1.0),
            (local.z / (2.0 * self.half_length) + 0.5).clamp(0.0, 1.0),
        )
    }

    /// Surface area of the side (one side of it).
    pub fn area(&self) -> f32 {
        2.0 * PI * self.radius * 2.0 * self.half_length
    }

    /// A point uniform by area, its outward normal and texture coordinates.
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec3, Vec3, Vec2) {
        let frame = Frame::from_normal(self.axis);
        let phi = 2.0 * PI * u.y;
        let n = frame.s * phi.cos() + frame.t * phi.sin();
        let p = self.centre + (2.0 * u.x - 1.0) * self.half_length * self.axis + self.radius * n;
        (p, n, Vec2::new(u.y, u.x))
    }

    /// Render-space bounds: the two end disks' bounds.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let end = |s: f32| Disk {
            centre: self.centre + s * self.half_length * self.axis,
            normal: self.axis,
            radius: self.radius,
        };
        let (a, b) = (end(-1.0).bounds(), end(1.0).bounds());
        (a.0.min(b.0), a.1.max(b.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disk_hits_inside_its_radius_from_both_sides() {
        let disk = Disk {
            centre: Vec3::new(0.0, 1.0, 0.0),
            normal: -Vec3::Y,
            radius: 0.5,
        };
        let h = disk
            .intersect(&Ray::new(Vec3::new(0.3, 0.0, 0.3), Vec3::Y), f32::INFINITY)
            .unwrap();
        assert!((h.t - 1.0).abs() < 1e-6 && h.front);
        let h = disk
            .intersect(&Ray::new(Vec3::new(0.3, 2.0, 0.3), -Vec3::Y * 2.0), 10.0)
            .unwrap();
        assert!((h.t - 0.5).abs() < 1e-6 && !h.front);
        assert!(
            disk.intersect(&Ray::new(Vec3::new(0.4, 0.0, 0.4), Vec3::Y), 10.0)
                .is_none()
        );
        let (lo, hi) = disk.bounds();
        assert!((lo - Vec3::new(-0.5, 1.0, -0.5)).length() < 1e-6);
        assert!((hi - Vec3::new(0.5, 1.0, 0.5)).length() < 1e-6);
    }

    #[test]
    fn cylinder_hits_its_side_from_outside_and_inside_and_not_its_ends() {
        let c = Cylinder {
            centre: Vec3::ZERO,
            axis: Vec3::X,
            radius: 0.5,
            half_length: 1.0,
        };
        let h = c
            .intersect(&Ray::new(Vec3::new(0.2, 3.0, 0.0), -Vec3::Y), f32::INFINITY)
            .unwrap();
        assert!((h.t - 2.5).abs() < 1e-6 && h.front);
        let p = Ray::new(Vec3::new(0.2, 3.0, 0.0), -Vec3::Y).at(h.t);
        assert!((c.normal(p) - Vec3::Y).length() < 1e-6);
        let h = c
            .intersect(&Ray::new(Vec3::new(0.2, 0.0, 0.0), Vec3::Z), f32::INFINITY)
            .unwrap();
        assert!((h.t - 0.5).abs() < 1e-6 && !h.front, "from inside");
        // Along the axis there is no cap to hit.
        assert!(
            c.intersect(&Ray::new(Vec3::new(5.0, 0.1, 0.0), -Vec3::X), f32::INFINITY)
                .is_none()
        );
        // Beyond the ends.
        assert!(
            c.intersect(&Ray::new(Vec3::new(1.2, 3.0, 0.0), -Vec3::Y), f32::INFINITY)
                .is_none()
        );
        // Entering past an end, leaving through the side from inside.
        let h = c
            .intersect(
                &Ray::new(Vec3::new(2.0, 0.0, 0.0), Vec3::new(-1.0, 0.3, 0.0)),
                f32::INFINITY,
            )
            .unwrap();
        assert!(!h.front);
        let (lo, hi) = c.bounds();
        assert!((lo - Vec3::new(-1.0, -0.5, -0.5)).length() < 1e-6);
        assert!((hi - Vec3::new(1.0, 0.5, 0.5)).length() < 1e-6);
    }

    #[test]
    fn samples_lie_on_the_surfaces() {
        let disk = Disk {
            centre: Vec3::new(1.0, 2.0, 3.0),
            normal: Vec3::new(1.0, 1.0, 0.0).normalize(),
            radius: 0.7,
        };
        let c = Cylinder {
            centre: Vec3::new(-1.0, 0.0, 2.0),
            axis: Vec3::new(0.0, 1.0, 1.0).normalize(),
            radius: 0.3,
            half_length: 2.0,
        };
        for u in [
            Vec2::new(0.1, 0.9),
            Vec2::new(0.7, 0.3),
            Vec2::new(0.99, 0.01),
        ] {
            let (p, _) = disk.sample(u);
            assert!((p - disk.centre).dot(disk.normal).abs() < 1e-6);
            assert!((p - disk.centre).length() <= disk.radius * (1.0 + 1e-6));
            let (p, n, _) = c.sample(u);
            assert!((c.normal(p) - n).length() < 1e-5);
            assert!((c.surface_point(p) - p).length() < 1e-6);
        }
    }
}
