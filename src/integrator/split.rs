//! Splitting at the first vertex: where its split points lie in the pixel's sequence, and
//! the learned choice of the split counts (`--split auto`).
//!
//! A pixel sample's estimate is what the camera sees directly, plus the mean of n_nee light
//! estimates and of n_bsdf BSDF paths from the first vertex. Given that vertex, the light
//! estimates are independent of each other, and so are the BSDF paths, so the variance of
//! a sample is V₀ + V_nee / n_nee + V_bsdf / n_bsdf (V₀: the variance of the first vertex's
//! expected value; V_nee, V_bsdf: the variance of one estimate given the first vertex), at a
//! cost of C₀ + n_nee C_nee + n_bsdf C_bsdf. Their product is least at
//! n = sqrt(V C₀ / (V₀ C)) for each technique (the optimum of splitting, as in Rath et al.
//! 2022, "EARS", section 4).
//!
//! `auto` learns the V and C: the first [`LEARNING_SAMPLES`] samples of one pixel in every
//! 2×2 block ([`LearningPixels`]) split [`LEARNING_SPLIT`], with independent points. The
//! halved squared difference of a sample's two light estimates is an unbiased estimate of
//! V_nee (the same for its two BSDF paths), and the spread of the samples of a pixel
//! estimates the whole; the pixels are summed weighted as relMSE weighs them
//! (1 / (mean² + 0.01)). Costs are counted in rays, as efficiency-aware roulette counts
//! them, so the choice (and the image) is the same at every run. The remaining samples,
//! and all the samples of the other pixels, split by the counts chosen.
//!
//! Learning in a quarter of the pixels costs a quarter as much and leaves the other three
//! quarters' split points one stratified sequence: on the Cornell box, where the learned
//! counts gain least, learning in every pixel made 10 spp 15 % less efficient than the
//! counts it learned, fixed from the start.

use super::settings::Split;
use crate::color::luminance;
use crate::sampling::pcg::hash_u32;
use crate::sampling::sampler::SplitKind;
use glam::Vec3;

/// Samples of every pixel that learn the split counts (fewer if the render takes fewer
/// before adaptive sampling).
pub const LEARNING_SAMPLES: u32 = 4;
/// How the learning samples split: two of each, the fewest that show their spread.
pub const LEARNING_SPLIT: Split = Split { nee: 2, bsdf: 2 };
/// Largest count the learned choice takes.
pub const MAX_LEARNED_SPLIT: u32 = 16;

/// The pixels whose first samples learn the split counts: one in every 2×2 block of the
/// image, at a position hashed from the block (a block cut by the image's edge chooses
/// among its pixels inside), so that every part of the image is represented, no regular
/// grid shows in the noise, and even a one-pixel image learns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LearningPixels {
    width: u32,
    height: u32,
}

impl LearningPixels {
    /// The learning pixels of a `width` × `height` image.
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height }
    }

    /// Whether pixel (`x`, `y`) learns.
    #[inline]
    pub fn contains(&self, x: u32, y: u32) -> bool {
        let (bx, by) = (x & !1, y & !1);
        let columns = (self.width - bx).min(2);
        let rows = (self.height - by).min(2);
        let chosen = hash_u32(bx.wrapping_mul(0x9e37_79b9) ^ by) % (columns * rows);
        (y - by) * columns + (x - bx) == chosen
    }
}

/// The first vertex's split counts, and where their points lie in each pixel's split
/// sequences (one sequence of each [`SplitKind`] per stream).
///
/// With fixed counts, sample `index`'s j-th point is point
/// `from + (index - from) × count + j` of stream 0, where `from` is the number of
/// learning samples the pixel took (each took one point of stream 0; none in a pixel that
/// did not learn): every sample's points follow the last's, and the points of all the
/// pixel's samples together are one stratified sequence. The learning samples instead take
/// their j-th point from stream j, at point `index`: the two points of a sample are then
/// independent of each other (two points of one stratified sequence are not: their
/// difference would overstate the spread of one estimate), and each stream is stratified
/// across the samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FirstSplit {
    pub counts: Split,
    /// The samples each learning pixel took before these counts, and those pixels.
    learned: Option<(u32, LearningPixels)>,
    independent: bool,
}

impl FirstSplit {
    /// The same counts at every sample.
    pub fn fixed(counts: Split) -> Self {
        Self {
            counts,
            learned: None,
            independent: false,
        }
    }

