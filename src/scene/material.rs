//! Material descriptions: which BSDF model, its parameters and textures. Evaluation at a
//! surface point lives in `crate::material`.

use glam::{Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// Below this alpha (roughness²) a surface is treated as perfectly smooth (a delta lobe),
/// as pbrt-v4 does: the distribution is too peaked for floats to evaluate reliably. The
/// BSDFs (`material::microfacet`) and the analysis of a scene's lobes both read it.
pub const SMOOTH_ALPHA: f32 = 1e-3;

/// A material as the scene describes it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Material {
    pub name: String,
    pub model: BsdfModel,
    /// Linear RGBA base colour factor.
    pub base_color: Vec4,
    pub base_color_texture: Option<TextureRef>,
    pub metallic: f32,
    pub roughness: f32,
    /// Roughness of the diffuse base in [0, 1] (OpenPBR's `base_diffuse_roughness`):
    /// 0 is Lambert, above it OpenPBR's energy-preserving Oren-Nayar (`material::oren_nayar`).
    /// glTF has none.
    #[serde(default)]
    pub diffuse_roughness: f32,
    /// Metalness in B, roughness in G (glTF layout).
    pub metallic_roughness_texture: Option<TextureRef>,
    pub normal_texture: Option<TextureRef>,
    pub normal_scale: f32,
    /// Emitted radiance factor (emissive factor times emissive strength).
    pub emissive: Vec3,
    pub emissive_texture: Option<TextureRef>,
    /// Index of refraction of the dielectric layer (glTF default 1.5).
    pub ior: f32,
    /// Reflectance at normal incidence of the dielectric (UsdPreviewSurface's specular
    /// workflow `specularColor`); replaces the one `ior` gives. `None`: from `ior`.
    #[serde(default)]
    pub specular_color: Option<Vec3>,
    /// Clear coat weight in [0, 1] (KHR_materials_clearcoat; 0: none).
    #[serde(default)]
    pub clearcoat: f32,
    /// Perceptual roughness of the clear coat.
    #[serde(default)]
    pub clearcoat_roughness: f32,
    /// Clear coat weight (R) and roughness (G) textures, multiplying the factors, and the
    /// coat's own tangent-space normal map with its scale (KHR_materials_clearcoat).
    #[serde(default)]
    pub clearcoat_texture: Option<TextureRef>,
    #[serde(default)]
    pub clearcoat_roughness_texture: Option<TextureRef>,
    #[serde(default)]
    pub clearcoat_normal_texture: Option<TextureRef>,
    #[serde(default = "one")]
    pub clearcoat_normal_scale: f32,
    /// Share of the dielectric base that is specular transmission instead of diffuse
    /// reflection, in [0, 1] (KHR_materials_transmission; UsdPreviewSurface opacity with an
    /// ior), times `transmission_texture`'s R.
    #[serde(default)]
    pub transmission: f32,
    #[serde(default)]
    pub transmission_texture: Option<TextureRef>,
    /// The colour transmitted light is tinted by at each crossing; `None`: the base colour
    /// (glTF's rule). UsdPreviewSurface glass is untinted (white).
    #[serde(default)]
    pub transmission_color: Option<Vec3>,
    /// The material bounds a volume (KHR_materials_volume with a thickness): light refracts
    /// into it and is absorbed inside. `None`: a thin wall, which transmits without bending.
    #[serde(default)]
    pub volume: Option<Volume>,
    /// KHR_materials_diffuse_transmission: a share of the diffuse base transmits as a
    /// Lambertian lobe to the other side (leaves, paper, lampshades; on a volume's boundary
    /// a translucent entrance). `None`: no diffuse transmission.
    #[serde(default)]
    pub diffuse_transmission: Option<DiffuseTransmission>,
    /// KHR_materials_specular: the strength and F0 colour of the dielectric's reflection.
    #[serde(default)]
    pub specular: Specular,
    /// KHR_materials_sheen.
    #[serde(default)]
    pub sheen: Option<Sheen>,
    /// KHR_materials_iridescence.
    #[serde(default)]
    pub iridescence: Option<Iridescence>,
    /// KHR_materials_anisotropy.
    #[serde(default)]
    pub anisotropy: Option<Anisotropy>,
    /// KHR_materials_unlit: the base colour is seen by the camera as is, and every other
    /// ray passes through (Blender's and three.js's reading of the extension).
    #[serde(default)]
    pub unlit: bool,
    pub alpha_mode: AlphaMode,
    /// Both sides are visible and shaded; otherwise back faces are invisible to every ray.
    /// Transmissive materials are seen from both sides whatever it says (a volume's inside
    /// must be, and light crossing a thin wall reaches its back).
    pub double_sided: bool,
    /// Rough microfacet lobes are compensated for the energy that single scattering loses
    /// between facets (`material::energy`, Cycles' "Multiscatter GGX"); false: the
    /// single-scattering GGX of glTF's appendix B and Mitsuba's rough models (the
    /// `--microfacet single` setting clears it on every material).
    #[serde(default = "yes")]
    pub multiscatter: bool,
}

