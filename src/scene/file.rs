//! The scene file: the internal [`Scene`] on disk, so that other programs (the USD plugin,
//! the benchmark's Mitsuba exporter) can write or read exactly what the renderer sees.
//!
//! One concept in one file (some 1300 lines): the format, read and written here side by side so
//! that every field's validation sits next to its writing.
//!
//! Two files: a JSON manifest `NAME.lucerna` and one little-endian binary buffer beside it
//! (the manifest's `buffer`, normally `NAME.lucerna.bin`). Small values (materials, lights,
//! cameras, instances) are JSON; bulk arrays are *views* into the buffer: `{offset, count}`
//! with the offset in bytes and the count in elements. Element layouts: positions and
//! normals 3 × f32, tangents and colours 4 × f32, uvs 2 × f32, triangles 3 × u32, texels
//! 4 × u8 (`rgba8`, sRGB-encoded or data as the material slot says) or 4 × f32 (`rgba32f`).
//! Matrices are 16 f64 in column-major order; enums are externally tagged in snake_case.
//! Density grids are either in the buffer (`grids`, dense f32) or read from OpenVDB files
//! (`volumes`: file, grid, transform and the interface material whose medium they scale;
//! the reader adds the grid and a box of that material around it, and writes them back as
//! `grids`, meshes and instances). Things that move over the shutter carry keys at evenly
//! spaced times from its opening to its closing: instances' and cameras' `motion`
//! (matrices), and a mesh's `deformation` (a view of positions per key, and of normals per
//! key where the mesh has normals; the mesh's own arrays are the frame's).
//!
//! A scene file is untrusted input: [`read`] checks the format and version, every view
//! against the buffer, every count, index and range, and that every number is finite,
//! before anything uses the scene. The buffer is read view by view, never whole: most of it
//! is texels, which go one image at a time to the texture cache's tiled files when they need
//! more than the texture memory (`texture_cache`).

use super::{BoundaryInterpolation, SubdivisionScheme, SubdivisionSurface};
use super::{Camera, Environment, Light, LightKind, Material, Mesh, Projection, Scene};
use super::{Cylinder, Disk, Instance, LightGroup, RenderSettings, Sphere, Texels, Texture, Wrap};
use crate::error::{Error, Result};
use crate::geometry::deformation::Deformation;
use glam::{Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// The manifest's `format` value.
pub const FORMAT: &str = "lucerna-scene";
/// The manifest version this build writes and reads.
pub const VERSION: u32 = 1;
/// File extension of a manifest; `ingest::load` recognises scene files by it.
pub const EXTENSION: &str = "lucerna";

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    format: String,
    version: u32,
    source: String,
    /// The binary buffer's file name, relative to the manifest.
    buffer: String,
    buffer_bytes: u64,
    meshes: Vec<MeshEntry>,
    instances: Vec<Instance>,
    spheres: Vec<Sphere>,
    #[serde(default)]
    disks: Vec<Disk>,
    #[serde(default)]
    cylinders: Vec<Cylinder>,
    materials: Vec<Material>,
    textures: Vec<TextureEntry>,
    lights: Vec<Light>,
    cameras: Vec<Camera>,
    environment: Option<Environment>,
    #[serde(default)]
    light_groups: Vec<LightGroup>,
    warnings: Vec<String>,
    #[serde(default)]
    render_settings: Option<RenderSettings>,
    #[serde(default)]
    subdivision_surfaces: Vec<SubdivisionEntry>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    grids: Vec<GridEntry>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    volumes: Vec<VolumeEntry>,
    /// The interval the motion keys span.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    shutter: Option<super::Shutter>,
}

/// A volume whose grid is read from an OpenVDB file (USD `Volume` prims): the grid `grid`
/// of `file` (relative to the scene file's folder unless absolute), its own transform
/// followed by `to_world` (column-major 4x4), inside an enclosing box of `material`, an
/// interface with a medium that the grid's densities scale.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct VolumeEntry {
    name: String,
    file: String,
    grid: Option<String>,
    to_world: [f64; 16],
    material: u32,
    /// The temperature field of the material's blackbody (a grid of an OpenVDB file, under
    /// the same transform).
    #[serde(default)]
    temperature: Option<FieldEntry>,
    /// The grid of the material's emission field (an OpenVDB file's grid, under the same
    /// transform).
    #[serde(default)]
    emission: Option<FieldEntry>,
    /// A colour grid (an OpenVDB file's vector grid, or a scalar one read as grey, under the
    /// same transform) that tints the material's scattering point by point.
    #[serde(default)]
    scatter_color: Option<FieldEntry>,
}

/// A grid of an OpenVDB file beside the scene file.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FieldEntry {
    file: String,
    grid: Option<String>,
}

/// A density grid: its resolution, its unit cube to world (a column-major 4x4 matrix) and
/// its values (f32, x fastest).
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GridEntry {
    source: String,
    resolution: [u32; 3],
    to_world: [f64; 16],
    values: View,
}

/// A subdivision surface: its cage (points f32×3, face counts and indices u32), creases
/// (point, point, sharpness: u32, u32, f32), corners (point, sharpness: u32, f32), per-corner
/// texture coordinates (f32×2) and colours (f32×4), and the faces rendered (u32 indices).
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SubdivisionEntry {
    mesh: u32,
    scheme: SubdivisionScheme,
    boundary: BoundaryInterpolation,
    points: View,
    face_counts: View,
    face_indices: View,
    #[serde(default)]
    creases: Option<View>,
    #[serde(default)]
    corners: Option<View>,
    #[serde(default)]
    uvs: Option<View>,
    #[serde(default)]
    colors: Option<View>,
    #[serde(default)]
    keep: Option<View>,
    /// The points at the shutter's keys, where the cage deforms.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    point_keys: Vec<View>,
}

/// `count` elements starting `offset` bytes into the buffer.
#[derive(Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct View {
    offset: u64,
    count: u64,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct MeshEntry {
    name: String,
    material: u32,
    positions: View,
    normals: Option<View>,
    tangents: Option<View>,
    uvs: [Option<View>; 2],
    colors: Option<View>,
    triangles: View,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    deformation: Option<DeformationEntry>,
}

/// A mesh's vertex keys over the shutter (`geometry::deformation`): positions, and normals
/// where the mesh has them, one view a key.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct DeformationEntry {
    positions: Vec<View>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    normals: Option<Vec<View>>,
}

