//! glTF 2.0 import (`.gltf` and `.glb`) with the `gltf` crate.
//!
//! The crate parses and validates the JSON; this module loads buffers and images itself
//! (safe URI resolution, no network), checks every accessor's type and byte range and every
//! vertex index before reading, and converts the default scene into a [`Scene`]: node
//! hierarchy, triangle primitives (strips and fans converted; points and lines skipped),
//! cameras, materials (metallic-roughness, normal maps, emission, KHR_texture_transform,
//! alpha modes, double-sidedness, lucerna's BSDF selection in `extras`) and
//! KHR_lights_punctual lights.
//!
//! The import is one [`Importer`] whose methods live by concept: `document` (parsing,
//! version, buffers), `delivery` (Draco, meshopt, quantization, WebP decoded into plain
//! buffers), `accessors` (type and range checks), `nodes` (the hierarchy, instancing and
//! animation), `mesh` (primitives, spheres, skinning and morphing), `material` and
//! `texture`, `camera` and `lights`.

mod accessors;
mod camera;
mod deformation;
pub mod delivery;
mod document;
mod lights;
mod material;
mod mesh;
mod nodes;
mod texture;

use crate::error::{Error, Result};
use crate::scene::{self, Scene};
use document::{load_buffers, parse};
use glam::{DMat4, DQuat, DVec3};
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// What to take from a glTF file that offers several: a KHR_materials_variants variant and an
/// animation (clip), by name (`None`: the default materials; the file's animations as
/// [`Importer::pose_at`] plays them).
#[derive(Clone, Copy, Debug, Default)]
pub struct Choices<'a> {
    pub material_variant: Option<&'a str>,
    /// An animation's name, or its index in the file.
    pub animation: Option<&'a str>,
    /// The shutter's opening and closing, seconds of the animations: nodes that move
    /// while it is open get their transforms over it (motion blur).
    pub shutter: Option<(f64, f64)>,
}

/// Reads and converts the glTF file at `path`, posed at `time` seconds of its animations
/// (`None`: the nodes' own transforms), with `choices`.
pub fn load(path: &Path, time: Option<f64>, choices: Choices) -> Result<Scene> {
    let bytes = crate::files::read_input(path).map_err(|e| Error::bad_input(path, "file", e))?;
    let base = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    import_with(
        &bytes,
        &path.display().to_string(),
        Some(base),
        time,
        choices,
    )
}

/// Converts glTF bytes; `source` names the file in messages, `base` is its directory
/// (`None`: external files are refused).
pub fn import(bytes: &[u8], source: &str, base: Option<&Path>) -> Result<Scene> {
    import_at(bytes, source, base, None)
}

/// [`import`], posed at `time` seconds of the file's animations.
pub fn import_at(
    bytes: &[u8],
    source: &str,
    base: Option<&Path>,
    time: Option<f64>,
) -> Result<Scene> {
    import_with(bytes, source, base, time, Choices::default())
}

/// [`import_at`] with `choices` (material variant, animation).
pub fn import_with(
    bytes: &[u8],
    source: &str,
    base: Option<&Path>,
    time: Option<f64>,
    choices: Choices,
) -> Result<Scene> {
    let gltf = parse(bytes, source)?;
    let mut buffers = load_buffers(&gltf.document, gltf.blob.as_deref(), source, base)?;
    let document = delivery::decode(gltf.document, &mut buffers, source)?;
    let mut importer = Importer {
        source: source.to_string(),
        base,
        doc: &document,
        buffers,
        scene: Scene {
            source: source.to_string(),
            ..Default::default()
        },
        images: HashMap::new(),
        textures: HashMap::new(),
        grids: HashMap::new(),
        materials: HashMap::new(),
        meshes: HashMap::new(),
        pose: HashMap::new(),
        morph_weights: HashMap::new(),
        world_of: HashMap::new(),
        skinned: Vec::new(),
        variant: None,
        animation: None,
        shutter: choices.shutter.filter(|(open, close)| close > open),
        placed: Vec::new(),
        placed_cameras: Vec::new(),
        unblurred: Vec::new(),
        deforming: Vec::new(),
        unsupported_material_extensions: Default::default(),
        texture_plan: Default::default(),
    };
    importer.plan_texture_memory();
    importer.select_variant(choices.material_variant)?;
    importer.select_animation(choices.animation)?;
    importer.run(time)?;
    Ok(importer.scene)
}

