//! Light selection by learned contribution (`--light-select learned`): where the light BVH
//! (`light::tree`) guesses each light's contribution from its power, distance and
//! orientation alone, this learns from the light samples themselves, shadow rays included,
//! how much each group of lights brings to each region of the scene, so that lights behind
//! a wall stop taking samples from the rooms they do not light. The idea is Vévoda, Kondapaneni
//! and Křivánek's (2018, "Bayesian online regression for adaptive direct illumination
//! sampling"): a spatial cache of per-cluster contributions, occlusion included, mixed with
//! a distribution that never misses a light; we keep their cache and their clusters (a cut
//! of the light tree) and use a plain mean instead of their Bayesian regression.
//!
//! - **Regions**: a grid of [`RESOLUTION`]³ cells over the scene's bounding cube, each split
//!   by the dominant axis of the shading normal (six bins: the two sides of a wall lie in one
//!   cell but see different lights) and a seventh bin for points in media (no normal).
//! - **Clusters**: at most [`CLUSTERS`] groups of lights: a cut of the light tree, split
//!   where the most power is ([`LightTree::cut`]), and each light at infinity on its own.
//!   Within a cluster, a light is chosen by the tree below the cluster's node, as the tree
//!   would.
//! - **What is learned**: every light sample at a surface vertex of a training pass adds
//!   its unweighted contribution estimate (luminance of f·Lᵢ·V / (p_point · p_select)) to
//!   its region and the cluster of the light chosen, and counts one sample of its region,
//!   failed samples included. A cluster's sum over the region's count is an unbiased
//!   estimate of what the cluster brings there, whatever distribution chose the lights.
//! - **Selection**: in a region with at least [`MIN_SAMPLES`] samples and some light found,
//!   a cluster is chosen in proportion to its estimate with probability [`LEARNED_SHARE`],
//!   and the light by the tree's own selection otherwise (one-sample mixture: a light's
//!   probability is `s·q(c)·p_tree(l | c) + (1 − s)·p_tree(l)`, which MIS against BSDF
//!   sampling uses too), so a light the first samples missed is still sampled, and the
//!   estimate stays unbiased wherever what was learned is wrong.
//! - **Passes**: training passes of 1, 1, 2, 4, 8, 16 samples up to [`TRAINING_SAMPLES`],
//!   each sampling from what the passes before learned; every sample is kept (each pass is
//!   unbiased under its own fixed distribution). Tiles' records are merged in tile order, so
//!   the image does not depend on the thread count.
//!
//! Only the scalar kernel selects this way (the render plan keeps the packet kernel out).

use super::LightSet;
use super::tree::TreeNode;
use glam::Vec3;
use std::collections::HashMap;

/// Cells per axis of the grid of regions.
pub const RESOLUTION: u32 = 24;
/// Normal bins per cell: ±x, ±y, ±z and none (points in media).
const ORIENTATIONS: u32 = 7;
/// Clusters of lights learned at most.
pub const CLUSTERS: usize = 32;
/// Light samples a region must have taken before its learned distribution is used.
pub const MIN_SAMPLES: u64 = 16;
/// Share of light samples chosen by the learned distribution where there is one.
pub const LEARNED_SHARE: f32 = 0.5;
/// Samples per pixel that training takes; passes of 1, 1, 2, 4, 8, 16 up to it.
pub const TRAINING_SAMPLES: u32 = 32;
/// No region (outside the grid).
const NO_ROW: u32 = u32::MAX;

/// A group of lights whose contribution is learned as one.
#[derive(Clone, Copy, Debug)]
enum Cluster {
    /// The lights below a node of the light tree.
    Node(TreeNode),
    /// One light at infinity (chosen by the tree's selector as a group of its own).
    Infinite(u32),
}

/// What a tile's training records: per region, the samples taken, and per (region,
/// cluster), the contributions found.
#[derive(Debug, Default)]
pub struct LightRecords {
    pub samples: HashMap<u32, u64>,
    pub found: HashMap<(u32, u16), f64>,
}

impl LightRecords {
    /// One light sample taken in region `region` (from [`LightLearning::region`]).
    #[inline]
    pub fn sample(&mut self, region: u32) {
        *self.samples.entry(region).or_default() += 1;
    }

