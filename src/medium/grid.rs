//! A heterogeneous medium: absorption and scattering scaled point by point by a density
//! grid (`scene::grid`), with one albedo and phase function throughout (smoke, clouds).
//!
//! Distances are sampled by delta tracking in the null-scattering formulation (Miller,
//! Georgiev and Jarosz 2019): tentative collisions come from a majorant, the largest
//! extinction over a coarse cell of the grid ([`MajorantGrid`], cells of [`CELL`] voxels
//! a side, walked cell by cell along the ray), so thin and dense regions of one grid each get
//! a majorant that fits them; a tentative collision is real with probability σt(x) / majorant
//! in the path's channel, and null (the flight goes on) otherwise. The majorant is the same
//! in every channel (the densest channel's), so the distances' density is too and only the
//! real/null choices differ by channel: the flight returns their weight in every channel
//! against the path's channel and each channel's probability relative to it, which the path
//! tracer combines over channels as it does for homogeneous media (spectral MIS).
//! Transmittance (shadow rays, media that only absorb) is estimated by ratio tracking over
//! the same tentative collisions, with Russian roulette once it is small (as pbrt-v4 does).
//! The random numbers of a walk come from a generator seeded by the ray and the sample
//! number that drives it, so renders stay deterministic.

use super::flight::Flight;
use super::phase::HenyeyGreenstein;
use crate::sampling::pcg::{Pcg32, mix_u64};
use crate::scene::DensityGrid;
use glam::{Affine3A, DMat4, DVec3, Vec3};
use std::sync::Arc;

/// Voxels along a side of a majorant cell.
pub const CELL: usize = 8;

/// Below this transmittance (largest channel) ratio tracking plays Russian roulette.
const ROULETTE_BELOW: f32 = 0.05;

/// The most tentative collisions of one walk: a grid whose majorant far exceeds its
/// densities along a ray (one voxel of 1e28 among thin ones) would otherwise step for
/// hours; a walk that reaches it counts as blocked. A walk of real media reaches it only
/// where the majorant's optical depth along the ray exceeds the real one some 20 000-fold
/// (past a real optical depth of about 3, ratio tracking's roulette ends it); 2^16 steps
/// take about a millisecond.
const MAX_COLLISIONS: u32 = 1 << 16;

/// Tentative collisions at least per voxel length (of the shortest side) where the grid is
/// densest, in the walks that gather emission.
const EMISSION_SAMPLES: f32 = 2.0;

/// Mixed into the seed of the walks that gather emission, so that they are independent of
/// the transmittance walks of the same segment.
const EMISSION_SALT: u32 = 0x9e37_79b9;

/// A heterogeneous medium in render space.
#[derive(Clone, Debug)]
pub struct Heterogeneous {
    density: Arc<[f32]>,
    resolution: [usize; 3],
    /// Render space to voxel space (the grid's box is [0, n] along each axis).
    to_voxel: Affine3A,
    majorants: MajorantGrid,
    /// Coefficients at density 1 per render-space unit.
    sigma_s: Vec3,
    sigma_t: Vec3,
    /// The largest channel of `sigma_t`: majorants are densities times it.
    sigma_max: f32,
    /// Emitted radiance per render-space unit of length at density 1.
    emission: Vec3,
    /// The tentative collisions per unit length and unit density of the walks that gather
    /// emission: `sigma_max`, or more where it leaves fewer than [`EMISSION_SAMPLES`] to a
    /// voxel of the densest part (a flame that barely absorbs).
    emission_rate: f32,
    phase: HenyeyGreenstein,
}

/// The largest density over each cell of [`CELL`]³ voxels, taken over every voxel that
/// trilinear interpolation inside the cell reads.
#[derive(Clone, Debug)]
struct MajorantGrid {
    cells: [usize; 3],
    max: Vec<f32>,
}

impl MajorantGrid {
    fn new(density: &[f32], res: [usize; 3]) -> Self {
        let cells = res.map(|n| n.div_ceil(CELL));
        let mut max = vec![0.0f32; cells[0] * cells[1] * cells[2]];
        // Voxels a cell's lookups read: one beyond each face (clamped).
        let span = |c: usize, n: usize| (c * CELL).saturating_sub(1)..((c + 1) * CELL + 1).min(n);
        for cz in 0..cells[2] {
            for cy in 0..cells[1] {
                for cx in 0..cells[0] {
                    let mut m = 0.0f32;
                    for z in span(cz, res[2]) {
                        for y in span(cy, res[1]) {
                            let row = (z * res[1] + y) * res[0];
                            for x in span(cx, res[0]) {
                                m = m.max(density[row + x]);
                            }
                        }
                    }
                    max[(cz * cells[1] + cy) * cells[0] + cx] = m;
                }
            }
        }
        Self { cells, max }
    }