#[derive(Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
enum Encoding {
    Rgba8,
    /// Two words a texel: R | G << 16, B | A << 16.
    Rgba16,
    /// Linear floats (never sRGB-decoded).
    Rgba32f,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TextureEntry {
    name: String,
    width: u32,
    height: u32,
    encoding: Encoding,
    texels: View,
    wrap_u: Wrap,
    wrap_v: Wrap,
    nearest: bool,
    /// Absent in files written before MIP filtering: allowed.
    #[serde(default = "allowed")]
    mipmaps: bool,
    /// A UDIM set: its tiles as (tile number, index of the texture holding the tile's
    /// image); this entry's own image is read where the set has no tile. Empty for an
    /// ordinary texture.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    tiles: Vec<(u32, u32)>,
}

fn allowed() -> bool {
    true
}

/// Appends arrays of plain little-endian values to the buffer.
#[derive(Default)]
struct BufferWriter {
    bytes: Vec<u8>,
}

impl BufferWriter {
    fn push<const N: usize>(&mut self, elements: impl ExactSizeIterator<Item = [u32; N]>) -> View {
        let view = View {
            offset: self.bytes.len() as u64,
            count: elements.len() as u64,
        };
        for e in elements {
            for word in e {
                self.bytes.extend_from_slice(&word.to_le_bytes());
            }
        }
        view
    }

    fn floats<const N: usize>(&mut self, values: &[[f32; N]]) -> View {
        self.push(values.iter().map(|v| v.map(f32::to_bits)))
    }
}

/// The buffer file name written beside `manifest`.
fn buffer_name(manifest: &Path) -> String {
    let name = manifest.file_name().map_or_else(
        || "scene.lucerna".into(),
        |n| n.to_string_lossy().into_owned(),
    );
    format!("{name}.bin")
}

/// Writes `bytes` to `path` through a temporary file and a rename, so a reader never sees
/// a half-written file.
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    crate::files::write_atomically(path, |w| {
        use std::io::Write;
        w.write_all(bytes)
            .map_err(|e| Error::other(path, "write", e.to_string()))
    })
}

/// Writes `scene` as the manifest `path` (conventionally `*.lucerna`) and its buffer beside
/// it. The buffer is written first, so a complete manifest always has its buffer.
pub fn write(scene: &Scene, path: &Path) -> Result<()> {
    let mut buffer = BufferWriter::default();
    let v3 = |v: &[Vec3]| v.iter().map(|x| x.to_array()).collect::<Vec<_>>();
    let v4 = |v: &[Vec4]| v.iter().map(|x| x.to_array()).collect::<Vec<_>>();
    let v2 = |v: &[Vec2]| v.iter().map(|x| x.to_array()).collect::<Vec<_>>();
    let meshes = scene
        .meshes
        .iter()
        .map(|m| MeshEntry {
            name: m.name.clone(),
            material: m.material,
            positions: buffer.floats(&v3(&m.positions)),
            normals: m.normals.as_deref().map(|n| buffer.floats(&v3(n))),
            tangents: m.tangents.as_deref().map(|t| buffer.floats(&v4(t))),
            uvs: m.uvs.clone().map(|uv| uv.map(|uv| buffer.floats(&v2(&uv)))),
            colors: m.colors.as_deref().map(|c| buffer.floats(&v4(c))),
            triangles: buffer.push(m.triangles.iter().copied()),
            deformation: m.deformation.as_ref().map(|d| DeformationEntry {
                positions: d.positions.iter().map(|k| buffer.floats(&v3(k))).collect(),
                normals: d
                    .normals
                    .as_ref()
                    .map(|n| n.iter().map(|k| buffer.floats(&v3(k))).collect()),
            }),
        })
        .collect();
    // Texel arrays shared between textures are written once.
    let mut written: HashMap<*const Texels, (Encoding, View)> = HashMap::new();
    let textures = scene
        .textures
        .iter()
        .map(|t| {
            let (encoding, texels) = *written
                .entry(Arc::as_ptr(&t.texels))
                .or_insert_with(|| push_texels(&mut buffer, &t.texels));
            TextureEntry {
                name: t.name.clone(),
                width: t.width,
                height: t.height,
                encoding,
                texels,
                wrap_u: t.wrap_u,
                wrap_v: t.wrap_v,
                nearest: t.nearest,
                mipmaps: t.mipmaps,
                tiles: t.udim.as_ref().map_or(Vec::new(), |u| u.tiles.clone()),
            }
        })
        .collect();
    let subdivision_surfaces: Vec<SubdivisionEntry> = scene
        .subdivision_surfaces
        .iter()
        .map(|s| SubdivisionEntry {
            mesh: s.mesh,
            scheme: s.scheme,
            boundary: s.boundary,
            points: buffer.floats(&v3(&s.points)),
            face_counts: buffer.push(s.face_counts.iter().map(|&c| [c])),
            face_indices: buffer.push(s.face_indices.iter().map(|&i| [i])),
            creases: (!s.creases.is_empty())
                .then(|| buffer.push(s.creases.iter().map(|([a, b], w)| [*a, *b, w.to_bits()]))),
            corners: (!s.corners.is_empty())
                .then(|| buffer.push(s.corners.iter().map(|(v, w)| [*v, w.to_bits()]))),
            uvs: s.uvs.as_deref().map(|u| buffer.floats(&v2(u))),
            colors: s.colors.as_deref().map(|c| buffer.floats(&v4(c))),
            keep: s.keep.as_ref().map(|k| {
                let faces: Vec<u32> = (0..k.len() as u32).filter(|&f| k[f as usize]).collect();
                buffer.push(faces.iter().map(|&f| [f]))
            }),
            point_keys: s.point_keys.iter().map(|k| buffer.floats(&v3(k))).collect(),
        })
        .collect();
    let grids = scene
        .grids
        .iter()
        .map(|g| GridEntry {
            source: g.source.clone(),
            resolution: g.resolution,
            to_world: g.to_world.to_cols_array(),
            values: buffer.floats(&g.values.iter().map(|&v| [v]).collect::<Vec<_>>()),
        })
        .collect();
    let manifest = Manifest {
        format: FORMAT.into(),
        version: VERSION,
        source: scene.source.clone(),
        buffer: buffer_name(path),
        buffer_bytes: buffer.bytes.len() as u64,
        meshes,
        instances: scene.instances.clone(),
        spheres: scene.spheres.clone(),
        disks: scene.disks.clone(),
        cylinders: scene.cylinders.clone(),
        materials: scene.materials.clone(),
        textures,
        lights: scene.lights.clone(),
        cameras: scene.cameras.clone(),
        environment: scene.environment.clone(),
        light_groups: scene.light_groups.clone(),
        warnings: scene.warnings.clone(),
        render_settings: scene.render_settings.clone(),
        subdivision_surfaces,
        grids,
        // Volumes read from OpenVDB files are written as the grids, meshes and instances
        // they became.
        volumes: Vec::new(),
        shutter: scene.shutter,
    };
    let json = serde_json::to_vec_pretty(&manifest)
        .map_err(|e| Error::other(path, "manifest", e.to_string()))?;
    write_atomically(&path.with_file_name(&manifest.buffer), &buffer.bytes)?;
    write_atomically(path, &json)
}

/// Reads a scene file written by [`write`] (or by any program following the format),
/// rejecting anything malformed with an error naming the element.
pub fn read(path: &Path) -> Result<Scene> {
    let text = crate::files::read_input(path).map_err(|e| Error::bad_input(path, "file", e))?;
    parse(path, &text, |buffer| {
        crate::files::check_input(buffer).map_err(std::io::Error::other)?;
        Ok(BufferSource::File(std::fs::File::open(buffer)?))
    })
}

