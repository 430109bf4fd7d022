//! OpenVDB files (`.vdb`): the sparse grids that Houdini, Blender and EmberGen write for
//! smoke and fire, read into a [`DensityGrid`] (scalar grids: density, temperature,
//! emission), or into three of them, one a channel (vector grids read as colours: `Cd`).
//!
//! The format (OpenVDB's `io/` and `tree/` sources, file versions 222 and later, that is
//! OpenVDB 2.0 onward): a header (magic, versions, UUID, file metadata), then per grid a
//! descriptor (name, type, offsets), the grid's compression flags, metadata and transform
//! (index space to world), the tree's topology (the root's background and tiles; 32³
//! internal nodes holding 16³ internal nodes holding 8³ leaves, each with child and value
//! masks and its tile values) and then the leaves' values. Value arrays may leave inactive
//! values out (active-mask compression, restored from the background or one or two stored
//! values) and are stored raw, zlib-compressed or Blosc-compressed (OpenVDB writes LZ4 in
//! Blosc), as 32-bit floats, 64-bit floats or halves (`_HalfFloat` grids), a value of a
//! vector grid as its three components in a row. A colour is read one component at a time
//! (three passes over the file's bytes, which keep the reader's single dense grid of floats
//! and cost only decoding time, small beside the render).
//!
//! The sparse tree becomes a dense grid over the box of the active voxels, padded by one
//! voxel of background so that interpolation fades to it as OpenVDB's samplers do: voxel
//! (i, j, k) holds the value at index point (i, j, k), which the grid's transform maps to
//! world space (renders therefore match OpenVDB's trilinear sampling inside the box).
//! Every size is checked against the bytes that remain and every dense allocation against
//! `--max-memory` before it is made, so a corrupt file is an error, never a huge allocation.
//! Level sets (signed distances, not densities) are refused; negative values, which
//! simulations leave in places, read as zero and are counted in a warning.

use crate::scene::DensityGrid;
use glam::{DMat4, DVec3, I64Vec3};

/// The 8 bytes every OpenVDB file starts with: "VDB " and four zeros (little endian).
const MAGIC: [u8; 8] = [0x20, 0x42, 0x44, 0x56, 0, 0, 0, 0];

/// The oldest file version read: per-grid compression and node-mask compression.
const FIRST_VERSION: u32 = 222;

/// Compression flags of a grid.
const ZIP: u32 = 0x1;
const ACTIVE_MASK: u32 = 0x2;
const BLOSC: u32 = 0x4;

/// The most voxels of the dense grid a file becomes (8 GiB of densities), whatever the
/// memory limit.
const MAX_DENSE_VOXELS: u64 = 1 << 31;

/// Separates a grid's name from the suffix that makes it unique in its file.
const NAME_SUFFIX: char = '\u{1e}';

/// A density grid read from a VDB file, and what the user should know about it.
#[derive(Debug)]
pub struct VdbGrid {
    pub grid: DensityGrid,
    pub warnings: Vec<String>,
}

/// True where `bytes` start as an OpenVDB file does.
pub fn is_vdb(bytes: &[u8]) -> bool {
    bytes.starts_with(&MAGIC)
}

/// Reads the grid `name` of the VDB file `bytes` (without a name: the grid called
/// `density`, or the file's only grid) as a density grid; `source` names the file in the
/// grid and in messages. Errors are reasons for the user.
pub fn parse(bytes: &[u8], source: &str, name: Option<&str>) -> Result<VdbGrid, String> {
    parse_within(bytes, source, name, crate::memory::process_limit())
}

/// [`parse`] with a dense grid of at most `limit` bytes (`None`: any), whatever
/// `--max-memory` says.
pub fn parse_within(
    bytes: &[u8],
    source: &str,
    name: Option<&str>,
    limit: Option<u64>,
) -> Result<VdbGrid, String> {
    let file = File::read(bytes)?;
    let wanted = file.find(name, &["density"])?;
    file.read_grid(bytes, wanted, source, None, limit)
}

/// A colour grid read from a VDB file: one scalar grid per channel (red, green, blue), on
/// one lattice, and what the user should know about it.
#[derive(Debug)]
pub struct VdbColor {
    pub channels: [DensityGrid; 3],
    pub warnings: Vec<String>,
}

