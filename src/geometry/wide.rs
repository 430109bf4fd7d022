//! A four-wide BVH laid out for SIMD traversal on the CPU. obvhs builds a binary BVH (PLOC,
//! reinsertion, SAH leaf collapse); its nodes are then merged four children to a node
//! (Wald et al. 2008, "Getting Rid of Packets"), each node holding its children's boxes as
//! six 4-lane vectors, so one slab test of four lanes decides all four children. Closest-hit
//! traversal visits the hit children nearest first and skips stacked nodes farther than the
//! closest hit so far, as Embree's single-ray kernels do. The packet kernel's queries take
//! eight rays through the same nodes at once ([`WideBvh::traverse_lanes`]).
//!
//! The structure knows only leaves: what a leaf holds (triangles, placements) is the
//! caller's, tested by a closure. As built, a leaf is a range of [`WideBvh::order`]; the
//! caller may relabel each leaf with its own index and count (see
//! [`WideBvh::relabel_leaves`]).

use super::ray::Ray;
#[cfg(target_arch = "x86_64")]
use super::triangle::Lanes;
#[cfg(target_arch = "x86_64")]
use crate::simd::{F8, LANES, M8, U8, V3};
use glam::{Vec3, Vec3A, Vec4};
use obvhs::{BvhBuildParams, aabb::Aabb, bvh2::builder::build_bvh2};
use std::mem::MaybeUninit;

/// A node's child: an inner node, or a leaf of `count` primitives from `index` in leaf order
/// (or as the caller relabelled it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Child {
    /// Node index (inner) or the leaf's index.
    index: u32,
    /// The leaf's count (never 0); 0 for an inner node.
    count: u32,
}

/// No child: the root of an empty BVH.
const NO_CHILD: Child = Child {
    index: u32::MAX,
    count: 0,
};

/// Four children's boxes, `bounds[axis]` the lower planes and `bounds[3 + axis]` the upper,
/// one lane a child. Unused lanes hold a box at infinity (both planes +inf): the slab
/// test orders each axis's two distances by min and max, so an inverted empty box
/// (+inf, -inf) would span every axis, but this one is entered at +inf or left at -inf.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node {
    bounds: [Vec4; 6],
    children: [Child; 4],
}

/// Relative error bound of the slab test's three float operations (pbrt's 1 + 2γ₃): the
/// far distance is enlarged by it so rounding never culls a box the ray touches.
const SLAB_ROBUSTNESS: f32 =
    1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// A ray's slab-test constants, broadcast to four lanes.
struct NodeRay {
    origin: [Vec4; 3],
    inv_dir: [Vec4; 3],
}

/// The reciprocal direction the slab test multiplies by: finite, so that 0 * inf = NaN
/// stays out of the test.
#[inline(always)]
fn slab_inv_dir(dir: Vec3) -> Vec3A {
    let d = Vec3A::from(dir);
    let tiny = d.abs().cmplt(Vec3A::splat(1e-20));
    Vec3A::select(tiny, Vec3A::splat(1e20).copysign(d), d.recip())
}

impl NodeRay {
    #[inline(always)]
    fn new(ray: &Ray) -> Self {
        let inv = slab_inv_dir(ray.dir);
        let o = ray.origin;
        Self {
            origin: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            inv_dir: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
        }
    }

    /// Entry distances of the four children and the mask of those the ray overlaps within
    /// `[0, tmax]`. Boxes are accepted from t = 0: rays leave surfaces at tiny offsets and
    /// must still see a wall right next to them.
    #[inline(always)]
    fn test(&self, node: &Node, tmax: f32) -> (Vec4, u32) {
        let b = &node.bounds;
        let t = |plane: usize, a: usize| (b[plane] - self.origin[a]) * self.inv_dir[a];
        let (x0, x1) = (t(0, 0), t(3, 0));
        let (y0, y1) = (t(1, 1), t(4, 1));
        let (z0, z1) = (t(2, 2), t(5, 2));
        let near = x0.min(x1).max(y0.min(y1)).max(z0.min(z1)).max(Vec4::ZERO);
        let far = x0.max(x1).min(y0.max(y1)).min(z0.max(z1)) * SLAB_ROBUSTNESS;
        // A finite bound: a lane at infinity is entered at +inf, beyond every bound.
        let far = far.min(Vec4::splat(tmax.min(f32::MAX)));
        (near, near.cmple(far).bitmask())
    }
}

/// A stacked subtree and the distance at which the ray enters its box.
#[derive(Clone, Copy, Debug)]
struct Entry {
    child: Child,
    t: f32,
}