pub(crate) struct Importer<'a> {
    source: String,
    base: Option<&'a Path>,
    doc: &'a gltf::Document,
    buffers: Vec<Vec<u8>>,
    scene: Scene,
    /// glTF image index → decoded size and texels (shared by the textures that use it).
    images: HashMap<usize, (u32, u32, Arc<scene::Texels>)>,
    /// glTF texture index → scene texture.
    textures: HashMap<usize, u32>,
    /// Density grid URI → scene grid.
    grids: HashMap<String, u32>,
    /// glTF material index (`None`: the default material) → scene material.
    materials: HashMap<Option<usize>, u32>,
    /// (glTF mesh, primitive) → scene mesh, or `None` for a skipped primitive.
    meshes: HashMap<(usize, usize), Option<u32>>,
    /// Animated nodes' translation, rotation and scale at the render's time.
    pose: HashMap<usize, NodePose>,
    /// Animated nodes' morph target weights at the render's time.
    morph_weights: HashMap<usize, Vec<f32>>,
    /// World transforms of the nodes visited so far (skins read their joints' from here).
    world_of: HashMap<usize, DMat4>,
    /// Skinned nodes (index, name), converted once every joint's transform is known.
    skinned: Vec<(usize, String)>,
    /// The KHR_materials_variants variant to render (index into the file's variants).
    variant: Option<usize>,
    /// The one animation that plays (`--animation`); `None`: all, clips resolved as
    /// [`Importer::pose_at`] says.
    animation: Option<usize>,
    /// The open shutter, seconds: its opening and closing.
    shutter: Option<(f64, f64)>,
    /// With a shutter, each instance placed by a node: its index in the scene, the node,
    /// and its transform in the node's space (GPU instancing), so that its motion over the
    /// shutter can follow the node's ([`Importer::sample_motion`]).
    placed: Vec<(usize, usize, DMat4)>,
    /// With a shutter, each camera: its index in the scene and its node.
    placed_cameras: Vec<(usize, usize)>,
    /// With a shutter, the nodes of lights and analytic spheres (which do not move), and
    /// what they are, for a warning where they would.
    unblurred: Vec<(usize, &'static str)>,
    /// With the shutter open on an animation, the deformed meshes, posed again at its keys
    /// ([`Importer::sample_motion`]).
    deforming: Vec<deformation::Deforming>,
    /// Unsupported extensions a material uses → the materials' names (one warning each).
    unsupported_material_extensions: std::collections::BTreeMap<String, Vec<String>>,
    /// Which images are read through a tile cache (the textures do not fit in the texture
    /// memory) and which are kept in memory.
    texture_plan: crate::scene::texture_cache::TexturePlan,
}

/// The animated parts of a node's transform at one time (the rest come from the node).
#[derive(Default)]
pub(super) struct NodePose {
    translation: Option<DVec3>,
    rotation: Option<DQuat>,
    scale: Option<DVec3>,
}

/// The lucerna section of a material's `extras`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LucernaExtras {
    #[serde(default = "gltf_bsdf")]
    bsdf: String,
    exponent: Option<f32>,
    specular: Option<SpecularValue>,
    /// The diffuse base's roughness in [0, 1] (OpenPBR's EON), which glTF lacks.
    diffuse_roughness: Option<f32>,
    /// The medium inside the material's closed surface (per metre), which glTF lacks.
    medium: Option<MediumExtras>,
}

/// `extras.lucerna.medium`: a medium's coefficients per metre (a grey number or an RGB
/// triple each), its Henyey-Greenstein anisotropy and the radiance it emits per metre.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MediumExtras {
    absorption: Option<SpecularValue>,
    #[serde(default)]
    scattering: Option<SpecularValue>,
    #[serde(default)]
    anisotropy: f32,
    /// A density grid (a Mitsuba `.vol` or an OpenVDB `.vdb` file beside the glTF) that
    /// scales absorption and scattering point by point: they are then the coefficients at
    /// density 1.
    density: Option<String>,
    /// The grid of a `.vdb` file to read (default: `density`, or the file's only grid).
    #[serde(default)]
    density_grid: Option<String>,
    /// Radiance emitted per metre (scaled by the density grid, if any).
    emission: Option<SpecularValue>,
    /// Light from a temperature grid through Planck's law (needs `density`).
    #[serde(default)]
    pub(super) blackbody: Option<BlackbodyExtras>,
    /// Light from an emission grid: radiance per metre = value × tint (needs `density`).
    #[serde(default)]
    pub(super) emission_field: Option<EmissionFieldExtras>,
    /// Colour grids that tint the scattering point by point (needs `density`).
    #[serde(default)]
    pub(super) scatter_color: Option<ScatterColorExtras>,
}