fn one() -> f32 {
    1.0
}

fn yes() -> bool {
    true
}

/// The inside of a closed surface: a homogeneous medium that absorbs and scatters
/// (`crate::medium`). Clear (all zero) inside plain glass.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Volume {
    /// Absorption coefficient per world unit, per channel (-ln(attenuationColor) /
    /// attenuationDistance for KHR_materials_volume); zero for a clear volume.
    pub absorption: Vec3,
    /// Scattering coefficient per world unit, per channel.
    #[serde(default)]
    pub scattering: Vec3,
    /// Henyey-Greenstein mean cosine of scattering, in (−1, 1).
    #[serde(default)]
    pub anisotropy: f32,
    /// The density grid (an index into `Scene::grids`) that scales absorption and
    /// scattering point by point: they are then the coefficients at density 1, and the
    /// medium is empty outside the grid. `None`: the same everywhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub density: Option<u32>,
    /// Radiance emitted per world unit of length, per channel (scaled by the density
    /// grid): a flame's or glowing gas's light, which needs no absorption to exist.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub emission: Vec3,
    /// Light emitted by a temperature grid through Planck's law (fire), besides
    /// `emission`; only with a density grid.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blackbody: Option<Blackbody>,
    /// Light emitted by an emission grid, besides `emission`; only with a density grid and
    /// without a `blackbody` (one glowing field a medium).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub emission_field: Option<EmissionField>,
    /// Colour grids (indices into `Scene::grids`: red, green and blue, one lattice) that
    /// tint the scattering point by point, as Arnold standard_volume's
    /// `scatter_color_channel` and the colour attribute of Cycles' Principled Volume do: the
    /// extinction stays, the albedo is multiplied by the colour (at most 1) and the
    /// absorption is the rest. Only with a density grid; a scene file's `volumes` entry
    /// names the field instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scatter_color: Option<[u32; 3]>,
}

/// Emission of a medium by a grid of its own (Arnold standard_volume's emission_mode
/// "channel"): radiance per metre = the grid's value × `tint`; not scaled by the density.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmissionField {
    /// The emission grid (an index into `Scene::grids`); a scene file's `volumes` entry
    /// names it by its field instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid: Option<u32>,
    /// Radiance per metre per unit of the grid's value, per channel.
    #[serde(default = "white")]
    pub tint: Vec3,
}

/// Blackbody emission of a medium from a temperature grid, as Cycles' Principled Volume
/// defines it (`crate::medium::blackbody`): radiance per metre σ T⁴ / π × 10⁻⁶ in the
/// colour of Planck's spectrum, times `intensity` and `tint`, where T is the grid's value
/// times `kelvin`; not scaled by the density.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Blackbody {
    /// The temperature grid (an index into `Scene::grids`); a scene file's `volumes` entry
    /// names it by its field instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature: Option<u32>,
    /// Kelvin per unit of the grid's values (Cycles' Temperature input).
    #[serde(default = "one")]
    pub kelvin: f32,
    /// Scales the radiance (Cycles' Blackbody Intensity, 1 for the physical brightness).
    #[serde(default = "one")]
    pub intensity: f32,
    /// Multiplies the radiance per channel.
    #[serde(default = "white")]
    pub tint: Vec3,
}