/// Reads the grid `name` of the VDB file `bytes` (without a name: the grid called `Cd`,
/// Houdini's colour, or `color`, Blender's, or the file's only grid) as a colour: a vector
/// grid's three components, or a scalar grid's value in every channel (grey); each channel
/// is a dense grid of at most `limit` bytes (`None`: any).
pub fn parse_color_within(
    bytes: &[u8],
    source: &str,
    name: Option<&str>,
    limit: Option<u64>,
) -> Result<VdbColor, String> {
    let file = File::read(bytes)?;
    let wanted = file.find(name, &["Cd", "color"])?;
    let mut warnings = Vec::new();
    let mut channel = |c: usize| -> Result<DensityGrid, String> {
        let read = file.read_grid(bytes, wanted, source, Some(c), limit)?;
        warnings.extend(read.warnings);
        Ok(read.grid)
    };
    let channels = [channel(0)?, channel(1)?, channel(2)?];
    warnings.dedup();
    Ok(VdbColor { channels, warnings })
}

/// [`parse_color_within`] within `--max-memory`.
pub fn parse_color(bytes: &[u8], source: &str, name: Option<&str>) -> Result<VdbColor, String> {
    parse_color_within(bytes, source, name, crate::memory::process_limit())
}

/// The grids of a file, in order.
struct File {
    grids: Vec<Descriptor>,
}

/// Where a grid is in the file and what it holds.
struct Descriptor {
    /// The name, with the suffix that makes it unique in the file.
    unique_name: String,
    /// `Tree_float_5_4_3`, possibly with `_HalfFloat`.
    kind: String,
    /// The unique name of the grid whose tree this one shares (empty: its own).
    parent: String,
    /// Where its compression flags, metadata and transform start.
    start: usize,
}

impl Descriptor {
    fn name(&self) -> &str {
        self.unique_name
            .split(NAME_SUFFIX)
            .next()
            .unwrap_or_default()
    }
}

impl File {
    fn read(bytes: &[u8]) -> Result<Self, String> {
        if !is_vdb(bytes) {
            return Err("not an OpenVDB file (it does not start with \"VDB \")".into());
        }
        let mut r = Reader::at(bytes, MAGIC.len());
        let version = r.u32()?;
        if version < FIRST_VERSION {
            return Err(format!(
                "OpenVDB file version {version}: lucerna reads version {FIRST_VERSION} \
                 (OpenVDB 2.0, 2013) and later"
            ));
        }
        r.skip(8)?; // the library's major and minor version
        if r.u8()? == 0 {
            return Err("the file has no grid offsets (written to a stream, not a file)".into());
        }
        r.skip(36)?; // the file's UUID
        Metadata::read(&mut r)?;
        let count = r.u32()?;
        let mut grids = Vec::new();
        for _ in 0..count {
            let unique_name = r.string()?;
            let kind = r.string()?;
            let parent = r.string()?;
            let start = r.offset()?;
            let _blocks = r.offset()?;
            let end = r.offset()?;
            if !(start == r.pos && start <= end) {
                return Err(format!(
                    "grid {unique_name:?}: its offsets are inconsistent"
                ));
            }
            grids.push(Descriptor {
                unique_name,
                kind,
                parent,
                start,
            });
            r.pos = end;
        }
        if grids.is_empty() {
            return Err("it holds no grids".into());
        }
        Ok(Self { grids })
    }

    /// The grid `name`, or without one the first of `defaults` the file has, or its only
    /// grid.
    fn find(&self, name: Option<&str>, defaults: &[&str]) -> Result<&Descriptor, String> {
        if let Some(name) = name {
            return self
                .grids
                .iter()
                .find(|g| g.name() == name)
                .ok_or_else(|| format!("it has no grid {name:?} ({})", self.listing()));
        }
        let named = defaults
            .iter()
            .find_map(|d| self.grids.iter().find(|g| g.name() == *d));
        match named {
            Some(g) => Ok(g),
            None if self.grids.len() == 1 => Ok(&self.grids[0]),
            None => Err(format!(
                "it has no grid {} and more than one grid: name the one to read ({})",
                defaults
                    .iter()
                    .map(|d| format!("{d:?}"))
                    .collect::<Vec<_>>()
                    .join(" or "),
                self.listing()
            )),
        }
    }

