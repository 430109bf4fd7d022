//! A heterogeneous medium: absorption and scattering scaled point by point by a density
//! grid (`scene::grid`), with one phase function throughout and one albedo, or an albedo
//! tinted point by point by colour grids (smoke, clouds, coloured dust).
//!
//! Distances are sampled by delta tracking in the null-scattering formulation (Miller,
//! Georgiev and Jarosz 2019): tentative collisions come from a majorant, the largest
//! extinction over a coarse cell of the grid (`lattice`: cells of 8³ voxels, walked cell
//! by cell along the ray), so thin and dense regions of one grid each get
//! a majorant that fits them; a tentative collision is real with probability σt(x) / majorant
//! in the path's channel, and null (the flight goes on) otherwise. The majorant is the same
//! in every channel (the densest channel's), so the distances' density is too and only the
//! real/null choices differ by channel: the flight returns their weight in every channel
//! against the path's channel and each channel's probability relative to it, which the path
//! tracer combines over channels as it does for homogeneous media (spectral MIS). A colour
//! grid changes only the albedo, never the extinction, so it enters at real collisions
//! alone (the scattering weight there) and the walks stay as they are.
//! Transmittance (shadow rays, media that only absorb) is estimated by ratio tracking over
//! the same tentative collisions, with Russian roulette once it is small (as pbrt-v4 does).
//! The random numbers of a walk come from a generator seeded by the ray and the sample
//! number that drives it, so renders stay deterministic.
//!
//! A medium may also glow by a field of its own ([`GlowField`]: a temperature grid through
//! Planck's law, fire, or an emission grid), on its own lattice: flames reach where smoke is
//! thin, and simulations write the fields over different voxels.

use super::flight::Flight;
use super::glow::Glow;
use super::lattice::{Collision, Lattice, walk_rng};
use super::phase::HenyeyGreenstein;
use crate::sampling::pcg::Pcg32;
use crate::scene::DensityGrid;
use glam::{DMat4, Vec3};

/// Below this transmittance (largest channel) ratio tracking plays Russian roulette.
const ROULETTE_BELOW: f32 = 0.05;

/// Tentative collisions at least per voxel length (of the shortest side) where the grid is
/// densest (or hottest), in the walks that gather emission.
const EMISSION_SAMPLES: f32 = 2.0;

/// Mixed into the seed of the walks that gather emission, so that they are independent of
/// the transmittance walks of the same segment.
const EMISSION_SALT: u32 = 0x9e37_79b9;

/// A heterogeneous medium in render space.
#[derive(Clone, Debug)]
pub struct Heterogeneous {
    density: Lattice,
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
    /// Emission by a field of its own, independent of the density.
    glowing: Option<Glowing>,
    /// Colour grids (red, green, blue) that tint the scattering point by point.
    scatter_color: Option<Box<[Lattice; 3]>>,
    phase: HenyeyGreenstein,
}

/// A glowing field and the radiance it emits ([`Glow`]). Its lattice's majorants are
/// bounds of the radiance over each cell, so that the walks gathering its emission place
/// their collisions where it is bright.
#[derive(Clone, Debug)]
struct Glowing {
    field: Lattice,
    glow: Glow,
    /// Collisions per unit length and unit radiance bound: [`EMISSION_SAMPLES`] per voxel
    /// where the field is brightest.
    rate: f32,
}

/// A grid that makes a medium glow, and how its values become radiance.
pub struct GlowField<'g> {
    pub grid: &'g DensityGrid,
    pub radiance: FieldRadiance,
}

/// How a glowing field's values become radiance per render-space unit of length.
#[derive(Clone, Copy, Debug)]
pub enum FieldRadiance {
    /// Temperatures of `kelvin_per_unit` per unit value, glowing by Planck's law times
    /// `scale` (blackbody intensity × tint × metres per render-space unit).
    Blackbody { kelvin_per_unit: f32, scale: Vec3 },
    /// The value times `scale` (emission × colour × metres per render-space unit).
    Linear { scale: Vec3 },
}