    #[inline]
    fn at(&self, c: [usize; 3]) -> f32 {
        self.max[(c[2] * self.cells[1] + c[1]) * self.cells[0] + c[0]]
    }
}

/// The cells a ray crosses, in order: `(t_enter, t_leave, majorant density)` (3D DDA,
/// Amanatides and Woo).
struct Cells<'g> {
    grid: &'g MajorantGrid,
    cell: [i64; 3],
    step: [i64; 3],
    t_next: [f32; 3],
    t_delta: [f32; 3],
    t: f32,
    t_end: f32,
}

impl Iterator for Cells<'_> {
    type Item = (f32, f32, f32);

    #[inline]
    fn next(&mut self) -> Option<Self::Item> {
        if self.t >= self.t_end {
            return None;
        }
        let axis = if self.t_next[0] < self.t_next[1] {
            if self.t_next[0] < self.t_next[2] {
                0
            } else {
                2
            }
        } else if self.t_next[1] < self.t_next[2] {
            1
        } else {
            2
        };
        let leave = self.t_next[axis].min(self.t_end);
        let c = self.cell.map(|c| c as usize);
        let item = (self.t, leave, self.grid.at(c));
        self.t = leave;
        self.cell[axis] += self.step[axis];
        self.t_next[axis] += self.t_delta[axis];
        if self.cell[axis] < 0 || self.cell[axis] >= self.grid.cells[axis] as i64 {
            self.t_end = self.t;
        }
        Some(item)
    }
}

impl Heterogeneous {
    /// The medium of `grid` (its unit cube to world space) scaled by coefficients at density
    /// 1, per render-space unit (absorption, scattering, emitted radiance), in a render
    /// space that `world_to_render` maps world space to; `None` where it neither absorbs,
    /// scatters nor emits anywhere.
    pub fn new(
        grid: &DensityGrid,
        [sigma_a, sigma_s, emission]: [Vec3; 3],
        g: f32,
        world_to_render: DMat4,
    ) -> Option<Self> {
        let sigma_t = sigma_a + sigma_s;
        let resolution = grid.resolution.map(|r| r as usize);
        let to_voxel = DMat4::from_scale(DVec3::from(grid.resolution.map(f64::from)))
            * grid.to_world.inverse()
            * world_to_render.inverse();
        let sigma_max = sigma_t.max_element();
        let to_voxel = Affine3A::from_mat4(to_voxel.as_mat4());
        // The shortest voxel side in render space: 1 over the longest row of the linear map.
        let rows = to_voxel.matrix3.transpose();
        let longest_row = rows
            .x_axis
            .length()
            .max(rows.y_axis.length())
            .max(rows.z_axis.length());
        let densest = grid.max_density();
        let emission_rate = sigma_max.max(EMISSION_SAMPLES * longest_row / densest);
        let active = sigma_max > 0.0 || emission.max_element() > 0.0;
        (active && densest > 0.0 && emission_rate.is_finite()).then(|| Self {
            majorants: MajorantGrid::new(&grid.values, resolution),
            density: grid.values.clone(),
            resolution,
            to_voxel,
            sigma_s,
            sigma_t,
            sigma_max,
            emission,
            emission_rate,
            phase: HenyeyGreenstein::new(g),
        })
    }

