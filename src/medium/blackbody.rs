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
//! Grids are sampled at every tentative collision, so `glow::Glow` tabulates the radiance
//! by temperature once per medium.

use glam::{DVec3, Vec3};

/// Stefan-Boltzmann's constant over π, times Cycles' 10⁻⁶ (radiance per metre per K⁴).
const SIGMA_OVER_PI: f64 = 5.670_374_419e-8 * 1e-6 / std::f64::consts::PI;

/// The coldest temperature whose colour is computed (colder ones take its colour).
const COLDEST: f64 = 800.0;

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

    /// The radiance follows T⁴ at Cycles' scale.
    #[test]
    fn the_radiance_follows_stefan_boltzmann() {
        let l = crate::color::luminance(radiance(1000.0));
        assert!(
            (f64::from(l) / (SIGMA_OVER_PI * 1e12) - 1.0).abs() < 0.05,
            "{l}"
        );
    }
}
