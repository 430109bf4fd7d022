//! Energy compensation of rough microfacet lobes: the light that a single-scattering GGX
//! model loses, because it ends every path that a microfacet masks instead of letting it
//! bounce on, given back by albedo scaling (Turquin 2019), as Cycles' "Multiscatter GGX",
//! Arnold and Karma do and OpenPBR assumes.
//!
//! A lobe whose single-scattering directional albedo with a perfect reflector (F = 1) is
//! E(μo) is scaled by 1 / E(μo) where nothing is absorbed at the facets, so a white rough
//! metal or a rough clear glass loses nothing (the white furnace reads 1 for every
//! roughness). With a Fresnel term F < 1, every further bounce between facets is darkened
//! (and tinted) by F again, so a reflection lobe is scaled by
//!
//! ```text
//! 1 + F_ms (1 - E(μo)) / E(μo),   F_ms = F_avg E_avg / (1 - F_avg (1 - E_avg))
//! ```
//!
//! with F_avg the Fresnel term's cosine-weighted hemispherical average and E_avg the
//! lobe's (Kulla and Conty 2017's multiple-bounce Fresnel, with one F_avg cancelled by the
//! F the single-scattering lobe already carries, as Cycles computes it). A rough dielectric
//! (reflection and refraction together, whose Fresnel only shares light between its lobes)
//! is scaled by 1 / E(μo, η). The scale depends on `wo` alone, so sampling and densities
//! are the single-scattering lobes' and only values change; the price is reciprocity,
//! which a unidirectional path tracer does not need.
//!
//! The albedos come from `microfacet_albedo` (tabulated by
//! `tools/generate/microfacet_albedo.py` over cos θo, perceptual roughness and, for the
//! dielectric, η) and are read with linear interpolation. Anisotropic lobes take the
//! isotropic albedo of the geometric mean of their two alphas (as Cycles does). E is
//! floored at [`MIN_ALBEDO`], so the scale never exceeds 10: only nearly index-matched rough
//! interfaces at grazing angles (whose separable masking loses most of what they refract)
//! reach the floor.

use super::microfacet::SMOOTH_ALPHA;
use super::microfacet_albedo::{
    CORRELATED, CORRELATED_AVERAGE, DIELECTRIC, GLASS_T, SEPARABLE, SEPARABLE_AVERAGE, T_MAX,
};
use super::table::{bilinear, cell, linear};
use glam::Vec3;

/// The smallest albedo divided by.
pub const MIN_ALBEDO: f32 = 0.1;

/// The Smith masking-shadowing form of a reflection lobe: height-correlated (the glTF
/// BRDF's visibility) or separable (the dielectrics', as Walter et al. and Mitsuba).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Masking {
    Correlated,
    Separable,
}

/// Perceptual roughness of GGX `alpha`.
#[inline]
fn roughness(alpha: f32) -> f32 {
    alpha.max(0.0).sqrt()
}

/// Single-scattering directional albedo with F = 1 of a GGX reflection lobe of `alpha` at
/// cos θo = `cos`.
#[inline]
pub fn reflection_albedo(masking: Masking, alpha: f32, cos: f32) -> f32 {
    let table = match masking {
        Masking::Correlated => &CORRELATED,
        Masking::Separable => &SEPARABLE,
    };
    bilinear(table, roughness(alpha), cos)
}

/// The cosine-weighted hemispherical average of [`reflection_albedo`].
#[inline]
pub fn average_reflection_albedo(masking: Masking, alpha: f32) -> f32 {
    let table = match masking {
        Masking::Correlated => &CORRELATED_AVERAGE,
        Masking::Separable => &SEPARABLE_AVERAGE,
    };
    linear(table, roughness(alpha))
}

/// Single-scattering directional albedo of a rough dielectric interface of relative index
/// `eta` (reflection and refraction, energy rather than radiance) at cos θo = `cos`.
#[inline]
pub fn dielectric_albedo(alpha: f32, eta: f32, cos: f32) -> f32 {
    let leaving = eta < 1.0;
    let denser = if leaving { 1.0 / eta } else { eta };
    // An infinite index (a perfect reflector) reads the table's densest plane.
    let t = if denser.is_finite() {
        (denser - 1.0) / (denser + 1.0)
    } else {
        T_MAX
    };
    let side = &DIELECTRIC[leaving as usize];
    let (k, fk) = cell(t, GLASS_T, T_MAX);
    let r = roughness(alpha);
    let a = bilinear(&side[k], r, cos);
    let b = bilinear(&side[k + 1], r, cos);
    a + (b - a) * fk
}

/// The cosine-weighted hemispherical average of Schlick's Fresnel with reflectance `f0` at
/// normal incidence: f0 + (1 - f0) / 21.
#[inline]
pub fn schlick_average(f0: Vec3) -> Vec3 {
    f0 + (Vec3::ONE - f0) / 21.0
}

