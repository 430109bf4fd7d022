//! Builds small glTF files for tests: JSON plus one binary buffer, written as a `.gltf`
//! with an embedded data URI, a `.gltf` with an external `.bin`, or a `.glb`.

use base64::Engine;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

/// A glTF document under construction.
pub struct Builder {
    pub json: Value,
    pub bin: Vec<u8>,
}

impl Default for Builder {
    fn default() -> Self {
        Self::new()
    }
}

fn push(json: &mut Value, key: &str, item: Value) -> usize {
    let list = json
        .as_object_mut()
        .unwrap()
        .entry(key)
        .or_insert_with(|| json!([]))
        .as_array_mut()
        .unwrap();
    list.push(item);
    list.len() - 1
}

impl Builder {
    /// An empty document with one scene.
    pub fn new() -> Self {
        Self {
            json: json!({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": []}]}),
            bin: Vec::new(),
        }
    }

    /// Appends bytes to the buffer (4-byte aligned) and returns a new buffer view.
    pub fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        push(
            &mut self.json,
            "bufferViews",
            json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()}),
        )
    }

    /// A float accessor of `kind` (SCALAR, VEC2, VEC3, VEC4) over `values`.
    pub fn floats(&mut self, kind: &str, values: &[f32]) -> usize {
        let width = match kind {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            _ => 4,
        };
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes);
        let mut acc = json!({"bufferView": view, "componentType": 5126, "count": values.len() / width, "type": kind});
        if kind == "VEC3" {
            let lo: Vec<f32> = (0..3)
                .map(|k| {
                    values
                        .iter()
                        .skip(k)
                        .step_by(3)
                        .cloned()
                        .fold(f32::INFINITY, f32::min)
                })
                .collect();
            let hi: Vec<f32> = (0..3)
                .map(|k| {
                    values
                        .iter()
                        .skip(k)
                        .step_by(3)
                        .cloned()
                        .fold(f32::NEG_INFINITY, f32::max)
                })
                .collect();
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        push(&mut self.json, "accessors", acc)
    }

    /// A u32 index accessor.
    pub fn indices(&mut self, indices: &[u32]) -> usize {
        let bytes: Vec<u8> = indices.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes);
        push(
            &mut self.json,
            "accessors",
            json!({"bufferView": view, "componentType": 5125, "count": indices.len(), "type": "SCALAR"}),
        )
    }

    /// A mesh with the given primitives.
    pub fn mesh(&mut self, primitives: Value) -> usize {
        push(&mut self.json, "meshes", json!({"primitives": primitives}))
    }

    /// A node (not yet in the scene).
    pub fn node(&mut self, node: Value) -> usize {
        push(&mut self.json, "nodes", node)
    }

    /// A node added to the scene's roots.
    pub fn root(&mut self, node: Value) -> usize {
        let index = self.node(node);
        self.json["scenes"][0]["nodes"]
            .as_array_mut()
            .unwrap()
            .push(json!(index));
        index
    }

    /// Appends to any top-level array (materials, cameras, textures, samplers, …).
    pub fn add(&mut self, key: &str, item: Value) -> usize {
        push(&mut self.json, key, item)
    }

    /// An image stored in the buffer, and a texture using it with `sampler`.
    pub fn png_texture(&mut self, png: &[u8], sampler: Value) -> usize {
        let view = self.view(png);
        let image = push(
            &mut self.json,
            "images",
            json!({"bufferView": view, "mimeType": "image/png"}),
        );
        let sampler = push(&mut self.json, "samplers", sampler);
        push(
            &mut self.json,
            "textures",
            json!({"source": image, "sampler": sampler}),
        )
    }

    /// A quad (two triangles) in the XY plane from -1 to 1 facing +Z, with UVs (v down).
    pub fn quad_primitive(&mut self, material: Option<usize>) -> Value {
        let pos = self.floats(
            "VEC3",
            &[
                -1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 1.0, 1.0, 0.0, -1.0, 1.0, 0.0,
            ],
        );
        let uv = self.floats("VEC2", &[0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0]);
        let idx = self.indices(&[0, 1, 2, 0, 2, 3]);
        let mut p = json!({"attributes": {"POSITION": pos, "TEXCOORD_0": uv}, "indices": idx});
        if let Some(m) = material {
            p["material"] = json!(m);
        }
        p
    }

    fn with_buffer_uri(&self, uri: Option<String>) -> Value {
        let mut json = self.json.clone();
        let mut buffer = json!({"byteLength": self.bin.len()});
        if let Some(uri) = uri {
            buffer["uri"] = json!(uri);
        }
        json["buffers"] = json!([buffer]);
        json
    }

    /// Writes `<dir>/<name>.gltf` with the buffer as a data URI.
    pub fn write_embedded(&self, dir: &Path, name: &str) -> PathBuf {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bin)
        );
        let path = dir.join(format!("{name}.gltf"));
        std::fs::write(
            &path,
            serde_json::to_vec_pretty(&self.with_buffer_uri(Some(uri))).unwrap(),
        )
        .unwrap();
        path
    }

    /// Writes `<dir>/<name>.gltf` and `<dir>/<name>.bin`.
    pub fn write_external(&self, dir: &Path, name: &str) -> PathBuf {
        std::fs::write(dir.join(format!("{name}.bin")), &self.bin).unwrap();
        let path = dir.join(format!("{name}.gltf"));
        let json = self.with_buffer_uri(Some(format!("{name}.bin")));
        std::fs::write(&path, serde_json::to_vec_pretty(&json).unwrap()).unwrap();
        path
    }

    /// The document as GLB bytes.
    pub fn glb(&self) -> Vec<u8> {
        let mut json = serde_json::to_vec(&self.with_buffer_uri(None)).unwrap();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }

    /// Writes `<dir>/<name>.glb`.
    pub fn write_glb(&self, dir: &Path, name: &str) -> PathBuf {
        let path = dir.join(format!("{name}.glb"));
        std::fs::write(&path, self.glb()).unwrap();
        path
    }
}

/// Encodes an RGBA8 image as PNG.
pub fn png_rgba(width: u32, height: u32, rgba: &[[u8; 4]]) -> Vec<u8> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().unwrap();
        writer.write_image_data(rgba.as_flattened()).unwrap();
    }
    out
}
