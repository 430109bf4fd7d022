//! What the render learns while it runs, in one holder that the render loop drives between
//! passes: efficiency-aware roulette and splitting (`integrator::ears`: per-region radiance
//! moments and costs, learned in passes of 1, 1, 2, 4 and 8 samples), learned first-vertex
//! splitting (`integrator::split`: the split counts, learned in a pass of their own over one
//! pixel in every 2×2 block), path guiding (`integrator::guiding`: the SD-tree, trained in
//! passes of 1, 1, 2, 4, ... samples) and learned light selection (`light::learned`: what
//! each cluster of lights brings to each region, trained in passes of 1, 1, 2, 4, 8, 16).
//!
//! Each pass, the loop asks the holder whether a technique needs a learning pass of its own
//! ([`LearnedState::split_learning_pass`]) or a shorter pass ([`LearnedState::limit_pass`]),
//! renders with what has been learned so far ([`LearnedState::ears`],
//! [`LearnedState::first_split`], [`LearnedState::guide`], [`LearnedState::lights`]), and
//! hands back what each tile learned, in tile order whatever the thread count, so that the
//! next pass decides the same way ([`LearnedState::absorb`]). A new learned technique is a
//! field of the holder, a field of [`TileLearning`], and its arms in these methods; the
//! kernels read its state as they read these.

use super::schedule::PassSamples;
use crate::film::Film;
use crate::integrator::ears::{self, Ears, Learning};
use crate::integrator::guiding::record::TileRecords;
use crate::integrator::guiding::sdtree::SdTree;
use crate::integrator::guiding::{AUTO_INDIRECT_SHARE, Guide, GuidingMode, TRAINING_SAMPLES};
use crate::integrator::split::{self, FirstSplit, LearningPixels, SplitStats};
use crate::integrator::{RussianRoulette, Settings, Split, SplitChoice};
use crate::light::LightSelect;
use crate::light::learned::{self, LightLearning, LightRecords};
use crate::world::World;

/// What one pass lets the techniques learn.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct PassLearning {
    /// Efficiency-aware roulette gathers statistics in this pass.
    pub ears: bool,
    /// This pass takes this many samples in each learning pixel to learn the split counts.
    pub split: Option<u32>,
    /// Path guiding records what this pass's paths find (the samples per pixel taken
    /// when the pass ends).
    pub guiding: Option<u32>,
    /// Learned light selection records what this pass's light samples find.
    pub lights: bool,
}

/// What one tile learned in a pass.
#[derive(Default)]
pub(super) struct TileLearning {
    pub ears: Option<Learning>,
    pub split: Option<SplitStats>,
    pub guiding: Option<TileRecords>,
    pub lights: Option<LightRecords>,
}

/// The learned state of a render.
pub(super) struct LearnedState {
    /// Efficiency-aware roulette's statistics (`rr = efficiency` only).
    ears: Option<Ears>,
    /// Whether the split counts are learned (`split = auto`).
    split_auto: bool,
    /// How the first vertex splits: the fixed counts, the learning split, or the counts
    /// learned.
    first_split: FirstSplit,
    learned_split: Option<Split>,
    learning_pixels: LearningPixels,
    /// Path guiding's SD-tree, while guiding is on.
    guiding: Option<Guiding>,
    /// Learned light selection (`--light-select learned`, where there are lights to
    /// choose between).
    lights: Option<LightLearning>,
}

/// Path guiding's state between passes.
struct Guiding {
    tree: SdTree,
    /// `auto`: decided after the first pass that records.
    auto: bool,
    /// Samples per pixel when the current training iteration began; above 0 once some
    /// iteration has been learned from (paths then sample from the tree).
    iteration_start: u32,
}

impl LearnedState {
    /// Nothing learned yet, for a render with `settings` of `world` into `film`, its paths
    /// guided if `guided` (the plan's decision).
    pub(super) fn new(settings: &Settings, guided: bool, world: &World, film: &Film) -> Self {
        let guiding = guided.then(|| Guiding {
            tree: SdTree::new(
                glam::Vec3::splat(-world.radius),
                glam::Vec3::splat(2.0 * world.radius),
            ),
            auto: settings.guiding == GuidingMode::Auto,
            iteration_start: 0,
        });
        let lights = (settings.light_select == LightSelect::Learned)
            .then(|| LightLearning::new(&world.lights, world.radius))
            .flatten();
        Self {
            guiding,
            lights,
            ears: match settings.rr {
                RussianRoulette::Efficiency(max_split) => {
                    Some(Ears::new(film.width, film.height, max_split))
                }
                _ => None,
            },
            split_auto: settings.split == SplitChoice::Auto,
            // Learned splitting takes the first samples of its learning pixels split two
            // and two, then the counts chosen everywhere.
            first_split: match settings.split {
                SplitChoice::Fixed(counts) => FirstSplit::fixed(counts),
                SplitChoice::Auto => FirstSplit::learning(),
            },
            learned_split: None,
            learning_pixels: LearningPixels::new(film.display.0, film.display.1),
        }
    }