    /// True where it emits light.
    #[inline]
    pub fn emits(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// The radiance its emission along the ray from `origin` in unit direction `dir` over
    /// `length` sends to the ray's origin, ∫ T(s) σe(s) ds, estimated over tentative
    /// collisions: each adds the ratio-tracked transmittance up to it times σe over the
    /// majorant there (the collisions are a Poisson process of that rate, so the sum is
    /// unbiased), with the same roulette as shadow rays.
    pub fn emitted(&self, origin: Vec3, dir: Vec3, length: f32) -> Vec3 {
        let mut rng = walk_rng(origin, dir, length.to_bits() ^ EMISSION_SALT);
        self.emitted_with(origin, dir, length, &mut rng)
    }

    fn emitted_with(&self, origin: Vec3, dir: Vec3, length: f32, rng: &mut Pcg32) -> Vec3 {
        let Some(mut walk) = self.walk(origin, dir, length, self.emission_rate) else {
            return Vec3::ZERO;
        };
        let (mut through, mut sum) = (Vec3::ONE, Vec3::ZERO);
        while let Some(collision) = walk.next(rng) {
            let Collision::At {
                density, majorant, ..
            } = collision
            else {
                break;
            };
            sum += through * self.emission * (density / majorant);
            through *= (Vec3::ONE - self.sigma_t * density / majorant).max(Vec3::ZERO);
            let largest = through.max_element();
            if largest < ROULETTE_BELOW {
                if !(rng.next_f32() < largest) {
                    break;
                }
                through /= largest;
            }
        }
        sum
    }

    /// True where light scatters inside (not only absorbed).
    #[inline]
    pub fn scatters(&self) -> bool {
        self.sigma_s.max_element() > 0.0
    }

    /// Its phase function.
    #[inline]
    pub fn phase(&self) -> &HenyeyGreenstein {
        &self.phase
    }

    /// The density at voxel-space point `q` (inside the grid's box).
    #[inline]
    fn density(&self, q: Vec3) -> f32 {
        let [nx, ny, nz] = self.resolution;
        let axis = |v: f32, n: usize| {
            let x = (v - 0.5).clamp(0.0, (n - 1) as f32);
            let i = (x as usize).min(n - 1);
            (i, (i + 1).min(n - 1), x - i as f32)
        };
        let (x0, x1, fx) = axis(q.x, nx);
        let (y0, y1, fy) = axis(q.y, ny);
        let (z0, z1, fz) = axis(q.z, nz);
        let d = &self.density;
        let at = |x: usize, y: usize, z: usize| d[(z * ny + y) * nx + x];
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let plane = |z: usize| {
            lerp(
                lerp(at(x0, y0, z), at(x1, y0, z), fx),
                lerp(at(x0, y1, z), at(x1, y1, z), fx),
                fy,
            )
        };
        lerp(plane(z0), plane(z1), fz)
    }

    /// The tentative collisions along the ray from `origin` in unit direction `dir` up to
    /// `length`, at `rate` per unit length and unit density of the majorant grid; `None`
    /// where it misses the grid.
    #[inline]
    fn walk(&self, origin: Vec3, dir: Vec3, length: f32, rate: f32) -> Option<Walk<'_>> {
        let o = self.to_voxel.transform_point3(origin);
        let d = self.to_voxel.transform_vector3(dir);
        // A ray with a NaN or infinite component (corrupt geometry upstream) crosses nothing,
        // as it hits nothing (`geometry::bvh`).
        if !(o.is_finite() && d.is_finite()) {
            return None;
        }
        let hi = Vec3::from(self.resolution.map(|n| n as f32));
        let inv = d.recip();
        let (a, b) = ((Vec3::ZERO - o) * inv, (hi - o) * inv);
        // NaN (a ray along a face) drops out of min/max.
        let t0 = a.min(b).max_element().max(0.0);
        let t1 = a.max(b).min_element().min(length);
        if !(t0 < t1) {
            return None;
        }
        let g = &self.majorants;
        let p = (o + d * t0) / CELL as f32;
        let mut cell = [0i64; 3];
        let mut step = [0i64; 3];
        let mut t_next = [f32::INFINITY; 3];
        let mut t_delta = [f32::INFINITY; 3];
        for k in 0..3 {
            cell[k] = (p[k].floor() as i64).clamp(0, g.cells[k] as i64 - 1);
            if d[k] > 0.0 {
                step[k] = 1;
                t_delta[k] = CELL as f32 / d[k];
                t_next[k] = t0 + ((cell[k] + 1) as f32 - p[k]) * t_delta[k];
            } else if d[k] < 0.0 {
                step[k] = -1;
                t_delta[k] = -(CELL as f32) / d[k];
                t_next[k] = t0 + (p[k] - cell[k] as f32) * t_delta[k];
            }
        }
        let cells = Cells {
            grid: g,
            cell,
            step,
            t_next,
            t_delta,
            t: t0,
            t_end: t1,
        };
        Some(Walk {
            medium: self,
            cells,
            o,
            d,
            t: t0,
            leave: t0,
            rate,
            majorant: 0.0,
            collisions: 0,
        })
    }