/// Where a scene file's buffer is read from: bytes in memory, or the file, read view by
/// view (so that loading never holds the whole buffer, which is mostly texels, at once).
pub enum BufferSource {
    Bytes(Vec<u8>),
    File(std::fs::File),
}

impl From<Vec<u8>> for BufferSource {
    fn from(bytes: Vec<u8>) -> Self {
        BufferSource::Bytes(bytes)
    }
}

impl BufferSource {
    fn len(&self) -> std::io::Result<u64> {
        match self {
            BufferSource::Bytes(b) => Ok(b.len() as u64),
            BufferSource::File(f) => Ok(f.metadata()?.len()),
        }
    }

    /// Fills `out` from byte `offset` (which the caller has checked lies inside).
    fn read_at(&self, offset: u64, out: &mut [u8]) -> std::io::Result<()> {
        match self {
            BufferSource::Bytes(b) => {
                out.copy_from_slice(&b[offset as usize..offset as usize + out.len()]);
                Ok(())
            }
            BufferSource::File(f) => crate::platform::read_exact_at(f, out, offset),
        }
    }
}

/// Appends `texels` to `buffer` (a tiled image's read back from its tiles).
fn push_texels(buffer: &mut BufferWriter, texels: &Texels) -> (Encoding, View) {
    match texels {
        Texels::Rgba8(p) => (
            Encoding::Rgba8,
            buffer.push(p.iter().map(|p| [u32::from_le_bytes(*p)])),
        ),
        Texels::Rgba16(p) => (
            Encoding::Rgba16,
            buffer.push(p.iter().map(|[r, g, b, a]| {
                [*r as u32 | (*g as u32) << 16, *b as u32 | (*a as u32) << 16]
            })),
        ),
        Texels::RgbaF32(p) => (Encoding::Rgba32f, buffer.floats(p)),
        Texels::Tiled(image) => push_texels(buffer, &image.read_all().into()),
    }
}

