//! Efficiency-aware Russian roulette and splitting, after Rath et al. 2022 ("EARS:
//! Efficiency-Aware Russian Roulette and Splitting").
//!
//! At a path vertex v with throughput w (luminance), the factor
//!
//! ```text
//! q(v) = w · sqrt(M2(v) / V_pixel) · sqrt(C_pixel / C(v))
//! ```
//!
//! minimises variance × cost of the image estimate when the sub-path leaving v is either
//! continued with probability q (q < 1, Russian roulette) or split into q copies (q > 1,
//! stochastic rounding of the count, each weighted 1/q). M2(v) is the second moment of the
//! luminance of the radiance estimate leaving v per unit throughput, C(v) the rays that
//! sub-path costs, V_pixel the variance of one pixel sample and C_pixel its cost.
//!
//! What this implementation does, and how it differs from the paper:
//! - M2 and C are learned in a hashed grid over render-space position and the dominant axis
//!   of the geometric normal (the paper uses an adaptive spatio-directional octree, which
//!   also resolves the outgoing direction; ours cannot tell glossy lobes apart).
//! - V_pixel is the image's mean relative variance of a pixel sample times the pixel's
//!   squared mean (blurred over 3×3 pixels, plus 0.01 so that black pixels stay finite),
//!   and C_pixel the image's mean cost of a pixel sample. The paper does the same with a
//!   denoised image for the pixel means; we use the noisy means of earlier passes.
//! - Learning is progressive but short: passes of 1, 1, 2, 4, 8 samples per pixel learn
//!   (the first with throughput roulette, each later one deciding with everything recorded
//!   before it) until [`LEARNING_SAMPLES`]; later passes only decide, which saves the
//!   bookkeeping (about a fifth of the render time). A decision never uses the sample it
//!   affects, so the estimator stays unbiased; statistics are merged in tile order, so the
//!   image does not depend on the thread count.
//! - q is clamped to [1/32, max split] (`efficiency:MAX_SPLIT`) and a pixel sample may
//!   branch into at most [`MAX_BRANCHES`] paths; cells with too few samples fall back to
//!   throughput roulette. The default max split is 1 (roulette only): the costs C(v) are
//!   learned under the policy of the early passes, and once splitting compounds along a
//!   path they underestimate what a split sub-path costs, so splitting overshoots. On the
//!   indirect room, at equal time, `efficiency:4` took an eighth of the samples of
//!   `efficiency:1` and was about 0.7× as efficient (tools/experiments/results/lecture).

use crate::color::luminance;
use glam::Vec3;
use std::collections::HashMap;

/// Grid cells per render-space unit (render space spans about [-1, 1]).
const CELLS_PER_UNIT: f32 = 32.0;
/// Hash table size (a power of two).
const TABLE_SIZE: usize = 1 << 19;
/// Samples a cell needs before its statistics are trusted.
const MIN_CELL_SAMPLES: u32 = 16;
/// Smallest survival factor.
const MIN_FACTOR: f32 = 1.0 / 32.0;
/// Added to a pixel's squared mean so that relative variances of black pixels stay finite.
const RELATIVE_EPSILON: f64 = 0.01;
/// Most paths one pixel sample may branch into.
pub const MAX_BRANCHES: u32 = 64;
/// Samples per pixel after which the statistics are frozen.
pub const LEARNING_SAMPLES: u32 = 16;

/// Running sums of one cell: second moment of the radiance per unit throughput, cost in
/// rays, sub-paths seen.
#[derive(Clone, Copy, Debug, Default)]
struct CellSums {
    second_moment: f64,
    cost: f64,
    count: u32,
}

/// Running sums of one pixel's samples: luminance, its square, cost in rays, count.
#[derive(Clone, Copy, Debug, Default)]
struct PixelSums {
    sum: f64,
    squares: f64,
    cost: f64,
    count: u32,
}

/// The learned state, frozen while a pass renders.
#[derive(Clone, Debug)]
pub struct Ears {
    width: u32,
    height: u32,
    max_split: f32,
    cells: Vec<CellSums>,
    pixels: Vec<PixelSums>,
    /// Per cell, sqrt(M2 / C), or NaN when unknown.
    cell_term: Vec<f32>,
    /// Per pixel, sqrt(C_pixel / V_pixel), or NaN when unknown.
    pixel_term: Vec<f32>,
    /// True once a pass has been recorded.
    active: bool,
}

/// Hasher for keys that are hashes already (cell and pixel indices).
#[derive(Default, Clone, Copy)]
pub struct IdentityHasher(u64);

impl std::hash::Hasher for IdentityHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 << 8) | b as u64;
        }
    }
    fn write_u32(&mut self, i: u32) {
        self.0 = i as u64;
    }
}

