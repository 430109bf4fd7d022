//! BSDFs and their evaluation from scene materials.
//!
//! Every BSDF works in the local shading frame (+z = shading normal) and offers the same
//! three operations, which the chi-square tests check against each other:
//! `eval` (f · |cos θi|), `pdf` (solid-angle density of `sample`) and `sample`
//! (direction, weight f · |cos θi| / pdf). Directions below the surface (wi.z < 0) are
//! transmission, which only the dielectrics produce. Delta lobes never appear in `eval` or
//! `pdf`; a sampled delta lobe reports [`Lobe::Specular`] (a mirror) or
//! [`Lobe::SpecularTransmission`] and its discrete probability as `pdf`.

pub mod dielectric;
pub mod fresnel;
pub mod gltf_pbr;
pub mod lambert;
#[cfg(target_arch = "x86_64")]
pub(crate) mod lanes;
pub mod layered;
pub mod microfacet;
pub mod phong;
pub mod sheen;
mod sheen_albedo;
pub mod thin_film;

use crate::scene::{BsdfModel, Material, Texture, TextureRef};
use dielectric::{Dielectric, ThinDielectric};
use glam::{Vec2, Vec3, Vec4};
use gltf_pbr::GltfPbr;
use lambert::Lambert;
use layered::{Film, Layered, LayeredParams};
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
            Self::Diffuse => 0,
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
            Lobe::GlossyTransmission | Lobe::SpecularTransmission | Lobe::StraightTransmission
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
pub struct BsdfStorage(Option<Layered>);

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
fn decode_normal(
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

/// A texture slot's value at a surface point (white without the texture), linear.
#[inline]
fn slot(textures: &[Texture], slot: Option<&TextureRef>, attrs: &SurfaceAttributes) -> Vec4 {
    slot.map_or(Vec4::ONE, |t| texture_lookup(textures, t, attrs, false))
}

/// The BSDF of material `m` at a surface point seen from the front, in air (a layered one
/// built in `storage`).
pub fn bsdf<'s>(
    m: &Material,
    textures: &[Texture],
    attrs: &SurfaceAttributes,
    storage: &'s mut BsdfStorage,
) -> Bsdf<'s> {
    bsdf_in(m, textures, attrs, &ShadingContext::default(), storage)
}

/// The BSDF of material `m` at a surface point in context `ctx` (a layered one built in
/// `storage`).
pub fn bsdf_in<'s>(
    m: &Material,
    textures: &[Texture],
    attrs: &SurfaceAttributes,
    ctx: &ShadingContext,
    storage: &'s mut BsdfStorage,
) -> Bsdf<'s> {
    match build(m, textures, attrs, ctx) {
        Built::Compact(b) => b,
        Built::Layered(params) => Bsdf::Layered(storage.0.insert(Layered::new(params))),
    }
}

/// The BSDF of material `m` at a surface point in context `ctx` where it is not the
/// layered model (which needs a [`BsdfStorage`]).
pub fn compact_bsdf(
    m: &Material,
    textures: &[Texture],
    attrs: &SurfaceAttributes,
    ctx: &ShadingContext,
) -> Option<Bsdf<'static>> {
    match build(m, textures, attrs, ctx) {
        Built::Compact(b) => Some(b),
        Built::Layered(_) => None,
    }
}

