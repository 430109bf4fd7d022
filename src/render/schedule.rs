//! How many samples each pass takes: fixed passes, passes that fit a time budget, and
//! adaptive sampling's per-pixel counts from the film's noise estimates.

use crate::film::Film;
use crate::integrator::split::LearningPixels;

/// Samples per pixel of a pass without a time budget.
const PASS_SAMPLES: u32 = 16;

/// The samples of the next pass, `left` being the most it may take: fixed-size passes
/// without a budget. With one (`elapsed` of `budget` seconds having gone to `rendered`
/// samples per pixel, on average over the pixels): one sample to measure, then the samples
/// that fit in what remains, in the fewest passes of at most a quarter of the budget, of
/// equal size; none when less than half a sample's time remains. Every pass costs a fixed
/// time (about 3 ms on the Cornell box at 256², 2 threads, where a sample takes 65 ms: 32
/// passes of one sample against one of 32), which budgets cut into twentieths paid about
/// 15 times a second; a pass of at most a quarter of the budget still ends near it if the
/// machine slows down.
pub(super) fn next_pass(left: u32, budget: Option<f64>, elapsed: f64, rendered: f64) -> u32 {
    let Some(budget) = budget else {
        return left.min(PASS_SAMPLES);
    };
    if rendered <= 0.0 {
        return 1.min(left);
    }
    let per_sample = elapsed / rendered;
    let remaining = budget - elapsed;
    if remaining < 0.5 * per_sample {
        return 0;
    }
    let fit = (remaining / per_sample).round().max(1.0);
    let most = (budget / 4.0 / per_sample).floor().max(1.0);
    let passes = (fit / most).ceil();
    ((fit / passes).ceil() as u32).clamp(1, left)
}

/// Samples each pixel takes in one pass.
pub(super) enum PassSamples {
    /// Up to this many in all, everywhere (a pixel behind, after an interrupted pass or a
    /// resumed one, catches up).
    UpTo(u32),
    /// Per pixel, row-major over the film (adaptive sampling).
    PerPixel(Vec<u32>),
}

impl PassSamples {
    /// The split learning's pass: `n` samples in each of `film`'s learning pixels.
    pub(super) fn learning(film: &Film, pixels: LearningPixels, n: u32) -> Self {
        let w = film.window;
        Self::PerPixel(
            (w.y..w.y + w.height)
                .flat_map(|y| (w.x..w.x + w.width).map(move |x| (x, y)))
                .map(|(x, y)| if pixels.contains(x, y) { n } else { 0 })
                .collect(),
        )
    }

    /// Samples to take at film pixel `pixel`, which has taken `taken`.
    #[inline]
    pub(super) fn at(&self, pixel: usize, taken: u32) -> u32 {
        match self {
            Self::UpTo(total) => total.saturating_sub(taken),
            Self::PerPixel(counts) => counts[pixel],
        }
    }
}