impl Blackbody {
    /// The hottest temperature a grid may reach, in kelvin: the radiance of hotter gas
    /// (10⁻¹⁴ T⁴ per metre) overflows single precision within a few voxels.
    pub const HOTTEST: f64 = 1e6;

    /// Why `temperature` cannot be this blackbody's grid (its largest value times `kelvin`
    /// is hotter than [`Self::HOTTEST`]); `None` where it can.
    pub fn too_hot(&self, temperature: &super::DensityGrid) -> Option<String> {
        let hottest = f64::from(temperature.max_density()) * f64::from(self.kelvin);
        (hottest > Self::HOTTEST).then(|| {
            format!(
                "the temperature grid reaches {hottest:e} K (its largest value times kelvin), \
                 beyond {:e} K",
                Self::HOTTEST
            )
        })
    }
}

fn white() -> Vec3 {
    Vec3::ONE
}

fn is_zero(v: &Vec3) -> bool {
    *v == Vec3::ZERO
}

impl Volume {
    /// A volume that only absorbs.
    pub fn absorbing(absorption: Vec3) -> Self {
        Self {
            absorption,
            scattering: Vec3::ZERO,
            anisotropy: 0.0,
            density: None,
            emission: Vec3::ZERO,
            blackbody: None,
            emission_field: None,
            scatter_color: None,
        }
    }

    /// True where light scatters inside.
    pub fn scatters(&self) -> bool {
        self.scattering.max_element() > 0.0
    }

    /// True where it emits light.
    pub fn emits(&self) -> bool {
        self.emission.max_element() > 0.0
            || self
                .blackbody
                .is_some_and(|b| b.intensity > 0.0 && b.tint.max_element() > 0.0)
            || self
                .emission_field
                .is_some_and(|e| e.tint.max_element() > 0.0)
    }
}

/// KHR_materials_specular: `weight` scales the dielectric's reflection (F0 and F90), `color`
/// tints its F0.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Specular {
    /// specularFactor, times `weight_texture`'s A.
    pub weight: f32,
    pub weight_texture: Option<TextureRef>,
    /// specularColorFactor (may exceed 1; F0 is clamped), times `color_texture`'s RGB (sRGB).
    pub color: Vec3,
    pub color_texture: Option<TextureRef>,
}

impl Default for Specular {
    fn default() -> Self {
        Self {
            weight: 1.0,
            weight_texture: None,
            color: Vec3::ONE,
            color_texture: None,
        }
    }
}

impl Specular {
    /// True where the extension changes nothing.
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// What a glTF PBR material reduces to where some of its lobes weigh nothing
/// ([`Material::reduced`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reduced {
    /// The diffuse base alone.
    Lambert,
    /// The metal alone: GGX with Schlick's Fresnel of the base colour.
    Conductor,
}

/// KHR_materials_diffuse_transmission: the diffuse base becomes
/// `mix(diffuse_brdf(base colour), diffuse_btdf(color), factor)`, under the same Fresnel
/// weight; a specular transmission (KHR_materials_transmission) takes precedence over it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiffuseTransmission {
    /// diffuseTransmissionFactor in [0, 1], times `texture`'s A.
    pub factor: f32,
    pub texture: Option<TextureRef>,
    /// diffuseTransmissionColorFactor, times `color_texture`'s RGB (sRGB).
    #[serde(default = "white")]
    pub color: Vec3,
    #[serde(default)]
    pub color_texture: Option<TextureRef>,
}

/// KHR_materials_sheen: a retro-reflective layer of fibres over the base.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sheen {
    /// sheenColorFactor, times `color_texture`'s RGB (sRGB).
    pub color: Vec3,
    pub color_texture: Option<TextureRef>,
    /// sheenRoughnessFactor, times `roughness_texture`'s A.
    pub roughness: f32,
    pub roughness_texture: Option<TextureRef>,
}

