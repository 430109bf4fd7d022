//! Dielectric interfaces that transmit: glass, water, clear plastic. The conventions are
//! pbrt-v4's and Mitsuba 3's, and the models the same as Mitsuba's `dielectric`,
//! `roughdielectric` and `thindielectric`, so that `tools/lucerna_tools/mitsuba_export.py` maps them one
//! to one:
//!
//! - [`Dielectric`]: the boundary of a volume. Smooth: exact Fresnel reflectance R picks
//!   mirror reflection (probability R) or refraction by Snell's law (1 - R), both delta
//!   lobes. Rough: the microfacet BSDF of Walter et al. 2007 with GGX normals sampled among
//!   those visible from `wo` (Heitz 2018) and separable Smith masking G1(wo) G1(wi), as
//!   Walter and Mitsuba use it (pbrt-v4 uses the height-correlated form; for transmission
//!   neither is exact, and the reference renderer decides). Refracted radiance is scaled by
//!   1/η² (η the relative index across the interface as the light crosses it, Veach 1997
//!   §5.2): a camera path entering glass carries 1/η², leaving it η², so radiance is
//!   conserved along a closed crossing while the path's throughput stays the BSDF's.
//! - [`ThinDielectric`]: an infinitely thin slab (a window pane, a soap bubble; glTF
//!   transmission without KHR_materials_volume). Light is not bent; the slab reflects
//!   R' = 2R / (1 + R) (every internal bounce summed, `fresnel::thin_slab`) and transmits
//!   1 - R'. Smooth, both are delta lobes, the transmission straight through; rough, the
//!   transmitted lobe is the reflected one mirrored through the surface (the glTF
//!   transmission extension's thin BTDF), weighted by the slab's reflectance at each
//!   microfacet.
//!
//! Rough, both are scaled by `energy`'s compensation for the light single scattering loses
//! between facets (1 / E(μo, η), and 1 / E(μo) of the reflection for the slab, whose lobes
//! share the reflection's microfacets), unless built `with_multiscatter(false)`
//! (Mitsuba's models exactly).
//!
//! Both take a transmission `tint` applied at each crossing (glTF's base colour, Mitsuba's
//! `specular_transmittance`). Directions are local with +z the shading normal on the side of
//! `wo`; `eta` is the index below the surface over the index on `wo`'s side.

use super::energy::{self, Masking};
use super::fresnel;
use super::microfacet::{Ggx, Microfacet, reflect};
use super::{BsdfSample, Lobe, PerLobe};
use glam::{Vec2, Vec3};

/// Indices of refraction closer to 1 than this are an invisible interface: smooth, with no
/// reflection (the rough transmission's half vector is undefined at η = 1).
const INDEX_MATCHED: f32 = 1e-4;

/// The microfacet normal and D(h) G(wo, wi) / (4 cos θo) (f · cos θi without the Fresnel
/// factor) of reflecting `wo` into `wi`, both above the surface.
#[inline]
pub(crate) fn rough_reflection<M: Microfacet>(m: &M, wo: Vec3, wi: Vec3) -> Option<(Vec3, f32)> {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return None;
    }
    let h = (wo + wi).normalize();
    if !h.is_finite() {
        return None;
    }
    Some((h, m.d(h) * m.g_separable(wo, wi) / (4.0 * wo.z)))
}

/// Density of the reflected direction when the microfacet normal `h` is sampled among those
/// visible from `wo`: D_wo(h) / (4 wo·h).
#[inline]
pub(crate) fn reflection_pdf<M: Microfacet>(m: &M, wo: Vec3, h: Vec3) -> f32 {
    let wo_h = wo.dot(h);
    if wo_h <= 0.0 {
        return 0.0;
    }
    m.visible_normal_pdf(wo, h) / (4.0 * wo_h)
}

/// Refraction of `wo` (above) into `wi` (below) through a rough interface of relative index
/// `eta`: the generalised half vector, f · |cos θi| without (1 - F) and tint (radiance scaled
/// by 1/η²), and the density of `wi` when the normal is sampled among those visible from
/// `wo`, without the probability of choosing refraction.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Refraction {
    pub wm: Vec3,
    pub value: f32,
    pub pdf: f32,
}

