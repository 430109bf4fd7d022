//! A light BVH for choosing a light in proportion to an estimate of its unoccluded
//! contribution at a shading point (Conty Estevez & Kulla 2018, "Importance Sampling of
//! Many Lights with Adaptive Tree Splitting"; the bounds and importance follow pbrt-v4's
//! BVH light sampler). Each node bounds its lights' positions, total power and emission
//! directions (a cone); sampling descends the tree choosing children in proportion to their
//! importance, so a light's probability is the product of the choices on its path, which
//! its bit trail replays for MIS.

use glam::Vec3;
use std::f32::consts::PI;

/// What the tree knows of a light or a group of lights.
#[derive(Clone, Copy, Debug)]
pub struct LightBounds {
    pub min: Vec3,
    pub max: Vec3,
    /// Emitted power (luminance).
    pub phi: f32,
    /// Axis of the cone of emission normals.
    pub w: Vec3,
    /// Cosine of the cone's half-angle (-1: every direction).
    pub cos_theta_o: f32,
    /// Cosine of the angle beyond the normals that light still leaves at (0 for diffuse
    /// emitters: 90°).
    pub cos_theta_e: f32,
    pub two_sided: bool,
}

/// cos(a - b), or 1 when a < b (the angles are clamped at 0: pbrt's cosSubClamped).
#[inline]
fn cos_sub_clamped(sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32) -> f32 {
    if cos_a > cos_b {
        1.0
    } else {
        cos_a * cos_b + sin_a * sin_b
    }
}

/// sin(a - b), or 0 when a < b.
#[inline]
fn sin_sub_clamped(sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32) -> f32 {
    if cos_a > cos_b {
        0.0
    } else {
        sin_a * cos_b - cos_a * sin_b
    }
}

#[inline]
fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}

impl LightBounds {
    fn centre(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Estimated contribution at `p` with shading normal `n` (ZERO: unknown): power over
    /// squared distance, times bounds on the emission and incidence cosines.
    pub fn importance(&self, p: Vec3, n: Vec3) -> f32 {
        let pc = self.centre();
        let diagonal = (self.max - self.min).length();
        let d2 = p.distance_squared(pc).max(diagonal / 2.0);
        let wi = (p - pc).normalize_or_zero();
        let mut cos_w = self.w.dot(wi);
        if self.two_sided {
            cos_w = cos_w.abs();
        }
        let sin_w = safe_sqrt(1.0 - cos_w * cos_w);
        // Angle the box subtends from p (its bounding sphere).
        let radius = diagonal / 2.0;
        let cos_b = if p.distance_squared(pc) < radius * radius {
            -1.0
        } else {
            safe_sqrt(1.0 - radius * radius / p.distance_squared(pc))
        };
        let sin_b = safe_sqrt(1.0 - cos_b * cos_b);
        let sin_o = safe_sqrt(1.0 - self.cos_theta_o * self.cos_theta_o);
        let cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, self.cos_theta_o);
        let sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, self.cos_theta_o);
        let cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
        if cos_p <= self.cos_theta_e {
            return 0.0;
        }
        let mut importance = self.phi * cos_p / d2;
        if n != Vec3::ZERO {
            let cos_i = wi.dot(n).abs();
            let sin_i = safe_sqrt(1.0 - cos_i * cos_i);
            importance *= cos_sub_clamped(sin_i, cos_i, sin_b, cos_b);
        }
        importance.max(0.0)
    }

    /// The bounds of two groups.
    pub fn union(&self, o: &Self) -> Self {
        if self.phi == 0.0 {
            return *o;
        }
        if o.phi == 0.0 {
            return *self;
        }
        let (w, cos_theta_o) = cone_union(self.w, self.cos_theta_o, o.w, o.cos_theta_o);
        Self {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
            phi: self.phi + o.phi,
            w,
            cos_theta_o,
            cos_theta_e: self.cos_theta_e.min(o.cos_theta_e),
            two_sided: self.two_sided || o.two_sided,
        }
    }

    /// The orientation measure of the surface-area-orientation heuristic (pbrt-v4's M_Ω).
    fn orientation_measure(&self) -> f32 {
        let theta_o = self.cos_theta_o.clamp(-1.0, 1.0).acos();
        let theta_e = self.cos_theta_e.clamp(-1.0, 1.0).acos();
        let theta_w = (theta_o + theta_e).min(PI);
        let sin_o = theta_o.sin();
        2.0 * PI * (1.0 - theta_o.cos())
            + PI / 2.0
                * (2.0 * theta_w * sin_o - (theta_o - 2.0 * theta_w).cos() - 2.0 * theta_o * sin_o
                    + theta_o.cos())
    }
}

