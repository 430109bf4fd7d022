//! Participating media: the space inside a closed surface that absorbs and scatters light
//! along the way, not only at its boundary (fog, smoke, murky water, milk).
//!
//! A medium has absorption σa and scattering σs per unit length, per colour channel, a
//! Henyey-Greenstein phase function ([`phase`]), and may emit radiance σe per unit length
//! (flames, glowing gas: Cycles' and Karma's volume emission; pbrt-v4's σa Le). These are
//! the same everywhere ([`homogeneous`]: closed-form flights), or scaled point by point by a
//! density grid ([`grid`]: delta and ratio tracking against majorants). It fills the inside
//! of a closed surface whose material bounds it (`scene::Volume`): a glass or other
//! dielectric that refracts light into it, or an interface that does not scatter at all
//! (Mitsuba's `null` BSDF: fog in a box that is not there). The path tracer keeps the media
//! a path is inside (`integrator::media`) and asks the innermost one here how far light
//! gets, and what the medium itself emits along each segment ([`Medium::emitted`]: exact
//! for a homogeneous medium, ratio-tracked over a grid), which it adds before sampling the
//! segment's flight: emission is then gathered along every segment whatever the flight
//! does, independently of the channel the path samples in.
//!
//! Free-flight distances are sampled in one colour channel, the path's (chosen once per
//! path, uniformly): [`Homogeneous::sample_flight`] gives the weight of the sample in every
//! channel against that channel's density, and each channel's density relative to it, from
//! which the path tracer (`integrator::media`) combines the three channels' sampling of the
//! whole path by the balance heuristic (spectral MIS, as pbrt-v4 does for wavelengths and
//! Mitsuba's `volpathmis`): a chromatic medium, whose extinction differs by channel, then
//! converges in every channel. Mixing the channels' densities segment by segment instead is
//! unbiased too, but a path's weight in its densest channel becomes a product of factors
//! that are mostly near 0 and rarely near 3, whose mean finite sample counts do not reach
//! (a diffusive cube of optical depth 12 rendered 6 % dark); so is sampling by one channel
//! without MIS, as Mitsuba's `volpath` does.

pub mod blackbody;
pub mod flight;
pub mod glow;
pub mod grid;
pub mod homogeneous;
mod lattice;
pub mod phase;

pub use flight::{Flight, transmittance};
pub use grid::Heterogeneous;
pub use homogeneous::Homogeneous;

use crate::geometry::space::RenderSpace;
use crate::scene::{DensityGrid, Material};
use glam::Vec3;
use phase::HenyeyGreenstein;

/// A medium in render space.
#[derive(Clone, Debug)]
pub enum Medium {
    Homogeneous(Homogeneous),
    Heterogeneous(Box<Heterogeneous>),
}

/// The field that makes volume `v` glow (a blackbody's temperature grid or an emission
/// grid), its radiance per render-space unit of length (`per_unit`: world units per
/// render-space unit, which turns a per-world-unit coefficient into a per-render-space-unit
/// one).
fn glow_field<'g>(
    v: &crate::scene::Volume,
    grids: &'g [DensityGrid],
    per_unit: f32,
) -> Option<grid::GlowField<'g>> {
    if let Some(b) = v.blackbody {
        return Some(grid::GlowField {
            grid: grids.get(b.temperature? as usize)?,
            radiance: grid::FieldRadiance::Blackbody {
                kelvin_per_unit: b.kelvin,
                scale: b.tint * b.intensity * per_unit,
            },
        });
    }
    let e = v.emission_field?;
    Some(grid::GlowField {
        grid: grids.get(e.grid? as usize)?,
        radiance: grid::FieldRadiance::Linear {
            scale: e.tint * per_unit,
        },
    })
}

impl Medium {
    /// The medium inside material `m`'s volume, in render space `space` (coefficients per
    /// render-space unit, grids placed in it); `None` without one or where it is clear.
    pub fn inside(m: &Material, grids: &[DensityGrid], space: &RenderSpace) -> Option<Self> {
        let v = m.volume?;
        let per_unit = (1.0 / space.scale) as f32;
        let [sigma_a, sigma_s, emission] =
            [v.absorption, v.scattering, v.emission].map(|c| c * per_unit);
        match v.density {
            None => Homogeneous::emitting(sigma_a, sigma_s, v.anisotropy, emission)
                .map(Self::Homogeneous),
            Some(g) => Heterogeneous::new(
                grids.get(g as usize)?,
                [sigma_a, sigma_s, emission],
                v.anisotropy,
                space.matrix(),
                glow_field(&v, grids, per_unit),
                match v.scatter_color {
                    None => None,
                    Some(c) => Some([
                        grids.get(c[0] as usize)?,
                        grids.get(c[1] as usize)?,
                        grids.get(c[2] as usize)?,
                    ]),
                },
            )
            .map(|h| Self::Heterogeneous(Box::new(h))),
        }
    }

    /// True where a path's segments through it must be flown (it scatters, or its
    /// transmittance has no closed form); false for a homogeneous medium that only absorbs.
    #[inline]
    pub fn needs_flight(&self) -> bool {
        match self {
            Self::Homogeneous(h) => h.scatters(),
            Self::Heterogeneous(_) => true,
        }
    }

    /// True where it emits light.
    #[inline]
    pub fn emits(&self) -> bool {
        match self {
            Self::Homogeneous(h) => h.emits(),
            Self::Heterogeneous(h) => h.emits(),
        }
    }

    /// The radiance its emission along `length` of the ray from `origin` in unit direction
    /// `dir` sends to `origin` (exact, or an unbiased estimate for a grid).
    #[inline]
    pub fn emitted(&self, origin: Vec3, dir: Vec3, length: f32) -> Vec3 {
        match self {
            Self::Homogeneous(h) => h.emitted(length),
            Self::Heterogeneous(h) => h.emitted(origin, dir, length),
        }
    }

    /// Its phase function.
    #[inline]
    pub fn phase(&self) -> &HenyeyGreenstein {
        match self {
            Self::Homogeneous(h) => h.phase(),
            Self::Heterogeneous(h) => h.phase(),
        }
    }

    /// The free flight along the ray from `origin` in unit direction `dir` over `length`,
    /// sampled in `channel` from `u`, with each channel's density relative to it.
    #[inline]
    pub fn sample_flight(
        &self,
        origin: Vec3,
        dir: Vec3,
        u: f32,
        length: f32,
        channel: usize,
    ) -> (Flight, Vec3) {
        match self {
            Self::Homogeneous(h) => h.sample_flight(u, length, channel),
            Self::Heterogeneous(h) => h.sample_flight(origin, dir, u, length, channel),
        }
    }

    /// The fraction of light that crosses `length` along the ray from `origin` in unit
    /// direction `dir` (exact, or an unbiased estimate for a grid).
    #[inline]
    pub fn transmittance(&self, origin: Vec3, dir: Vec3, length: f32) -> Vec3 {
        match self {
            Self::Homogeneous(h) => h.transmittance(length),
            Self::Heterogeneous(h) => h.transmittance(origin, dir, length),
        }
    }
}
