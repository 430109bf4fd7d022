//! Chi-square goodness-of-fit tests of sampling routines against their densities, in the
//! manner of Mitsuba's `chi2` tests: histogram N samples over a grid of equal-measure cells,
//! integrate the density over every cell (adaptive Simpson), pool cells whose expected count
//! is below 5, and reject when the p-value of Pearson's statistic is below the significance.
//!
//! Significance: the whole suite allows a 1% false-alarm rate, split over its tests with the
//! Šidák correction; every test uses a fixed seed, so a run is deterministic.

use glam::{Vec2, Vec3};
use std::f64::consts::PI;

/// Number of chi-square tests in the suite (for the Šidák correction).
pub const SUITE_TESTS: u32 = 127;
/// Suite-wide false-alarm rate.
pub const SUITE_SIGNIFICANCE: f64 = 0.01;

/// Per-test significance so that the suite's false-alarm rate is [`SUITE_SIGNIFICANCE`].
pub fn significance() -> f64 {
    1.0 - (1.0 - SUITE_SIGNIFICANCE).powf(1.0 / SUITE_TESTS as f64)
}

/// A rectangular domain [x0, x1] × [y0, y1] and its map to the sampled space.
pub struct Domain {
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub cells: (usize, usize),
}

impl Domain {
    /// The unit sphere as (cos θ, φ): equal-area cells, Jacobian 1.
    pub fn sphere() -> Self {
        Self {
            x: (-1.0, 1.0),
            y: (0.0, 2.0 * PI),
            cells: (24, 48),
        }
    }

    /// A plane rectangle.
    pub fn plane(x: (f64, f64), y: (f64, f64)) -> Self {
        Self {
            x,
            y,
            cells: (32, 32),
        }
    }

    fn cell_of(&self, p: (f64, f64)) -> Option<usize> {
        let fx = (p.0 - self.x.0) / (self.x.1 - self.x.0);
        let fy = (p.1 - self.y.0) / (self.y.1 - self.y.0);
        if !(0.0..=1.0).contains(&fx) || !(0.0..=1.0).contains(&fy) {
            return None;
        }
        let i = ((fx * self.cells.0 as f64) as usize).min(self.cells.0 - 1);
        let j = ((fy * self.cells.1 as f64) as usize).min(self.cells.1 - 1);
        Some(j * self.cells.0 + i)
    }
}

/// Direction to (cos θ, φ).
pub fn to_sphere(d: Vec3) -> (f64, f64) {
    let d = d.as_dvec3().normalize();
    let phi = d.y.atan2(d.x).rem_euclid(2.0 * PI);
    (d.z.clamp(-1.0, 1.0), phi)
}

/// (cos θ, φ) to a direction.
pub fn from_sphere(z: f64, phi: f64) -> Vec3 {
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
}

fn simpson(f: &impl Fn(f64, f64) -> f64, x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
    let (xm, ym) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let corners = f(x0, y0) + f(x1, y0) + f(x0, y1) + f(x1, y1);
    let edges = f(xm, y0) + f(xm, y1) + f(x0, ym) + f(x1, ym);
    (x1 - x0) * (y1 - y0) / 36.0 * (corners + 4.0 * edges + 16.0 * f(xm, ym))
}

#[allow(clippy::too_many_arguments)]
fn adaptive(
    f: &impl Fn(f64, f64) -> f64,
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    whole: f64,
    tol: f64,
    depth: u32,
) -> f64 {
    let (xm, ym) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let q = [
        simpson(f, x0, xm, y0, ym),
        simpson(f, xm, x1, y0, ym),
        simpson(f, x0, xm, ym, y1),
        simpson(f, xm, x1, ym, y1),
    ];
    let sum: f64 = q.iter().sum();
    if depth == 0 || (sum - whole).abs() <= 15.0 * tol {
        return sum + (sum - whole) / 15.0;
    }
    adaptive(f, x0, xm, y0, ym, q[0], tol / 4.0, depth - 1)
        + adaptive(f, xm, x1, y0, ym, q[1], tol / 4.0, depth - 1)
        + adaptive(f, x0, xm, ym, y1, q[2], tol / 4.0, depth - 1)
        + adaptive(f, xm, x1, ym, y1, q[3], tol / 4.0, depth - 1)
}

/// Integral of `f` over a cell: 4×4 sub-cells (so no narrow peak hides between the
/// points), each refined adaptively.
fn integrate(f: &impl Fn(f64, f64) -> f64, x0: f64, x1: f64, y0: f64, y1: f64, tol: f64) -> f64 {
    let n = 4;
    let (dx, dy) = ((x1 - x0) / n as f64, (y1 - y0) / n as f64);
    let mut total = 0.0;
    for j in 0..n {
        for i in 0..n {
            let (a0, b0) = (x0 + i as f64 * dx, y0 + j as f64 * dy);
            let whole = simpson(f, a0, a0 + dx, b0, b0 + dy);
            total += adaptive(f, a0, a0 + dx, b0, b0 + dy, whole, tol / 16.0, 7);
        }
    }
    total
}