/// Decodes the manifest bytes `text` of the scene file at `path`, reading its buffer with
/// `read_buffer` (given the buffer's path beside the manifest). [`read`] reads both from
/// disk; the fuzz targets (tools/fuzz) feed them from memory.
pub fn parse(
    path: &Path,
    text: &[u8],
    read_buffer: impl FnOnce(&Path) -> std::io::Result<BufferSource>,
) -> Result<Scene> {
    let bad = |element: &str, reason: String| Error::bad_input(path, element, reason);
    let manifest: Manifest =
        serde_json::from_slice(text).map_err(|e| bad("manifest", e.to_string()))?;
    if manifest.format != FORMAT {
        return Err(bad("format", format!("expected \"{FORMAT}\"")));
    }
    if manifest.version != VERSION {
        return Err(bad(
            "version",
            format!(
                "version {} is not supported (this build reads {VERSION})",
                manifest.version
            ),
        ));
    }
    let buffer_path = path.with_file_name(&manifest.buffer);
    let mut components = Path::new(&manifest.buffer).components();
    if !(matches!(components.next(), Some(std::path::Component::Normal(_)))
        && components.next().is_none())
    {
        return Err(bad(
            "buffer",
            "must be a file name beside the manifest".into(),
        ));
    }
    let source = read_buffer(&buffer_path)
        .map_err(|e| bad("buffer", format!("{}: {e}", buffer_path.display())))?;
    let len =
        (source.len()).map_err(|e| bad("buffer", format!("{}: {e}", buffer_path.display())))?;
    if len != manifest.buffer_bytes {
        return Err(bad(
            "buffer",
            format!("{len} bytes, the manifest says {}", manifest.buffer_bytes),
        ));
    }
    let buffer = BufferReader {
        source: &source,
        len,
        path,
    };

    let mut meshes = Vec::with_capacity(manifest.meshes.len());
    for (i, m) in manifest.meshes.iter().enumerate() {
        let element = |field: &str| format!("meshes[{i}].{field}");
        let positions: Vec<Vec3> = buffer.floats(m.positions, &element("positions"))?;
        let n = positions.len();
        let triangles: Vec<[u32; 3]> = buffer.words(m.triangles, &element("triangles"))?;
        if let Some((t, _)) = triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v as usize >= n))
        {
            return Err(bad(
                &format!("meshes[{i}].triangles[{t}]"),
                format!("vertex index out of range (the mesh has {n} vertices)"),
            ));
        }
        let deformation = match &m.deformation {
            None => None,
            Some(d) => {
                let keys = |views: &[View], what: &str| -> Result<Vec<Vec<Vec3>>> {
                    (views.iter().enumerate())
                        .map(|(k, &v)| {
                            buffer.vertices(v, n, &element(&format!("deformation.{what}[{k}]")))
                        })
                        .collect()
                };
                let deformation = Deformation {
                    positions: keys(&d.positions, "positions")?,
                    normals: d
                        .normals
                        .as_deref()
                        .map(|v| keys(v, "normals"))
                        .transpose()?,
                };
                deformation
                    .check(n, m.normals.is_some())
                    .map_err(|reason| bad(&element("deformation"), reason))?;
                Some(deformation)
            }
        };
        meshes.push(Mesh {
            name: m.name.clone(),
            positions,
            normals: m
                .normals
                .map(|v| buffer.vertices(v, n, &element("normals")))
                .transpose()?,
            tangents: m
                .tangents
                .map(|v| buffer.vertices(v, n, &element("tangents")))
                .transpose()?,
            uvs: [
                m.uvs[0]
                    .map(|v| buffer.vertices(v, n, &element("uvs[0]")))
                    .transpose()?,
                m.uvs[1]
                    .map(|v| buffer.vertices(v, n, &element("uvs[1]")))
                    .transpose()?,
            ],
            colors: m
                .colors
                .map(|v| buffer.vertices(v, n, &element("colors")))
                .transpose()?,
            triangles,
            material: m.material,
            deformation,
        });
    }
    let mut textures = Vec::with_capacity(manifest.textures.len());
    // Textures naming the same texels share them, as they did when written. When the
    // texels need more than the texture memory, they are moved to tiled files one by one.
    let mut shared: HashMap<(u64, u64, Encoding), Arc<Texels>> = HashMap::new();
    // The distinct images, numbered in order of first use, their sizes, and which stays in
    // memory whatever its size: the environment map, whose sampling tables read every
    // texel and which is checked for values that are not radiance.
    let environment = match manifest.environment {
        Some(Environment::LatLong { texture, .. }) => Some(texture as usize),
        _ => None,
    };
    let mut images: HashMap<(u64, u64, Encoding), usize> = HashMap::new();
    let (mut sizes, mut pinned) = (Vec::new(), Vec::new());
    for (i, t) in manifest.textures.iter().enumerate() {
        let key = (t.texels.offset, t.texels.count, t.encoding);
        let image = *images.entry(key).or_insert_with(|| {
            let texel = match t.encoding {
                Encoding::Rgba8 => 4,
                Encoding::Rgba16 => 8,
                Encoding::Rgba32f => 16,
            };
            sizes.push(t.texels.count.saturating_mul(texel));
            pinned.push(false);
            sizes.len() - 1
        });
        pinned[image] |= environment == Some(i);
    }
    let plan = super::texture_cache::TexturePlan::new(&sizes, &pinned);
    // Named after the scene the file holds (a USD stage's path, not the plugin's file).
    let name = match manifest.source.as_str() {
        "" => path.display().to_string(),
        source => source.to_string(),
    };
    let cache_notice = plan.notice(&name);
    for (i, t) in manifest.textures.iter().enumerate() {
        let element = format!("textures[{i}].texels");
        if t.width == 0 || t.height == 0 || t.texels.count != t.width as u64 * t.height as u64 {
            return Err(bad(
                &element,
                format!(
                    "{} texels for a {}x{} image",
                    t.texels.count, t.width, t.height
                ),
            ));
        }
        let key = (t.texels.offset, t.texels.count, t.encoding);
        if let Some(texels) = shared.get(&key) {
            textures.push(texture(t, texels.clone()));
            continue;
        }
        let texels = match t.encoding {
            Encoding::Rgba8 => {
                let words: Vec<[u32; 1]> = buffer.words(t.texels, &element)?;
                Texels::Rgba8(words.iter().map(|w| w[0].to_le_bytes()).collect())
            }
            Encoding::Rgba16 => {
                let words: Vec<[u32; 2]> = buffer.words(t.texels, &element)?;
                Texels::Rgba16(
                    words
                        .iter()
                        .map(|[rg, ba]| {
                            [*rg as u16, (rg >> 16) as u16, *ba as u16, (ba >> 16) as u16]
                        })
                        .collect(),
                )
            }
            Encoding::Rgba32f => Texels::RgbaF32(buffer.floats(t.texels, &element)?),
        };
        let texels = match plan.cache_of(images[&key]) {
            Some(cache) => texels
                .to_tiled(&t.name, t.width, t.height, cache)
                .map_err(|e| {
                    Error::other(
                        path,
                        &element,
                        format!("writing its tiled copy failed: {e}"),
                    )
                })?,
            _ => texels,
        };
        let texels = Arc::new(texels);
        shared.insert(key, texels.clone());
        textures.push(texture(t, texels));
    }
    // UDIM sets, once every texture they name is read.
    for (i, t) in manifest.textures.iter().enumerate() {
        if t.tiles.is_empty() {
            continue;
        }
        let element = format!("textures[{i}].tiles");
        let nested = |&(_, index): &(u32, u32)| {
            manifest
                .textures
                .get(index as usize)
                .is_some_and(|e| !e.tiles.is_empty())
        };
        if let Some((number, index)) = t.tiles.iter().find(|tile| nested(tile)) {
            return Err(bad(
                &element,
                format!("tile {number}: texture {index} is itself a UDIM set"),
            ));
        }
        let udim =
            super::udim_set(t.tiles.clone(), &textures).map_err(|reason| bad(&element, reason))?;
        textures[i].udim = Some(Arc::new(udim));
    }
    let scene = Scene {
        source: manifest.source,
        meshes,
        instances: manifest.instances,
        spheres: manifest.spheres,
        disks: manifest.disks,
        cylinders: manifest.cylinders,
        materials: manifest.materials,
        textures,
        lights: manifest.lights,
        cameras: manifest.cameras,
        environment: manifest.environment,
        light_groups: manifest.light_groups,
        warnings: manifest.warnings,
        render_settings: manifest.render_settings,
        subdivision_surfaces: Vec::new(),
        subdivision_level: None,
        grids: Vec::new(),
        shutter: manifest.shutter,
    };
    let mut scene = scene;
    for (i, entry) in manifest.grids.iter().enumerate() {
        let element = format!("grids[{i}]");
        let values: Vec<[f32; 1]> = buffer.floats(entry.values, &format!("{element}.values"))?;
        let grid = super::DensityGrid {
            source: entry.source.clone(),
            resolution: entry.resolution,
            to_world: glam::DMat4::from_cols_array(&entry.to_world),
            values: values.into_iter().map(|[v]| v).collect(),
        };
        if let Some(reason) = grid.defect() {
            return Err(bad(&element, reason));
        }
        scene.grids.push(grid);
    }
    let mut volume_grids = HashMap::new();
    for (i, entry) in manifest.volumes.iter().enumerate() {
        read_volume(&mut scene, path, entry, &mut volume_grids)
            .map_err(|(field, reason)| bad(&format!("volumes[{i}]{field}"), reason))?;
    }
    for (i, entry) in manifest.subdivision_surfaces.iter().enumerate() {
        let surface = read_subdivision(&buffer, entry, &format!("subdivision_surfaces[{i}]"))
            .map_err(|(element, reason)| bad(&element, reason))?;
        if surface.mesh as usize >= scene.meshes.len() {
            return Err(bad(
                &format!("subdivision_surfaces[{i}].mesh"),
                format!("mesh {} does not exist", surface.mesh),
            ));
        }
        scene.subdivision_surfaces.push(surface);
    }
    validate(&scene).map_err(|(element, reason)| bad(&element, reason))?;
    let udim_warnings = super::features::missing_tile_warnings(&scene);
    scene.warnings.extend(udim_warnings);
    scene.warnings.extend(cache_notice);
    Ok(scene)
}

