//! The glTF 2.0 metallic-roughness BRDF exactly as the specification's appendix B defines it:
//!
//! ```text
//! metal      = F_m(v·h) · V · D,            F_m = base + (1 - base)(1 - |v·h|)^5
//! dielectric = mix(base / π, V · D, F_d),    F_d = f0 + (1 - f0)(1 - |v·h|)^5, f0 = 0.04
//! material   = mix(dielectric, metal, metallic)
//! ```
//!
//! with GGX D, the height-correlated Smith visibility V and alpha = roughness². `f0` follows
//! KHR_materials_ior when present ((ior - 1) / (ior + 1))², 0.04 for the default 1.5), or is
//! the specular colour in UsdPreviewSurface's specular workflow.
//! Below [`SMOOTH_ALPHA`] the specular lobe is a perfect mirror (a delta lobe) with the
//! same Fresnel weights at h = n, so roughness 0 is exact rather than NaN.
//!
//! A clear coat (KHR_materials_clearcoat, UsdPreviewSurface clearcoat) of weight `c` and its
//! own roughness is layered on top, as a reciprocal, energy-conserving mix:
//!
//! ```text
//! coated = c F_c(v·h) V_c D_c  +  (1 - c F_c(n·wo)) (1 - c F_c(n·wi)) material,  F_c: f0 = 0.04
//! ```
//!
//! (the base is seen through the coat twice, in and out). A smooth coat is a delta lobe,
//! like a smooth specular layer; when both are smooth their mirror reflections add up.
//!
//! A diffuse roughness above 0 (OpenPBR's, from USD; glTF has none) makes the diffuse lobe
//! OpenPBR's energy-preserving Oren-Nayar (`oren_nayar`) in place of base / π, under the
//! same weight.
//!
//! Rough specular and coat lobes are compensated for the energy single scattering loses
//! between facets (`energy`: Turquin's albedo scaling with Kulla and Conty's
//! multiple-bounce Fresnel, as Cycles' "Multiscatter GGX"), unless the BRDF is built
//! `with_multiscatter(false)` (appendix B exactly). The diffuse weight stays the
//! specification's.
//!
//! Sampling picks the coat, the specular lobe (GGX visible normals) or the diffuse lobe
//! (cosine) with probabilities proportional to their albedo estimates at `wo`; the density
//! is the mixture.

use super::energy::{self, Masking};
use super::microfacet::{Ggx, SMOOTH_ALPHA, reflect, schlick};
use super::oren_nayar;
use super::{BsdfSample, Lobe};
use crate::color::luminance;
use crate::sampling::warp::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// The glTF metallic-roughness BRDF at one surface point.
#[derive(Clone, Copy, Debug)]
pub struct GltfPbr {
    base: Vec3,
    metallic: f32,
    ggx: Ggx,
    /// The dielectric's reflectance at normal incidence (per channel for the specular
    /// workflow).
    f0: Vec3,
    /// Clear coat weight (0: no coat).
    coat: f32,
    coat_ggx: Ggx,
    /// Rough lobes compensated for the energy single scattering loses.
    multiscatter: bool,
    /// Diffuse roughness (0: Lambert).
    diffuse_roughness: f32,
}

/// What an uncoated [`GltfPbr`] is made of: base colour, metallic, GGX alpha and the
/// dielectric's reflectance at normal incidence.
#[derive(Clone, Copy, Debug)]
pub struct UncoatedParts {
    pub base: Vec3,
    pub metallic: f32,
    pub alpha: f32,
    pub f0: Vec3,
}

/// Reflectance at normal incidence of the clear coat (ior 1.5, as KHR_materials_clearcoat
/// and UsdPreviewSurface fix it).
const COAT_F0: f32 = 0.04;

impl GltfPbr {
    /// A BRDF from base colour, metallic, perceptual roughness and dielectric ior.
    pub fn new(base: Vec3, metallic: f32, roughness: f32, ior: f32) -> Self {
        let r = roughness.clamp(0.0, 1.0);
        let f0 = ((ior - 1.0) / (ior + 1.0)).powi(2);
        Self {
            base: base.clamp(Vec3::ZERO, Vec3::ONE),
            metallic: metallic.clamp(0.0, 1.0),
            ggx: Ggx { alpha: r * r },
            f0: Vec3::splat(if f0.is_finite() {
                f0.clamp(0.0, 1.0)
            } else {
                0.04
            }),
            coat: 0.0,
            coat_ggx: Ggx { alpha: 0.0 },
            multiscatter: true,
            diffuse_roughness: 0.0,
        }
    }

    /// The same BRDF with a rough diffuse base (OpenPBR's EON) of `roughness` in [0, 1].
    pub fn with_diffuse_roughness(self, roughness: f32) -> Self {
        Self {
            diffuse_roughness: if roughness.is_finite() {
                roughness.clamp(0.0, 1.0)
            } else {
                0.0
            },
            ..self
        }
    }

    /// The same BRDF with energy compensation (`on`, the default) or without it:
    /// single-scattering GGX, as appendix B defines it.
    pub fn with_multiscatter(self, on: bool) -> Self {
        Self {
            multiscatter: on,
            ..self
        }
    }

