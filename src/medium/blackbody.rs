//! Light emitted by hot gas: the radiance per unit length of a medium at a temperature, by
//! Planck's law (fire and explosions from a temperature grid).
//!
//! The brightness is Cycles' Principled Volume's, which Blender users calibrate fire
//! against: σ T⁴ / π × 10⁻⁶ per metre (Stefan-Boltzmann's radiant exitance over π, scaled so
//! that flames of 1000-2000 K are a few units bright), times a blackbody intensity and a
//! tint. The colour is the chromaticity of Planck's spectrum at that temperature in linear
//! Rec.709 with luminance 1: the spectrum integrated against the CIE 1931 2° colour-matching
//! functions (Wyman, Sloan and Shirley's multi-lobe fit, within about 1 % of the tables),
//! XYZ to Rec.709 under D65, negative channels (deep red below about 1000 K is outside the
//! gamut) clamped to 0. Below 800 K the colour is held at 800 K's, where the light is
//! invisible anyway, as Cycles and OSL do.
//!
//! Grids are sampled at every tentative collision, so [`Glow`] tabulates the radiance by
//! temperature once per medium.

use glam::{DVec3, Vec3};

/// Stefan-Boltzmann's constant over π, times Cycles' 10⁻⁶ (radiance per metre per K⁴).
const SIGMA_OVER_PI: f64 = 5.670_374_419e-8 * 1e-6 / std::f64::consts::PI;

/// The coldest temperature whose colour is computed (colder ones take its colour).
const COLDEST: f64 = 800.0;

/// Entries of a [`Glow`] table.
const TABLE: usize = 2048;

/// The colour of a blackbody at `kelvin`: linear Rec.709 of luminance 1 (channels clamped
/// to non-negative, so the luminance of deep reds is a little above 1).
pub fn colour(kelvin: f64) -> Vec3 {
    let t = kelvin.max(COLDEST);
    // Planck's spectral radiance up to a constant factor, over 360-830 nm in 1 nm steps.
    const HC_OVER_K: f64 = 1.438_776_877e-2; // m K
    let mut xyz = DVec3::ZERO;
    for nm in 360..=830 {
        let lambda = f64::from(nm);
        let metres = lambda * 1e-9;
        let planck = 1.0 / (metres.powi(5) * ((HC_OVER_K / (metres * t)).exp() - 1.0));
        xyz += planck * cie_1931(lambda);
    }
    let xyz = xyz / xyz.y;
    let rgb = DVec3::new(
        3.240_454_2 * xyz.x - 1.537_138_5 * xyz.y - 0.498_531_4 * xyz.z,
        -0.969_266_0 * xyz.x + 1.876_010_8 * xyz.y + 0.041_556_0 * xyz.z,
        0.055_643_4 * xyz.x - 0.204_025_9 * xyz.y + 1.057_225_2 * xyz.z,
    );
    rgb.max(DVec3::ZERO).as_vec3()
}

/// The CIE 1931 2° colour-matching functions at `nm` (Wyman, Sloan and Shirley 2013,
/// multi-lobe piecewise Gaussian fit).
fn cie_1931(nm: f64) -> DVec3 {
    let g = |mu: f64, below: f64, above: f64| {
        let s = if nm < mu { below } else { above };
        (-0.5 * ((nm - mu) / s).powi(2)).exp()
    };
    DVec3::new(
        1.056 * g(599.8, 37.9, 31.0) + 0.362 * g(442.0, 16.0, 26.7) - 0.065 * g(501.1, 20.4, 26.2),
        0.821 * g(568.8, 46.9, 40.5) + 0.286 * g(530.9, 16.3, 31.1),
        1.217 * g(437.0, 11.8, 36.0) + 0.681 * g(459.0, 26.0, 13.8),
    )
}

/// The radiance per metre emitted at `kelvin` (before intensity and tint).
pub fn radiance(kelvin: f64) -> Vec3 {
    if !(kelvin > 0.0) {
        return Vec3::ZERO;
    }
    colour(kelvin) * (SIGMA_OVER_PI * kelvin.powi(4)) as f32
}

/// The emission of a medium by the value of its temperature grid: radiance per render-space
/// unit of length, tabulated over the grid's values and interpolated linearly.
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
    /// The glow of values up to `largest` (at least the grid's largest value), each
    /// `kelvin_per_unit` kelvin, scaled by `scale` (intensity × tint × metres per
    /// render-space unit); `None` where it gives no light.
    pub fn new(largest: f32, kelvin_per_unit: f32, scale: Vec3) -> Option<Self> {
        if !(largest > 0.0 && kelvin_per_unit > 0.0 && scale.max_element() > 0.0) {
            return None;
        }
        let step = largest / (TABLE - 1) as f32;
        let table: Vec<Vec3> = (0..TABLE)
            .map(|i| radiance(f64::from(i as f32 * step * kelvin_per_unit)) * scale)
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

    /// The chromaticity of the colour (back to XYZ) at `kelvin`.
    fn chromaticity(kelvin: f64) -> (f64, f64) {
        let c = colour(kelvin).as_dvec3();
        let x = 0.412_456_4 * c.x + 0.357_576_1 * c.y + 0.180_437_5 * c.z;
        let y = 0.212_672_9 * c.x + 0.715_152_2 * c.y + 0.072_175_0 * c.z;
        let z = 0.019_333_9 * c.x + 0.119_192_0 * c.y + 0.950_304_1 * c.z;
        (x / (x + y + z), y / (x + y + z))
    }

    /// The colours lie on the Planckian locus: CIE illuminant A (a blackbody at 2856 K,
    /// x 0.44757, y 0.40745) and the locus at 6500 K (x 0.3135, y 0.3237, CIE 15), with
    /// luminance 1; hotter is bluer.
    #[test]
    fn colours_follow_the_planckian_locus() {
        for (kelvin, x, y) in [(2856.0, 0.44757, 0.40745), (6500.0, 0.3135, 0.3237)] {
            let (cx, cy) = chromaticity(kelvin);
            assert!(
                (cx - x).abs() < 2e-3 && (cy - y).abs() < 2e-3,
                "{kelvin} K: ({cx:.5}, {cy:.5}) against ({x}, {y})"
            );
            let l = crate::color::luminance(colour(kelvin));
            assert!((l - 1.0).abs() < 1e-3, "{kelvin} K: luminance {l}");
        }
        let ratio = |k: f64| {
            let c = colour(k);
            c.z / c.x
        };
        assert!(ratio(1500.0) < ratio(3000.0) && ratio(3000.0) < ratio(10000.0));
        assert_eq!(colour(300.0), colour(800.0));
    }

    /// The radiance follows T⁴ at Cycles' scale, and the table interpolates it and bounds it.
    #[test]
    fn the_table_interpolates_and_bounds_the_radiance() {
        let l = crate::color::luminance(radiance(1000.0));
        assert!(
            (f64::from(l) / (SIGMA_OVER_PI * 1e12) - 1.0).abs() < 0.05,
            "{l}"
        );
        let glow = Glow::new(3.0, 1000.0, Vec3::ONE).unwrap();
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
        assert!(Glow::new(3.0, 0.0, Vec3::ONE).is_none());
        assert!(Glow::new(0.0, 1000.0, Vec3::ONE).is_none());
    }
}