    /// Where light that enters the ray from `origin` along unit `dir`, over a segment of
    /// `length` (infinite: nothing ends it), first really interacts, by delta tracking in
    /// channel `channel` from `u`; with each channel's probability relative to `channel`'s
    /// (see the module notes). A medium that only absorbs returns the ratio-tracked
    /// transmittance as a pass.
    pub fn sample_flight(
        &self,
        origin: Vec3,
        dir: Vec3,
        u: f32,
        length: f32,
        channel: usize,
    ) -> (Flight, Vec3) {
        let mut rng = walk_rng(origin, dir, u.to_bits());
        if !self.scatters() {
            return (
                Flight::Pass {
                    weight: self.transmittance_with(origin, dir, length, &mut rng),
                },
                Vec3::ONE,
            );
        }
        let Some(mut walk) = self.walk(origin, dir, length, self.sigma_max) else {
            return (Flight::Pass { weight: Vec3::ONE }, Vec3::ONE);
        };
        let blocked = (Flight::Pass { weight: Vec3::ZERO }, Vec3::ONE);
        // The weight (f over the channel's density) and relative densities so far; both are
        // rescaled alike when they drift, which the balance heuristic does not see.
        let (mut weight, mut ratios) = (Vec3::ONE, Vec3::ONE);
        while let Some(collision) = walk.next(&mut rng) {
            let Collision::At {
                t,
                density,
                majorant,
            } = collision
            else {
                return blocked;
            };
            let sigma_t = self.sigma_t * density;
            let own = sigma_t[channel];
            if rng.next_f32() * majorant < own {
                return (
                    Flight::Scatter {
                        t,
                        weight: weight * self.sigma_s * density / own,
                    },
                    ratios * sigma_t / own,
                );
            }
            let null = (Vec3::splat(majorant) - sigma_t).max(Vec3::ZERO);
            let own_null = majorant - own;
            if !(own_null > 0.0) {
                return blocked;
            }
            let r = null / own_null;
            weight *= r;
            ratios *= r;
            let sum = ratios.element_sum();
            if !(sum > 0.0) {
                return blocked;
            }
            if !(1e-6..1e6).contains(&sum) {
                weight *= 3.0 / sum;
                ratios *= 3.0 / sum;
            }
        }
        (Flight::Pass { weight }, ratios)
    }

    /// The transmittance along the ray from `origin` in unit direction `dir` over `length`,
    /// estimated by ratio tracking (unbiased in every channel).
    pub fn transmittance(&self, origin: Vec3, dir: Vec3, length: f32) -> Vec3 {
        let mut rng = walk_rng(origin, dir, length.to_bits());
        self.transmittance_with(origin, dir, length, &mut rng)
    }

    fn transmittance_with(&self, origin: Vec3, dir: Vec3, length: f32, rng: &mut Pcg32) -> Vec3 {
        let Some(mut walk) = self.walk(origin, dir, length, self.sigma_max) else {
            return Vec3::ONE;
        };
        let mut through = Vec3::ONE;
        while let Some(collision) = walk.next(rng) {
            let Collision::At {
                density, majorant, ..
            } = collision
            else {
                return Vec3::ZERO;
            };
            through *= (Vec3::ONE - self.sigma_t * density / majorant).max(Vec3::ZERO);
            let largest = through.max_element();
            if largest < ROULETTE_BELOW {
                // Survives with probability `largest` (at most 1 / 20).
                if !(rng.next_f32() < largest) {
                    return Vec3::ZERO;
                }
                through /= largest;
            }
        }
        through
    }
}

/// A tentative collision of a walk.
enum Collision {
    /// At distance `t`, where the density is `density` under majorant extinction `majorant`.
    At { t: f32, density: f32, majorant: f32 },
    /// The walk reached [`MAX_COLLISIONS`]: it counts as blocked.
    Capped,
}