    /// The sample of light `light` in region `region` found `value` (luminance of its
    /// unweighted estimate, selection probability divided out).
    #[inline]
    pub fn found(&mut self, learning: &LightLearning, region: u32, light: usize, value: f32) {
        let cluster = learning.cluster_of[light];
        if cluster != u16::MAX && value.is_finite() && value > 0.0 {
            *self.found.entry((region, cluster)).or_default() += value as f64;
        }
    }
}

/// The learned selection: clusters, what the training passes found, and the distribution
/// over clusters per region that selection samples from.
#[derive(Debug)]
pub struct LightLearning {
    clusters: Vec<Cluster>,
    /// Per light: its cluster (`u16::MAX`: none, it emits nothing).
    cluster_of: Vec<u16>,
    lo: Vec3,
    cells_per_unit: f32,
    samples: HashMap<u32, u64>,
    found: HashMap<u32, Vec<f64>>,
    /// Per region: its row of `rows` (`NO_ROW`: nothing learned, the tree's selection).
    row_of: Vec<u32>,
    /// Rows of `clusters.len()` probabilities, each row summing to 1.
    rows: Vec<f32>,
}

impl LightLearning {
    /// The learning for the lights of `set`, over the cube of half-size `radius` around the
    /// origin; `None` where there is nothing to choose between (fewer than two clusters),
    /// or the set's selection is not by the light tree.
    pub fn new(set: &LightSet, radius: f32) -> Option<Self> {
        let (tree, infinite) = set.tree()?;
        let cut = tree.cut(CLUSTERS.saturating_sub(infinite.len()).max(1));
        let mut clusters: Vec<Cluster> = cut.iter().map(|&n| Cluster::Node(n)).collect();
        clusters.extend(infinite.iter().map(|&i| Cluster::Infinite(i)));
        if clusters.len() < 2 {
            return None;
        }
        let mut cluster_of = vec![u16::MAX; set.lights.len()];
        for (light, c) in cluster_of.iter_mut().enumerate() {
            if let Some(i) = tree.cluster_of(&cut, light) {
                *c = i as u16;
            }
        }
        for (k, &i) in infinite.iter().enumerate() {
            cluster_of[i as usize] = (cut.len() + k) as u16;
        }
        let cells = RESOLUTION.pow(3) * ORIENTATIONS;
        Some(Self {
            clusters,
            cluster_of,
            lo: Vec3::splat(-radius),
            cells_per_unit: RESOLUTION as f32 / (2.0 * radius),
            samples: HashMap::new(),
            found: HashMap::new(),
            row_of: vec![NO_ROW; cells as usize],
            rows: Vec::new(),
        })
    }

    /// Number of clusters.
    pub fn cluster_count(&self) -> usize {
        self.clusters.len()
    }

    /// The region of a point `p` with shading normal `n` (ZERO in media); `None` outside
    /// the grid.
    #[inline]
    pub fn region(&self, p: Vec3, n: Vec3) -> Option<u32> {
        let c = (p - self.lo) * self.cells_per_unit;
        if !(c.min_element() >= 0.0 && c.max_element() < RESOLUTION as f32) {
            return None;
        }
        let (x, y, z) = (c.x as u32, c.y as u32, c.z as u32);
        let a = n.abs();
        let orientation = if n == Vec3::ZERO {
            6
        } else if a.x >= a.y && a.x >= a.z {
            u32::from(n.x < 0.0)
        } else if a.y >= a.z {
            2 + u32::from(n.y < 0.0)
        } else {
            4 + u32::from(n.z < 0.0)
        };
        Some(((z * RESOLUTION + y) * RESOLUTION + x) * ORIENTATIONS + orientation)
    }

    /// The learned distribution over clusters at region `region`, if there is one.
    #[inline]
    fn row(&self, region: Option<u32>) -> Option<&[f32]> {
        let row = *self.row_of.get(region? as usize)?;
        if row == NO_ROW {
            return None;
        }
        let k = self.clusters.len();
        Some(&self.rows[row as usize * k..(row as usize + 1) * k])
    }

