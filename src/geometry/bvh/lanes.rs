//! The BVH's packet queries: eight rays in SIMD lanes traverse the wide BVH together
//! (`wide::WideBvh::traverse_lanes`) and test a leaf's triangles lane by lane or triangle by
//! triangle, whichever costs less; each lane's answer is the single-ray query's.

use super::{Bvh, Closest, LeafTriangles, Shape, accepted};
use crate::geometry::hit::{Hit, PrimitiveHit};
use crate::geometry::ray::RayLanes;
use crate::geometry::sphere;
use crate::geometry::triangle::{LaneHits, Lanes, RayShear, ShearLanes};
use crate::geometry::wide::{LaneRays, LaneVisitor, Subtree};
use crate::simd::{F8, LANES, M8};
use std::mem::MaybeUninit;

impl Bvh {
    /// [`Bvh::intersect`] of the `mask` lanes of `rays` at once (a packet traversal; see
    /// [`WideBvh::traverse_lanes`]): the same hits, lane by lane. `accept(lane, prim, hit)`
    /// filters hits on alpha-tested triangles. Runs only inside the packet kernel.
    #[inline(always)]
    pub(crate) fn intersect_lanes<F: FnMut(usize, u32, &PrimitiveHit) -> bool>(
        &self,
        rays: &RayLanes,
        mask: u32,
        accept: F,
    ) -> [Option<Hit>; LANES] {
        let tmax = bounds_of(rays, mask);
        let mut visitor = ClosestLanes {
            bvh: self,
            rays,
            shears: LaneShears::new(ShearLanes::of_rays(rays.origin, rays.dir)),
            closest: tmax.map(Closest::new),
            bound: tmax,
            accept,
        };
        let lane_rays = LaneRays::new(rays.origin, rays.dir);
        self.bvh.traverse_lanes(&lane_rays, &mut visitor);
        visitor.closest.map(Closest::into_hit)
    }

    /// [`Bvh::occluded`] of the `mask` lanes of `rays` at once: the mask of those occluded.
    /// `accept` as for [`Bvh::intersect_lanes`]. Runs only inside the packet kernel.
    #[inline(always)]
    pub(crate) fn occluded_lanes<F: FnMut(usize, u32, &PrimitiveHit) -> bool>(
        &self,
        rays: &RayLanes,
        mask: u32,
        accept: F,
    ) -> u32 {
        let mut visitor = OccludedLanes {
            bvh: self,
            rays,
            shears: LaneShears::new(ShearLanes::of_rays(rays.origin, rays.dir)),
            bounds: bounds_of(rays, mask),
            occluded: 0,
            accept,
        };
        let lane_rays = LaneRays::new(rays.origin, rays.dir);
        self.bvh.traverse_lanes(&lane_rays, &mut visitor);
        visitor.occluded
    }
}

/// Each lane's bound for a packet query of the `mask` lanes of `rays`: its ray's, or -1 for
/// an idle lane, which keeps it out of every box.
#[inline(always)]
fn bounds_of(rays: &RayLanes, mask: u32) -> [f32; LANES] {
    F8::select(M8::from_bits(mask), rays.tmax, F8::splat(-1.0)).to_array()
}

/// Whether a leaf's triangles are tested for the `active` lanes faster one triangle
/// against all lanes ([`crate::geometry::triangle::intersect_lanes`]) than one block of four triangles
/// against each lane ([`crate::geometry::triangle::intersect`]): when there are more lanes than triangles,
/// the two tests costing about as many instructions.
#[inline(always)]
fn lanes_pay(blocks: &[LeafTriangles], active: u32) -> bool {
    let triangles: usize = blocks.iter().map(|b| b.block.triangles()).sum();
    active.count_ones() as usize > triangles
}

/// A packet's watertight-test constants: in lanes, and each lane's taken out of them
/// where first needed (by a single-ray test).
struct LaneShears {
    lanes: ShearLanes,
    /// Lane i's constants, initialised where bit i of `taken` is set (left uninitialised
    /// elsewhere, so that a query that never needs them pays nothing).
    each: [MaybeUninit<RayShear>; LANES],
    taken: u32,
}