    /// Grid `wanted` of the file `bytes` as a dense grid (`component`: the component of a
    /// vector grid to read, or a scalar grid read as one; `None`: a scalar grid).
    fn read_grid(
        &self,
        bytes: &[u8],
        wanted: &Descriptor,
        source: &str,
        component: Option<usize>,
        limit: Option<u64>,
    ) -> Result<VdbGrid, String> {
        let tree_of = match wanted.parent.is_empty() {
            true => wanted,
            false => self
                .grids
                .iter()
                .find(|g| g.unique_name == wanted.parent)
                .ok_or_else(|| {
                    format!(
                        "grid {:?} is an instance of {:?}, which the file lacks",
                        wanted.name(),
                        wanted.parent
                    )
                })?,
        };
        let label = match component {
            None => format!("{source}[{}]", wanted.name()),
            Some(c) => format!("{source}[{}].{}", wanted.name(), ["r", "g", "b"][c]),
        };
        let in_grid = |reason: String| format!("grid {:?}: {reason}", wanted.name());
        let header = GridHeader::read(bytes, wanted, component).map_err(in_grid)?;
        let tree = if std::ptr::eq(tree_of, wanted) {
            Tree::read(bytes, &header).map_err(in_grid)?
        } else {
            let parent = GridHeader::read(bytes, tree_of, component).map_err(in_grid)?;
            Tree::read(bytes, &parent).map_err(in_grid)?
        };
        densify(&tree, header.index_to_world, label, limit).map_err(in_grid)
    }

    /// "grids: density (float), temperature (float)" for messages.
    fn listing(&self) -> String {
        let names: Vec<String> = self
            .grids
            .iter()
            .map(|g| format!("{} ({})", g.name(), g.kind))
            .collect();
        format!("grids: {}", names.join(", "))
    }
}

/// How a grid's values are stored: bytes of a component in the value arrays (2 for grids
/// saved as halves, `_HalfFloat`) and elsewhere (background, tiles, inactive values: 4 or
/// 8), the components of a value (1, or 3 for a vector grid) and the one that is read.
#[derive(Clone, Copy, PartialEq)]
struct Values {
    stored: usize,
    full: usize,
    components: usize,
    pick: usize,
}

/// What precedes a grid's tree.
struct GridHeader {
    compression: u32,
    values: Values,
    index_to_world: DMat4,
    /// Where the tree's topology starts.
    tree: usize,
}

impl GridHeader {
    fn read(bytes: &[u8], grid: &Descriptor, component: Option<usize>) -> Result<Self, String> {
        let (full, components) = match grid.kind.trim_end_matches("_HalfFloat") {
            "Tree_float_5_4_3" => (4, 1),
            "Tree_double_5_4_3" => (8, 1),
            "Tree_vec3s_5_4_3" if component.is_some() => (4, 3),
            "Tree_vec3d_5_4_3" if component.is_some() => (8, 3),
            kind => {
                return Err(format!(
                    "its type is {kind}: lucerna reads scalar float and double grids \
                     (Tree_float_5_4_3, Tree_double_5_4_3){}",
                    if component.is_none() {
                        ", and vector grids (Tree_vec3s_5_4_3, Tree_vec3d_5_4_3) only as colours"
                    } else {
                        " and vector ones (Tree_vec3s_5_4_3, Tree_vec3d_5_4_3)"
                    }
                ));
            }
        };
        let values = Values {
            stored: if grid.kind.ends_with("_HalfFloat") {
                2
            } else {
                full
            },
            full,
            components,
            pick: if components == 1 {
                0
            } else {
                component.unwrap_or(0)
            },
        };
        let mut r = Reader::at(bytes, grid.start);
        let compression = r.u32()?;
        if compression & !(ZIP | ACTIVE_MASK | BLOSC) != 0 {
            return Err(format!("unknown compression flags {compression:#x}"));
        }
        let metadata = Metadata::read(&mut r)?;
        if metadata.class.as_deref() == Some("level set") {
            return Err(
                "it is a level set (signed distances), not a density; convert it \
                 to a fog volume (Houdini: VDB Convert, OpenVDB: sdfToFogVolume)"
                    .into(),
            );
        }
        let index_to_world = read_transform(&mut r)?;
        Ok(Self {
            compression,
            values,
            index_to_world,
            tree: r.pos,
        })
    }
}

/// The metadata a reader needs (the rest is skipped).
struct Metadata {
    /// The grid class: "fog volume", "level set", "unknown", "staggered".
    class: Option<String>,
}

