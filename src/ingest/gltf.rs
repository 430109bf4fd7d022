//! glTF 2.0 import (`.gltf` and `.glb`) with the `gltf` crate.
//!
//! The crate parses and validates the JSON; this module loads buffers and images itself
//! (safe URI resolution, no network), checks every accessor's type and byte range and every
//! vertex index before reading, and converts the default scene into a [`Scene`]: node
//! hierarchy, triangle primitives (strips and fans converted; points and lines skipped),
//! cameras, materials (metallic-roughness, normal maps, emission, KHR_texture_transform,
//! alpha modes, double-sidedness, lucerna's BSDF selection in `extras`) and
//! KHR_lights_punctual lights.

use super::animation::{Interpolation, Track};
use super::image as img;
use super::{gltf_delivery, skinning, tangents, uri};
use crate::error::{Error, Result};
use crate::scene::{
    self, AlphaMode, BsdfModel, Camera, Instance, Light, LightKind, Material, Mesh, Projection,
    Scene, TextureRef, UvTransform, Wrap,
};
use glam::{DMat4, DQuat, DVec3, Vec2, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// Extensions lucerna implements; a required extension outside this list is an error, a
/// used one a warning.
pub const SUPPORTED_EXTENSIONS: &[&str] = &[
    "EXT_mesh_gpu_instancing",
    "EXT_meshopt_compression",
    "EXT_texture_webp",
    "KHR_draco_mesh_compression",
    "KHR_lights_punctual",
    "KHR_materials_anisotropy",
    "KHR_materials_clearcoat",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_iridescence",
    "KHR_materials_sheen",
    "KHR_materials_specular",
    "KHR_materials_transmission",
    "KHR_materials_unlit",
    "KHR_materials_variants",
    "KHR_materials_volume",
    "KHR_mesh_quantization",
    "KHR_meshopt_compression",
    "KHR_texture_transform",
];

/// Component types of rotation and morph-weight outputs: floats or normalized integers.
const FLOAT_OR_NORMALIZED: &[DataType] = &[
    DataType::F32,
    DataType::I8,
    DataType::U8,
    DataType::I16,
    DataType::U16,
];

/// Deepest node hierarchy accepted (deeper ones are almost certainly malicious).
const MAX_NODE_DEPTH: usize = 1024;

/// What to take from a glTF file that offers several: a KHR_materials_variants variant and an
/// animation (clip), by name (`None`: the default materials; the file's animations as
/// [`Importer::pose_at`] plays them).
#[derive(Clone, Copy, Debug, Default)]
pub struct Choices<'a> {
    pub material_variant: Option<&'a str>,
    /// An animation's name, or its index in the file.
    pub animation: Option<&'a str>,
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
    let document = gltf_delivery::decode(gltf.document, &mut buffers, source)?;
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
        materials: HashMap::new(),
        meshes: HashMap::new(),
        pose: HashMap::new(),
        morph_weights: HashMap::new(),
        world_of: HashMap::new(),
        skinned: Vec::new(),
        variant: None,
        animation: None,
        unsupported_material_extensions: Default::default(),
    };
    importer.select_variant(choices.material_variant)?;
    importer.select_animation(choices.animation)?;
    importer.run(time)?;
    Ok(importer.scene)
}