#[inline]
pub(crate) fn rough_refraction<M: Microfacet>(
    m: &M,
    wo: Vec3,
    wi: Vec3,
    eta: f32,
) -> Option<Refraction> {
    if wo.z <= 0.0 || wi.z >= 0.0 {
        return None;
    }
    let wm = (wi * eta + wo).normalize();
    let wm = if wm.z < 0.0 { -wm } else { wm };
    let (wo_m, wi_m) = (wo.dot(wm), wi.dot(wm));
    // Microfacets seen from behind by either direction carry nothing.
    if !wm.is_finite() || wo_m <= 0.0 || wi_m >= 0.0 {
        return None;
    }
    let denom = wi_m + wo_m / eta;
    let jacobian = wi_m.abs() / (denom * denom);
    let value = m.d(wm) * m.g_separable(wo, wi) * jacobian * wo_m / (wo.z * eta * eta);
    let pdf = m.visible_normal_pdf(wo, wm) * jacobian;
    Some(Refraction { wm, value, pdf })
}

/// `w` mirrored through the surface plane.
#[inline]
pub(crate) fn flip(w: Vec3) -> Vec3 {
    Vec3::new(w.x, w.y, -w.z)
}

/// The boundary of a dielectric volume, smooth or rough.
#[derive(Clone, Copy, Debug)]
pub struct Dielectric {
    eta: f32,
    ggx: Ggx,
    tint: Vec3,
    /// Rough lobes compensated for the energy single scattering loses.
    multiscatter: bool,
}

impl Dielectric {
    /// An interface of relative index `eta` (below over `wo`'s side), GGX roughness `alpha`
    /// (smooth below `microfacet::SMOOTH_ALPHA`) and transmission tint `tint`.
    pub fn new(eta: f32, alpha: f32, tint: Vec3) -> Self {
        let eta = if eta.is_finite() && eta > 0.0 {
            eta.clamp(1e-2, 1e2)
        } else {
            1.0
        };
        Self {
            eta,
            ggx: Ggx {
                alpha: if alpha.is_finite() {
                    alpha.clamp(0.0, 1.0)
                } else {
                    1.0
                },
            },
            tint: tint.clamp(Vec3::ZERO, Vec3::ONE),
            multiscatter: true,
        }
    }

    /// The same interface with energy compensation (`on`, the default) or without it:
    /// single-scattering GGX.
    pub fn with_multiscatter(self, on: bool) -> Self {
        Self {
            multiscatter: on,
            ..self
        }
    }

    /// The energy compensation's scale at `wo` (one for single scattering).
    #[inline]
    fn energy_scale(&self, wo: Vec3) -> f32 {
        if self.multiscatter {
            energy::dielectric_scale(self.ggx.alpha, self.eta, wo.z)
        } else {
            1.0
        }
    }

    /// True if both lobes are deltas (smooth, or an index-matched interface).
    pub fn is_smooth(&self) -> bool {
        self.ggx.is_smooth() || (self.eta - 1.0).abs() < INDEX_MATCHED
    }

