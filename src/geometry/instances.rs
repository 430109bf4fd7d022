//! Geometry placed many times: a two-level BVH. Each shared mesh has one BVH in its own
//! object space; a top-level BVH over the render-space bounds of its placements sends a ray,
//! moved into the placement's object space, into the shared BVH. Memory grows with the
//! shared geometry plus one transform and one top-level leaf per placement, as in pbrt's
//! and Cycles' instancing, instead of with every placed triangle.
//!
//! A placement may move over the shutter (`geometry::motion`): its top-level box bounds the
//! whole motion, as pbrt-v4's does for animated transforms, and a ray enters it through
//! the inverse of its transform at the ray's time.

use super::bvh::Bvh;
use super::hit::{Hit, PrimitiveHit};
use super::motion::MotionTransform;
use super::ray::Ray;
use super::wide::{LeafResult, WideBvh};
use glam::{Affine3A, Vec3};
use obvhs::aabb::Aabb;

/// Most placements a top-level leaf holds, and the cost of a node visit in placements
/// entered, for the surface area heuristic: each placement costs a transform and a whole
/// BVH traversal, so leaves stay small (two, with a node visit costing one entry, was the
/// best of leaf sizes 1, 2, 4, 8 and visit costs 1, 2, 3 by instructions per image when
/// triangles were tested one by one, as placements are).
const PLACEMENTS_PER_LEAF: u32 = 2;
const PLACEMENT_NODE_COST: f32 = 1.0;

/// [`Placement::motion`] of a placement that does not move.
pub const STILL: u32 = u32::MAX;

/// One placement of a shared BVH.
#[derive(Clone, Copy, Debug)]
pub struct Placement {
    /// Index of the shared BVH.
    pub shared: u32,
    /// Render space to the shared geometry's object space (of a still placement).
    pub to_object: Affine3A,
    /// Index of its motion (object space to render space over the shutter), or [`STILL`].
    pub motion: u32,
}

/// A top-level BVH over placements of shared BVHs.
pub struct InstancedBvh {
    /// The top level; its leaf order maps to the placement's index as given to
    /// [`InstancedBvh::build`].
    top: WideBvh,
    /// Placements in top-level leaf order.
    placements: Vec<Placement>,
    shared: Vec<Bvh>,
    /// The motions that [`Placement::motion`] indexes.
    motions: Vec<MotionTransform>,
}

impl InstancedBvh {
    /// Builds the top level over `placements` of the `shared` BVHs, moving by `motions`;
    /// `bounds[i]` is the render-space box of placement `i` (over its whole motion).
    pub fn build(
        shared: Vec<Bvh>,
        placements: &[Placement],
        bounds: &[(Vec3, Vec3)],
        motions: Vec<MotionTransform>,
    ) -> Self {
        assert_eq!(placements.len(), bounds.len());
        let aabbs: Vec<Aabb> = bounds
            .iter()
            .map(|&(lo, hi)| Aabb::new(lo.into(), hi.into()))
            .collect();
        let top = WideBvh::build(&aabbs, PLACEMENTS_PER_LEAF, PLACEMENT_NODE_COST);
        Self {
            placements: top.order.iter().map(|&i| placements[i as usize]).collect(),
            top,
            shared,
            motions,
        }
    }

    /// Bytes the structure holds: top-level nodes, placements, and the shared BVHs.
    pub fn bytes(&self) -> usize {
        self.top.bytes()
            + self.placements.len() * std::mem::size_of::<Placement>()
            + self.shared.iter().map(Bvh::bytes).sum::<usize>()
    }

    /// Top-level leaf `leaf`: its placement's index, `ray` in the placement's object space
    /// at the ray's time (the parameter `t` is the same in both spaces because the
    /// direction is not renormalised), and the shared BVH to trace it in.
    #[inline]
    fn enter(&self, leaf: usize, ray: &Ray, tmax: f32) -> (u32, Ray, &Bvh) {
        let placement = &self.placements[leaf];
        let moved;
        let m = if placement.motion == STILL {
            &placement.to_object
        } else {
            moved = self.motions[placement.motion as usize]
                .affine_at(ray.time)
                .inverse();
            &moved
        };
        let object_ray = Ray {
            origin: m.transform_point3(ray.origin),
            dir: m.transform_vector3(ray.dir),
            tmax,
            time: ray.time,
        };
        (
            self.top.order[leaf],
            object_ray,
            &self.shared[placement.shared as usize],
        )
    }

