//! Material descriptions: which BSDF model, its parameters and textures. Evaluation at a
//! surface point lives in `crate::material`.

use glam::{Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};

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
    pub alpha_mode: AlphaMode,
    /// Both sides are visible and shaded; otherwise back faces are invisible to every ray.
    pub double_sided: bool,
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
            metallic_roughness_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            emissive: Vec3::ZERO,
            emissive_texture: None,
            ior: 1.5,
            specular_color: None,
            clearcoat: 0.0,
            clearcoat_roughness: 0.0,
            alpha_mode: AlphaMode::Opaque,
            double_sided: false,
        }
    }
}

impl Material {
    /// True if the material can emit light.
    pub fn is_emissive(&self) -> bool {
        self.emissive.max_element() > 0.0
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
}

impl BsdfModel {
    /// Short name for summaries.
    pub fn name(&self) -> &'static str {
        match self {
            Self::GltfPbr => "gltf-pbr",
            Self::Lambert => "lambert",
            Self::Phong { .. } => "phong",
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
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
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
    /// The KHR_texture_transform matrix, translation * rotation * scale, as the ratified
    /// specification's (column-major) GLSL defines it: the u axis maps to (cos r, sin r).
    pub fn new(offset: Vec2, rotation: f32, scale: Vec2) -> Self {
        let (s, c) = rotation.sin_cos();
        Self {
            x: Vec2::new(c, s) * scale.x,
            y: Vec2::new(-s, c) * scale.y,
            offset,
        }
    }

    /// Applies the transform.
    #[inline]
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        self.x * uv.x + self.y * uv.y + self.offset
    }
}