impl Metadata {
    fn read(r: &mut Reader) -> Result<Self, String> {
        let count = r.u32()?;
        let mut class = None;
        for _ in 0..count {
            let name = r.string()?;
            let kind = r.string()?;
            let size = r.u32()? as usize;
            let value = r.bytes(size)?;
            if name == "class" && kind == "string" {
                class = Some(String::from_utf8_lossy(value).into_owned());
            }
        }
        Ok(Self { class })
    }
}

/// The grid's transform from index space to world space.
fn read_transform(r: &mut Reader) -> Result<DMat4, String> {
    let kind = r.string()?;
    let vec3 =
        |r: &mut Reader| -> Result<DVec3, String> { Ok(DVec3::new(r.f64()?, r.f64()?, r.f64()?)) };
    let scale_map = |r: &mut Reader| -> Result<DVec3, String> {
        let scale = vec3(r)?;
        r.skip(4 * 24)?; // voxel size, inverse scale, its square, inverse twice the scale
        Ok(scale)
    };
    let map = match kind.as_str() {
        "UniformScaleMap" | "ScaleMap" => DMat4::from_scale(scale_map(r)?),
        "UniformScaleTranslateMap" | "ScaleTranslateMap" => {
            let translation = vec3(r)?;
            DMat4::from_translation(translation) * DMat4::from_scale(scale_map(r)?)
        }
        "TranslationMap" => DMat4::from_translation(vec3(r)?),
        // A row-major matrix acting on row vectors: read in order, it is glam's columns.
        "AffineMap" | "UnitaryMap" => {
            let mut m = [0.0; 16];
            for v in &mut m {
                *v = r.f64()?;
            }
            DMat4::from_cols_array(&m)
        }
        "NonlinearFrustumMap" => {
            return Err("its transform is a frustum map, which lucerna does not read".into());
        }
        kind => return Err(format!("unknown transform {kind:?}")),
    };
    if !(map.is_finite() && map.determinant().is_normal()) {
        return Err("its transform is not finite or flattens the grid".into());
    }
    Ok(map)
}

/// A grid's tree flattened: its leaves and the tiles that hold values.
struct Tree {
    background: f32,
    leaves: Vec<Leaf>,
    tiles: Vec<Tile>,
}

/// 8³ voxels from `origin`, x slowest, z fastest (OpenVDB's order).
struct Leaf {
    origin: I64Vec3,
    active: [u64; 8],
    values: Box<[f32; 512]>,
}

/// A constant region of `size`³ voxels from `origin`.
struct Tile {
    origin: I64Vec3,
    size: i64,
    value: f32,
    active: bool,
}

/// Log2 of the sides of the internal nodes and the leaves (the 5_4_3 configuration).
const LOG2_UPPER: u32 = 5;
const LOG2_LOWER: u32 = 4;
const LOG2_LEAF: u32 = 3;

/// One node's masks: `words` 64-bit words each.
fn mask(r: &mut Reader, words: usize) -> Result<Vec<u64>, String> {
    (0..words).map(|_| r.u64()).collect()
}

fn bit(mask: &[u64], i: usize) -> bool {
    mask[i / 64] >> (i % 64) & 1 == 1
}

fn ones(mask: &[u64]) -> usize {
    mask.iter().map(|w| w.count_ones() as usize).sum()
}

/// The local coordinate of entry `i` of a node of `log2` entries a side (x slowest).
fn local(i: usize, log2: u32) -> I64Vec3 {
    let n = (1usize << log2) - 1;
    I64Vec3::new(
        (i >> (2 * log2)) as i64,
        (i >> log2 & n) as i64,
        (i & n) as i64,
    )
}

impl Tree {
    fn read(bytes: &[u8], header: &GridHeader) -> Result<Self, String> {
        let mut r = Reader::at(bytes, header.tree);
        let buffers = r.u32()?;
        if buffers != 1 {
            return Err(format!(
                "its tree has {buffers} buffers (lucerna reads one)"
            ));
        }
        let values = header.values;
        let background = r.value(values)?;
        let mut tree = Tree {
            background,
            leaves: Vec::new(),
            tiles: Vec::new(),
        };
        let root_tiles = r.u32()?;
        let children = r.u32()?;
        let root_side = 1i64 << (LOG2_UPPER + LOG2_LOWER + LOG2_LEAF);
        for _ in 0..root_tiles {
            let origin = r.coord()?;
            let value = r.value(values)?;
            let active = r.u8()? != 0;
            tree.push_tile(origin, root_side, value, active);
        }
        let values_of = Compressed {
            compression: header.compression,
            values,
            background,
        };
        for _ in 0..children {
            let origin = r.coord()?;
            tree.read_internal(&mut r, &values_of, origin, LOG2_UPPER)?;
        }
        // The leaves' values follow the topology, in the same order.
        for leaf in &mut tree.leaves {
            let stored = mask(&mut r, 8)?;
            if stored[..] != leaf.active[..] {
                return Err(format!(
                    "the leaf at {} has a value mask unlike its topology's",
                    leaf.origin
                ));
            }
            let read = values_of.read(&mut r, 512, &leaf.active)?;
            leaf.values.copy_from_slice(&read);
        }
        Ok(tree)
    }

