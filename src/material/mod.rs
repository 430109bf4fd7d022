//! BSDFs and their evaluation from scene materials.
//!
//! Every BSDF works in the local shading frame (+z = shading normal) and offers the same
//! three operations, which the chi-square tests check against each other:
//! `eval` (f · cos θi), `pdf` (solid-angle density of `sample`) and `sample`
//! (direction, weight f · cos θi / pdf). Delta lobes never appear in `eval` or `pdf`; a
//! sampled delta lobe reports [`Lobe::Specular`] and its discrete probability as `pdf`.

pub mod gltf_pbr;
pub mod lambert;
#[cfg(target_arch = "x86_64")]
pub(crate) mod lanes;
pub mod microfacet;
pub mod phong;

use crate::scene::{BsdfModel, Material, Texture, TextureRef};
use glam::{Vec2, Vec3, Vec4};
use gltf_pbr::GltfPbr;
use lambert::Lambert;
use phong::Phong;

/// A colour per lobe kind: diffuse, glossy, transmission. As lobe shares, the parts of a
/// path's light owed to each lobe of its first scattering event, per channel (they add up
/// to one where the path carries light); as albedos, each lobe's reflectance.
pub type PerLobe = [Vec3; 3];

/// The lobe shares of f · cos θi split as `[diffuse, glossy]` (see [`Bsdf::eval_lobes`]).
#[inline]
pub fn shares([diffuse, glossy]: [Vec3; 2]) -> PerLobe {
    let total = diffuse + glossy;
    let share = |part: Vec3| Vec3::select(total.cmpgt(Vec3::ZERO), part / total, Vec3::ZERO);
    [share(diffuse), share(glossy), Vec3::ZERO]
}

/// The kind of lobe a sample came from (the lobe splits of the AOVs follow it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lobe {
    Diffuse,
    Glossy,
    /// A delta lobe (perfect mirror): only BSDF sampling can find it.
    Specular,
}

/// A sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    pub wi: Vec3,
    /// f · |cos θi| / pdf.
    pub weight: Vec3,
    /// Solid-angle density, or the lobe's discrete probability for a delta lobe.
    pub pdf: f32,
    pub lobe: Lobe,
}

impl BsdfSample {
    /// The sample of direction `wi` from a mixture of lobes whose combined density there is
    /// `pdf` and whose f · cos θi is `f_cos`; `None` where the density vanishes.
    #[inline]
    pub fn from_mixture(wi: Vec3, f_cos: Vec3, pdf: f32, lobe: Lobe) -> Option<Self> {
        (pdf > 0.0).then(|| Self {
            wi,
            weight: f_cos / pdf,
            pdf,
            lobe,
        })
    }

    /// True if the sample came from a delta lobe.
    pub fn is_delta(&self) -> bool {
        self.lobe == Lobe::Specular
    }
}

/// A BSDF at one surface point.
#[derive(Clone, Copy, Debug)]
pub enum Bsdf {
    Lambert(Lambert),
    GltfPbr(GltfPbr),
    Phong(Phong),
}

