//! Participating media: the space inside a closed surface that absorbs and scatters light
//! along the way, not only at its boundary (fog, smoke, murky water, milk).
//!
//! A medium is homogeneous: absorption σa and scattering σs per unit length, per colour
//! channel, and a Henyey-Greenstein phase function ([`phase`]). It fills the inside of a
//! closed surface whose material bounds it (`scene::Volume`): a glass or other dielectric
//! that refracts light into it, or an interface that does not scatter at all (Mitsuba's
//! `null` BSDF: fog in a box that is not there). The path tracer keeps the media a path is
//! inside (`integrator::media`) and asks the innermost one here how far light gets.
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

pub mod phase;

use crate::scene::Material;
use glam::Vec3;
use phase::HenyeyGreenstein;

/// A homogeneous medium in render-space units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homogeneous {
    sigma_a: Vec3,
    sigma_s: Vec3,
    sigma_t: Vec3,
    phase: HenyeyGreenstein,
}

/// What happens to light that travels a segment of a medium, as sampled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Flight {
    /// It scatters at distance `t`; `weight` multiplies the throughput (transmittance to
    /// there times σs, over the density of that distance).
    Scatter { t: f32, weight: Vec3 },
    /// It crosses the whole segment; `weight` is the transmittance over its probability.
    Pass { weight: Vec3 },
}

impl Flight {
    /// The flight with its weight scaled by `s`.
    #[inline]
    pub fn scaled(self, s: f32) -> Self {
        match self {
            Self::Scatter { t, weight } => Self::Scatter {
                t,
                weight: weight * s,
            },
            Self::Pass { weight } => Self::Pass { weight: weight * s },
        }
    }
}

impl Homogeneous {
    /// The medium of absorption `sigma_a` and scattering `sigma_s` per render-space unit
    /// (non-negative, finite) and anisotropy `g`; `None` where it neither absorbs nor
    /// scatters (clear glass).
    pub fn new(sigma_a: Vec3, sigma_s: Vec3, g: f32) -> Option<Self> {
        let sigma_t = sigma_a + sigma_s;
        (sigma_t.max_element() > 0.0).then_some(Self {
            sigma_a,
            sigma_s,
            sigma_t,
            phase: HenyeyGreenstein::new(g),
        })
    }

    /// The medium inside material `m`'s volume, in a render space `scale` times the
    /// scene's units (coefficients per render-space unit); `None` without one or where it
    /// is clear.
    pub fn inside(m: &Material, scale: f64) -> Option<Self> {
        let per_unit = (1.0 / scale) as f32;
        m.volume.and_then(|v| {
            Self::new(
                v.absorption * per_unit,
                v.scattering * per_unit,
                v.anisotropy,
            )
        })
    }

    /// True where light scatters inside (not only absorbed).
    #[inline]
    pub fn scatters(&self) -> bool {
        self.sigma_s.max_element() > 0.0
    }

    /// Extinction σt = σa + σs per channel.
    #[inline]
    pub fn extinction(&self) -> Vec3 {
        self.sigma_t
    }

    /// Absorption per channel.
    #[inline]
    pub fn absorption(&self) -> Vec3 {
        self.sigma_a
    }

    /// Its phase function.
    #[inline]
    pub fn phase(&self) -> &HenyeyGreenstein {
        &self.phase
    }

    /// The fraction of light that crosses `length` of the medium (channels without
    /// extinction stay 1 even along an infinite length).
    #[inline]
    pub fn transmittance(&self, length: f32) -> Vec3 {
        transmittance(self.sigma_t, length)
    }