/// The smallest cone containing two cones (axis, cos half-angle).
fn cone_union(wa: Vec3, cos_a: f32, wb: Vec3, cos_b: f32) -> (Vec3, f32) {
    let (theta_a, theta_b) = (cos_a.clamp(-1.0, 1.0).acos(), cos_b.clamp(-1.0, 1.0).acos());
    let theta_d = wa.dot(wb).clamp(-1.0, 1.0).acos();
    if (theta_d + theta_b).min(PI) <= theta_a {
        return (wa, cos_a);
    }
    if (theta_d + theta_a).min(PI) <= theta_b {
        return (wb, cos_b);
    }
    let theta_o = (theta_a + theta_d + theta_b) / 2.0;
    if theta_o >= PI {
        return (wa, -1.0);
    }
    let theta_r = theta_o - theta_a;
    let axis = wa.cross(wb);
    if axis.length_squared() < 1e-12 {
        return (wa, -1.0);
    }
    let w = glam::Quat::from_axis_angle(axis.normalize(), theta_r) * wa;
    (w, theta_o.cos())
}

#[derive(Clone, Debug)]
struct Node {
    bounds: LightBounds,
    /// Leaf: the light index; interior: index of the second child (the first follows).
    child_or_light: u32,
    leaf: bool,
}

/// The light BVH over bounded lights.
#[derive(Clone, Debug, Default)]
pub struct LightTree {
    nodes: Vec<Node>,
    /// Per light index (of the whole light list): bit trail from the root, and depth.
    trails: Vec<(u64, u8)>,
}

/// Deepest tree: a bit trail is a u64.
const MAX_DEPTH: usize = 60;
const BINS: usize = 12;

impl LightTree {
    /// A tree over `lights`: (index in the light list, bounds). `light_count` is the length
    /// of the whole light list (lights not in the tree get no trail).
    pub fn build(lights: &[(u32, LightBounds)], light_count: usize) -> Self {
        let mut tree = Self {
            nodes: Vec::with_capacity(2 * lights.len()),
            trails: vec![(0, u8::MAX); light_count],
        };
        let mut items: Vec<(u32, LightBounds)> = lights
            .iter()
            .copied()
            .filter(|(_, b)| b.phi > 0.0)
            .collect();
        if !items.is_empty() {
            tree.build_node(&mut items, 0, 0);
        }
        tree
    }

    fn build_node(
        &mut self,
        items: &mut [(u32, LightBounds)],
        trail: u64,
        depth: usize,
    ) -> LightBounds {
        if items.len() == 1 {
            let (light, bounds) = items[0];
            self.nodes.push(Node {
                bounds,
                child_or_light: light,
                leaf: true,
            });
            self.trails[light as usize] = (trail, depth as u8);
            return bounds;
        }
        let split = if depth + 1 >= MAX_DEPTH {
            items.len() / 2
        } else {
            self.choose_split(items)
        };
        let index = self.nodes.len();
        self.nodes.push(Node {
            bounds: items[0].1,
            child_or_light: 0,
            leaf: false,
        });
        let (left, right) = items.split_at_mut(split);
        let lb = self.build_node(left, trail, depth + 1);
        self.nodes[index].child_or_light = self.nodes.len() as u32;
        let rb = self.build_node(right, trail | (1 << depth), depth + 1);
        let bounds = lb.union(&rb);
        self.nodes[index].bounds = bounds;
        bounds
    }

    /// Sorts `items` along the best axis and returns where to split them, by a binned
    /// surface-area-orientation heuristic; the median when no bin split is valid.
    fn choose_split(&self, items: &mut [(u32, LightBounds)]) -> usize {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for (_, b) in items.iter() {
            lo = lo.min(b.centre());
            hi = hi.max(b.centre());
        }
        let extent = hi - lo;
        let mut best = (f32::INFINITY, 0usize, 0usize);
        for axis in 0..3 {
            if extent[axis] <= 0.0 {
                continue;
            }
            let bin_of = |b: &LightBounds| {
                (((b.centre()[axis] - lo[axis]) / extent[axis] * BINS as f32) as usize)
                    .min(BINS - 1)
            };
            let mut bins: Vec<Option<LightBounds>> = vec![None; BINS];
            let mut counts = [0usize; BINS];
            for (_, b) in items.iter() {
                let i = bin_of(b);
                bins[i] = Some(bins[i].map_or(*b, |x| x.union(b)));
                counts[i] += 1;
            }
            let cost = |b: &Option<LightBounds>| {
                b.map_or(0.0, |b| {
                    let d = b.max - b.min;
                    let area = 2.0 * (d.x * d.y + d.y * d.z + d.z * d.x);
                    b.phi * b.orientation_measure() * area.max(1e-12)
                })
            };
            for split in 1..BINS {
                let union = |r: std::ops::Range<usize>| {
                    bins[r]
                        .iter()
                        .flatten()
                        .fold(None::<LightBounds>, |acc, b| {
                            Some(acc.map_or(*b, |a| a.union(b)))
                        })
                };
                let (left, right) = (union(0..split), union(split..BINS));
                if left.is_none() || right.is_none() {
                    continue;
                }
                let c = cost(&left) + cost(&right);
                if c < best.0 {
                    best = (c, axis, counts[..split].iter().sum());
                }
            }
        }
        let axis = best.1;
        items.sort_by(|a, b| a.1.centre()[axis].total_cmp(&b.1.centre()[axis]));
        if best.0.is_finite() && best.2 > 0 && best.2 < items.len() {
            best.2
        } else {
            items.len() / 2
        }
    }

