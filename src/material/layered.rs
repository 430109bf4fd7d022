//! The full glTF 2.0 material model with its PBR extensions, for the materials that use
//! more than `gltf_pbr`'s base: the specification's layering (appendix B and each
//! extension's "implementation" section), from the top:
//!
//! ```text
//! coated  = c F_c(v·h_c) coat_brdf + (1 - c F_c(n_c·wo)) (1 - c F_c(n_c·wi)) sheened
//! sheened = sheen_brdf + min(1 - max(sheen) E(wo), 1 - max(sheen) E(wi)) material
//! material = mix(dielectric, metal, metallic)
//! metal      = F_m(v·h) specular_brdf,                  F_m = schlick(base) (iridescent: mixed)
//! dielectric = F_d(v·h) specular_brdf + (1 - max F_d) mix(diffuse, base btdf, transmission)
//! diffuse    = mix(diffuse_brdf(base), diffuse_btdf(translucency colour), translucency)
//! F_d = weight (f0 + (1 - f0) s(v·h)),  f0 = min(F0(ior) specular_colour, 1)
//! ```
//!
//! The coat (KHR_materials_clearcoat) has its own roughness and normal map; the sheen is
//! `sheen`'s; iridescence (KHR_materials_iridescence) mixes the thin-film reflectance of
//! `thin_film` into F_d and F_m; anisotropy (KHR_materials_anisotropy) stretches the
//! specular and transmission microfacets along a direction of the tangent plane.
//!
//! Fresnel and masking follow appendix B (Schlick's s = (1 - v·h)⁵, height-correlated Smith)
//! for opaque materials, so that this model and `gltf_pbr` agree where both apply. A
//! material that transmits anywhere takes the exact dielectric Fresnel instead, remapped so
//! that the specular colour still sets F0 (s = (F(v·h) - F(1)) / (1 - F(1)), as Blender's
//! principled BSDF does), and separable masking: its reflection and refraction are then
//! those of `dielectric::Dielectric` (total internal reflection included), which is what the
//! pure-glass materials use. A thin wall (transmission without KHR_materials_volume) reflects
//! from both faces (`fresnel::thin_slab`) and transmits without bending.
//!
//! Rough specular, transmission and coat lobes are compensated for the energy single
//! scattering loses between facets (`energy`), unless `multiscatter` is off: an opaque
//! specular lobe as `gltf_pbr`'s, a transmissive material's reflection and transmission as
//! the rough dielectric (or thin slab) it is where it transmits, the specular lobe's scale
//! blended from the opaque one's by the transmitting share (1 - metallic) transmission.
//! Iridescence's and the sheen's effect on the average Fresnel are not counted.
//!
//! Diffuse transmission (KHR_materials_diffuse_transmission) is a Lambertian lobe on the
//! other side (colour / π · |cos θi|), weighted as the diffuse reflection it replaces; its
//! Fresnel weight is taken at the half vector of `wo` and `wi` mirrored to `wo`'s side, as
//! a thin wall's rough transmission does. It counts as diffuse in the lobe layers, where
//! Cycles puts its Translucent BSDF.
//!
//! Sampling picks one lobe (coat, sheen, specular reflection, transmission, diffuse,
//! diffuse transmission) with probabilities proportional to their albedo estimates at `wo`;
//! a direction's density is the mixture's. The sheen counts as diffuse in the lobe layers
//! (Cycles does the same).

use super::dielectric::{flip, reflection_pdf, rough_reflection, rough_refraction};
use super::energy::{self, Masking};
use super::fresnel;
use super::microfacet::{AnisotropicGgx, Ggx, Microfacet, reflect, schlick};
use super::oren_nayar;
use super::sheen::Sheen;
use super::thin_film;
use super::{BsdfSample, Lobe, PerLobe};
use crate::color::luminance;
use crate::geometry::frame::Frame;
use crate::sampling::warp::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Reflectance at normal incidence of the clear coat (ior 1.5, as the extension fixes it).
const COAT_F0: f32 = 0.04;

