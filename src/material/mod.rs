//! BSDFs and their evaluation from scene materials.
//!
//! Every BSDF works in the local shading frame (+z = shading normal) and offers the same
//! three operations, which the chi-square tests check against each other:
//! `eval` (f · |cos θi|), `pdf` (solid-angle density of `sample`) and `sample`
//! (direction, weight f · |cos θi| / pdf). Directions below the surface (wi.z < 0) are
//! transmission, which only the dielectrics produce. Delta lobes never appear in `eval` or
//! `pdf`; a sampled delta lobe reports [`Lobe::Specular`] (a mirror) or
//! [`Lobe::SpecularTransmission`] and its discrete probability as `pdf`.

mod build;
pub mod dielectric;
pub mod energy;
pub mod fresnel;
pub mod gltf_pbr;
pub mod lambert;
#[cfg(target_arch = "x86_64")]
pub(crate) mod lanes;
pub mod layered;
pub mod microfacet;
mod microfacet_albedo;
pub mod oren_nayar;
pub mod phong;
pub mod sheen;
mod sheen_albedo;
mod table;
pub mod thin_film;

use crate::scene::{Material, Texture, TextureRef};
pub use build::{bsdf, bsdf_in, compact_bsdf};
use dielectric::{Dielectric, ThinDielectric};
use glam::{Vec2, Vec3, Vec4};
use gltf_pbr::GltfPbr;
use lambert::Lambert;
use layered::Layered;
use phong::Phong;

/// A colour per lobe kind: diffuse, glossy, transmission. As lobe shares, the parts of a
/// path's light owed to each lobe of its first scattering event, per channel (they add up
/// to one where the path carries light); as albedos, each lobe's reflectance.
pub type PerLobe = [Vec3; 3];

/// The lobe shares of f · cos θi split as `[diffuse, glossy, transmission]` (see
/// [`Bsdf::eval_lobes`]).
#[inline]
pub fn shares(lobes: PerLobe) -> PerLobe {
    let total = lobes[0] + lobes[1] + lobes[2];
    let share = |part: Vec3| Vec3::select(total.cmpgt(Vec3::ZERO), part / total, Vec3::ZERO);
    lobes.map(share)
}

/// The kind of lobe a sample came from (the lobe splits of the AOVs follow it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lobe {
    Diffuse,
    Glossy,
    /// A delta reflection lobe (perfect mirror): only BSDF sampling can find it.
    Specular,
    /// Rough transmission (refraction through a rough interface, or a rough thin slab).
    GlossyTransmission,
    /// Lambertian transmission to the other side (KHR_materials_diffuse_transmission): it
    /// crosses the surface but counts as diffuse in the lobe layers.
    DiffuseTransmission,
    /// Delta transmission bent by refraction (a smooth volume boundary).
    SpecularTransmission,
    /// Delta transmission straight through (a smooth thin wall): the surface is a filter
    /// that paths cross without a scattering event (see `integrator::path`).
    StraightTransmission,
}

impl Lobe {
    /// Index of the lobe kind in a [`PerLobe`]: diffuse, glossy (mirrors too),
    /// transmission.
    #[inline]
    pub fn kind(self) -> usize {
        match self {
            Self::Diffuse | Self::DiffuseTransmission => 0,
            Self::Glossy | Self::Specular => 1,
            Self::GlossyTransmission | Self::SpecularTransmission | Self::StraightTransmission => 2,
        }
    }
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
    #[inline]
    pub fn is_delta(&self) -> bool {
        matches!(
            self.lobe,
            Lobe::Specular | Lobe::SpecularTransmission | Lobe::StraightTransmission
        )
    }

    /// True if the sampled direction crosses the surface.
    #[inline]
    pub fn is_transmission(&self) -> bool {
        matches!(
            self.lobe,
            Lobe::GlossyTransmission
                | Lobe::DiffuseTransmission
                | Lobe::SpecularTransmission
                | Lobe::StraightTransmission
        )
    }
}

