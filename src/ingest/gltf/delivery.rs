//! glTF as web pipelines deliver it, decoded into the plain form the importer reads:
//!
//! - `EXT_meshopt_compression` buffer views (gltfpack's output) are decoded with
//!   meshoptimizer's own decoder (the `meshopt` crate) into the buffer they describe, with
//!   the octahedral, quaternion, exponential and colour filters;
//! - `KHR_draco_mesh_compression` primitives are decoded with the pure-Rust `draco-core`
//!   decoder; their accessors are repointed at the decoded data;
//! - `KHR_mesh_quantization`'s integer positions, normals, tangents and texture coordinates
//!   (and any other non-float vertex attribute lucerna reads as floats) become floats, with
//!   the normalisation rules of glTF 2.0 section 3.11. Quantized assets put the
//!   dequantisation scale and offset in the node transform, which the importer applies.
//!
//! Decoding happens once, before the importer walks the document: the decoded bytes go to
//! one appended buffer and the JSON is rewritten to point at them, so everything after this
//! (bounds checks, readers, tangent generation) sees ordinary float accessors.

use crate::error::{Error, Result};
use gltf::json::{self, validation::Checked};
use serde_json::{Value, json};

/// The name under which a buffer view or primitive carries an extension's JSON.
fn extension<'a>(
    others: Option<&'a serde_json::Map<String, Value>>,
    name: &str,
) -> Option<&'a Value> {
    others.and_then(|o| o.get(name))
}

/// Whether buffer `buffer` is a meshopt fallback buffer: no data of its own (no URI), to be
/// filled by decoding the compressed views that point into it.
pub fn is_meshopt_fallback(buffer: &json::Buffer) -> bool {
    buffer.uri.is_none()
        && ["EXT_meshopt_compression", "KHR_meshopt_compression"]
            .iter()
            .any(|name| {
                extension(buffer.extensions.as_ref().map(|e| &e.others), name)
                    .and_then(|e| e.get("fallback"))
                    .and_then(Value::as_bool)
                    .unwrap_or(false)
            })
}

/// Decodes every compressed or quantized part of `document` (whose buffers are `buffers`)
/// and returns the document to import; unchanged when there is nothing to decode.
pub fn decode(
    document: gltf::Document,
    buffers: &mut Vec<Vec<u8>>,
    source: &str,
) -> Result<gltf::Document> {
    decode_meshopt(document.as_json(), buffers, source)?;
    let mut root = document.into_json();
    let mut out = Appended::new(buffers.len());
    let draco = decode_draco(&mut root, buffers, &mut out, source)?;
    let quantized = dequantize(&mut root, buffers, &mut out, source)?;
    // The document was validated when parsed; the rewrite only adds buffer views and
    // repoints accessors at them (and drops their now meaningless bounds).
    if !draco && !quantized {
        return Ok(gltf::Document::from_json_without_validation(root));
    }
    root.buffers.push(
        serde_json::from_value(json!({ "byteLength": out.bytes.len().max(4) }))
            .expect("a buffer's JSON"),
    );
    let mut bytes = out.bytes;
    bytes.resize(bytes.len().max(4), 0);
    buffers.push(bytes);
    Ok(gltf::Document::from_json_without_validation(root))
}

/// Decoded data appended as one new buffer (index `buffer`), a view for each array.
struct Appended {
    buffer: usize,
    bytes: Vec<u8>,
}

impl Appended {
    fn new(buffer: usize) -> Self {
        Self {
            buffer,
            bytes: Vec::new(),
        }
    }

    /// Appends `data` (4-byte aligned) as a new buffer view of `root`; returns its index.
    fn view(&mut self, root: &mut json::Root, data: &[u8]) -> u32 {
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        let view = json!({
            "buffer": self.buffer,
            "byteOffset": self.bytes.len(),
            "byteLength": data.len().max(1),
        });
        self.bytes.extend_from_slice(data);
        if data.is_empty() {
            self.bytes.push(0);
        }
        root.buffer_views
            .push(serde_json::from_value(view).expect("a buffer view's JSON"));
        (root.buffer_views.len() - 1) as u32
    }

    /// Points accessor `a` at `data`, tightly packed floats of its type.
    fn float_accessor(&mut self, root: &mut json::Root, a: usize, data: &[f32], count: usize) {
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(root, &bytes);
        let accessor = &mut root.accessors[a];
        accessor.buffer_view = Some(json::Index::new(view));
        accessor.byte_offset = None;
        accessor.count = count.into();
        accessor.component_type = Checked::Valid(json::accessor::GenericComponentType(
            json::accessor::ComponentType::F32,
        ));
        accessor.normalized = false;
        accessor.sparse = None;
        accessor.min = None;
        accessor.max = None;
    }
}

