//! What a free flight through a medium samples: where light interacts along a segment, or
//! that it crosses it, with the sample's weight.

use glam::Vec3;

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

/// exp(−σ length) per channel, 1 where σ is 0 whatever the length.
#[inline]
pub fn transmittance(sigma: Vec3, length: f32) -> Vec3 {
    Vec3::select(sigma.cmpgt(Vec3::ZERO), (-sigma * length).exp(), Vec3::ONE)
}
