//! Parsing a glTF or GLB file: the JSON (with the version checked first, so that a glTF 1.0
//! file gets a clear message), and the buffers it references: the GLB binary chunk, data
//! URIs and files beside it (resolved safely, never from the network).

use super::super::uri;
use crate::error::{Error, Result};
use std::path::Path;

/// Extensions lucerna implements; a required extension outside this list is an error, a
/// used one a warning.
pub(super) const SUPPORTED_EXTENSIONS: &[&str] = &[
    "EXT_mesh_gpu_instancing",
    "EXT_meshopt_compression",
    "EXT_texture_webp",
    "KHR_draco_mesh_compression",
    "KHR_lights_punctual",
    "KHR_materials_anisotropy",
    "KHR_materials_clearcoat",
    "KHR_materials_diffuse_transmission",
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
    "KHR_texture_basisu",
    "KHR_texture_transform",
];

/// Reads the document's buffers: the GLB binary chunk, data URIs and files beside it. A
/// meshopt fallback buffer has no data of its own; it is allocated for the decoder to fill.
pub(super) fn load_buffers(
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
        let data = if super::delivery::is_meshopt_fallback(json) {
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
pub(super) fn parse(bytes: &[u8], source: &str) -> Result<gltf::Gltf> {
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