// ---- EXT_meshopt_compression --------------------------------------------------------------

fn decode_meshopt(root: &json::Root, buffers: &mut [Vec<u8>], source: &str) -> Result<()> {
    for (v, view) in root.buffer_views.iter().enumerate() {
        let others = view.extensions.as_ref().map(|e| &e.others);
        let Some(ext) = extension(others, "EXT_meshopt_compression")
            .or_else(|| extension(others, "KHR_meshopt_compression"))
        else {
            continue;
        };
        let element = format!("bufferViews[{v}].extensions.EXT_meshopt_compression");
        let err = |reason: String| Error::bad_input(source, &element, reason);
        let field = |name: &str| ext.get(name).and_then(Value::as_u64).map(|n| n as usize);
        let (Some(buffer), Some(length), Some(stride), Some(count)) = (
            field("buffer"),
            field("byteLength"),
            field("byteStride"),
            field("count"),
        ) else {
            return Err(err("needs buffer, byteLength, byteStride and count".into()));
        };
        let offset = field("byteOffset").unwrap_or(0);
        let mode = ext.get("mode").and_then(Value::as_str).unwrap_or("");
        let filter = ext.get("filter").and_then(Value::as_str).unwrap_or("NONE");
        let compressed = buffers
            .get(buffer)
            .and_then(|b| b.get(offset..offset.checked_add(length)?))
            .ok_or_else(|| {
                err(format!(
                    "bytes {offset}..+{length} are outside buffer {buffer}"
                ))
            })?
            .to_vec();
        let size = count
            .checked_mul(stride)
            .filter(|&s| s as u64 <= view.byte_length.0)
            .ok_or_else(|| {
                err(format!(
                    "count {count} x byteStride {stride} exceeds the view's byteLength {}",
                    view.byte_length.0
                ))
            })?;
        crate::memory::check_allocation(size as u64, &element).map_err(err)?;
        let mut out = vec![0u8; size];
        let dst = out.as_mut_ptr().cast();
        let (src, n) = (compressed.as_ptr(), compressed.len());
        // SAFETY: `out` holds count × stride bytes, the size each decoder writes; the
        // decoders read at most `n` bytes of `src` and report malformed input by a non-zero
        // result; the filters rewrite count × stride bytes in place.
        let status = unsafe {
            use meshopt::ffi::*;
            match (mode, stride) {
                ("ATTRIBUTES", s) if s % 4 == 0 && s <= 256 => {
                    let status = meshopt_decodeVertexBuffer(dst, count, s, src, n);
                    if status == 0 {
                        match (filter, s) {
                            ("NONE", _) => {}
                            ("OCTAHEDRAL", 4 | 8) => meshopt_decodeFilterOct(dst, count, s),
                            ("QUATERNION", 8) => meshopt_decodeFilterQuat(dst, count, s),
                            ("EXPONENTIAL", _) => meshopt_decodeFilterExp(dst, count, s),
                            ("COLOR", 4 | 8) => meshopt_decodeFilterColor(dst, count, s),
                            _ => {
                                return Err(err(format!(
                                    "filter {filter} with byteStride {s} is not defined"
                                )));
                            }
                        }
                    }
                    status
                }
                ("TRIANGLES", 2 | 4) if count % 3 == 0 => {
                    meshopt_decodeIndexBuffer(dst, count, stride, src, n)
                }
                ("INDICES", 2 | 4) => meshopt_decodeIndexSequence(dst, count, stride, src, n),
                _ => {
                    return Err(err(format!(
                        "mode {mode:?} with byteStride {stride} and count {count} is not defined"
                    )));
                }
            }
        };
        if status != 0 {
            return Err(err(format!(
                "the compressed data is malformed (meshoptimizer error {status})"
            )));
        }
        let target = view.buffer.value();
        let start = view.byte_offset.map_or(0, |o| o.0 as usize);
        let slot = buffers
            .get_mut(target)
            .and_then(|b| b.get_mut(start..start + size))
            .ok_or_else(|| {
                Error::bad_input(
                    source,
                    format!("bufferViews[{v}]"),
                    format!("runs past the end of buffer {target}"),
                )
            })?;
        slot.copy_from_slice(&out);
    }
    Ok(())
}

// ---- KHR_draco_mesh_compression ----------------------------------------------------------