impl LaneShears {
    #[inline(always)]
    fn new(lanes: ShearLanes) -> Self {
        Self {
            lanes,
            each: [const { MaybeUninit::uninit() }; LANES],
            taken: 0,
        }
    }

    /// Lane `lane`'s constants.
    #[inline(always)]
    fn lane(&mut self, lane: usize) -> &RayShear {
        if self.taken & (1 << lane) == 0 {
            self.each[lane] = MaybeUninit::new(self.lanes.lane(lane));
            self.taken |= 1 << lane;
        }
        // SAFETY: bit `lane` of `taken` is set, so the entry was initialised above or before.
        unsafe { self.each[lane].assume_init_ref() }
    }
}

/// A closest-hit query of eight lanes: each lane's closest hit so far.
struct ClosestLanes<'a, F> {
    bvh: &'a Bvh,
    rays: &'a RayLanes,
    shears: LaneShears,
    closest: [Closest; LANES],
    /// Each lane's `Closest::bound`, kept beside `closest` so that testing a triangle
    /// against the lanes reads it as one vector instead of deriving it eight times.
    bound: [f32; LANES],
    accept: F,
}

impl<F: FnMut(usize, u32, &PrimitiveHit) -> bool> ClosestLanes<'_, F> {
    /// Each hit lane's closest hit considers its hit of primitive `prim`.
    #[inline(always)]
    fn consider(&mut self, hits: &LaneHits, prim: u32, flags: u8) {
        for lane in Lanes::new(hits.mask) {
            let accept = &mut |prim, hit: &PrimitiveHit| (self.accept)(lane, prim, hit);
            let closest = &mut self.closest[lane];
            closest.consider(hits.get(lane), prim, flags, accept);
            self.bound[lane] = closest.bound();
        }
    }
}

impl<F: FnMut(usize, u32, &PrimitiveHit) -> bool> LaneVisitor for ClosestLanes<'_, F> {
    #[inline(always)]
    fn bounds(&self) -> F8 {
        F8::from_array(self.closest.each_ref().map(|c| c.tmax))
    }

    #[inline(always)]
    fn leaf(&mut self, index: u32, count: u32, active: u32) {
        let (blocks, shapes) = self.bvh.leaf(index, count);
        if !lanes_pay(blocks, active) {
            for lane in Lanes::new(active) {
                let accept = &mut |prim, hit: &PrimitiveHit| (self.accept)(lane, prim, hit);
                let (ray, shear) = (self.rays.ray(lane), self.shears.lane(lane));
                let closest = &mut self.closest[lane];
                self.bvh
                    .leaf_closest(index, count, &ray, shear, closest, accept);
                self.bound[lane] = closest.bound();
            }
            return;
        }
        // Triangle by triangle, the lanes at once. A lane's hits are taken in the
        // single-ray test's order within each block, and its closest hit is the least
        // (distance, primitive) whatever the order: the single-ray query's.
        for leaf in blocks {
            for tri in 0..leaf.block.triangles() {
                let bound = F8::from_array(self.bound);
                let Some(hits) = crate::geometry::triangle::intersect_lanes(
                    &self.shears.lanes,
                    &leaf.block,
                    tri,
                    bound,
                    active,
                ) else {
                    continue;
                };
                self.consider(&hits, leaf.prims[tri], leaf.flags[tri]);
            }
        }
        // Shape by shape: each lane still takes the shapes in the single-ray test's order.
        for s in shapes {
            let Shape::Sphere { centre, radius } = s.shape else {
                for lane in Lanes::new(active) {
                    let (ray, shear) = (self.rays.ray(lane), self.shears.lane(lane));
                    let closest = &mut self.closest[lane];
                    let accept = &mut |prim, hit: &PrimitiveHit| (self.accept)(lane, prim, hit);
                    self.bvh.shape_closest(s, &ray, shear, closest, accept);
                    self.bound[lane] = closest.bound();
                }
                continue;
            };
            let bound = F8::from_array(self.bound);
            let (origin, dir) = (self.rays.origin, self.rays.dir);
            let hits = sphere::intersect_lanes(origin, dir, centre, radius, bound, active);
            self.consider(&hits, s.prim, s.flags);
        }
    }

    #[inline(always)]
    fn single(&mut self, subtree: Subtree, lane: usize) {
        let (ray, shear) = (self.rays.ray(lane), self.shears.lane(lane));
        let closest = &mut self.closest[lane];
        let accept = &mut |prim, hit: &PrimitiveHit| (self.accept)(lane, prim, hit);
        self.bvh.closest_in(subtree, &ray, shear, closest, accept);
        self.bound[lane] = closest.bound();
    }
}