    /// True if the tree holds no light.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Chooses a light for shading point `p` (normal `n`): its index and probability.
    pub fn sample(&self, p: Vec3, n: Vec3, u: f32) -> Option<(usize, f32)> {
        let root = self.nodes.first()?;
        if root.leaf {
            return (root.bounds.importance(p, n) > 0.0)
                .then_some((root.child_or_light as usize, 1.0));
        }
        self.sample_below(0, p, n, u)
    }

    /// Chooses a light among those below node `node` (see [`LightTree::cut`]): its index
    /// and probability given the node.
    pub fn sample_below(
        &self,
        mut node: usize,
        p: Vec3,
        n: Vec3,
        mut u: f32,
    ) -> Option<(usize, f32)> {
        let mut pmf = 1.0f32;
        loop {
            let current = self.nodes.get(node)?;
            if current.leaf {
                return Some((current.child_or_light as usize, pmf));
            }
            let (a, b) = (node + 1, current.child_or_light as usize);
            let ia = self.nodes[a].bounds.importance(p, n);
            let ib = self.nodes[b].bounds.importance(p, n);
            if !(ia + ib > 0.0) {
                return None;
            }
            let pa = ia / (ia + ib);
            if u < pa {
                u = (u / pa).min(1.0 - f32::EPSILON);
                pmf *= pa;
                node = a;
            } else {
                u = ((u - pa) / (1.0 - pa)).min(1.0 - f32::EPSILON);
                pmf *= 1.0 - pa;
                node = b;
            }
        }
    }

    /// Probability that [`LightTree::sample`] picks light `light` at `p` with normal `n`.
    pub fn pmf(&self, p: Vec3, n: Vec3, light: usize) -> f32 {
        match self.nodes.first() {
            None => 0.0,
            // The root is the light's leaf: sampled whenever it matters at all.
            Some(root) if root.leaf => f32::from(
                root.child_or_light as usize == light && root.bounds.importance(p, n) > 0.0,
            ),
            Some(_) => self.pmf_below(
                TreeNode {
                    index: 0,
                    depth: 0,
                    trail: 0,
                },
                p,
                n,
                light,
            ),
        }
    }

    /// Probability that [`LightTree::sample_below`] picks light `light` below `node`; 0 for
    /// a light not below it.
    pub fn pmf_below(&self, node: TreeNode, p: Vec3, n: Vec3, light: usize) -> f32 {
        self.descend(node, node.depth as usize, p, n, light).1
    }

    /// [`LightTree::pmf`] of light `light` and, in the same descent, its
    /// [`LightTree::pmf_below`] node `node`.
    pub fn pmf_and_below(&self, node: TreeNode, p: Vec3, n: Vec3, light: usize) -> (f32, f32) {
        if self.nodes.first().is_some_and(|root| root.leaf) {
            let pmf = self.pmf(p, n, light);
            return (pmf, f32::from(pmf > 0.0));
        }
        let root = TreeNode {
            index: 0,
            depth: 0,
            trail: 0,
        };
        let (above, below) = self.descend(root, node.depth as usize, p, n, light);
        // Below `node` only if the light's trail passes through it.
        let mask = if node.depth == 0 {
            0
        } else {
            u64::MAX >> (64 - node.depth as u32)
        };
        match self.trails.get(light) {
            Some(&(trail, _)) if trail & mask == node.trail & mask => (above * below, below),
            _ => (above * below, 0.0),
        }
    }