/// Reads the grid of a volume entry into `scene` (the scene file at `path` locates a
/// relative file; `read` keeps the grids read so far by file and grid name, so instances
/// of one volume share their densities), scales its material's medium by it and encloses it
/// in a box of that material (a copy of it where an earlier volume took the material for
/// its own grid); errors are (field, reason).
fn read_volume(
    scene: &mut Scene,
    path: &Path,
    v: &VolumeEntry,
    read: &mut HashMap<(String, Option<String>), super::DensityGrid>,
) -> std::result::Result<(), (String, String)> {
    let Some(material) = scene.materials.get(v.material as usize) else {
        return Err((
            ".material".into(),
            format!("material {} does not exist", v.material),
        ));
    };
    let Some(volume) = material.volume else {
        return Err((
            ".material".into(),
            format!(
                "material {} has no medium for the grid to scale",
                v.material
            ),
        ));
    };
    let to_world = glam::DMat4::from_cols_array(&v.to_world);
    let grid = field_grid(
        scene,
        path,
        &v.name,
        &v.file,
        v.grid.as_deref(),
        to_world,
        read,
    )
    .map_err(|(field, reason)| (field.to_string(), reason))?;
    // The field the medium glows by: a blackbody's temperature or an emission grid, each
    // named by its own entry field and owned by its own part of the material's volume.
    let glow = match (&v.temperature, &v.emission) {
        (None, None) => None,
        (Some(_), Some(_)) => {
            return Err((
                ".emission".into(),
                "a volume glows by one field: a temperature or an emission grid".into(),
            ));
        }
        (Some(t), None) => Some((".temperature", t, "blackbody", volume.blackbody.is_some())),
        (None, Some(e)) => Some((
            ".emission",
            e,
            "emission_field",
            volume.emission_field.is_some(),
        )),
    };
    let glow = match glow {
        None => None,
        Some((field, entry, owner, owned)) => {
            if !owned {
                return Err((
                    field.into(),
                    format!("material {} has no {owner} for it", v.material),
                ));
            }
            let grid = field_grid(
                scene,
                path,
                &v.name,
                &entry.file,
                entry.grid.as_deref(),
                to_world,
                read,
            )
            .map_err(|(at, reason)| (format!("{field}{at}"), reason))?;
            if field == ".temperature"
                && let Some(reason) = volume.blackbody.and_then(|b| b.too_hot(&grid))
            {
                return Err((field.into(), reason));
            }
            Some(grid)
        }
    };
    let scatter_color = match &v.scatter_color {
        None => None,
        Some(_) if !volume.scatters() => {
            scene.warnings.push(format!(
                "{}: material {} does not scatter: its scatter colour grid is not read",
                v.name, v.material
            ));
            None
        }
        Some(entry) => Some(
            color_grids(scene, path, &v.name, entry, to_world, read)
                .map_err(|(at, reason)| (format!(".scatter_color{at}"), reason))?,
        ),
    };
    let density = Some(scene.grids.len() as u32);
    let material = if volume.density.is_none() {
        v.material
    } else {
        scene
            .materials
            .push(scene.materials[v.material as usize].clone());
        scene.materials.len() as u32 - 1
    };
    let (mesh, mut instance) = enclosure(covering(&grid, glow.as_ref()), &v.name, material);
    instance.mesh = scene.meshes.len() as u32;
    scene.meshes.push(mesh);
    scene.instances.push(instance);
    scene.grids.push(grid);
    let glow = glow.map(|t| {
        scene.grids.push(t);
        scene.grids.len() as u32 - 1
    });
    let scatter_color = scatter_color.map(|channels| {
        let first = scene.grids.len() as u32;
        scene.grids.extend(channels);
        [first, first + 1, first + 2]
    });
    if let Some(volume) = scene.materials[material as usize].volume.as_mut() {
        volume.density = density;
        volume.scatter_color = scatter_color;
        if let Some(b) = volume.blackbody.as_mut() {
            b.temperature = glow;
        }
        if let Some(e) = volume.emission_field.as_mut() {
            e.grid = glow;
        }
    }
    Ok(())
}

/// Grid `name` of the OpenVDB file `file` (beside the scene file at `path`; read once per
/// scene, `read` keeps them) under `to_world`, for volume `volume`; on failure, the entry's
/// field at fault and why.
fn field_grid(
    scene: &mut Scene,
    path: &Path,
    volume: &str,
    file: &str,
    name: Option<&str>,
    to_world: glam::DMat4,
    read: &mut HashMap<(String, Option<String>), super::DensityGrid>,
) -> std::result::Result<super::DensityGrid, (&'static str, String)> {
    let key = (file.to_string(), name.map(str::to_string));
    let mut grid = match read.get(&key) {
        Some(grid) => grid.clone(),
        None => {
            let full = path.parent().unwrap_or(Path::new("")).join(file);
            let bytes = crate::files::read_input(&full)
                .map_err(|reason| (".file", format!("{}: {reason}", full.display())))?;
            let parsed = crate::ingest::vdb::parse(&bytes, file, name)
                .map_err(|reason| (".file", format!("{file}: {reason}")))?;
            scene
                .warnings
                .extend(parsed.warnings.iter().map(|w| format!("{volume}: {w}")));
            read.insert(key, parsed.grid.clone());
            parsed.grid
        }
    };
    grid.to_world = to_world * grid.to_world;
    if let Some(reason) = grid.defect() {
        return Err((".to_world", reason));
    }
    Ok(grid)
}

/// The colour grid of `entry` (red, green and blue; read once per scene, `read` keeps its
/// channels) under `to_world`, for volume `volume`; on failure, the entry's field at fault
/// and why.
fn color_grids(
    scene: &mut Scene,
    path: &Path,
    volume: &str,
    entry: &FieldEntry,
    to_world: glam::DMat4,
    read: &mut HashMap<(String, Option<String>), super::DensityGrid>,
) -> std::result::Result<[super::DensityGrid; 3], (&'static str, String)> {
    let file = entry.file.as_str();
    let channel_key = |c: &str| {
        let grid = entry.grid.as_deref().unwrap_or_default();
        (file.to_string(), Some(format!("{grid}\u{1e}{c}")))
    };
    let keys = ["r", "g", "b"].map(channel_key);
    let mut channels = match keys
        .iter()
        .map(|k| read.get(k).cloned())
        .collect::<Option<Vec<_>>>()
    {
        Some(cached) => <[super::DensityGrid; 3]>::try_from(cached).expect("three channels"),
        None => {
            let full = path.parent().unwrap_or(Path::new("")).join(file);
            let bytes = crate::files::read_input(&full)
                .map_err(|reason| (".file", format!("{}: {reason}", full.display())))?;
            let parsed = crate::ingest::vdb::parse_color(&bytes, file, entry.grid.as_deref())
                .map_err(|reason| (".file", format!("{file}: {reason}")))?;
            scene
                .warnings
                .extend(parsed.warnings.iter().map(|w| format!("{volume}: {w}")));
            for (key, grid) in keys.into_iter().zip(&parsed.channels) {
                read.insert(key, grid.clone());
            }
            parsed.channels
        }
    };
    for grid in &mut channels {
        grid.to_world = to_world * grid.to_world;
        if let Some(reason) = grid.defect() {
            return Err((".to_world", reason));
        }
    }
    Ok(channels)
}

/// The unit cube to world transform of a box around `density`'s cube and `other`'s (a
/// temperature or emission grid, whose flames may reach beyond the smoke): the density's cube widened,
/// in its own axes, to hold the other's corners.
fn covering(density: &super::DensityGrid, other: Option<&super::DensityGrid>) -> glam::DMat4 {
    let Some(other) = other else {
        return density.to_world;
    };
    let to_density = density.to_world.inverse() * other.to_world;
    let (mut lo, mut hi) = (glam::DVec3::ZERO, glam::DVec3::ONE);
    for i in 0..8u32 {
        let corner = glam::DVec3::new(
            f64::from(i & 1),
            f64::from(i >> 1 & 1),
            f64::from(i >> 2 & 1),
        );
        let p = to_density.transform_point3(corner);
        (lo, hi) = (lo.min(p), hi.max(p));
    }
    density.to_world * glam::DMat4::from_translation(lo) * glam::DMat4::from_scale(hi - lo)
}

