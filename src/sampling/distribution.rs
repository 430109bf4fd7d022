//! Distributions built from tabulated non-negative weights: an alias table for discrete
//! choices (light selection) and piecewise-constant densities in 1D and 2D (environment
//! maps, pixel filters).

use glam::Vec2;

/// A discrete distribution sampled in O(1) (Walker's alias method, Vose's construction).
#[derive(Clone, Debug)]
pub struct AliasTable {
    /// Per bin: probability of keeping the bin, and the bin to use otherwise.
    bins: Vec<(f32, u32)>,
    pmf: Vec<f32>,
}

impl AliasTable {
    /// A table proportional to `weights`; `None` when no weight is positive and finite.
    pub fn new(weights: &[f32]) -> Option<Self> {
        let clean = |w: f32| {
            if w.is_finite() && w > 0.0 {
                w as f64
            } else {
                0.0
            }
        };
        let total: f64 = weights.iter().map(|&w| clean(w)).sum();
        if !(total > 0.0) || weights.len() > u32::MAX as usize {
            return None;
        }
        let n = weights.len();
        let pmf: Vec<f32> = weights.iter().map(|&w| (clean(w) / total) as f32).collect();
        let mut scaled: Vec<f64> = weights
            .iter()
            .map(|&w| clean(w) / total * n as f64)
            .collect();
        let mut bins = vec![(1.0f32, 0u32); n];
        let (mut small, mut large): (Vec<usize>, Vec<usize>) =
            (0..n).partition(|&i| scaled[i] < 1.0);
        while let (Some(s), Some(&l)) = (small.pop(), large.last()) {
            bins[s] = (scaled[s] as f32, l as u32);
            scaled[l] -= 1.0 - scaled[s];
            if scaled[l] < 1.0 {
                large.pop();
                small.push(l);
            }
        }
        // Leftovers are 1 up to rounding.
        for i in small.into_iter().chain(large) {
            bins[i] = (1.0, i as u32);
        }
        Some(Self { bins, pmf })
    }

    /// Number of outcomes.
    pub fn len(&self) -> usize {
        self.bins.len()
    }

    /// True when the table has no outcome (never: construction requires a positive weight).
    pub fn is_empty(&self) -> bool {
        self.bins.is_empty()
    }

    /// Draws an outcome with one uniform `u` in [0, 1); returns it and its probability.
    #[inline]
    pub fn sample(&self, u: f32) -> (usize, f32) {
        let n = self.bins.len();
        let x = u as f64 * n as f64;
        let i = (x as usize).min(n - 1);
        let frac = (x - i as f64) as f32;
        let (keep, alias) = self.bins[i];
        let chosen = if frac < keep { i } else { alias as usize };
        (chosen, self.pmf[chosen])
    }

    /// Probability of outcome `i`.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf[i]
    }

    /// Per outcome: the probability of keeping its bin, the outcome taken otherwise, and
    /// its probability (for a copy laid out for SIMD lanes, `light::lanes`).
    pub fn bins(&self) -> impl Iterator<Item = (f32, u32, f32)> + '_ {
        self.bins
            .iter()
            .zip(&self.pmf)
            .map(|(&(keep, alias), &pmf)| (keep, alias, pmf))
    }
}

/// A piecewise-constant density on [0, 1) with `n` equal bins.
#[derive(Clone, Debug)]
pub struct Distribution1D {
    func: Vec<f32>,
    cdf: Vec<f32>,
    integral: f32,
}

impl Distribution1D {
    /// A density proportional to `func` (non-negative); uniform if `func` integrates to 0.
    pub fn new(func: &[f32]) -> Self {
        assert!(!func.is_empty());
        let n = func.len();
        let func: Vec<f32> = func
            .iter()
            .map(|&f| if f.is_finite() { f.max(0.0) } else { 0.0 })
            .collect();
        let mut cdf = Vec::with_capacity(n + 1);
        let mut acc = 0.0f64;
        cdf.push(0.0f32);
        for &f in &func {
            acc += f as f64 / n as f64;
            cdf.push(acc as f32);
        }
        let integral = acc as f32;
        if integral > 0.0 {
            for c in &mut cdf {
                *c /= integral;
            }
        } else {
            for (i, c) in cdf.iter_mut().enumerate() {
                *c = i as f32 / n as f32;
            }
        }
        cdf[n] = 1.0;
        Self {
            func,
            cdf,
            integral,
        }
    }

    /// Integral of the tabulated function over [0, 1).
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// Number of bins.
    pub fn len(&self) -> usize {
        self.func.len()
    }