type IndexMap<V> = HashMap<u32, V, std::hash::BuildHasherDefault<IdentityHasher>>;

/// Hash-grid cell of a vertex at render-space `p` with geometric normal `n`.
#[inline]
pub fn cell(p: Vec3, n: Vec3) -> u32 {
    let g = (p * CELLS_PER_UNIT).floor().as_ivec3();
    let a = n.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    let bucket = 2 * axis + u32::from(n[axis as usize] < 0.0);
    let h = (g.x as u32).wrapping_mul(0x8da6b343)
        ^ (g.y as u32).wrapping_mul(0xd8163841)
        ^ (g.z as u32).wrapping_mul(0xcb1ab31f)
        ^ bucket.wrapping_mul(0x165667b1);
    crate::sampling::pcg::hash_u32(h) & (TABLE_SIZE as u32 - 1)
}

impl Ears {
    /// Empty statistics for an image of `width` × `height`, splitting at most `max_split`.
    pub fn new(width: u32, height: u32, max_split: f32) -> Self {
        let n = (width * height) as usize;
        Self {
            width,
            height,
            max_split,
            cells: vec![CellSums::default(); TABLE_SIZE],
            pixels: vec![PixelSums::default(); n],
            cell_term: vec![f32::NAN; TABLE_SIZE],
            pixel_term: vec![f32::NAN; n],
            active: false,
        }
    }

    /// The factor for a vertex in `cell` on a path of pixel `pixel` with throughput
    /// luminance `w`; `None` when the statistics do not know the cell or the pixel.
    #[inline]
    pub fn factor(&self, pixel: usize, cell: u32, w: f32) -> Option<f32> {
        let q = w * self.cell_term[cell as usize] * self.pixel_term[pixel];
        (self.active && q.is_finite()).then(|| q.clamp(MIN_FACTOR, self.max_split))
    }

    /// Adds what a pass learned (the caller merges tiles in order).
    pub fn merge(&mut self, learned: &Learning) {
        for (&cell, s) in &learned.cells {
            let c = &mut self.cells[cell as usize];
            c.second_moment += s.second_moment;
            c.cost += s.cost;
            c.count += s.count;
        }
        for (&pixel, s) in &learned.pixels {
            let p = &mut self.pixels[pixel as usize];
            p.sum += s.sum;
            p.squares += s.squares;
            p.cost += s.cost;
            p.count += s.count;
        }
    }

    /// Recomputes the per-cell and per-pixel terms from all statistics so far.
    pub fn refresh(&mut self) {
        for (term, c) in self.cell_term.iter_mut().zip(&self.cells) {
            *term = if c.count >= MIN_CELL_SAMPLES && c.cost > 0.0 {
                (c.second_moment / c.cost).sqrt() as f32
            } else {
                f32::NAN
            };
        }
        // Per pixel, the mean and variance of one sample (from two samples on).
        let stats: Vec<Option<(f64, f64)>> = self
            .pixels
            .iter()
            .map(|p| {
                (p.count >= 2).then(|| {
                    let n = p.count as f64;
                    let mean = p.sum / n;
                    (mean, ((p.squares - p.sum * mean) / (n - 1.0)).max(0.0))
                })
            })
            .collect();
        // Image-wide relative variance and cost: a few heavy-tailed samples of one pixel
        // mostly underestimate its variance badly, the image's average does not.
        let (mut relative, mut cost, mut known) = (0.0, 0.0, 0.0);
        for (s, p) in stats.iter().zip(&self.pixels) {
            if let Some((mean, var)) = s {
                relative += var / (mean * mean + RELATIVE_EPSILON);
                cost += p.cost / p.count as f64;
                known += 1.0;
            }
        }
        if known == 0.0 || relative <= 0.0 {
            return;
        }
        let (relative, cost) = (relative / known, cost / known);
        let (w, h) = (self.width as i64, self.height as i64);
        for y in 0..h {
            for x in 0..w {
                let (mut sum, mut n) = (0.0, 0.0);
                for (xx, yy) in (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy))) {
                    if (0..w).contains(&xx)
                        && (0..h).contains(&yy)
                        && let Some((mean, _)) = stats[(yy * w + xx) as usize]
                    {
                        sum += mean;
                        n += 1.0;
                    }
                }
                let i = (y * w + x) as usize;
                self.pixel_term[i] = if stats[i].is_some() {
                    let mean = sum / n;
                    (cost / (relative * (mean * mean + RELATIVE_EPSILON))).sqrt() as f32
                } else {
                    f32::NAN
                };
            }
        }
        self.active = true;
    }
}

