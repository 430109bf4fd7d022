//! Rough diffuse reflection: OpenPBR's energy-preserving Oren-Nayar model (EON; Portsmouth,
//! Kutz and Hill 2025), which Cycles' Principled BSDF uses for its diffuse roughness. The
//! single-scattering part is Fujii's improved Oren-Nayar (FON)
//!
//! ```text
//! f_ss = ρ/π A (1 + σ s/t),   A = 1 / (1 + (1/2 - 2/(3π)) σ),
//! s = wi·wo - cos θi cos θo,  t = max(cos θi, cos θo) where s > 0, else 1
//! ```
//!
//! whose directional albedo E_F(μ) (at ρ = 1) has a closed form; the light it loses to
//! inter-reflections between the rough surface's facets comes back as a separate lobe
//!
//! ```text
//! f_ms = ρ_ms/π (1 - E_F(μo)) (1 - E_F(μi)) / (1 - E_avg),
//! ρ_ms = ρ² E_avg / (1 - ρ (1 - E_avg)),  E_avg = A (1 + (2/3 - 28/(15π)) σ)
//! ```
//!
//! so that a white surface reflects all the light at every roughness (the white furnace
//! reads 1), and the BRDF stays reciprocal. σ is the diffuse roughness in [0, 1] (OpenPBR's
//! `base_diffuse_roughness`, Standard Surface's `diffuse_roughness`); at 0 it is Lambert's,
//! which the callers keep for σ = 0 exactly. Sampled, as Lambert, by the cosine: the lobe is
//! broad, and its densities stay the diffuse lobe's.

use glam::Vec3;
use std::f32::consts::{FRAC_1_PI, PI};

/// FON's A coefficient: A = 1 / (1 + C1 σ).
const C1: f32 = 0.5 - 2.0 / (3.0 * PI);
/// E_avg = A (1 + C2 σ).
const C2: f32 = 2.0 / 3.0 - 28.0 / (15.0 * PI);

/// The single-scattering FON lobe's directional albedo at ρ = 1 and cos θ = `mu`.
#[inline]
fn fon_albedo(mu: f32, sigma: f32) -> f32 {
    let a = 1.0 / (1.0 + C1 * sigma);
    let b = sigma * a;
    let mu = mu.clamp(1e-6, 1.0);
    let si = (1.0 - mu * mu).max(0.0).sqrt();
    let g = si * (mu.acos() - si * mu) + (2.0 / 3.0) * ((si / mu) * (1.0 - si * si * si) - si);
    a + b * FRAC_1_PI * g
}

/// The EON BRDF f (without the cosine) of albedo `rho` and roughness `sigma` (in (0, 1]) for
/// `wo` and `wi` above the surface (local frame).
#[inline]
pub fn eval(rho: Vec3, sigma: f32, wo: Vec3, wi: Vec3) -> Vec3 {
    let (mu_i, mu_o) = (wi.z, wo.z);
    let s = wi.dot(wo) - mu_i * mu_o;
    let s_over_t = if s > 0.0 { s / mu_i.max(mu_o) } else { s };
    let a = 1.0 / (1.0 + C1 * sigma);
    let single = rho * (FRAC_1_PI * a * (1.0 + sigma * s_over_t));
    let e_avg = a * (1.0 + C2 * sigma);
    let rho_ms = rho * rho * e_avg / (Vec3::ONE - rho * (1.0 - e_avg));
    let lost = (1.0 - fon_albedo(mu_o, sigma)).max(0.0) * (1.0 - fon_albedo(mu_i, sigma)).max(0.0);
    single + rho_ms * (FRAC_1_PI * lost / (1.0 - e_avg).max(1e-7))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::pcg::Pcg32;
    use crate::sampling::warp::square_to_cosine_hemisphere;
    use glam::Vec2;

    /// ∫ f cos dωi by cosine sampling (weight f π), with its standard error.
    fn albedo(rho: Vec3, sigma: f32, wo: Vec3, seed: u64) -> (f64, f64) {
        let mut rng = Pcg32::new(seed, 1);
        let n = 200_000;
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let wi = square_to_cosine_hemisphere(Vec2::new(rng.next_f32(), rng.next_f32()));
            if wi.z <= 0.0 {
                continue;
            }
            let x = (eval(rho, sigma, wo, wi).x * PI) as f64;
            sum += x;
            sum2 += x * x;
        }
        let mean = sum / n as f64;
        (mean, ((sum2 / n as f64 - mean * mean) / n as f64).sqrt())
    }

    /// A white rough diffuse surface reflects everything (EON's white furnace), a grey one
    /// less than its albedo's worth never exceeds it, the closed-form albedo of the
    /// single-scattering lobe is the lobe's integral, and the BRDF is reciprocal.
    #[test]
    fn white_rough_diffuse_loses_no_energy() {
        for (k, sigma) in [0.1f32, 0.5, 1.0].into_iter().enumerate() {
            for (j, cos) in [0.05f32, 0.4, 0.95].into_iter().enumerate() {
                let wo = Vec3::new((1.0 - cos * cos).sqrt(), 0.0, cos);
                let seed = (3 * k + j) as u64;
                let (m, se) = albedo(Vec3::ONE, sigma, wo, seed);
                assert!(
                    (m - 1.0).abs() < 4.5 * se + 1e-4,
                    "σ {sigma} μ {cos}: {m} ± {se}"
                );
                let (grey, se) = albedo(Vec3::splat(0.5), sigma, wo, seed);
                assert!(
                    grey < 0.5 + 4.5 * se && grey > 0.4,
                    "σ {sigma} μ {cos}: {grey}"
                );
                // The single-scattering lobe alone integrates to E_F.
                let mut rng = Pcg32::new(seed, 2);
                let (n, mut sum, mut sum2) = (200_000, 0.0f64, 0.0f64);
                let a = 1.0 / (1.0 + C1 * sigma);
                for _ in 0..n {
                    let wi = square_to_cosine_hemisphere(Vec2::new(rng.next_f32(), rng.next_f32()));
                    let s = wi.dot(wo) - wi.z * wo.z;
                    let st = if s > 0.0 { s / wi.z.max(wo.z) } else { s };
                    let x = (a * (1.0 + sigma * st)) as f64;
                    sum += x;
                    sum2 += x * x;
                }
                let (mean, e) = (sum / n as f64, fon_albedo(cos, sigma) as f64);
                let se = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
                assert!(
                    (mean - e).abs() < 4.5 * se + 1e-4,
                    "σ {sigma} μ {cos}: {mean} ± {se} vs {e}"
                );
            }
        }
        let (wo, wi) = (
            Vec3::new(0.6, 0.0, 0.8),
            Vec3::new(-0.3, 0.4, 0.866).normalize(),
        );
        let rho = Vec3::new(0.9, 0.5, 0.1);
        assert!(
            (eval(rho, 0.7, wo, wi) - eval(rho, 0.7, wi, wo))
                .abs()
                .max_element()
                < 1e-6
        );
    }
}