    /// The learning samples' split: [`LEARNING_SPLIT`], each point from a stream of its own.
    pub fn learning() -> Self {
        Self {
            counts: LEARNING_SPLIT,
            independent: true,
            ..Self::fixed(LEARNING_SPLIT)
        }
    }

    /// `counts` at every sample, but the first `learned` samples of `pixels`, which were
    /// [`FirstSplit::learning`]'s and took points 0 to `learned` - 1 of stream 0.
    pub fn after_learning(counts: Split, learned: u32, pixels: LearningPixels) -> Self {
        Self {
            counts,
            learned: Some((learned, pixels)),
            independent: false,
        }
    }

    /// Shadow rays and BSDF samples at a vertex `depth` scattering events down a path: the
    /// split counts at the first vertex, one of each deeper.
    #[inline]
    pub fn at(&self, depth: u32) -> Split {
        if depth == 0 {
            self.counts
        } else {
            Split { nee: 1, bsdf: 1 }
        }
    }

    /// Where sample `index` of pixel `(x, y)` takes its split points. Taken once per
    /// sample: whether the pixel learned is a hash, which every split point would repeat
    /// (1.8 % of the MIS plates' instructions with nee=5,bsdf=2).
    #[inline]
    pub fn sample_points(&self, (x, y): (u32, u32), index: u32) -> SamplePoints {
        let from = match self.learned {
            Some((n, pixels)) if pixels.contains(x, y) => n,
            _ => 0,
        };
        SamplePoints {
            counts: self.counts,
            from,
            index,
            independent: self.independent,
        }
    }
}

/// Where one pixel sample's first-vertex split points lie (see [`FirstSplit`]).
#[derive(Clone, Copy, Debug)]
pub struct SamplePoints {
    counts: Split,
    /// The learning samples its pixel took (0 where it did not learn).
    from: u32,
    index: u32,
    independent: bool,
}

impl SamplePoints {
    /// The stream and the index in it of the sample's point `j` for `kind`.
    #[inline]
    pub fn point(&self, kind: SplitKind, j: u32) -> (u32, u64) {
        let (from, index) = (self.from, self.index);
        if self.independent {
            return (j, index as u64);
        }
        let count = match kind {
            SplitKind::Light => self.counts.nee,
            SplitKind::Bsdf => self.counts.bsdf,
        };
        (
            0,
            from as u64 + index.saturating_sub(from) as u64 * count as u64 + j as u64,
        )
    }
}

/// What one learning sample brought back, by part (luminance), and the rays each part
/// traced.
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleParts {
    /// The whole sample.
    pub total: f32,
    /// Each light estimate's share (its estimate over the count) and each BSDF path's.
    pub nee: [f32; 2],
    pub bsdf: [f32; 2],
    /// The light estimate or BSDF path being traced.
    pub current: usize,
    /// The ray count (of the thread) when the sample started, before the first vertex's
    /// light samples, before its BSDF paths, and when it ended.
    pub rays: [u64; 4],
    /// Whether the sample reached a first vertex that split.
    pub split: bool,
}

impl SampleParts {
    /// Adds a contribution: direct light found by light sampling at the first vertex goes
    /// to the current light estimate, anything else past the first vertex to the current
    /// BSDF path.
    #[inline]
    pub fn add(&mut self, value: Vec3, depth: u32, by_light: bool) {
        let y = luminance(value);
        self.total += y;
        if depth == 1 && by_light {
            self.nee[self.current] += y;
        } else if depth >= 1 {
            self.bsdf[self.current] += y;
        }
    }
}

/// One pixel's learning samples, summed.
#[derive(Clone, Copy, Debug, Default)]
pub struct PixelParts {
    n: u32,
    sum: f64,
    sum_sq: f64,
    nee_spread: f64,
    bsdf_spread: f64,
}

impl PixelParts {
    /// Adds a sample.
    pub fn add(&mut self, s: &SampleParts) {
        let total = s.total as f64;
        self.n += 1;
        self.sum += total;
        self.sum_sq += total * total;
        // Each share is the estimate over 2: the halved squared difference of the two
        // estimates is 2 (a - b)² of the shares.
        let spread = |[a, b]: [f32; 2]| 2.0 * (a as f64 - b as f64).powi(2);
        self.nee_spread += spread(s.nee);
        self.bsdf_spread += spread(s.bsdf);
    }
}