/// Decodes the Draco primitives; returns whether there were any.
fn decode_draco(
    root: &mut json::Root,
    buffers: &[Vec<u8>],
    out: &mut Appended,
    source: &str,
) -> Result<bool> {
    let mut any = false;
    for m in 0..root.meshes.len() {
        for p in 0..root.meshes[m].primitives.len() {
            let primitive = &root.meshes[m].primitives[p];
            let others = primitive.extensions.as_ref().map(|e| &e.others);
            let Some(ext) = extension(others, "KHR_draco_mesh_compression").cloned() else {
                continue;
            };
            any = true;
            let element =
                format!("meshes[{m}].primitives[{p}].extensions.KHR_draco_mesh_compression");
            let err = |reason: String| Error::bad_input(source, &element, reason);
            let view = ext
                .get("bufferView")
                .and_then(Value::as_u64)
                .and_then(|v| root.buffer_views.get(v as usize))
                .ok_or_else(|| err("bufferView is missing or does not exist".into()))?;
            let start = view.byte_offset.map_or(0, |o| o.0 as usize);
            let bytes = buffers
                .get(view.buffer.value())
                .and_then(|b| b.get(start..start.checked_add(view.byte_length.0 as usize)?))
                .ok_or_else(|| err("its bufferView runs past the end of its buffer".into()))?;
            // The decoder reads untrusted bytes: a panic in it is a malformed file too.
            let decoded = std::panic::catch_unwind(|| {
                let mut mesh = draco_core::Mesh::new();
                let mut decoder = draco_core::MeshDecoder::new();
                decoder
                    .decode(&mut draco_core::DecoderBuffer::new(bytes), &mut mesh)
                    .map(|_| mesh)
                    .map_err(|e| format!("{e:?}"))
            });
            let mesh = match decoded {
                Ok(Ok(mesh)) => mesh,
                Ok(Err(e)) => return Err(err(format!("the Draco data cannot be decoded: {e}"))),
                Err(_) => return Err(err("the Draco data cannot be decoded (malformed)".into())),
            };
            let points = mesh.num_points();
            let attributes: Vec<(Checked<json::mesh::Semantic>, usize)> = primitive
                .attributes
                .iter()
                .map(|(s, a)| (s.clone(), a.value()))
                .collect();
            let ids = ext.get("attributes").and_then(Value::as_object);
            for (semantic, accessor) in attributes {
                let Checked::Valid(semantic) = semantic else {
                    continue;
                };
                let name = semantic.to_string();
                let Some(id) = ids.and_then(|ids| ids.get(&name)).and_then(Value::as_u64) else {
                    continue; // Stored uncompressed beside the Draco data.
                };
                let attribute = mesh.attribute_by_unique_id(id as u32).ok_or_else(|| {
                    err(format!(
                        "attribute {name} (id {id}) is not in the Draco data"
                    ))
                })?;
                let acc = &root.accessors[accessor];
                let components = match acc.type_ {
                    Checked::Valid(t) => t.multiplicity(),
                    Checked::Invalid => return Err(err(format!("{name}'s accessor type"))),
                };
                let values = attribute.read_f32s(points, components);
                let kind = match acc.component_type {
                    Checked::Valid(json::accessor::GenericComponentType(k)) => k,
                    Checked::Invalid => return Err(err(format!("{name}'s component type"))),
                };
                let bytes = encode_components(&values, kind);
                let view = out.view(root, &bytes);
                let acc = &mut root.accessors[accessor];
                acc.buffer_view = Some(json::Index::new(view));
                acc.byte_offset = None;
                acc.count = points.into();
                acc.sparse = None;
            }
            if let Some(indices) = root.meshes[m].primitives[p].indices.map(|i| i.value()) {
                let faces = mesh.num_faces();
                let mut data = Vec::with_capacity(faces * 12);
                for f in 0..faces {
                    for point in mesh.face(draco_core::FaceIndex(f as u32)) {
                        data.extend_from_slice(&point.0.to_le_bytes());
                    }
                }
                let view = out.view(root, &data);
                let acc = &mut root.accessors[indices];
                acc.buffer_view = Some(json::Index::new(view));
                acc.byte_offset = None;
                acc.count = (faces * 3).into();
                acc.component_type = Checked::Valid(json::accessor::GenericComponentType(
                    json::accessor::ComponentType::U32,
                ));
                acc.sparse = None;
            }
        }
    }
    Ok(any)
}