impl Bsdf {
    /// f(wo, wi) · cos θi over the non-delta lobes.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        match self {
            Self::Lambert(b) => b.eval(wo, wi),
            Self::GltfPbr(b) => b.eval(wo, wi),
            Self::Phong(b) => b.eval(wo, wi),
        }
    }

    /// [`Bsdf::eval`] split by lobe: diffuse, glossy (lucerna's BSDFs transmit nothing).
    #[inline]
    pub fn eval_lobes(&self, wo: Vec3, wi: Vec3) -> [Vec3; 2] {
        match self {
            Self::Lambert(b) => [b.eval(wo, wi), Vec3::ZERO],
            Self::GltfPbr(b) => b.eval_lobes(wo, wi),
            Self::Phong(b) => b.eval_lobes(wo, wi),
        }
    }

    /// The lobe shares of light arriving along `wi` and leaving along `wo`; for a sample of
    /// a delta lobe (a perfect mirror: glossy), pass `wi` = `None`.
    #[inline]
    pub fn lobe_shares(&self, wo: Vec3, wi: Option<Vec3>) -> PerLobe {
        match wi {
            Some(wi) => shares(self.eval_lobes(wo, wi)),
            None => [Vec3::ZERO, Vec3::ONE, Vec3::ZERO],
        }
    }

    /// Solid-angle density with which [`Bsdf::sample`] produces `wi` (non-delta lobes).
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Self::Lambert(b) => b.pdf(wo, wi),
            Self::GltfPbr(b) => b.pdf(wo, wi),
            Self::Phong(b) => b.pdf(wo, wi),
        }
    }

    /// Samples a direction: `u_lobe` picks the lobe, `u` the direction in it.
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        match self {
            Self::Lambert(b) => b.sample(wo, u),
            Self::GltfPbr(b) => b.sample(wo, u_lobe, u),
            Self::Phong(b) => b.sample(wo, u_lobe, u),
        }
    }

    /// True if the surface reflects nothing in any direction (a black Lambert or Phong
    /// surface, as emitters often are): a path ends there, with no light samples or
    /// continuations whose every contribution would be zero. A glTF surface always reflects
    /// something (its Fresnel term is never zero at grazing angles).
    #[inline]
    pub fn is_black(&self) -> bool {
        match self {
            Self::Lambert(b) => b.albedo == Vec3::ZERO,
            Self::Phong(b) => b.kd == Vec3::ZERO && b.ks == Vec3::ZERO,
            Self::GltfPbr(_) => false,
        }
    }

    /// True if some lobe is not a delta, i.e. light sampling can contribute.
    #[inline]
    pub fn has_non_delta(&self) -> bool {
        match self {
            Self::GltfPbr(b) => b.has_non_delta(),
            Self::Lambert(_) | Self::Phong(_) => true,
        }
    }

    /// Directional albedo estimate at `wo` of each lobe (diffuse, glossy, transmission):
    /// the `*_color` AOVs; their sum is the albedo denoisers expect in the albedo AOV.
    pub fn albedo_lobes(&self, wo: Vec3) -> PerLobe {
        match self {
            Self::Lambert(b) => [b.albedo, Vec3::ZERO, Vec3::ZERO],
            Self::GltfPbr(b) => {
                let [diffuse, glossy] = b.albedo_lobes(wo);
                [diffuse, glossy, Vec3::ZERO]
            }
            Self::Phong(b) => [b.kd, b.ks, Vec3::ZERO],
        }
    }
}

/// Interpolated vertex attributes at a surface point that material lookups read.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceAttributes {
    /// Texture coordinate sets 0 and 1 (zero where the mesh has none).
    pub uv: [Vec2; 2],
    /// Vertex colour (white where the mesh has none).
    pub color: Vec4,
}

/// Looks up a texture slot, applying its UV set and transform.
#[inline]
pub fn texture_lookup(
    textures: &[Texture],
    slot: &TextureRef,
    attrs: &SurfaceAttributes,
    srgb: bool,
) -> Vec4 {
    let uv = attrs.uv[(slot.tex_coord as usize).min(1)];
    let uv = slot.transform.map_or(uv, |t| t.apply(uv));
    textures[slot.texture as usize].sample(uv, srgb)
}

/// Base colour (factor × texture × vertex colour), linear RGBA.
#[inline]
pub fn base_color(m: &Material, textures: &[Texture], attrs: &SurfaceAttributes) -> Vec4 {
    let mut c = m.base_color * attrs.color;
    if let Some(t) = &m.base_color_texture {
        c *= texture_lookup(textures, t, attrs, true);
    }
    c
}

/// Coverage alpha of the material at a surface point.
#[inline]
pub fn alpha(m: &Material, textures: &[Texture], attrs: &SurfaceAttributes) -> f32 {
    base_color(m, textures, attrs).w
}