/// Reads the document's buffers: the GLB binary chunk, data URIs and files beside it. A
/// meshopt fallback buffer has no data of its own; it is allocated for the decoder to fill.
fn load_buffers(
    doc: &gltf::Document,
    blob: Option<&[u8]>,
    source: &str,
    base: Option<&Path>,
) -> Result<Vec<Vec<u8>>> {
    let err = |element: String, reason: String| Error::bad_input(source, element, reason);
    let mut buffers = Vec::new();
    for buffer in doc.buffers() {
        let element = format!("buffers[{}]", buffer.index());
        let json = &doc.as_json().buffers[buffer.index()];
        let data = if gltf_delivery::is_meshopt_fallback(json) {
            crate::memory::check_allocation(buffer.length() as u64, &element)
                .map_err(|r| err(element.clone(), r))?;
            vec![0; buffer.length()]
        } else {
            match buffer.source() {
                gltf::buffer::Source::Bin => blob
                    .ok_or_else(|| {
                        err(
                            element.clone(),
                            "refers to the GLB binary chunk, which is missing".into(),
                        )
                    })?
                    .to_vec(),
                gltf::buffer::Source::Uri(u) => {
                    uri::read(u, base).map_err(|r| err(format!("{element}.uri"), r))?
                }
            }
        };
        if data.len() < buffer.length() {
            return Err(err(
                element,
                format!(
                    "has {} bytes but byteLength is {} (truncated?)",
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// Parses and validates the document. gltf-json's validation indexes a primitive's POSITION
/// accessor without a bounds check (it panics on a bad index), and never checks animation
/// channels' target nodes, so those indices are checked first. Missing or malformed POSITION `min`/`max` are tolerated: lucerna computes bounds
/// itself, and several exporters omit them.
fn parse(bytes: &[u8], source: &str) -> Result<gltf::Gltf> {
    use gltf::json::validation::{Checked, Validate};
    if bytes.starts_with(b"glTF") && bytes.len() >= 12 {
        let declared = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize;
        if declared > bytes.len() {
            return Err(Error::bad_input(
                source,
                "GLB container",
                format!(
                    "file is truncated: {} bytes, the header declares {declared}",
                    bytes.len()
                ),
            ));
        }
        // The gltf crate subtracts the header's size from the declared length unchecked.
        if declared < 12 {
            return Err(Error::bad_input(
                source,
                "GLB container",
                format!("the header declares {declared} bytes, less than the 12-byte header"),
            ));
        }
        // glTF-Validator: GLB_LENGTH_MISMATCH, an error (trailing bytes are not glTF).
        if declared < bytes.len() {
            return Err(Error::bad_input(
                source,
                "GLB container",
                format!(
                    "the header declares {declared} bytes, but the file has {}",
                    bytes.len()
                ),
            ));
        }
    }
    let gltf =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| parse_error(source, e))?;
    let root = gltf.document.as_json();
    check_version(root, source)?;
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let position = primitive
                .attributes
                .get(&Checked::Valid(gltf::Semantic::Positions));
            if let Some(index) = position.filter(|i| i.value() >= root.accessors.len()) {
                return Err(Error::bad_input(
                    source,
                    format!("meshes[{m}].primitives[{p}].attributes.POSITION"),
                    format!(
                        "accessor {} does not exist (the file has {})",
                        index.value(),
                        root.accessors.len()
                    ),
                ));
            }
        }
    }
    // An image is a URI or a buffer view with a MIME type (the gltf crate unwraps both).
    for (i, image) in root.images.iter().enumerate() {
        let reason = match (&image.uri, &image.buffer_view, &image.mime_type) {
            (Some(_), None, _) | (None, Some(_), Some(_)) => continue,
            (None, None, _) => "has neither uri nor bufferView",
            (Some(_), Some(_), _) => "has both uri and bufferView",
            (None, Some(_), None) => "has a bufferView but no mimeType",
        };
        return Err(Error::bad_input(source, format!("images[{i}]"), reason));
    }
    // Nor does it check an animation channel's target node (the gltf crate then panics).
    for (a, animation) in root.animations.iter().enumerate() {
        for (c, channel) in animation.channels.iter().enumerate() {
            let node = channel.target.node.value();
            if node >= root.nodes.len() {
                return Err(Error::bad_input(
                    source,
                    format!("animations[{a}].channels[{c}].target.node"),
                    format!(
                        "node {node} does not exist (the file has {})",
                        root.nodes.len()
                    ),
                ));
            }
        }
    }
    let draco = root
        .extensions_used
        .iter()
        .any(|e| e == "KHR_draco_mesh_compression");
    let mut errors = Vec::new();
    root.validate(root, gltf::json::Path::new, &mut |path, error| {
        let path = path();
        let bounds =
            path.0.ends_with("[\"POSITION\"].min") || path.0.ends_with("[\"POSITION\"].max");
        // The crate refuses required extensions it has no feature for; lucerna decides
        // that from the extensions it implements (below).
        let required = path.0.starts_with("extensionsRequired")
            && matches!(error, gltf::json::validation::Error::Unsupported);
        // A Draco primitive's accessors have no bufferView: their data is decoded
        // (gltf_delivery), and the importer's checks refuse any still without data.
        let draco_data = draco
            && path.0.starts_with("accessors[")
            && path.0.ends_with("].bufferView")
            && matches!(error, gltf::json::validation::Error::Missing);
        if !bounds && !required && !draco_data {
            errors.push((path, error));
        }
    });
    if !errors.is_empty() {
        return Err(parse_error(source, gltf::Error::Validation(errors)));
    }
    for (i, ext) in root.extensions_required.iter().enumerate() {
        if !SUPPORTED_EXTENSIONS.contains(&ext.as_str()) {
            return Err(Error::bad_input(
                source,
                format!("extensionsRequired[{i}] = {ext:?}"),
                "required extension is not supported by lucerna",
            ));
        }
    }
    Ok(gltf)
}

/// `asset.version` (and `minVersion`) must name glTF 2.x, as the specification requires;
/// glTF-Validator calls another major version an error and a later minor one a warning
/// (the file then may hold what lucerna cannot read), which [`Importer::run`] gives.
fn check_version(root: &gltf::json::Root, source: &str) -> Result<()> {
    let parse = |v: &str| -> Option<(u32, u32)> {
        let (major, minor) = v.split_once('.')?;
        Some((major.parse().ok()?, minor.parse().ok()?))
    };
    let version = &root.asset.version;
    match parse(version) {
        Some((2, 0)) => {}
        Some((2, _)) => {} // a later minor version: warned about by the importer
        _ => {
            return Err(Error::bad_input(
                source,
                "asset.version",
                format!("{version:?}: lucerna reads glTF 2.x (\"2.0\")"),
            ));
        }
    }
    if let Some(min) = &root.asset.min_version
        && parse(min).is_none_or(|m| m > (2, 0))
    {
        return Err(Error::bad_input(
            source,
            "asset.minVersion",
            format!("{min:?}: the file needs a reader of a later glTF than 2.0"),
        ));
    }
    Ok(())
}

fn parse_error(source: &str, e: gltf::Error) -> Error {
    match e {
        gltf::Error::Binary(e) => Error::bad_input(source, "GLB container", e.to_string()),
        gltf::Error::Deserialize(e) => Error::bad_input(source, "JSON", e.to_string()),
        gltf::Error::Validation(errors) => {
            let (path, err) = &errors[0];
            let reason = match err {
                gltf::json::validation::Error::Unsupported => {
                    "required extension is not supported by lucerna".into()
                }
                other => other.to_string(),
            };
            let more = if errors.len() > 1 {
                format!(" (and {} more problems)", errors.len() - 1)
            } else {
                String::new()
            };
            Error::bad_input(source, path.to_string(), format!("{reason}{more}"))
        }
        other => Error::bad_input(source, "file", other.to_string()),
    }
}

struct Importer<'a> {
    source: String,
    base: Option<&'a Path>,
    doc: &'a gltf::Document,
    buffers: Vec<Vec<u8>>,
    scene: Scene,
    /// glTF image index → decoded size and texels (shared by the textures that use it).
    images: HashMap<usize, (u32, u32, Arc<scene::Texels>)>,
    /// glTF texture index → scene texture.
    textures: HashMap<usize, u32>,
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
    /// Unsupported extensions a material uses → the materials' names (one warning each).
    unsupported_material_extensions: std::collections::BTreeMap<String, Vec<String>>,
}

/// The animated parts of a node's transform at one time (the rest come from the node).
#[derive(Default)]
struct NodePose {
    translation: Option<DVec3>,
    rotation: Option<DQuat>,
    scale: Option<DVec3>,
}

/// The lucerna section of a material's `extras`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct LucernaExtras {
    bsdf: String,
    exponent: Option<f32>,
    specular: Option<SpecularValue>,
}

#[derive(serde::Deserialize)]
#[serde(untagged)]
enum SpecularValue {
    Grey(f32),
    Rgb([f32; 3]),
}

impl<'a> Importer<'a> {
    fn err(&self, element: impl Into<String>, reason: impl Into<String>) -> Error {
        Error::bad_input(&self.source, element, reason)
    }

    fn warn(&mut self, element: impl AsRef<str>, message: impl AsRef<str>) {
        self.scene.warnings.push(format!(
            "{}: {}: {}",
            self.source,
            element.as_ref(),
            message.as_ref()
        ));
    }

    fn run(&mut self, time: Option<f64>) -> Result<()> {
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
        self.warn_unsupported_extensions();
        if self.scene.instanced_triangle_count() == 0 && self.scene.spheres.is_empty() {
            return Err(self.err(
                format!("scenes[{}]", gltf_scene.index()),
                "contains no triangles",
            ));
        }
        Ok(())
    }

    /// Samples every animation channel at `time` seconds into [`Importer::pose`]: the
    /// chosen animation's alone (`--animation`), else all the file's together, an animation
    /// that animates what an earlier one does being a clip of one character that does not
    /// play (warned).
    fn pose_at(&mut self, time: f64) -> Result<()> {
        use gltf::animation::Property;
        use gltf::animation::util::ReadOutputs;
        let mut animated: HashMap<(usize, &str), usize> = HashMap::new();
        // Animations that animate what an earlier one does: clips of one character (a
        // walk, a run); the earlier one plays.
        let mut clips = std::collections::BTreeSet::new();
        let chosen = self.animation;
        for animation in self
            .doc
            .animations()
            .filter(|a| chosen.is_none_or(|c| c == a.index()))
        {
            for channel in animation.channels() {
                let element = format!(
                    "animations[{}].channels[{}]",
                    animation.index(),
                    channel.index()
                );
                let sampler = channel.sampler();
                let interpolation = match sampler.interpolation() {
                    gltf::animation::Interpolation::Step => Interpolation::Step,
                    gltf::animation::Interpolation::Linear => Interpolation::Linear,
                    gltf::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
                };
                let property = channel.target().property();
                let (name, dims, types) = match property {
                    Property::Translation => {
                        ("translation", Dimensions::Vec3, &[DataType::F32][..])
                    }
                    Property::Scale => ("scale", Dimensions::Vec3, &[DataType::F32][..]),
                    Property::Rotation => ("rotation", Dimensions::Vec4, FLOAT_OR_NORMALIZED),
                    Property::MorphTargetWeights => {
                        let node = channel.target().node().index();
                        match animated.get(&(node, "weights")) {
                            Some(&earlier) if earlier != animation.index() => {
                                clips.insert(animation.index());
                            }
                            _ => {
                                animated.insert((node, "weights"), animation.index());
                                self.sample_weights(&channel, &element, interpolation, time)?;
                            }
                        }
                        continue;
                    }
                };
                let node = channel.target().node().index();
                match animated.get(&(node, name)) {
                    Some(&earlier) if earlier != animation.index() => {
                        clips.insert(animation.index());
                        continue;
                    }
                    _ => {
                        animated.insert((node, name), animation.index());
                    }
                }
                self.check_sampler(&sampler, &element, dims, types)?;
                let buffers = &self.buffers;
                let reader = channel.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
                let unreadable = || self.err(&element, "the sampler's data cannot be read");
                let times: Vec<f32> = reader.read_inputs().ok_or_else(unreadable)?.collect();
                let sample = |values: &[[f32; 4]]| {
                    let track = Track {
                        times: &times,
                        values,
                        interpolation,
                    };
                    track.check().map(|()| track.sample(time))
                };
                let sample3 = |values: &[[f32; 3]]| {
                    let track = Track {
                        times: &times,
                        values,
                        interpolation,
                    };
                    track.check().map(|()| track.sample(time).truncate())
                };
                let pose = match reader.read_outputs().ok_or_else(unreadable)? {
                    ReadOutputs::Translations(values) => {
                        let v = sample3(&values.collect::<Vec<_>>());
                        v.map(|v| (Some(v), None, None))
                    }
                    ReadOutputs::Scales(values) => {
                        let v = sample3(&values.collect::<Vec<_>>());
                        v.map(|v| (None, None, Some(v)))
                    }
                    ReadOutputs::Rotations(values) => {
                        let v = sample(&values.into_f32().collect::<Vec<_>>());
                        v.map(|q| (None, Some(DQuat::from_vec4(q)), None))
                    }
                    ReadOutputs::MorphTargetWeights(_) => unreachable!("skipped above"),
                }
                .map_err(|e| self.err(&element, e))?;
                let entry = self.pose.entry(node).or_default();
                match pose {
                    (Some(t), _, _) => entry.translation = Some(t),
                    (_, Some(r), _) => entry.rotation = Some(r),
                    (_, _, Some(s)) => entry.scale = Some(s),
                    _ => {}
                }
            }
        }
        if !clips.is_empty() {
            let name = |i: usize| {
                let a = self.doc.animations().nth(i).expect("animation index");
                a.name()
                    .map_or_else(|| format!("animations[{i}]"), |n| format!("{n:?}"))
            };
            let skipped: Vec<String> = clips.iter().map(|&i| name(i)).collect();
            let first = (0..self.doc.animations().count())
                .find(|i| !clips.contains(i))
                .map_or_else(String::new, name);
            self.warn(
                "animations",
                format!(
                    "{} animate the same nodes as {first} (clips of one animation); {first} is rendered (--animation NAME plays another)",
                    skipped.join(", ")
                ),
            );
        }
        Ok(())
    }

    /// Checks an animation sampler's accessors: float key times, and outputs of `dims` and
    /// one of `types` (integers normalized).
    fn check_sampler(
        &self,
        sampler: &gltf::animation::Sampler,
        element: &str,
        dims: Dimensions,
        types: &[DataType],
    ) -> Result<()> {
        self.check_accessor(
            &sampler.input(),
            &format!("{element} input"),
            &[Dimensions::Scalar],
            &[DataType::F32],
            false,
        )?;
        self.check_accessor(
            &sampler.output(),
            &format!("{element} output"),
            &[dims],
            types,
            true,
        )
    }

    /// Samples a morph target weights channel at `time` into [`Importer::morph_weights`].
    fn sample_weights(
        &mut self,
        channel: &gltf::animation::Channel,
        element: &str,
        interpolation: Interpolation,
        time: f64,
    ) -> Result<()> {
        let sampler = channel.sampler();
        self.check_sampler(&sampler, element, Dimensions::Scalar, FLOAT_OR_NORMALIZED)?;
        let buffers = &self.buffers;
        let reader = channel.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let unreadable = || self.err(element, "the sampler's data cannot be read");
        let times: Vec<f32> = reader.read_inputs().ok_or_else(unreadable)?.collect();
        let values: Vec<f32> = match reader.read_outputs().ok_or_else(unreadable)? {
            gltf::animation::util::ReadOutputs::MorphTargetWeights(w) => w.into_f32().collect(),
            _ => return Err(unreadable()),
        };
        let per_key = if interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
        if times.is_empty() || !values.len().is_multiple_of(times.len() * per_key) {
            return Err(self.err(
                element,
                format!(
                    "{} weights do not divide into {} keys",
                    values.len(),
                    times.len()
                ),
            ));
        }
        let targets = values.len() / (times.len() * per_key);
        let mut weights = Vec::with_capacity(targets);
        for t in 0..targets {
            // Output element k × targets + t is target t's value in slot k (a key, or an
            // in-tangent, value and out-tangent of one for cubic splines).
            let track_values: Vec<[f32; 1]> = (0..times.len() * per_key)
                .map(|k| [values[k * targets + t]])
                .collect();
            let track = Track {
                times: &times,
                values: &track_values,
                interpolation,
            };
            track.check().map_err(|e| self.err(element, e))?;
            weights.push(track.sample(time).x as f32);
        }
        let node = channel.target().node().index();
        self.morph_weights.insert(node, weights);
        Ok(())
    }

    /// A node's local transform: its own, with the animated parts of its pose.
    fn local_transform(&self, node: &gltf::Node) -> DMat4 {
        let Some(pose) = self.pose.get(&node.index()) else {
            return DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        };
        let (t, r, s) = node.transform().decomposed();
        DMat4::from_scale_rotation_translation(
            pose.scale.unwrap_or(DVec3::from(s.map(f64::from))),
            pose.rotation
                .unwrap_or(DQuat::from_array(r.map(f64::from)))
                .normalize(),
            pose.translation.unwrap_or(DVec3::from(t.map(f64::from))),
        )
    }

    fn visit(&mut self, node: gltf::Node<'a>, parent: DMat4, path: &mut Vec<usize>) -> Result<()> {
        let element = format!("nodes[{}]", node.index());
        if path.contains(&node.index()) {
            return Err(self.err(&element, "node hierarchy contains a cycle"));
        }
        if path.len() >= MAX_NODE_DEPTH {
            return Err(self.err(
                &element,
                format!("node hierarchy deeper than {MAX_NODE_DEPTH}"),
            ));
        }
        let local = self.local_transform(&node);
        if !local.is_finite() {
            return Err(self.err(&element, "transform is not finite"));
        }
        let world = parent * local;
        let name = node.name().map_or_else(|| element.clone(), str::to_string);
        if let Some(group) = self.light_group(&node, &element)? {
            self.scene.add_to_light_group(&group, &name);
        }
        self.world_of.insert(node.index(), world);
        if let Some(mesh) = node.mesh() {
            let weights = self.node_weights(&node, &mesh);
            if node.skin().is_some() {
                // Skinned vertices are placed by their joints, whose transforms are known
                // once the whole scene has been visited.
                self.skinned.push((node.index(), name.clone()));
            } else if self.is_sphere(&mesh)? {
                self.sphere(&mesh, world, &name)?;
            } else {
                let transforms = self.instance_transforms(&node, world)?;
                for primitive in mesh.primitives() {
                    let m = if weights.iter().any(|&w| w != 0.0) {
                        self.deformed(&node, &mesh, &primitive, &weights, None)?
                    } else {
                        self.primitive(&mesh, &primitive)?
                    };
                    if let Some(m) = m {
                        for &transform in &transforms {
                            self.scene.instances.push(Instance {
                                name: name.clone(),
                                mesh: m,
                                transform,
                            });
                        }
                    }
                }
            }
        }
        if let Some(camera) = node.camera() {
            let cam = self.camera(&camera, world, &name)?;
            self.scene.cameras.push(cam);
        }
        if let Some(light) = node.light() {
            self.light(&light, world, &name)?;
        }
        path.push(node.index());
        for child in node.children() {
            self.visit(child, world, path)?;
        }
        path.pop();
        Ok(())
    }

    /// The light group a node's `extras` put it in: `{"lucerna": {"light_group": "key"}}`
    /// (its emitting meshes and its light go to `lg_key`).
    fn light_group(&self, node: &gltf::Node, element: &str) -> Result<Option<String>> {
        let Some(raw) = node.extras() else {
            return Ok(None);
        };
        let value: serde_json::Value = serde_json::from_str(raw.get())
            .map_err(|e| self.err(format!("{element}.extras"), e.to_string()))?;
        match value.get("lucerna").and_then(|l| l.get("light_group")) {
            None => Ok(None),
            Some(serde_json::Value::String(group))
                if !group.is_empty()
                    && group.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') =>
            {
                Ok(Some(group.to_ascii_lowercase()))
            }
            Some(other) => Err(self.err(
                format!("{element}.extras.lucerna.light_group"),
                format!("{other} is not a group name (letters, digits and _)"),
            )),
        }
    }

    /// Whether the mesh's `extras` make it an analytic sphere:
    /// `{"lucerna": {"shape": "sphere"}}`.
    fn is_sphere(&self, mesh: &gltf::Mesh) -> Result<bool> {
        let Some(raw) = mesh.extras() else {
            return Ok(false);
        };
        let e = format!("meshes[{}].extras.lucerna", mesh.index());
        let value: serde_json::Value =
            serde_json::from_str(raw.get()).map_err(|err| self.err(&e, err.to_string()))?;
        match value.get("lucerna").and_then(|l| l.get("shape")) {
            None => Ok(false),
            Some(shape) if shape == "sphere" => Ok(true),
            Some(other) => {
                Err(self.err(&e, format!("unknown shape {other} (expected \"sphere\")")))
            }
        }
    }

    /// Places the analytic sphere that bounds `mesh`'s vertices, with its first primitive's
    /// material. The node's transform must scale uniformly.
    fn sphere(&mut self, mesh: &gltf::Mesh<'a>, world: DMat4, name: &str) -> Result<()> {
        let element = format!("meshes[{}]", mesh.index());
        let mut positions = Vec::new();
        let mut material = None;
        for primitive in mesh.primitives() {
            if let Some(m) = self.primitive(mesh, &primitive)? {
                let m = &self.scene.meshes[m as usize];
                positions.extend(m.positions.iter().map(|p| p.as_dvec3()));
                material.get_or_insert(m.material);
            }
        }
        let Some(material) = material else {
            return Err(self.err(&element, "a sphere mesh needs triangles to bound"));
        };
        let (lo, hi) = positions
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            });
        let centre = (lo + hi) * 0.5;
        let radius = positions
            .iter()
            .map(|p| p.distance(centre))
            .fold(0.0, f64::max);
        let axes = [DVec3::X, DVec3::Y, DVec3::Z].map(|a| world.transform_vector3(a).length());
        let scale = axes[0];
        if !(scale > 0.0) || axes.iter().any(|a| (a - scale).abs() > 1e-6 * scale) {
            return Err(self.err(
                format!("nodes \"{name}\""),
                "an analytic sphere needs a uniform scale",
            ));
        }
        self.scene.spheres.push(scene::Sphere {
            name: name.to_string(),
            centre: world.transform_point3(centre),
            radius: radius * scale,
            material,
        });
        Ok(())
    }

    /// Checks that `accessor` has an allowed type and that all its bytes exist.
    fn check_accessor(
        &self,
        accessor: &gltf::Accessor,
        element: &str,
        dims: &[Dimensions],
        types: &[DataType],
        normalized_integers: bool,
    ) -> Result<()> {
        let e = format!("{element} (accessors[{}])", accessor.index());
        if accessor.count() == 0 {
            return Err(self.err(&e, "accessor has count 0"));
        }
        if !dims.contains(&accessor.dimensions()) || !types.contains(&accessor.data_type()) {
            return Err(self.err(
                &e,
                format!(
                    "accessor is {:?} of {:?}; expected {dims:?} of {types:?}",
                    accessor.dimensions(),
                    accessor.data_type()
                ),
            ));
        }
        if normalized_integers && accessor.data_type() != DataType::F32 && !accessor.normalized() {
            return Err(self.err(&e, "integer accessor must be normalized"));
        }
        let check_range =
            |view: gltf::buffer::View, offset: usize, count: usize, elem: usize| -> Result<()> {
                let stride = view.stride().unwrap_or(elem);
                if count == 0 {
                    return Ok(());
                }
                if stride < elem {
                    return Err(self.err(
                        &e,
                        format!("byteStride {stride} is smaller than the element size {elem}"),
                    ));
                }
                let end = (count - 1)
                    .checked_mul(stride)
                    .and_then(|x| x.checked_add(offset))
                    .and_then(|x| x.checked_add(elem));
                if end.is_none_or(|end| end > view.length()) {
                    return Err(self.err(
                        &e,
                        format!(
                            "accessor data runs past the end of bufferViews[{}]",
                            view.index()
                        ),
                    ));
                }
                let buffer_len = self.buffers.get(view.buffer().index()).map_or(0, Vec::len);
                if view
                    .offset()
                    .checked_add(view.length())
                    .is_none_or(|end| end > buffer_len)
                {
                    return Err(self.err(
                        &e,
                        format!(
                            "bufferViews[{}] runs past the end of its buffer",
                            view.index()
                        ),
                    ));
                }
                Ok(())
            };
        match (accessor.view(), accessor.sparse()) {
            (Some(view), _) => {
                check_range(view, accessor.offset(), accessor.count(), accessor.size())?
            }
            (None, None) => {
                return Err(self.err(
                    &e,
                    "accessor has no data (no bufferView and no sparse values)",
                ));
            }
            (None, Some(_)) => {}
        }
        if let Some(sparse) = accessor.sparse() {
            let indices = sparse.indices();
            check_range(
                indices.view(),
                indices.offset(),
                sparse.count(),
                indices.index_type().size(),
            )?;
            let values = sparse.values();
            check_range(
                values.view(),
                values.offset(),
                sparse.count(),
                accessor.size(),
            )?;
            // Each index names an element of the accessor, in increasing order
            // (glTF-Validator: ACCESSOR_SPARSE_INDEX_OOB, ACCESSOR_SPARSE_INDICES_NON_INCREASING).
            let view = indices.view();
            let size = indices.index_type().size();
            if view.stride().is_some_and(|s| s != size) {
                return Err(self.err(&e, "sparse.indices' bufferView must not have a byteStride"));
            }
            let start = view.offset() + indices.offset();
            let bytes = &self.buffers[view.buffer().index()][start..start + sparse.count() * size];
            let mut previous: Option<usize> = None;
            for (k, chunk) in bytes.chunks_exact(size).enumerate() {
                let index = match size {
                    1 => chunk[0] as usize,
                    2 => u16::from_le_bytes([chunk[0], chunk[1]]) as usize,
                    _ => u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]) as usize,
                };
                if index >= accessor.count() {
                    return Err(self.err(
                        &e,
                        format!(
                            "sparse.indices[{k}] = {index} is past the accessor's {} elements",
                            accessor.count()
                        ),
                    ));
                }
                if previous.is_some_and(|p| index <= p) {
                    return Err(self.err(
                        &e,
                        format!("sparse.indices[{k}] = {index} does not increase"),
                    ));
                }
                previous = Some(index);
            }
        }
        Ok(())
    }

    /// Selects KHR_materials_variants variant `name`; without one, a file with variants gets
    /// a warning naming them.
    /// Chooses the animation that plays, by name or index; an unknown one is refused with
    /// the file's animations listed.
    fn select_animation(&mut self, wanted: Option<&str>) -> Result<()> {
        let Some(wanted) = wanted else {
            return Ok(());
        };
        let names: Vec<String> = self
            .doc
            .animations()
            .map(|a| {
                a.name()
                    .map_or_else(|| format!("{}", a.index()), |n| format!("{n:?}"))
            })
            .collect();
        let found = self
            .doc
            .animations()
            .position(|a| a.name() == Some(wanted))
            .or_else(|| wanted.parse::<usize>().ok().filter(|&i| i < names.len()));
        match found {
            Some(i) => {
                self.animation = Some(i);
                Ok(())
            }
            None if names.is_empty() => Err(self.err(
                "animations",
                format!("animation {wanted:?} requested, but the file has no animations"),
            )),
            None => Err(self.err(
                "animations",
                format!(
                    "has no animation {wanted:?} (it has {}; give a name or an index)",
                    names.join(", ")
                ),
            )),
        }
    }

    fn select_variant(&mut self, name: Option<&str>) -> Result<()> {
        let names: Vec<String> = self
            .doc
            .extension_value("KHR_materials_variants")
            .and_then(|e| e.get("variants"))
            .and_then(serde_json::Value::as_array)
            .map(|v| {
                v.iter()
                    .map(|v| {
                        v.get("name")
                            .and_then(serde_json::Value::as_str)
                            .unwrap_or("")
                            .to_string()
                    })
                    .collect()
            })
            .unwrap_or_default();
        match name {
            Some(name) => match names.iter().position(|n| n == name) {
                Some(i) => self.variant = Some(i),
                None if names.is_empty() => {
                    return Err(self.err(
                        "extensions.KHR_materials_variants",
                        format!("material variant {name:?} requested, but the file has no variants"),
                    ));
                }
                None => {
                    return Err(self.err(
                        "extensions.KHR_materials_variants",
                        format!(
                            "has no material variant {name:?} (it has {})",
                            names.join(", ")
                        ),
                    ));
                }
            },
            None if !names.is_empty() => self.warn(
                "extensions.KHR_materials_variants",
                format!(
                    "the file has material variants {}; the default materials are rendered (--material-variant NAME)",
                    names.join(", ")
                ),
            ),
            None => {}
        }
        Ok(())
    }

    /// The material the selected variant maps `primitive` to, if it maps it.
    fn variant_material(&self, primitive: &gltf::Primitive) -> Option<gltf::Material<'a>> {
        let variant = self.variant? as u64;
        let mappings = primitive
            .extensions()?
            .get("KHR_materials_variants")?
            .get("mappings")?
            .as_array()?;
        let material = mappings.iter().find_map(|m| {
            let listed = m.get("variants")?.as_array()?;
            listed
                .iter()
                .any(|v| v.as_u64() == Some(variant))
                .then(|| m.get("material")?.as_u64())?
        })?;
        self.doc.materials().nth(material as usize)
    }

    /// The morph target weights of `node`'s mesh at the render's time: animated, else the
    /// node's, else the mesh's (empty: no targets).
    fn node_weights(&self, node: &gltf::Node, mesh: &gltf::Mesh) -> Vec<f32> {
        if let Some(w) = self.morph_weights.get(&node.index()) {
            return w.clone();
        }
        node.weights()
            .or_else(|| mesh.weights())
            .map(<[f32]>::to_vec)
            .unwrap_or_default()
    }

    /// The world transforms a node's mesh is drawn at: `world`, or one for each instance of
    /// its EXT_mesh_gpu_instancing attributes (TRANSLATION, ROTATION, SCALE; float or, with
    /// KHR_mesh_quantization, normalized integers), each applied before the node's own.
    fn instance_transforms(&self, node: &gltf::Node, world: DMat4) -> Result<Vec<DMat4>> {
        let Some(ext) = node
            .extensions()
            .and_then(|e| e.get("EXT_mesh_gpu_instancing"))
        else {
            return Ok(vec![world]);
        };
        let element = format!("nodes[{}].extensions.EXT_mesh_gpu_instancing", node.index());
        let attributes = ext.get("attributes").and_then(serde_json::Value::as_object);
        let read = |name: &str, width: usize| -> Result<Option<Vec<f32>>> {
            let Some(a) = attributes.and_then(|a| a.get(name)) else {
                return Ok(None);
            };
            let e = format!("{element}.attributes.{name}");
            let a = a
                .as_u64()
                .ok_or_else(|| self.err(&e, "is not an accessor index"))?;
            let values = gltf_delivery::read_floats(self.doc.as_json(), &self.buffers, a as usize)
                .map_err(|r| self.err(&e, r))?;
            let ty = self.doc.as_json().accessors[a as usize].type_;
            let expected = if width == 4 {
                gltf::json::accessor::Type::Vec4
            } else {
                gltf::json::accessor::Type::Vec3
            };
            if ty != gltf::json::validation::Checked::Valid(expected) {
                return Err(self.err(&e, format!("must be a {expected:?} accessor")));
            }
            if values.iter().any(|v| !v.is_finite()) {
                return Err(self.err(&e, "holds a value that is not finite"));
            }
            Ok(Some(values))
        };
        let translation = read("TRANSLATION", 3)?;
        let rotation = read("ROTATION", 4)?;
        let scale = read("SCALE", 3)?;
        let counts: Vec<usize> = [(&translation, 3), (&rotation, 4), (&scale, 3)]
            .iter()
            .filter_map(|(v, w)| v.as_ref().map(|v| v.len() / w))
            .collect();
        let Some(&count) = counts.first() else {
            return Err(self.err(&element, "has no TRANSLATION, ROTATION or SCALE attribute"));
        };
        if counts.iter().any(|&c| c != count) {
            return Err(self.err(
                &element,
                format!("its attributes have different counts {counts:?}"),
            ));
        }
        let v3 = |v: &Option<Vec<f32>>, i: usize, default: DVec3| {
            v.as_ref().map_or(default, |v| {
                DVec3::new(v[3 * i] as f64, v[3 * i + 1] as f64, v[3 * i + 2] as f64)
            })
        };
        Ok((0..count)
            .map(|i| {
                let r = rotation.as_ref().map_or(DQuat::IDENTITY, |r| {
                    DQuat::from_xyzw(
                        r[4 * i] as f64,
                        r[4 * i + 1] as f64,
                        r[4 * i + 2] as f64,
                        r[4 * i + 3] as f64,
                    )
                    .normalize()
                });
                world
                    * DMat4::from_scale_rotation_translation(
                        v3(&scale, i, DVec3::ONE),
                        r,
                        v3(&translation, i, DVec3::ZERO),
                    )
            })
            .collect())
    }

    /// Converts skinned node `index` (named `name`): its mesh posed by its joints' world
    /// transforms at the render's time, placed in world space.
    fn skinned_node(&mut self, index: usize, name: &str) -> Result<()> {
        let doc = self.doc;
        let node = doc.nodes().nth(index).expect("visited node");
        let (Some(skin), Some(mesh)) = (node.skin(), node.mesh()) else {
            return Ok(());
        };
        let element = format!("skins[{}]", skin.index());
        let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        let inverse_bind: Vec<DMat4> = match skin.inverse_bind_matrices() {
            Some(acc) => {
                self.check_accessor(
                    &acc,
                    &format!("{element}.inverseBindMatrices"),
                    &[Dimensions::Mat4],
                    &[DataType::F32],
                    false,
                )?;
                if acc.count() < joints.len() {
                    return Err(self.err(
                        format!("{element}.inverseBindMatrices"),
                        format!("has {} matrices for {} joints", acc.count(), joints.len()),
                    ));
                }
                let buffers = &self.buffers;
                let reader = skin.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
                reader
                    .read_inverse_bind_matrices()
                    .ok_or_else(|| self.err(&element, "inverseBindMatrices cannot be read"))?
                    .map(|m| DMat4::from_cols_array_2d(&m.map(|c| c.map(f64::from))))
                    .collect()
            }
            None => vec![DMat4::IDENTITY; joints.len()],
        };
        let mut joint_matrices = Vec::with_capacity(joints.len());
        for (j, &joint) in joints.iter().enumerate() {
            let world = match self.world_of.get(&joint) {
                Some(w) => *w,
                None => {
                    return Err(self.err(
                        format!("{element}.joints[{j}]"),
                        format!("node {joint} is not in the rendered scene"),
                    ));
                }
            };
            joint_matrices.push(world * inverse_bind[j]);
        }
        if joint_matrices.iter().any(|m| !m.is_finite()) {
            return Err(self.err(&element, "a joint matrix is not finite"));
        }
        let weights = self.node_weights(&node, &mesh);
        for primitive in mesh.primitives() {
            if let Some(m) =
                self.deformed(&node, &mesh, &primitive, &weights, Some(&joint_matrices))?
            {
                self.scene.instances.push(Instance {
                    name: name.to_string(),
                    mesh: m,
                    transform: DMat4::IDENTITY,
                });
            }
        }
        Ok(())
    }

    /// A primitive converted for one node: morphed by `weights` and, with `joints` (the
    /// skin's joint matrices), skinned to world space. Not shared with other nodes.
    fn deformed(
        &mut self,
        node: &gltf::Node,
        mesh: &gltf::Mesh,
        primitive: &gltf::Primitive,
        weights: &[f32],
        joints: Option<&[DMat4]>,
    ) -> Result<Option<u32>> {
        if !matches!(
            primitive.mode(),
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            return self.primitive(mesh, primitive); // Warned and skipped there.
        }
        let element = format!(
            "nodes[{}] meshes[{}].primitives[{}]",
            node.index(),
            mesh.index(),
            primitive.index()
        );
        let Some(mut out) = self.convert_primitive(mesh, primitive, &element)? else {
            return Ok(None);
        };
        let vertices = out.positions.len();
        let mut notes: Vec<String> = Vec::new();
        let buffers = &self.buffers;
        let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        if weights.iter().any(|&w| w != 0.0) {
            for (t, target) in primitive.morph_targets().enumerate() {
                for (name, acc) in [
                    ("POSITION", target.positions()),
                    ("NORMAL", target.normals()),
                    ("TANGENT", target.tangents()),
                ] {
                    if let Some(acc) = acc {
                        let e = format!("{element}.targets[{t}].{name}");
                        self.check_accessor(
                            &acc,
                            &e,
                            &[Dimensions::Vec3],
                            &[DataType::F32],
                            false,
                        )?;
                        if acc.count() != vertices {
                            return Err(self.err(
                                e,
                                format!("has {} elements for {vertices} vertices", acc.count()),
                            ));
                        }
                    }
                }
            }
            let targets: Vec<skinning::MorphTarget> = reader
                .read_morph_targets()
                .map(|(p, n, t)| skinning::MorphTarget {
                    positions: p.map(|it| it.map(Vec3::from_array).collect()),
                    normals: n.map(|it| it.map(Vec3::from_array).collect()),
                    tangents: t.map(|it| it.map(Vec3::from_array).collect()),
                })
                .collect();
            if targets.len() != weights.len() {
                notes.push(format!(
                    "{} morph targets but {} weights; the missing weights are 0",
                    targets.len(),
                    weights.len()
                ));
            }
            skinning::morph(&mut out, &targets, weights);
        }
        if let Some(joints) = joints {
            let mut influences: Vec<skinning::Influences> = vec![Vec::new(); vertices];
            let mut set = 0;
            while let (Some(j), Some(w)) = (
                primitive.get(&gltf::Semantic::Joints(set)),
                primitive.get(&gltf::Semantic::Weights(set)),
            ) {
                let je = format!("{element}.attributes.JOINTS_{set}");
                let we = format!("{element}.attributes.WEIGHTS_{set}");
                self.check_accessor(
                    &j,
                    &je,
                    &[Dimensions::Vec4],
                    &[DataType::U8, DataType::U16],
                    false,
                )?;
                self.check_accessor(
                    &w,
                    &we,
                    &[Dimensions::Vec4],
                    &[DataType::F32, DataType::U8, DataType::U16],
                    true,
                )?;
                for (e, acc) in [(&je, &j), (&we, &w)] {
                    if acc.count() != vertices {
                        return Err(self.err(
                            e,
                            format!("has {} elements for {vertices} vertices", acc.count()),
                        ));
                    }
                }
                let js = reader
                    .read_joints(set)
                    .ok_or_else(|| self.err(&je, "cannot be read"))?;
                let ws = reader
                    .read_weights(set)
                    .ok_or_else(|| self.err(&we, "cannot be read"))?;
                for ((inf, j), w) in influences.iter_mut().zip(js.into_u16()).zip(ws.into_f32()) {
                    inf.extend(
                        (0..4).map(|k| (j[k], if w[k].is_finite() { w[k].max(0.0) } else { 0.0 })),
                    );
                }
                set += 1;
            }
            if set == 0 {
                notes.push("the node has a skin but the primitive has no JOINTS_0/WEIGHTS_0; it is placed by the skin's first joint".into());
                influences.iter_mut().for_each(|i| i.push((0, 1.0)));
            }
            let bad = skinning::skin(&mut out, &influences, joints);
            if bad > 0 {
                notes.push(format!(
                    "{bad} joint influences name a joint the skin does not have and are ignored"
                ));
            }
        }
        for note in notes {
            self.warn(&element, note);
        }
        self.complete_tangents(&mut out, &element);
        self.scene.meshes.push(out);
        Ok(Some((self.scene.meshes.len() - 1) as u32))
    }

    fn primitive(&mut self, mesh: &gltf::Mesh, primitive: &gltf::Primitive) -> Result<Option<u32>> {
        let key = (mesh.index(), primitive.index());
        if let Some(m) = self.meshes.get(&key) {
            return Ok(*m);
        }
        let element = format!("meshes[{}].primitives[{}]", mesh.index(), primitive.index());
        let mode = primitive.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            self.warn(
                &element,
                format!("{mode:?} primitive skipped (only triangles are rendered)"),
            );
            self.meshes.insert(key, None);
            return Ok(None);
        }
        let converted = self.convert_primitive(mesh, primitive, &element)?;
        let index = converted.map(|mut m| {
            self.complete_tangents(&mut m, &element);
            self.scene.meshes.push(m);
            (self.scene.meshes.len() - 1) as u32
        });
        self.meshes.insert(key, index);
        Ok(index)
    }

    fn convert_primitive(
        &mut self,
        mesh: &gltf::Mesh,
        primitive: &gltf::Primitive,
        element: &str,
    ) -> Result<Option<Mesh>> {
        let f32_only = [DataType::F32];
        let uv_types = [DataType::F32, DataType::U8, DataType::U16];
        let position_acc = primitive
            .get(&gltf::Semantic::Positions)
            .ok_or_else(|| self.err(element, "has no POSITION attribute"))?;
        let pos_el = format!("{element}.attributes.POSITION");
        self.check_accessor(
            &position_acc,
            &pos_el,
            &[Dimensions::Vec3],
            &f32_only,
            false,
        )?;
        let checks: [(gltf::Semantic, &[Dimensions], &[DataType]); 5] = [
            (gltf::Semantic::Normals, &[Dimensions::Vec3], &f32_only),
            (gltf::Semantic::Tangents, &[Dimensions::Vec4], &f32_only),
            (gltf::Semantic::TexCoords(0), &[Dimensions::Vec2], &uv_types),
            (gltf::Semantic::TexCoords(1), &[Dimensions::Vec2], &uv_types),
            (
                gltf::Semantic::Colors(0),
                &[Dimensions::Vec3, Dimensions::Vec4],
                &uv_types,
            ),
        ];
        let vertex_count = position_acc.count();
        for (semantic, dims, types) in checks {
            if let Some(acc) = primitive.get(&semantic) {
                let el = format!("{element}.attributes.{}", semantic.to_string());
                self.check_accessor(&acc, &el, dims, types, true)?;
                if acc.count() != vertex_count {
                    return Err(self.err(
                        el,
                        format!(
                            "has {} elements but POSITION has {vertex_count}",
                            acc.count()
                        ),
                    ));
                }
            }
        }
        if let Some(acc) = primitive.indices() {
            self.check_accessor(
                &acc,
                &format!("{element}.indices"),
                &[Dimensions::Scalar],
                &[DataType::U8, DataType::U16, DataType::U32],
                false,
            )?;
        }

        let buffers = &self.buffers;
        let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or_else(|| self.err(&pos_el, "cannot read positions"))?
            .map(Vec3::from_array)
            .collect();
        let bad = positions.iter().filter(|p| !p.is_finite()).count();
        if bad > 0 {
            return Err(self.err(
                &pos_el,
                format!("{bad} of {} positions are NaN or infinite", positions.len()),
            ));
        }
        let mut repaired = 0usize;
        let normals = reader.read_normals().map(|it| {
            let ok = |n: &Vec3| n.is_finite() && n.length_squared() > 0.0;
            finite_or(it.map(Vec3::from_array), ok, Vec3::ZERO, &mut repaired)
        });
        let tangents: Option<Vec<Vec4>> = reader
            .read_tangents()
            .map(|it| it.map(Vec4::from_array).collect());
        let uvs = [0, 1].map(|set| {
            reader.read_tex_coords(set).map(|it| {
                let values = it.into_f32().map(Vec2::from_array);
                finite_or(values, |uv| uv.is_finite(), Vec2::ZERO, &mut repaired)
            })
        });
        let colors = reader.read_colors(0).map(|it| {
            let values = it.into_rgba_f32().map(Vec4::from_array);
            finite_or(values, |c| c.is_finite(), Vec4::ONE, &mut repaired)
        });
        let indices: Vec<u32> = match reader.read_indices() {
            Some(it) => it.into_u32().collect(),
            None => (0..vertex_count as u32).collect(),
        };
        if let Some((i, &bad)) = indices
            .iter()
            .enumerate()
            .find(|(_, i)| **i as usize >= vertex_count)
        {
            return Err(self.err(
                format!("{element}.indices"),
                format!("index {bad} at position {i} is out of range (the primitive has {vertex_count} vertices)"),
            ));
        }
        if repaired > 0 {
            self.warn(
                element,
                format!("{repaired} NaN/infinite normals, texture coordinates or colours replaced"),
            );
        }
        let triangles = assemble_triangles(primitive.mode(), &indices);
        if triangles.is_empty() {
            self.warn(element, "has no non-degenerate triangles and is skipped");
            return Ok(None);
        }
        let material = match self.variant_material(primitive) {
            Some(m) => self.material(m)?,
            None => self.material(primitive.material())?,
        };
        let mut out = Mesh {
            name: mesh
                .name()
                .map_or_else(|| format!("meshes[{}]", mesh.index()), str::to_string),
            positions,
            normals,
            tangents: None,
            uvs,
            colors,
            triangles,
            material,
        };
        // The file's tangents where a normal map or anisotropy needs them (MikkTSpace's
        // are made by complete_tangents, after any deformation: it splits vertices).
        if self.scene.materials[material as usize]
            .tangent_uv_set()
            .is_some()
        {
            out.tangents = tangents.filter(|t| t.iter().all(|t| t.is_finite()));
        }
        Ok(Some(out))
    }

    /// MikkTSpace tangents for a converted primitive whose material needs tangents and
    /// whose file gave none.
    fn complete_tangents(&mut self, out: &mut Mesh, element: &str) {
        let Some(uv_set) = self.scene.materials[out.material as usize].tangent_uv_set() else {
            return;
        };
        if out.tangents.is_none() && !tangents::generate(out, uv_set) {
            self.warn(
                element,
                "normal map and anisotropy ignored: the mesh has no texture coordinates for their tangents",
            );
        }
    }

    fn material(&mut self, m: gltf::Material) -> Result<u32> {
        if let Some(&index) = self.materials.get(&m.index()) {
            return Ok(index);
        }
        let converted = match m.index() {
            None => Material::default(),
            Some(i) => self.convert_material(&m, &format!("materials[{i}]"))?,
        };
        self.scene.materials.push(converted);
        let index = (self.scene.materials.len() - 1) as u32;
        self.materials.insert(m.index(), index);
        Ok(index)
    }

    fn convert_material(&mut self, m: &gltf::Material, element: &str) -> Result<Material> {
        let pbr = m.pbr_metallic_roughness();
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        let base_color = Vec4::from_array(pbr.base_color_factor());
        let emissive = Vec3::from_array(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0);
        if !finite(&base_color.to_array())
            || !emissive.is_finite()
            || !pbr.metallic_factor().is_finite()
            || !pbr.roughness_factor().is_finite()
        {
            return Err(self.err(element, "a factor is not finite"));
        }
        // Ranges of the specification's schema (glTF-Validator: VALUE_NOT_IN_RANGE, an error).
        let unit = |x: f32| (0.0..=1.0).contains(&x);
        for (key, ok) in [
            (
                "pbrMetallicRoughness.baseColorFactor",
                base_color.to_array().into_iter().all(unit),
            ),
            (
                "pbrMetallicRoughness.metallicFactor",
                unit(pbr.metallic_factor()),
            ),
            (
                "pbrMetallicRoughness.roughnessFactor",
                unit(pbr.roughness_factor()),
            ),
            ("emissiveFactor", m.emissive_factor().into_iter().all(unit)),
            ("alphaCutoff", m.alpha_cutoff().is_none_or(|c| c >= 0.0)),
            (
                "occlusionTexture.strength",
                m.occlusion_texture().is_none_or(|t| unit(t.strength())),
            ),
            (
                "KHR_materials_emissive_strength.emissiveStrength",
                m.emissive_strength().is_none_or(|s| s >= 0.0),
            ),
        ] {
            if !ok {
                return Err(self.err(element, format!("{key} is outside its range (factors are in [0, 1], strengths and cutoffs not negative)")));
            }
        }
        let model = self.bsdf_model(m, element)?;
        let base_color_texture = self.info_ref(pbr.base_color_texture())?;
        let metallic_roughness_texture = self.info_ref(pbr.metallic_roughness_texture())?;
        let normal = m.normal_texture();
        let normal_texture = normal
            .as_ref()
            .map(|t| {
                let transform = t
                    .extension_value("KHR_texture_transform")
                    .map(transform_from_json);
                self.texture_ref(t.texture(), t.tex_coord(), transform)
            })
            .transpose()?;
        let emissive_texture = self.info_ref(m.emissive_texture())?;
        if m.occlusion_texture().is_some() {
            self.warn(
                element,
                "occlusionTexture ignored (a path tracer computes occlusion)",
            );
        }
        let alpha_mode = match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => AlphaMode::Mask {
                cutoff: m.alpha_cutoff().unwrap_or(0.5),
            },
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        };
        let name = m.name().map_or_else(|| element.to_string(), str::to_string);
        let mut material = Material {
            name: name.clone(),
            model,
            base_color,
            base_color_texture,
            metallic: pbr.metallic_factor().clamp(0.0, 1.0),
            roughness: pbr.roughness_factor().clamp(0.0, 1.0),
            metallic_roughness_texture,
            normal_texture,
            normal_scale: normal.map_or(1.0, |n| n.scale()),
            emissive: emissive.max(Vec3::ZERO),
            emissive_texture,
            ior: m.ior().unwrap_or(1.5),
            alpha_mode,
            double_sided: m.double_sided(),
            ..Material::default()
        };
        if !(material.ior == 0.0 || material.ior >= 1.0) || !material.ior.is_finite() {
            self.warn(
                element,
                format!(
                    "KHR_materials_ior.ior {} is outside [1, inf) and not 0; 1.5 is used",
                    material.ior
                ),
            );
            material.ior = 1.5;
        }
        let extensions = MaterialExtensions {
            element,
            json: m
                .extensions()
                .map(|e| e.iter().map(|(k, v)| (k.as_str(), v)).collect())
                .unwrap_or_default(),
        };
        self.material_extensions(&extensions, &mut material)?;
        for name in extensions.json.keys() {
            if !SUPPORTED_EXTENSIONS.contains(name) {
                self.unsupported_material_extensions
                    .entry(name.to_string())
                    .or_default()
                    .push(material.name.clone());
            }
        }
        if material.unlit && material.emissive_texture.is_some() {
            self.warn(element, "KHR_materials_unlit: the emission is ignored");
        }
        Ok(material)
    }

    /// Reads the material extensions lucerna implements into `material`: clear coat (with
    /// its textures and normal map), transmission, volume, specular, sheen, iridescence,
    /// anisotropy, unlit. Factors must be finite numbers (an error names the one that is
    /// not); values outside the specification's range are clamped into it with a warning.
    fn material_extensions(
        &mut self,
        ext: &MaterialExtensions,
        material: &mut Material,
    ) -> Result<()> {
        if let Some(e) = ext.get("KHR_materials_clearcoat") {
            let name = "KHR_materials_clearcoat";
            material.clearcoat = self.unit_factor(ext, name, e, "clearcoatFactor", 0.0)?;
            material.clearcoat_texture = self.json_texture(ext, e, "clearcoatTexture")?;
            material.clearcoat_roughness =
                self.unit_factor(ext, name, e, "clearcoatRoughnessFactor", 0.0)?;
            material.clearcoat_roughness_texture =
                self.json_texture(ext, e, "clearcoatRoughnessTexture")?;
            material.clearcoat_normal_texture =
                self.json_texture(ext, e, "clearcoatNormalTexture")?;
            if let Some(n) = e.get("clearcoatNormalTexture") {
                material.clearcoat_normal_scale = ext.number(self, name, n, "scale", 1.0)?;
            }
        }
        if let Some(e) = ext.get("KHR_materials_transmission") {
            let name = "KHR_materials_transmission";
            material.transmission = self.unit_factor(ext, name, e, "transmissionFactor", 0.0)?;
            material.transmission_texture = self.json_texture(ext, e, "transmissionTexture")?;
        }
        if let Some(e) = ext.get("KHR_materials_volume") {
            let name = "KHR_materials_volume";
            let thickness = ext.number(self, name, e, "thicknessFactor", 0.0)?;
            let distance = ext.number(self, name, e, "attenuationDistance", f32::INFINITY)?;
            let color = ext.color(self, name, e, "attenuationColor", Vec3::ONE)?;
            if thickness < 0.0 || distance <= 0.0 {
                self.warn(
                    ext.element,
                    format!("{name}: thicknessFactor must be >= 0 and attenuationDistance > 0; the volume is ignored"),
                );
            } else if thickness > 0.0 {
                // σ = -ln(c) / d per world unit (Beer-Lambert), zero where c is 1 or d infinite.
                let color = color.clamp(Vec3::splat(1e-6), Vec3::ONE);
                let absorption = if distance.is_finite() {
                    -Vec3::new(color.x.ln(), color.y.ln(), color.z.ln()) / distance
                } else {
                    Vec3::ZERO
                };
                material.volume = Some(scene::Volume {
                    absorption: absorption.max(Vec3::ZERO),
                });
            }
        }
        if let Some(e) = ext.get("KHR_materials_specular") {
            let name = "KHR_materials_specular";
            let weight = ext.number(self, name, e, "specularFactor", 1.0)?;
            let color = ext.color(self, name, e, "specularColorFactor", Vec3::ONE)?;
            if weight < 0.0 || color.min_element() < 0.0 {
                self.warn(
                    ext.element,
                    format!("{name}: negative factors are taken as 0"),
                );
            }
            material.specular = scene::Specular {
                weight: weight.clamp(0.0, 1.0),
                weight_texture: self.json_texture(ext, e, "specularTexture")?,
                color: color.max(Vec3::ZERO),
                color_texture: self.json_texture(ext, e, "specularColorTexture")?,
            };
        }
        if let Some(e) = ext.get("KHR_materials_sheen") {
            let name = "KHR_materials_sheen";
            let color = ext.color(self, name, e, "sheenColorFactor", Vec3::ZERO)?;
            let color_texture = self.json_texture(ext, e, "sheenColorTexture")?;
            let roughness = self.unit_factor(ext, name, e, "sheenRoughnessFactor", 0.0)?;
            let roughness_texture = self.json_texture(ext, e, "sheenRoughnessTexture")?;
            // A black sheen colour disables the layer.
            if color.max_element() > 0.0 {
                material.sheen = Some(scene::Sheen {
                    color: color.clamp(Vec3::ZERO, Vec3::ONE),
                    color_texture,
                    roughness,
                    roughness_texture,
                });
            }
        }
        if let Some(e) = ext.get("KHR_materials_iridescence") {
            let name = "KHR_materials_iridescence";
            let factor = self.unit_factor(ext, name, e, "iridescenceFactor", 0.0)?;
            let ior = ext.number(self, name, e, "iridescenceIor", 1.3)?;
            let thickness_min = ext.number(self, name, e, "iridescenceThicknessMinimum", 100.0)?;
            let thickness_max = ext.number(self, name, e, "iridescenceThicknessMaximum", 400.0)?;
            if ior < 1.0 || thickness_min < 0.0 || thickness_max < 0.0 {
                self.warn(
                    ext.element,
                    format!("{name}: iridescenceIor must be >= 1 and thicknesses >= 0; clamped"),
                );
            }
            let texture = self.json_texture(ext, e, "iridescenceTexture")?;
            let thickness_texture = self.json_texture(ext, e, "iridescenceThicknessTexture")?;
            if factor > 0.0 {
                material.iridescence = Some(scene::Iridescence {
                    factor,
                    texture,
                    ior: ior.max(1.0),
                    thickness_min: thickness_min.max(0.0),
                    thickness_max: thickness_max.max(0.0),
                    thickness_texture,
                });
            }
        }
        if let Some(e) = ext.get("KHR_materials_anisotropy") {
            let name = "KHR_materials_anisotropy";
            let strength = self.unit_factor(ext, name, e, "anisotropyStrength", 0.0)?;
            let rotation = ext.number(self, name, e, "anisotropyRotation", 0.0)?;
            let texture = self.json_texture(ext, e, "anisotropyTexture")?;
            if strength > 0.0 {
                material.anisotropy = Some(scene::Anisotropy {
                    strength,
                    rotation,
                    texture,
                });
            }
        }
        material.unlit = ext.get("KHR_materials_unlit").is_some();
        Ok(())
    }

    /// A factor in [0, 1] of extension `name`'s JSON `e` (default `default`); a number
    /// outside the range is an error, as glTF-Validator classifies it (VALUE_NOT_IN_RANGE).
    fn unit_factor(
        &mut self,
        ext: &MaterialExtensions,
        name: &str,
        e: &serde_json::Value,
        key: &str,
        default: f32,
    ) -> Result<f32> {
        let x = ext.number(self, name, e, key, default)?;
        if !(0.0..=1.0).contains(&x) {
            return Err(self.err(ext.element, format!("{name}.{key} = {x} is outside [0, 1]")));
        }
        Ok(x)
    }

    /// The texture slot of a textureInfo in an extension's JSON (`e[key]`), if present.
    fn json_texture(
        &mut self,
        ext: &MaterialExtensions,
        e: &serde_json::Value,
        key: &str,
    ) -> Result<Option<TextureRef>> {
        let Some(info) = e.get(key) else {
            return Ok(None);
        };
        let element = format!("{}.{key}", ext.element);
        let index = info
            .get("index")
            .and_then(serde_json::Value::as_u64)
            .ok_or_else(|| self.err(&element, "textureInfo needs an integer \"index\""))?;
        let Some(texture) = usize::try_from(index)
            .ok()
            .and_then(|i| self.doc.textures().nth(i))
        else {
            return Err(self.err(&element, format!("texture {index} does not exist")));
        };
        let tex_coord = match info.get("texCoord") {
            None => 0,
            Some(v) => v
                .as_u64()
                .map(|x| x.min(u32::MAX as u64) as u32)
                .ok_or_else(|| self.err(&element, "texCoord is not an integer"))?,
        };
        let transform = info
            .get("extensions")
            .and_then(|x| x.get("KHR_texture_transform"))
            .map(transform_from_json);
        self.texture_ref(texture, tex_coord, transform).map(Some)
    }

    /// One warning for each unsupported extension, naming the materials that use it.
    fn warn_unsupported_extensions(&mut self) {
        let by_material = std::mem::take(&mut self.unsupported_material_extensions);
        for ext in self.doc.extensions_used() {
            if SUPPORTED_EXTENSIONS.contains(&ext) {
                continue;
            }
            let detail = match ext {
                "KHR_materials_dispersion" => {
                    ": refraction uses the material's ior at every wavelength"
                }
                "KHR_materials_pbrSpecularGlossiness" => {
                    ": the metallic-roughness parameters are rendered"
                }
                _ => "",
            };
            let users = match by_material.get(ext) {
                Some(names) => format!(" (materials: {})", names.join(", ")),
                None => String::new(),
            };
            self.warn(
                "extensionsUsed",
                format!("extension {ext} is not supported and is ignored{detail}{users}"),
            );
        }
    }

    /// The BSDF model from `extras.lucerna` (default: the glTF BRDF).
    fn bsdf_model(&self, m: &gltf::Material, element: &str) -> Result<BsdfModel> {
        let Some(raw) = m.extras() else {
            return Ok(BsdfModel::GltfPbr);
        };
        let e = format!("{element}.extras.lucerna");
        let value: serde_json::Value =
            serde_json::from_str(raw.get()).map_err(|err| self.err(&e, err.to_string()))?;
        let Some(section) = value.get("lucerna") else {
            return Ok(BsdfModel::GltfPbr);
        };
        let extras: LucernaExtras =
            serde_json::from_value(section.clone()).map_err(|err| self.err(&e, err.to_string()))?;
        match extras.bsdf.as_str() {
            "gltf" => Ok(BsdfModel::GltfPbr),
            "lambert" => Ok(BsdfModel::Lambert),
            "phong" => {
                let exponent = extras
                    .exponent
                    .ok_or_else(|| self.err(&e, "phong needs an \"exponent\""))?;
                if !(exponent.is_finite() && (0.0..=1e7).contains(&exponent)) {
                    return Err(self.err(&e, format!("exponent {exponent} must be in [0, 1e7]")));
                }
                let specular = match extras.specular {
                    None => Vec3::splat(0.04),
                    Some(SpecularValue::Grey(g)) => Vec3::splat(g),
                    Some(SpecularValue::Rgb(c)) => Vec3::from_array(c),
                };
                if !(specular.is_finite()
                    && specular.min_element() >= 0.0
                    && specular.max_element() <= 1.0)
                {
                    return Err(self.err(&e, "specular must be in [0, 1]"));
                }
                Ok(BsdfModel::Phong { exponent, specular })
            }
            other => Err(self.err(
                &e,
                format!("unknown bsdf {other:?} (expected gltf, lambert or phong)"),
            )),
        }
    }

    /// The texture slot of a material's texture info, if present.
    fn info_ref(&mut self, info: Option<gltf::texture::Info>) -> Result<Option<TextureRef>> {
        info.map(|t| {
            self.texture_ref(
                t.texture(),
                t.tex_coord(),
                t.texture_transform().map(TextureTransform::from),
            )
        })
        .transpose()
    }

    fn texture_ref(
        &mut self,
        texture: gltf::Texture,
        tex_coord: u32,
        transform: Option<TextureTransform>,
    ) -> Result<TextureRef> {
        let index = self.texture(&texture)?;
        let (tex_coord, transform) = match transform {
            Some(t) => {
                if !(t.offset.is_finite() && t.rotation.is_finite() && t.scale.is_finite()) {
                    return Err(self.err(
                        format!("textures[{}]", texture.index()),
                        "KHR_texture_transform is not finite",
                    ));
                }
                (
                    t.tex_coord.unwrap_or(tex_coord),
                    Some(UvTransform::new(t.offset, t.rotation, t.scale)),
                )
            }
            None => (tex_coord, None),
        };
        if tex_coord > 1 {
            self.warn(
                format!("textures[{}]", texture.index()),
                format!("TEXCOORD_{tex_coord} is not supported; set 0 is used"),
            );
        }
        Ok(TextureRef {
            texture: index,
            tex_coord: tex_coord.min(1),
            transform,
        })
    }

    fn texture(&mut self, texture: &gltf::Texture) -> Result<u32> {
        if let Some(&index) = self.textures.get(&texture.index()) {
            return Ok(index);
        }
        let image = self.texture_image(texture)?;
        let element = format!("images[{}]", image.index());
        let decoded = match self.images.get(&image.index()) {
            Some(d) => d.clone(),
            None => {
                let bytes: Vec<u8> = match image.source() {
                    gltf::image::Source::View { view, .. } => {
                        let data = self
                            .buffers
                            .get(view.buffer().index())
                            .map(Vec::as_slice)
                            .unwrap_or(&[]);
                        let end = view.offset().checked_add(view.length());
                        match end.and_then(|end| data.get(view.offset()..end)) {
                            Some(slice) => slice.to_vec(),
                            None => {
                                return Err(self
                                    .err(&element, "bufferView runs past the end of its buffer"));
                            }
                        }
                    }
                    gltf::image::Source::Uri { uri: u, .. } => uri::read(u, self.base)
                        .map_err(|r| self.err(format!("{element}.uri"), r))?,
                };
                let d = img::decode(&bytes).map_err(|r| self.err(&element, r))?;
                let decoded = (d.width, d.height, Arc::new(d.texels));
                self.images.insert(image.index(), decoded.clone());
                decoded
            }
        };
        let sampler = texture.sampler();
        let wrap = |w: gltf::texture::WrappingMode| match w {
            gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
            gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
            gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
        };
        self.scene.textures.push(scene::Texture {
            name: image.name().map_or(element, str::to_string),
            width: decoded.0,
            height: decoded.1,
            texels: decoded.2,
            wrap_u: wrap(sampler.wrap_s()),
            wrap_v: wrap(sampler.wrap_t()),
            nearest: sampler.mag_filter() == Some(gltf::texture::MagFilter::Nearest),
        });
        let index = (self.scene.textures.len() - 1) as u32;
        self.textures.insert(texture.index(), index);
        Ok(index)
    }

    /// The image a texture shows: its EXT_texture_webp image where it has one, else its
    /// core `source` (a KHR_texture_basisu texture's PNG/JPEG fallback; KTX2 itself cannot be
    /// transcoded).
    fn texture_image(&mut self, texture: &gltf::Texture) -> Result<gltf::Image<'a>> {
        let element = format!("textures[{}]", texture.index());
        let extension_source = |name: &str| {
            texture
                .extensions()
                .and_then(|e| e.get(name))
                .and_then(|e| e.get("source"))
                .and_then(serde_json::Value::as_u64)
        };
        if let Some(i) = extension_source("EXT_texture_webp") {
            return self.doc.images().nth(i as usize).ok_or_else(|| {
                self.err(
                    format!("{element}.extensions.EXT_texture_webp.source"),
                    format!("image {i} does not exist"),
                )
            });
        }
        let basisu = extension_source("KHR_texture_basisu").is_some();
        match texture.source().and_then(|i| self.doc.images().nth(i.index())) {
            Some(image) => {
                if basisu {
                    self.warn(
                        &element,
                        "KHR_texture_basisu: KTX2 textures cannot be transcoded; the fallback image is used",
                    );
                }
                Ok(image)
            }
            None if basisu => Err(self.err(
                &element,
                "KHR_texture_basisu: the texture is KTX2 (Basis Universal) only, which lucerna cannot transcode; export PNG, JPEG or WebP textures (e.g. gltf-transform png/webp)",
            )),
            None => Err(self.err(&element, "has no image (no source)")),
        }
    }

    fn camera(&self, camera: &gltf::Camera, world: DMat4, node_name: &str) -> Result<Camera> {
        let element = format!("cameras[{}]", camera.index());
        let (projection, znear, zfar) = match camera.projection() {
            gltf::camera::Projection::Perspective(p) => {
                let yfov = p.yfov();
                if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
                    return Err(self.err(&element, format!("yfov {yfov} must be in (0, π)")));
                }
                if let Some(a) = p.aspect_ratio().filter(|a| !(a.is_finite() && *a > 0.0)) {
                    return Err(self.err(&element, format!("aspectRatio {a} must be positive")));
                }
                if !(p.znear() > 0.0 && p.znear().is_finite()) {
                    return Err(self.err(&element, format!("znear {} must be positive", p.znear())));
                }
                if let Some(f) = p.zfar().filter(|f| !(*f > p.znear())) {
                    return Err(self.err(
                        &element,
                        format!("zfar {f} must be greater than znear {}", p.znear()),
                    ));
                }
                let aspect = p.aspect_ratio();
                (
                    Projection::Perspective { yfov, aspect },
                    p.znear(),
                    p.zfar(),
                )
            }
            gltf::camera::Projection::Orthographic(o) => {
                let (xmag, ymag) = (o.xmag().abs(), o.ymag().abs());
                if !(xmag > 0.0 && ymag > 0.0 && xmag.is_finite() && ymag.is_finite()) {
                    return Err(self.err(&element, "xmag and ymag must be non-zero and finite"));
                }
                if !(o.znear() >= 0.0 && o.zfar() > o.znear()) {
                    return Err(self.err(
                        &element,
                        format!(
                            "znear {} must not be negative and zfar {} must be greater",
                            o.znear(),
                            o.zfar()
                        ),
                    ));
                }
                (
                    Projection::Orthographic { xmag, ymag },
                    o.znear(),
                    Some(o.zfar()),
                )
            }
        };
        let name = camera
            .name()
            .map_or_else(|| node_name.to_string(), str::to_string);
        Ok(Camera {
            name,
            projection,
            transform: world,
            aperture_radius: 0.0,
            focus_distance: 1.0,
            clip_near: znear.max(0.0) as f64,
            clip_far: zfar.filter(|f| f.is_finite() && *f > znear).map(f64::from),
            fit: Default::default(),
        })
    }

    fn light(
        &mut self,
        light: &gltf::khr_lights_punctual::Light,
        world: DMat4,
        node_name: &str,
    ) -> Result<()> {
        let element = format!("KHR_lights_punctual.lights[{}]", light.index());
        let radiant = Vec3::from_array(light.color()) * light.intensity();
        if !radiant.is_finite() || radiant.min_element() < 0.0 {
            self.warn(
                &element,
                "colour × intensity is negative or not finite; light skipped",
            );
            return Ok(());
        }
        let position = world.transform_point3(DVec3::ZERO);
        let direction = world.transform_vector3(-DVec3::Z).normalize_or_zero();
        if direction == DVec3::ZERO {
            self.warn(&element, "node transform is degenerate; light skipped");
            return Ok(());
        }
        let kind = match light.kind() {
            gltf::khr_lights_punctual::Kind::Point => LightKind::Point {
                position,
                intensity: radiant,
            },
            gltf::khr_lights_punctual::Kind::Directional => LightKind::Directional {
                direction,
                irradiance: radiant,
                angle: 0.0,
            },
            gltf::khr_lights_punctual::Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                // The extension's rule: 0 <= inner < outer <= π/2 (glTF-Validator: an error).
                if !(inner_cone_angle >= 0.0
                    && inner_cone_angle < outer_cone_angle
                    && outer_cone_angle <= std::f32::consts::FRAC_PI_2)
                {
                    return Err(self.err(
                        &element,
                        format!(
                            "spot.innerConeAngle {inner_cone_angle} and outerConeAngle {outer_cone_angle} must satisfy 0 <= inner < outer <= π/2"
                        ),
                    ));
                }
                LightKind::Spot {
                    position,
                    direction,
                    intensity: radiant,
                    inner_cone: inner_cone_angle,
                    outer_cone: outer_cone_angle,
                }
            }
        };
        self.scene.lights.push(Light {
            name: light
                .name()
                .map_or_else(|| node_name.to_string(), str::to_string),
            kind,
        });
        Ok(())
    }
}