/// Values as little-endian components of `kind` (integers rounded, as Draco stores them).
fn encode_components(values: &[f32], kind: json::accessor::ComponentType) -> Vec<u8> {
    use json::accessor::ComponentType as C;
    let mut bytes = Vec::with_capacity(values.len() * 4);
    for &v in values {
        let r = v.round();
        match kind {
            C::F32 => bytes.extend_from_slice(&v.to_le_bytes()),
            C::I8 => bytes.push(r as i8 as u8),
            C::U8 => bytes.push(r as u8),
            C::I16 => bytes.extend_from_slice(&(r as i16).to_le_bytes()),
            C::U16 => bytes.extend_from_slice(&(r as u16).to_le_bytes()),
            C::U32 => bytes.extend_from_slice(&(r as u32).to_le_bytes()),
        }
    }
    bytes
}

// ---- KHR_mesh_quantization ------------------------------------------------------------------

/// Rewrites integer vertex attributes read as floats (positions, normals, tangents, texture
/// coordinates, in primitives and morph targets) as float accessors; returns whether any
/// were rewritten. Each attribute's component type must be one glTF allows for it: floats,
/// and for texture coordinates normalized unsigned bytes and shorts; with
/// `KHR_mesh_quantization` also the integer types that extension lists (never 32-bit
/// integers). Anything else is refused, naming the attribute.
fn dequantize(
    root: &mut json::Root,
    buffers: &[Vec<u8>],
    out: &mut Appended,
    source: &str,
) -> Result<bool> {
    use json::accessor::ComponentType as C;
    use json::mesh::Semantic as S;
    let quantization = root
        .extensions_used
        .iter()
        .any(|e| e == "KHR_mesh_quantization");
    // (accessor, the attribute's name in messages, what it is)
    let mut uses: Vec<(usize, String, &'static str)> = Vec::new();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let at = format!("meshes[{m}].primitives[{p}]");
            for (semantic, accessor) in &primitive.attributes {
                let kind = match semantic {
                    Checked::Valid(S::Positions) => "POSITION",
                    Checked::Valid(S::Normals) => "NORMAL",
                    Checked::Valid(S::Tangents) => "TANGENT",
                    Checked::Valid(S::TexCoords(_)) => "TEXCOORD",
                    _ => continue,
                };
                let name = match semantic {
                    Checked::Valid(s) => s.to_string(),
                    _ => kind.to_string(),
                };
                uses.push((accessor.value(), format!("{at}.attributes.{name}"), kind));
            }
            for (t, target) in primitive.targets.iter().flatten().enumerate() {
                for (accessor, kind) in [
                    (&target.positions, "POSITION"),
                    (&target.normals, "NORMAL"),
                    (&target.tangents, "TANGENT"),
                ] {
                    if let Some(accessor) = accessor {
                        uses.push((accessor.value(), format!("{at}.targets[{t}].{kind}"), kind));
                    }
                }
            }
        }
    }
    let mut rewrite = std::collections::BTreeSet::new();
    for (a, element, kind) in &uses {
        let Some(acc) = root.accessors.get(*a) else {
            continue; // Reported by the importer's checks.
        };
        let Checked::Valid(json::accessor::GenericComponentType(component)) = acc.component_type
        else {
            continue;
        };
        let normalized = acc.normalized;
        let allowed = match (component, *kind) {
            (C::F32, _) => true,
            (C::U8 | C::U16, "TEXCOORD") if normalized => true,
            (C::U32, _) => false,
            _ if !quantization => false,
            (_, "POSITION" | "TEXCOORD") => true,
            (C::I8 | C::I16, "NORMAL" | "TANGENT") => normalized,
            _ => false,
        };
        if !allowed {
            let name = match component {
                C::I8 => "BYTE",
                C::U8 => "UNSIGNED_BYTE",
                C::I16 => "SHORT",
                C::U16 => "UNSIGNED_SHORT",
                C::U32 => "UNSIGNED_INT",
                C::F32 => "FLOAT",
            };
            let normalized = if normalized { "normalized " } else { "" };
            let rule = if quantization {
                "KHR_mesh_quantization allows bytes and shorts"
            } else {
                "glTF allows FLOAT (integers need KHR_mesh_quantization)"
            };
            return Err(Error::bad_input(
                source,
                element.as_str(),
                format!("{kind} of {normalized}{name} components is not allowed ({rule})"),
            ));
        }
        if component != C::F32 {
            rewrite.insert(*a);
        }
    }
    let mut any = false;
    for a in rewrite {
        let Some(acc) = root.accessors.get(a) else {
            continue;
        };
        let values = read_floats(root, buffers, a)
            .map_err(|r| Error::bad_input(source, format!("accessors[{a}]"), r))?;
        let count = acc.count.0 as usize;
        out.float_accessor(root, a, &values, count);
        any = true;
    }
    Ok(any)
}

