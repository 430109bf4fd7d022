//! Geometry in render space: triangles, the BVH over them (an obvhs compressed wide BVH8),
//! and the two ray queries the integrator needs: closest hit and occlusion.

pub mod frame;
pub mod instances;
pub mod quadric;
pub mod ray;
pub mod sphere;
pub mod triangle;

use glam::{UVec2, Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    cwbvh::{CwBvh, builder::build_cwbvh, node::CwBvhNode},
    faststack::FastStack,
    traverse,
};
use ray::Ray;
use triangle::RayShear;

/// A primitive the BVH holds.
#[derive(Clone, Copy, Debug)]
pub enum Primitive {
    /// A triangle, counter-clockwise from its front.
    Triangle([Vec3; 3]),
    /// A sphere; its front is the outside.
    Sphere { centre: Vec3, radius: f32 },
    /// A disk (front towards its normal) or an open cylinder (front outside).
    Quadric(quadric::Quadric),
}

impl Primitive {
    fn aabb(&self) -> Aabb {
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

/// A primitive's intersection with a ray, before the caller's filter.
#[derive(Clone, Copy, Debug)]
pub struct PrimitiveHit {
    pub t: f32,
    /// Barycentric weights of triangle vertices 1 and 2 (vertex 0 has `1 - b1 - b2`); 0 for
    /// the analytic shapes.
    pub b1: f32,
    pub b2: f32,
    /// True when the ray arrives on the primitive's front (a triangle's counter-clockwise
    /// side, a sphere's outside).
    pub front: bool,
}

/// Intersection flag: the primitive is invisible from its back (glTF `doubleSided: false`).
pub const CULL_BACK: u8 = 1;
/// Intersection flag: the primitive's material has an alpha cut-out; the caller's filter
/// decides whether a hit counts.
pub const ALPHA_TESTED: u8 = 2;

/// A ray's closest accepted hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    /// Index of the primitive in the order given to [`Bvh::build`] (of the shared BVH for
    /// a placed hit).
    pub prim: u32,
    pub b1: f32,
    pub b2: f32,
    pub front: bool,
    /// The placement hit in an [`instances::InstancedBvh`], or [`NOT_PLACED`].
    pub instance: u32,
}

/// [`Hit::instance`] of a hit on geometry that is not placed through a shared BVH.
pub const NOT_PLACED: u32 = u32::MAX;

/// A BVH over primitives with per-primitive flags, answering closest-hit and occlusion
/// queries.
pub struct Bvh {
    bvh: CwBvh,
    /// Primitives in BVH leaf order, so leaves read them without indirection.
    prims: Vec<Primitive>,
    flags: Vec<u8>,
    /// BVH leaf order to input order.
    order: Vec<u32>,
}

/// Slab-test constants of a ray for wide-node traversal.
struct NodeRay {
    origin: Vec3A,
    inv_dir: Vec3A,
    negative: [bool; 3],
    tmax: f32,
}

/// Relative error bound of the slab test's three float operations (pbrt's 1 + 2γ₃): the
/// far distance is enlarged by it so rounding never culls a box the ray touches.
const SLAB_ROBUSTNESS: f32 =
    1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

impl NodeRay {
    fn new(ray: &Ray) -> Self {
        // A finite reciprocal keeps 0 * inf = NaN out of the slab test.
        let inv = |d: f32| {
            if d.abs() < 1e-20 {
                1e20f32.copysign(d)
            } else {
                1.0 / d
            }
        };
        let inv_dir = Vec3A::new(inv(ray.dir.x), inv(ray.dir.y), inv(ray.dir.z));
        Self {
            origin: ray.origin.into(),
            inv_dir,
            // From the reciprocal's sign, so that -0.0 components pick near and far planes
            // consistently with it.
            negative: [inv_dir.x < 0.0, inv_dir.y < 0.0, inv_dir.z < 0.0],
            tmax: ray.tmax,
        }
    }
}

/// Which of a node's eight children the ray overlaps, as the hit mask obvhs's traversal
/// expects. Unlike obvhs's own node test, which clamps the near distance to an absolute 1e-4,
/// this one accepts boxes from t = 0: rays leave surfaces at tiny offsets and must still see
/// a wall right next to them.
#[inline(always)]
fn intersect_node(node: &CwBvhNode, ray: &NodeRay, oct_inv4: u32) -> u32 {
    let scale = node.compute_extent() * ray.inv_dir;
    let offset = (Vec3A::from(node.p) - ray.origin) * ray.inv_dir;
    let pick = |neg: bool, lo: &[u8; 8], hi: &[u8; 8]| if neg { (*hi, *lo) } else { (*lo, *hi) };
    let (near_x, far_x) = pick(ray.negative[0], &node.child_min_x, &node.child_max_x);
    let (near_y, far_y) = pick(ray.negative[1], &node.child_min_y, &node.child_max_y);
    let (near_z, far_z) = pick(ray.negative[2], &node.child_min_z, &node.child_max_z);
    let mut overlaps = [false; 8];
    for c in 0..8 {
        let t0 = (near_x[c] as f32 * scale.x + offset.x)
            .max(near_y[c] as f32 * scale.y + offset.y)
            .max(near_z[c] as f32 * scale.z + offset.z)
            .max(0.0);
        let t1 = (far_x[c] as f32 * scale.x + offset.x)
            .min(far_y[c] as f32 * scale.y + offset.y)
            .min(far_z[c] as f32 * scale.z + offset.z)
            * SLAB_ROBUSTNESS;
        overlaps[c] = t0 <= t1.min(ray.tmax);
    }
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let mut hit_mask = 0u32;
    for (c, &hit) in overlaps.iter().enumerate() {
        if hit {
            let child_bits = (child_bits8 >> (c * 8)) as u32 & 0xff;
            let bit_index = (bit_index8 >> (c * 8)) as u32 & 0xff;
            hit_mask |= child_bits << bit_index;
        }
    }
    hit_mask
}

/// Builds obvhs's wide BVH over `aabbs` (not empty).
fn build_wide_bvh(aabbs: &[Aabb]) -> CwBvh {
    build_cwbvh(
        aabbs,
        BvhBuildParams::medium_build(),
        &mut std::time::Duration::default(),
    )
}

/// Node groups the traversal stack keeps inline: a BVH8 of any sensible scene is far
/// shallower.
const INLINE_STACK: usize = 32;

/// The traversal stack. obvhs's own holds 32 node groups and, when full, overwrites its top
/// one, losing geometry; a BVH can be deeper than that (PLOC chains thousands of coincident
/// instances, corrupt vertex data spans every float exponent). This one spills into a heap
/// vector past its inline entries, which only such BVHs ever allocate.
struct TraversalStack {
    inline: [UVec2; INLINE_STACK],
    len: usize,
    spill: Vec<UVec2>,
}

impl FastStack<UVec2> for TraversalStack {
    #[inline(always)]
    fn push(&mut self, v: UVec2) {
        if self.len < INLINE_STACK {
            self.inline[self.len] = v;
            self.len += 1;
        } else {
            #[cfg(test)]
            SPILLED.store(true, std::sync::atomic::Ordering::Relaxed);
            self.spill.push(v);
        }
    }
    #[inline(always)]
    fn pop_fast(&mut self) -> UVec2 {
        self.pop().unwrap_or_default()
    }
    #[inline(always)]
    fn pop(&mut self) -> Option<UVec2> {
        if let Some(v) = self.spill.pop() {
            return Some(v);
        }
        self.len = self.len.checked_sub(1)?;
        Some(self.inline[self.len])
    }
    #[inline(always)]
    fn len(&self) -> usize {
        self.len + self.spill.len()
    }
    #[inline(always)]
    fn is_empty(&self) -> bool {
        self.len == 0
    }
    #[inline(always)]
    fn clear(&mut self) {
        self.len = 0;
        self.spill.clear();
    }
}

/// Set when a traversal stack spills (tests check that deep cases reach the spill).
#[cfg(test)]
static SPILLED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Traversal state with the fields obvhs's `traverse!` macro uses, over a
/// [`TraversalStack`].
struct Traversal {
    stack: TraversalStack,
    current_group: UVec2,
    primitive_group: UVec2,
    oct_inv4: u32,
    primitive_id: u32,
    hitmask: u32,
}

impl Traversal {
    /// The state at the root of `bvh` for rays along `dir`.
    #[inline(always)]
    fn new(bvh: &CwBvh, dir: Vec3) -> Self {
        let start = bvh.new_traversal(Vec3A::from(dir));
        Self {
            stack: TraversalStack {
                inline: [UVec2::ZERO; INLINE_STACK],
                len: 0,
                spill: Vec::new(),
            },
            current_group: start.current_group,
            primitive_group: start.primitive_group,
            oct_inv4: start.oct_inv4,
            primitive_id: 0,
            hitmask: 0,
        }
    }
}

impl Bvh {
    /// Builds the BVH over `prims` (render space) with their intersection `flags`. Runs on
    /// the current rayon pool.
    pub fn build(prims: &[Primitive], flags: &[u8]) -> Self {
        assert_eq!(prims.len(), flags.len());
        if prims.is_empty() {
            return Self {
                bvh: CwBvh::default(),
                prims: Vec::new(),
                flags: Vec::new(),
                order: Vec::new(),
            };
        }
        let aabbs: Vec<Aabb> = prims.iter().map(Primitive::aabb).collect();
        let mut bvh = build_wide_bvh(&aabbs);
        drop(aabbs);
        // Leaves index `prims` directly; the BVH's own copy of the order is not needed.
        let order = std::mem::take(&mut bvh.primitive_indices);
        Self {
            prims: order.iter().map(|&i| prims[i as usize]).collect(),
            flags: order.iter().map(|&i| flags[i as usize]).collect(),
            order,
            bvh,
        }
    }