/// A closed box of `material` (a unit cube as a mesh named `name`, placed by `to_world`),
/// faces outward: the interface that holds a medium, for volumes that come without a
/// surface (USD `Volume` prims).
fn enclosure(to_world: glam::DMat4, name: &str, material: u32) -> (Mesh, Instance) {
    let corner = |i: u32| glam::Vec3::new((i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2 & 1) as f32);
    // Two triangles a face, counter-clockwise seen from outside the cube.
    let mut triangles = vec![
        [0, 2, 3],
        [0, 3, 1], // z = 0
        [4, 5, 7],
        [4, 7, 6], // z = 1
        [0, 1, 5],
        [0, 5, 4], // y = 0
        [2, 6, 7],
        [2, 7, 3], // y = 1
        [0, 4, 6],
        [0, 6, 2], // x = 0
        [1, 3, 7],
        [1, 7, 5], // x = 1
    ];
    if to_world.determinant() < 0.0 {
        // A mirroring transform turns the faces inward: wind them the other way.
        triangles.iter_mut().for_each(|t| t.swap(1, 2));
    }
    let mesh = Mesh {
        name: name.to_string(),
        positions: (0..8).map(corner).collect(),
        normals: None,
        tangents: None,
        uvs: [None, None],
        colors: None,
        triangles,
        material,
        deformation: None,
    };
    let instance = Instance {
        name: name.to_string(),
        mesh: 0,
        transform: to_world,
        motion: Vec::new(),
    };
    (mesh, instance)
}

/// Reads and checks one subdivision surface: polygons of 3 or more points (triangles for
/// Loop), indices in range, per-corner data for every corner, finite sharpness.
fn read_subdivision(
    buffer: &BufferReader,
    e: &SubdivisionEntry,
    element: &str,
) -> std::result::Result<SubdivisionSurface, (String, String)> {
    let field = |f: &str| format!("{element}.{f}");
    // The reader's errors name the field already.
    let lift = |err: Error| (element.to_string(), err.to_string());
    let points: Vec<Vec3> = buffer.floats(e.points, &field("points")).map_err(lift)?;
    let counts: Vec<[u32; 1]> = buffer
        .words(e.face_counts, &field("face_counts"))
        .map_err(lift)?;
    let face_counts: Vec<u32> = counts.iter().map(|c| c[0]).collect();
    let indices: Vec<[u32; 1]> = buffer
        .words(e.face_indices, &field("face_indices"))
        .map_err(lift)?;
    let face_indices: Vec<u32> = indices.iter().map(|i| i[0]).collect();
    if let Some(f) = face_counts
        .iter()
        .position(|&n| n < 3 || (e.scheme == SubdivisionScheme::Loop && n != 3))
    {
        return Err((
            field("face_counts"),
            format!("face {f} has {} points", face_counts[f]),
        ));
    }
    let corners: u64 = face_counts.iter().map(|&n| n as u64).sum();
    if corners != face_indices.len() as u64 {
        return Err((
            field("face_indices"),
            format!("{} indices for {corners} face corners", face_indices.len()),
        ));
    }
    let n = points.len() as u32;
    if face_indices.iter().any(|&i| i >= n) {
        return Err((field("face_indices"), format!("an index is not below {n}")));
    }
    let creases: Vec<([u32; 2], f32)> = match e.creases {
        Some(v) => buffer
            .words::<3>(v, &field("creases"))
            .map_err(lift)?
            .iter()
            .map(|w| ([w[0], w[1]], f32::from_bits(w[2])))
            .collect(),
        None => Vec::new(),
    };
    let sharp_corners: Vec<(u32, f32)> = match e.corners {
        Some(v) => buffer
            .words::<2>(v, &field("corners"))
            .map_err(lift)?
            .iter()
            .map(|w| (w[0], f32::from_bits(w[1])))
            .collect(),
        None => Vec::new(),
    };
    if creases
        .iter()
        .any(|(p, s)| p[0] >= n || p[1] >= n || !(s.is_finite() && *s >= 0.0))
        || sharp_corners
            .iter()
            .any(|(p, s)| *p >= n || !(s.is_finite() && *s >= 0.0))
    {
        return Err((
            field("creases"),
            "a crease or corner names a point out of range or has a sharpness that is not finite and non-negative".into(),
        ));
    }
    let per_corner =
        |view: Option<View>, f: &str| -> std::result::Result<Option<usize>, (String, String)> {
            match view {
                Some(v) if v.count != corners => Err((
                    field(f),
                    format!("{} values for {corners} face corners", v.count),
                )),
                Some(_) => Ok(Some(0)),
                None => Ok(None),
            }
        };
    per_corner(e.uvs, "uvs")?;
    per_corner(e.colors, "colors")?;
    let uvs = e
        .uvs
        .map(|v| buffer.floats::<2, Vec2>(v, &field("uvs")))
        .transpose()
        .map_err(lift)?;
    let colors = e
        .colors
        .map(|v| buffer.floats::<4, Vec4>(v, &field("colors")))
        .transpose()
        .map_err(lift)?;
    let keep = match e.keep {
        Some(v) => {
            let faces: Vec<[u32; 1]> = buffer.words(v, &field("keep")).map_err(lift)?;
            let mut mask = vec![false; face_counts.len()];
            for [f] in faces {
                *mask
                    .get_mut(f as usize)
                    .ok_or_else(|| (field("keep"), format!("face {f} does not exist")))? = true;
            }
            Some(mask)
        }
        None => None,
    };
    let point_keys = (e.point_keys.iter().enumerate())
        .map(|(k, &v)| buffer.vertices(v, points.len(), &field(&format!("point_keys[{k}]"))))
        .collect::<Result<Vec<Vec<Vec3>>>>()
        .map_err(lift)?;
    let keys = Deformation {
        positions: point_keys,
        normals: None,
    };
    if !keys.positions.is_empty() {
        keys.check(points.len(), false)
            .map_err(|reason| (field("point_keys"), reason))?;
    }
    let finite_uvs = uvs.as_ref().is_none_or(|u| u.iter().all(|v| v.is_finite()));
    if !finite_uvs || !points.iter().all(|p| p.is_finite()) {
        return Err((
            element.to_string(),
            "points or texture coordinates are not finite".into(),
        ));
    }
    Ok(SubdivisionSurface {
        mesh: e.mesh,
        scheme: e.scheme,
        boundary: e.boundary,
        points,
        face_counts,
        face_indices,
        creases,
        corners: sharp_corners,
        uvs,
        colors,
        keep,
        point_keys: keys.positions,
    })
}

fn texture(entry: &TextureEntry, texels: Arc<Texels>) -> Texture {
    Texture {
        name: entry.name.clone(),
        width: entry.width,
        height: entry.height,
        texels,
        mips: Default::default(),
        wrap_u: entry.wrap_u,
        wrap_v: entry.wrap_v,
        nearest: entry.nearest,
        mipmaps: entry.mipmaps,
        udim: None,
    }
}

/// Reads typed views out of the buffer with bounds checks.
struct BufferReader<'a> {
    source: &'a BufferSource,
    len: u64,
    path: &'a Path,
}

