//! Path guiding: directions at a path's vertices sampled from a learned distribution of the
//! light arriving there, mixed with BSDF sampling, so that light that enters through a gap
//! or comes off a bright wall around a corner is found on purpose rather than by chance.
//!
//! The distribution is Practical Path Guiding's SD-tree (Müller, Gross and Novák 2017): a
//! binary tree over space (`sdtree`) whose leaves hold directional quadtrees (`dtree`),
//! learned in training passes of growing size (each pass samples from what the one before
//! learned, and records what its paths found: `record`). We chose it over Open PGL's
//! parallax-aware von Mises-Fisher mixtures (what Cycles ships) because its densities are
//! exact and cheap to evaluate (a descent of a quadtree), it has no fitting step that could
//! fail or depend on the order of samples, and it is small enough to own and test here;
//! Open PGL has no Rust binding.
//!
//! At a vertex whose leaf has learned something, the continuation's direction comes from the
//! quadtree with probability [`GUIDE_PROBABILITY`] and from the BSDF otherwise (one-sample
//! MIS, the balance heuristic over the two: the density of every continuation is the mixture
//! `α p_guide + (1 − α) p_bsdf`, which also enters the MIS weights against light sampling),
//! so the estimate stays unbiased wherever the learned distribution is wrong. Delta lobes
//! are the BSDF's alone. Every sample is kept, the training passes' included, at equal
//! weight: each is unbiased.
//!
//! `--guiding off|on|auto` (default off). Guided and training passes run in the scalar
//! kernel, which alone has guiding: against the packet kernel's unguided paths, guided
//! paths lose at equal time on the scenes measured (tools/bench/results/guiding.md). So
//! `auto` guides only where the plan runs the scalar kernel anyway (light layers, data AOVs,
//! learning roulette; `render::plan::RenderPlan::with_guiding`), and there only when the
//! first training pass finds the light mostly indirect (two or more bounces:
//! [`AUTO_INDIRECT_SHARE`]), the case guiding is for; where direct light dominates, paths
//! find it by light sampling and guiding would only cost. The share does not tell every
//! case: light through a narrow gap is indirect too, and there guiding loses.

pub mod dtree;
pub mod mixture;
pub mod record;
pub mod sdtree;

use dtree::{SPHERE_AREA, SamplingTree, direction_to_square, square_to_direction};
use glam::{Vec2, Vec3};
use sdtree::SdTree;

/// Probability of taking a continuation's direction from the learned distribution where
/// there is one (Open PGL and Cycles use 0.5 too).
pub const GUIDE_PROBABILITY: f32 = 0.5;
/// `auto` keeps guiding when at least this share of the first pass's light is indirect.
pub const AUTO_INDIRECT_SHARE: f64 = 0.5;
/// Samples per pixel that training takes at most; passes of 1, 1, 2, 4, 8, 16, 32 up to
/// it, each learning from the one before.
pub const TRAINING_SAMPLES: u32 = 128;
/// Records a quadtree must have been learned from before paths sample from it (guards
/// against leaves that saw a handful of paths).
const MIN_RECORDS: u64 = 64;

/// Whether paths are guided.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum GuidingMode {
    #[default]
    Off,
    On,
    Auto,
}

impl GuidingMode {
    /// Parses `off`, `on` or `auto`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "off" => Ok(Self::Off),
            "on" => Ok(Self::On),
            "auto" => Ok(Self::Auto),
            _ => Err(format!("guiding: off, on or auto, got {s:?}")),
        }
    }

    /// The textual form [`GuidingMode::parse`] reads.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::On => "on",
            Self::Auto => "auto",
        }
    }
}

/// The learned distributions paths sample from during a pass (read-only).
#[derive(Clone, Copy)]
pub struct Guide<'g> {
    tree: &'g SdTree,
}

impl<'g> Guide<'g> {
    /// Paths sample from `tree`'s sampling quadtrees.
    pub fn new(tree: &'g SdTree) -> Self {
        Self { tree }
    }

    /// The cell of a vertex at render-space point `p` with arrival-side normal `n`.
    #[inline]
    pub fn cell(&self, p: Vec3, n: Vec3) -> sdtree::Cell {
        self.tree.cell(p, n)
    }

    /// The distribution of cell `cell`, if it has learned enough.
    #[inline]
    pub fn at(&self, cell: sdtree::Cell) -> Option<Distribution<'g>> {
        let leaf = self.tree.bin(cell);
        (leaf.trained >= MIN_RECORDS && leaf.sampling.total() > 0.0).then_some(Distribution {
            tree: &leaf.sampling,
        })
    }
}

/// One leaf's learned distribution of directions (world space, unit vectors).
#[derive(Clone, Copy)]
pub struct Distribution<'g> {
    tree: &'g SamplingTree,
}

impl<'g> Distribution<'g> {
    /// The distribution of quadtree `tree` (a leaf's, or one built for a test).
    pub fn new(tree: &'g SamplingTree) -> Self {
        Self { tree }
    }

    /// A world direction drawn with `u`, and its solid-angle density.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, f32)> {
        let (p, pdf) = self.tree.sample(u)?;
        Some((square_to_direction(p), pdf / SPHERE_AREA))
    }

    /// The solid-angle density of unit world direction `d`.
    #[inline]
    pub fn pdf(&self, d: Vec3) -> f32 {
        self.tree.pdf(direction_to_square(d)) / SPHERE_AREA
    }
}