/// Entries the traversal stack keeps inline: a four-wide BVH of any sensible scene needs
/// far fewer (three per level).
const INLINE_STACK: usize = 64;

/// The traversal stack: inline entries that spill into a heap vector, which only degenerate
/// BVHs ever allocate (PLOC chains thousands of coincident instances; corrupt vertex data
/// spans every float exponent).
struct Stack<E> {
    /// Entries below `len` are initialised; left uninitialised above, so that starting a
    /// ray costs nothing.
    inline: [MaybeUninit<E>; INLINE_STACK],
    len: usize,
    spill: Vec<E>,
}

impl<E: Copy> Stack<E> {
    #[inline(always)]
    fn new() -> Self {
        Self {
            inline: [const { MaybeUninit::uninit() }; INLINE_STACK],
            len: 0,
            spill: Vec::new(),
        }
    }

    #[inline(always)]
    fn push(&mut self, e: E) {
        if self.len < INLINE_STACK {
            self.inline[self.len] = MaybeUninit::new(e);
            self.len += 1;
        } else {
            #[cfg(test)]
            SPILLED.store(true, std::sync::atomic::Ordering::Relaxed);
            self.spill.push(e);
        }
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<E> {
        if let Some(e) = self.spill.pop() {
            return Some(e);
        }
        self.len = self.len.checked_sub(1)?;
        // SAFETY: `push` initialised every entry below the old `len`.
        Some(unsafe { self.inline[self.len].assume_init() })
    }
}

/// Set when a traversal stack spills (tests check that deep cases reach the spill).
#[cfg(test)]
pub(super) static SPILLED: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// What a leaf test tells the traversal.
pub enum LeafResult {
    /// Nothing closer than the current bound.
    Miss,
    /// A closer hit: the ray's bound shrinks to this distance.
    Closer(f32),
    /// Traversal ends (an occlusion query found something).
    Stop,
}

/// A subtree of a [`WideBvh`], where a single-ray traversal starts: the root, or where a
/// packet traversal hands a lane over ([`LaneVisitor::single`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Subtree(Child);

/// A four-wide BVH over primitives given by their boxes.
pub struct WideBvh {
    nodes: Vec<Node>,
    root: Child,
    /// Leaf order to the input order: leaf ranges index this.
    pub order: Vec<u32>,
}

impl WideBvh {
    /// Builds the BVH over `aabbs` (render space; may be empty) with leaves of up to
    /// `max_leaf` primitives, where the surface area heuristic prefers them with a node
    /// visit costing `node_cost` leaf primitive tests. Runs on the current rayon pool.
    pub fn build(aabbs: &[Aabb], max_leaf: u32, node_cost: f32) -> Self {
        if aabbs.is_empty() {
            return Self {
                nodes: Vec::new(),
                root: NO_CHILD,
                order: Vec::new(),
            };
        }
        let mut bvh2 = build_bvh2(
            aabbs,
            build_params(max_leaf, node_cost),
            &mut std::time::Duration::default(),
        );
        let order = std::mem::take(&mut bvh2.primitive_indices);
        let (nodes, root) = collapse(&bvh2.nodes);
        Self { nodes, root, order }
    }

    /// Gives every leaf the caller's label: `label(index, count)` of the leaf as built (a
    /// range of [`WideBvh::order`]) returns the `(index, count)` that
    /// [`WideBvh::traverse`] passes for it from then on; the count must not be 0. Leaves are
    /// visited once each, in node order.
    pub fn relabel_leaves(&mut self, mut label: impl FnMut(u32, u32) -> (u32, u32)) {
        let mut relabel = |child: &mut Child| {
            if child.count != 0 {
                (child.index, child.count) = label(child.index, child.count);
                assert_ne!(child.count, 0, "a leaf's count must not be 0");
            }
        };
        relabel(&mut self.root);
        for node in &mut self.nodes {
            node.children.iter_mut().for_each(&mut relabel);
        }
    }

    /// Bytes the nodes and the order hold.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node>() + self.order.len() * 4
    }

    /// Visits the leaves `ray` overlaps in `(0, tmax)`, nearest box first, calling
    /// `leaf(index, count, bound)` with the leaf's label (as built, its range in
    /// [`WideBvh::order`]) and the current bound; a closer hit shrinks the bound and prunes
    /// the boxes beyond it. Returns the final bound. Occlusion queries take the same order:
    /// on the million-triangle sphere field, node order traced shadow rays 8-15 % slower (it
    /// saved 4 % of the Cornell box's occlusion instructions).
    #[inline(always)]
    pub fn traverse<F: FnMut(u32, u32, f32) -> LeafResult>(&self, ray: &Ray, leaf: F) -> f32 {
        self.traverse_from(self.root(), ray, ray.tmax, leaf)
    }