/// KHR_materials_iridescence: a thin film over the base whose interference colours the
/// specular reflection.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Iridescence {
    /// iridescenceFactor, times `texture`'s R.
    pub factor: f32,
    pub texture: Option<TextureRef>,
    /// Index of refraction of the film.
    pub ior: f32,
    /// Film thickness in nanometres: `thickness_min` at `thickness_texture`'s G = 0,
    /// `thickness_max` at 1 (and without the texture).
    pub thickness_min: f32,
    pub thickness_max: f32,
    pub thickness_texture: Option<TextureRef>,
}

/// KHR_materials_anisotropy: the specular lobes stretch along a direction of the tangent
/// plane.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Anisotropy {
    /// anisotropyStrength in [0, 1], times `texture`'s B.
    pub strength: f32,
    /// Radians counter-clockwise from the tangent, added to `texture`'s RG direction.
    pub rotation: f32,
    pub texture: Option<TextureRef>,
}

impl Default for Material {
    /// The glTF default material: white, fully metallic and rough, opaque, one-sided.
    fn default() -> Self {
        Self {
            name: "default".into(),
            model: BsdfModel::GltfPbr,
            base_color: Vec4::ONE,
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            diffuse_roughness: 0.0,
            metallic_roughness_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            emissive: Vec3::ZERO,
            emissive_texture: None,
            ior: 1.5,
            specular_color: None,
            clearcoat: 0.0,
            clearcoat_roughness: 0.0,
            clearcoat_texture: None,
            clearcoat_roughness_texture: None,
            clearcoat_normal_texture: None,
            clearcoat_normal_scale: 1.0,
            transmission: 0.0,
            transmission_texture: None,
            transmission_color: None,
            volume: None,
            diffuse_transmission: None,
            specular: Specular::default(),
            sheen: None,
            iridescence: None,
            anisotropy: None,
            unlit: false,
            alpha_mode: AlphaMode::Opaque,
            double_sided: false,
            multiscatter: true,
        }
    }
}

impl Material {
    /// True if the material can emit light (an unlit material shows its colour to the
    /// camera but lights nothing).
    pub fn is_emissive(&self) -> bool {
        self.emissive.max_element() > 0.0 && !self.unlit
    }

    /// The simpler model a glTF PBR material is everywhere because some of its lobes weigh
    /// nothing (factors multiply their textures, so a zero factor is zero everywhere):
    /// Lambert where the specular layer's weight is zero (KHR_materials_specular
    /// `specularFactor` 0) and it is neither metal nor transmitting nor coated nor
    /// sheened; a conductor where it is all metal (factor 1, no metallic texture), uncoated,
    /// without sheen, iridescence or anisotropy. `None` otherwise. The BSDF built at a
    /// point reduces the same way, and also where a texture makes the point all metal.
    pub fn reduced(&self) -> Option<Reduced> {
        let uncoated = self.clearcoat == 0.0;
        let unsheened = self.sheen.is_none_or(|s| s.color == Vec3::ZERO);
        if self.model != BsdfModel::GltfPbr || self.unlit || !(uncoated && unsheened) {
            return None;
        }
        if self.specular.weight == 0.0
            && self.metallic == 0.0
            && !self.transmits()
            && self.diffuse_roughness == 0.0
        {
            return Some(Reduced::Lambert);
        }
        let metal = self.metallic >= 1.0 && self.metallic_roughness_texture.is_none();
        (metal
            && !self.transmits()
            && self.iridescence.is_none_or(|i| i.factor == 0.0)
            && self.anisotropy.is_none())
        .then_some(Reduced::Conductor)
    }

    /// True if some point of the material can transmit light (its glTF BSDF has a
    /// specular or diffuse transmission lobe, or it is an interface): such surfaces are
    /// seen from both sides.
    pub fn transmits(&self) -> bool {
        self.model == BsdfModel::Interface || self.transmits_specularly() || self.translucent()
    }

