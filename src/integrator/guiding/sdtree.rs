//! The spatial half of Practical Path Guiding's SD-tree: a binary tree over the scene's box
//! in render space, split at the middle along x, y, z in turn, each leaf holding two
//! directional quadtrees: the one paths sample from (learned in the previous training
//! pass) and the one being filled in this pass. A leaf that received more records than
//! [`SPLIT_RECORDS`] · √(samples per pixel of the pass) is split after the pass (both halves
//! start from its distribution), so the tree follows where paths go.

use super::dtree::{DTree, SamplingTree};
use glam::Vec3;

/// PPG's c: a leaf splits once it holds more records than c · √spp of the pass.
pub const SPLIT_RECORDS: f64 = 12000.0;
/// Deepest level of the spatial tree.
const MAX_DEPTH: u32 = 24;

/// A node of the spatial tree: two children (indices, 0 for a leaf) or a leaf's index.
#[derive(Clone, Copy, Debug)]
struct SNode {
    children: u32,
    leaf: u32,
    axis: u8,
    depth: u32,
}

/// Surfaces are binned by the axis their normal (turned to the side paths arrive from) is
/// closest to, ±x, ±y, ±z: a spatial leaf holds one distribution per bin, so that a leaf
/// over a room's corner does not send a floor's paths into the wall beside it.
pub const NORMAL_BINS: usize = 6;

/// The bin of unit normal `n`.
#[inline]
pub fn normal_bin(n: Vec3) -> usize {
    let a = n.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    2 * axis + (n[axis] < 0.0) as usize
}

/// Where a vertex's distributions live: its spatial leaf and normal bin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Cell {
    pub leaf: u32,
    pub bin: u8,
}

/// A spatial leaf: one directional distribution per normal bin.
#[derive(Clone, Debug, Default)]
pub struct Leaf {
    pub bins: [Bin; NORMAL_BINS],
}

impl Leaf {
    /// Records deposited this pass in all bins.
    fn records(&self) -> u64 {
        self.bins.iter().map(|b| b.records).sum()
    }
}

/// One bin's distributions and what the current pass recorded there.
#[derive(Clone, Debug, Default)]
pub struct Bin {
    /// What paths sample from (empty before the first trained pass).
    pub sampling: SamplingTree,
    /// What this pass deposits into (its structure from `sampling`'s energy).
    pub building: DTree,
    /// Records deposited this pass.
    pub records: u64,
    /// Records `sampling` was learned from.
    pub trained: u64,
}

/// The spatial tree.
#[derive(Clone, Debug)]
pub struct SdTree {
    lo: Vec3,
    size: Vec3,
    nodes: Vec<SNode>,
    pub leaves: Vec<Leaf>,
}

impl SdTree {
    /// One leaf over the cube `[lo, lo + size]`, nothing learned.
    pub fn new(lo: Vec3, size: Vec3) -> Self {
        Self {
            lo,
            size: size.max(Vec3::splat(1e-6)),
            nodes: vec![SNode {
                children: 0,
                leaf: 0,
                axis: 0,
                depth: 0,
            }],
            leaves: vec![Leaf::default()],
        }
    }

    /// The cell of a vertex at render-space point `p` whose normal, turned to the side paths
    /// arrive from, is `n`.
    #[inline]
    pub fn cell(&self, p: Vec3, n: Vec3) -> Cell {
        Cell {
            leaf: self.leaf_of(p),
            bin: normal_bin(n) as u8,
        }
    }

    /// Cell `c`'s bin.
    #[inline]
    pub fn bin(&self, c: Cell) -> &Bin {
        &self.leaves[c.leaf as usize].bins[c.bin as usize]
    }

    /// The leaf whose box holds render-space point `p` (points outside go to the nearest).
    #[inline]
    pub fn leaf_of(&self, p: Vec3) -> u32 {
        let mut q = ((p - self.lo) / self.size).clamp(Vec3::ZERO, Vec3::ONE);
        let mut node = 0usize;
        loop {
            let n = self.nodes[node];
            if n.children == 0 {
                return n.leaf;
            }
            let a = n.axis as usize;
            let high = q[a] >= 0.5;
            q[a] = if high { q[a] * 2.0 - 1.0 } else { q[a] * 2.0 };
            node = n.children as usize + high as usize;
        }
    }

    /// After a pass of `spp` samples per pixel whose deposits are in the leaves' building
    /// trees: splits the leaves that received enough records, makes what was built the
    /// sampling distribution, and starts empty building trees refined from it.
    pub fn update(&mut self, spp: u32) {
        let threshold = SPLIT_RECORDS * (spp.max(1) as f64).sqrt();
        for bin in self.leaves.iter_mut().flat_map(|l| l.bins.iter_mut()) {
            bin.building.sum_up();
        }
        let mut i = 0;
        while i < self.nodes.len() {
            let n = self.nodes[i];
            if n.children == 0
                && n.depth < MAX_DEPTH
                && self.leaves[n.leaf as usize].records() as f64 > threshold
            {
                let leaf = &mut self.leaves[n.leaf as usize];
                for bin in &mut leaf.bins {
                    bin.records /= 2;
                }
                let copy = leaf.clone();
                let first = self.nodes.len() as u32;
                let second_leaf = self.leaves.len() as u32;
                self.leaves.push(copy);
                let axis = (n.axis + 1) % 3;
                for leaf in [n.leaf, second_leaf] {
                    self.nodes.push(SNode {
                        children: 0,
                        leaf,
                        axis,
                        depth: n.depth + 1,
                    });
                }
                self.nodes[i].children = first;
                // The new children may split again (their records were halved).
                continue;
            }
            i += 1;
        }
        for leaf in self.leaves.iter_mut().flat_map(|l| l.bins.iter_mut()) {
            let built = std::mem::take(&mut leaf.building);
            leaf.building = built.refined();
            leaf.sampling = built.frozen();
            leaf.trained = leaf.records;
            leaf.records = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Leaves split where records pile up and the lookup finds the leaf of a point's box.
    #[test]
    fn busy_leaves_split() {
        let mut tree = SdTree::new(Vec3::splat(-1.0), Vec3::splat(2.0));
        let hot = Vec3::new(0.7, -0.4, 0.2);
        let leaf = tree.leaf_of(hot);
        tree.leaves[leaf as usize].bins[0].records = (SPLIT_RECORDS * 9.0) as u64;
        tree.update(1);
        assert!(tree.leaves.len() >= 8, "{}", tree.leaves.len());
        let (a, b) = (tree.leaf_of(hot), tree.leaf_of(Vec3::new(-0.7, 0.4, -0.2)));
        assert_ne!(a, b);
        assert_eq!(tree.leaf_of(hot), tree.leaf_of(hot + Vec3::splat(1e-3)));
    }
}