    /// True if there are no bins (never: construction requires one).
    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// Samples x in [0, 1); returns x, its density and its bin.
    #[inline]
    pub fn sample(&self, u: f32) -> (f32, f32, usize) {
        let n = self.func.len();
        // Last bin whose cdf is <= u.
        let bin = self
            .cdf
            .partition_point(|&c| c <= u)
            .saturating_sub(1)
            .min(n - 1);
        let lo = self.cdf[bin];
        let width = self.cdf[bin + 1] - lo;
        let du = if width > 0.0 {
            ((u - lo) / width).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let x = ((bin as f32 + du) / n as f32).min(1.0 - f32::EPSILON / 2.0);
        (x, self.pdf_bin(bin), bin)
    }

    /// Density at bin `bin`.
    #[inline]
    pub fn pdf_bin(&self, bin: usize) -> f32 {
        if self.integral > 0.0 {
            self.func[bin] / self.integral
        } else {
            1.0
        }
    }

    /// Density at x in [0, 1).
    #[inline]
    pub fn pdf(&self, x: f32) -> f32 {
        let n = self.func.len();
        self.pdf_bin(((x * n as f32) as usize).min(n - 1))
    }
}

/// A piecewise-constant density on [0, 1)², rows (v) by a marginal, columns (u) by
/// conditionals.
#[derive(Clone, Debug)]
pub struct Distribution2D {
    conditional: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// A density proportional to `func`, given row by row (`width` values each).
    pub fn new(func: &[f32], width: usize, height: usize) -> Self {
        assert_eq!(func.len(), width * height);
        let conditional: Vec<Distribution1D> =
            func.chunks(width).map(Distribution1D::new).collect();
        let row_integrals: Vec<f32> = conditional.iter().map(|c| c.integral()).collect();
        Self {
            marginal: Distribution1D::new(&row_integrals),
            conditional,
        }
    }

    /// Integral of the tabulated function over the unit square.
    pub fn integral(&self) -> f32 {
        self.marginal.integral()
    }

    /// Samples a point of the unit square and returns it with its density.
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (v, pdf_v, row) = self.marginal.sample(u.y);
        let (x, pdf_u, _) = self.conditional[row].sample(u.x);
        (Vec2::new(x, v), pdf_u * pdf_v)
    }

    /// Density at a point of the unit square.
    #[inline]
    pub fn pdf(&self, p: Vec2) -> f32 {
        let h = self.conditional.len();
        let row = ((p.y * h as f32) as usize).min(h - 1);
        self.marginal.pdf_bin(row) * self.conditional[row].pdf(p.x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::pcg::Pcg32;

    #[test]
    fn alias_table_frequencies_match_weights() {
        let w = [1.0, 0.0, 3.0, 0.5, 10.0, f32::NAN];
        let t = AliasTable::new(&w).unwrap();
        let total: f32 = 14.5;
        let mut counts = [0usize; 6];
        let n = 400_000;
        let mut rng = Pcg32::new(1, 2);
        for _ in 0..n {
            let (i, p) = t.sample(rng.next_f32());
            assert!((p - t.pmf(i)).abs() < 1e-7);
            counts[i] += 1;
        }
        for i in 0..6 {
            let expected = if w[i].is_finite() { w[i] / total } else { 0.0 };
            assert!((t.pmf(i) - expected).abs() < 1e-6);
            let sd = (expected * (1.0 - expected) / n as f32).sqrt();
            assert!(
                (counts[i] as f32 / n as f32 - expected).abs() <= 5.0 * sd + 1e-9,
                "bin {i}"
            );
        }
        assert!(AliasTable::new(&[0.0, 0.0]).is_none());
    }

    #[test]
    fn piecewise_constant_pdf_matches_sampling() {
        let d = Distribution1D::new(&[0.0, 2.0, 1.0, 0.0, 5.0]);
        assert!((d.integral() - 8.0 / 5.0).abs() < 1e-6);
        let mut rng = Pcg32::new(3, 4);
        for _ in 0..10_000 {
            let (x, pdf, bin) = d.sample(rng.next_f32());
            assert!((0.0..1.0).contains(&x));
            assert_eq!(bin, (x * 5.0) as usize);
            assert!(pdf > 0.0 && (pdf - d.pdf(x)).abs() < 1e-5);
        }
        let d2 = Distribution2D::new(&[1.0, 0.0, 2.0, 1.0], 2, 2);
        let (p, pdf) = d2.sample(Vec2::new(0.3, 0.9));
        assert!((pdf - d2.pdf(p)).abs() < 1e-5);
    }
}
