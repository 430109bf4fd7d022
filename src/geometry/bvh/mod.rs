//! The BVH over render-space primitives: eight-wide nodes (`wide`, built from obvhs's PLOC),
//! leaves of up to four triangles tested as one block and analytic shapes tested one by
//! one, and the two ray queries the integrator needs: closest hit and occlusion, for one
//! ray or (in the packet kernel) eight as a packet. Coincident primitives resolve to the
//! least primitive index, whatever the BVH's layout. The packet queries are `lanes`.

#[cfg(target_arch = "x86_64")]
mod lanes;

use super::hit::{ALPHA_TESTED, CULL_BACK, Hit, NOT_PLACED, PrimitiveHit};
use super::primitive::Primitive;
use super::quadric;
use super::ray::Ray;
use super::sphere;
use super::triangle::{RayShear, TriangleBlock};
use super::wide::{LeafResult, Subtree, WideBvh};
use glam::Vec3;
use obvhs::aabb::Aabb;

/// Most primitives a leaf holds, and the cost of a node visit in leaf primitive tests, for
/// the surface area heuristic. A leaf's triangles are tested four at a time
/// ([`TriangleBlock`]), so a leaf of four costs little more than a leaf of one. Chosen over
/// leaf sizes 2, 4, 8 and visit costs 1, 2, 3, 4, 6 by rays per second. Against leaves of
/// two triangles tested one by one with a visit cost of 1 (tools/bench/throughput.rs, one thread,
/// interleaved runs), the million-triangle sphere field traces 7 % more coherent and 13 %
/// more incoherent closest-hit rays and 8-9 % more shadow rays, with 13 % less BVH memory;
/// the MIS plates' bounce and shadow rays are 12 % faster; the Cornell box's rays are
/// within the noise.
const PRIMITIVES_PER_LEAF: u32 = 4;
const NODE_COST: f32 = 3.0;

/// A leaf's triangles, up to four to a block, with what the leaf test needs of each lane.
#[derive(Clone, Copy, Debug)]
struct LeafTriangles {
    block: TriangleBlock,
    /// Each lane's primitive index, as given to [`Bvh::build`].
    prims: [u32; 4],
    /// Each lane's intersection flags.
    flags: [u8; 4],
    /// Index in [`Bvh::shapes`] of the leaf's first sphere or quadric (read from the leaf's
    /// first block).
    shapes: u32,
}

/// A sphere or quadric of a leaf, tested one by one.
#[derive(Clone, Copy, Debug)]
struct LeafShape {
    shape: Shape,
    /// The primitive index, as given to [`Bvh::build`].
    prim: u32,
    flags: u8,
}

/// The shapes tested one by one: the analytic ones, and up to four triangles that change
/// shape over the shutter (a [`DeformingBlock`] of [`Bvh::deforming`]), tested together.
#[derive(Clone, Copy, Debug)]
enum Shape {
    Sphere { centre: Vec3, radius: f32 },
    Quadric(quadric::Quadric),
    Deforming(u32),
}

/// Up to four triangles of a leaf that change shape over the shutter: each lane's corners at
/// its keys are `keys[lane]` entries of [`Bvh::corners`] from `first[lane]` on (no keys: an
/// empty lane). A ray tests them as one [`TriangleBlock`] made where they are at its time.
#[derive(Clone, Copy, Debug)]
struct DeformingBlock {
    first: [u32; 4],
    keys: [u32; 4],
    prims: [u32; 4],
    flags: [u8; 4],
}

impl DeformingBlock {
    /// The ray's hits (`shear` is its) on the block's triangles where they are at shutter
    /// time `time`, in `(0, tmax)`.
    #[inline]
    fn intersect(
        &self,
        corners: &[[Vec3; 3]],
        time: f32,
        shear: &RayShear,
        tmax: f32,
    ) -> Option<super::triangle::BlockHits> {
        let count = self.keys.iter().take_while(|&&k| k > 0).count();
        let mut tris = [[Vec3::ZERO; 3]; 4];
        for (tri, (&first, &keys)) in tris.iter_mut().zip(self.first.iter().zip(&self.keys)) {
            let (first, keys) = (first as usize, keys as usize);
            if keys > 0 {
                *tri = super::deformation::triangle_at(&corners[first..first + keys], time);
            }
        }
        super::triangle::intersect(shear, &TriangleBlock::new(&tris[..count]), tmax)
    }
}