/// Accessor `a`'s elements as floats (components flattened), whatever its component type:
/// normalized integers map to [0, 1] or [-1, 1] (glTF 2.0 section 3.11), others convert
/// as they are; sparse substitutions applied. Every range is checked.
pub fn read_floats(
    root: &json::Root,
    buffers: &[Vec<u8>],
    a: usize,
) -> std::result::Result<Vec<f32>, String> {
    use json::accessor::ComponentType as C;
    let acc = root.accessors.get(a).ok_or("the accessor does not exist")?;
    let (Checked::Valid(json::accessor::GenericComponentType(kind)), Checked::Valid(ty)) =
        (acc.component_type, acc.type_)
    else {
        return Err("invalid component type or type".into());
    };
    let components = ty.multiplicity();
    let size = kind.size();
    let count = acc.count.0 as usize;
    let normalized = acc.normalized;
    let convert = move |b: &[u8]| -> f32 {
        match (kind, normalized) {
            (C::F32, _) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            (C::I8, true) => (b[0] as i8 as f32 / 127.0).max(-1.0),
            (C::I8, false) => b[0] as i8 as f32,
            (C::U8, true) => b[0] as f32 / 255.0,
            (C::U8, false) => b[0] as f32,
            (C::I16, n) => {
                let v = i16::from_le_bytes([b[0], b[1]]) as f32;
                if n { (v / 32767.0).max(-1.0) } else { v }
            }
            (C::U16, n) => {
                let v = u16::from_le_bytes([b[0], b[1]]) as f32;
                if n { v / 65535.0 } else { v }
            }
            (C::U32, _) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
        }
    };
    crate::memory::check_allocation(
        (count as u64).saturating_mul(components as u64 * 4),
        &format!("accessors[{a}]"),
    )?;
    let view_bytes =
        |view: usize, offset: usize| -> std::result::Result<(&[u8], Option<usize>), String> {
            let v = root
                .buffer_views
                .get(view)
                .ok_or(format!("bufferViews[{view}] does not exist"))?;
            let start = v.byte_offset.map_or(0, |o| o.0 as usize);
            let bytes = buffers
                .get(v.buffer.value())
                .and_then(|b| b.get(start..start.checked_add(v.byte_length.0 as usize)?))
                .ok_or(format!(
                    "bufferViews[{view}] runs past the end of its buffer"
                ))?;
            let bytes = bytes
                .get(offset..)
                .ok_or(format!("byteOffset {offset} is past bufferViews[{view}]"))?;
            Ok((bytes, v.byte_stride.map(|s| s.0)))
        };
    let element = components * size;
    let mut values = vec![0.0f32; count * components];
    let read_elements = |bytes: &[u8], stride: usize, n: usize, out: &mut [f32]| {
        if n == 0 {
            return Ok(());
        }
        if stride < element || (n - 1) * stride + element > bytes.len() {
            return Err("the accessor's data runs past the end of its bufferView".to_string());
        }
        for i in 0..n {
            for c in 0..components {
                let at = i * stride + c * size;
                out[i * components + c] = convert(&bytes[at..at + size]);
            }
        }
        Ok(())
    };
    if let Some(view) = acc.buffer_view {
        let (bytes, stride) =
            view_bytes(view.value(), acc.byte_offset.map_or(0, |o| o.0 as usize))?;
        read_elements(bytes, stride.unwrap_or(element), count, &mut values)?;
    }
    if let Some(sparse) = &acc.sparse {
        let n = sparse.count.0 as usize;
        let (index_bytes, _) = view_bytes(
            sparse.indices.buffer_view.value(),
            sparse.indices.byte_offset.0 as usize,
        )?;
        let index_size = match sparse.indices.component_type {
            Checked::Valid(json::accessor::IndexComponentType(k)) => k.size(),
            Checked::Invalid => return Err("invalid sparse index type".into()),
        };
        let mut substituted = vec![0.0f32; n * components];
        let (value_bytes, _) = view_bytes(
            sparse.values.buffer_view.value(),
            sparse.values.byte_offset.0 as usize,
        )?;
        read_elements(value_bytes, element, n, &mut substituted)?;
        if n * index_size > index_bytes.len() {
            return Err("sparse indices run past the end of their bufferView".into());
        }
        for k in 0..n {
            let b = &index_bytes[k * index_size..];
            let index = match index_size {
                1 => b[0] as usize,
                2 => u16::from_le_bytes([b[0], b[1]]) as usize,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
            };
            if index >= count {
                return Err(format!(
                    "sparse index {index} is past the accessor's {count} elements"
                ));
            }
            values[index * components..(index + 1) * components]
                .copy_from_slice(&substituted[k * components..(k + 1) * components]);
        }
    }
    Ok(values)
}