impl Heterogeneous {
    /// The medium of `grid` (its unit cube to world space) scaled by coefficients at density
    /// 1, per render-space unit (absorption, scattering, emitted radiance), glowing by
    /// `glow` if given, its scattering tinted by the colour grids `scatter_color` if given
    /// (the extinction unchanged, the albedo at most 1), in a render space that
    /// `world_to_render` maps world space to; `None` where it neither absorbs, scatters nor
    /// emits anywhere.
    pub fn new(
        grid: &DensityGrid,
        [sigma_a, sigma_s, emission]: [Vec3; 3],
        g: f32,
        world_to_render: DMat4,
        glow: Option<GlowField>,
        scatter_color: Option<[&DensityGrid; 3]>,
    ) -> Option<Self> {
        let sigma_t = sigma_a + sigma_s;
        let sigma_max = sigma_t.max_element();
        let density = Lattice::new(grid, world_to_render);
        // The largest cell majorant is the largest density.
        let densest = density.largest_majorant();
        let emission_rate = if densest > 0.0 {
            sigma_max.max(EMISSION_SAMPLES * density.voxels_per_unit() / densest)
        } else {
            sigma_max
        };
        let glowing = glow.and_then(|g| Glowing::new(g, world_to_render));
        let active = densest > 0.0 && (sigma_max > 0.0 || emission.max_element() > 0.0);
        ((active || glowing.is_some()) && emission_rate.is_finite()).then(|| Self {
            density,
            sigma_s,
            sigma_t,
            sigma_max,
            emission,
            emission_rate,
            glowing,
            scatter_color: scatter_color
                .map(|c| Box::new(c.map(|g| Lattice::new(g, world_to_render)))),
            phase: HenyeyGreenstein::new(g),
        })
    }

    /// The scattering coefficient at density 1 at render-space point `p`.
    #[inline]
    fn scattering_at(&self, p: Vec3) -> Vec3 {
        match &self.scatter_color {
            None => self.sigma_s,
            Some(c) => {
                let colour = Vec3::new(c[0].value_at(p), c[1].value_at(p), c[2].value_at(p));
                (self.sigma_s * colour).min(self.sigma_t)
            }
        }
    }

    /// True where it emits light.
    #[inline]
    pub fn emits(&self) -> bool {
        self.emission.max_element() > 0.0 || self.glowing.is_some()
    }

    /// The radiance its emission along the ray from `origin` in unit direction `dir` over
    /// `length` sends to the ray's origin, ∫ T(s) σe(s) ds, estimated over tentative
    /// collisions: each adds the ratio-tracked transmittance up to it times σe over the
    /// majorant there (the collisions are a Poisson process of that rate, so the sum is
    /// unbiased), with the same roulette as shadow rays. A glowing field's emission is gathered
    /// over collisions of its own lattice, each weighted by the transmittance that the density
    /// walk has estimated up to it: the two walks are independent, so each product is an
    /// unbiased estimate of T(s) σe(s) at its point.
    pub fn emitted(&self, origin: Vec3, dir: Vec3, length: f32) -> Vec3 {
        let mut rng = walk_rng(origin, dir, length.to_bits() ^ EMISSION_SALT);
        self.emitted_with(origin, dir, length, &mut rng)
    }