    /// True if some point of the glTF BSDF has a specular transmission lobe
    /// (KHR_materials_transmission): refraction through a volume's boundary or straight
    /// through a thin wall.
    pub fn transmits_specularly(&self) -> bool {
        self.model == BsdfModel::GltfPbr
            && (self.transmission > 0.0 || self.transmission_texture.is_some())
            && self.dielectric_somewhere()
    }

    /// True if some point of the glTF BSDF has a diffuse transmission lobe
    /// (KHR_materials_diffuse_transmission) that a specular transmission of 1 does not
    /// replace.
    pub fn translucent(&self) -> bool {
        let all_glass = self.transmission >= 1.0 && self.transmission_texture.is_none();
        self.model == BsdfModel::GltfPbr
            && self.diffuse_transmission.is_some_and(|d| d.factor > 0.0)
            && self.dielectric_somewhere()
            && !all_glass
    }

    /// True if the glTF material is not all metal at some point.
    fn dielectric_somewhere(&self) -> bool {
        self.metallic < 1.0 || self.metallic_roughness_texture.is_some()
    }

    /// True if some point of the material can be a filter that light crosses in a straight
    /// line without scattering (a smooth thin wall, an unlit surface): shadow rays pass
    /// such surfaces, attenuated (see `integrator::path`).
    pub fn can_filter(&self) -> bool {
        self.unlit
            || self.model == BsdfModel::Interface
            || (self.transmits_specularly()
                && self.volume.is_none()
                && (self.roughness * self.roughness < SMOOTH_ALPHA
                    || self.metallic_roughness_texture.is_some()
                    || self.anisotropy.is_some()))
    }

    /// True if the material bounds a participating medium: its volume scatters, emits or
    /// has a density grid, or it is an interface around a medium (which shadow rays cross
    /// into).
    pub fn bounds_participating_medium(&self) -> bool {
        self.volume.is_some_and(|v| {
            v.scatters()
                || v.emits()
                || v.density.is_some()
                || (self.model == BsdfModel::Interface && v.absorption != Vec3::ZERO)
        })
    }

    /// True for the texture slots (by [`Material::texture_slots`] name) that are read as
    /// colour, sRGB-decoding integer texels (`material::base_color`, `emission`, the
    /// specular and sheen colours); the others are data.
    pub fn is_colour_slot(name: &str) -> bool {
        matches!(
            name,
            "base_color_texture"
                | "emissive_texture"
                | "specular.color_texture"
                | "sheen.color_texture"
                | "diffuse_transmission.color_texture"
        )
    }

    /// Every texture slot the material uses, with its field name.
    pub fn texture_slots(&self) -> impl Iterator<Item = (&'static str, &TextureRef)> {
        let specular = &self.specular;
        let sheen = self.sheen.as_ref();
        let iridescence = self.iridescence.as_ref();
        let translucency = self.diffuse_transmission.as_ref();
        [
            ("base_color_texture", self.base_color_texture.as_ref()),
            (
                "metallic_roughness_texture",
                self.metallic_roughness_texture.as_ref(),
            ),
            ("normal_texture", self.normal_texture.as_ref()),
            ("emissive_texture", self.emissive_texture.as_ref()),
            ("clearcoat_texture", self.clearcoat_texture.as_ref()),
            (
                "clearcoat_roughness_texture",
                self.clearcoat_roughness_texture.as_ref(),
            ),
            (
                "clearcoat_normal_texture",
                self.clearcoat_normal_texture.as_ref(),
            ),
            ("transmission_texture", self.transmission_texture.as_ref()),
            (
                "diffuse_transmission.texture",
                translucency.and_then(|d| d.texture.as_ref()),
            ),
            (
                "diffuse_transmission.color_texture",
                translucency.and_then(|d| d.color_texture.as_ref()),
            ),
            ("specular.weight_texture", specular.weight_texture.as_ref()),
            ("specular.color_texture", specular.color_texture.as_ref()),
            (
                "sheen.color_texture",
                sheen.and_then(|s| s.color_texture.as_ref()),
            ),
            (
                "sheen.roughness_texture",
                sheen.and_then(|s| s.roughness_texture.as_ref()),
            ),
            (
                "iridescence.texture",
                iridescence.and_then(|i| i.texture.as_ref()),
            ),
            (
                "iridescence.thickness_texture",
                iridescence.and_then(|i| i.thickness_texture.as_ref()),
            ),
            (
                "anisotropy.texture",
                self.anisotropy.as_ref().and_then(|a| a.texture.as_ref()),
            ),
        ]
        .into_iter()
        .filter_map(|(name, slot)| slot.map(|s| (name, s)))
    }