    /// The whole BVH as a subtree, for [`WideBvh::traverse_from`].
    #[inline(always)]
    pub(crate) fn root(&self) -> Subtree {
        Subtree(self.root)
    }

    /// [`WideBvh::traverse`] of `subtree` alone, from the bound `tmax`.
    #[inline(always)]
    pub(crate) fn traverse_from<F: FnMut(u32, u32, f32) -> LeafResult>(
        &self,
        subtree: Subtree,
        ray: &Ray,
        mut tmax: f32,
        mut leaf: F,
    ) -> f32 {
        // A ray with NaN or infinity (an instance transform of corrupt data makes one)
        // would pass every slab test, the empty lanes' too: it hits nothing.
        if subtree.0 == NO_CHILD || !(ray.origin.is_finite() && ray.dir.is_finite()) {
            return tmax;
        }
        let node_ray = NodeRay::new(ray);
        let mut stack = Stack::new();
        let mut current = subtree.0;
        loop {
            if current.count == 0 {
                let node = &self.nodes[current.index as usize];
                let (near, mut mask) = node_ray.test(node, tmax);
                if mask != 0 {
                    let near = near.to_array();
                    let first = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    if mask == 0 {
                        current = node.children[first];
                        continue;
                    }
                    // Two to four children: push all but the nearest, farthest deepest.
                    let mut hits = [Entry {
                        child: NO_CHILD,
                        t: 0.0,
                    }; 4];
                    hits[0] = Entry {
                        child: node.children[first],
                        t: near[first],
                    };
                    let mut n = 1;
                    while mask != 0 {
                        let c = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let e = Entry {
                            child: node.children[c],
                            t: near[c],
                        };
                        // Insertion into descending order of distance.
                        let mut k = n;
                        while k > 0 && hits[k - 1].t < e.t {
                            hits[k] = hits[k - 1];
                            k -= 1;
                        }
                        hits[k] = e;
                        n += 1;
                    }
                    for e in &hits[..n - 1] {
                        stack.push(*e);
                    }
                    current = hits[n - 1].child;
                    continue;
                }
            } else {
                match leaf(current.index, current.count, tmax) {
                    LeafResult::Miss => {}
                    LeafResult::Closer(t) => tmax = t,
                    LeafResult::Stop => return tmax,
                }
            }
            // Next: the nearest stacked subtree still in front of the closest hit.
            loop {
                let Some(e) = stack.pop() else {
                    return tmax;
                };
                if e.t <= tmax {
                    current = e.child;
                    break;
                }
            }
        }
    }
}

/// Below this many lanes in an inner node, a packet traversal hands each of them to the
/// single-ray traversal. Chosen over 1 (never), 2, 3 and 4: the Cornell box's instructions
/// are the same from 2 to 4, and on the flattened million-triangle sphere field handing
/// over below 3 traces incoherent shadow rays in packets 1.14x faster than one by one,
/// never below 1 traced them 0.83x as fast (`cargo bench --bench throughput`).
#[cfg(target_arch = "x86_64")]
const PACKET_MIN_LANES: u32 = 3;

/// What a packet traversal ([`WideBvh::traverse_lanes`]) asks of its caller.
#[cfg(target_arch = "x86_64")]
pub(crate) trait LaneVisitor {
    /// Each lane's bound: boxes entered beyond it are skipped, and a negative bound ends
    /// the lane (an idle lane, or an occlusion query answered).
    fn bounds(&self) -> F8;
    /// Tests the leaf labelled `(index, count)` for the `active` lanes, lowering their
    /// bounds on closer hits.
    fn leaf(&mut self, index: u32, count: u32, active: u32);
    /// Traverses `subtree` with lane `lane` alone (the single-ray traversal).
    fn single(&mut self, subtree: Subtree, lane: usize);
}

/// Eight rays' slab-test constants, one a lane.
#[cfg(target_arch = "x86_64")]
pub(crate) struct LaneRays {
    origin: [F8; 3],
    inv_dir: [F8; 3],
}

#[cfg(target_arch = "x86_64")]
impl LaneRays {
    /// The constants of the rays from `origin` along `dir` (one a lane), each lane's as
    /// [`NodeRay`] takes them (`slab_inv_dir`'s operations in lanes).
    #[inline(always)]
    pub(crate) fn new(origin: V3, dir: V3) -> Self {
        let mut inv_dir = [dir.x, dir.y, dir.z];
        for d in &mut inv_dir {
            let tiny = d.abs().lt(F8::splat(1e-20));
            let sign = d.to_bits() & U8::splat(0x8000_0000);
            let huge = F8::from_bits(sign | F8::splat(1e20).to_bits());
            *d = F8::select(tiny, huge, F8::ONE / *d);
        }
        Self {
            origin: [origin.x, origin.y, origin.z],
            inv_dir,
        }
    }