    fn emitted_with(&self, origin: Vec3, dir: Vec3, length: f32, rng: &mut Pcg32) -> Vec3 {
        let mut walk = self.density.walk(origin, dir, length, self.emission_rate);
        let mut fire = self
            .glowing
            .as_ref()
            .and_then(|f| f.field.walk(origin, dir, length, f.rate).map(|w| (f, w)));
        if walk.is_none() && fire.is_none() {
            return Vec3::ZERO;
        }
        let (mut through, mut sum) = (Vec3::ONE, Vec3::ZERO);
        // The next collision of each walk (`None`: that walk is over).
        let mut next_density = walk.as_mut().and_then(|w| w.next(rng));
        let mut next_fire = fire.as_mut().and_then(|(_, w)| w.next(rng));
        loop {
            let density_first = match (&next_density, &next_fire) {
                (None, None) => break,
                (Some(Collision::At { t: a, .. }), Some(Collision::At { t: b, .. })) => a <= b,
                (Some(_), None) => true,
                (None, Some(_)) => false,
                // A capped walk counts as blocked from there on.
                (Some(Collision::Capped), _) | (_, Some(Collision::Capped)) => break,
            };
            if density_first {
                let Some(Collision::At {
                    value: density,
                    majorant,
                    ..
                }) = next_density
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
                next_density = walk.as_mut().and_then(|w| w.next(rng));
            } else if let Some((f, w)) = fire.as_mut() {
                if let Some(Collision::At {
                    value, majorant, ..
                }) = next_fire
                {
                    sum += through * f.glow.at(value) / majorant;
                }
                next_fire = w.next(rng);
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
        let Some(mut walk) = self.density.walk(origin, dir, length, self.sigma_max) else {
            return (Flight::Pass { weight: Vec3::ONE }, Vec3::ONE);
        };
        let blocked = (Flight::Pass { weight: Vec3::ZERO }, Vec3::ONE);
        // The weight (f over the channel's density) and relative densities so far; both are
        // rescaled alike when they drift, which the balance heuristic does not see.
        let (mut weight, mut ratios) = (Vec3::ONE, Vec3::ONE);
        while let Some(collision) = walk.next(&mut rng) {
            let Collision::At {
                t,
                value: density,
                majorant,
            } = collision
            else {
                return blocked;
            };
            let sigma_t = self.sigma_t * density;
            let own = sigma_t[channel];
            if rng.next_f32() * majorant < own {
                let scattering = self.scattering_at(origin + dir * t);
                return (
                    Flight::Scatter {
                        t,
                        weight: weight * scattering * density / own,
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
        let Some(mut walk) = self.density.walk(origin, dir, length, self.sigma_max) else {
            return Vec3::ONE;
        };
        let mut through = Vec3::ONE;
        while let Some(collision) = walk.next(rng) {
            let Collision::At {
                value: density,
                majorant,
                ..
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

impl Glowing {
    fn new(g: GlowField, world_to_render: DMat4) -> Option<Self> {
        let mut field = Lattice::new(g.grid, world_to_render);
        // The largest cell majorant is the largest value, before it becomes a radiance bound.
        let largest = field.largest_majorant();
        let glow = match g.radiance {
            FieldRadiance::Blackbody {
                kelvin_per_unit,
                scale,
            } => Glow::blackbody(largest, kelvin_per_unit, scale)?,
            FieldRadiance::Linear { scale } => Glow::linear(largest, scale)?,
        };
        field.map_majorants(|m| glow.bound(m));
        let rate = EMISSION_SAMPLES * field.voxels_per_unit() / field.largest_majorant();
        (rate.is_finite() && rate > 0.0).then_some(Self { field, glow, rate })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::lattice::Walk;

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
            None,
            None,
        )
        .unwrap()
    }

    /// The optical depth along the ray at density 1, by the midpoint rule.
    fn depth(m: &Heterogeneous, origin: Vec3, dir: Vec3, length: f32) -> f64 {
        let Some(Walk { cells, o, d, .. }) = m.density.walk(origin, dir, length, 1.0) else {
            return 0.0;
        };
        let (t0, t1) = (cells.t, cells.t_end);
        let n = 200_000;
        let h = (t1 - t0) as f64 / n as f64;
        (0..n)
            .map(|i| {
                m.density
                    .value(o + d * (t0 + ((i as f64 + 0.5) * h) as f32)) as f64
                    * h
            })
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
            let Some(Walk { cells, o, d, .. }) = m.density.walk(origin, dir, length, 1.0) else {
                continue;
            };
            let (mut t, end) = (cells.t, cells.t_end);
            for (enter, leave, max) in cells {
                assert!((enter - t).abs() < 1e-5, "a gap from {t} to {enter}");
                assert!(leave >= enter);
                for k in 0..4 {
                    let s = enter + (leave - enter) * (k as f32 + 0.5) / 4.0;
                    let density = m.density.value(o + d * s);
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
            let m = Heterogeneous::new(
                &grid(),
                [sigma_a, sigma_s, emission],
                0.0,
                DMat4::IDENTITY,
                None,
                None,
            )
            .unwrap();
            // The integral along the ray by the midpoint rule.
            let Some(Walk { cells, o, d, .. }) = m.density.walk(origin, dir, length, 1.0) else {
                panic!("the ray misses the grid");
            };
            let (t0, t1) = (f64::from(cells.t), f64::from(cells.t_end));
            let steps = 100_000;
            let h = (t1 - t0) / f64::from(steps);
            let sigma_t = (sigma_a + sigma_s).as_dvec3();
            let (mut depth, mut exact) = (0.0, glam::DVec3::ZERO);
            for i in 0..steps {
                let density = f64::from(
                    m.density
                        .value(o + d * (t0 + (f64::from(i) + 0.5) * h) as f32),
                );
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

    /// A glowing field on a lattice of its own (another resolution, shifted so that part of
    /// it lies outside the smoke's box, with a hot spot) glows by the unbiased integral of
    /// the smoke's transmittance times the radiance of the interpolated value: a fire's
    /// blackbody radiance of its temperature, an emission grid's value times its tint.
    #[test]
    fn glowing_field_on_its_own_lattice_emits_the_transmitted_integral() {
        let kelvin = 1000.0;
        let scale = Vec3::new(1.0, 0.8, 1.2);
        let blackbody = FieldRadiance::Blackbody {
            kelvin_per_unit: kelvin,
            scale,
        };
        let planck =
            |v: f64| (crate::medium::blackbody::radiance(v * kelvin as f64) * scale).as_dvec3();
        glowing_field_emits_the_transmitted_integral(blackbody, &planck);
        let linear = FieldRadiance::Linear { scale };
        glowing_field_emits_the_transmitted_integral(linear, &|v| scale.as_dvec3() * v);
    }

    fn glowing_field_emits_the_transmitted_integral(
        radiance: FieldRadiance,
        exact_glow: &dyn Fn(f64) -> glam::DVec3,
    ) {
        let (origin, dir) = ray();
        let length = 1.5;
        let res = [12u32, 5, 4];
        let mut values = Vec::new();
        for z in 0..res[2] {
            for y in 0..res[1] {
                for x in 0..res[0] {
                    let hot = if x == 7 { 2.5 } else { 0.0 };
                    values.push((0.2 + 0.15 * x as f32 + hot) * (1.0 + 0.1 * (y + z) as f32));
                }
            }
        }
        let temperature = DensityGrid {
            source: "temperature".into(),
            resolution: res,
            to_world: DMat4::from_translation(glam::DVec3::new(0.3, -0.1, 0.05))
                * DMat4::from_scale(glam::DVec3::new(1.2, 1.1, 0.9)),
            values: values.into(),
        };
        let (sigma_a, sigma_s) = (Vec3::new(0.05, 0.15, 0.3), Vec3::new(0.1, 0.02, 0.05));
        let m = Heterogeneous::new(
            &grid(),
            [sigma_a, sigma_s, Vec3::ZERO],
            0.0,
            DMat4::IDENTITY,
            Some(GlowField {
                grid: &temperature,
                radiance,
            }),
            None,
        )
        .unwrap();
        assert!(m.emits());
        let fire = m.glowing.as_ref().unwrap();
        let steps = 200_000;
        let h = f64::from(length) / f64::from(steps);
        let sigma_t = (sigma_a + sigma_s).as_dvec3();
        let (mut depth, mut exact) = (0.0, glam::DVec3::ZERO);
        let in_box = |q: Vec3, n: [u32; 3]| {
            q.cmpge(Vec3::ZERO).all() && q.cmple(Vec3::from(n.map(|v| v as f32))).all()
        };
        for i in 0..steps {
            let p = origin + dir * ((f64::from(i) + 0.5) * h) as f32;
            let qd = p * Vec3::new(40.0, 3.0, 2.0);
            let density = if in_box(qd, [40, 3, 2]) {
                f64::from(m.density.value(qd))
            } else {
                0.0
            };
            let qt = fire.field.to_voxel(p);
            let glow = if in_box(qt, res) {
                exact_glow(f64::from(fire.field.value(qt)))
            } else {
                glam::DVec3::ZERO
            };
            let through = (-sigma_t * (depth + density * h / 2.0)).exp();
            exact += through * glow * h;
            depth += density * h;
        }
        let mut rng = Pcg32::new(11, 5);
        let (mean, se) = mean_and_error(100_000, || m.emitted_with(origin, dir, length, &mut rng));
        for c in 0..3 {
            // The table's interpolation of the radiance is within 0.2 % of Planck's.
            assert!(
                (mean[c] - exact[c]).abs() < 4.5 * se[c] + 2e-3 * exact[c],
                "{radiance:?}: emission {mean} ± {se}, exact {exact}"
            );
            assert!(se[c] < 0.02 * exact[c], "{se} against {exact}");
        }
        assert!(exact.min_element() > 0.0, "{exact}");
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

    /// A colour grid tints the scattering where the flight scatters: the scatter weights,
    /// combined over channels, estimate ∫ T(t) min(σs c(t), σt) ρ(t) dt in every channel (c
    /// the colour on its own, coarser lattice, some of it bright enough to be clamped),
    /// against the midpoint rule, within 4.5 standard errors.
    #[test]
    fn a_colour_grid_tints_the_scattering_where_it_happens() {
        let (sigma_a, sigma_s) = (Vec3::new(0.3, 0.1, 0.2), Vec3::new(0.6, 0.9, 0.5));
        let sigma_t = sigma_a + sigma_s;
        let channel = |k: usize| {
            let mut values = Vec::new();
            for z in 0..4 {
                for y in 0..3 {
                    for x in 0..5 {
                        let v = 0.2 + 0.35 * ((x + 2 * y + 3 * z + k) % 5) as f32;
                        values.push(v);
                    }
                }
            }
            DensityGrid {
                source: format!("colour {k}"),
                resolution: [5, 3, 4],
                to_world: DMat4::IDENTITY,
                values: values.into(),
            }
        };
        let colour = [channel(0), channel(1), channel(2)];
        let m = Heterogeneous::new(
            &grid(),
            [sigma_a, sigma_s, Vec3::ZERO],
            0.0,
            DMat4::IDENTITY,
            None,
            Some([&colour[0], &colour[1], &colour[2]]),
        )
        .unwrap();
        let (origin, dir) = ray();
        let length = 0.9;
        // The integral by the midpoint rule, the transmittance carried along.
        let Some(Walk { cells, .. }) = m.density.walk(origin, dir, length, 1.0) else {
            panic!("the ray misses the grid");
        };
        let (t0, t1) = (cells.t, cells.t_end);
        let steps = 200_000;
        let h = f64::from(t1 - t0) / f64::from(steps);
        let (mut depth, mut exact) = (0.0f64, glam::DVec3::ZERO);
        let mut tinted = false;
        for i in 0..steps {
            let p = origin + dir * (t0 + ((f64::from(i) + 0.5) * h) as f32);
            let density = f64::from(m.density.value_at(p));
            let lattices = m.scatter_color.as_deref().unwrap();
            let c = Vec3::from_array([0, 1, 2].map(|k| lattices[k].value_at(p)));
            tinted |= (sigma_s * c).cmpgt(sigma_t).any();
            let scattering = (sigma_s * c).min(sigma_t).as_dvec3();
            let mid = depth + density * h / 2.0;
            exact += (-sigma_t.as_dvec3() * mid).exp() * scattering * density * h;
            depth += density * h;
        }
        assert!(tinted, "no point where the colour is clamped");
        let mut rng = Pcg32::new(11, 3);
        let (mean, se) = mean_and_error(200_000, || {
            let channel = (rng.next_f32() * 3.0) as usize % 3;
            let (flight, ratios) = m.sample_flight(origin, dir, rng.next_f32(), length, channel);
            match flight.scaled(3.0 / ratios.element_sum()) {
                Flight::Pass { .. } => Vec3::ZERO,
                Flight::Scatter { weight, .. } => weight,
            }
        });
        for c in 0..3 {
            assert!(
                (mean[c] - exact[c]).abs() < 4.5 * se[c],
                "scattered {mean} ± {se} against {exact}"
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
            None,
            None,
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
        let m = Heterogeneous::new(
            &g,
            [sigma, Vec3::ZERO, Vec3::ZERO],
            0.0,
            DMat4::IDENTITY,
            None,
            None,
        )
        .unwrap();
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
