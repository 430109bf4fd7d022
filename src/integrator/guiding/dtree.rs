//! The directional quadtree of Practical Path Guiding (Müller, Gross and Novák 2017): a
//! piecewise-constant distribution of directions over the unit square of the equal-area
//! cylindrical mapping of the sphere (z = 2x − 1, φ = 2πy), whose nodes hold the energy
//! (incident radiance over solid angle) that paths deposited in their square. Sampling
//! descends from the root choosing children in proportion to their energy and ends uniform
//! in a leaf, so a direction's density is the leaf's share of the energy over its area.
//!
//! Nodes where much of the energy falls are refined between training passes
//! ([`DTree::refined`]), down to [`MAX_DEPTH`] levels; a node's sum is its subtree's.

use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Deepest level of a quadtree (a leaf of the deepest level spans 4⁻²⁰ of the sphere).
pub const MAX_DEPTH: u32 = 20;
/// Share of the tree's energy above which a node is subdivided (PPG's ρ).
pub const SUBDIVIDE_SHARE: f64 = 0.01;

/// One node: the energy deposited in its square (its subtree's, once summed) and its four
/// children (`children` is the index of the first, 0 for a leaf: the root is nobody's
/// child). Child `c` covers the quarter `(c & 1, c >> 1)` of the node's square.
#[derive(Clone, Copy, Debug, Default)]
struct Node {
    sum: f64,
    children: u32,
}

/// A directional quadtree.
#[derive(Clone, Debug)]
pub struct DTree {
    nodes: Vec<Node>,
}

impl Default for DTree {
    fn default() -> Self {
        Self::new()
    }
}

/// The direction of point `p` of the unit square (equal-area cylindrical mapping).
#[inline]
pub fn square_to_direction(p: Vec2) -> Vec3 {
    let z = 2.0 * p.x - 1.0;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * p.y).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// The point of the unit square of unit direction `d`.
#[inline]
pub fn direction_to_square(d: Vec3) -> Vec2 {
    let x = ((d.z.clamp(-1.0, 1.0) + 1.0) * 0.5).clamp(0.0, 1.0);
    let mut phi = atan2(d.y, d.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let y = (phi / (2.0 * PI)).clamp(0.0, 1.0);
    Vec2::new(x, y)
}

/// atan2(y, x) by Abramowitz and Stegun's polynomial 4.4.49 (error below 1e-7 rad, under
/// f32's rounding of the result), inlined: libm's call was a tenth of a guided render.
#[inline]
fn atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = (ax.min(ay), ax.max(ay));
    if !(hi > 0.0) {
        return 0.0;
    }
    let a = lo / hi;
    let s = a * a;
    let mut r = 0.002_866_225_7_f32;
    for c in [
        -0.016_165_737,
        0.042_909_614,
        -0.075_289_64,
        0.106_562_64,
        -0.142_089,
        0.199_935_51,
        -0.333_331_45,
        1.0,
    ] {
        r = r * s + c;
    }
    r *= a;
    if ay > ax {
        r = std::f32::consts::FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = PI - r;
    }
    if y < 0.0 { -r } else { r }
}

/// Solid angle of the unit square's image: densities over the square divided by this are
/// densities over the sphere.
pub const SPHERE_AREA: f32 = 4.0 * PI;

/// The child of a node that holds square point `p` (node-local coordinates in [0, 1)²),
/// and `p` in the child's coordinates.
#[inline]
fn child_of(p: Vec2) -> (usize, Vec2) {
    let (ix, iy) = (p.x >= 0.5, p.y >= 0.5);
    let q = Vec2::new(
        if ix { p.x * 2.0 - 1.0 } else { p.x * 2.0 },
        if iy { p.y * 2.0 - 1.0 } else { p.y * 2.0 },
    );
    (
        ix as usize + 2 * iy as usize,
        q.clamp(Vec2::ZERO, Vec2::splat(0.999_999_9)),
    )
}