/// A BSDF as built: one that fits in [`Bsdf`], or the layered model's parameters.
enum Built {
    Compact(Bsdf<'static>),
    Layered(LayeredParams),
}

fn build(
    m: &Material,
    textures: &[Texture],
    attrs: &SurfaceAttributes,
    ctx: &ShadingContext,
) -> Built {
    let base = base_color(m, textures, attrs).truncate();
    if m.unlit {
        // A clear filter: every ray but the camera's passes (see `integrator::path`).
        return Built::Compact(Bsdf::ThinDielectric(ThinDielectric::new(
            1.0,
            0.0,
            Vec3::ONE,
        )));
    }
    match m.model {
        BsdfModel::Lambert => Built::Compact(Bsdf::Lambert(Lambert {
            albedo: base.clamp(Vec3::ZERO, Vec3::ONE),
        })),
        BsdfModel::Phong { exponent, specular } => Built::Compact(Bsdf::Phong(Phong {
            // kd + ks <= 1 keeps the lobe pair energy-conserving.
            kd: base.min(Vec3::ONE - specular).max(Vec3::ZERO),
            ks: specular,
            exponent,
        })),
        BsdfModel::GltfPbr => {
            let (mut metallic, mut roughness) = (m.metallic, m.roughness);
            if let Some(t) = &m.metallic_roughness_texture {
                let mr = texture_lookup(textures, t, attrs, false);
                roughness *= mr.y;
                metallic *= mr.z;
            }
            let transmission = if m.transmits() {
                m.transmission * slot(textures, m.transmission_texture.as_ref(), attrs).x
            } else {
                0.0
            };
            if let Some(b) = reduced_bsdf(m, base, metallic, roughness, transmission) {
                return Built::Compact(b);
            }
            if m.transmits()
                && let Some(b) = dielectric_bsdf(m, base, metallic, roughness, transmission, ctx)
            {
                return Built::Compact(b);
            }
            if m.transmits() || needs_layers(m) {
                let point = Point {
                    textures,
                    attrs,
                    ctx,
                };
                let params = layered_params(m, &point, base, metallic, roughness, transmission);
                return Built::Layered(params);
            }
            let coat = slot(textures, m.clearcoat_texture.as_ref(), attrs).x * m.clearcoat;
            let coat_roughness = slot(textures, m.clearcoat_roughness_texture.as_ref(), attrs).y
                * m.clearcoat_roughness;
            let mut pbr =
                GltfPbr::new(base, metallic, roughness, m.ior).with_clearcoat(coat, coat_roughness);
            if let Some(color) = m.specular_color {
                pbr = pbr.with_specular_color(color);
            }
            Built::Compact(Bsdf::GltfPbr(pbr))
        }
    }
}

/// The simpler BSDF a glTF material is at a point where its other lobes weigh nothing, or
/// `None`: where the specular layer's weight is zero (KHR_materials_specular
/// `specularFactor` 0) and the point is neither metal nor transmitting nor coated nor
/// sheened, the layered model is exactly Lambert's (its diffuse base, under a layer that
/// reflects nothing); where the point is all metal, uncoated, without sheen, iridescence or
/// anisotropy, it is exactly `gltf_pbr`'s conductor (the specular extension does not apply
/// to metals). Factors multiply their textures, so a zero factor is zero everywhere; the
/// unit tests compare each reduction with the model it replaces.
fn reduced_bsdf(
    m: &Material,
    base: Vec3,
    metallic: f32,
    roughness: f32,
    transmission: f32,
) -> Option<Bsdf<'static>> {
    let uncoated = m.clearcoat == 0.0;
    let unsheened = m.sheen.is_none_or(|s| s.color == Vec3::ZERO);
    if !(uncoated && unsheened) {
        return None;
    }
    if m.specular.weight == 0.0 && metallic <= 0.0 && transmission <= 0.0 {
        return Some(Bsdf::Lambert(Lambert {
            albedo: base.clamp(Vec3::ZERO, Vec3::ONE),
        }));
    }
    let plain_metal = metallic >= 1.0
        && !m.transmits()
        && m.iridescence.is_none_or(|i| i.factor == 0.0)
        && m.anisotropy.is_none();
    if plain_metal && (!m.specular.is_default() || needs_layers(m)) {
        return Some(Bsdf::GltfPbr(GltfPbr::new(base, 1.0, roughness, m.ior)));
    }
    None
}

/// True if material `m` needs the layered model (beyond `gltf_pbr`'s base and coat) even
/// where it does not transmit.
fn needs_layers(m: &Material) -> bool {
    m.sheen.is_some_and(|s| s.color != Vec3::ZERO)
        || m.iridescence.is_some_and(|i| i.factor != 0.0)
        || m.anisotropy.is_some()
        || !m.specular.is_default()
        || (m.clearcoat_normal_texture.is_some() && m.clearcoat != 0.0)
}

/// Where a BSDF is built: the textures, the point's attributes and its context.
struct Point<'p> {
    textures: &'p [Texture],
    attrs: &'p SurfaceAttributes,
    ctx: &'p ShadingContext,
}

impl Point<'_> {
    /// A texture slot's value (white without one), linear or sRGB-decoded.
    fn read(&self, slot: Option<&TextureRef>, srgb: bool) -> Vec4 {
        slot.map_or(Vec4::ONE, |t| {
            texture_lookup(self.textures, t, self.attrs, srgb)
        })
    }

    /// A vector of the tangent frame (tangent-space coordinates) in the local shading frame.
    fn tangent_to_local(&self, v: Vec3) -> Option<Vec3> {
        let [t, b, n] = self.ctx.tangents?;
        Some(t * v.x + b * v.y + n * v.z)
    }
}