impl BufferReader<'_> {
    /// The view's elements as `N` little-endian 32-bit words each.
    fn words<const N: usize>(&self, view: View, element: &str) -> Result<Vec<[u32; N]>> {
        let size = 4 * N as u64;
        let end = view
            .count
            .checked_mul(size)
            .and_then(|len| view.offset.checked_add(len))
            .filter(|&end| end <= self.len)
            .ok_or_else(|| {
                Error::bad_input(
                    self.path,
                    element,
                    format!(
                        "view of {} elements at byte {} runs past the buffer ({} bytes)",
                        view.count, view.offset, self.len
                    ),
                )
            })?;
        crate::memory::check_allocation(end - view.offset, element)
            .map_err(|reason| Error::bad_input(self.path, element, reason))?;
        // Read a block at a time: the words are the only full copy.
        const BLOCK_ELEMENTS: u64 = 1 << 16;
        let mut out = Vec::with_capacity(view.count as usize);
        let mut block = vec![0u8; (BLOCK_ELEMENTS.min(view.count) * size) as usize];
        let mut offset = view.offset;
        while offset < end {
            let n = ((end - offset) as usize).min(block.len());
            self.source
                .read_at(offset, &mut block[..n])
                .map_err(|e| Error::bad_input(self.path, element, format!("cannot read: {e}")))?;
            out.extend(block[..n].chunks_exact(size as usize).map(|chunk| {
                std::array::from_fn(|k| {
                    u32::from_le_bytes(chunk[4 * k..4 * k + 4].try_into().unwrap())
                })
            }));
            offset += n as u64;
        }
        Ok(out)
    }

    /// The view's elements as `N` finite floats each, converted to `T`.
    fn floats<const N: usize, T: From<[f32; N]>>(
        &self,
        view: View,
        element: &str,
    ) -> Result<Vec<T>> {
        let words: Vec<[u32; N]> = self.words(view, element)?;
        let mut out = Vec::with_capacity(words.len());
        for (k, w) in words.iter().enumerate() {
            let v = w.map(f32::from_bits);
            if !v.iter().all(|x| x.is_finite()) {
                return Err(Error::bad_input(
                    self.path,
                    format!("{element}[{k}]"),
                    "value is NaN or infinite",
                ));
            }
            out.push(T::from(v));
        }
        Ok(out)
    }

    /// A per-vertex attribute: finite floats, one element per vertex.
    fn vertices<const N: usize, T: From<[f32; N]>>(
        &self,
        view: View,
        vertices: usize,
        element: &str,
    ) -> Result<Vec<T>> {
        if view.count != vertices as u64 {
            return Err(Error::bad_input(
                self.path,
                element,
                format!("{} values for {vertices} vertices", view.count),
            ));
        }
        self.floats(view, element)
    }
}