/// A thin film over the base (KHR_materials_iridescence) at a point.
#[derive(Clone, Copy, Debug)]
pub struct Film {
    /// How much of the film's reflectance replaces the base's, in [0, 1].
    pub factor: f32,
    /// Thickness in nanometres.
    pub thickness: f32,
    pub ior: f32,
}

/// Everything the layered model needs at a surface point.
#[derive(Clone, Copy, Debug)]
pub struct LayeredParams {
    pub base: Vec3,
    pub metallic: f32,
    /// GGX alpha (roughness²) across and along the anisotropy direction.
    pub alpha: Vec2,
    /// The anisotropy direction in the local tangent plane, (cos, sin) from the local x
    /// axis.
    pub anisotropy_direction: Vec2,
    /// Share of the dielectric base that transmits.
    pub transmission: f32,
    /// What transmitted light is tinted by at each crossing.
    pub transmission_tint: Vec3,
    /// Transmission through a thin wall (no bending) rather than a volume's boundary.
    pub thin: bool,
    /// Relative index of refraction across the interface (below the surface over `wo`'s
    /// side); infinite for ior 0 (a perfect reflector).
    pub eta: f32,
    /// Exact Fresnel and separable masking (transmissive materials).
    pub exact: bool,
    /// Dielectric F0 (before the specular weight): min(F0(ior) colour, 1), or the
    /// specular workflow's colour.
    pub f0: Vec3,
    pub specular_weight: f32,
    pub sheen: Option<Sheen>,
    pub coat: f32,
    pub coat_alpha: f32,
    /// The coat's normal in the local shading frame.
    pub coat_normal: Vec3,
    pub film: Option<Film>,
    /// Rough lobes compensated for the energy single scattering loses.
    pub multiscatter: bool,
    /// Diffuse roughness in [0, 1] (0: Lambert; above, OpenPBR's EON).
    pub diffuse_roughness: f32,
    /// Share of the diffuse base that is Lambertian transmission, in [0, 1].
    pub translucency: f32,
    /// The colour of the diffuse transmission.
    pub translucency_color: Vec3,
}

/// The layered glTF BSDF at one surface point.
#[derive(Clone, Debug)]
pub struct Layered {
    p: LayeredParams,
    ggx: AnisotropicGgx,
    coat_ggx: Ggx,
    /// The coat's frame (around its normal), when it differs from the shading frame.
    coat_frame: Option<Frame>,
    /// F(1) of the bare interface, for the exact Fresnel's remapping.
    f0_interface: f32,
}

/// Lobe selection probabilities at `wo`: coat, sheen, specular, transmission, diffuse,
/// diffuse transmission.
type Probabilities = [f32; 6];
const COAT: usize = 0;
const SHEEN: usize = 1;
const SPECULAR: usize = 2;
const TRANSMISSION: usize = 3;
const DIFFUSE: usize = 4;
const TRANSLUCENT: usize = 5;

impl Layered {
    pub fn new(p: LayeredParams) -> Self {
        let mut p = p;
        p.base = p.base.clamp(Vec3::ZERO, Vec3::ONE);
        p.metallic = p.metallic.clamp(0.0, 1.0);
        p.transmission = p.transmission.clamp(0.0, 1.0);
        p.transmission_tint = p.transmission_tint.clamp(Vec3::ZERO, Vec3::ONE);
        p.translucency = if p.translucency.is_finite() {
            p.translucency.clamp(0.0, 1.0)
        } else {
            0.0
        };
        p.translucency_color = p.translucency_color.clamp(Vec3::ZERO, Vec3::ONE);
        p.coat = p.coat.clamp(0.0, 1.0);
        p.diffuse_roughness = if p.diffuse_roughness.is_finite() {
            p.diffuse_roughness.clamp(0.0, 1.0)
        } else {
            0.0
        };
        p.specular_weight = p.specular_weight.clamp(0.0, 1.0);
        p.f0 = p.f0.clamp(Vec3::ZERO, Vec3::ONE);
        let clamp_alpha = |a: f32| {
            if a.is_finite() {
                a.clamp(0.0, 1.0)
            } else {
                1.0
            }
        };
        let coat_normal = p.coat_normal.normalize_or(Vec3::Z);
        p.coat_normal = if coat_normal.z > 0.0 {
            coat_normal
        } else {
            Vec3::Z
        };
        let f0_interface = if p.eta.is_finite() {
            fresnel::normal_reflectance(p.eta)
        } else {
            1.0
        };
        Self {
            ggx: AnisotropicGgx {
                alpha_x: clamp_alpha(p.alpha.x),
                alpha_y: clamp_alpha(p.alpha.y),
            },
            coat_ggx: Ggx {
                alpha: clamp_alpha(p.coat_alpha),
            },
            coat_frame: (p.coat > 0.0 && p.coat_normal != Vec3::Z)
                .then(|| Frame::from_normal(p.coat_normal)),
            f0_interface,
            p,
        }
    }