    /// Closest hit along `ray` in `(0, ray.tmax)`; [`Hit::instance`] is the placement's index
    /// and [`Hit::prim`] the primitive in its shared BVH. `accept(placement, prim, hit,
    /// object_ray)` filters hits on alpha-tested primitives.
    pub fn intersect<F: FnMut(u32, u32, &PrimitiveHit, &Ray) -> bool>(
        &self,
        ray: &Ray,
        mut accept: F,
    ) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        self.top.traverse(ray, |first, count, mut tmax| {
            let mut result = LeafResult::Miss;
            for leaf in first as usize..(first + count) as usize {
                let (placement, object_ray, shared) = self.enter(leaf, ray, tmax);
                if let Some(mut hit) = shared.intersect(&object_ray, |prim, h| {
                    accept(placement, prim, h, &object_ray)
                }) {
                    tmax = hit.t;
                    result = LeafResult::Closer(hit.t);
                    hit.instance = placement;
                    best = Some(hit);
                }
            }
            result
        });
        best
    }

    /// True if anything accepted lies along `ray` in `(0, ray.tmax)`; stops at the first hit.
    pub fn occluded<F: FnMut(u32, u32, &PrimitiveHit, &Ray) -> bool>(
        &self,
        ray: &Ray,
        mut accept: F,
    ) -> bool {
        let mut occluded = false;
        self.top.traverse(ray, |first, count, _| {
            for leaf in first as usize..(first + count) as usize {
                let (placement, object_ray, shared) = self.enter(leaf, ray, ray.tmax);
                if shared.occluded(&object_ray, |prim, h| {
                    accept(placement, prim, h, &object_ray)
                }) {
                    occluded = true;
                    return LeafResult::Stop;
                }
            }
            LeafResult::Miss
        });
        occluded
    }
}

/// The render-space box of an object-space box `(lo, hi)` under `to_render`: the bounds of
/// its eight transformed corners.
pub fn transformed_bounds(lo: Vec3, hi: Vec3, to_render: &Affine3A) -> (Vec3, Vec3) {
    let mut out = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for corner in 0..8 {
        let p = Vec3::new(
            if corner & 1 == 0 { lo.x } else { hi.x },
            if corner & 2 == 0 { lo.y } else { hi.y },
            if corner & 4 == 0 { lo.z } else { hi.z },
        );
        let q = to_render.transform_point3(p);
        out = (out.0.min(q), out.1.max(q));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::Primitive;
    use super::super::bvh::tests::cube;
    use super::*;
    use glam::Quat;

    /// A grid of rotated, scaled and mirrored cubes finds the same hits as the same cubes
    /// flattened into one BVH.
    #[test]
    fn placements_hit_like_flattened_copies() {
        let cube = cube();
        let shared = Bvh::build(
            &cube
                .iter()
                .map(|&t| Primitive::Triangle(t))
                .collect::<Vec<_>>(),
            &vec![0; cube.len()],
        );
        let mut placements = Vec::new();
        let mut bounds = Vec::new();
        let mut flat = Vec::new();
        for i in 0..27 {
            let (x, y, z) = ((i % 3) as f32, ((i / 3) % 3) as f32, (i / 9) as f32);
            let mirror = if i % 2 == 0 { 1.0 } else { -1.0 };
            let to_render = Affine3A::from_scale_rotation_translation(
                Vec3::new(0.3 * mirror, 0.2 + 0.05 * x, 0.25),
                Quat::from_euler(glam::EulerRot::XYZ, 0.3 * x, 0.2 * y, 0.1 * z),
                Vec3::new(x, y, z) * 0.8 - 0.8,
            );
            placements.push(Placement {
                shared: 0,
                to_object: to_render.inverse(),
                motion: STILL,
            });
            bounds.push(transformed_bounds(Vec3::ZERO, Vec3::ONE, &to_render));
            for t in &cube {
                let p = t.map(|v| to_render.transform_point3(v));
                // Mirrored copies are rewound, as the world does when flattening.
                flat.push(Primitive::Triangle(if mirror < 0.0 {
                    [p[0], p[2], p[1]]
                } else {
                    p
                }));
            }
        }
        let instanced = InstancedBvh::build(vec![shared], &placements, &bounds, Vec::new());
        let flat_bvh = Bvh::build(&flat, &vec![0; flat.len()]);
        let mut rng = crate::sampling::pcg::Pcg32::new(3, 0);
        let mut hits = 0;
        let mut point = |scale: f32| {
            (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0) * scale
        };
        for _ in 0..5000 {
            // From anywhere around the grid towards a point inside it.
            let o = point(2.0);
            let ray = Ray::new(o, point(1.0) - o);
            let a = instanced.intersect(&ray, |_, _, _, _| true);
            let b = flat_bvh.intersect(&ray, |_, _| true);
            assert_eq!(a.is_some(), b.is_some());
            assert_eq!(
                instanced.occluded(&ray, |_, _, _, _| true),
                flat_bvh.occluded(&ray, |_, _| true)
            );
            if let (Some(a), Some(b)) = (a, b) {
                hits += 1;
                assert!(
                    (a.t - b.t).abs() <= 1e-5 * b.t.max(1.0),
                    "{} vs {}",
                    a.t,
                    b.t
                );
                assert_eq!(a.instance * 12 + a.prim, b.prim);
                assert_eq!(a.front, b.front);
            }
        }
        assert!(hits > 1000, "{hits} hits");
    }
}