/// The child (`ix + 2 iy`) that sample numbers `u` choose among four children of energy
/// shares `share` (summing to 1): the column (x) first, then the row (y) within it, each
/// with its own number, which is rescaled to [0, 1) for the levels below.
#[inline]
fn choose_child(u: &mut Vec2, share: [f32; 4]) -> usize {
    let p_right = share[1] + share[3];
    let ix = if u.x < 1.0 - p_right {
        u.x /= (1.0 - p_right).max(f32::MIN_POSITIVE);
        0
    } else {
        u.x = (u.x - (1.0 - p_right)) / p_right.max(f32::MIN_POSITIVE);
        1
    };
    let (low, high) = (share[ix], share[ix + 2]);
    let p_high = high / (low + high);
    let iy = if u.y < 1.0 - p_high {
        u.y /= (1.0 - p_high).max(f32::MIN_POSITIVE);
        0
    } else {
        u.y = (u.y - (1.0 - p_high)) / p_high.max(f32::MIN_POSITIVE);
        1
    };
    *u = u.clamp(Vec2::ZERO, Vec2::splat(0.999_999_9));
    ix + 2 * iy
}

/// A quadtree frozen for sampling: each inner node holds its four children's shares of its
/// energy and their indices (0 where the child is a leaf: the root is nobody's child), so
/// that a descent reads one 32-byte node a level and divides nothing. No nodes: uniform.
#[derive(Clone, Debug, Default)]
pub struct SamplingTree {
    nodes: Vec<Quad>,
    total: f64,
}

#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
struct Quad {
    share: [f32; 4],
    child: [u32; 4],
}

impl SamplingTree {
    /// The energy the tree was learned from.
    pub fn total(&self) -> f64 {
        self.total
    }

    /// A point of the unit square drawn with `u`, and its density over the square.
    #[inline]
    pub fn sample(&self, mut u: Vec2) -> Option<(Vec2, f32)> {
        if !(self.total > 0.0) {
            return None;
        }
        if self.nodes.is_empty() {
            return Some((u, 1.0));
        }
        let (mut origin, mut size, mut pdf) = (Vec2::ZERO, 1.0f32, 1.0f32);
        let mut q = 0usize;
        loop {
            let n = &self.nodes[q];
            let e = n.share;
            let c = choose_child(&mut u, e);
            if !(e[c] > 0.0) {
                return None;
            }
            pdf *= 4.0 * e[c];
            size *= 0.5;
            origin += Vec2::new((c & 1) as f32, (c >> 1) as f32) * size;
            if n.child[c] == 0 {
                break;
            }
            q = n.child[c] as usize;
        }
        Some(((origin + u * size).min(Vec2::splat(0.999_999_9)), pdf))
    }

    /// Density over the unit square of point `p` under [`SamplingTree::sample`].
    #[inline]
    pub fn pdf(&self, mut p: Vec2) -> f32 {
        if !(self.total > 0.0) {
            return 0.0;
        }
        if self.nodes.is_empty() {
            return 1.0;
        }
        let (mut pdf, mut q) = (1.0f32, 0usize);
        loop {
            let n = &self.nodes[q];
            let (c, r) = child_of(p);
            pdf *= 4.0 * n.share[c];
            if n.child[c] == 0 {
                return pdf;
            }
            q = n.child[c] as usize;
            p = r;
        }
    }
}