/// Emitted radiance of the material at a surface point.
#[inline]
pub fn emission(m: &Material, textures: &[Texture], attrs: &SurfaceAttributes) -> Vec3 {
    let mut e = m.emissive;
    if let Some(t) = &m.emissive_texture {
        e *= texture_lookup(textures, t, attrs, true).truncate();
    }
    e
}

/// The tangent-space normal from the material's normal map (scaled in x and y as glTF
/// specifies), or `None` without a normal map.
#[inline]
pub fn tangent_space_normal(
    m: &Material,
    textures: &[Texture],
    attrs: &SurfaceAttributes,
) -> Option<Vec3> {
    let t = m.normal_texture.as_ref()?;
    let c = texture_lookup(textures, t, attrs, false).truncate() * 2.0 - Vec3::ONE;
    let n = Vec3::new(c.x * m.normal_scale, c.y * m.normal_scale, c.z);
    let n = n.normalize_or_zero();
    (n.z > 0.0).then_some(n)
}

/// The BSDF of material `m` at a surface point.
pub fn bsdf(m: &Material, textures: &[Texture], attrs: &SurfaceAttributes) -> Bsdf {
    let base = base_color(m, textures, attrs).truncate();
    match m.model {
        BsdfModel::Lambert => Bsdf::Lambert(Lambert {
            albedo: base.clamp(Vec3::ZERO, Vec3::ONE),
        }),
        BsdfModel::Phong { exponent, specular } => Bsdf::Phong(Phong {
            // kd + ks <= 1 keeps the lobe pair energy-conserving.
            kd: base.min(Vec3::ONE - specular).max(Vec3::ZERO),
            ks: specular,
            exponent,
        }),
        BsdfModel::GltfPbr => {
            let (mut metallic, mut roughness) = (m.metallic, m.roughness);
            if let Some(t) = &m.metallic_roughness_texture {
                let mr = texture_lookup(textures, t, attrs, false);
                roughness *= mr.y;
                metallic *= mr.z;
            }
            let mut pbr = GltfPbr::new(base, metallic, roughness, m.ior)
                .with_clearcoat(m.clearcoat, m.clearcoat_roughness);
            if let Some(color) = m.specular_color {
                pbr = pbr.with_specular_color(color);
            }
            Bsdf::GltfPbr(pbr)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `is_black` holds exactly for the surfaces that reflect nothing: their f · cos θi and
    /// sample weights vanish in every direction, while every surface it rejects reflects
    /// something in some direction (a black glTF surface at grazing angles, by Fresnel).
    #[test]
    fn black_surfaces_are_the_ones_that_reflect_nothing() {
        let phong = |kd: Vec3, ks: Vec3| {
            Bsdf::Phong(Phong {
                kd,
                ks,
                exponent: 20.0,
            })
        };
        let cases = [
            Bsdf::Lambert(Lambert { albedo: Vec3::ZERO }),
            Bsdf::Lambert(Lambert {
                albedo: Vec3::new(0.0, 0.0, 0.1),
            }),
            phong(Vec3::ZERO, Vec3::ZERO),
            phong(Vec3::ZERO, Vec3::splat(0.2)),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::ZERO, 0.0, 0.5, 1.5)),
            Bsdf::GltfPbr(GltfPbr::new(Vec3::ZERO, 1.0, 0.5, 1.5)),
        ];
        let directions: Vec<Vec3> = (1..12)
            .flat_map(|i| {
                let z = i as f32 / 12.0;
                let r = (1.0 - z * z).sqrt();
                (0..8).map(move |k| {
                    let phi = k as f32 * 0.785;
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                })
            })
            .collect();
        for (i, bsdf) in cases.iter().enumerate() {
            let reflects = directions.iter().any(|&wo| {
                directions.iter().any(|&wi| bsdf.eval(wo, wi) != Vec3::ZERO)
                    || [0.1, 0.5, 0.9].iter().any(|&u| {
                        bsdf.sample(wo, u, Vec2::new(u, 1.0 - u))
                            .is_some_and(|s| s.weight != Vec3::ZERO)
                    })
            });
            assert_eq!(bsdf.is_black(), !reflects, "case {i}");
        }
    }
}