    /// f · |cos θi|: reflection above the surface, refraction below (zero when smooth).
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let [_, reflection, transmission] = self.eval_lobes(wo, wi);
        reflection + transmission
    }

    /// [`Dielectric::eval`] by lobe: diffuse (none), glossy reflection, transmission.
    #[inline]
    pub fn eval_lobes(&self, wo: Vec3, wi: Vec3) -> PerLobe {
        let mut lobes = [Vec3::ZERO; 3];
        if self.is_smooth() {
            return lobes;
        }
        let scale = self.energy_scale(wo);
        if wi.z > 0.0 {
            if let Some((h, value)) = rough_reflection(&self.ggx, wo, wi) {
                lobes[1] = Vec3::splat(fresnel::dielectric(wo.dot(h), self.eta) * value * scale);
            }
        } else if let Some(r) = rough_refraction(&self.ggx, wo, wi, self.eta) {
            let t = 1.0 - fresnel::dielectric(wo.dot(r.wm), self.eta);
            lobes[2] = self.tint * (t * r.value * scale);
        }
        lobes
    }

    /// Density of [`Dielectric::sample`] for the rough lobes.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.is_smooth() || wo.z <= 0.0 {
            return 0.0;
        }
        if wi.z > 0.0 {
            let h = (wo + wi).normalize();
            let r = fresnel::dielectric(wo.dot(h), self.eta);
            r * reflection_pdf(&self.ggx, wo, h)
        } else {
            rough_refraction(&self.ggx, wo, wi, self.eta).map_or(0.0, |r| {
                (1.0 - fresnel::dielectric(wo.dot(r.wm), self.eta)) * r.pdf
            })
        }
    }

    /// Chooses reflection or refraction by the Fresnel reflectance (of the interface, or of
    /// the microfacet sampled with `u`) against `u_lobe`.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        if self.is_smooth() {
            return Some(self.smooth_sample(wo, u_lobe));
        }
        let h = self.ggx.sample_visible_normal(wo, u);
        let r = fresnel::dielectric(wo.dot(h), self.eta);
        let (wi, lobe) = if u_lobe < r {
            (reflect(wo, h), Lobe::Glossy)
        } else {
            (fresnel::refract(wo, h, self.eta)?, Lobe::GlossyTransmission)
        };
        if (wi.z > 0.0) != (lobe == Lobe::Glossy) {
            return None;
        }
        BsdfSample::from_mixture(wi, self.eval(wo, wi), self.pdf(wo, wi), lobe)
    }

    fn smooth_sample(&self, wo: Vec3, u_lobe: f32) -> BsdfSample {
        let r = if (self.eta - 1.0).abs() < INDEX_MATCHED {
            0.0
        } else {
            fresnel::dielectric(wo.z, self.eta)
        };
        if u_lobe < r {
            return BsdfSample {
                wi: Vec3::new(-wo.x, -wo.y, wo.z),
                weight: Vec3::ONE,
                pdf: r,
                lobe: Lobe::Specular,
            };
        }
        // r < 1 here, so Snell's law has a solution.
        let wi = fresnel::refract(wo, Vec3::Z, self.eta).unwrap_or(-wo);
        BsdfSample {
            wi,
            weight: self.tint / (self.eta * self.eta),
            pdf: 1.0 - r,
            lobe: Lobe::SpecularTransmission,
        }
    }

    /// True if some lobe is not a delta (light sampling can contribute).
    pub fn has_non_delta(&self) -> bool {
        !self.is_smooth()
    }

    /// Directional albedo estimate at `wo` of each lobe kind (Fresnel at n·wo): reflection
    /// R, transmission (1 - R) tint.
    pub fn albedo_lobes(&self, wo: Vec3) -> PerLobe {
        let r = fresnel::dielectric(wo.z, self.eta);
        [Vec3::ZERO, Vec3::splat(r), self.tint * (1.0 - r)]
    }
}

/// An infinitely thin dielectric slab: no bending, both faces' reflections summed.
#[derive(Clone, Copy, Debug)]
pub struct ThinDielectric {
    /// The slab's index of refraction relative to its surroundings (either side).
    eta: f32,
    ggx: Ggx,
    tint: Vec3,
    /// Rough lobes compensated for the energy single scattering loses.
    multiscatter: bool,
}

impl ThinDielectric {
    /// A slab of relative index `eta`, GGX roughness `alpha` and transmission tint `tint`.
    pub fn new(eta: f32, alpha: f32, tint: Vec3) -> Self {
        let Dielectric {
            eta,
            ggx,
            tint,
            multiscatter,
        } = Dielectric::new(eta, alpha, tint);
        Self {
            eta,
            ggx,
            tint,
            multiscatter,
        }
    }

    /// The same slab with energy compensation (`on`, the default) or without it:
    /// single-scattering GGX.
    pub fn with_multiscatter(self, on: bool) -> Self {
        Self {
            multiscatter: on,
            ..self
        }
    }