    /// Chooses a light at `p` (normal `n`, region `region` from [`LightLearning::region`])
    /// with `u`: its index and probability.
    #[inline]
    pub fn select(
        &self,
        set: &LightSet,
        u: f32,
        p: Vec3,
        n: Vec3,
        region: Option<u32>,
    ) -> Option<(usize, f32)> {
        let Some(row) = self.row(region) else {
            return set.select(u, p, n);
        };
        let light = if u < LEARNED_SHARE {
            let mut u = u / LEARNED_SHARE;
            // Rounding may run past the last cluster: it then falls to the last one that
            // has a probability.
            let mut chosen = row.iter().rposition(|&q| q > 0.0)?;
            for (c, &q) in row.iter().enumerate() {
                if u < q {
                    chosen = c;
                    break;
                }
                u -= q;
            }
            let u = (u / row[chosen]).clamp(0.0, 1.0 - f32::EPSILON);
            match self.clusters[chosen] {
                Cluster::Node(node) => {
                    let (tree, _) = set.tree()?;
                    tree.sample_below(node.index as usize, p, n, u)?.0
                }
                Cluster::Infinite(i) => i as usize,
            }
        } else {
            let u = ((u - LEARNED_SHARE) / (1.0 - LEARNED_SHARE)).min(1.0 - f32::EPSILON);
            set.select(u, p, n)?.0
        };
        let probability = self.mix(set, row, light, p, n);
        (probability > 0.0).then_some((light, probability))
    }

    /// Probability that [`LightLearning::select`] picks light `light` at `p` with normal
    /// `n`.
    #[inline]
    pub fn probability(&self, set: &LightSet, light: usize, p: Vec3, n: Vec3) -> f32 {
        match self.row(self.region(p, n)) {
            Some(row) => self.mix(set, row, light, p, n),
            None => set.selection_probability(light, p, n),
        }
    }

    /// The mixture's probability of `light` where the learned distribution is `row`.
    fn mix(&self, set: &LightSet, row: &[f32], light: usize, p: Vec3, n: Vec3) -> f32 {
        let cluster = self.cluster_of[light];
        let (base, within) = match (self.clusters.get(cluster as usize), set.tree()) {
            // One descent of the tree gives both the tree's probability and the one below
            // the cluster's node.
            (Some(&Cluster::Node(node)), Some((tree, _))) => {
                let (pmf, below) = tree.pmf_and_below(node, p, n, light);
                (pmf * set.tree_share(), below)
            }
            (Some(Cluster::Infinite(_)), _) => (set.selection_probability(light, p, n), 1.0),
            _ => (set.selection_probability(light, p, n), 0.0),
        };
        let learned = row.get(cluster as usize).map_or(0.0, |&q| q * within);
        LEARNED_SHARE * learned + (1.0 - LEARNED_SHARE) * base
    }

    /// Adds what a tile recorded (tiles in tile order).
    pub fn absorb(&mut self, records: &LightRecords) {
        let k = self.clusters.len();
        for (&region, &count) in &records.samples {
            *self.samples.entry(region).or_default() += count;
        }
        for (&(region, cluster), &value) in &records.found {
            self.found.entry(region).or_insert_with(|| vec![0.0; k])[cluster as usize] += value;
        }
    }