    /// True if the material needs a tangent frame at its surface points: a normal map (of
    /// the base or the coat) or anisotropy.
    pub fn needs_tangents(&self) -> bool {
        self.tangent_uv_set().is_some()
    }

    /// The texture coordinate set whose tangent frame the material's normal maps and
    /// anisotropy use (the base normal map's, else the coat's, else the anisotropy
    /// texture's, else set 0), or `None` if it needs none.
    pub fn tangent_uv_set(&self) -> Option<usize> {
        let anisotropy = self
            .anisotropy
            .as_ref()
            .map(|a| a.texture.map_or(0, |t| t.tex_coord));
        self.normal_texture
            .or(self.clearcoat_normal_texture)
            .map(|t| t.tex_coord)
            .or(anisotropy)
            .map(|set| (set as usize).min(1))
    }
}

/// The BSDF model a material uses.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BsdfModel {
    /// The glTF 2.0 metallic-roughness BRDF (specification, appendix B).
    GltfPbr,
    /// A Lambertian reflector with the base colour as albedo.
    Lambert,
    /// The modified (energy-normalised) Phong BRDF: base colour as diffuse albedo `kd`,
    /// `specular` as `ks`, lobe exponent `exponent`.
    Phong { exponent: f32, specular: Vec3 },
    /// No surface: the boundary of the medium inside (`volume`), which every ray crosses
    /// unchanged (Mitsuba's `null` BSDF around a medium). Fog in a box, smoke in a hull.
    Interface,
}

impl BsdfModel {
    /// Short name for summaries.
    pub fn name(&self) -> &'static str {
        match self {
            Self::GltfPbr => "gltf-pbr",
            Self::Lambert => "lambert",
            Self::Phong { .. } => "phong",
            Self::Interface => "interface",
        }
    }
}

/// How a material's alpha is used.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlphaMode {
    Opaque,
    /// Cut-out: the surface exists where alpha >= cutoff.
    Mask {
        cutoff: f32,
    },
    /// Partial coverage: the surface is hit with probability alpha.
    Blend,
}

/// A texture used by a material slot.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TextureRef {
    pub texture: u32,
    /// Which texture coordinate set (0 or 1).
    pub tex_coord: u32,
    pub transform: Option<UvTransform>,
}

/// An affine UV transform (KHR_texture_transform): `uv' = m * uv + offset`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct UvTransform {
    /// Columns of the 2x2 linear part.
    pub x: Vec2,
    pub y: Vec2,
    pub offset: Vec2,
}

impl UvTransform {
    /// The KHR_texture_transform matrix, translation * rotation * scale, with the rotation
    /// turning the UVs (v pointing down the image) by `rotation` radians counter-clockwise
    /// as the image shows them: the u axis maps to (cos r, -sin r). This is the matrix of
    /// the specification's GLSL read row by row, what its reference implementations (the
    /// Khronos sample viewer, three.js, Blender's importer) compute and what
    /// TextureTransformTest checks; read as GLSL's column-major constructor it would turn
    /// the other way.
    pub fn new(offset: Vec2, rotation: f32, scale: Vec2) -> Self {
        let (s, c) = rotation.sin_cos();
        Self {
            x: Vec2::new(c, -s) * scale.x,
            y: Vec2::new(s, c) * scale.y,
            offset,
        }
    }

    /// Applies the transform.
    #[inline]
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        self.x * uv.x + self.y * uv.y + self.offset
    }
}