/// The layered model's parameters of material `m` at a point, given its base colour,
/// metallic, roughness and transmission there.
fn layered_params(
    m: &Material,
    at: &Point,
    base: Vec3,
    metallic: f32,
    roughness: f32,
    transmission: f32,
) -> LayeredParams {
    let ctx = at.ctx;
    let r = roughness.clamp(0.0, 1.0);
    let alpha = r * r;
    // Anisotropy: alpha along the direction rises towards 1 with the strength squared.
    let (alpha, anisotropy_direction) = match &m.anisotropy {
        Some(a) => {
            let texel = a.texture.map_or(Vec4::new(1.0, 0.5, 1.0, 1.0), |t| {
                texture_lookup(at.textures, &t, at.attrs, false)
            });
            let strength = (a.strength * texel.z).clamp(0.0, 1.0);
            let d = Vec2::new(texel.x * 2.0 - 1.0, texel.y * 2.0 - 1.0).normalize_or(Vec2::X);
            let (s, c) = a.rotation.sin_cos();
            let d = Vec2::new(c * d.x - s * d.y, s * d.x + c * d.y);
            let direction = at
                .tangent_to_local(d.extend(0.0))
                .map(|v| Vec2::new(v.x, v.y).normalize_or(Vec2::X))
                .unwrap_or(Vec2::X);
            let along = alpha + (1.0 - alpha) * strength * strength;
            (Vec2::new(along, alpha), direction)
        }
        None => (Vec2::splat(alpha), Vec2::X),
    };
    let ior = if m.ior > 0.0 { m.ior } else { f32::INFINITY };
    let relative = ior / ctx.outside_ior;
    let eta = match (m.volume, ctx.front) {
        (Some(_), false) => 1.0 / relative,
        _ => relative,
    };
    let f0 = match m.specular_color {
        Some(color) => color,
        None => {
            let f0_ior = if relative.is_finite() {
                fresnel::normal_reflectance(relative)
            } else {
                1.0
            };
            let color =
                m.specular.color * at.read(m.specular.color_texture.as_ref(), true).truncate();
            (color * f0_ior).min(Vec3::ONE)
        }
    };
    let specular_weight = m.specular.weight * at.read(m.specular.weight_texture.as_ref(), false).w;
    let sheen = m.sheen.map(|s| {
        sheen::Sheen::new(
            s.color * at.read(s.color_texture.as_ref(), true).truncate(),
            s.roughness * at.read(s.roughness_texture.as_ref(), false).w,
        )
    });
    let coat = m.clearcoat * at.read(m.clearcoat_texture.as_ref(), false).x;
    let coat_roughness =
        m.clearcoat_roughness * at.read(m.clearcoat_roughness_texture.as_ref(), false).y;
    let coat_normal = m
        .clearcoat_normal_texture
        .as_ref()
        .and_then(|t| decode_normal(at.textures, t, m.clearcoat_normal_scale, at.attrs))
        .and_then(|n| at.tangent_to_local(n))
        .unwrap_or(Vec3::Z);
    let film = m.iridescence.map(|i| {
        let thickness_texel = i
            .thickness_texture
            .map_or(1.0, |t| texture_lookup(at.textures, &t, at.attrs, false).y);
        Film {
            factor: (i.factor * at.read(i.texture.as_ref(), false).x).clamp(0.0, 1.0),
            thickness: i.thickness_min + (i.thickness_max - i.thickness_min) * thickness_texel,
            ior: i.ior,
        }
    });
    LayeredParams {
        base,
        metallic,
        alpha,
        anisotropy_direction,
        transmission,
        transmission_tint: m.transmission_color.unwrap_or(base),
        thin: m.volume.is_none(),
        eta,
        exact: m.transmits(),
        f0,
        specular_weight,
        sheen,
        coat,
        coat_alpha: coat_roughness * coat_roughness,
        coat_normal,
        film: film.filter(|f| f.factor > 0.0),
    }
}

