//! A homogeneous medium: the same absorption, scattering and phase function everywhere, so
//! that free flights and transmittance have closed forms (exponential distances).

use super::flight::{Flight, transmittance};
use super::phase::HenyeyGreenstein;
use glam::Vec3;

/// A homogeneous medium in render-space units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homogeneous {
    sigma_a: Vec3,
    sigma_s: Vec3,
    sigma_t: Vec3,
    /// Emitted radiance per render-space unit of length.
    emission: Vec3,
    phase: HenyeyGreenstein,
}

impl Homogeneous {
    /// The medium of absorption `sigma_a` and scattering `sigma_s` per render-space unit
    /// (non-negative, finite) and anisotropy `g`; `None` where it neither absorbs nor
    /// scatters (clear glass).
    pub fn new(sigma_a: Vec3, sigma_s: Vec3, g: f32) -> Option<Self> {
        Self::emitting(sigma_a, sigma_s, g, Vec3::ZERO)
    }

    /// The same, emitting `emission` (radiance per render-space unit of length); `None`
    /// where it neither absorbs, scatters nor emits.
    pub fn emitting(sigma_a: Vec3, sigma_s: Vec3, g: f32, emission: Vec3) -> Option<Self> {
        let sigma_t = sigma_a + sigma_s;
        (sigma_t.max_element() > 0.0 || emission.max_element() > 0.0).then_some(Self {
            sigma_a,
            sigma_s,
            sigma_t,
            emission,
            phase: HenyeyGreenstein::new(g),
        })
    }

    /// True where it emits light.
    #[inline]
    pub fn emits(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// The radiance its emission along `length` of it sends to the segment's start: per
    /// channel ∫ exp(−σt s) σe ds = σe (1 − exp(−σt length)) / σt, σe length where nothing
    /// attenuates (nothing along an infinite length, which no closed volume has).
    #[inline]
    pub fn emitted(&self, length: f32) -> Vec3 {
        let along = |s: f32| {
            if s > 0.0 {
                // exp_m1 keeps the thin limit (σt length ≪ 1) exact.
                -(-s * length).exp_m1() / s
            } else if length.is_finite() {
                length
            } else {
                0.0
            }
        };
        self.emission * Vec3::from(self.sigma_t.to_array().map(along))
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