    /// The same BRDF in the specular workflow of UsdPreviewSurface: the dielectric reflects
    /// `color` at normal incidence (white at grazing, Schlick in between) instead of the
    /// ior's grey.
    pub fn with_specular_color(self, color: Vec3) -> Self {
        Self {
            f0: color.clamp(Vec3::ZERO, Vec3::ONE),
            ..self
        }
    }

    /// The same BRDF under a clear coat of `weight` and perceptual `roughness`.
    pub fn with_clearcoat(self, weight: f32, roughness: f32) -> Self {
        let r = roughness.clamp(0.0, 1.0);
        Self {
            coat: weight.clamp(0.0, 1.0),
            coat_ggx: Ggx { alpha: r * r },
            ..self
        }
    }

    fn smooth(&self) -> bool {
        self.ggx.alpha < SMOOTH_ALPHA
    }

    fn coat_smooth(&self) -> bool {
        self.coat_ggx.alpha < SMOOTH_ALPHA
    }

    /// Weighted coat reflectance c F_c at `cos`.
    #[inline]
    fn coat_fresnel(&self, cos: f32) -> f32 {
        if self.coat == 0.0 {
            return 0.0;
        }
        self.coat * schlick(Vec3::splat(COAT_F0), cos).x
    }

    /// Share of the light that crosses the coat in (along `wi`) and out (along `wo`).
    #[inline]
    fn coat_transmission(&self, cos_o: f32, cos_i: f32) -> f32 {
        (1.0 - self.coat_fresnel(cos_o)) * (1.0 - self.coat_fresnel(cos_i))
    }

    /// Specular reflectance (dielectric and metal Fresnel, mixed by metallic) at `cos`.
    #[inline]
    fn specular_fresnel(&self, cos: f32) -> Vec3 {
        let fd = schlick(self.f0, cos);
        let fm = schlick(self.base, cos);
        fd * (1.0 - self.metallic) + fm * self.metallic
    }

    /// The energy compensation's scale of the rough specular lobe at cos θo = `cos` (one
    /// where it is smooth or single-scattering); the packet kernel's lanes call it too.
    #[inline]
    pub(crate) fn specular_energy(&self, cos: f32) -> Vec3 {
        if !self.multiscatter {
            return Vec3::ONE;
        }
        let f_avg = energy::schlick_average(self.f0) * (1.0 - self.metallic)
            + energy::schlick_average(self.base) * self.metallic;
        energy::reflection_scale(Masking::Correlated, self.ggx.alpha, f_avg, cos)
    }

    /// The energy compensation's scale of the rough coat at cos θo = `cos`.
    #[inline]
    fn coat_energy(&self, cos: f32) -> f32 {
        if !self.multiscatter {
            return 1.0;
        }
        let f_avg = energy::schlick_average(Vec3::splat(COAT_F0)) * self.coat;
        energy::reflection_scale(Masking::Correlated, self.coat_ggx.alpha, f_avg, cos).x
    }

    /// Diffuse weight (1 - metallic)(1 - F_d(cos)) base.
    #[inline]
    fn diffuse_weight(&self, cos: f32) -> Vec3 {
        let fd = schlick(self.f0, cos);
        self.base * (1.0 - self.metallic) * (Vec3::ONE - fd)
    }

    /// Probabilities of sampling the coat, the specular and the diffuse lobe from `wo`.
    #[inline]
    fn lobe_probabilities(&self, wo: Vec3) -> (f32, f32, f32) {
        let c = self.coat_fresnel(wo.z);
        let through = 1.0 - c;
        let s = through * luminance(self.specular_fresnel(wo.z));
        let d = through * luminance(self.diffuse_weight(wo.z));
        let total = c + s + d;
        if total > 0.0 {
            (c / total, s / total, d / total)
        } else {
            (0.0, 1.0, 0.0)
        }
    }