    /// Entry distances of the lanes into child `c` of `node`, and the lanes that overlap it
    /// within `[0, tmax]`: [`NodeRay::test`]'s operations, lane by lane (`tmax` finite).
    #[inline(always)]
    fn test(&self, node: &Node, c: usize, tmax: F8) -> (F8, M8) {
        // Planes read as arrays (a vector's index is a match, compiled to a jump table), and
        // no closure over vectors (it would compile outside the packet kernel's AVX2 context).
        let mut planes = [0.0; 6];
        for (plane, bounds) in planes.iter_mut().zip(&node.bounds) {
            *plane = AsRef::<[f32; 4]>::as_ref(bounds)[c];
        }
        let (o, inv) = (&self.origin, &self.inv_dir);
        let (x0, x1) = (
            (F8::splat(planes[0]) - o[0]) * inv[0],
            (F8::splat(planes[3]) - o[0]) * inv[0],
        );
        let (y0, y1) = (
            (F8::splat(planes[1]) - o[1]) * inv[1],
            (F8::splat(planes[4]) - o[1]) * inv[1],
        );
        let (z0, z1) = (
            (F8::splat(planes[2]) - o[2]) * inv[2],
            (F8::splat(planes[5]) - o[2]) * inv[2],
        );
        let near = x0.min(x1).max(y0.min(y1)).max(z0.min(z1)).max(F8::ZERO);
        let far = x0.max(x1).min(y0.max(y1)).min(z0.max(z1)) * SLAB_ROBUSTNESS;
        (near, near.le(far.min(tmax)))
    }
}

/// A subtree on a packet traversal's stack, with the lanes' distances to its box (+inf
/// for lanes that miss it).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
struct LaneEntry {
    child: Child,
    near: F8,
}

#[cfg(target_arch = "x86_64")]
impl WideBvh {
    /// Visits the leaves that eight rays overlap, the rays as one packet (Wald et al. 2001,
    /// "Interactive Rendering with Coherent Ray Tracing", on four-wide nodes): a node's four
    /// boxes are tested against the eight lanes at once, and its hit children are taken
    /// nearest first by the least lane distance. An inner node that fewer than
    /// [`PACKET_MIN_LANES`] lanes enter goes to the single-ray traversal lane by lane
    /// (Benthin et al. 2012, "Combining Single and Packet-Ray Tracing for Arbitrary Ray
    /// Distributions"), so that lanes which part ways do not pay for each other's nodes.
    ///
    /// Each lane meets the boxes of [`WideBvh::traverse`] with the same test and culls them
    /// by its own bound, so it finds the hits a single-ray traversal finds; only the order
    /// of its leaves differs. Runs only inside the packet kernel (AVX2 and FMA; see
    /// `crate::simd`).
    #[inline(always)]
    pub(crate) fn traverse_lanes<V: LaneVisitor>(&self, rays: &LaneRays, visitor: &mut V) {
        if self.root == NO_CHILD {
            return;
        }
        // A finite bound, as `NodeRay::test` takes it; negative lanes stay negative.
        let finite = F8::splat(f32::MAX);
        let mut tmax = visitor.bounds().min(finite);
        let mut stack = Stack::<LaneEntry>::new();
        let mut current = LaneEntry {
            child: self.root,
            near: F8::ZERO,
        };
        loop {
            let active = current.near.le(tmax).bits();
            if active != 0 {
                let inner = current.child.count == 0;
                if inner && active.count_ones() < PACKET_MIN_LANES {
                    for lane in Lanes::new(active) {
                        visitor.single(Subtree(current.child), lane);
                    }
                    tmax = visitor.bounds().min(finite);
                    if tmax.lt(F8::ZERO).bits() == (1 << LANES) - 1 {
                        return;
                    }
                } else if inner {
                    let node = &self.nodes[current.child.index as usize];
                    let lanes = M8::from_bits(active);
                    // Hit children in descending order of their nearest lane's distance.
                    let mut hits = [current; 4];
                    let mut keys = [0.0f32; 4];
                    let mut n = 0;
                    for c in 0..4 {
                        let child = node.children[c];
                        if child == NO_CHILD {
                            break;
                        }
                        let (near, hit) = rays.test(node, c, tmax);
                        let hit = hit & lanes;
                        if hit.bits() == 0 {
                            continue;
                        }
                        let near = F8::select(hit, near, F8::splat(f32::INFINITY));
                        let key = near.reduce_min();
                        let mut k = n;
                        while k > 0 && keys[k - 1] < key {
                            (hits[k], keys[k]) = (hits[k - 1], keys[k - 1]);
                            k -= 1;
                        }
                        (hits[k], keys[k]) = (LaneEntry { child, near }, key);
                        n += 1;
                    }
                    if n > 0 {
                        for e in &hits[..n - 1] {
                            stack.push(*e);
                        }
                        current = hits[n - 1];
                        continue;
                    }
                } else {
                    visitor.leaf(current.child.index, current.child.count, active);
                    tmax = visitor.bounds().min(finite);
                    if tmax.lt(F8::ZERO).bits() == (1 << LANES) - 1 {
                        return;
                    }
                }
            }
            match stack.pop() {
                Some(e) => current = e,
                None => return,
            }
        }
    }
}