    fn push_tile(&mut self, origin: I64Vec3, size: i64, value: f32, active: bool) {
        if active || value != self.background {
            self.tiles.push(Tile {
                origin,
                size,
                value,
                active,
            });
        }
    }

    /// An internal node of `log2` entries a side at `origin`, with its descendants.
    fn read_internal(
        &mut self,
        r: &mut Reader,
        values: &Compressed,
        origin: I64Vec3,
        log2: u32,
    ) -> Result<(), String> {
        let entries = 1usize << (3 * log2);
        let child = mask(r, entries / 64)?;
        let active = mask(r, entries / 64)?;
        let tiles = values.read(r, entries, &active)?;
        let child_log2 = if log2 == LOG2_UPPER {
            LOG2_LOWER + LOG2_LEAF
        } else {
            LOG2_LEAF
        };
        for (i, &value) in tiles.iter().enumerate() {
            if !bit(&child, i) {
                let at = origin + (local(i, log2) << child_log2);
                self.push_tile(at, 1 << child_log2, value, bit(&active, i));
            }
        }
        for i in (0..entries).filter(|&i| bit(&child, i)) {
            let at = origin + (local(i, log2) << child_log2);
            if log2 == LOG2_UPPER {
                self.read_internal(r, values, at, LOG2_LOWER)?;
            } else {
                let m = mask(r, 8)?;
                self.leaves.push(Leaf {
                    origin: at,
                    active: m.try_into().unwrap(),
                    values: Box::new([self.background; 512]),
                });
            }
        }
        Ok(())
    }
}

/// How a grid's value arrays are stored.
struct Compressed {
    compression: u32,
    values: Values,
    background: f32,
}

impl Compressed {
    /// `count` values of a node whose active voxels are `active` (OpenVDB's
    /// `readCompressedValues`).
    fn read(&self, r: &mut Reader, count: usize, active: &[u64]) -> Result<Vec<f32>, String> {
        let metadata = r.u8()?;
        if metadata > 6 {
            return Err(format!("a node's value metadata is {metadata} (0 to 6)"));
        }
        let bg = self.background;
        let mut inactive = [if metadata == 0 { bg } else { -bg }, bg];
        if matches!(metadata, 2 | 4 | 5) {
            inactive[0] = r.value(self.values)?;
            if metadata == 5 {
                inactive[1] = r.value(self.values)?;
            }
        }
        let selection = match metadata {
            3..=5 => Some(mask(r, count / 64)?),
            _ => None,
        };
        let masked = self.compression & ACTIVE_MASK != 0 && metadata != 6;
        let stored = if masked { ones(active) } else { count };
        let data = self.data(r, stored)?;
        if stored == count {
            return Ok(data);
        }
        let mut next = data.into_iter();
        Ok((0..count)
            .map(|i| match bit(active, i) {
                true => next.next().unwrap_or(bg),
                false => inactive[selection.as_ref().is_some_and(|s| bit(s, i)) as usize],
            })
            .collect())
    }