/// Collects attribute values, replacing those that fail `ok` by `fallback` and counting them.
fn finite_or<T>(
    values: impl Iterator<Item = T>,
    ok: impl Fn(&T) -> bool,
    fallback: T,
    repaired: &mut usize,
) -> Vec<T>
where
    T: Copy,
{
    values
        .map(|v| {
            if ok(&v) {
                v
            } else {
                *repaired += 1;
                fallback
            }
        })
        .collect()
}

/// A material's `extensions` object, for reading the extensions that the `gltf` crate does
/// not type.
struct MaterialExtensions<'j> {
    /// The material's element, for messages.
    element: &'j str,
    json: std::collections::BTreeMap<&'j str, &'j serde_json::Value>,
}

impl MaterialExtensions<'_> {
    fn get(&self, name: &str) -> Option<&serde_json::Value> {
        self.json.get(name).copied()
    }

    /// `e[key]` of extension `name` as a finite number (`default` when absent).
    fn number(
        &self,
        importer: &Importer,
        name: &str,
        e: &serde_json::Value,
        key: &str,
        default: f32,
    ) -> Result<f32> {
        match e.get(key) {
            None => Ok(default),
            Some(v) => v
                .as_f64()
                .map(|x| x as f32)
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    importer.err(self.element, format!("{name}.{key} is not a finite number"))
                }),
        }
    }

    /// `e[key]` of extension `name` as an RGB triple of finite numbers.
    fn color(
        &self,
        importer: &Importer,
        name: &str,
        e: &serde_json::Value,
        key: &str,
        default: Vec3,
    ) -> Result<Vec3> {
        let Some(v) = e.get(key) else {
            return Ok(default);
        };
        let values: Option<Vec<f32>> = v.as_array().and_then(|a| {
            (a.len() == 3)
                .then(|| a.iter().map(|x| x.as_f64().map(|x| x as f32)).collect())
                .flatten()
        });
        match values {
            Some(c) if c.iter().all(|x| x.is_finite()) => Ok(Vec3::new(c[0], c[1], c[2])),
            _ => Err(importer.err(
                self.element,
                format!("{name}.{key} is not three finite numbers"),
            )),
        }
    }
}