/// The glass of a glTF material that is all transmission at a point (transmission 1,
/// metallic 0, no other layer): a [`Dielectric`] bounding its volume, or a
/// [`ThinDielectric`] wall, tinted by the base colour; `None` where the material mixes
/// other lobes in.
fn dielectric_bsdf(
    m: &Material,
    base: Vec3,
    metallic: f32,
    roughness: f32,
    transmission: f32,
    ctx: &ShadingContext,
) -> Option<Bsdf<'static>> {
    let pure = transmission >= 1.0
        && metallic <= 0.0
        && m.clearcoat == 0.0
        && m.sheen.is_none()
        && m.iridescence.is_none()
        && m.anisotropy.is_none()
        && m.specular.is_default()
        && m.specular_color.is_none();
    if !pure {
        return None;
    }
    let r = roughness.clamp(0.0, 1.0);
    let alpha = r * r;
    let ior = if m.ior > 0.0 { m.ior } else { f32::INFINITY };
    let tint = m.transmission_color.unwrap_or(base);
    Some(match m.volume {
        Some(_) => {
            let eta = if ctx.front {
                ior / ctx.outside_ior
            } else {
                ctx.outside_ior / ior
            };
            Bsdf::Dielectric(Dielectric::new(eta, alpha, tint))
        }
        None => Bsdf::ThinDielectric(ThinDielectric::new(ior / ctx.outside_ior, alpha, tint)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Specular;

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

    /// Directions over the upper hemisphere, grazing ones included.
    fn hemisphere() -> Vec<Vec3> {
        (1..12)
            .flat_map(|i| {
                let z = i as f32 / 12.0;
                let r = (1.0 - z * z).sqrt();
                (0..8).map(move |k| {
                    let phi = k as f32 * 0.785 + 0.1;
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                })
            })
            .collect()
    }

    /// The layered model of `m` at a point, built whatever the reductions say.
    fn layered(m: &Material) -> Layered {
        let attrs = SurfaceAttributes {
            uv: [Vec2::ZERO; 2],
            color: Vec4::ONE,
            footprint: [[glam::Vec2::ZERO; 2]; 2],
        };
        let ctx = ShadingContext::default();
        let at = Point {
            textures: &[],
            attrs: &attrs,
            ctx: &ctx,
        };
        let base = m.base_color.truncate();
        Layered::new(layered_params(m, &at, base, m.metallic, m.roughness, 0.0))
    }

    /// A glTF material whose specular layer weighs nothing and that is neither metal nor
    /// coated reduces to Lambert, and an uncoated all-metal one to `gltf_pbr`'s conductor,
    /// and each reduction is the layered model it replaces: the same f · cos θi in every
    /// pair of directions (to float rounding: the two compute GGX in another order), and the
    /// material-level classification that the render plan reports agrees.
    #[test]
    fn zero_weight_lobes_reduce_to_the_same_bsdf() {
        let colour = Vec4::new(0.8, 0.4, 0.2, 1.0);
        let lambertian = Material {
            base_color: colour,
            metallic: 0.0,
            roughness: 0.4,
            specular: Specular {
                weight: 0.0,
                ..Specular::default()
            },
            sheen: Some(crate::scene::Sheen {
                color: Vec3::ZERO,
                color_texture: None,
                roughness: 0.5,
                roughness_texture: None,
            }),
            ..Material::default()
        };
        let metal = Material {
            base_color: colour,
            metallic: 1.0,
            roughness: 0.3,
            specular: Specular {
                weight: 0.5,
                color: Vec3::new(1.0, 0.5, 0.5),
                ..Specular::default()
            },
            ..Material::default()
        };
        let mut storage = BsdfStorage::default();
        let attrs = SurfaceAttributes {
            uv: [Vec2::ZERO; 2],
            color: Vec4::ONE,
            footprint: [[glam::Vec2::ZERO; 2]; 2],
        };
        for (m, reduced) in [
            (&lambertian, crate::scene::Reduced::Lambert),
            (&metal, crate::scene::Reduced::Conductor),
        ] {
            assert_eq!(m.reduced(), Some(reduced));
            let simple = bsdf(m, &[], &attrs, &mut storage);
            match (reduced, &simple) {
                (crate::scene::Reduced::Lambert, Bsdf::Lambert(_))
                | (crate::scene::Reduced::Conductor, Bsdf::GltfPbr(_)) => {}
                _ => panic!("{reduced:?}: built {simple:?}"),
            }
            let full = layered(m);
            for &wo in &hemisphere() {
                for &wi in &hemisphere() {
                    let (a, b) = (simple.eval(wo, wi), full.eval(wo, wi));
                    assert!(
                        (a - b).abs().max_element() <= 1e-4 * b.max_element().max(1e-3),
                        "{reduced:?} at {wo} {wi}: {a} against {b}"
                    );
                }
            }
        }
        // A specular layer of some weight, a coat, a sheen or a metallic texture keep the
        // full model.
        for m in [
            Material {
                specular: Specular {
                    weight: 0.1,
                    ..lambertian.specular
                },
                ..lambertian.clone()
            },
            Material {
                clearcoat: 0.5,
                ..lambertian.clone()
            },
            Material {
                sheen: Some(crate::scene::Sheen {
                    color: Vec3::splat(0.5),
                    ..lambertian.sheen.unwrap()
                }),
                ..lambertian.clone()
            },
            Material {
                metallic: 0.5,
                ..metal.clone()
            },
        ] {
            assert_eq!(m.reduced(), None, "{m:?}");
            assert!(matches!(
                bsdf(&m, &[], &attrs, &mut storage),
                Bsdf::Layered(_)
            ));
        }
    }
}