/// Q(a, x), the regularised upper incomplete gamma function: the chi-square p-value of
/// statistic 2x with 2a degrees of freedom. Series for P when x < a + 1, Lentz's continued
/// fraction for Q otherwise (Numerical Recipes §6.2); valid for large `a`, unlike
/// `puruspe::gammq`'s quadrature branch, which returns NaN there.
pub fn upper_regularized_gamma(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let prefactor = (-x + a * x.ln() - puruspe::ln_gamma(a)).exp();
    if x < a + 1.0 {
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..100_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * prefactor).clamp(0.0, 1.0)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..100_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (prefactor * h).clamp(0.0, 1.0)
    }
}

/// Outcome of a test.
#[derive(Debug)]
pub struct Outcome {
    pub statistic: f64,
    pub dof: usize,
    pub p_value: f64,
}

/// Runs a chi-square test: `sample(i)` returns the i-th sample in domain coordinates (or
/// `None` for a failed sample, which must correspond to missing density mass), `pdf(x, y)`
/// the density with respect to the domain's measure.
pub fn test(
    name: &str,
    domain: &Domain,
    samples: usize,
    mut sample: impl FnMut(usize) -> Option<(f64, f64)>,
    pdf: impl Fn(f64, f64) -> f64,
) -> Outcome {
    let (nx, ny) = domain.cells;
    let mut observed = vec![0.0f64; nx * ny];
    for i in 0..samples {
        if let Some(p) = sample(i) {
            let cell = domain
                .cell_of(p)
                .unwrap_or_else(|| panic!("{name}: sample {p:?} outside the domain"));
            observed[cell] += 1.0;
        }
    }
    let (dx, dy) = (
        (domain.x.1 - domain.x.0) / nx as f64,
        (domain.y.1 - domain.y.0) / ny as f64,
    );
    let mut expected = vec![0.0f64; nx * ny];
    for j in 0..ny {
        for i in 0..nx {
            let (x0, y0) = (domain.x.0 + i as f64 * dx, domain.y.0 + j as f64 * dy);
            let integral = integrate(&pdf, x0, x0 + dx, y0, y0 + dy, 1e-3 / samples as f64);
            expected[j * nx + i] = integral * samples as f64;
        }
    }
    let total_expected: f64 = expected.iter().sum();
    assert!(
        total_expected <= samples as f64 * 1.001,
        "{name}: the density integrates to {} > 1",
        total_expected / samples as f64
    );
    for (c, (&o, &e)) in observed.iter().zip(&expected).enumerate() {
        assert!(
            !(o > 0.0 && e <= 0.0),
            "{name}: {o} samples in cell {c}, where the density is 0"
        );
    }
    // Pool cells in increasing order of expectation until each bin expects at least 5.
    let mut order: Vec<usize> = (0..nx * ny).filter(|&c| expected[c] > 0.0).collect();
    order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]));
    let (mut statistic, mut bins) = (0.0, 0usize);
    let (mut pool_o, mut pool_e) = (0.0, 0.0);
    for &c in &order {
        pool_o += observed[c];
        pool_e += expected[c];
        if pool_e >= 5.0 {
            statistic += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
            bins += 1;
            pool_o = 0.0;
            pool_e = 0.0;
        }
    }
    if pool_e > 0.0 {
        statistic += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
        bins += 1;
    }
    let dof = bins.saturating_sub(1).max(1);
    let p_value = upper_regularized_gamma(dof as f64 / 2.0, statistic / 2.0);
    Outcome {
        statistic,
        dof,
        p_value,
    }
}

/// Asserts that `outcome` passes at the per-test significance.
pub fn assert_passes(name: &str, outcome: &Outcome) {
    let alpha = significance();
    assert!(
        outcome.p_value >= alpha,
        "{name}: chi-square {:.1} with {} dof, p = {:.3e} < {:.3e}",
        outcome.statistic,
        outcome.dof,
        outcome.p_value,
        alpha
    );
}

/// Convenience: test a direction sampler on the sphere.
pub fn sphere(
    name: &str,
    samples: usize,
    mut sample: impl FnMut(usize) -> Option<Vec3>,
    pdf: impl Fn(Vec3) -> f64,
) {
    let outcome = test(
        name,
        &Domain::sphere(),
        samples,
        |i| sample(i).map(to_sphere),
        |z, phi| pdf(from_sphere(z, phi)),
    );
    assert_passes(name, &outcome);
}

/// Convenience: test a point sampler on a plane rectangle.
pub fn plane(
    name: &str,
    domain: &Domain,
    samples: usize,
    mut sample: impl FnMut(usize) -> Option<Vec2>,
    pdf: impl Fn(Vec2) -> f64,
) {
    let outcome = test(
        name,
        domain,
        samples,
        |i| sample(i).map(|p| (p.x as f64, p.y as f64)),
        |x, y| pdf(Vec2::new(x as f32, y as f32)),
    );
    assert_passes(name, &outcome);
}
