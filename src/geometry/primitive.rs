//! What a BVH holds: triangles, spheres, disks and cylinders in render space.

use super::quadric::Quadric;
use glam::Vec3;
use obvhs::aabb::Aabb;

/// A primitive the BVH holds.
#[derive(Clone, Copy, Debug)]
pub enum Primitive {
    /// A triangle, counter-clockwise from its front.
    Triangle([Vec3; 3]),
    /// A sphere; its front is the outside.
    Sphere { centre: Vec3, radius: f32 },
    /// A disk (front towards its normal) or an open cylinder (front outside).
    Quadric(Quadric),
}

impl Primitive {
    pub(super) fn aabb(&self) -> Aabb {
        match *self {
            Self::Triangle([a, b, c]) => Aabb::new(a.min(b).min(c).into(), a.max(b).max(c).into()),
            Self::Sphere { centre, radius } => {
                Aabb::new((centre - radius).into(), (centre + radius).into())
            }
            Self::Quadric(q) => {
                let (lo, hi) = q.bounds();
                Aabb::new(lo.into(), hi.into())
            }
        }
    }
}