/// obvhs's build: PLOC with medium search, reinsertion, and leaves of up to `max_leaf`
/// primitives where the surface area heuristic (a node visit costing `node_cost` primitive
/// tests) prefers them.
fn build_params(max_leaf: u32, node_cost: f32) -> BvhBuildParams {
    BvhBuildParams {
        max_prims_per_leaf: max_leaf,
        collapse_traversal_cost: node_cost,
        ..BvhBuildParams::medium_build()
    }
}

/// Merges a binary BVH (obvhs's: an inner node's children are at `first_index` and
/// `first_index + 1`) into four-wide nodes: each node takes the binary node's children and
/// keeps opening its largest inner child until it has four. Returns the nodes and the root.
fn collapse(bvh2: &[obvhs::bvh2::node::Bvh2Node]) -> (Vec<Node>, Child) {
    let as_child = |i: usize| Child {
        index: bvh2[i].first_index,
        count: bvh2[i].prim_count,
    };
    if bvh2[0].is_leaf() {
        return (Vec::new(), as_child(0));
    }
    let empty = Node {
        bounds: [
            Vec4::INFINITY,
            Vec4::INFINITY,
            Vec4::INFINITY,
            Vec4::INFINITY,
            Vec4::INFINITY,
            Vec4::INFINITY,
        ],
        children: [NO_CHILD; 4],
    };
    let mut nodes = vec![empty];
    // (binary inner node, wide node it becomes); an explicit stack: a degenerate binary BVH
    // can be as deep as it has primitives.
    let mut work = vec![(0usize, 0usize)];
    while let Some((inner, wide)) = work.pop() {
        let left = bvh2[inner].first_index as usize;
        let mut group = [left, left + 1, 0, 0];
        let mut len = 2;
        while len < 4 {
            let largest = group[..len]
                .iter()
                .enumerate()
                .filter(|&(_, &c)| !bvh2[c].is_leaf())
                .max_by(|a, b| {
                    let area = |c: usize| bvh2[c].aabb().half_area();
                    area(*a.1).total_cmp(&area(*b.1))
                });
            let Some((slot, &open)) = largest else { break };
            let first = bvh2[open].first_index as usize;
            group[slot] = first;
            group[len] = first + 1;
            len += 1;
        }
        let mut node = empty;
        for (lane, &c) in group[..len].iter().enumerate() {
            let aabb = bvh2[c].aabb();
            let (lo, hi) = (Vec3::from(aabb.min), Vec3::from(aabb.max));
            for axis in 0..3 {
                node.bounds[axis][lane] = lo[axis];
                node.bounds[3 + axis][lane] = hi[axis];
            }
            node.children[lane] = if bvh2[c].is_leaf() {
                as_child(c)
            } else {
                nodes.push(empty);
                work.push((c, nodes.len() - 1));
                Child {
                    index: (nodes.len() - 1) as u32,
                    count: 0,
                }
            };
        }
        nodes[wide] = node;
    }
    (nodes, Child { index: 0, count: 0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stack stays last-in first-out past its inline entries.
    #[test]
    fn stack_spills_in_order() {
        let mut stack = Stack::new();
        let entry = |i: u32, round: u32| Entry {
            child: Child {
                index: i,
                count: round,
            },
            t: i as f32,
        };
        for round in 0..2 {
            for i in 0..3 * INLINE_STACK as u32 {
                stack.push(entry(i, round));
            }
            for i in (0..3 * INLINE_STACK as u32).rev() {
                assert_eq!(stack.pop().map(|e| e.child), Some(entry(i, round).child));
            }
            assert!(stack.pop().is_none());
        }
    }
}
