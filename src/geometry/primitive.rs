//! What a BVH holds: triangles (still or deforming over the shutter), spheres, disks and
//! cylinders in render space.

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
    /// A triangle that changes shape over the shutter: its corners at `keys` keys are at
    /// `first` on in the corners given to the BVH's build.
    Deforming { first: u32, keys: u32 },
}

impl Primitive {
    /// Its box (over the whole shutter for a deforming triangle, whose corners at its keys
    /// are in `corners`).
    pub(super) fn aabb(&self, corners: &[[Vec3; 3]]) -> Aabb {
        match *self {
            Self::Triangle([a, b, c]) => Aabb::new(a.min(b).min(c).into(), a.max(b).max(c).into()),
            Self::Sphere { centre, radius } => {
                Aabb::new((centre - radius).into(), (centre + radius).into())
            }
            Self::Quadric(q) => {
                let (lo, hi) = q.bounds();
                Aabb::new(lo.into(), hi.into())
            }
            Self::Deforming { first, keys } => {
                let (lo, hi) = super::deformation::swept_bounds(
                    &corners[first as usize..(first + keys) as usize],
                );
                Aabb::new(lo.into(), hi.into())
            }
        }
    }
}