/// A KHR_texture_transform's values.
struct TextureTransform {
    offset: Vec2,
    rotation: f32,
    scale: Vec2,
    tex_coord: Option<u32>,
}

impl From<gltf::texture::TextureTransform<'_>> for TextureTransform {
    fn from(t: gltf::texture::TextureTransform) -> Self {
        Self {
            offset: Vec2::from_array(t.offset()),
            rotation: t.rotation(),
            scale: Vec2::from_array(t.scale()),
            tex_coord: t.tex_coord(),
        }
    }
}

/// Reads a KHR_texture_transform from raw JSON (normal textures do not expose it typed).
fn transform_from_json(v: &serde_json::Value) -> TextureTransform {
    let pair = |key: &str, default: f32| {
        let get = |i: usize| {
            v.get(key)
                .and_then(|a| a.get(i))
                .and_then(|x| x.as_f64())
                .map_or(default, |x| x as f32)
        };
        Vec2::new(get(0), get(1))
    };
    TextureTransform {
        offset: pair("offset", 0.0),
        rotation: v
            .get("rotation")
            .and_then(|x| x.as_f64())
            .map_or(0.0, |x| x as f32),
        scale: pair("scale", 1.0),
        tex_coord: v
            .get("texCoord")
            .and_then(|x| x.as_u64())
            .map(|x| x.min(u32::MAX as u64) as u32),
    }
}