    /// A local direction in the anisotropy's frame (x along the stretched direction).
    #[inline]
    fn to_aniso(&self, w: Vec3) -> Vec3 {
        let (c, s) = (self.p.anisotropy_direction.x, self.p.anisotropy_direction.y);
        Vec3::new(c * w.x + s * w.y, -s * w.x + c * w.y, w.z)
    }

    #[inline]
    fn aniso_to_local(&self, w: Vec3) -> Vec3 {
        let (c, s) = (self.p.anisotropy_direction.x, self.p.anisotropy_direction.y);
        Vec3::new(c * w.x - s * w.y, s * w.x + c * w.y, w.z)
    }

    #[inline]
    fn to_coat(&self, w: Vec3) -> Vec3 {
        self.coat_frame.map_or(w, |f| f.to_local(w))
    }

    #[inline]
    fn coat_to_local(&self, w: Vec3) -> Vec3 {
        self.coat_frame.map_or(w, |f| f.to_world(w))
    }

    /// The weighted dielectric reflectance F_d at `cos` (of `wo` to the microfacet).
    #[inline]
    fn dielectric_fresnel(&self, cos: f32) -> Vec3 {
        let p = &self.p;
        let s = if !p.exact {
            (1.0 - cos.abs()).clamp(0.0, 1.0).powi(5)
        } else if self.f0_interface < 1.0 {
            let f = fresnel::dielectric(cos, p.eta);
            ((f - self.f0_interface) / (1.0 - self.f0_interface)).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let mut fr = p.f0 + (Vec3::ONE - p.f0) * s;
        if p.thin && p.exact {
            let slab = |r: f32| fresnel::thin_slab(r).0;
            fr = Vec3::new(slab(fr.x), slab(fr.y), slab(fr.z));
        }
        let weighted = fr * p.specular_weight;
        match p.film {
            Some(film) => {
                let iridescent = thin_film::reflectance(
                    1.0,
                    film.ior,
                    p.f0 * p.specular_weight,
                    film.thickness,
                    cos.abs(),
                );
                weighted.lerp(iridescent, film.factor)
            }
            None => weighted,
        }
    }

    /// The metal's reflectance F_m at `cos`.
    #[inline]
    fn metal_fresnel(&self, cos: f32) -> Vec3 {
        let fm = schlick(self.p.base, cos);
        match self.p.film {
            Some(film) => fm.lerp(
                thin_film::reflectance(1.0, film.ior, self.p.base, film.thickness, cos.abs()),
                film.factor,
            ),
            None => fm,
        }
    }

    /// The coat's reflectance c F_c at `cos` to its normal.
    #[inline]
    fn coat_fresnel(&self, cos: f32) -> f32 {
        if self.p.coat == 0.0 {
            return 0.0;
        }
        self.p.coat * schlick(Vec3::splat(COAT_F0), cos).x
    }

    /// The share of light crossing the coat in along `wi` and out along `wo`, times the
    /// share the sheen lets through: the weight of everything below the sheen.
    #[inline]
    fn through_layers(&self, wo: Vec3, wi: Vec3) -> f32 {
        let n = self.p.coat_normal;
        let coat =
            (1.0 - self.coat_fresnel(n.dot(wo).abs())) * (1.0 - self.coat_fresnel(n.dot(wi).abs()));
        let sheen = self.p.sheen.map_or(1.0, |s| s.scaling(wo.z, wi.z));
        coat * sheen
    }

    /// The weight of what lies below the sheen's fibres (coat only).
    #[inline]
    fn through_coat(&self, wo: Vec3, wi: Vec3) -> f32 {
        let n = self.p.coat_normal;
        (1.0 - self.coat_fresnel(n.dot(wo).abs())) * (1.0 - self.coat_fresnel(n.dot(wi).abs()))
    }

    fn specular_smooth(&self) -> bool {
        self.ggx.is_smooth()
    }

    fn coat_smooth(&self) -> bool {
        self.coat_ggx.alpha < super::microfacet::SMOOTH_ALPHA
    }

    /// The energy compensation's scales at `wo` of the rough specular reflection and of
    /// the rough transmission (ones where smooth or single-scattering).
    fn specular_energy(&self, wo: Vec3) -> (Vec3, f32) {
        let p = &self.p;
        if !p.multiscatter || self.specular_smooth() {
            return (Vec3::ONE, 1.0);
        }
        let alpha = (self.ggx.alpha_x * self.ggx.alpha_y).sqrt();
        let f_avg = energy::schlick_average(p.f0) * (p.specular_weight * (1.0 - p.metallic))
            + energy::schlick_average(p.base) * p.metallic;
        if !p.exact {
            let scale = energy::reflection_scale(Masking::Correlated, alpha, f_avg, wo.z);
            return (scale, 1.0);
        }
        let opaque = energy::reflection_scale(Masking::Separable, alpha, f_avg, wo.z);
        let lossless = if p.thin || !p.eta.is_finite() {
            energy::lossless_reflection_scale(Masking::Separable, alpha, wo.z)
        } else {
            energy::dielectric_scale(alpha, p.eta, wo.z)
        };
        let share = p.transmission * (1.0 - p.metallic);
        (opaque.lerp(Vec3::splat(lossless), share), lossless)
    }

    /// The energy compensation's scale of the rough coat at `wo_c` (in the coat's frame).
    fn coat_energy(&self, wo_c: Vec3) -> f32 {
        if !self.p.multiscatter {
            return 1.0;
        }
        let f_avg = energy::schlick_average(Vec3::splat(COAT_F0)) * self.p.coat;
        energy::reflection_scale(Masking::Correlated, self.coat_ggx.alpha, f_avg, wo_c.z).x
    }

    /// Probabilities of sampling each lobe at `wo`, proportional to their albedo estimates.
    fn probabilities(&self, wo: Vec3) -> Probabilities {
        let p = &self.p;
        let cos = wo.z.clamp(0.0, 1.0);
        let c = self.coat_fresnel(p.coat_normal.dot(wo).abs());
        let under = 1.0 - c;
        let (sheen, scaling) = match p.sheen {
            Some(s) => (luminance(s.color) * s.albedo(cos), s.scaling(cos, cos)),
            None => (0.0, 1.0),
        };
        let below = under * scaling;
        let fd = self.dielectric_fresnel(cos);
        let fm = self.metal_fresnel(cos);
        let specular = below * (luminance(fd) * (1.0 - p.metallic) + luminance(fm) * p.metallic);
        let rest = below * (1.0 - p.metallic) * (1.0 - fd.max_element());
        let diffuse = rest * (1.0 - p.transmission);
        let mut w = [
            c,
            under * sheen,
            specular,
            rest * p.transmission * luminance(p.transmission_tint),
            diffuse * (1.0 - p.translucency) * luminance(p.base),
            diffuse * p.translucency * luminance(p.translucency_color),
        ];
        let total: f32 = w.iter().sum();
        if !(total > 0.0) {
            return [0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
        }
        w.iter_mut().for_each(|x| *x /= total);
        w
    }

    /// f · |cos θi| of the non-delta lobes split into diffuse (sheen included), glossy
    /// (specular and coat) and transmission.
    pub fn eval_lobes(&self, wo: Vec3, wi: Vec3) -> PerLobe {
        let p = &self.p;
        let mut lobes = [Vec3::ZERO; 3];
        if wo.z <= 0.0 || wi.z == 0.0 {
            return lobes;
        }
        let under = self.through_layers(wo, wi);
        if wi.z > 0.0 {
            let h = (wo + wi).normalize();
            let v_h = wo.dot(h);
            let fd = self.dielectric_fresnel(v_h);
            if !self.specular_smooth() {
                let (wo_a, wi_a) = (self.to_aniso(wo), self.to_aniso(wi));
                let h_a = self.to_aniso(h);
                let g = if p.exact {
                    self.ggx.g_separable(wo_a, wi_a)
                } else {
                    self.ggx.g_correlated(wo_a, wi_a)
                };
                let dg = self.ggx.d(h_a) * g / (4.0 * wo.z);
                let f = fd * (1.0 - p.metallic) + self.metal_fresnel(v_h) * p.metallic;
                lobes[1] += f * self.specular_energy(wo).0 * (dg * under);
            }
            let diffuse_weight = (1.0 - p.metallic)
                * (1.0 - p.transmission)
                * (1.0 - p.translucency)
                * (1.0 - fd.max_element());
            let diffuse_brdf = if p.diffuse_roughness > 0.0 {
                oren_nayar::eval(p.base, p.diffuse_roughness, wo, wi)
            } else {
                p.base * FRAC_1_PI
            };
            lobes[0] += diffuse_brdf * (diffuse_weight * wi.z * under);
            if let Some(sheen) = &p.sheen {
                lobes[0] += sheen.eval(wo, wi) * self.through_coat(wo, wi);
            }
            if p.coat > 0.0 && !self.coat_smooth() {
                let (wo_c, wi_c) = (self.to_coat(wo), self.to_coat(wi));
                // With its own normal map the coat's cosine is its own normal's (as its
                // mirror's weight is its reflectance when smooth).
                if let Some((h_c, _)) = rough_reflection(&self.coat_ggx, wo_c, wi_c) {
                    let g = self.coat_ggx.g_correlated(wo_c, wi_c);
                    let f_cos = self.coat_fresnel(wo_c.dot(h_c)) * self.coat_ggx.d(h_c) * g
                        / (4.0 * wo_c.z)
                        * self.coat_energy(wo_c);
                    lobes[1] += Vec3::splat(f_cos);
                }
            }
        } else {
            if p.translucency > 0.0 && p.metallic < 1.0 {
                let fd = self.dielectric_fresnel(wo.dot((wo + flip(wi)).normalize()));
                let weight = (1.0 - p.metallic)
                    * (1.0 - p.transmission)
                    * p.translucency
                    * (1.0 - fd.max_element());
                lobes[0] += p.translucency_color * (FRAC_1_PI * weight * -wi.z * under);
            }
            if p.transmission > 0.0 && p.metallic < 1.0 && !self.specular_smooth() {
                lobes[2] = self.rough_transmission(wo, wi, under);
            }
        }
        lobes
    }

    /// f · |cos θi| of the rough specular transmission towards `wi` below the surface,
    /// `under` the share the layers above let through.
    fn rough_transmission(&self, wo: Vec3, wi: Vec3, under: f32) -> Vec3 {
        let p = &self.p;
        let (wo_a, wi_a) = (self.to_aniso(wo), self.to_aniso(wi));
        let weight = (1.0 - p.metallic) * p.transmission * under * self.specular_energy(wo).1;
        let (h_a, value) = if p.thin {
            rough_reflection(&self.ggx, wo_a, flip(wi_a))
        } else {
            rough_refraction(&self.ggx, wo_a, wi_a, p.eta).map(|r| (r.wm, r.value))
        }
        .unwrap_or((Vec3::Z, 0.0));
        let fd = self.dielectric_fresnel(wo_a.dot(h_a));
        p.transmission_tint * ((1.0 - fd.max_element()) * value * weight)
    }

    /// f · |cos θi| of the non-delta lobes.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let [d, g, t] = self.eval_lobes(wo, wi);
        d + g + t
    }

    /// Density of [`Layered::sample`] for the non-delta lobes.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z == 0.0 {
            return 0.0;
        }
        self.pdf_with(wo, wi, &self.probabilities(wo))
    }

    fn pdf_with(&self, wo: Vec3, wi: Vec3, prob: &Probabilities) -> f32 {
        let p = &self.p;
        let mut pdf = 0.0;
        if wi.z > 0.0 {
            pdf += (prob[SHEEN] + prob[DIFFUSE]) * cosine_hemisphere_pdf(wi);
            if prob[SPECULAR] > 0.0 && !self.specular_smooth() {
                let (wo_a, wi_a) = (self.to_aniso(wo), self.to_aniso(wi));
                pdf += prob[SPECULAR] * reflection_pdf(&self.ggx, wo_a, (wo_a + wi_a).normalize());
            }
            if prob[COAT] > 0.0 && !self.coat_smooth() {
                let (wo_c, wi_c) = (self.to_coat(wo), self.to_coat(wi));
                if wi_c.z > 0.0 {
                    pdf += prob[COAT]
                        * reflection_pdf(&self.coat_ggx, wo_c, (wo_c + wi_c).normalize());
                }
            }
        } else {
            pdf += prob[TRANSLUCENT] * cosine_hemisphere_pdf(flip(wi));
        }
        if wi.z < 0.0 && prob[TRANSMISSION] > 0.0 && !self.specular_smooth() {
            let (wo_a, wi_a) = (self.to_aniso(wo), self.to_aniso(wi));
            pdf += prob[TRANSMISSION]
                * if p.thin {
                    reflection_pdf(&self.ggx, wo_a, (wo_a + flip(wi_a)).normalize())
                } else {
                    rough_refraction(&self.ggx, wo_a, wi_a, p.eta).map_or(0.0, |r| r.pdf)
                };
        }
        pdf
    }

    /// Picks a lobe with `u_lobe`, then a direction in it with `u`.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let prob = self.probabilities(wo);
        let mut lobe = DIFFUSE;
        let mut acc = 0.0;
        for (k, &pk) in prob.iter().enumerate() {
            acc += pk;
            if u_lobe < acc {
                lobe = k;
                break;
            }
        }
        let p = &self.p;
        let (wi, kind) = match lobe {
            COAT if self.coat_smooth() => {
                let wi = reflect(wo, p.coat_normal);
                if wi.z <= 0.0 {
                    return None;
                }
                let r = self.coat_fresnel(p.coat_normal.dot(wo));
                return delta(wi, Vec3::splat(r), prob[COAT], Lobe::Specular);
            }
            COAT => {
                let wo_c = self.to_coat(wo);
                let h = self.coat_ggx.sample_visible_normal(wo_c, u);
                (self.coat_to_local(reflect(wo_c, h)), Lobe::Glossy)
            }
            SPECULAR if self.specular_smooth() => {
                let wi = Vec3::new(-wo.x, -wo.y, wo.z);
                let f = self.dielectric_fresnel(wo.z) * (1.0 - p.metallic)
                    + self.metal_fresnel(wo.z) * p.metallic;
                return delta(
                    wi,
                    f * self.through_layers(wo, wi),
                    prob[SPECULAR],
                    Lobe::Specular,
                );
            }
            SPECULAR => {
                let wo_a = self.to_aniso(wo);
                let h = self.ggx.sample_visible_normal(wo_a, u);
                (self.aniso_to_local(reflect(wo_a, h)), Lobe::Glossy)
            }
            TRANSMISSION if self.specular_smooth() => {
                let fd = self.dielectric_fresnel(wo.z);
                let weight = p.transmission_tint
                    * ((1.0 - p.metallic) * p.transmission * (1.0 - fd.max_element()));
                let (wi, scale, kind) = if p.thin {
                    (-wo, 1.0, Lobe::StraightTransmission)
                } else {
                    let wi = fresnel::refract(wo, Vec3::Z, p.eta)?;
                    (wi, 1.0 / (p.eta * p.eta), Lobe::SpecularTransmission)
                };
                return delta(
                    wi,
                    weight * (scale * self.through_layers(wo, wi)),
                    prob[TRANSMISSION],
                    kind,
                );
            }
            TRANSMISSION => {
                let wo_a = self.to_aniso(wo);
                let h = self.ggx.sample_visible_normal(wo_a, u);
                let wi_a = if p.thin {
                    let r = reflect(wo_a, h);
                    if r.z <= 0.0 {
                        return None;
                    }
                    flip(r)
                } else {
                    fresnel::refract(wo_a, h, p.eta)?
                };
                (self.aniso_to_local(wi_a), Lobe::GlossyTransmission)
            }
            TRANSLUCENT => (
                flip(square_to_cosine_hemisphere(u)),
                Lobe::DiffuseTransmission,
            ),
            // The sheen and the diffuse base are both sampled by the cosine.
            _ => (square_to_cosine_hemisphere(u), Lobe::Diffuse),
        };
        let transmitted = matches!(kind, Lobe::GlossyTransmission | Lobe::DiffuseTransmission);
        if wi.z == 0.0 || (wi.z < 0.0) != transmitted {
            return None;
        }
        BsdfSample::from_mixture(wi, self.eval(wo, wi), self.pdf_with(wo, wi, &prob), kind)
    }

    /// True if some lobe is not a delta.
    pub fn has_non_delta(&self) -> bool {
        let p = &self.p;
        !self.specular_smooth()
            || (p.metallic < 1.0 && p.transmission < 1.0)
            || p.sheen.is_some()
            || (p.coat > 0.0 && !self.coat_smooth())
    }

    /// True if some lobe transmits.
    pub fn transmits(&self) -> bool {
        (self.p.transmission > 0.0 || self.p.translucency > 0.0) && self.p.metallic < 1.0
    }

    /// The weight of the straight-through delta lobe (a smooth thin wall) for light
    /// crossing along `-wo`.
    pub fn straight_transmission(&self, wo: Vec3) -> Vec3 {
        let p = &self.p;
        if !(p.thin && self.specular_smooth() && self.transmits()) {
            return Vec3::ZERO;
        }
        let wo = if wo.z < 0.0 { -wo } else { wo };
        let fd = self.dielectric_fresnel(wo.z);
        p.transmission_tint
            * ((1.0 - p.metallic)
                * p.transmission
                * (1.0 - fd.max_element())
                * self.through_layers(wo, -wo))
    }

    /// Directional albedo estimates at `wo` of the diffuse (sheen included), glossy and
    /// transmission lobes.
    pub fn albedo_lobes(&self, wo: Vec3) -> PerLobe {
        let p = &self.p;
        let cos = wo.z.clamp(0.0, 1.0);
        let c = self.coat_fresnel(p.coat_normal.dot(wo).abs());
        let under = 1.0 - c;
        let (sheen, scaling) = match p.sheen {
            Some(s) => (s.color * s.albedo(cos), s.scaling(cos, cos)),
            None => (Vec3::ZERO, 1.0),
        };
        let below = under * scaling;
        let fd = self.dielectric_fresnel(cos);
        let specular = (fd * (1.0 - p.metallic) + self.metal_fresnel(cos) * p.metallic) * below;
        let rest = (1.0 - p.metallic) * (1.0 - fd.max_element()) * below;
        let diffuse = rest * (1.0 - p.transmission);
        [
            p.base * (diffuse * (1.0 - p.translucency))
                + p.translucency_color * (diffuse * p.translucency)
                + sheen * under,
            specular + Vec3::splat(c),
            p.transmission_tint * (rest * p.transmission),
        ]
    }
}

/// A sample of a delta lobe chosen with probability `probability` whose reflectance or
/// transmittance towards `wi` is `value`.
#[inline]
fn delta(wi: Vec3, value: Vec3, probability: f32, lobe: Lobe) -> Option<BsdfSample> {
    (probability > 0.0).then(|| BsdfSample {
        wi,
        weight: value / probability,
        pdf: probability,
        lobe,
    })
}