/// Adaptive sampling's next pass: the samples each pixel still needs, or all zero when
/// every pixel has stopped.
///
/// The allocation that minimises the image's relMSE for the time spent gives pixel p a
/// sample count n_p = K·sqrt(v_p / c_p) (v_p: per-sample relative variance, c_p: rays per
/// sample); K is set so that the predicted relMSE, mean of v_p / n_p, equals the threshold
/// squared. Equivalently, a pixel stops once one more sample would lower the error per ray
/// by less than an image-wide amount: it stops on its own variance estimate, against a
/// threshold derived from the noise target. v_p and c_p come from the pixel's eight
/// neighbours, not from its own samples, so that the decision to stop a pixel does not
/// depend directly on the values averaged into it; what remains (its share of K, and its
/// neighbours' sample counts) is second order, and `tests/it/plan.rs` measures the bias.
/// A pixel at most doubles its count in a pass, so that later passes decide on better
/// estimates, and deficits under a sixteenth of its count wait for a later pass.
pub(super) fn adaptive_pass(film: &Film, threshold: f64, most: u32) -> Vec<u32> {
    let (w, h) = (film.width as usize, film.height as usize);
    let mut variance = vec![0.0f64; w * h];
    let mut cost = vec![1.0f64; w * h];
    let mut samples = vec![0u32; w * h];
    for tile in &film.tiles {
        for ty in 0..tile.height {
            for tx in 0..tile.width {
                let p = (ty * tile.width + tx) as usize;
                let out = film.index(tile.x0 + tx, tile.y0 + ty);
                samples[out] = tile.samples_at(p);
                if let Some((v, c)) = tile.pixel_statistics(p) {
                    variance[out] = v;
                    cost[out] = c.max(1.0);
                }
            }
        }
    }
    // Leave-one-out neighbourhood means (the pixel itself when it has no neighbour).
    let neighbourhood = |values: &[f64], x: usize, y: usize| {
        let (mut sum, mut n) = (0.0, 0u32);
        for ny in y.saturating_sub(1)..(y + 2).min(h) {
            for nx in x.saturating_sub(1)..(x + 2).min(w) {
                if (nx, ny) != (x, y) {
                    sum += values[ny * w + nx];
                    n += 1;
                }
            }
        }
        if n == 0 {
            values[y * w + x]
        } else {
            sum / n as f64
        }
    };
    let estimates: Vec<(f64, f64)> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            (neighbourhood(&variance, x, y), neighbourhood(&cost, x, y))
        })
        .collect();
    let k = estimates.iter().map(|(v, c)| (v * c).sqrt()).sum::<f64>()
        / ((w * h) as f64 * threshold * threshold);
    estimates
        .iter()
        .zip(&samples)
        .map(|(&(v, c), &n)| {
            let wanted = (k * (v / c).sqrt()).ceil().min(most as f64) as u32;
            let deficit = wanted.saturating_sub(n);
            if deficit == 0 || deficit < n / 16 {
                0
            } else {
                deficit.min(n.max(1))
            }
        })
        .collect()
}

/// Scales a pass down to `allowed` samples in all (a time budget's share).
pub(super) fn fit_pass(counts: &mut [u32], allowed: f64) {
    let total: u64 = counts.iter().map(|&c| c as u64).sum();
    if (total as f64) <= allowed {
        return;
    }
    let scale = allowed / total as f64;
    for c in counts {
        *c = (*c as f64 * scale).floor() as u32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::options::MAX_SPP;

    #[test]
    fn passes_fit_the_budget() {
        assert_eq!(next_pass(100, None, 0.0, 0.0), 16);
        assert_eq!(next_pass(4, None, 0.0, 0.0), 4);
        assert_eq!(next_pass(MAX_SPP, Some(10.0), 0.0, 0.0), 1);
        // 0.1 s a sample, 10 s budget: 90 samples left, in four passes of at most 25.
        assert_eq!(next_pass(MAX_SPP, Some(10.0), 1.0, 10.0), 23);
        // 0.07 s a sample, 1 s budget: 13 samples left, in five passes of at most 3.
        assert_eq!(next_pass(MAX_SPP, Some(1.0), 0.07, 1.0), 3);
        assert_eq!(next_pass(MAX_SPP, Some(1.0), 0.7, 10.0), 2);
        // A learning pass that took a quarter of the pixels' first 4 samples counts as one.
        assert_eq!(next_pass(MAX_SPP, Some(1.0), 0.07, 0.25 * 4.0), 3);
        // Near the end: what fits, then nothing.
        assert_eq!(next_pass(MAX_SPP, Some(10.0), 9.7, 97.0), 3);
        assert_eq!(next_pass(MAX_SPP, Some(10.0), 9.97, 100.0), 0);
        // The sample count still caps a budget.
        assert_eq!(next_pass(2, Some(10.0), 0.1, 62.0), 2);
    }
}