/// An occlusion query of eight lanes: the lanes found occluded so far.
struct OccludedLanes<'a, F> {
    bvh: &'a Bvh,
    rays: &'a RayLanes,
    shears: LaneShears,
    /// The rays' bounds; -1 once a lane is answered (or idle).
    bounds: [f32; LANES],
    occluded: u32,
    accept: F,
}

impl<F: FnMut(usize, u32, &PrimitiveHit) -> bool> OccludedLanes<'_, F> {
    #[inline(always)]
    fn answer(&mut self, lane: usize) {
        self.occluded |= 1 << lane;
        self.bounds[lane] = -1.0;
    }

    /// Answers the lanes whose hit of primitive `prim` is accepted; returns them.
    #[inline(always)]
    fn answer_hits(&mut self, hits: &LaneHits, prim: u32, flags: u8) -> u32 {
        let mut answered = 0;
        for lane in Lanes::new(hits.mask) {
            let accept = &mut |prim, hit: &PrimitiveHit| (self.accept)(lane, prim, hit);
            if accepted(&hits.get(lane), prim, flags, accept) {
                self.answer(lane);
                answered |= 1 << lane;
            }
        }
        answered
    }
}

impl<F: FnMut(usize, u32, &PrimitiveHit) -> bool> LaneVisitor for OccludedLanes<'_, F> {
    #[inline(always)]
    fn bounds(&self) -> F8 {
        F8::from_array(self.bounds)
    }

    #[inline(always)]
    fn leaf(&mut self, index: u32, count: u32, mut active: u32) {
        let (blocks, shapes) = self.bvh.leaf(index, count);
        if !lanes_pay(blocks, active) {
            for lane in Lanes::new(active) {
                let accept = &mut |prim, hit: &PrimitiveHit| (self.accept)(lane, prim, hit);
                let (ray, shear) = (self.rays.ray(lane), self.shears.lane(lane));
                if self.bvh.leaf_occludes(index, count, &ray, shear, accept) {
                    self.answer(lane);
                }
            }
            return;
        }
        let tmax = F8::from_array(self.bounds);
        for leaf in blocks {
            for tri in 0..leaf.block.triangles() {
                let Some(hits) = crate::geometry::triangle::intersect_lanes(
                    &self.shears.lanes,
                    &leaf.block,
                    tri,
                    tmax,
                    active,
                ) else {
                    continue;
                };
                active &= !self.answer_hits(&hits, leaf.prims[tri], leaf.flags[tri]);
                if active == 0 {
                    return;
                }
            }
        }
        // Shape by shape; a lane is answered by the first shape that occludes it.
        for s in shapes {
            if active == 0 {
                return;
            }
            let Shape::Sphere { centre, radius } = s.shape else {
                for lane in Lanes::new(active) {
                    let (ray, shear) = (self.rays.ray(lane), self.shears.lane(lane));
                    let accept = &mut |prim, hit: &PrimitiveHit| (self.accept)(lane, prim, hit);
                    if self.bvh.shape_occludes(s, &ray, shear, accept) {
                        self.answer(lane);
                        active &= !(1 << lane);
                    }
                }
                continue;
            };
            let tmax = F8::from_array(self.bounds);
            let (origin, dir) = (self.rays.origin, self.rays.dir);
            let hits = sphere::intersect_lanes(origin, dir, centre, radius, tmax, active);
            active &= !self.answer_hits(&hits, s.prim, s.flags);
        }
    }

    #[inline(always)]
    fn single(&mut self, subtree: Subtree, lane: usize) {
        let (ray, shear) = (self.rays.ray(lane), self.shears.lane(lane));
        let accept = &mut |prim, hit: &PrimitiveHit| (self.accept)(lane, prim, hit);
        if self.bvh.occludes_in(subtree, &ray, shear, accept) {
            self.answer(lane);
        }
    }
}