    /// The descent from `node` to light `light`: the product of the choices above depth
    /// `split` and of those from it on; zeros where the light is not below `node`.
    fn descend(&self, node: TreeNode, split: usize, p: Vec3, n: Vec3, light: usize) -> (f32, f32) {
        let Some(&(trail, depth)) = self.trails.get(light) else {
            return (0.0, 0.0);
        };
        let start = node.depth as usize;
        if depth == u8::MAX || (depth as usize) < start || self.nodes.is_empty() {
            return (0.0, 0.0);
        }
        // The light is below `node` when its trail passes through it: its first `start`
        // choices are the node's.
        let mask = if start == 0 {
            0
        } else {
            u64::MAX >> (64 - start)
        };
        if trail & mask != node.trail & mask {
            return (0.0, 0.0);
        }
        let mut index = node.index as usize;
        let (mut above, mut below) = (1.0f32, 1.0f32);
        for level in start..depth as usize {
            let current = &self.nodes[index];
            let (a, b) = (index + 1, current.child_or_light as usize);
            let ia = self.nodes[a].bounds.importance(p, n);
            let ib = self.nodes[b].bounds.importance(p, n);
            if !(ia + ib > 0.0) {
                return (0.0, 0.0);
            }
            let choice = if trail & (1 << level) == 0 {
                index = a;
                ia / (ia + ib)
            } else {
                index = b;
                ib / (ia + ib)
            };
            if level < split {
                above *= choice;
            } else {
                below *= choice;
            }
        }
        (above, below)
    }

    /// At most `count` nodes (at least one, if the tree holds a light) that together hold
    /// every light once: the root, split where the most power is until there are `count`
    /// nodes or only leaves. Learned light selection learns one value per node of the cut.
    pub fn cut(&self, count: usize) -> Vec<TreeNode> {
        if self.nodes.is_empty() || count == 0 {
            return Vec::new();
        }
        let mut cut = vec![TreeNode {
            index: 0,
            depth: 0,
            trail: 0,
        }];
        while cut.len() < count {
            let widest = cut
                .iter()
                .enumerate()
                .filter(|(_, c)| !self.nodes[c.index as usize].leaf)
                .max_by(|a, b| {
                    let phi = |c: &TreeNode| self.nodes[c.index as usize].bounds.phi;
                    phi(a.1).total_cmp(&phi(b.1)).then(b.0.cmp(&a.0))
                })
                .map(|(i, _)| i);
            let Some(i) = widest else { break };
            let node = cut[i];
            let second = self.nodes[node.index as usize].child_or_light;
            cut[i] = TreeNode {
                index: node.index + 1,
                depth: node.depth + 1,
                trail: node.trail,
            };
            cut.insert(
                i + 1,
                TreeNode {
                    index: second,
                    depth: node.depth + 1,
                    trail: node.trail | (1 << node.depth),
                },
            );
        }
        cut
    }

    /// The node of the cut `cut` that light `light` is below, if it is in the tree.
    pub fn cluster_of(&self, cut: &[TreeNode], light: usize) -> Option<usize> {
        let &(trail, depth) = self.trails.get(light)?;
        if depth == u8::MAX {
            return None;
        }
        cut.iter().position(|c| {
            let start = c.depth as usize;
            let mask = if start == 0 {
                0
            } else {
                u64::MAX >> (64 - start)
            };
            start <= depth as usize && trail & mask == c.trail & mask
        })
    }
}

/// A node of the light tree with where it lies: its depth and the bit trail of the choices
/// from the root to it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TreeNode {
    pub index: u32,
    pub depth: u8,
    pub trail: u64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::pcg::Pcg32;

    fn point(x: f32, phi: f32) -> LightBounds {
        let p = Vec3::new(x, 1.0, 0.0);
        LightBounds {
            min: p,
            max: p,
            phi,
            w: Vec3::Y,
            cos_theta_o: -1.0,
            cos_theta_e: 0.0,
            two_sided: false,
        }
    }

    #[test]
    fn sampling_frequencies_match_the_pmf_and_it_sums_to_one() {
        let lights: Vec<(u32, LightBounds)> = (0..37)
            .map(|i| (i, point(i as f32 * 0.3 - 5.0, 1.0 + (i % 5) as f32)))
            .collect();
        let tree = LightTree::build(&lights, 37);
        let (p, n) = (Vec3::new(0.3, 0.0, 0.2), Vec3::Y);
        let total: f32 = (0..37).map(|i| tree.pmf(p, n, i)).sum();
        assert!((total - 1.0).abs() < 1e-4, "{total}");
        let mut counts = [0u32; 37];
        let mut rng = Pcg32::new(1, 1);
        let trials = 200_000;
        for _ in 0..trials {
            let (i, pmf) = tree.sample(p, n, rng.next_f32()).unwrap();
            assert!((pmf - tree.pmf(p, n, i)).abs() < 1e-5);
            counts[i] += 1;
        }
        for (i, &count) in counts.iter().enumerate() {
            let expected = tree.pmf(p, n, i) as f64;
            let sd = (expected * (1.0 - expected) / trials as f64).sqrt();
            assert!(
                (count as f64 / trials as f64 - expected).abs() <= 5.0 * sd + 1e-6,
                "light {i}"
            );
        }
        // Nearby lights are preferred.
        assert!(tree.pmf(p, n, 17) > tree.pmf(p, n, 0));
    }
}