/// The learning samples of part of the image (weighted variances, rays); sums of tiles in
/// tile order give the same choice whatever the thread count.
#[derive(Clone, Copy, Debug, Default)]
pub struct SplitStats {
    /// Σ weight × variance of a whole sample, of one light estimate, of one BSDF path.
    total: f64,
    nee: f64,
    bsdf: f64,
    /// Samples, rays before the first vertex's light samples, in its light samples and in
    /// its BSDF paths.
    samples: u64,
    camera_rays: u64,
    nee_rays: u64,
    bsdf_rays: u64,
}

impl SplitStats {
    /// Adds a sample's rays.
    pub fn add_rays(&mut self, s: &SampleParts) {
        let [start, nee, bsdf, end] = s.rays;
        self.samples += 1;
        if s.split {
            self.camera_rays += nee - start;
            self.nee_rays += bsdf - nee;
            self.bsdf_rays += end - bsdf;
        } else {
            self.camera_rays += end - start;
        }
    }

    /// Adds a pixel's variances, weighted as relMSE weighs the pixel.
    pub fn add_pixel(&mut self, p: &PixelParts) {
        if p.n < 2 {
            return;
        }
        let n = p.n as f64;
        let mean = p.sum / n;
        let weight = 1.0 / (mean * mean + 0.01);
        self.total += weight * ((p.sum_sq - n * mean * mean) / (n - 1.0)).max(0.0);
        self.nee += weight * p.nee_spread / n;
        self.bsdf += weight * p.bsdf_spread / n;
    }

    /// Adds another part of the image.
    pub fn merge(&mut self, o: &SplitStats) {
        self.total += o.total;
        self.nee += o.nee;
        self.bsdf += o.bsdf;
        self.samples += o.samples;
        self.camera_rays += o.camera_rays;
        self.nee_rays += o.nee_rays;
        self.bsdf_rays += o.bsdf_rays;
    }

