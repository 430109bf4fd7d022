#!/usr/bin/env python3
"""Generate src/material/microfacet_albedo.rs: the directional albedo of lucerna's GGX
lobes with single scattering, which the energy compensation of `material::energy` divides
by (the light that single-scattering microfacet models lose between facets).

    reflection, height-correlated Smith (the glTF BRDF):  E(μo, r) = ∫ D G2 / (4 μo) dωi, F = 1
    reflection, separable Smith (the dielectrics):        the same with G1(wo) G1(wi)
    rough dielectric (reflection and refraction, exact Fresnel, separable Smith, energy
    rather than radiance: no 1/η²):                       E(μo, r, η)

for wo above the surface, r the perceptual roughness (alpha = r²), μo = cos θo, and η the
relative index across the interface: above 1 entering a denser medium, below 1 leaving it.
Each table samples μo and r at SIZE evenly spaced points of [0, 1] (μo = 0 is taken at
1e-3); the dielectric's third axis is t = (η - 1) / (η + 1) (for η < 1, of 1/η) at GLASS_T
evenly spaced points of [0, T_MAX], η from 1 to 4. The averages E_avg(r) = 2 ∫ E(μ) μ dμ
are integrated over 256 values of μ.

Every entry is a mean over 96 x 96 jittered strata of GGX normals visible from wo (Dupuy
and Benyoub 2023, as `material::microfacet` samples them), of the estimator f cos θi / pdf:
G2 / G1(wo) for the correlated reflection, G1(wi) for the separable one, and
F G1(wi_r) + (1 - F) G1(wi_t) for the dielectric (each term zero where its direction leaves
its hemisphere). The standard error of an entry is below 1e-4; the Rust tests
`material::energy::tests` check the tables against lucerna's own BSDFs.

    python3 tools/generate/microfacet_albedo.py > src/material/microfacet_albedo.rs
"""
import numpy as np

SIZE = 32
GLASS_T = 16
T_MAX = 0.6  # η = 4
STRATA = 96
AVERAGE_POINTS = 256
MU_MIN = 1e-3


def strata(rng):
    i, j = np.meshgrid(np.arange(STRATA), np.arange(STRATA), indexing="ij")
    u1 = (i.ravel() + rng.random(STRATA * STRATA)) / STRATA
    u2 = (j.ravel() + rng.random(STRATA * STRATA)) / STRATA
    return u1, u2


def lam(cos, alpha):
    cos2 = np.maximum(cos * cos, 1e-12)
    tan2 = np.maximum((1 - cos2) / cos2, 0)
    return 0.5 * (np.sqrt(1 + alpha * alpha * tan2) - 1)


def visible_normals(mu, alpha, u1, u2):
    """Normals visible from wo = (sqrt(1 - μ²), 0, μ): arrays [len(mu), len(u1)]."""
    mu = mu[:, None]
    wo = np.stack(np.broadcast_arrays(np.sqrt(1 - mu * mu), 0 * mu, mu), axis=-1)
    std = wo * np.array([alpha, alpha, 1.0])
    std /= np.linalg.norm(std, axis=-1, keepdims=True)
    phi = 2 * np.pi * u1[None, :]
    z = (1 - u2[None, :]) * (1 + std[..., 2]) - std[..., 2]
    sin = np.sqrt(np.clip(1 - z * z, 0, 1))
    h = np.stack([sin * np.cos(phi) + std[..., 0], sin * np.sin(phi) + std[..., 1], z + std[..., 2]], axis=-1)
    h = h * np.array([alpha, alpha, 1.0])
    h[..., 2] = np.maximum(h[..., 2], 0)
    h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-30)
    wo = np.broadcast_to(wo, h.shape)
    return wo, h


def reflect(wo, h):
    return 2 * np.sum(wo * h, axis=-1, keepdims=True) * h - wo


def fresnel(cos_i, eta):
    cos_i = np.clip(cos_i, 0, 1)
    sin2_t = (1 - cos_i * cos_i) / (eta * eta)
    cos_t = np.sqrt(np.maximum(1 - sin2_t, 0))
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return np.where(sin2_t >= 1, 1.0, 0.5 * (rp * rp + rs * rs))


def refract(wo, h, eta):
    cos_i = np.sum(wo * h, axis=-1, keepdims=True)
    sin2_t = np.maximum(1 - cos_i * cos_i, 0) / (eta * eta)
    cos_t = np.sqrt(np.maximum(1 - sin2_t, 0))
    return -wo / eta + h * (cos_i / eta - cos_t)


