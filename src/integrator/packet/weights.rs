//! Russian roulette and the MIS heuristics in lanes, each with the scalar code's operations
//! in its order, so that a lane's result is the scalar kernel's to the bit.

use super::super::mis::{Mis, Technique};
use super::super::roulette::{ROULETTE_CAP, ROULETTE_CAP_DEPTH, RussianRoulette};
use crate::geometry::triangle::Lanes;
use crate::simd::{F8, LANES, U8};

/// [`RussianRoulette::survival`] in lanes, with its operations: the probability that a
/// path of throughput luminance `luminance` goes on after `depth` scattering events.
#[inline(always)]
pub(super) fn roulette_survival(rr: RussianRoulette, luminance: F8, depth: U8) -> F8 {
    match rr {
        RussianRoulette::Off | RussianRoulette::Efficiency(_) => F8::ONE,
        RussianRoulette::Fixed(p) => F8::splat(p),
        RussianRoulette::Throughput(threshold) => {
            let capped = depth.gt(U8::splat(ROULETTE_CAP_DEPTH));
            let cap = F8::select(capped, F8::splat(ROULETTE_CAP), F8::ONE);
            (luminance / F8::splat(threshold)).min(cap)
        }
    }
}

/// MIS weights of `technique` for the lanes of `lanes` (densities times sample counts):
/// the balance and default power heuristics in lanes, the others lane by lane.
#[inline(always)]
pub(super) fn mis_weights(mis: Mis, technique: Technique, own: F8, other: F8, lanes: u32) -> F8 {
    let zero = F8::ZERO;
    let w = match mis {
        Mis::Balance => own / (own + other),
        Mis::Power(2.0) => {
            let q = other / own;
            F8::ONE / (F8::ONE + q * q)
        }
        _ => {
            let (o, t) = (own.to_array(), other.to_array());
            let mut w = [0.0; LANES];
            for lane in Lanes::new(lanes) {
                w[lane] = mis.weight(technique, o[lane], t[lane]);
            }
            return F8::from_array(w);
        }
    };
    let w = F8::select(other.gt(zero), w, F8::ONE);
    F8::select(own.gt(zero), w, zero)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lanes' survival probability is `RussianRoulette::survival`'s to the bit, for
    /// every kind of roulette, at depths on both sides of the cap and across it, and for
    /// zero, tiny, huge, infinite and NaN luminances.
    #[test]
    fn lane_roulette_is_the_scalar_roulette() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let luminances = [
            0.0,
            -0.0,
            1e-30,
            0.004,
            0.05,
            0.0999,
            0.1,
            0.35,
            0.95,
            1.0,
            7.5,
            1e30,
            f32::INFINITY,
            f32::NAN,
        ];
        let depths = [0, 1, 7, 8, 9, 10, 200, u32::MAX];
        let kinds = [
            RussianRoulette::Off,
            RussianRoulette::Fixed(0.3),
            RussianRoulette::Throughput(0.1),
            RussianRoulette::Throughput(0.01),
            RussianRoulette::Efficiency(1.0),
        ];
        for rr in kinds {
            for i in 0..luminances.len() {
                let n = luminances.len();
                let lum: [f32; LANES] = std::array::from_fn(|l| luminances[(i + l) % n]);
                let depth: [u32; LANES] = std::array::from_fn(|l| depths[(i + 3 * l) % 8]);
                let lanes = roulette_survival(rr, F8::from_array(lum), U8::from_array(depth));
                for l in 0..LANES {
                    let scalar = rr.survival(lum[l], depth[l]);
                    assert_eq!(
                        lanes.lane(l).to_bits(),
                        scalar.to_bits(),
                        "{rr:?}, luminance {} at depth {}",
                        lum[l],
                        depth[l]
                    );
                }
            }
        }
    }
}