/// The scale of a reflection lobe of GGX `alpha` whose Fresnel term averages `f_avg` over
/// the hemisphere, at cos θo = `cos`: 1 + F_ms (1 - E) / E (one for a smooth lobe).
#[inline]
pub fn reflection_scale(masking: Masking, alpha: f32, f_avg: Vec3, cos: f32) -> Vec3 {
    if alpha < SMOOTH_ALPHA {
        return Vec3::ONE;
    }
    let e = reflection_albedo(masking, alpha, cos).max(MIN_ALBEDO);
    let e_avg = average_reflection_albedo(masking, alpha);
    let f_ms = f_avg * e_avg / (Vec3::ONE - f_avg * (1.0 - e_avg));
    Vec3::ONE + f_ms * ((1.0 - e) / e)
}

/// The scale 1 / E of a lobe pair that absorbs nothing at its facets and whose albedo with
/// F = 1 is a reflection lobe's (a thin slab: what it does not reflect it transmits).
#[inline]
pub fn lossless_reflection_scale(masking: Masking, alpha: f32, cos: f32) -> f32 {
    if alpha < SMOOTH_ALPHA {
        return 1.0;
    }
    1.0 / reflection_albedo(masking, alpha, cos).max(MIN_ALBEDO)
}

/// The scale 1 / E of a rough dielectric interface of relative index `eta` at cos θo.
#[inline]
pub fn dielectric_scale(alpha: f32, eta: f32, cos: f32) -> f32 {
    if alpha < SMOOTH_ALPHA {
        return 1.0;
    }
    1.0 / dielectric_albedo(alpha, eta, cos).max(MIN_ALBEDO)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::dielectric::{Dielectric, ThinDielectric};
    use crate::material::gltf_pbr::GltfPbr;
    use crate::material::{Bsdf, microfacet::Ggx};
    use crate::sampling::pcg::Pcg32;
    use glam::Vec2;

    /// ∫ f cos dωi of a BSDF at `wo` by its own sampling (the mean sample weight), with
    /// its standard error; delta lobes count with their weights.
    fn albedo_by_sampling(bsdf: &Bsdf, wo: Vec3, seed: u64) -> (f64, f64) {
        let mut rng = Pcg32::new(seed, 11);
        let n = 200_000;
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let u_lobe = rng.next_f32();
            let u = Vec2::new(rng.next_f32(), rng.next_f32());
            let x = bsdf
                .sample(wo, u_lobe, u)
                .map_or(0.0, |s| s.weight.x as f64);
            sum += x;
            sum2 += x * x;
        }
        let mean = sum / n as f64;
        (mean, ((sum2 / n as f64 - mean * mean) / n as f64).sqrt())
    }

    fn direction(cos: f32) -> Vec3 {
        Vec3::new((1.0 - cos * cos).sqrt(), 0.0, cos)
    }

    /// The tables hold the albedo of lucerna's own single-scattering lobes: a GGX
    /// reflection's f cos / pdf by visible-normal sampling (G2 / G1(wo), or G1(wi)) and a
    /// rough dielectric's sample weights (without the 1/η² of radiance), averaged, agree
    /// with the tables between their samples.
    #[test]
    fn tables_hold_the_single_scattering_albedos() {
        let mut rng = Pcg32::new(5, 5);
        for case in 0..24 {
            let alpha = (0.05 + 0.95 * rng.next_f32()).powi(2);
            let cos = 0.05 + 0.95 * rng.next_f32();
            let wo = direction(cos);
            let ggx = Ggx { alpha };
            let n = 100_000;
            let (mut correlated, mut separable) = (0.0f64, 0.0f64);
            for _ in 0..n {
                let h = ggx.sample_visible_normal(wo, Vec2::new(rng.next_f32(), rng.next_f32()));
                let wi = crate::material::microfacet::reflect(wo, h);
                if wi.z > 0.0 {
                    let (lo, li) = (ggx.lambda(wo), ggx.lambda(wi));
                    correlated += ((1.0 + lo) / (1.0 + lo + li)) as f64;
                    separable += (1.0 / (1.0 + li)) as f64;
                }
            }
            let (correlated, separable) = (correlated / n as f64, separable / n as f64);
            let tc = reflection_albedo(Masking::Correlated, alpha, cos) as f64;
            let ts = reflection_albedo(Masking::Separable, alpha, cos) as f64;
            assert!(
                (correlated - tc).abs() < 4e-3,
                "{case}: α {alpha} μ {cos}: {correlated} vs {tc}"
            );
            assert!(
                (separable - ts).abs() < 4e-3,
                "{case}: α {alpha} μ {cos}: {separable} vs {ts}"
            );

            let eta = if case % 2 == 0 {
                1.1 + 2.5 * rng.next_f32()
            } else {
                1.0 / (1.1 + 2.5 * rng.next_f32())
            };
            let glass =
                Bsdf::Dielectric(Dielectric::new(eta, alpha, Vec3::ONE).with_multiscatter(false));
            let (mut sum, n) = (0.0f64, 100_000);
            let mut srng = Pcg32::new(case, 3);
            for _ in 0..n {
                let u = Vec2::new(srng.next_f32(), srng.next_f32());
                if let Some(s) = glass.sample(wo, srng.next_f32(), u) {
                    let radiance = if s.wi.z < 0.0 { eta * eta } else { 1.0 };
                    sum += (s.weight.x * radiance) as f64;
                }
            }
            let sampled = sum / n as f64;
            let table = dielectric_albedo(alpha, eta, cos) as f64;
            assert!(
                (sampled - table).abs() < 6e-3,
                "{case}: α {alpha} η {eta} μ {cos}: {sampled} vs {table}"
            );
        }
    }

    /// The white furnace of every compensated lobe: a white rough metal (both masking
    /// forms' tables through the glTF BRDF), a rough glass interface from either side and a
    /// rough thin slab reflect and transmit all the light at every roughness and angle,
    /// within the sampling's noise and the tables' interpolation (2e-3).
    #[test]
    fn compensated_lobes_lose_no_energy() {
        for (k, roughness) in [0.3f32, 0.6, 1.0].into_iter().enumerate() {
            let alpha = roughness * roughness;
            for (j, cos) in [0.15f32, 0.5, 0.9].into_iter().enumerate() {
                let wo = direction(cos);
                let seed = (k * 3 + j) as u64;
                let cases = [
                    (
                        "metal",
                        Bsdf::GltfPbr(GltfPbr::new(Vec3::ONE, 1.0, roughness, 1.5)),
                    ),
                    (
                        "glass entering",
                        Bsdf::Dielectric(Dielectric::new(1.5, alpha, Vec3::ONE)),
                    ),
                    (
                        "glass leaving",
                        Bsdf::Dielectric(Dielectric::new(1.0 / 1.5, alpha, Vec3::ONE)),
                    ),
                    (
                        "thin glass",
                        Bsdf::ThinDielectric(ThinDielectric::new(1.5, alpha, Vec3::ONE)),
                    ),
                ];
                for (name, bsdf) in cases {
                    let (mut m, se) = albedo_by_sampling(&bsdf, wo, seed);
                    if name == "glass entering" {
                        // Undo refraction's radiance scaling 1/η² on the transmitted share.
                        let t = albedo_by_sampling_transmitted(&bsdf, wo, seed);
                        m += t * (1.5f64 * 1.5 - 1.0);
                    } else if name == "glass leaving" {
                        let t = albedo_by_sampling_transmitted(&bsdf, wo, seed);
                        m += t * (1.0 / (1.5f64 * 1.5) - 1.0);
                    }
                    assert!(
                        (m - 1.0).abs() < 4.5 * se + 2e-3,
                        "{name} roughness {roughness} μ {cos}: {m} ± {se}"
                    );
                }
            }
        }
    }

    /// The transmitted part of [`albedo_by_sampling`]'s mean (same samples).
    fn albedo_by_sampling_transmitted(bsdf: &Bsdf, wo: Vec3, seed: u64) -> f64 {
        let mut rng = Pcg32::new(seed, 11);
        let n = 200_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let u_lobe = rng.next_f32();
            let u = Vec2::new(rng.next_f32(), rng.next_f32());
            if let Some(s) = bsdf.sample(wo, u_lobe, u).filter(|s| s.wi.z < 0.0) {
                sum += s.weight.x as f64;
            }
        }
        sum / n as f64
    }

    /// With a Fresnel term below one the scale gives back what further bounces between
    /// facets keep: less than for a white reflector, more than nothing, tinted towards the
    /// Fresnel colour (a gold-like F0 is scaled up more in red than in blue).
    #[test]
    fn coloured_fresnel_is_scaled_by_its_multiple_bounces() {
        let alpha = 0.64;
        let white = reflection_scale(Masking::Correlated, alpha, Vec3::ONE, 0.5);
        let e = reflection_albedo(Masking::Correlated, alpha, 0.5).max(MIN_ALBEDO);
        assert!((white.x - 1.0 / e).abs() < 1e-5);
        let gold = reflection_scale(
            Masking::Correlated,
            alpha,
            schlick_average(Vec3::new(1.0, 0.78, 0.34)),
            0.5,
        );
        assert!(gold.x > gold.y && gold.y > gold.z && gold.z > 1.0 && gold.x <= white.x + 1e-6);
        assert_eq!(
            reflection_scale(Masking::Correlated, 1e-4, Vec3::ONE, 0.5),
            Vec3::ONE
        );
        // Out-of-range and NaN inputs read the tables' edges.
        for x in [f32::NAN, -1.0, 2.0] {
            assert!(dielectric_scale(0.5, 1.5, x).is_finite());
            assert!(reflection_scale(Masking::Separable, 0.5, Vec3::ONE, x).is_finite());
        }
        assert!(
            dielectric_scale(0.5, 100.0, 0.5).is_finite()
                && dielectric_scale(0.5, 0.01, 0.5).is_finite()
        );
    }
}