def reflection_albedo(mu, r, correlated, u):
    alpha = max(r * r, 1e-4)
    wo, h = visible_normals(mu, alpha, *u)
    wi = reflect(wo, h)
    lo, li = lam(wo[..., 2], alpha), lam(wi[..., 2], alpha)
    weight = (1 + lo) / (1 + lo + li) if correlated else 1 / (1 + li)
    return np.where(wi[..., 2] > 0, weight, 0.0).mean(axis=-1)


def dielectric_albedo(mu, r, eta, u):
    alpha = max(r * r, 1e-4)
    wo, h = visible_normals(mu, alpha, *u)
    f = fresnel(np.sum(wo * h, axis=-1), eta)
    wr = reflect(wo, h)
    wt = refract(wo, h, eta)
    reflected = np.where(wr[..., 2] > 0, 1 / (1 + lam(wr[..., 2], alpha)), 0.0)
    refracted = np.where(wt[..., 2] < 0, 1 / (1 + lam(wt[..., 2], alpha)), 0.0)
    return (f * reflected + (1 - f) * refracted).mean(axis=-1)


def table_mu():
    return np.maximum(np.arange(SIZE) / (SIZE - 1), MU_MIN)


def average(albedo_of_mu):
    mu = (np.arange(AVERAGE_POINTS) + 0.5) / AVERAGE_POINTS
    return float(2 * np.mean(albedo_of_mu(mu) * mu))


def rows(values, indent="    "):
    out = []
    for row in values:
        out.append(indent + "[" + ", ".join(f"{x:.6}" for x in row) + "],")
    return out


def main():
    rng = np.random.default_rng(20261205)
    u = strata(rng)
    mu = table_mu()
    roughness = np.arange(SIZE) / (SIZE - 1)
    correlated = [reflection_albedo(mu, r, True, u) for r in roughness]
    separable = [reflection_albedo(mu, r, False, u) for r in roughness]
    correlated_avg = [average(lambda m: reflection_albedo(m, r, True, u)) for r in roughness]
    separable_avg = [average(lambda m: reflection_albedo(m, r, False, u)) for r in roughness]
    glass = []
    for side in (0, 1):
        planes = []
        for k in range(GLASS_T):
            t = T_MAX * k / (GLASS_T - 1)
            eta = (1 + t) / (1 - t)
            if side == 1:
                eta = 1 / eta
            planes.append([dielectric_albedo(mu, r, eta, u) for r in roughness])
        glass.append(planes)

    lines = [
        "//! Generated by tools/generate/microfacet_albedo.py: do not edit; one concept (data). The directional",
        "//! albedo of lucerna's single-scattering GGX lobes (see the script for the integrals),",
        f"//! cos θo and perceptual roughness each at {SIZE} evenly spaced points of [0, 1] (rows:",
        f"//! roughness); the dielectric's planes at {GLASS_T} evenly spaced t = (η - 1) / (η + 1)",
        f"//! of [0, {T_MAX}] (η or 1/η from 1 to 4), entering (η > 1) then leaving (η < 1).",
        "",
        f"pub(super) const SIZE: usize = {SIZE};",
        f"pub(super) const GLASS_T: usize = {GLASS_T};",
        f"pub(super) const T_MAX: f32 = {T_MAX};",
        "",
        "/// Reflection with height-correlated Smith masking, F = 1.",
        "#[rustfmt::skip]",
        "pub(super) static CORRELATED: [[f32; SIZE]; SIZE] = [",
        *rows(correlated),
        "];",
        "",
        "/// Its cosine-weighted hemispherical average, per roughness.",
        "#[rustfmt::skip]",
        "pub(super) static CORRELATED_AVERAGE: [f32; SIZE] = [",
        "    " + ", ".join(f"{x:.6}" for x in correlated_avg) + ",",
        "];",
        "",
        "/// Reflection with separable Smith masking, F = 1.",
        "#[rustfmt::skip]",
        "pub(super) static SEPARABLE: [[f32; SIZE]; SIZE] = [",
        *rows(separable),
        "];",
        "",
        "/// Its cosine-weighted hemispherical average, per roughness.",
        "#[rustfmt::skip]",
        "pub(super) static SEPARABLE_AVERAGE: [f32; SIZE] = [",
        "    " + ", ".join(f"{x:.6}" for x in separable_avg) + ",",
        "];",
        "",
        "/// The rough dielectric's reflection and refraction together: [side][t][roughness][cos θo].",
        "#[rustfmt::skip]",
        "pub(super) static DIELECTRIC: [[[[f32; SIZE]; SIZE]; GLASS_T]; 2] = [",
    ]
    for side in glass:
        lines.append("    [")
        for plane in side:
            lines.append("        [")
            lines.extend(rows(plane, indent="            "))
            lines.append("        ],")
        lines.append("    ],")
    lines.append("];")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
