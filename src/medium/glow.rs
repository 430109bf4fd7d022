//! The emission of a medium by the value of a field of its own, independent of its density:
//! a temperature grid glowing by Planck's law (fire, [`Glow::blackbody`]) or an emission
//! grid whose value is the radiance, times a tint (Arnold standard_volume's emission
//! channel, [`Glow::linear`]).
//!
//! Grids are sampled at every tentative collision, so a [`Glow`] tabulates the radiance by
//! value once per medium, with a bound that never decreases for the majorants of the walks
//! that gather it.

use super::blackbody;
use glam::Vec3;

/// Entries of a [`Glow`] table.
const TABLE: usize = 2048;

/// Radiance per render-space unit of length by a field's value, tabulated over the field's
/// values and interpolated linearly (exact for [`Glow::linear`]).
#[derive(Clone, Debug)]
pub struct Glow {
    /// Radiance at values `i × step`, `i` in 0..TABLE.
    table: Vec<Vec3>,
    /// The largest channel of any entry up to `i`: a bound of the radiance at values up to
    /// `i × step` that never decreases, for majorants.
    envelope: Vec<f32>,
    step: f32,
}

impl Glow {
    /// The blackbody glow of temperatures up to `largest` (at least the grid's largest
    /// value), each `kelvin_per_unit` kelvin, scaled by `scale` (intensity × tint × metres
    /// per render-space unit); `None` where it gives no light.
    pub fn blackbody(largest: f32, kelvin_per_unit: f32, scale: Vec3) -> Option<Self> {
        if !(kelvin_per_unit > 0.0) {
            return None;
        }
        Self::tabulate(largest, |v| {
            blackbody::radiance(f64::from(v * kelvin_per_unit)) * scale
        })
    }

    /// The glow of a field whose value times `scale` (tint × metres per render-space unit)
    /// is the radiance per unit length, for values up to `largest`; negative values do not
    /// glow. `None` where it gives no light.
    pub fn linear(largest: f32, scale: Vec3) -> Option<Self> {
        Self::tabulate(largest, |v| scale * v)
    }

    /// The table of `radiance` over values up to `largest`.
    fn tabulate(largest: f32, radiance: impl Fn(f32) -> Vec3) -> Option<Self> {
        if !(largest > 0.0 && largest.is_finite()) {
            return None;
        }
        let step = largest / (TABLE - 1) as f32;
        let table: Vec<Vec3> = (0..TABLE)
            .map(|i| radiance(i as f32 * step).max(Vec3::ZERO))
            .collect();
        let envelope = table
            .iter()
            .scan(0.0f32, |m, v| {
                *m = m.max(v.max_element());
                Some(*m)
            })
            .collect();
        let glow = Self {
            table,
            envelope,
            step,
        };
        (glow.bound(largest) > 0.0 && glow.bound(largest).is_finite()).then_some(glow)
    }
    /// The radiance per unit length at grid value `v`.
    #[inline]
    pub fn at(&self, v: f32) -> Vec3 {
        let x = (v / self.step).clamp(0.0, (TABLE - 1) as f32);
        let i = (x as usize).min(TABLE - 2);
        let f = x - i as f32;
        self.table[i] * (1.0 - f) + self.table[i + 1] * f
    }

    /// A bound of the largest channel of [`Self::at`] over values up to `v`.
    #[inline]
    pub fn bound(&self, v: f32) -> f32 {
        let x = (v / self.step).clamp(0.0, (TABLE - 1) as f32);
        self.envelope[(x.ceil() as usize).min(TABLE - 1)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::blackbody::radiance;

    /// The blackbody table interpolates Planck's radiance within 0.2 % and bounds it.
    #[test]
    fn the_blackbody_table_interpolates_and_bounds_the_radiance() {
        let glow = Glow::blackbody(3.0, 1000.0, Vec3::ONE).unwrap();
        for v in [0.0f32, 0.37, 1.0, 1.91, 2.5, 3.0] {
            let exact = radiance(f64::from(v) * 1000.0);
            let table = glow.at(v);
            assert!(
                (table - exact).abs().max_element() <= 2e-3 * exact.max_element() + 1e-9,
                "{v}: {table} against {exact}"
            );
            for w in [0.0, v * 0.5, v] {
                assert!(glow.at(w).max_element() <= glow.bound(v) * (1.0 + 1e-6));
            }
        }
        assert!(Glow::blackbody(3.0, 0.0, Vec3::ONE).is_none());
        assert!(Glow::blackbody(0.0, 1000.0, Vec3::ONE).is_none());
    }

    /// The linear table is the value times the scale, 0 below 0, bounded by the largest.
    #[test]
    fn the_linear_table_is_exact() {
        let scale = Vec3::new(2.0, 0.5, 0.0);
        let glow = Glow::linear(4.0, scale).unwrap();
        for v in [0.0f32, 0.013, 1.0, 2.7, 4.0] {
            let table = glow.at(v);
            assert!(
                (table - scale * v).abs().max_element() <= 1e-5 * v.max(1.0),
                "{v}: {table}"
            );
            assert!(table.max_element() <= glow.bound(v) * (1.0 + 1e-6));
        }
        assert_eq!(glow.at(-1.0), Vec3::ZERO);
        assert!(Glow::linear(4.0, Vec3::ZERO).is_none());
        assert!(Glow::linear(f32::INFINITY, scale).is_none());
    }
}