    /// Rebuilds the distributions selection samples from out of everything absorbed: in
    /// each region with enough samples where some light was found, clusters in proportion
    /// to their estimated contributions. Returns the number of regions that have one.
    pub fn update(&mut self) -> usize {
        let k = self.clusters.len();
        self.row_of.fill(NO_ROW);
        self.rows.clear();
        let mut regions: Vec<u32> = self.found.keys().copied().collect();
        // Rows in region order: the tables do not depend on the map's order.
        regions.sort_unstable();
        for region in regions {
            let samples = self.samples.get(&region).copied().unwrap_or(0);
            let sums = &self.found[&region];
            let total: f64 = sums.iter().sum();
            if samples < MIN_SAMPLES || !(total > 0.0) || !total.is_finite() {
                continue;
            }
            self.row_of[region as usize] = (self.rows.len() / k) as u32;
            self.rows.extend(sums.iter().map(|&s| (s / total) as f32));
        }
        self.rows.len() / k.max(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::{Light, LightSelect, PointLight};
    use crate::sampling::pcg::Pcg32;

    fn lights() -> LightSet {
        let lights = (0..40)
            .map(|i| {
                Light::Point(PointLight {
                    position: Vec3::new((i % 8) as f32 - 3.5, 1.0 + (i / 8) as f32 * 0.5, 0.3),
                    intensity: Vec3::splat(1.0 + (i % 3) as f32),
                })
            })
            .collect();
        LightSet::new(lights, None, 10.0, LightSelect::Learned)
    }

    /// A learning whose regions near the origin found only some clusters.
    fn learned(set: &LightSet) -> LightLearning {
        let mut learning = LightLearning::new(set, 10.0).unwrap();
        let mut records = LightRecords::default();
        let mut rng = Pcg32::new(3, 5);
        for _ in 0..4000 {
            let p = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            );
            let n = Vec3::new(rng.next_f32() - 0.5, 1.0, 0.0).normalize();
            let region = learning.region(p, n).unwrap();
            records.sample(region);
            let light = (rng.next_f32() * 40.0) as usize % 40;
            if !light.is_multiple_of(3) {
                records.found(&learning, region, light, rng.next_f32() * light as f32);
            }
        }
        learning.absorb(&records);
        assert!(learning.update() > 0);
        learning
    }

    /// The probabilities of learned selection sum to one over the lights, and selection
    /// picks each light as often as its probability says (5 standard deviations), in a
    /// region that learned and one that did not.
    #[test]
    fn learned_selection_matches_its_probabilities_which_sum_to_one() {
        let set = lights();
        let learning = learned(&set);
        assert!(learning.cluster_count() > 2);
        let learned_point = (Vec3::new(0.1, 0.2, -0.1), Vec3::Y);
        let other_point = (Vec3::new(5.0, -3.0, 2.0), Vec3::X);
        assert!(
            learning
                .row(learning.region(learned_point.0, learned_point.1))
                .is_some()
        );
        assert!(
            learning
                .row(learning.region(other_point.0, other_point.1))
                .is_none()
        );
        for (p, n) in [learned_point, other_point] {
            let total: f32 = (0..40).map(|i| learning.probability(&set, i, p, n)).sum();
            assert!((total - 1.0).abs() < 1e-4, "{total}");
            let region = learning.region(p, n);
            let mut counts = [0u32; 40];
            let mut rng = Pcg32::new(7, 9);
            let trials = 200_000;
            for _ in 0..trials {
                let (i, pmf) = learning.select(&set, rng.next_f32(), p, n, region).unwrap();
                assert!((pmf - learning.probability(&set, i, p, n)).abs() < 1e-5);
                counts[i] += 1;
            }
            for (i, &count) in counts.iter().enumerate() {
                let expected = learning.probability(&set, i, p, n) as f64;
                let sd = (expected * (1.0 - expected) / trials as f64).sqrt();
                assert!(
                    (count as f64 / trials as f64 - expected).abs() <= 5.0 * sd + 1e-6,
                    "light {i}: {count} of {trials}, expected {expected}"
                );
            }
        }
    }

    /// Every light belongs to exactly one cluster, and the tree's probabilities within a
    /// cluster sum to one.
    #[test]
    fn clusters_partition_the_lights() {
        let set = lights();
        let learning = LightLearning::new(&set, 10.0).unwrap();
        let (tree, _) = set.tree().unwrap();
        let (p, n) = (Vec3::new(0.2, 0.0, 0.1), Vec3::Y);
        for (c, cluster) in learning.clusters.iter().enumerate() {
            let Cluster::Node(node) = *cluster else {
                continue;
            };
            let members: Vec<usize> = (0..40)
                .filter(|&l| learning.cluster_of[l] == c as u16)
                .collect();
            assert!(!members.is_empty());
            let total: f32 = (0..40).map(|l| tree.pmf_below(node, p, n, l)).sum();
            assert!((total - 1.0).abs() < 1e-4, "cluster {c}: {total}");
            for l in 0..40 {
                let below = tree.pmf_below(node, p, n, l);
                assert_eq!(below > 0.0, members.contains(&l));
                let (pmf, below_too) = tree.pmf_and_below(node, p, n, l);
                assert!((pmf - tree.pmf(p, n, l)).abs() < 1e-6 && (below - below_too).abs() < 1e-6);
            }
        }
        assert!(learning.cluster_of.iter().all(|&c| c != u16::MAX));
    }
}