    /// `count` stored values, raw or compressed.
    fn data(&self, r: &mut Reader, count: usize) -> Result<Vec<f32>, String> {
        let size = self.values.stored;
        if count == 0 && size == 2 {
            // Halves store nothing at all for an empty array (OpenVDB's HalfReader).
            return Ok(Vec::new());
        }
        let (components, pick) = (self.values.components, self.values.pick);
        let expected = count * size * components;
        let raw: std::borrow::Cow<[u8]> = if self.compression & (ZIP | BLOSC) == 0 {
            r.bytes(expected)?.into()
        } else {
            let n = r.i64()?;
            if n <= 0 {
                let n = n.unsigned_abs() as usize;
                if n != expected {
                    return Err(format!(
                        "a node stores {n} bytes of values where {count} values need {expected}"
                    ));
                }
                r.bytes(n)?.into()
            } else {
                let packed = r.bytes(usize::try_from(n).map_err(|_| "a size is too large")?)?;
                if count == 0 {
                    return Ok(Vec::new());
                }
                match self.compression & BLOSC != 0 {
                    true => unblosc(packed, expected)?.into(),
                    false => unzip(packed, expected)?.into(),
                }
            }
        };
        // The picked component of each value.
        let picked = raw
            .chunks_exact(size * components)
            .map(|v| &v[pick * size..(pick + 1) * size]);
        Ok(match size {
            4 => picked
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect(),
            8 => picked
                .map(|c| f64::from_le_bytes(c.try_into().unwrap()) as f32)
                .collect(),
            _ => picked
                .map(|c| half::f16::from_le_bytes(c.try_into().unwrap()).to_f32())
                .collect(),
        })
    }
}

/// Inflates zlib data that must hold exactly `expected` bytes.
fn unzip(packed: &[u8], expected: usize) -> Result<Vec<u8>, String> {
    let out = miniz_oxide::inflate::decompress_to_vec_zlib_with_limit(packed, expected)
        .map_err(|e| format!("corrupt zlib data ({:?})", e.status))?;
    if out.len() != expected {
        return Err(format!(
            "zlib data inflates to {} bytes where {expected} were expected",
            out.len()
        ));
    }
    Ok(out)
}

/// Decompresses Blosc data that must hold exactly `expected` bytes.
fn unblosc(packed: &[u8], expected: usize) -> Result<Vec<u8>, String> {
    let mut declared = 0usize;
    // SAFETY: Blosc reads at most `packed.len()` bytes to validate the header.
    let valid = unsafe {
        blosc_src::blosc_cbuffer_validate(packed.as_ptr().cast(), packed.len(), &mut declared)
    };
    if valid != 0 || declared != expected {
        return Err(format!(
            "corrupt Blosc data (it declares {declared} bytes where {expected} were expected)"
        ));
    }
    let mut out = vec![0u8; expected];
    // SAFETY: the header was validated against `packed`'s length; Blosc writes at most
    // `expected` bytes (its documented guarantee) into `out`, which holds them.
    let written = unsafe {
        blosc_src::blosc_decompress_ctx(
            packed.as_ptr().cast(),
            out.as_mut_ptr().cast(),
            expected,
            1,
        )
    };
    if written != expected as i32 {
        return Err("corrupt Blosc data".into());
    }
    Ok(out)
}