    /// f · cos θi of the non-delta lobes.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let [diffuse, glossy] = self.eval_lobes(wo, wi);
        diffuse + glossy
    }

    /// f · cos θi split into the diffuse lobe and the glossy ones (specular and coat).
    #[inline]
    pub fn eval_lobes(&self, wo: Vec3, wi: Vec3) -> [Vec3; 2] {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return [Vec3::ZERO; 2];
        }
        self.eval_lobes_at(wo, wi, (wo + wi).normalize())
    }

    /// [`GltfPbr::eval_lobes`] for wo and wi above the surface, with their half vector `h`.
    #[inline]
    fn eval_lobes_at(&self, wo: Vec3, wi: Vec3, h: Vec3) -> [Vec3; 2] {
        let v_h = wo.dot(h);
        let mut diffuse = if self.diffuse_roughness > 0.0 {
            let fd = schlick(self.f0, v_h);
            oren_nayar::eval(self.base, self.diffuse_roughness, wo, wi)
                * (1.0 - self.metallic)
                * (Vec3::ONE - fd)
        } else {
            self.diffuse_weight(v_h) * FRAC_1_PI
        };
        let mut glossy = Vec3::ZERO;
        if !self.smooth() {
            let vd = self.ggx.visibility(wi.z, wo.z) * self.ggx.d(h);
            glossy += self.specular_fresnel(v_h) * vd * self.specular_energy(wo.z);
        }
        if self.coat > 0.0 {
            let through = self.coat_transmission(wo.z, wi.z);
            diffuse *= through;
            glossy *= through;
            if !self.coat_smooth() {
                let vd = self.coat_ggx.visibility(wi.z, wo.z) * self.coat_ggx.d(h);
                glossy += Vec3::splat(self.coat_fresnel(v_h) * vd * self.coat_energy(wo.z));
            }
        }
        [diffuse * wi.z, glossy * wi.z]
    }

    /// Density of [`GltfPbr::sample`] for the non-delta lobes.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        self.pdf_at(wo, wi, self.lobe_probabilities(wo), (wo + wi).normalize())
    }

    /// [`GltfPbr::pdf`] for wo and wi above the surface, given the lobe probabilities at wo
    /// and the half vector `h`.
    #[inline]
    fn pdf_at(&self, wo: Vec3, wi: Vec3, (pc, ps, pd): (f32, f32, f32), h: Vec3) -> f32 {
        let mut pdf = pd * cosine_hemisphere_pdf(wi);
        let glossy_coat = pc > 0.0 && !self.coat_smooth();
        if self.smooth() && !glossy_coat {
            return pdf;
        }
        if !self.smooth() {
            pdf += ps * self.ggx.reflection_pdf(wo, h);
        }
        if glossy_coat {
            pdf += pc * self.coat_ggx.reflection_pdf(wo, h);
        }
        pdf
    }

    /// Samples a lobe with `u_lobe`, then a direction with `u`.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let probabilities = self.lobe_probabilities(wo);
        let (pc, ps, _) = probabilities;
        let (glossy, delta) = if u_lobe < pc {
            (Some(&self.coat_ggx), self.coat_smooth())
        } else if u_lobe < pc + ps {
            (Some(&self.ggx), self.smooth())
        } else {
            (None, false)
        };
        if delta {
            return Some(self.mirror_sample(wo, pc, ps));
        }
        let Some(ggx) = glossy else {
            let wi = square_to_cosine_hemisphere(u);
            return self.finish(wo, wi, probabilities, Lobe::Diffuse);
        };
        let h = ggx.sample_visible_normal(wo, u);
        self.finish(wo, reflect(wo, h), probabilities, Lobe::Glossy)
    }

    /// The mirror direction, reached by whichever smooth lobes (coat, specular) there are:
    /// their reflectances add up and so do their probabilities.
    fn mirror_sample(&self, wo: Vec3, pc: f32, ps: f32) -> BsdfSample {
        let (mut reflectance, mut probability) = (Vec3::ZERO, 0.0);
        if self.coat_smooth() {
            reflectance += Vec3::splat(self.coat_fresnel(wo.z));
            probability += pc;
        }
        if self.smooth() {
            reflectance += self.specular_fresnel(wo.z) * self.coat_transmission(wo.z, wo.z);
            probability += ps;
        }
        BsdfSample {
            wi: Vec3::new(-wo.x, -wo.y, wo.z),
            weight: reflectance / probability,
            pdf: probability,
            lobe: Lobe::Specular,
        }
    }

    /// The sample in direction `wi` of lobe `lobe` (none below the surface): f · cos θi and
    /// the mixture density, sharing the half vector and the lobe probabilities at `wo`.
    fn finish(
        &self,
        wo: Vec3,
        wi: Vec3,
        probabilities: (f32, f32, f32),
        lobe: Lobe,
    ) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let h = (wo + wi).normalize();
        let [diffuse, glossy] = self.eval_lobes_at(wo, wi, h);
        let pdf = self.pdf_at(wo, wi, probabilities, h);
        BsdfSample::from_mixture(wi, diffuse + glossy, pdf, lobe)
    }

    /// The parameters of a BRDF without a clear coat and with a Lambertian base, which the
    /// packet kernel evaluates in SIMD lanes (`material::lanes`); `None` for the others.
    pub fn uncoated(&self) -> Option<UncoatedParts> {
        (self.coat == 0.0 && self.diffuse_roughness == 0.0).then_some(UncoatedParts {
            base: self.base,
            metallic: self.metallic,
            alpha: self.ggx.alpha,
            f0: self.f0,
        })
    }

    /// True if some lobe is not a delta: false only for a smooth pure metal under no coat or
    /// a smooth one.
    pub fn has_non_delta(&self) -> bool {
        !self.smooth() || self.metallic < 1.0 || (self.coat > 0.0 && !self.coat_smooth())
    }

    /// Directional albedo estimate at `wo` (Fresnel at n·v, no microfacet energy loss) of
    /// the diffuse lobe and of the glossy ones: their sum is the denoising albedo.
    pub fn albedo_lobes(&self, wo: Vec3) -> [Vec3; 2] {
        let c = wo.z.clamp(0.0, 1.0);
        let coat = self.coat_fresnel(c);
        [
            self.diffuse_weight(c) * (1.0 - coat),
            self.specular_fresnel(c) * (1.0 - coat) + Vec3::splat(coat),
        ]
    }
}