impl DTree {
    /// The tree frozen for sampling.
    pub fn frozen(&self) -> SamplingTree {
        let total = self.total();
        let mut out = SamplingTree {
            nodes: Vec::new(),
            total,
        };
        if self.nodes[0].children == 0 || !(total > 0.0) {
            return out;
        }
        // (node of this tree, its quad in the frozen one)
        out.nodes.push(Quad::default());
        let mut stack = vec![(0usize, 0usize)];
        while let Some((node, quad)) = stack.pop() {
            let first = self.nodes[node].children as usize;
            let sum = self.nodes[node].sum;
            for c in 0..4 {
                let child = first + c;
                out.nodes[quad].share[c] = if sum > 0.0 {
                    (self.nodes[child].sum / sum) as f32
                } else {
                    0.25
                };
                if self.nodes[child].children != 0 {
                    let q = out.nodes.len();
                    out.nodes.push(Quad::default());
                    out.nodes[quad].child[c] = q as u32;
                    stack.push((child, q));
                }
            }
        }
        out
    }

    /// A tree of one leaf with nothing deposited.
    pub fn new() -> Self {
        Self {
            nodes: vec![Node::default()],
        }
    }

    /// Energy deposited in the whole tree.
    pub fn total(&self) -> f64 {
        self.nodes[0].sum
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The leaf that holds square point `p`.
    #[inline]
    pub fn leaf_of(&self, mut p: Vec2) -> u32 {
        let mut node = 0usize;
        while self.nodes[node].children != 0 {
            let (c, q) = child_of(p);
            node = self.nodes[node].children as usize + c;
            p = q;
        }
        node as u32
    }

    /// Adds `value` to leaf `leaf`'s energy; [`DTree::sum_up`] makes the ancestors' sums
    /// agree afterwards.
    #[inline]
    pub fn add_to_leaf(&mut self, leaf: u32, value: f64) {
        self.nodes[leaf as usize].sum += value;
    }

    /// Makes every inner node's sum its children's (after deposits into leaves).
    pub fn sum_up(&mut self) {
        // Children always come after their parent: one pass from the back suffices.
        for i in (0..self.nodes.len()).rev() {
            let first = self.nodes[i].children as usize;
            if first != 0 {
                self.nodes[i].sum = (first..first + 4).map(|c| self.nodes[c].sum).sum();
            }
        }
    }

    /// A point of the unit square drawn from the tree's distribution with `u`, and its
    /// density over the square; `None` where the tree holds no energy.
    #[inline]
    pub fn sample(&self, mut u: Vec2) -> Option<(Vec2, f32)> {
        if !(self.nodes[0].sum > 0.0) {
            return None;
        }
        let mut node = 0usize;
        let (mut origin, mut size, mut pdf) = (Vec2::ZERO, 1.0f32, 1.0f32);
        while self.nodes[node].children != 0 {
            let first = self.nodes[node].children as usize;
            let total = self.nodes[node].sum;
            let share = [0, 1, 2, 3].map(|c| (self.nodes[first + c].sum / total) as f32);
            let c = choose_child(&mut u, share);
            let child = first + c;
            if !(share[c] > 0.0) {
                return None;
            }
            pdf *= 4.0 * share[c];
            size *= 0.5;
            origin += Vec2::new((c & 1) as f32, (c >> 1) as f32) * size;
            node = child;
        }
        Some(((origin + u * size).min(Vec2::splat(0.999_999_9)), pdf))
    }

    /// Density over the unit square of point `p` under [`DTree::sample`].
    #[inline]
    pub fn pdf(&self, mut p: Vec2) -> f32 {
        if !(self.nodes[0].sum > 0.0) {
            return 0.0;
        }
        let mut node = 0usize;
        let mut pdf = 1.0f32;
        while self.nodes[node].children != 0 {
            let (c, q) = child_of(p);
            let child = self.nodes[node].children as usize + c;
            let parent = self.nodes[node].sum;
            if !(parent > 0.0) {
                return 0.0;
            }
            pdf *= 4.0 * (self.nodes[child].sum / parent) as f32;
            node = child;
            p = q;
        }
        pdf
    }

    /// An empty tree whose structure follows this one's energy: nodes holding more than
    /// [`SUBDIVIDE_SHARE`] of it are subdivided (a leaf into four), the others are leaves.
    pub fn refined(&self) -> DTree {
        let total = self.total();
        let mut out = DTree::new();
        if !(total > 0.0) {
            return out;
        }
        // (old node or none, new node, depth, the old node's energy share)
        let mut stack = vec![(Some(0usize), 0usize, 0u32, 1.0f64)];
        while let Some((old, new, depth, share)) = stack.pop() {
            if !(share > SUBDIVIDE_SHARE) || depth >= MAX_DEPTH {
                continue;
            }
            let first = out.nodes.len();
            out.nodes[new].children = first as u32;
            out.nodes.extend([Node::default(); 4]);
            for c in 0..4 {
                let (old_child, child_share) = match old {
                    Some(o) if self.nodes[o].children != 0 => {
                        let oc = self.nodes[o].children as usize + c;
                        (Some(oc), self.nodes[oc].sum / total)
                    }
                    // A leaf split now: its energy spread evenly over its quarters.
                    _ => (None, share / 4.0),
                };
                stack.push((old_child, first + c, depth + 1, child_share));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::pcg::Pcg32;

    /// The mapping is a bijection and preserves area: a square's image has the solid angle
    /// of its area times 4π.
    #[test]
    fn the_mapping_round_trips() {
        let mut rng = Pcg32::new(3, 1);
        for _ in 0..1000 {
            let p = Vec2::new(rng.next_f32(), rng.next_f32());
            let d = square_to_direction(p);
            assert!((d.length() - 1.0).abs() < 1e-5);
            let q = direction_to_square(d);
            assert!((p - q).abs().max_element() < 1e-4, "{p} -> {d} -> {q}");
            let (y, x) = (rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0);
            assert!((atan2(y, x) - y.atan2(x)).abs() < 1e-6, "atan2({y}, {x})");
        }
    }

    /// A refined tree's leaves hold the energy they were given; its densities integrate to 1
    /// over the square and its samples land where the density says.
    #[test]
    fn deposits_refine_and_normalise() {
        let mut tree = DTree::new();
        let mut rng = Pcg32::new(7, 2);
        for round in 0..3 {
            let mut next = tree.refined();
            if round == 0 {
                next = DTree::new();
            }
            for _ in 0..20000 {
                // Energy concentrated near (0.8, 0.3).
                let p = Vec2::new(
                    (0.8 + 0.05 * (rng.next_f32() - 0.5)).clamp(0.0, 0.999),
                    rng.next_f32() * 0.6,
                );
                let leaf = next.leaf_of(p);
                next.add_to_leaf(leaf, 1.0 + p.y as f64);
            }
            next.sum_up();
            tree = next;
        }
        assert!(tree.node_count() > 20, "{}", tree.node_count());
        let n = 256;
        let integral: f64 = (0..n * n)
            .map(|i| {
                let p = Vec2::new(
                    ((i % n) as f32 + 0.5) / n as f32,
                    ((i / n) as f32 + 0.5) / n as f32,
                );
                tree.pdf(p) as f64
            })
            .sum::<f64>()
            / (n * n) as f64;
        assert!((integral - 1.0).abs() < 1e-3, "{integral}");
        let frozen = tree.frozen();
        for _ in 0..1000 {
            let u = Vec2::new(rng.next_f32(), rng.next_f32());
            let (p, pdf) = tree.sample(u).unwrap();
            assert!(
                (pdf - tree.pdf(p)).abs() <= 1e-3 * pdf,
                "{pdf} vs {}",
                tree.pdf(p)
            );
            let (q, frozen_pdf) = frozen.sample(u).unwrap();
            assert!((p - q).abs().max_element() < 1e-5, "{p} vs {q}");
            assert!(
                (frozen_pdf - pdf).abs() <= 1e-4 * pdf,
                "{frozen_pdf} vs {pdf}"
            );
            assert!((frozen.pdf(q) - pdf).abs() <= 1e-4 * pdf);
        }
    }
}