/// The dense grid over the active voxels' box, padded by a voxel of background.
fn densify(
    tree: &Tree,
    index_to_world: DMat4,
    source: String,
    limit: Option<u64>,
) -> Result<VdbGrid, String> {
    let mut lo = I64Vec3::MAX;
    let mut hi = I64Vec3::MIN;
    for leaf in &tree.leaves {
        for i in (0..512).filter(|&i| bit(&leaf.active, i)) {
            let p = leaf.origin + local(i, LOG2_LEAF);
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    for tile in tree.tiles.iter().filter(|t| t.active) {
        lo = lo.min(tile.origin);
        hi = hi.max(tile.origin + (tile.size - 1));
    }
    let mut warnings = Vec::new();
    if lo.cmpgt(hi).any() {
        // No active voxel: a grid of one background voxel (an empty frame of a simulation).
        lo = I64Vec3::ZERO;
        hi = I64Vec3::ZERO;
        warnings.push(format!(
            "{source} has no active voxels: it renders as nothing"
        ));
    }
    let lo = lo - 1;
    let dims = hi + 1 - lo + 1;
    let count = dims
        .to_array()
        .iter()
        .try_fold(1u64, |n, &d| n.checked_mul(d as u64))
        .filter(|&n| n <= MAX_DENSE_VOXELS)
        .ok_or_else(|| {
            format!(
                "its active voxels span {}x{}x{} voxels, more than the {MAX_DENSE_VOXELS} a \
                 dense grid holds",
                dims.x, dims.y, dims.z
            )
        })?;
    crate::memory::check_allocation_within(
        count * 4,
        &format!("the dense grid of {}x{}x{} voxels", dims.x, dims.y, dims.z),
        limit,
    )?;
    let [nx, ny, nz] = dims.to_array().map(|d| d as usize);
    let background = tree.background.max(0.0);
    let mut values = vec![background; count as usize];
    let index = |p: I64Vec3| -> Option<usize> {
        let q = p - lo;
        (q.cmpge(I64Vec3::ZERO).all() && q.cmplt(dims).all())
            .then(|| q.x as usize + nx * (q.y as usize + ny * q.z as usize))
    };
    for tile in &tree.tiles {
        let from = (tile.origin - lo).max(I64Vec3::ZERO);
        let to = (tile.origin + tile.size - lo).min(dims);
        for z in from.z..to.z {
            for y in from.y..to.y {
                for x in from.x..to.x {
                    values[x as usize + nx * (y as usize + ny * z as usize)] = tile.value;
                }
            }
        }
    }
    for leaf in &tree.leaves {
        for (i, &v) in leaf.values.iter().enumerate() {
            if let Some(at) = index(leaf.origin + local(i, LOG2_LEAF)) {
                values[at] = v;
            }
        }
    }
    let mut negative = 0usize;
    for (i, v) in values.iter_mut().enumerate() {
        if !v.is_finite() {
            let p = I64Vec3::new(
                (i % nx) as i64,
                (i / nx % ny) as i64,
                (i / (nx * ny)) as i64,
            ) + lo;
            return Err(format!("voxel {p} has value {v}: values must be finite"));
        }
        if *v < 0.0 {
            negative += 1;
            *v = 0.0;
        }
    }
    if negative > 0 {
        warnings.push(format!(
            "{source}: {negative} voxel(s) with a negative value read as 0"
        ));
    }
    let unit_to_index =
        DMat4::from_translation(lo.as_dvec3() - 0.5) * DMat4::from_scale(dims.as_dvec3());
    let grid = DensityGrid {
        source,
        resolution: [nx, ny, nz].map(|n| n as u32),
        to_world: index_to_world * unit_to_index,
        values: values.into(),
    };
    match grid.defect() {
        Some(reason) => Err(reason),
        None => Ok(VdbGrid { grid, warnings }),
    }
}

/// Little-endian reads from a slice that fail, with a reason, past its end.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn at(bytes: &'a [u8], pos: usize) -> Self {
        Self { bytes, pos }
    }

    fn bytes(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| {
            format!(
                "the file ends early ({n} bytes wanted at byte {}, it has {})",
                self.pos,
                self.bytes.len()
            )
        })?;
        let out = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(out)
    }

    fn skip(&mut self, n: usize) -> Result<(), String> {
        self.bytes(n).map(|_| ())
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        Ok(self.bytes(N)?.try_into().unwrap())
    }

    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.array::<1>()?[0])
    }

    fn u32(&mut self) -> Result<u32, String> {
        self.array().map(u32::from_le_bytes)
    }

    fn u64(&mut self) -> Result<u64, String> {
        self.array().map(u64::from_le_bytes)
    }

    fn i64(&mut self) -> Result<i64, String> {
        self.array().map(i64::from_le_bytes)
    }

    fn f64(&mut self) -> Result<f64, String> {
        self.array().map(f64::from_le_bytes)
    }

    fn coord(&mut self) -> Result<I64Vec3, String> {
        let mut c = [0i64; 3];
        for v in &mut c {
            *v = i32::from_le_bytes(self.array()?) as i64;
        }
        Ok(I64Vec3::from_array(c))
    }

    /// A value outside the value arrays (components of 32 or 64 bits): its picked component.
    fn value(&mut self, values: Values) -> Result<f32, String> {
        let mut picked = 0.0;
        for c in 0..values.components {
            let v = match values.full {
                8 => self.f64()? as f32,
                _ => f32::from_le_bytes(self.array()?),
            };
            if c == values.pick {
                picked = v;
            }
        }
        Ok(picked)
    }

    /// A file offset (64 bits), which must lie inside the file.
    fn offset(&mut self) -> Result<usize, String> {
        let at = self.i64()?;
        usize::try_from(at)
            .ok()
            .filter(|&at| at <= self.bytes.len())
            .ok_or_else(|| format!("offset {at} lies outside the file"))
    }

    /// A string: a 32-bit length, then its bytes.
    fn string(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        Ok(String::from_utf8_lossy(self.bytes(n)?).into_owned())
    }
}

#[cfg(test)]
mod tests;