/// A leaf's label in the wide BVH: its blocks (or, without triangles, its shapes) start at
/// the label's index; the count holds the number of blocks in its low 16 bits and the
/// number of shapes above.
const SHAPE_COUNT_SHIFT: u32 = 16;

/// A BVH over primitives with per-primitive flags, answering closest-hit and occlusion
/// queries.
pub struct Bvh {
    bvh: WideBvh,
    /// Leaves' triangles, in leaf order.
    blocks: Vec<LeafTriangles>,
    /// Leaves' spheres, quadrics and blocks of deforming triangles, in leaf order.
    shapes: Vec<LeafShape>,
    /// The blocks of deforming triangles that [`Shape::Deforming`] indexes.
    deforming: Vec<DeformingBlock>,
    /// The corners of deforming triangles at their keys (`geometry::deformation`).
    corners: Vec<[Vec3; 3]>,
}

impl Bvh {
    /// Builds the BVH over `prims` (render space) with their intersection `flags`. Runs on
    /// the current rayon pool.
    pub fn build(prims: &[Primitive], flags: &[u8]) -> Self {
        assert_eq!(prims.len(), flags.len());
        Self::build_from(flags, |i| prims[i as usize])
    }

    /// [`Bvh::build`] over the primitives `primitive(i)` for `i` in `0..flags.len()`, made when
    /// the build needs them (their bounds, then the leaves) instead of held in an array
    /// through the build's peak: 40 bytes a primitive less at that peak.
    pub fn build_from(flags: &[u8], primitive: impl Fn(u32) -> Primitive + Sync) -> Self {
        Self::build_deforming(flags, primitive, Vec::new())
    }

    /// [`Bvh::build_from`] where some primitives are deforming triangles
    /// ([`Primitive::Deforming`]), whose corners at their keys `corners` holds.
    pub fn build_deforming(
        flags: &[u8],
        primitive: impl Fn(u32) -> Primitive + Sync,
        corners: Vec<[Vec3; 3]>,
    ) -> Self {
        use rayon::prelude::*;
        let aabbs: Vec<Aabb> = (0..flags.len() as u32)
            .into_par_iter()
            .map(|i| primitive(i).aabb(&corners))
            .collect();
        let mut bvh = WideBvh::build(&aabbs, PRIMITIVES_PER_LEAF, NODE_COST);
        drop(aabbs);
        let order = std::mem::take(&mut bvh.order);
        let (mut blocks, mut shapes, mut deforming) = (Vec::new(), Vec::new(), Vec::new());
        bvh.relabel_leaves(|first, count| {
            let leaf = &order[first as usize..(first + count) as usize];
            let (first_block, first_shape) = (blocks.len(), shapes.len());
            let mut triangles = Vec::with_capacity(leaf.len());
            let mut moving = Vec::new();
            for &prim in leaf {
                let flags = flags[prim as usize];
                match primitive(prim) {
                    Primitive::Triangle(p) => triangles.push((p, prim, flags)),
                    Primitive::Sphere { centre, radius } => shapes.push(LeafShape {
                        shape: Shape::Sphere { centre, radius },
                        prim,
                        flags,
                    }),
                    Primitive::Quadric(q) => shapes.push(LeafShape {
                        shape: Shape::Quadric(q),
                        prim,
                        flags,
                    }),
                    Primitive::Deforming { first, keys } => moving.push((first, keys, prim, flags)),
                }
            }
            for chunk in moving.chunks(4) {
                let mut block = DeformingBlock {
                    first: [0; 4],
                    keys: [0; 4],
                    prims: [0; 4],
                    flags: [0; 4],
                };
                for (lane, &(first, keys, prim, flags)) in chunk.iter().enumerate() {
                    block.first[lane] = first;
                    block.keys[lane] = keys;
                    block.prims[lane] = prim;
                    block.flags[lane] = flags;
                }
                shapes.push(LeafShape {
                    shape: Shape::Deforming(deforming.len() as u32),
                    prim: block.prims[0],
                    flags: 0,
                });
                deforming.push(block);
            }
            for chunk in triangles.chunks(4) {
                let (mut lane_prims, mut lane_flags) = ([0; 4], [0; 4]);
                for (lane, &(_, prim, flags)) in chunk.iter().enumerate() {
                    (lane_prims[lane], lane_flags[lane]) = (prim, flags);
                }
                let tris: Vec<[Vec3; 3]> = chunk.iter().map(|t| t.0).collect();
                blocks.push(LeafTriangles {
                    block: TriangleBlock::new(&tris),
                    prims: lane_prims,
                    flags: lane_flags,
                    shapes: first_shape as u32,
                });
            }
            let (block_count, shape_count) =
                (blocks.len() - first_block, shapes.len() - first_shape);
            let index = if block_count > 0 {
                first_block
            } else {
                first_shape
            };
            (
                index as u32,
                block_count as u32 | (shape_count as u32) << SHAPE_COUNT_SHIFT,
            )
        });
        Self {
            bvh,
            blocks,
            shapes,
            deforming,
            corners,
        }
    }