    /// The slab's reflectance and transmittance where a microfacet (or the surface) is seen
    /// at `cos`.
    #[inline]
    fn slab(&self, cos: f32) -> (f32, f32) {
        if (self.eta - 1.0).abs() < INDEX_MATCHED {
            return (0.0, 1.0);
        }
        fresnel::thin_slab(fresnel::dielectric(cos, self.eta))
    }

    /// True if both lobes are deltas.
    pub fn is_smooth(&self) -> bool {
        self.ggx.is_smooth() || (self.eta - 1.0).abs() < INDEX_MATCHED
    }

    /// f · |cos θi| (zero when smooth).
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let [_, reflection, transmission] = self.eval_lobes(wo, wi);
        reflection + transmission
    }

    /// [`ThinDielectric::eval`] by lobe: diffuse (none), glossy reflection, transmission.
    #[inline]
    pub fn eval_lobes(&self, wo: Vec3, wi: Vec3) -> PerLobe {
        let mut lobes = [Vec3::ZERO; 3];
        if self.is_smooth() {
            return lobes;
        }
        let through = wi.z < 0.0;
        if let Some((h, value)) =
            rough_reflection(&self.ggx, wo, if through { flip(wi) } else { wi })
        {
            let (r, t) = self.slab(wo.dot(h));
            let value = if self.multiscatter {
                value * energy::lossless_reflection_scale(Masking::Separable, self.ggx.alpha, wo.z)
            } else {
                value
            };
            if through {
                lobes[2] = self.tint * (t * value);
            } else {
                lobes[1] = Vec3::splat(r * value);
            }
        }
        lobes
    }

    /// Density of [`ThinDielectric::sample`] for the rough lobes.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.is_smooth() || wo.z <= 0.0 || wi.z == 0.0 {
            return 0.0;
        }
        let through = wi.z < 0.0;
        let h = (wo + if through { flip(wi) } else { wi }).normalize();
        let (r, t) = self.slab(wo.dot(h));
        (if through { t } else { r }) * reflection_pdf(&self.ggx, wo, h)
    }

    /// Chooses reflection or transmission by the slab's reflectance against `u_lobe`.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        if self.is_smooth() {
            let (r, t) = self.slab(wo.z);
            return Some(if u_lobe < r {
                BsdfSample {
                    wi: Vec3::new(-wo.x, -wo.y, wo.z),
                    weight: Vec3::ONE,
                    pdf: r,
                    lobe: Lobe::Specular,
                }
            } else {
                BsdfSample {
                    wi: -wo,
                    weight: self.tint,
                    pdf: t,
                    lobe: Lobe::StraightTransmission,
                }
            });
        }
        let h = self.ggx.sample_visible_normal(wo, u);
        let (r, _) = self.slab(wo.dot(h));
        let reflected = reflect(wo, h);
        if reflected.z <= 0.0 {
            return None;
        }
        let (wi, lobe) = if u_lobe < r {
            (reflected, Lobe::Glossy)
        } else {
            (flip(reflected), Lobe::GlossyTransmission)
        };
        BsdfSample::from_mixture(wi, self.eval(wo, wi), self.pdf(wo, wi), lobe)
    }

    /// The weight of the straight-through delta lobe for light crossing the slab along
    /// `-wo` (what a shadow ray crossing it carries): zero when rough.
    #[inline]
    pub fn straight_transmission(&self, wo: Vec3) -> Vec3 {
        if !self.is_smooth() {
            return Vec3::ZERO;
        }
        self.tint * self.slab(wo.z.abs()).1
    }

    /// True if some lobe is not a delta.
    pub fn has_non_delta(&self) -> bool {
        !self.is_smooth()
    }

    /// Directional albedo estimate at `wo` of each lobe kind.
    pub fn albedo_lobes(&self, wo: Vec3) -> PerLobe {
        let (r, t) = self.slab(wo.z);
        [Vec3::ZERO, Vec3::splat(r), self.tint * t]
    }
}