    /// Bytes the structure holds: wide nodes, and per primitive its data, flags and index.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.bvh.nodes.len() * size_of::<CwBvhNode>()
            + self.prims.len() * (size_of::<Primitive>() + size_of::<u8>() + size_of::<u32>())
    }

    /// Tests one leaf primitive; `accept` is consulted only for alpha-tested ones.
    #[inline(always)]
    fn test<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        leaf: usize,
        ray: &Ray,
        shear: &RayShear,
        tmax: f32,
        accept: &mut F,
    ) -> Option<PrimitiveHit> {
        let hit = match self.prims[leaf] {
            Primitive::Triangle([p0, p1, p2]) => triangle::intersect(shear, p0, p1, p2, tmax)?,
            Primitive::Sphere { centre, radius } => sphere::intersect(ray, centre, radius, tmax)?,
            Primitive::Quadric(q) => q.intersect(ray, tmax)?,
        };
        let flags = self.flags[leaf];
        if flags != 0 {
            if flags & CULL_BACK != 0 && !hit.front {
                return None;
            }
            if flags & ALPHA_TESTED != 0 && !accept(self.order[leaf], &hit) {
                return None;
            }
        }
        Some(hit)
    }

    /// Closest hit along `ray` in `(0, ray.tmax)`. `accept(prim, hit)` filters hits on
    /// alpha-tested triangles.
    pub fn intersect<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        ray: &Ray,
        mut accept: F,
    ) -> Option<Hit> {
        if self.bvh.nodes.is_empty() {
            return None;
        }
        let shear = RayShear::new(ray);
        let mut node_ray = NodeRay::new(ray);
        let mut best: Option<(usize, PrimitiveHit)> = None;
        let mut state = Traversal::new(&self.bvh, ray.dir);
        let mut node;
        traverse!(
            self.bvh,
            node,
            state,
            intersect_node(node, &node_ray, state.oct_inv4),
            {
                let leaf = state.primitive_id as usize;
                if let Some(hit) = self.test(leaf, ray, &shear, node_ray.tmax, &mut accept) {
                    node_ray.tmax = hit.t;
                    best = Some((leaf, hit));
                }
            }
        );
        best.map(|(leaf, h)| Hit {
            t: h.t,
            prim: self.order[leaf],
            b1: h.b1,
            b2: h.b2,
            front: h.front,
            instance: NOT_PLACED,
        })
    }

    /// True if anything accepted lies along `ray` in `(0, ray.tmax)`; stops at the first hit.
    pub fn occluded<F: FnMut(u32, &PrimitiveHit) -> bool>(&self, ray: &Ray, mut accept: F) -> bool {
        if self.bvh.nodes.is_empty() {
            return false;
        }
        let shear = RayShear::new(ray);
        let node_ray = NodeRay::new(ray);
        let mut state = Traversal::new(&self.bvh, ray.dir);
        let mut node;
        let mut occluded = false;
        'search: {
            traverse!(
                self.bvh,
                node,
                state,
                intersect_node(node, &node_ray, state.oct_inv4),
                {
                    let leaf = state.primitive_id as usize;
                    if self
                        .test(leaf, ray, &shear, ray.tmax, &mut accept)
                        .is_some()
                    {
                        occluded = true;
                        break 'search;
                    }
                }
            );
        }
        occluded
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    pub(super) fn cube() -> Vec<[Vec3; 3]> {
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
                .filter_map(|t| triangle::intersect(&shear, t[0], t[1], t[2], f32::INFINITY))
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
        SPILLED.store(false, std::sync::atomic::Ordering::Relaxed);
        let ray = Ray::new(Vec3::new(-1.0, 0.0, 0.0), Vec3::X);
        let shear = RayShear::new(&ray);
        let mut found = 0;
        for first in -120..120 {
            let accepted = |prim: u32| prim / PER_SCALE >= (first + 120) as u32;
            let best = (0..tris.len() as u32)
                .filter(|&p| accepted(p))
                .filter_map(|p| {
                    let t = tris[p as usize];
                    triangle::intersect(&shear, t[0], t[1], t[2], f32::INFINITY)
                })
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
            SPILLED.load(std::sync::atomic::Ordering::Relaxed),
            "never spilled"
        );
    }

    /// The stack stays last-in first-out past its inline entries.
    #[test]
    fn traversal_stack_spills_in_order() {
        let mut stack = Traversal::new(&CwBvh::default(), Vec3::X).stack;
        for round in 0..2 {
            for i in 0..3 * INLINE_STACK as u32 {
                stack.push(UVec2::new(i, round));
            }
            assert_eq!(stack.len(), 3 * INLINE_STACK);
            for i in (0..3 * INLINE_STACK as u32).rev() {
                assert_eq!(stack.pop(), Some(UVec2::new(i, round)));
            }
            assert!(stack.is_empty() && stack.pop().is_none());
        }
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