/// Triangles of a primitive in counter-clockwise order, degenerate ones (repeated
/// indices) dropped. Strips and fans follow the glTF specification (§3.7.2.1).
fn assemble_triangles(mode: Mode, indices: &[u32]) -> Vec<[u32; 3]> {
    let tris: Vec<[u32; 3]> = match mode {
        Mode::Triangles => indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
        Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
            .map(|i| {
                if i % 2 == 0 {
                    [indices[i], indices[i + 1], indices[i + 2]]
                } else {
                    [indices[i], indices[i + 2], indices[i + 1]]
                }
            })
            .collect(),
        Mode::TriangleFan => (1..indices.len().saturating_sub(1))
            .map(|i| [indices[i], indices[i + 1], indices[0]])
            .collect(),
        _ => Vec::new(),
    };
    tris.into_iter()
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_follow_the_specification() {
        assert_eq!(
            assemble_triangles(Mode::TriangleStrip, &[0, 1, 2, 3, 4]),
            vec![[0, 1, 2], [1, 3, 2], [2, 3, 4]]
        );
        assert_eq!(
            assemble_triangles(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![[1, 2, 0], [2, 3, 0]]
        );
        assert_eq!(
            assemble_triangles(Mode::Triangles, &[0, 1, 2, 3, 3, 4, 5]),
            vec![[0, 1, 2]]
        );
    }
}