/// One vertex whose sub-path is still being traced.
#[derive(Clone, Copy, Debug)]
struct OpenVertex {
    cell: u32,
    depth: u32,
    /// Throughput luminance at the vertex.
    w: f32,
    /// Luminance of the contributions found after it so far.
    gathered: f32,
    rays_at_start: u64,
}

/// What one tile learns in a pass: per-cell and per-pixel sums.
#[derive(Clone, Debug, Default)]
pub struct Learning {
    cells: IndexMap<CellSums>,
    pixels: IndexMap<PixelSums>,
    /// Vertices of the current pixel sample, ancestors first.
    open: Vec<OpenVertex>,
}

impl Learning {
    /// Opens a vertex of the current path, `rays` traced so far.
    #[inline]
    pub fn open(&mut self, cell: u32, depth: u32, w: f32, rays: u64) {
        self.open.push(OpenVertex {
            cell,
            depth,
            w,
            gathered: 0.0,
            rays_at_start: rays,
        });
    }

    /// Number of open vertices (to close a branch's own on return).
    #[inline]
    pub fn mark(&self) -> usize {
        self.open.len()
    }

    /// A contribution found at `depth` belongs to every open vertex before that depth.
    #[inline]
    pub fn gathered(&mut self, value: Vec3, depth: u32) {
        let l = luminance(value);
        if !(l > 0.0) || !l.is_finite() {
            return;
        }
        for v in self.open.iter_mut().filter(|v| v.depth < depth) {
            v.gathered += l;
        }
    }

    /// Closes the vertices opened after `mark`, `rays` traced so far: their sub-paths
    /// are complete.
    pub fn close(&mut self, mark: usize, rays: u64) {
        for v in self.open.drain(mark..) {
            if !(v.w > 0.0) {
                continue;
            }
            let radiance = (v.gathered / v.w) as f64;
            let s = self.cells.entry(v.cell).or_default();
            s.second_moment += radiance * radiance;
            s.cost += (rays - v.rays_at_start) as f64;
            s.count += 1;
        }
    }

    /// Records a finished pixel sample: its beauty and its cost in rays.
    pub fn pixel_sample(&mut self, pixel: u32, beauty: Vec3, rays: u64) {
        let l = luminance(beauty) as f64;
        if !l.is_finite() {
            return;
        }
        let s = self.pixels.entry(pixel).or_default();
        s.sum += l;
        s.squares += l * l;
        s.cost += rays as f64;
        s.count += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contributions_reach_only_earlier_vertices_and_factors_follow_the_formula() {
        let mut learning = Learning::default();
        learning.open(cell(Vec3::ZERO, Vec3::Y), 0, 1.0, 0);
        learning.open(cell(Vec3::splat(0.5), Vec3::X), 1, 0.5, 2);
        learning.gathered(Vec3::splat(0.2), 1); // NEE at vertex 0: vertex 0 only
        learning.gathered(Vec3::splat(0.1), 2); // found from vertex 1: both
        learning.close(0, 10);
        let a = learning.cells[&cell(Vec3::ZERO, Vec3::Y)];
        let b = learning.cells[&cell(Vec3::splat(0.5), Vec3::X)];
        assert!((a.second_moment - 0.3f64.powi(2)).abs() < 1e-6 && a.cost == 10.0);
        assert!((b.second_moment - 0.2f64.powi(2)).abs() < 1e-6 && b.cost == 8.0);

        let mut ears = Ears::new(1, 1, 8.0);
        let mut learned = Learning::default();
        for _ in 0..MIN_CELL_SAMPLES {
            learned.open(7, 1, 1.0, 0);
            learned.gathered(Vec3::ONE, 2);
            learned.close(0, 4);
            learned.pixel_sample(0, Vec3::splat(2.0), 8);
            learned.pixel_sample(0, Vec3::splat(4.0), 8);
        }
        ears.merge(&learned);
        assert!(ears.factor(0, 7, 1.0).is_none(), "inactive before refresh");
        ears.refresh();
        // Cell: M2 = 1, C = 4. Pixel: 16 twos and 16 fours, mean 3, variance 32/31,
        // relative variance (32/31) / (9 + 0.01), cost 8.
        let q = ears.factor(0, 7, 0.5).unwrap();
        let v: f32 = 32.0 / 31.0;
        let expected = 0.5 * (1.0f32 / 4.0).sqrt() * (8.0 / v).sqrt();
        assert!((q - expected).abs() < 1e-4, "{q} vs {expected}");
        assert_eq!(
            ears.factor(0, 7, 1e3),
            Some(8.0),
            "clamped to the maximum split"
        );
        assert!(ears.factor(0, 8, 1.0).is_none(), "unknown cell");
    }
}