/// A BSDF at one surface point. The layered glTF model lives in a [`BsdfStorage`] that the
/// BSDF borrows: it is several times the size of the others, and a BSDF is copied (the
/// packet kernel keeps eight per bounce), so it is kept out of line, but not on the heap.
#[derive(Clone, Copy, Debug)]
pub enum Bsdf<'s> {
    Lambert(Lambert),
    GltfPbr(GltfPbr),
    Phong(Phong),
    Dielectric(Dielectric),
    ThinDielectric(ThinDielectric),
    Layered(&'s Layered),
}

/// Where a BSDF too large to keep in a [`Bsdf`] (the layered glTF model) is built; the BSDF
/// borrows it.
#[derive(Debug, Default)]
pub struct BsdfStorage(pub(super) Option<Layered>);

impl Bsdf<'_> {
    /// f(wo, wi) · |cos θi| over the non-delta lobes.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        match self {
            Self::Lambert(b) => b.eval(wo, wi),
            Self::GltfPbr(b) => b.eval(wo, wi),
            Self::Phong(b) => b.eval(wo, wi),
            Self::Dielectric(b) => b.eval(wo, wi),
            Self::ThinDielectric(b) => b.eval(wo, wi),
            Self::Layered(b) => b.eval(wo, wi),
        }
    }

    /// [`Bsdf::eval`] split by lobe kind: diffuse, glossy, transmission.
    #[inline]
    pub fn eval_lobes(&self, wo: Vec3, wi: Vec3) -> PerLobe {
        match self {
            Self::Lambert(b) => [b.eval(wo, wi), Vec3::ZERO, Vec3::ZERO],
            Self::GltfPbr(b) => {
                let [diffuse, glossy] = b.eval_lobes(wo, wi);
                [diffuse, glossy, Vec3::ZERO]
            }
            Self::Phong(b) => {
                let [diffuse, glossy] = b.eval_lobes(wo, wi);
                [diffuse, glossy, Vec3::ZERO]
            }
            Self::Dielectric(b) => b.eval_lobes(wo, wi),
            Self::ThinDielectric(b) => b.eval_lobes(wo, wi),
            Self::Layered(b) => b.eval_lobes(wo, wi),
        }
    }

    /// The lobe shares of the light a sample `s` of this BSDF at `wo` brings: split by
    /// lobe where it is not a delta, all of its own kind where it is.
    #[inline]
    pub fn lobe_shares(&self, wo: Vec3, s: &BsdfSample) -> PerLobe {
        if s.is_delta() {
            let mut shares = [Vec3::ZERO; 3];
            shares[s.lobe.kind()] = Vec3::ONE;
            return shares;
        }
        shares(self.eval_lobes(wo, s.wi))
    }

    /// Solid-angle density with which [`Bsdf::sample`] produces `wi` (non-delta lobes).
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Self::Lambert(b) => b.pdf(wo, wi),
            Self::GltfPbr(b) => b.pdf(wo, wi),
            Self::Phong(b) => b.pdf(wo, wi),
            Self::Dielectric(b) => b.pdf(wo, wi),
            Self::ThinDielectric(b) => b.pdf(wo, wi),
            Self::Layered(b) => b.pdf(wo, wi),
        }
    }

    /// Samples a direction: `u_lobe` picks the lobe, `u` the direction in it.
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        match self {
            Self::Lambert(b) => b.sample(wo, u),
            Self::GltfPbr(b) => b.sample(wo, u_lobe, u),
            Self::Phong(b) => b.sample(wo, u_lobe, u),
            Self::Dielectric(b) => b.sample(wo, u_lobe, u),
            Self::ThinDielectric(b) => b.sample(wo, u_lobe, u),
            Self::Layered(b) => b.sample(wo, u_lobe, u),
        }
    }

    /// True if light can cross the surface (some lobe transmits): light samples are then
    /// taken on both sides of it.
    #[inline]
    pub fn transmits(&self) -> bool {
        match self {
            Self::Dielectric(_) | Self::ThinDielectric(_) => true,
            Self::Layered(b) => b.transmits(),
            _ => false,
        }
    }

    /// The weight of a delta lobe that continues straight through the surface, for light
    /// crossing it along `-wo` (zero for none): such a surface is a filter that shadow
    /// rays pass, and that paths cross without a scattering event (see
    /// `integrator::path`).
    #[inline]
    pub fn straight_transmission(&self, wo: Vec3) -> Vec3 {
        match self {
            Self::ThinDielectric(b) => b.straight_transmission(wo),
            Self::Layered(b) => b.straight_transmission(wo),
            _ => Vec3::ZERO,
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
            Self::GltfPbr(_) | Self::Dielectric(_) | Self::ThinDielectric(_) | Self::Layered(_) => {
                false
            }
        }
    }

    /// True if some lobe is not a delta, i.e. light sampling can contribute.
    #[inline]
    pub fn has_non_delta(&self) -> bool {
        match self {
            Self::GltfPbr(b) => b.has_non_delta(),
            Self::Dielectric(b) => b.has_non_delta(),
            Self::ThinDielectric(b) => b.has_non_delta(),
            Self::Layered(b) => b.has_non_delta(),
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
            Self::Dielectric(b) => b.albedo_lobes(wo),
            Self::ThinDielectric(b) => b.albedo_lobes(wo),
            Self::Layered(b) => b.albedo_lobes(wo),
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
    /// For each UV set, the axes (full widths) of the footprint that lookups filter over
    /// (`world::footprint`); zero for lookups at the point.
    pub footprint: [[Vec2; 2]; 2],
}

/// Looks up a texture slot, applying its UV set and transform.
#[inline]
pub fn texture_lookup(
    textures: &[Texture],
    slot: &TextureRef,
    attrs: &SurfaceAttributes,
    srgb: bool,
) -> Vec4 {
    let set = (slot.tex_coord as usize).min(1);
    let uv = attrs.uv[set];
    let axes = attrs.footprint[set];
    let texture = &textures[slot.texture as usize];
    if axes == [Vec2::ZERO; 2] {
        return texture.sample(slot.transform.map_or(uv, |t| t.apply(uv)), srgb);
    }
    let (uv, axes) = match slot.transform {
        Some(t) => {
            let at = t.apply(uv);
            (at, axes.map(|a| t.apply(uv + a) - at))
        }
        None => (uv, axes),
    };
    texture.sample_footprint(uv, axes, srgb)
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
    decode_normal(textures, m.normal_texture.as_ref()?, m.normal_scale, attrs)
}

/// The tangent-space normal a normal map `slot` holds at a point, x and y scaled by `scale`.
#[inline]
pub(super) fn decode_normal(
    textures: &[Texture],
    slot: &TextureRef,
    scale: f32,
    attrs: &SurfaceAttributes,
) -> Option<Vec3> {
    let c = texture_lookup(textures, slot, attrs, false).truncate() * 2.0 - Vec3::ONE;
    let n = Vec3::new(c.x * scale, c.y * scale, c.z);
    let n = n.normalize_or_zero();
    (n.z > 0.0).then_some(n)
}

/// What a BSDF depends on beyond its material and the point's attributes: which side of
/// the surface the light leaves towards the path, and what lies outside.
#[derive(Clone, Copy, Debug)]
pub struct ShadingContext {
    /// The path arrived on the surface's front (the outside of a volume).
    pub front: bool,
    /// Index of refraction of the medium on the surface's outside (1 for air; the
    /// enclosing volume's for nested dielectrics).
    pub outside_ior: f32,
    /// The surface's tangent frame (tangent, bitangent with the mesh's handedness,
    /// interpolated normal) in the local shading frame, where the mesh has tangents: the
    /// frame that the coat's normal map and the anisotropy direction are given in.
    pub tangents: Option<[Vec3; 3]>,
}

impl Default for ShadingContext {
    fn default() -> Self {
        Self {
            front: true,
            outside_ior: 1.0,
            tangents: None,
        }
    }
}