/// The tentative collisions along a ray in voxel space: exponential steps under each
/// majorant cell's extinction in turn (memoryless, so a step cut at a cell's far side starts
/// afresh in the next cell).
struct Walk<'m> {
    medium: &'m Heterogeneous,
    cells: Cells<'m>,
    o: Vec3,
    d: Vec3,
    t: f32,
    /// Tentative collisions per unit length and unit density.
    rate: f32,
    /// The far side of the current cell, and its majorant extinction.
    leave: f32,
    majorant: f32,
    collisions: u32,
}

impl Walk<'_> {
    /// The next tentative collision, from `rng`; `None` past the end of the ray.
    #[inline(always)]
    fn next(&mut self, rng: &mut Pcg32) -> Option<Collision> {
        loop {
            if self.majorant > 0.0 {
                self.collisions += 1;
                if self.collisions > MAX_COLLISIONS {
                    return Some(Collision::Capped);
                }
                self.t -= (1.0 - rng.next_f32()).ln() / self.majorant;
                if self.t < self.leave {
                    let m = self.medium;
                    return Some(Collision::At {
                        t: self.t,
                        density: m.density(self.o + self.d * self.t),
                        majorant: self.majorant,
                    });
                }
            }
            let (enter, leave, max) = self.cells.next()?;
            self.t = enter;
            self.leave = leave;
            self.majorant = max * self.rate;
        }
    }
}

