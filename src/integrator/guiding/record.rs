//! What a training pass records for path guiding: at every vertex where a path continued
//! in a direction it sampled, the radiance that then arrived along that direction, learned
//! once the path (and the branches it split into) has ended.
//!
//! A vertex at depth d is opened when its continuation is sampled; a contribution found
//! later at depth d' belongs to it when it travelled along that direction: everything found
//! at depth d' ≥ d + 2 (past the next vertex, MIS-weighted as the image takes it), and at
//! d' = d + 1 the emitter the continuation hit, unweighted (the light samples taken at the
//! vertex itself went elsewhere). The incident radiance is that sum over the continuation's
//! throughput (luminance), and the record deposited in the quadtree is radiance over the
//! density the direction was sampled with: an estimate of the energy per node.
//!
//! Records are summed per tile into (spatial leaf, quadtree leaf) bins, which the render
//! loop adds to the tree tile by tile in tile order, so what is learned does not depend on
//! the thread count.

use super::dtree::direction_to_square;
use super::sdtree::{Cell, SdTree};
use crate::color::luminance;
use crate::integrator::mis::Technique;
use glam::Vec3;
use std::collections::HashMap;

/// A vertex whose continuation's radiance is being gathered.
#[derive(Clone, Copy, Debug)]
struct Open {
    leaf: u32,
    bin: u8,
    node: u32,
    depth: u32,
    /// Luminance of the continuation's throughput.
    beta: f32,
    pdf: f32,
    gathered: f32,
}

/// A tile's records for path guiding, and what the render loop needs to decide whether
/// guiding pays.
#[derive(Debug, Default)]
pub struct TileRecords {
    /// (spatial leaf, normal bin, quadtree leaf) → energy deposited.
    pub deposits: HashMap<(u32, u8, u32), f64>,
    /// (spatial leaf, normal bin) → records.
    pub records: HashMap<(u32, u8), u64>,
    /// Luminance of the MIS-weighted contributions of direct light (one scattering event)
    /// and of indirect light (two or more).
    pub direct: f64,
    pub indirect: f64,
}

/// The recorder a path tracer fills during a training pass.
pub struct PathRecords<'t> {
    tree: &'t SdTree,
    open: Vec<Open>,
    pub tile: TileRecords,
}

impl<'t> PathRecords<'t> {
    /// The cell of a vertex at `p` with arrival-side normal `n`.
    #[inline]
    pub fn cell(&self, p: Vec3, n: Vec3) -> Cell {
        self.tree.cell(p, n)
    }

    /// An empty recorder depositing into `tree`'s building quadtrees.
    pub fn new(tree: &'t SdTree) -> Self {
        Self {
            tree,
            open: Vec::new(),
            tile: TileRecords::default(),
        }
    }

    /// Opens the vertex of cell `cell` at depth `depth`, whose continuation leaves along
    /// unit world direction `wi`, sampled with density `pdf`, with throughput luminance
    /// `beta`.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn open(&mut self, cell: Cell, wi: Vec3, depth: u32, beta: f32, pdf: f32) {
        if !(beta > 0.0 && pdf > 0.0 && beta.is_finite() && pdf.is_finite()) {
            return;
        }
        let node = self
            .tree
            .bin(cell)
            .building
            .leaf_of(direction_to_square(wi));
        self.open.push(Open {
            leaf: cell.leaf,
            bin: cell.bin,
            node,
            depth,
            beta,
            pdf,
            gathered: 0.0,
        });
    }

    /// Number of open vertices (to close a branch's own when it ends).
    #[inline]
    pub fn mark(&self) -> usize {
        self.open.len()
    }

    /// A contribution found at `depth` by `technique`: `weighted` as the image takes it,
    /// `unweighted` before its MIS weight.
    #[inline]
    pub fn gathered(&mut self, weighted: Vec3, depth: u32, technique: Technique) {
        let w = luminance(weighted);
        if w.is_finite() && w > 0.0 {
            if depth == 1 {
                self.tile.direct += w as f64;
            } else if depth >= 2 {
                self.tile.indirect += w as f64;
            }
        }
        for v in self.open.iter_mut() {
            // Past the next vertex, or the emitter the continuation itself hit.
            if depth >= v.depth + 2 || depth == v.depth + 1 && technique == Technique::Bsdf {
                v.gathered += w;
            }
        }
    }

    /// Closes the vertices opened after `mark`: their continuations are complete.
    pub fn close(&mut self, mark: usize) {
        for v in self.open.drain(mark..) {
            let value = v.gathered / v.beta / v.pdf;
            if !value.is_finite() {
                continue;
            }
            *self.tile.records.entry((v.leaf, v.bin)).or_default() += 1;
            if value > 0.0 {
                *self
                    .tile
                    .deposits
                    .entry((v.leaf, v.bin, v.node))
                    .or_default() += value as f64;
            }
        }
    }
}

impl SdTree {
    /// Adds a tile's records to the building quadtrees (called tile by tile in tile order).
    pub fn absorb(&mut self, tile: &TileRecords) {
        // One addition per bin and tile: the sums do not depend on the table's order.
        for (&(leaf, bin, node), &value) in &tile.deposits {
            self.leaves[leaf as usize].bins[bin as usize]
                .building
                .add_to_leaf(node, value);
        }
        for (&(leaf, bin), &n) in &tile.records {
            self.leaves[leaf as usize].bins[bin as usize].records += n;
        }
    }
}