/// Checks the indices, ranges and finiteness of everything that is not a buffer view.
/// Returns the element and the reason of the first problem.
fn validate(scene: &Scene) -> std::result::Result<(), (String, String)> {
    let fail = |element: String, reason: &str| Err((element, reason.to_string()));
    let finite = |values: &[f32]| values.iter().all(|x| x.is_finite());
    let materials = scene.materials.len();
    let textures = scene.textures.len();
    for (i, g) in scene.light_groups.iter().enumerate() {
        let lower = |c: char| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_';
        if g.name.is_empty() || !g.name.chars().all(lower) {
            return fail(
                format!("light_groups[{i}].name"),
                "a light group name is lower-case letters, digits and _",
            );
        }
    }
    if let Some(settings) = &scene.render_settings {
        let views = std::iter::once((
            "render_settings".to_string(),
            settings.resolution,
            settings.crop,
            settings.overscan,
        ))
        .chain(settings.products.iter().enumerate().map(|(i, p)| {
            (
                format!("render_settings.products[{i}]"),
                p.resolution,
                p.crop,
                p.overscan,
            )
        }));
        let side = 1..=crate::camera::MAX_IMAGE_SIDE;
        for (element, resolution, crop, overscan) in views {
            if overscan.is_some_and(|o| o.iter().any(|&e| e > crate::camera::MAX_OVERSCAN)) {
                return fail(
                    format!("{element}.overscan"),
                    "at most 16384 pixels an edge",
                );
            }
            if let Some([w, h]) = resolution
                && !(side.contains(&w) && side.contains(&h))
            {
                return fail(
                    format!("{element}.resolution"),
                    "width and height must be 1 to 65536",
                );
            }
            if let Some([x0, y0, x1, y1]) = crop
                && (x0 >= x1 || y0 >= y1)
            {
                return fail(format!("{element}.crop"), "an empty pixel window");
            }
        }
        for (i, p) in settings.products.iter().enumerate() {
            if p.output.is_empty() {
                return fail(
                    format!("render_settings.products[{i}].output"),
                    "an output file name is needed",
                );
            }
        }
    }
    for (i, m) in scene.meshes.iter().enumerate() {
        if m.material as usize >= materials {
            return fail(
                format!("meshes[{i}].material"),
                "material index out of range",
            );
        }
    }
    if let Some(s) = scene.shutter
        && !(s.open.is_finite() && s.close.is_finite() && s.open < s.close && s.frames() <= 2e3)
    {
        return fail(
            "shutter".into(),
            "open and close must be finite, open before close",
        );
    }
    for (i, inst) in scene.instances.iter().enumerate() {
        if inst.mesh as usize >= scene.meshes.len() {
            return fail(format!("instances[{i}].mesh"), "mesh index out of range");
        }
        if !inst.transform.is_finite() {
            return fail(
                format!("instances[{i}].transform"),
                "transform is not finite",
            );
        }
        if let Err(reason) = crate::geometry::motion::check_keys(&inst.motion) {
            return fail(format!("instances[{i}].motion"), &reason);
        }
    }
    for (i, s) in scene.spheres.iter().enumerate() {
        if s.material as usize >= materials {
            return fail(
                format!("spheres[{i}].material"),
                "material index out of range",
            );
        }
        if !(s.centre.is_finite() && s.radius.is_finite() && s.radius > 0.0) {
            return fail(
                format!("spheres[{i}]"),
                "centre and radius must be finite, radius > 0",
            );
        }
    }
    let shapes = scene
        .disks
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let ok = d.centre.is_finite()
                && (d.normal.length() - 1.0).abs() < 1e-3
                && d.radius.is_finite()
                && d.radius > 0.0;
            (
                format!("disks[{i}]"),
                d.material,
                ok,
                "centre, unit normal and radius > 0",
            )
        })
        .chain(scene.cylinders.iter().enumerate().map(|(i, c)| {
            let ok = c.centre.is_finite()
                && (c.axis.length() - 1.0).abs() < 1e-3
                && c.radius.is_finite()
                && c.radius > 0.0
                && c.length.is_finite()
                && c.length > 0.0;
            (
                format!("cylinders[{i}]"),
                c.material,
                ok,
                "centre, unit axis, radius > 0 and length > 0",
            )
        }));
    for (element, material, ok, needs) in shapes {
        if material as usize >= materials {
            return fail(format!("{element}.material"), "material index out of range");
        }
        if !ok {
            return fail(element, &format!("needs a finite {needs}"));
        }
    }
    for (i, m) in scene.materials.iter().enumerate() {
        for (field, r) in m.texture_slots() {
            if r.texture as usize >= textures || r.tex_coord > 1 {
                return fail(
                    format!("materials[{i}].{field}"),
                    "texture index or texture coordinate set out of range",
                );
            }
            if let Some(t) = r.transform
                && !finite(&[t.x.to_array(), t.y.to_array(), t.offset.to_array()].concat())
            {
                return fail(format!("materials[{i}].{field}.transform"), "not finite");
            }
        }
        let phong_ok = match m.model {
            super::BsdfModel::Phong { exponent, specular } => {
                (0.0..=1e7).contains(&exponent)
                    && specular.is_finite()
                    && specular.min_element() >= 0.0
            }
            _ => true,
        };
        let alpha_ok = match m.alpha_mode {
            super::AlphaMode::Mask { cutoff } => cutoff.is_finite(),
            _ => true,
        };
        let unit = |x: f32| (0.0..=1.0).contains(&x);
        let colour = |c: Vec3| c.is_finite() && c.min_element() >= 0.0;
        let extensions_ok = unit(m.transmission)
            && m.transmission_color.is_none_or(colour)
            && m.clearcoat_normal_scale.is_finite()
            && m.volume.is_none_or(|v| {
                colour(v.absorption)
                    && colour(v.scattering)
                    && colour(v.emission)
                    && v.anisotropy.abs() < 1.0
                    && v.density.is_none_or(|g| (g as usize) < scene.grids.len())
                    && v.blackbody.is_none_or(|b| {
                        v.density.is_some()
                            && b.kelvin.is_finite()
                            && b.kelvin > 0.0
                            && b.intensity.is_finite()
                            && b.intensity >= 0.0
                            && colour(b.tint)
                            && b.temperature.is_none_or(|g| {
                                scene
                                    .grids
                                    .get(g as usize)
                                    .is_some_and(|t| b.too_hot(t).is_none())
                            })
                    })
                    && v.scatter_color.is_none_or(|c| {
                        v.density.is_some() && c.iter().all(|&g| (g as usize) < scene.grids.len())
                    })
                    && v.emission_field.is_none_or(|e| {
                        v.density.is_some()
                            && v.blackbody.is_none()
                            && colour(e.tint)
                            && e.grid.is_none_or(|g| (g as usize) < scene.grids.len())
                    })
            })
            && unit(m.specular.weight)
            && colour(m.specular.color)
            && m.sheen.is_none_or(|s| colour(s.color) && unit(s.roughness))
            && m.diffuse_transmission
                .is_none_or(|d| unit(d.factor) && colour(d.color) && d.color.max_element() <= 1.0)
            && m.iridescence.is_none_or(|i| {
                unit(i.factor)
                    && i.ior.is_finite()
                    && i.ior >= 1.0
                    && finite(&[i.thickness_min, i.thickness_max])
                    && i.thickness_min >= 0.0
                    && i.thickness_max >= 0.0
            })
            && m.anisotropy
                .is_none_or(|a| unit(a.strength) && a.rotation.is_finite());
        if !(finite(&m.base_color.to_array())
            && m.emissive.is_finite()
            && m.emissive.min_element() >= 0.0
            && finite(&[m.metallic, m.roughness, m.normal_scale, m.ior])
            && m.ior > 0.0
            && (0.0..=1.0).contains(&m.clearcoat)
            && m.specular_color
                .is_none_or(|c| c.is_finite() && c.min_element() >= 0.0 && c.max_element() <= 1.0)
            && (0.0..=1.0).contains(&m.clearcoat_roughness)
            && (0.0..=1.0).contains(&m.diffuse_roughness)
            && phong_ok
            && alpha_ok
            && extensions_ok)
        {
            return fail(
                format!("materials[{i}]"),
                "a factor is not finite or out of range",
            );
        }
    }
    for (i, l) in scene.lights.iter().enumerate() {
        let ok = match &l.kind {
            LightKind::Point {
                position,
                intensity,
            } => position.is_finite() && intensity.is_finite() && intensity.min_element() >= 0.0,
            LightKind::Spot {
                position,
                direction,
                intensity,
                inner_cone,
                outer_cone,
            } => {
                position.is_finite()
                    && direction.is_finite()
                    && direction.length_squared() > 0.0
                    && intensity.is_finite()
                    && intensity.min_element() >= 0.0
                    && (0.0..=*outer_cone).contains(inner_cone)
                    && *outer_cone <= std::f32::consts::FRAC_PI_2
            }
            LightKind::Directional {
                direction,
                irradiance,
                angle,
            } => {
                direction.is_finite()
                    && direction.length_squared() > 0.0
                    && irradiance.is_finite()
                    && irradiance.min_element() >= 0.0
                    && (0.0..=std::f32::consts::PI).contains(angle)
            }
        };
        if !ok {
            return fail(
                format!("lights[{i}]"),
                "a value is not finite or out of range",
            );
        }
    }
    for (i, c) in scene.cameras.iter().enumerate() {
        let projection_ok = match c.projection {
            Projection::Perspective { yfov, aspect } => {
                yfov > 0.0
                    && yfov < std::f32::consts::PI
                    && aspect.is_none_or(|a| a.is_finite() && a > 0.0)
            }
            Projection::Orthographic { xmag, ymag } => {
                xmag.is_finite() && ymag.is_finite() && xmag > 0.0 && ymag > 0.0
            }
        };
        if !(projection_ok
            && c.transform.is_finite()
            && c.aperture_radius.is_finite()
            && c.aperture_radius >= 0.0
            && c.focus_distance.is_finite()
            && c.focus_distance > 0.0
            && c.clip_near.is_finite()
            && c.clip_near >= 0.0
            && c.clip_far.is_none_or(|f| f > c.clip_near))
        {
            return fail(
                format!("cameras[{i}]"),
                "a value is not finite or out of range",
            );
        }
        if let Err(reason) = crate::geometry::motion::check_keys(&c.motion) {
            return fail(format!("cameras[{i}].motion"), &reason);
        }
    }
    match &scene.environment {
        Some(Environment::Constant(radiance))
            if !(radiance.is_finite() && radiance.min_element() >= 0.0) =>
        {
            fail(
                "environment".into(),
                "radiance is not finite and non-negative",
            )
        }
        Some(Environment::LatLong {
            texture,
            scale,
            rotation,
        }) => {
            if *texture as usize >= textures {
                fail("environment.texture".into(), "texture index out of range")
            } else if scene.textures[*texture as usize].udim.is_some() {
                fail(
                    "environment.texture".into(),
                    "a UDIM texture set cannot light the environment",
                )
            } else if !(scale.is_finite() && scale.min_element() >= 0.0 && rotation.is_finite()) {
                fail("environment".into(), "scale or rotation is not finite")
            } else {
                Ok(())
            }
        }
        _ => Ok(()),
    }
}