/// The generator of a walk along the ray from `origin` along `dir`, driven by `bits`.
#[inline]
fn walk_rng(origin: Vec3, dir: Vec3, bits: u32) -> Pcg32 {
    let a = u64::from(origin.x.to_bits()) << 32 | u64::from(origin.y.to_bits());
    let b = u64::from(origin.z.to_bits()) << 32 | u64::from(dir.x.to_bits());
    let c = u64::from(dir.y.to_bits()) << 32 | u64::from(dir.z.to_bits());
    let seed = mix_u64(a ^ mix_u64(b ^ mix_u64(c ^ u64::from(bits))));
    Pcg32::new(seed, mix_u64(seed))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of 40 x 3 x 2 voxels over the unit cube with structure along x: smooth
    /// variation, an empty stretch wider than a majorant cell, a dense block.
    fn grid() -> DensityGrid {
        let res = [40u32, 3, 2];
        let mut values = Vec::new();
        for z in 0..2 {
            for y in 0..3 {
                for x in 0..40 {
                    let v = match x {
                        6..=17 => 0.0,
                        30..=35 => 25.0,
                        _ => 4.0 + 3.0 * (x as f32 * 0.7).sin(),
                    };
                    values.push(v * (1.0 + 0.2 * y as f32 + 0.1 * z as f32));
                }
            }
        }
        DensityGrid {
            source: "test".into(),
            resolution: res,
            to_world: DMat4::IDENTITY,
            values: values.into(),
        }
    }

    fn medium(sigma_a: Vec3, sigma_s: Vec3) -> Heterogeneous {
        Heterogeneous::new(
            &grid(),
            [sigma_a, sigma_s, Vec3::ZERO],
            0.0,
            DMat4::IDENTITY,
        )
        .unwrap()
    }

    /// The optical depth along the ray at density 1, by the midpoint rule.
    fn depth(m: &Heterogeneous, origin: Vec3, dir: Vec3, length: f32) -> f64 {
        let Some(Walk { cells, o, d, .. }) = m.walk(origin, dir, length, 1.0) else {
            return 0.0;
        };
        let (t0, t1) = (cells.t, cells.t_end);
        let n = 200_000;
        let h = (t1 - t0) as f64 / n as f64;
        (0..n)
            .map(|i| m.density(o + d * (t0 + ((i as f64 + 0.5) * h) as f32)) as f64 * h)
            .sum()
    }

    /// The mean of `n` draws of `draw` per channel and its standard error.
    fn mean_and_error(n: u32, mut draw: impl FnMut() -> Vec3) -> (glam::DVec3, glam::DVec3) {
        let (mut sum, mut squares) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
        for _ in 0..n {
            let x = draw().as_dvec3();
            sum += x;
            squares += x * x;
        }
        let mean = sum / f64::from(n);
        let se = ((squares / f64::from(n) - mean * mean) / f64::from(n)).powf(0.5);
        (mean, se)
    }

    fn ray() -> (Vec3, Vec3) {
        (
            Vec3::new(-0.1, 0.2, 0.4),
            Vec3::new(1.0, 0.25, 0.15).normalize(),
        )
    }

    /// The majorant cells of any ray cover the part of it inside the grid without gaps, in
    /// order, and bound the density at every point of them.
    #[test]
    fn majorant_cells_cover_the_ray_and_bound_the_density() {
        let m = medium(Vec3::ZERO, Vec3::ONE);
        let mut rng = Pcg32::new(9, 2);
        let mut checked = 0;
        for _ in 0..2000 {
            let origin = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 1.6 - 0.3;
            let dir =
                (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0).normalize();
            let length = if rng.next_f32() < 0.5 {
                f32::INFINITY
            } else {
                rng.next_f32()
            };
            let Some(Walk { cells, o, d, .. }) = m.walk(origin, dir, length, 1.0) else {
                continue;
            };
            let (mut t, end) = (cells.t, cells.t_end);
            for (enter, leave, max) in cells {
                assert!((enter - t).abs() < 1e-5, "a gap from {t} to {enter}");
                assert!(leave >= enter);
                for k in 0..4 {
                    let s = enter + (leave - enter) * (k as f32 + 0.5) / 4.0;
                    let density = m.density(o + d * s);
                    assert!(
                        density <= max * (1.0 + 1e-5),
                        "{density} above majorant {max}"
                    );
                    checked += 1;
                }
                t = leave;
            }
            assert!((t - end).abs() < 1e-4, "cells end at {t}, the ray at {end}");
        }
        assert!(checked > 4000, "{checked} points checked");
    }

    /// Ratio tracking is unbiased in every channel of a chromatic medium.
    #[test]
    fn ratio_tracking_estimates_the_transmittance() {
        let sigma = Vec3::new(0.02, 0.08, 0.3);
        let m = medium(sigma, Vec3::ZERO);
        let (origin, dir) = ray();
        let exact = (-sigma.as_dvec3() * depth(&m, origin, dir, f32::INFINITY)).exp();
        let mut rng = Pcg32::new(1, 1);
        let (mean, se) = mean_and_error(100_000, || {
            m.transmittance_with(origin, dir, f32::INFINITY, &mut rng)
        });
        for c in 0..3 {
            assert!(
                (mean[c] - exact[c]).abs() < 4.5 * se[c] + 1e-9,
                "transmittance {mean} ± {se}, exact {exact}"
            );
        }
        assert!(
            exact.min_element() > 0.01 && exact.max_element() < 0.9,
            "{exact}"
        );
    }

    /// The emission gathered over tentative collisions is unbiased in every channel, in a
    /// chromatic medium that absorbs and scatters and in one that only emits (whose walks
    /// take their rate from the voxel size, not the extinction), against the integral
    /// ∫ T(s) σe d(s) ds by the midpoint rule.
    #[test]
    fn emission_along_a_ray_is_unbiased() {
        let (origin, dir) = ray();
        let length = 1.2;
        for (sigma_a, sigma_s) in [
            (Vec3::new(0.5, 1.5, 4.0), Vec3::new(1.0, 0.2, 0.5)),
            (Vec3::ZERO, Vec3::ZERO),
        ] {
            let emission = Vec3::new(2.0, 1.0, 0.5);
            let m = Heterogeneous::new(&grid(), [sigma_a, sigma_s, emission], 0.0, DMat4::IDENTITY)
                .unwrap();
            // The integral along the ray by the midpoint rule.
            let Some(Walk { cells, o, d, .. }) = m.walk(origin, dir, length, 1.0) else {
                panic!("the ray misses the grid");
            };
            let (t0, t1) = (f64::from(cells.t), f64::from(cells.t_end));
            let steps = 100_000;
            let h = (t1 - t0) / f64::from(steps);
            let sigma_t = (sigma_a + sigma_s).as_dvec3();
            let (mut depth, mut exact) = (0.0, glam::DVec3::ZERO);
            for i in 0..steps {
                let density = f64::from(m.density(o + d * (t0 + (f64::from(i) + 0.5) * h) as f32));
                let through = (-sigma_t * (depth + density * h / 2.0)).exp();
                exact += through * emission.as_dvec3() * density * h;
                depth += density * h;
            }
            let mut rng = Pcg32::new(7, 3);
            let (mean, se) =
                mean_and_error(100_000, || m.emitted_with(origin, dir, length, &mut rng));
            for c in 0..3 {
                assert!(
                    (mean[c] - exact[c]).abs() < 4.5 * se[c] + 1e-9,
                    "σa {sigma_a} σs {sigma_s}: emission {mean} ± {se}, exact {exact}"
                );
                assert!(se[c] < 0.01 * exact[c], "{se} against {exact}");
            }
        }
    }

    /// Delta-tracked flights through a chromatic medium, combined over the three channels by
    /// the balance heuristic, pass with the transmittance and interact with one minus it in
    /// every channel, over a segment that ends inside the grid.
    #[test]
    fn flights_combined_over_channels_are_unbiased() {
        let (sigma_a, sigma_s) = (Vec3::new(0.01, 0.1, 0.3), Vec3::new(0.2, 0.05, 0.4));
        let sigma_t = sigma_a + sigma_s;
        let m = medium(sigma_a, sigma_s);
        let (origin, dir) = ray();
        let length = 0.9;
        let exact = (-sigma_t.as_dvec3() * depth(&m, origin, dir, length)).exp();
        let mut rng = Pcg32::new(4, 5);
        let n = 200_000;
        let (mut pass, mut interact) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
        for _ in 0..n {
            let channel = (rng.next_f32() * 3.0) as usize % 3;
            let (flight, ratios) = m.sample_flight(origin, dir, rng.next_f32(), length, channel);
            match flight.scaled(3.0 / ratios.element_sum()) {
                Flight::Pass { weight } => pass += weight.as_dvec3(),
                Flight::Scatter { t, weight } => {
                    assert!(t < length);
                    interact += (weight / sigma_s * sigma_t).as_dvec3();
                }
            }
        }
        let (pass, interact) = (pass / n as f64, interact / n as f64);
        for c in 0..3 {
            assert!(
                (pass[c] - exact[c]).abs() < 4e-3,
                "pass {pass} against {exact}"
            );
            assert!(
                (interact[c] - (1.0 - exact[c])).abs() < 4e-3,
                "interaction {interact} against {}",
                glam::DVec3::ONE - exact
            );
        }
    }

    /// A grid whose majorant dwarfs its densities (one voxel of 1e30) ends its walks.
    #[test]
    fn an_extreme_majorant_ends_its_walks() {
        let mut values = vec![1.0f32; 64];
        values[0] = 1e30;
        let g = DensityGrid {
            values: values.into(),
            resolution: [64, 1, 1],
            ..grid()
        };
        let m = Heterogeneous::new(
            &g,
            [Vec3::ZERO, Vec3::ONE, Vec3::ZERO],
            0.0,
            DMat4::IDENTITY,
        )
        .unwrap();
        let (origin, dir) = (Vec3::new(-0.5, 0.5, 0.5), Vec3::X);
        assert_eq!(m.transmittance(origin, dir, f32::INFINITY), Vec3::ZERO);
        match m.sample_flight(origin, dir, 0.5, f32::INFINITY, 0).0 {
            Flight::Scatter { t, .. } => assert!(t < 1.0 / 64.0 + 0.5),
            Flight::Pass { weight } => assert_eq!(weight, Vec3::ZERO),
        }
    }

    /// A grid of one density everywhere renders as the homogeneous medium: its flights
    /// pass as often and its transmittance matches, inside the grid's box.
    #[test]
    fn a_constant_grid_is_the_homogeneous_medium() {
        let g = DensityGrid {
            values: vec![2.0; 8].into(),
            resolution: [2, 2, 2],
            ..grid()
        };
        let sigma = Vec3::new(0.5, 1.0, 2.0);
        let m =
            Heterogeneous::new(&g, [sigma, Vec3::ZERO, Vec3::ZERO], 0.0, DMat4::IDENTITY).unwrap();
        let origin = Vec3::new(0.1, 0.2, 0.3);
        let dir = Vec3::new(0.3, 0.5, 0.4).normalize();
        let length = 0.5;
        let mut rng = Pcg32::new(2, 2);
        let n = 20_000;
        let mean = (0..n)
            .map(|_| m.transmittance_with(origin, dir, length, &mut rng))
            .sum::<Vec3>()
            / n as f32;
        let exact = (-sigma * 2.0 * length).exp();
        assert!(
            (mean - exact).abs().max_element() < 0.01,
            "{mean} against {exact}"
        );
    }
}