    /// The counts that minimise variance × cost, n = sqrt(V C₀ / (V₀ C)), rounded, in
    /// 1..=[`MAX_LEARNED_SPLIT`]; V₀ is what the whole's variance leaves of the learning
    /// split's (at least a hundredth of it, where the estimates are that noisy).
    pub fn choose(&self) -> Split {
        let samples = self.samples.max(1) as f64;
        let cost = |rays: u64, per_sample: u32| rays as f64 / (samples * per_sample as f64);
        let c0 = cost(self.camera_rays, 1);
        let (c_nee, c_bsdf) = (
            cost(self.nee_rays, LEARNING_SPLIT.nee),
            cost(self.bsdf_rays, LEARNING_SPLIT.bsdf),
        );
        let within = self.nee / LEARNING_SPLIT.nee as f64 + self.bsdf / LEARNING_SPLIT.bsdf as f64;
        let v0 = (self.total - within).max(0.01 * self.total);
        let count = |v: f64, c: f64| {
            if v > 0.0 && c > 0.0 && v0 > 0.0 {
                (v * c0 / (v0 * c))
                    .sqrt()
                    .round()
                    .clamp(1.0, MAX_LEARNED_SPLIT as f64) as u32
            } else {
                1
            }
        };
        Split {
            nee: count(self.nee, c_nee),
            bsdf: count(self.bsdf, c_bsdf),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stream 0's points of every sample follow the last's, in a learning pixel through the
    /// change from the learning split to the learned one, without a gap or a repeat; the
    /// learning samples' second points come from stream 1. A pixel that did not learn
    /// takes the learned counts' points from its first sample on.
    #[test]
    fn split_points_run_on_from_sample_to_sample() {
        let pixels = LearningPixels::new(8, 8);
        let learner = (0..8)
            .flat_map(|y| (0..8).map(move |x| (x, y)))
            .find(|&(x, y)| pixels.contains(x, y))
            .unwrap();
        let other = (0..8)
            .flat_map(|y| (0..8).map(move |x| (x, y)))
            .find(|&(x, y)| !pixels.contains(x, y))
            .unwrap();
        let learned =
            FirstSplit::after_learning(Split { nee: 3, bsdf: 5 }, LEARNING_SAMPLES, pixels);
        for kind in [SplitKind::Light, SplitKind::Bsdf] {
            let count = match kind {
                SplitKind::Light => 3,
                SplitKind::Bsdf => 5,
            };
            for pixel in [learner, other] {
                let mut points = Vec::new();
                for index in 0..10 {
                    if pixel == learner && index < LEARNING_SAMPLES {
                        let learning = FirstSplit::learning();
                        assert_eq!(
                            learning.sample_points(pixel, index).point(kind, 1),
                            (1, index as u64)
                        );
                        points.push(learning.sample_points(pixel, index).point(kind, 0));
                    } else {
                        let sample = learned.sample_points(pixel, index);
                        points.extend((0..count).map(|j| sample.point(kind, j)));
                    }
                }
                assert!(
                    points
                        .iter()
                        .copied()
                        .eq((0..points.len() as u64).map(|p| (0, p))),
                    "{kind:?} {pixel:?}: {points:?}"
                );
            }
        }
    }

    /// Exactly one pixel of every 2×2 block learns, a block cut by the image's edge
    /// included, so a quarter of the pixels (rounded up by the blocks) and at least one;
    /// the chosen corner varies from block to block.
    #[test]
    fn one_pixel_in_every_block_learns() {
        for (w, h) in [(1, 1), (1, 5), (7, 3), (64, 64), (255, 129)] {
            let pixels = LearningPixels::new(w, h);
            let mut corners = [0u32; 4];
            for by in (0..h).step_by(2) {
                for bx in (0..w).step_by(2) {
                    let inside: Vec<(u32, u32)> = (by..(by + 2).min(h))
                        .flat_map(|y| (bx..(bx + 2).min(w)).map(move |x| (x, y)))
                        .filter(|&(x, y)| pixels.contains(x, y))
                        .collect();
                    assert_eq!(inside.len(), 1, "{w}x{h}, block ({bx}, {by})");
                    let (x, y) = inside[0];
                    corners[((y - by) * 2 + x - bx) as usize] += 1;
                }
            }
            if (w, h) == (64, 64) {
                // 1024 blocks: each corner about 256 times (binomial sd 14).
                assert!(
                    corners.iter().all(|&c| (200..=312).contains(&c)),
                    "{corners:?}"
                );
            }
        }
    }

    /// Pixels whose light estimates spread more than their samples do ask for the most
    /// light samples; otherwise the optimum's square-root law gives the count.
    #[test]
    fn counts_follow_the_variance_and_cost_optimum() {
        let sample = |nee: [f32; 2], bsdf: [f32; 2], rest: f32| SampleParts {
            total: rest + nee[0] + nee[1] + bsdf[0] + bsdf[1],
            nee,
            bsdf,
            current: 0,
            rays: [10, 11, 13, 17],
            split: true,
        };
        // rest = ±1, light shares ±1 (opposite, so the whole is rest): V_nee = 2 (a - b)² = 8,
        // V_bsdf = 0; costs C₀ = 1, C_nee = 1, C_bsdf = 2.
        let mut stats = SplitStats::default();
        let mut pixel = PixelParts::default();
        for i in 0..4000 {
            let rest = if i % 2 == 0 { 1.0 } else { -1.0 };
            let (a, b) = if i % 4 < 2 { (1.0, -1.0) } else { (-1.0, 1.0) };
            let s = sample([a, b], [0.0, 0.0], rest);
            pixel.add(&s);
            stats.add_rays(&s);
        }
        stats.add_pixel(&pixel);
        // Whole-sample variance 1 (the shares cancel), so V₀ = 1 - 8/2 is clamped to 1 %:
        // the light estimates' spread dominates and the count is the largest.
        assert_eq!(stats.choose(), Split { nee: 16, bsdf: 1 });

        // Shares ±s with s² = 2/9: V_nee = 8 s² = 16/9, V₀ = 1 - 16/9 / 2 = 1/9, so
        // n_nee = sqrt(16/9 × 1 / (1/9 × 1)) = 4.
        let share = (2.0f32 / 9.0).sqrt();
        let mut stats = SplitStats::default();
        let mut pixel = PixelParts::default();
        for i in 0..4000 {
            let rest = if i % 2 == 0 { 1.0 } else { -1.0 };
            let (a, b) = if i % 4 < 2 {
                (share, -share)
            } else {
                (-share, share)
            };
            let s = sample([a, b], [0.0, 0.0], rest);
            pixel.add(&s);
            stats.add_rays(&s);
        }
        stats.add_pixel(&pixel);
        assert_eq!(stats.choose(), Split { nee: 4, bsdf: 1 });
    }

    /// A black image (or one the camera sees directly only) splits nothing.
    #[test]
    fn nothing_to_learn_splits_nothing() {
        assert_eq!(SplitStats::default().choose(), Split { nee: 1, bsdf: 1 });
    }
}