    /// The samples each learning pixel takes in a pass that learns the split counts, when
    /// one is due: `done` samples of every pixel taken, `uniform_spp` to take before
    /// adaptive sampling.
    pub(super) fn split_learning_pass(&self, done: u32, uniform_spp: u32) -> Option<u32> {
        (self.split_auto && self.learned_split.is_none() && done < uniform_spp)
            .then(|| split::LEARNING_SAMPLES.min(uniform_spp - done))
    }

    /// The samples of that pass: `n` in each learning pixel of `film`, none elsewhere.
    pub(super) fn split_learning_samples(&self, film: &Film, n: u32) -> PassSamples {
        PassSamples::learning(film, self.learning_pixels, n)
    }

    /// A uniform pass of `n` samples after `done`, shortened where a technique learns in
    /// growing passes (efficiency-aware roulette: 1, 1, 2, 4, 8 samples, each deciding with
    /// everything learned before it), and what the pass learns.
    pub(super) fn limit_pass(&self, done: u32, n: u32) -> (u32, PassLearning) {
        let learning = self.ears.is_some() && done < ears::LEARNING_SAMPLES;
        // Path guiding trains in passes of 1, 1, 2, 4, ... too, each sampling from what
        // the one before learned.
        let training = self.guiding.is_some() && done < TRAINING_SAMPLES;
        // So does learned light selection.
        let lights = self.lights.is_some() && done < learned::TRAINING_SAMPLES;
        let n = if learning || training || lights {
            n.min(done.max(1))
        } else {
            n
        };
        (
            n,
            PassLearning {
                ears: learning,
                split: None,
                guiding: training.then_some(done + n),
                lights,
            },
        )
    }

    /// The learned distributions paths are guided by, once some pass has been learned
    /// from.
    pub(super) fn guide(&self) -> Option<Guide<'_>> {
        self.guiding
            .as_ref()
            .filter(|g| g.iteration_start > 0)
            .map(|g| Guide::new(&g.tree))
    }

    /// The tree a training pass records into.
    pub(super) fn guiding_tree(&self) -> Option<&SdTree> {
        self.guiding.as_ref().map(|g| &g.tree)
    }

    /// What learned light selection has learned (and records into in a training pass).
    pub(super) fn lights(&self) -> Option<&LightLearning> {
        self.lights.as_ref()
    }

    /// Efficiency-aware roulette's statistics so far.
    pub(super) fn ears(&self) -> Option<&Ears> {
        self.ears.as_ref()
    }

    /// How the first vertex splits in the next pass.
    pub(super) fn first_split(&self) -> FirstSplit {
        self.first_split
    }

    /// The split counts learned, once they are.
    pub(super) fn learned_split(&self) -> Option<Split> {
        self.learned_split
    }

    /// Takes what the tiles of a pass that learned `pass` learned, in tile order.
    pub(super) fn absorb(&mut self, pass: PassLearning, tiles: &[TileLearning]) {
        if let (Some(e), true) = (self.ears.as_mut(), pass.ears) {
            for l in tiles.iter().filter_map(|t| t.ears.as_ref()) {
                e.merge(l);
            }
            e.refresh();
        }
        if let (Some(l), true) = (self.lights.as_mut(), pass.lights) {
            for r in tiles.iter().filter_map(|t| t.lights.as_ref()) {
                l.absorb(r);
            }
            let regions = l.update();
            log::debug!("learned light selection: {regions} regions sample from what they learned");
        }
        if let Some(n) = pass.split {
            let mut stats = SplitStats::default();
            for s in tiles.iter().filter_map(|t| t.split.as_ref()) {
                stats.merge(s);
            }
            let counts = stats.choose();
            self.first_split = FirstSplit::after_learning(counts, n, self.learning_pixels);
            self.learned_split = Some(counts);
        }
        if let (Some(g), Some(after)) = (self.guiding.as_mut(), pass.guiding) {
            let (mut direct, mut indirect) = (0.0, 0.0);
            for t in tiles.iter().filter_map(|t| t.guiding.as_ref()) {
                g.tree.absorb(t);
                direct += t.direct;
                indirect += t.indirect;
            }
            if g.auto {
                g.auto = false;
                let share = indirect / (direct + indirect);
                if !(share >= AUTO_INDIRECT_SHARE) {
                    log::info!(
                        "guiding auto: off ({:.0} % of the light the first samples found is indirect; guiding pays from {:.0} %)",
                        100.0 * share,
                        100.0 * AUTO_INDIRECT_SHARE
                    );
                    self.guiding = None;
                    return;
                }
                log::info!(
                    "guiding auto: on ({:.0} % of the light the first samples found is indirect)",
                    100.0 * share
                );
            }
            // A training iteration ends where the samples taken double (PPG's schedule:
            // each iteration as long as all before it), so that the distribution paths
            // sample from is learned from as many samples as all earlier ones together.
            if after.is_power_of_two() {
                g.tree.update(after - g.iteration_start);
                g.iteration_start = after;
            }
        }
    }
}