    /// Lowers `closest` by shape `s`'s hits along `ray` (`shear` is the ray's).
    #[inline(always)]
    fn shape_closest<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        s: &LeafShape,
        ray: &Ray,
        shear: &RayShear,
        closest: &mut Closest,
        accept: &mut F,
    ) {
        if let Shape::Deforming(block) = s.shape {
            let block = &self.deforming[block as usize];
            if let Some(hits) = block.intersect(&self.corners, ray.time, shear, closest.bound()) {
                for lane in hits.lanes() {
                    closest.consider(hits.get(lane), block.prims[lane], block.flags[lane], accept);
                }
            }
        } else if let Some(hit) = s.shape.intersect(ray, closest.bound()) {
            closest.consider(hit, s.prim, s.flags, accept);
        }
    }

    /// Whether shape `s` holds an accepted hit along `ray` (`shear` is the ray's).
    #[inline(always)]
    fn shape_occludes<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        s: &LeafShape,
        ray: &Ray,
        shear: &RayShear,
        accept: &mut F,
    ) -> bool {
        if let Shape::Deforming(block) = s.shape {
            let block = &self.deforming[block as usize];
            let Some(hits) = block.intersect(&self.corners, ray.time, shear, ray.tmax) else {
                return false;
            };
            hits.lanes().any(|lane| {
                accepted(
                    &hits.get(lane),
                    block.prims[lane],
                    block.flags[lane],
                    accept,
                )
            })
        } else {
            s.shape
                .intersect(ray, ray.tmax)
                .is_some_and(|hit| accepted(&hit, s.prim, s.flags, accept))
        }
    }

    /// Bytes the structure holds: wide nodes, triangle blocks and shapes.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.bvh.bytes()
            + self.blocks.len() * size_of::<LeafTriangles>()
            + self.shapes.len() * size_of::<LeafShape>()
            + self.deforming.len() * size_of::<DeformingBlock>()
            + self.corners.len() * size_of::<[Vec3; 3]>()
    }

    /// A leaf's triangle blocks and shapes from its label.
    #[inline(always)]
    fn leaf(&self, index: u32, count: u32) -> (&[LeafTriangles], &[LeafShape]) {
        let index = index as usize;
        let blocks = (count & ((1 << SHAPE_COUNT_SHIFT) - 1)) as usize;
        let shapes = (count >> SHAPE_COUNT_SHIFT) as usize;
        if blocks == 0 {
            return (&[], &self.shapes[index..index + shapes]);
        }
        let first_shape = self.blocks[index].shapes as usize;
        (
            &self.blocks[index..index + blocks],
            &self.shapes[first_shape..first_shape + shapes],
        )
    }

    /// Closest hit along `ray` in `(0, ray.tmax)`. `accept(prim, hit)` filters hits on
    /// alpha-tested triangles.
    pub fn intersect<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        ray: &Ray,
        mut accept: F,
    ) -> Option<Hit> {
        let mut closest = Closest::new(ray.tmax);
        let shear = RayShear::new(ray);
        self.closest_in(self.bvh.root(), ray, &shear, &mut closest, &mut accept);
        closest.into_hit()
    }

    /// True if anything accepted lies along `ray` in `(0, ray.tmax)`; stops at the first hit.
    pub fn occluded<F: FnMut(u32, &PrimitiveHit) -> bool>(&self, ray: &Ray, mut accept: F) -> bool {
        let shear = RayShear::new(ray);
        self.occludes_in(self.bvh.root(), ray, &shear, &mut accept)
    }

    /// Lowers `closest` to the closest hit along `ray` in `subtree` (`shear` is the ray's):
    /// the single-ray closest-hit traversal, of the whole BVH or of a packet's lane.
    #[inline(always)]
    fn closest_in<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        subtree: Subtree,
        ray: &Ray,
        shear: &RayShear,
        closest: &mut Closest,
        accept: &mut F,
    ) {
        let tmax = closest.tmax;
        self.bvh
            .traverse_from(subtree, ray, tmax, |index, count, _| {
                self.leaf_closest(index, count, ray, shear, closest, accept)
            });
    }

    /// Whether `subtree` holds an accepted hit along `ray` (`shear` is the ray's): the
    /// single-ray occlusion traversal, stopping at the first hit.
    #[inline(always)]
    fn occludes_in<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        subtree: Subtree,
        ray: &Ray,
        shear: &RayShear,
        accept: &mut F,
    ) -> bool {
        let mut occluded = false;
        self.bvh
            .traverse_from(subtree, ray, ray.tmax, |index, count, _| {
                occluded = self.leaf_occludes(index, count, ray, shear, accept);
                if occluded {
                    LeafResult::Stop
                } else {
                    LeafResult::Miss
                }
            });
        occluded
    }

    /// Tests the leaf labelled `(index, count)` for `ray`'s closest hit (`shear` is the
    /// ray's): the leaf test of [`Bvh::intersect`].
    #[inline(always)]
    fn leaf_closest<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        index: u32,
        count: u32,
        ray: &Ray,
        shear: &RayShear,
        closest: &mut Closest,
        accept: &mut F,
    ) -> LeafResult {
        let (blocks, shapes) = self.leaf(index, count);
        let before = closest.tmax;
        for leaf in blocks {
            if let Some(hits) = super::triangle::intersect(shear, &leaf.block, closest.bound()) {
                for lane in hits.lanes() {
                    let (prim, flags) = (leaf.prims[lane], leaf.flags[lane]);
                    closest.consider(hits.get(lane), prim, flags, accept);
                }
            }
        }
        for s in shapes {
            self.shape_closest(s, ray, shear, closest, accept);
        }
        if closest.tmax < before {
            LeafResult::Closer(closest.tmax)
        } else {
            LeafResult::Miss
        }
    }

    /// Whether the leaf labelled `(index, count)` holds an accepted hit along `ray` (`shear`
    /// is the ray's): the leaf test of [`Bvh::occluded`].
    #[inline(always)]
    fn leaf_occludes<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        index: u32,
        count: u32,
        ray: &Ray,
        shear: &RayShear,
        accept: &mut F,
    ) -> bool {
        let (blocks, shapes) = self.leaf(index, count);
        for leaf in blocks {
            if let Some(hits) = super::triangle::intersect(shear, &leaf.block, ray.tmax) {
                for lane in hits.lanes() {
                    let (prim, flags) = (leaf.prims[lane], leaf.flags[lane]);
                    if accepted(&hits.get(lane), prim, flags, accept) {
                        return true;
                    }
                }
            }
        }
        shapes
            .iter()
            .any(|s| self.shape_occludes(s, ray, shear, accept))
    }
}