/// `extras.lucerna.medium.scatter_color`: a colour grid of an OpenVDB file that multiplies
/// the medium's albedo point by point, its extinction unchanged (`scene::Volume`).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ScatterColorExtras {
    /// The `.vdb` file.
    pub(super) file: String,
    /// Its grid (default: `Cd`, else `color`, else the file's only grid): a vector grid, or a
    /// scalar one read as grey.
    #[serde(default)]
    pub(super) grid: Option<String>,
}

/// `extras.lucerna.medium.emission_field`: glow from a grid whose value is the radiance per
/// metre, times a tint (`scene::EmissionField`).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct EmissionFieldExtras {
    /// The emission grid's file (`.vol` or `.vdb`).
    pub(super) file: String,
    /// The grid of a `.vdb` file (default: `emission`, or the file's only grid).
    #[serde(default)]
    pub(super) grid: Option<String>,
    /// Radiance per metre per unit value, per channel (default 1).
    #[serde(default)]
    pub(super) tint: Option<SpecularValue>,
}

/// `extras.lucerna.medium.blackbody`: fire from a temperature grid, as Cycles' Principled
/// Volume renders it (`scene::Blackbody`).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct BlackbodyExtras {
    /// The temperature grid's file (`.vol` or `.vdb`).
    pub(super) temperature: String,
    /// The grid of a `.vdb` file (default: `temperature`, or the file's only grid).
    #[serde(default)]
    pub(super) temperature_grid: Option<String>,
    /// Kelvin per unit of the grid's values.
    #[serde(default = "one")]
    pub(super) kelvin: f32,
    /// Scales the radiance (1: the physical brightness).
    #[serde(default = "one")]
    pub(super) intensity: f32,
    /// Multiplies the radiance per channel.
    #[serde(default)]
    pub(super) tint: Option<SpecularValue>,
}

fn one() -> f32 {
    1.0
}

impl SpecularValue {
    pub(super) fn rgb(&self) -> glam::Vec3 {
        match *self {
            Self::Grey(g) => glam::Vec3::splat(g),
            Self::Rgb(c) => glam::Vec3::from_array(c),
        }
    }
}

fn gltf_bsdf() -> String {
    "gltf".into()
}

#[derive(serde::Deserialize)]
#[serde(untagged)]
pub(super) enum SpecularValue {
    Grey(f32),
    Rgb([f32; 3]),
}

impl<'a> Importer<'a> {
    pub(super) fn err(&self, element: impl Into<String>, reason: impl Into<String>) -> Error {
        Error::bad_input(&self.source, element, reason)
    }

    pub(super) fn warn(&mut self, element: impl AsRef<str>, message: impl AsRef<str>) {
        self.scene.warnings.push(format!(
            "{}: {}: {}",
            self.source,
            element.as_ref(),
            message.as_ref()
        ));
    }

    pub(super) fn run(&mut self, time: Option<f64>) -> Result<()> {
        let version = &self.doc.as_json().asset.version;
        if let Some(minor) = version
            .strip_prefix("2.")
            .and_then(|m| m.parse::<u32>().ok())
            .filter(|&m| m > 0)
        {
            self.warn(
                "asset.version",
                format!("glTF 2.{minor} is newer than the 2.0 lucerna reads; its additions are not rendered"),
            );
        }
        match time {
            Some(t) => self.pose_at(t)?,
            None if self.doc.animations().next().is_some() => self.warn(
                "animations",
                "the file is animated; without a frame the nodes' rest transforms are rendered (render --frame F, at F / fps seconds)",
            ),
            None => {}
        }
        let gltf_scene = match self
            .doc
            .default_scene()
            .or_else(|| self.doc.scenes().next())
        {
            Some(s) => s,
            None => return Err(self.err("scenes", "the file has no scene")),
        };
        let mut path = Vec::new();
        for node in gltf_scene.nodes() {
            self.visit(node, DMat4::IDENTITY, &mut path)?;
        }
        for (node, name) in std::mem::take(&mut self.skinned) {
            self.skinned_node(node, &name)?;
        }
        if let Some(shutter) = self.shutter
            && self.doc.animations().next().is_some()
        {
            self.sample_motion(gltf_scene.clone(), shutter)?;
        }
        self.warn_unsupported_extensions();
        if self.scene.instanced_triangle_count() == 0 && self.scene.spheres.is_empty() {
            return Err(self.err(
                format!("scenes[{}]", gltf_scene.index()),
                "contains no triangles",
            ));
        }
        Ok(())
    }
}