    /// Where light that enters a segment of length `length` (infinite: nothing ends it)
    /// first interacts, drawn from `u` by channel `channel`'s density; with the densities of
    /// that event in each channel relative to `channel`'s (see the module notes).
    #[inline]
    pub fn sample_flight(&self, u: f32, length: f32, channel: usize) -> (Flight, Vec3) {
        let sigma = self.sigma_t[channel];
        let t = if sigma > 0.0 {
            -(1.0 - u.min(1.0 - f32::EPSILON)).ln() / sigma
        } else {
            f32::INFINITY
        };
        if t < length {
            let tr = self.transmittance(t);
            let pdf = self.sigma_t * tr;
            let own = pdf[channel];
            if !(own > 0.0) {
                return (Flight::Pass { weight: Vec3::ZERO }, Vec3::ONE);
            }
            (
                Flight::Scatter {
                    t,
                    weight: self.sigma_s * tr / own,
                },
                pdf / own,
            )
        } else {
            let tr = self.transmittance(length);
            let own = tr[channel];
            if !(own > 0.0) {
                return (Flight::Pass { weight: Vec3::ZERO }, Vec3::ONE);
            }
            (Flight::Pass { weight: tr / own }, tr / own)
        }
    }
}

/// exp(−σ length) per channel, 1 where σ is 0 whatever the length.
#[inline]
pub fn transmittance(sigma: Vec3, length: f32) -> Vec3 {
    Vec3::select(sigma.cmpgt(Vec3::ZERO), (-sigma * length).exp(), Vec3::ONE)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::pcg::Pcg32;

    /// Combined over the three channels by the balance heuristic (each channel chosen with
    /// probability 1/3, the weight divided by the mean relative density), the flight's
    /// weights are unbiased in every channel: the passes average to the transmittance, the
    /// interactions (weight / σs · σt) to one minus it, for a chromatic medium.
    #[test]
    fn flights_combined_over_channels_are_unbiased() {
        let m = Homogeneous::new(Vec3::new(0.1, 0.5, 2.0), Vec3::new(1.0, 0.2, 0.5), 0.3).unwrap();
        let length = 0.8;
        let mut rng = Pcg32::new(7, 1);
        let n = 400_000;
        let (mut pass, mut interact) = (Vec3::ZERO, Vec3::ZERO);
        for _ in 0..n {
            let channel = (rng.next_f32() * 3.0) as usize % 3;
            let (flight, ratios) = m.sample_flight(rng.next_f32(), length, channel);
            match flight.scaled(3.0 / ratios.element_sum()) {
                Flight::Pass { weight } => pass += weight,
                Flight::Scatter { t, weight } => {
                    assert!(t < length);
                    interact += weight / m.sigma_s * m.sigma_t;
                }
            }
        }
        let tr = m.transmittance(length);
        let pass = pass / n as f32;
        let interact = interact / n as f32;
        for c in 0..3 {
            assert!((pass[c] - tr[c]).abs() < 3e-3, "pass {pass} against {tr}");
            assert!(
                (interact[c] - (1.0 - tr[c])).abs() < 3e-3,
                "interaction {interact} against {}",
                Vec3::ONE - tr
            );
        }
    }

    #[test]
    fn an_unbounded_segment_always_scatters_where_every_channel_extinguishes() {
        let m = Homogeneous::new(Vec3::ZERO, Vec3::splat(0.5), 0.0).unwrap();
        let mut rng = Pcg32::new(3, 0);
        for _ in 0..1000 {
            match m.sample_flight(rng.next_f32(), f32::INFINITY, 1).0 {
                Flight::Scatter { weight, .. } => {
                    assert!((weight - Vec3::ONE).abs().max_element() < 1e-4)
                }
                Flight::Pass { .. } => panic!("light escaped an infinite medium"),
            }
        }
    }

    #[test]
    fn clear_media_are_none() {
        assert!(Homogeneous::new(Vec3::ZERO, Vec3::ZERO, 0.0).is_none());
        let absorbing = Homogeneous::new(Vec3::ONE, Vec3::ZERO, 0.0).unwrap();
        assert!(!absorbing.scatters());
        assert_eq!(absorbing.transmittance(f32::INFINITY), Vec3::ZERO);
    }
}