/// The closest accepted hit so far. A hit at exactly its distance wins if its primitive was
/// given first: coincident primitives resolve to the same one whatever the BVH's layout and
/// the order a leaf's primitives are tested in (the closest hit is the least distance, then
/// primitive).
struct Closest {
    /// The closest hit's distance (the ray's bound before any hit).
    tmax: f32,
    hit: Option<PrimitiveHit>,
    prim: u32,
}

impl Closest {
    /// No hit yet, below `tmax`.
    #[inline(always)]
    fn new(tmax: f32) -> Self {
        Self {
            tmax,
            hit: None,
            prim: u32::MAX,
        }
    }

    /// The closest hit found, if any (on geometry that is not placed).
    #[inline(always)]
    fn into_hit(self) -> Option<Hit> {
        self.hit.map(|h| Hit {
            t: h.t,
            prim: self.prim,
            b1: h.b1,
            b2: h.b2,
            front: h.front,
            instance: NOT_PLACED,
        })
    }

    /// The bound a primitive's hit must be below to be considered.
    #[inline(always)]
    fn bound(&self) -> f32 {
        if self.hit.is_some() {
            self.tmax.next_up()
        } else {
            self.tmax
        }
    }

    /// Takes `hit` on primitive `prim` if it is accepted and comes first.
    #[inline(always)]
    fn consider<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &mut self,
        hit: PrimitiveHit,
        prim: u32,
        flags: u8,
        accept: &mut F,
    ) {
        if hit.t < self.bound()
            && accepted(&hit, prim, flags, accept)
            && (hit.t < self.tmax || prim < self.prim)
        {
            (self.tmax, self.prim, self.hit) = (hit.t, prim, Some(hit));
        }
    }
}

impl Shape {
    /// The analytic shape's hit along `ray` in `(0, tmax)` (deforming blocks are tested by
    /// [`Bvh::shape_closest`] and [`Bvh::shape_occludes`]).
    #[inline(always)]
    fn intersect(&self, ray: &Ray, tmax: f32) -> Option<PrimitiveHit> {
        match *self {
            Self::Sphere { centre, radius } => sphere::intersect(ray, centre, radius, tmax),
            Self::Quadric(q) => q.intersect(ray, tmax),
            Self::Deforming(_) => None,
        }
    }
}

/// Whether a hit on primitive `prim` with intersection `flags` counts: not on a culled back,
/// and (for alpha-tested primitives) accepted by `accept`.
#[inline(always)]
fn accepted<F: FnMut(u32, &PrimitiveHit) -> bool>(
    hit: &PrimitiveHit,
    prim: u32,
    flags: u8,
    accept: &mut F,
) -> bool {
    flags == 0
        || ((hit.front || flags & CULL_BACK == 0)
            && (flags & ALPHA_TESTED == 0 || accept(prim, hit)))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    #[cfg(target_arch = "x86_64")]
    use crate::geometry::ray::RayLanes;
    #[cfg(target_arch = "x86_64")]
    use crate::simd::LANES;

    /// One triangle tested on its own, as brute force does.
    fn brute_force_test(shear: &RayShear, tri: [Vec3; 3], tmax: f32) -> Option<PrimitiveHit> {
        crate::geometry::triangle::intersect(shear, &TriangleBlock::new(&[tri]), tmax)
            .map(|h| h.get(0))
    }

    fn prims(tris: &[[Vec3; 3]]) -> Vec<Primitive> {
        tris.iter().map(|&t| Primitive::Triangle(t)).collect()
    }

    #[test]
    fn spheres_and_triangles_share_the_bvh() {
        let mut p = prims(&cube());
        p.push(Primitive::Sphere {
            centre: Vec3::new(3.0, 0.5, 0.5),
            radius: 0.5,
        });
        let bvh = Bvh::build(&p, &vec![0; p.len()]);
        let hit = bvh
            .intersect(&Ray::new(Vec3::new(5.0, 0.5, 0.5), -Vec3::X), |_, _| true)
            .unwrap();
        assert_eq!(hit.prim, 12);
        assert!((hit.t - 1.5).abs() < 1e-6 && hit.front);
        let hit = bvh
            .intersect(&Ray::new(Vec3::new(2.9, 0.5, 0.5), -Vec3::X), |_, _| true)
            .unwrap();
        assert!(
            hit.prim == 12 && (hit.t - 0.4).abs() < 1e-5 && !hit.front,
            "the sphere's inside"
        );
        let hit = bvh
            .intersect(&Ray::new(Vec3::new(2.4, 0.5, 0.5), -Vec3::X), |_, _| true)
            .unwrap();
        assert!(
            hit.prim < 12 && (hit.t - 1.4).abs() < 1e-5,
            "past the sphere, the cube"
        );
    }

    /// A closed unit cube of 12 triangles, wound outwards.
    pub(crate) fn cube() -> Vec<[Vec3; 3]> {
        let c = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let quads = [
            [c(0., 0., 0.), c(0., 1., 0.), c(1., 1., 0.), c(1., 0., 0.)],
            [c(0., 0., 1.), c(1., 0., 1.), c(1., 1., 1.), c(0., 1., 1.)],
            [c(0., 0., 0.), c(1., 0., 0.), c(1., 0., 1.), c(0., 0., 1.)],
            [c(0., 1., 0.), c(0., 1., 1.), c(1., 1., 1.), c(1., 1., 0.)],
            [c(0., 0., 0.), c(0., 0., 1.), c(0., 1., 1.), c(0., 1., 0.)],
            [c(1., 0., 0.), c(1., 1., 0.), c(1., 1., 1.), c(1., 0., 1.)],
        ];
        quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect()
    }

    /// 3,000 random triangles and 300 spheres within 5 of the origin (sizes over three
    /// decades, with exact duplicates), some culled from the back (flag CULL_BACK) and some
    /// alpha-tested (ALPHA_TESTED), with `point(scale)` a random point within `scale`.
    fn random_soup(point: &mut impl FnMut(f32) -> Vec3) -> (Vec<Primitive>, Vec<u8>) {
        let mut soup = Vec::new();
        for i in 0..3300 {
            let size = [0.01, 0.1, 1.0][i % 3];
            let c = point(4.0);
            soup.push(if i % 11 == 0 {
                Primitive::Sphere {
                    centre: c,
                    radius: size,
                }
            } else {
                Primitive::Triangle([c + point(size), c + point(size), c + point(size)])
            });
            if i % 50 == 0 {
                soup.push(soup[soup.len() - 1]);
            }
        }
        let flags = (0..soup.len())
            .map(|i| match i % 7 {
                0 => CULL_BACK,
                1 => ALPHA_TESTED,
                _ => 0,
            })
            .collect();
        (soup, flags)
    }

    /// The packet queries answer as the single-ray ones, lane by lane and to the bit, on the
    /// random soup: packets of rays from one point (coherent) and from anywhere
    /// (incoherent), with random bounds and random idle lanes.
    #[test]
    fn packet_queries_answer_as_single_rays() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let mut rng = crate::sampling::pcg::Pcg32::new(5, 9);
        let mut point = |scale: f32| {
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 * scale
                - Vec3::splat(scale)
        };
        let (soup, flags) = random_soup(&mut point);
        let bvh = Bvh::build(&soup, &flags);
        let (mut hits, mut lanes) = (0, 0);
        for k in 0..3000 {
            let shared = point(6.0);
            let rays: [Ray; LANES] = std::array::from_fn(|_| Ray {
                origin: if k % 2 == 0 { shared } else { point(6.0) },
                dir: point(1.0),
                tmax: if k % 3 == 0 {
                    f32::INFINITY
                } else {
                    8.0 * point(0.5).x.abs()
                },
                time: 0.0,
            });
            let mask = match k % 4 {
                0 => 0xff,
                _ => (point(0.5).x.to_bits() >> 3) & 0xff,
            };
            // SAFETY: the CPU has AVX2 and FMA.
            let (found, occluded) = unsafe { query_lanes(&bvh, &rays, mask) };
            for (lane, ray) in rays.iter().enumerate() {
                if mask & (1 << lane) == 0 {
                    assert!(found[lane].is_none() && occluded & (1 << lane) == 0);
                    continue;
                }
                let accept = |prim: u32, _: &PrimitiveHit| !prim.is_multiple_of(3);
                let single = bvh.intersect(ray, accept);
                let bits = |h: Option<Hit>| {
                    h.map(|h| {
                        (
                            h.t.to_bits(),
                            h.prim,
                            h.b1.to_bits(),
                            h.b2.to_bits(),
                            h.front,
                        )
                    })
                };
                assert_eq!(bits(found[lane]), bits(single), "packet {k}, lane {lane}");
                let blocked = occluded & (1 << lane) != 0;
                assert_eq!(
                    blocked,
                    bvh.occluded(ray, accept),
                    "packet {k}, lane {lane}"
                );
                (hits, lanes) = (hits + single.is_some() as u32, lanes + 1);
            }
        }
        assert!(
            hits > lanes / 4 && hits < lanes * 3 / 4,
            "{hits} of {lanes} lanes hit"
        );
    }

    /// The packet queries of the soup test, compiled for AVX2 and FMA; alpha-tested
    /// primitives accept unless a multiple of 3.
    #[target_feature(enable = "avx2,fma")]
    fn query_lanes(bvh: &Bvh, rays: &[Ray; LANES], mask: u32) -> ([Option<Hit>; LANES], u32) {
        let accept = |_: usize, prim: u32, _: &PrimitiveHit| !prim.is_multiple_of(3);
        let rays = RayLanes::of_rays(rays);
        (
            bvh.intersect_lanes(&rays, mask, accept),
            bvh.occluded_lanes(&rays, mask, accept),
        )
    }

    /// A soup of 3,000 random triangles and 300 spheres (sizes over three decades, with
    /// exact duplicates; some culled from the back, some alpha-tested and accepted for even
    /// primitives) against brute force, for random rays from inside and outside it with random
    /// bounds: the same closest hit (distance, and the first-given primitive of coincident
    /// ones) and the same occlusion answer. This exercises multi-level nodes, nearest-first
    /// order, pruning by the closest hit, and leaves of several triangle blocks' lanes and
    /// shapes.
    #[test]
    fn closest_hits_and_occlusion_match_brute_force() {
        let mut rng = crate::sampling::pcg::Pcg32::new(11, 3);
        let mut point = |scale: f32| {
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 * scale
                - Vec3::splat(scale)
        };
        let (soup, flags) = random_soup(&mut point);
        let accept = |prim: u32, _: &PrimitiveHit| prim.is_multiple_of(2);
        let bvh = Bvh::build(&soup, &flags);
        let (mut hits, mut sphere_hits) = (0, 0);
        for k in 0..4000 {
            let origin = point(6.0);
            let dir = point(1.0);
            let tmax = if k % 2 == 0 { f32::INFINITY } else { 4.0 };
            let ray = Ray {
                origin,
                dir,
                tmax,
                time: 0.0,
            };
            let shear = RayShear::new(&ray);
            let brute = soup
                .iter()
                .enumerate()
                .filter_map(|(i, p)| {
                    let hit = match *p {
                        Primitive::Triangle(t) => brute_force_test(&shear, t, tmax)?,
                        Primitive::Sphere { centre, radius } => {
                            sphere::intersect(&ray, centre, radius, tmax)?
                        }
                        Primitive::Quadric(_) | Primitive::Deforming { .. } => unreachable!(),
                    };
                    let culled = flags[i] == CULL_BACK && !hit.front;
                    let rejected = flags[i] == ALPHA_TESTED && !accept(i as u32, &hit);
                    (!culled && !rejected).then_some((hit, i))
                })
                .min_by(|a, b| a.0.t.total_cmp(&b.0.t).then(a.1.cmp(&b.1)));
            let hit = bvh.intersect(&ray, accept);
            assert_eq!(
                hit.map(|h| (h.t, h.prim)),
                brute.map(|(h, i)| (h.t, i as u32)),
                "ray {ray:?}"
            );
            assert_eq!(bvh.occluded(&ray, accept), brute.is_some());
            hits += brute.is_some() as u32;
            sphere_hits +=
                brute.is_some_and(|(_, i)| matches!(soup[i], Primitive::Sphere { .. })) as u32;
        }
        assert!(
            hits > 1000 && sphere_hits > 100,
            "only {hits} rays hit, {sphere_hits} of them a sphere"
        );
    }

    #[test]
    fn rays_from_inside_a_closed_cube_always_hit_it() {
        let tris = cube();
        let bvh = Bvh::build(&prims(&tris), &vec![0; tris.len()]);
        let mut rng = crate::sampling::pcg::Pcg32::new(7, 0);
        for _ in 0..20000 {
            let o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let u = glam::Vec2::new(rng.next_f32(), rng.next_f32());
            let d = crate::sampling::warp::square_to_uniform_sphere(u);
            let hit = bvh
                .intersect(&Ray::new(o, d), |_, _| true)
                .expect("escaped the cube");
            assert!(!hit.front, "the inside sees back faces");
            // Brute force agrees on the distance.
            let shear = RayShear::new(&Ray::new(o, d));
            let best = tris
                .iter()
                .filter_map(|t| brute_force_test(&shear, *t, f32::INFINITY))
                .map(|h| h.t)
                .fold(f32::INFINITY, f32::min);
            assert_eq!(hit.t, best);
        }
    }

    /// Geometry nested over every float exponent (clusters of 64 triangles at 2^-120 ..
    /// 2^119 along a line) needs more than the inline stack when a ray runs along it: the
    /// traversal descends into the small end first, pushing the larger clusters (45 groups
    /// deep). With only clusters from scale 2^`first` on accepted (as alpha testing would),
    /// the closest accepted hit lies in pushed groups. The stack spills, and the BVH finds
    /// what brute force finds. (obvhs's overwriting stack happens to pass this too: the
    /// groups it drops here hold no accepted hit; `traversal_stack_spills_in_order` checks
    /// the spill itself.)
    #[test]
    fn deep_traversals_lose_nothing() {
        const PER_SCALE: u32 = 64;
        let mut tris = Vec::new();
        for k in -120..120 {
            let x = 2f32.powi(k);
            for j in 0..PER_SCALE {
                let s = x * 0.1 * (1.0 + j as f32 * 0.01);
                let c = Vec3::new(x * (1.0 + j as f32 * 0.001), 0.0, 0.0);
                tris.push([
                    c - Vec3::new(0.0, s, s),
                    c + Vec3::new(0.0, s, -s),
                    c + Vec3::Z * s,
                ]);
            }
        }
        let bvh = Bvh::build(&prims(&tris), &vec![ALPHA_TESTED; tris.len()]);
        crate::geometry::wide::SPILLED.store(false, std::sync::atomic::Ordering::Relaxed);
        let ray = Ray::new(Vec3::new(-1.0, 0.0, 0.0), Vec3::X);
        let shear = RayShear::new(&ray);
        let mut found = 0;
        for first in -120..120 {
            let accepted = |prim: u32| prim / PER_SCALE >= (first + 120) as u32;
            let best = (0..tris.len() as u32)
                .filter(|&p| accepted(p))
                .filter_map(|p| brute_force_test(&shear, tris[p as usize], f32::INFINITY))
                .map(|h| h.t)
                .fold(f32::INFINITY, f32::min);
            let hit = bvh.intersect(&ray, |p, _| accepted(p));
            assert_eq!(hit.map_or(f32::INFINITY, |h| h.t), best, "from 2^{first}");
            let short = Ray {
                tmax: best * 1.0001,
                ..ray
            };
            assert_eq!(
                bvh.occluded(&short, |p, _| accepted(p)),
                best.is_finite(),
                "from 2^{first}"
            );
            found += best.is_finite() as u32;
        }
        assert!(found > 100, "only {found} rays hit");
        assert!(
            crate::geometry::wide::SPILLED.load(std::sync::atomic::Ordering::Relaxed),
            "never spilled"
        );
    }

    #[test]
    fn contact_hits_and_culling_and_occlusion() {
        let tris = cube();
        let mut flags = vec![0; tris.len()];
        let bvh = Bvh::build(&prims(&tris), &flags);
        // A ray starting 1e-6 in front of a face still sees it.
        let o = Vec3::new(0.5, 0.5, 1.0 + 1e-6);
        let hit = bvh.intersect(&Ray::new(o, -Vec3::Z), |_, _| true).unwrap();
        assert!(hit.front && (hit.t - 1e-6).abs() < 1e-6);
        // Culling back faces lets rays from inside escape.
        flags.iter_mut().for_each(|f| *f = CULL_BACK);
        let culled = Bvh::build(&prims(&tris), &flags);
        let inside = Ray::new(Vec3::splat(0.5), Vec3::Y);
        assert!(culled.intersect(&inside, |_, _| true).is_none());
        assert!(bvh.occluded(&inside, |_, _| true));
        let short = Ray {
            tmax: 0.49,
            ..inside
        };
        assert!(!bvh.occluded(&short, |_, _| true));
    }
}
