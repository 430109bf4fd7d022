//! Textures beyond memory: images moved out of memory into tiled files and read back through
//! a cache of tiles that holds at most the texture memory.
//!
//! When a scene's textures, decoded and with their MIP pyramids, need more than the texture
//! memory (`--texture-memory`, by default half of `--max-memory`:
//! [`crate::memory::texture_memory`]), every image is written as it is decoded to a file of
//! tiles of at most 64 × 64 texels (the layout `maketx` gives the `.tx` files that
//! OpenImageIO's texture system reads) and dropped from memory. The MIP levels for a way of
//! reading it (as data, or integer texels as sRGB colour) are appended to the file when a
//! render first needs them ([`TiledImage::levels`]: the caller builds them from level 0 read
//! back, with the same filter as the pyramids of images in memory). A lookup fetches the
//! tiles it touches from one cache shared by every texture and thread ([`TextureCache`]):
//! tiles read from disk on a miss, evicted (S3-FIFO, by bytes) when the cache is full. The
//! cache is `quick_cache`'s: sharded locks, a hit marks the entry with one atomic store, and a
//! tile wanted by several threads at once is read once while the others wait for it; and
//! each thread keeps the tiles it read last, so that most lookups touch no shared state.
//!
//! The tiles hold the texels of the image in memory and its levels are built alike, so a
//! lookup through the cache gives the value of the same lookup in memory, bit for bit: only
//! the speed differs.
//!
//! The files are unnamed temporary files (`O_TMPFILE`) in `TMPDIR`, or in /var/tmp when
//! `TMPDIR` is held in memory (tmpfs): the kernel frees them when the process ends, however
//! it ends, so a killed render leaves nothing behind.

use crate::color::{rgba8_to_linear, rgba16_to_linear};
use glam::Vec4;
use std::fmt;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// Largest side of a tile, in texels (OpenImageIO's and `maketx`'s default).
pub const TILE: u32 = 64;

/// Bytes a cached tile costs beyond its texels: the entry, its key and its allocation.
const TILE_OVERHEAD: u64 = 96;

/// Which of a scene's images are read through the tile cache, decided before any is decoded.
#[derive(Debug, Default)]
pub struct TexturePlan {
    /// The cache, when some images go to it.
    cache: Option<Arc<TextureCache>>,
    /// Per image (as numbered by the caller), whether it goes to the cache.
    tiled: Vec<bool>,
    /// Bytes all the images need in memory (with their MIP levels where `pyramids`), and the
    /// texture memory.
    needed: u64,
    pyramids: bool,
    /// Images of a known size (those the caller could not measure, or that no texture
    /// shows, have size 0 and stay in memory).
    measured: usize,
    memory: u64,
}

impl TexturePlan {
    /// Plans images of `sizes` decoded bytes under the texture memory
    /// ([`crate::memory::texture_memory`]); `pinned` images stay in memory whatever their
    /// size (an environment map, whose sampling tables read every texel).
    pub fn new(sizes: &[u64], pinned: &[bool]) -> Self {
        match crate::memory::texture_memory() {
            Some(memory) => Self::within(memory, sizes, pinned, crate::memory::mip_pyramids()),
            None => Self::default(),
        }
    }

    /// [`TexturePlan::new`] under a texture memory of `memory` bytes, images needing a MIP
    /// pyramid (a third more) where `pyramids`. All images stay in memory when they fit in
    /// it. Otherwise the largest go to tiled files, one by one, until those left need at
    /// most half of it; the cache takes the rest, so small images (and the many lookups
    /// they serve) keep the speed of memory.
    pub fn within(memory: u64, sizes: &[u64], pinned: &[bool], pyramids: bool) -> Self {
        let resident_bytes = |bytes: u64| match pyramids {
            true => bytes.saturating_add(bytes / 3),
            false => bytes,
        };
        let needed = resident_bytes(sizes.iter().fold(0u64, |a, &b| a.saturating_add(b)));
        let mut plan = Self {
            cache: None,
            tiled: vec![false; sizes.len()],
            needed,
            pyramids,
            measured: sizes.iter().filter(|&&n| n > 0).count(),
            memory,
        };
        if needed <= memory {
            return plan;
        }
        let mut largest: Vec<usize> = (0..sizes.len())
            .filter(|&i| sizes[i] > 0 && !pinned.get(i).copied().unwrap_or(false))
            .collect();
        largest.sort_by_key(|&i| std::cmp::Reverse(sizes[i]));
        let mut kept: u64 = sizes.iter().fold(0u64, |a, &b| a.saturating_add(b));
        for i in largest {
            if resident_bytes(kept) <= memory / 2 {
                break;
            }
            plan.tiled[i] = true;
            kept -= sizes[i];
        }
        let left = memory.saturating_sub(resident_bytes(kept));
        plan.cache = Some(TextureCache::new(left.max(memory / 2)));
        plan
    }

    /// The cache image `index` is read through, if it goes to one.
    pub fn cache_of(&self, index: usize) -> Option<&Arc<TextureCache>> {
        self.cache
            .as_ref()
            .filter(|_| self.tiled.get(index).copied().unwrap_or(false))
    }

    /// The warning that `source`'s textures are read through a cache, if they are.
    pub fn notice(&self, source: &str) -> Option<String> {
        use crate::memory::Bytes;
        let cache = self.cache.as_ref()?;
        let tiled = self.tiled.iter().filter(|&&t| t).count();
        let all = self.measured;
        let which = match tiled == all {
            true => format!("all {all} images are"),
            false => format!("the {tiled} largest of {all} images are"),
        };
        Some(format!(
            "{source}: the textures need {} in memory{}, more than the texture memory of {} \
             (--texture-memory): {which} read from tiled copies on disk through a cache of {}, \
             more slowly",
            Bytes(self.needed),
            if self.pyramids {
                " with their MIP levels"
            } else {
                ""
            },
            Bytes(self.memory),
            Bytes(cache.capacity())
        ))
    }
}

/// Where tiled copies are written: the temporary folder (`TMPDIR`), unless it is held in
/// memory (tmpfs or ramfs, as /tmp is on many systems), where copies would take the memory
/// they are meant to free: then /var/tmp, which the file system hierarchy keeps on disk.
fn folder_for_copies() -> std::path::PathBuf {
    let temp = std::env::temp_dir();
    let var_tmp = std::path::Path::new("/var/tmp");
    if crate::platform::in_memory(&temp) && var_tmp.is_dir() && !crate::platform::in_memory(var_tmp)
    {
        var_tmp.to_path_buf()
    } else {
        temp
    }
}

/// What the cache has done so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Images moved to tiled files.
    pub images: u32,
    /// Bytes of those files (the images and their MIP levels).
    pub bytes_on_disk: u64,
    /// Tiles read from disk, and their bytes.
    pub tiles_read: u64,
    pub bytes_read: u64,
    /// Bytes the cache holds now.
    pub resident: u64,
}

#[derive(Clone)]
struct TileWeight;

impl quick_cache::Weighter<u64, Arc<TexelArray>> for TileWeight {
    fn weight(&self, _: &u64, tile: &Arc<TexelArray>) -> u64 {
        tile.bytes() as u64 + TILE_OVERHEAD
    }
}

/// Texels of one level, borrowed to be written to a tiled file.
#[derive(Clone, Copy)]
pub enum LevelTexels<'a> {
    Rgba8(&'a [[u8; 4]]),
    Rgba16(&'a [[u16; 4]]),
    RgbaF32(&'a [[f32; 4]]),
}

/// One level of an image to be written to a tiled file: its size and its texels, row by
/// row.
pub struct LevelImage<'a> {
    pub width: u32,
    pub height: u32,
    pub texels: LevelTexels<'a>,
}

/// Texels of a tile, or of a whole image read back: row by row, in the image's format.
#[derive(Debug)]
pub enum TexelArray {
    Rgba8(Vec<[u8; 4]>),
    Rgba16(Vec<[u16; 4]>),
    RgbaF32(Vec<[f32; 4]>),
}

impl TexelArray {
    /// Texel `i`, linear (sRGB-decoded where `srgb` is set and the texels are integers).
    #[inline]
    fn fetch(&self, i: usize, srgb: bool) -> Vec4 {
        match self {
            TexelArray::Rgba8(t) => rgba8_to_linear(t[i], srgb),
            TexelArray::Rgba16(t) => rgba16_to_linear(t[i], srgb),
            TexelArray::RgbaF32(t) => Vec4::from_array(t[i]),
        }
    }

    fn borrowed(&self) -> LevelTexels<'_> {
        match self {
            TexelArray::Rgba8(t) => LevelTexels::Rgba8(t),
            TexelArray::Rgba16(t) => LevelTexels::Rgba16(t),
            TexelArray::RgbaF32(t) => LevelTexels::RgbaF32(t),
        }
    }

    fn bytes(&self) -> usize {
        match self {
            TexelArray::Rgba8(t) => t.len() * 4,
            TexelArray::Rgba16(t) => t.len() * 8,
            TexelArray::RgbaF32(t) => t.len() * 16,
        }
    }
}

/// The tiles of every tiled image of a scene, at most `capacity` bytes of them in memory.
pub struct TextureCache {
    tiles: quick_cache::sync::Cache<u64, Arc<TexelArray>, TileWeight>,
    capacity: u64,
    images: AtomicU32,
    bytes_on_disk: AtomicU64,
    /// Bytes of the largest tile stored (what a thread's recent tiles are counted in).
    largest_tile: AtomicU64,
    tiles_read: AtomicU64,
    bytes_read: AtomicU64,
    /// Whether a failed read has been reported (once: a failing disk fails every read).
    read_failed: AtomicBool,
}

impl fmt::Debug for TextureCache {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TextureCache")
            .field("capacity", &self.capacity)
            .field("stats", &self.stats())
            .finish()
    }
}

impl TextureCache {
    /// An empty cache of `capacity` bytes.
    pub fn new(capacity: u64) -> Arc<Self> {
        // Estimated entries: tiles of 8-bit RGBA, the common case.
        let tile = (TILE * TILE * 4) as u64 + TILE_OVERHEAD;
        Arc::new(Self {
            tiles: quick_cache::sync::Cache::with_weighter(
                (capacity / tile).clamp(16, 1 << 24) as usize,
                capacity,
                TileWeight,
            ),
            capacity,
            images: AtomicU32::new(0),
            bytes_on_disk: AtomicU64::new(0),
            largest_tile: AtomicU64::new(0),
            tiles_read: AtomicU64::new(0),
            bytes_read: AtomicU64::new(0),
            read_failed: AtomicBool::new(false),
        })
    }

    /// The most bytes the cache holds.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// The most bytes each render thread's recent tiles may keep alive beyond the cache.
    pub fn bytes_per_thread(&self) -> u64 {
        RECENT_TILES as u64 * (self.largest_tile.load(Ordering::Relaxed) + TILE_OVERHEAD)
    }

    pub fn stats(&self) -> CacheStats {
        CacheStats {
            images: self.images.load(Ordering::Relaxed),
            bytes_on_disk: self.bytes_on_disk.load(Ordering::Relaxed),
            tiles_read: self.tiles_read.load(Ordering::Relaxed),
            bytes_read: self.bytes_read.load(Ordering::Relaxed),
            resident: self.tiles.weight(),
        }
    }

    /// Writes the full-resolution image `base` to a tiled file, to be read through this
    /// cache (`name` names it in messages). Its MIP levels are written when a lookup first
    /// needs them ([`TiledImage::levels`]).
    pub fn store(self: &Arc<Self>, name: &str, base: &LevelImage) -> io::Result<TiledImage> {
        let format = match base.texels {
            LevelTexels::Rgba8(_) => Format::Rgba8,
            LevelTexels::Rgba16(_) => Format::Rgba16,
            LevelTexels::RgbaF32(_) => Format::RgbaF32,
        };
        let folder = folder_for_copies();
        let file = tempfile::tempfile_in(&folder)
            .map_err(|e| io::Error::new(e.kind(), format!("in {}: {e}", folder.display())))?;
        let (layout, end) = write_levels(&file, format, (0, 0), std::slice::from_ref(base))?;
        let layout = layout[0];
        self.largest_tile
            .fetch_max(layout.tile_bytes(format) as u64, Ordering::Relaxed);
        self.images.fetch_add(1, Ordering::Relaxed);
        self.bytes_on_disk.fetch_add(end.0, Ordering::Relaxed);
        Ok(TiledImage {
            id: NEXT_IMAGE.fetch_add(1, Ordering::Relaxed),
            name: name.to_string(),
            file,
            format,
            chains: Default::default(),
            base: layout,
            end: Mutex::new(end),
            cache: self.clone(),
        })
    }
}

/// Texel storage of a tiled image (that of the image it was made from).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Rgba8,
    Rgba16,
    RgbaF32,
}

impl Format {
    fn texel_bytes(self) -> usize {
        match self {
            Format::Rgba8 => 4,
            Format::Rgba16 => 8,
            Format::RgbaF32 => 16,
        }
    }
}

/// Where one level of a tiled image lies in its file: tiles row by row, each `tile_width` ×
/// `tile_height` texels row by row (those of the last column and row padded).
#[derive(Clone, Copy, Debug)]
pub struct LevelLayout {
    pub width: u32,
    pub height: u32,
    tile_width: u32,
    tile_height: u32,
    tiles_across: u32,
    /// Number of the level's first tile among the file's (tiles are keyed by number).
    first_tile: u32,
    offset: u64,
}

impl LevelLayout {
    /// The texel ranges of the level's tiles, `(x0, y0, x1, y1)` (ends excluded).
    pub fn tiles(&self) -> impl Iterator<Item = (usize, usize, usize, usize)> + use<> {
        let (w, h) = (self.width as usize, self.height as usize);
        let (tw, th) = (self.tile_width as usize, self.tile_height as usize);
        (0..h.div_ceil(th)).flat_map(move |ty| {
            (0..w.div_ceil(tw)).map(move |tx| {
                let (x0, y0) = (tx * tw, ty * th);
                (x0, y0, (x0 + tw).min(w), (y0 + th).min(h))
            })
        })
    }

    fn tile_bytes(&self, format: Format) -> usize {
        (self.tile_width * self.tile_height) as usize * format.texel_bytes()
    }
}

/// Writes `levels` one after the other into the tiled `file` from `start` (byte offset and
/// number of the first tile); returns where each lies and where the next would start.
fn write_levels(
    file: &File,
    format: Format,
    start: (u64, u32),
    levels: &[LevelImage],
) -> io::Result<(Vec<LevelLayout>, (u64, u32))> {
    let (mut offset, mut first_tile) = start;
    let mut out = BufWriter::with_capacity(1 << 20, WriteAt { file, offset });
    let mut layouts = Vec::with_capacity(levels.len());
    for level in levels {
        let (width, height) = (level.width, level.height);
        let (tile_width, tile_height) = (TILE.min(width), TILE.min(height));
        let (across, down) = (width.div_ceil(tile_width), height.div_ceil(tile_height));
        let layout = LevelLayout {
            width,
            height,
            tile_width,
            tile_height,
            tiles_across: across,
            first_tile,
            offset,
        };
        let padding = vec![0u8; format.texel_bytes()];
        for ty in 0..down {
            for tx in 0..across {
                for row in 0..tile_height {
                    for column in 0..tile_width {
                        let (x, y) = (tx * tile_width + column, ty * tile_height + row);
                        if x >= width || y >= height {
                            out.write_all(&padding)?;
                            continue;
                        }
                        let i = (y * width + x) as usize;
                        match level.texels {
                            LevelTexels::Rgba8(t) => out.write_all(&t[i])?,
                            LevelTexels::Rgba16(t) => {
                                for c in t[i] {
                                    out.write_all(&c.to_le_bytes())?;
                                }
                            }
                            LevelTexels::RgbaF32(t) => {
                                for c in t[i] {
                                    out.write_all(&c.to_le_bytes())?;
                                }
                            }
                        }
                    }
                }
            }
        }
        let tiles = across * down;
        first_tile = first_tile
            .checked_add(tiles)
            .ok_or_else(|| io::Error::other("too many tiles"))?;
        offset += tiles as u64 * layout.tile_bytes(format) as u64;
        layouts.push(layout);
    }
    out.flush()?;
    Ok((layouts, (offset, first_tile)))
}

/// Writes to a file from an offset on (`pwrite`), so that appending needs no shared file
/// position.
struct WriteAt<'a> {
    file: &'a File,
    offset: u64,
}

impl Write for WriteAt<'_> {
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        let n = crate::platform::write_at(self.file, bytes, self.offset)?;
        self.offset += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// An image in a tiled file, read through its cache.
pub struct TiledImage {
    id: u32,
    name: String,
    file: File,
    format: Format,
    /// The full-resolution level.
    base: LevelLayout,
    /// Level 0 and the MIP levels, written on first use: for reading the texels as they
    /// are, and for reading integer texels as sRGB colour (float images: the first).
    chains: [OnceLock<Vec<LevelLayout>>; 2],
    /// Where the next level written goes (byte offset, first tile number); held while
    /// levels are appended.
    end: Mutex<(u64, u32)>,
    cache: Arc<TextureCache>,
}

impl fmt::Debug for TiledImage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TiledImage")
            .field("name", &self.name)
            .field("format", &self.format)
            .field("size", &(self.base.width, self.base.height))
            .finish()
    }
}

/// Tiles each thread read last, so that most lookups find their tile without touching the
/// shared cache (whose entry for the tile may have been evicted meanwhile: the thread's
/// reference keeps it alive, so a render may hold [`RECENT_TILES`] tiles a thread beyond the
/// cache's capacity).
const RECENT_TILES: usize = 128;

/// Numbers tiled images process-wide, so that the threads' recent tiles never mistake one
/// scene's tile for another's.
static NEXT_IMAGE: AtomicU32 = AtomicU32::new(0);

struct RecentTiles([Option<(u64, Arc<TexelArray>)>; RECENT_TILES]);

thread_local! {
    static RECENT: std::cell::RefCell<RecentTiles> =
        const { std::cell::RefCell::new(RecentTiles([const { None }; RECENT_TILES])) };
}

impl TiledImage {
    /// The full-resolution level.
    #[inline]
    pub fn base(&self) -> &LevelLayout {
        &self.base
    }

    /// The levels (0 first) for reading the texels with `srgb`, MIP levels written on first
    /// use: `build` makes levels 1 and up (size and texels) from level 0, which it is given
    /// read back from the file. A level that cannot be written leaves the chain at level 0
    /// (lookups then read the full resolution), after an error message.
    #[inline]
    pub fn levels(
        &self,
        srgb: bool,
        build: impl FnOnce(TexelArray) -> Vec<(u32, u32, TexelArray)>,
    ) -> &[LevelLayout] {
        let chain = (srgb && self.format != Format::RgbaF32) as usize;
        self.chains[chain].get_or_init(|| {
            let levels = build(self.read_all());
            let images: Vec<LevelImage> = (levels.iter())
                .map(|(width, height, texels)| LevelImage {
                    width: *width,
                    height: *height,
                    texels: texels.borrowed(),
                })
                .collect();
            let mut end = self.end.lock().unwrap_or_else(|e| e.into_inner());
            match write_levels(&self.file, self.format, *end, &images) {
                Ok((layouts, new_end)) => {
                    self.cache
                        .bytes_on_disk
                        .fetch_add(new_end.0 - end.0, Ordering::Relaxed);
                    *end = new_end;
                    std::iter::once(self.base).chain(layouts).collect()
                }
                Err(e) => {
                    log::error!(
                        "{}: writing its MIP levels failed ({e}): lookups read its full resolution",
                        self.name
                    );
                    vec![self.base]
                }
            }
        })
    }

    /// The cache the image is read through.
    pub fn cache(&self) -> &Arc<TextureCache> {
        &self.cache
    }

    /// Texel (`x`, `y`) of `level`, linear (sRGB-decoded where `srgb` is set and the texels
    /// are integers).
    #[inline]
    pub fn texel(&self, level: &LevelLayout, x: usize, y: usize, srgb: bool) -> Vec4 {
        let (tw, th) = (level.tile_width as usize, level.tile_height as usize);
        let tile = (y / th) as u32 * level.tiles_across + (x / tw) as u32;
        let key = (self.id as u64) << 32 | (level.first_tile + tile) as u64;
        let i = (y % th) * tw + x % tw;
        RECENT.with_borrow_mut(|recent| {
            // Neighbouring tiles of an image take neighbouring slots; images start apart.
            let slot = (self.id as usize * 41 + (level.first_tile + tile) as usize) % RECENT_TILES;
            let slot = &mut recent.0[slot];
            match slot {
                Some((k, texels)) if *k == key => texels.fetch(i, srgb),
                _ => {
                    let texels = self.tile(key, level, tile);
                    let value = texels.fetch(i, srgb);
                    *slot = Some((key, texels));
                    value
                }
            }
        })
    }

    /// Tile `tile` of `level`, from the cache or read into it.
    fn tile(&self, key: u64, level: &LevelLayout, tile: u32) -> Arc<TexelArray> {
        let read = || -> Result<Arc<TexelArray>, std::convert::Infallible> {
            let texels = self.read_tile(level, tile);
            self.cache.tiles_read.fetch_add(1, Ordering::Relaxed);
            self.cache
                .bytes_read
                .fetch_add(texels.bytes() as u64, Ordering::Relaxed);
            Ok(Arc::new(texels))
        };
        match self.cache.tiles.get_or_insert_with(&key, read) {
            Ok(texels) => texels,
            Err(never) => match never {},
        }
    }

    /// Tile `tile` of `level`, read from the file (a failed read reads as black, after an
    /// error message: the render cannot stop in the middle of a lookup).
    fn read_tile(&self, level: &LevelLayout, tile: u32) -> TexelArray {
        let bytes = level.tile_bytes(self.format);
        let mut buffer = vec![0u8; bytes];
        let offset = level.offset + tile as u64 * bytes as u64;
        if let Err(e) = crate::platform::read_exact_at(&self.file, &mut buffer, offset) {
            if !self.cache.read_failed.swap(true, Ordering::Relaxed) {
                log::error!(
                    "{}: reading a texture tile failed ({e}): it reads as black",
                    self.name
                );
            }
            buffer.fill(0);
        }
        decode(self.format, &buffer)
    }

    /// The full-resolution texels, in memory again (for writing the scene to a file and
    /// building MIP levels), read from the file without passing through the cache.
    pub fn read_all(&self) -> TexelArray {
        let level = self.base;
        let (w, h) = (level.width as usize, level.height as usize);
        let (tw, th) = (level.tile_width as usize, level.tile_height as usize);
        let mut out = match self.format {
            Format::Rgba8 => TexelArray::Rgba8(vec![[0; 4]; w * h]),
            Format::Rgba16 => TexelArray::Rgba16(vec![[0; 4]; w * h]),
            Format::RgbaF32 => TexelArray::RgbaF32(vec![[0.0; 4]; w * h]),
        };
        for tile in 0..level.tiles_across * h.div_ceil(th) as u32 {
            let texels = self.read_tile(&level, tile);
            let x0 = (tile % level.tiles_across) as usize * tw;
            let y0 = (tile / level.tiles_across) as usize * th;
            for (row, y) in (y0..(y0 + th).min(h)).enumerate() {
                let columns = (x0 + tw).min(w) - x0;
                let (to, from) = (y * w + x0, row * tw);
                match (&mut out, &texels) {
                    (TexelArray::Rgba8(o), TexelArray::Rgba8(t)) => {
                        o[to..to + columns].copy_from_slice(&t[from..from + columns])
                    }
                    (TexelArray::Rgba16(o), TexelArray::Rgba16(t)) => {
                        o[to..to + columns].copy_from_slice(&t[from..from + columns])
                    }
                    (TexelArray::RgbaF32(o), TexelArray::RgbaF32(t)) => {
                        o[to..to + columns].copy_from_slice(&t[from..from + columns])
                    }
                    _ => unreachable!("tiles keep the image's format"),
                }
            }
        }
        out
    }
}

/// A tile's bytes as texels of `format`.
fn decode(format: Format, bytes: &[u8]) -> TexelArray {
    match format {
        Format::Rgba8 => TexelArray::Rgba8(
            bytes
                .chunks_exact(4)
                .map(|t| [t[0], t[1], t[2], t[3]])
                .collect(),
        ),
        Format::Rgba16 => TexelArray::Rgba16(
            bytes
                .chunks_exact(8)
                .map(|t| std::array::from_fn(|c| u16::from_le_bytes([t[2 * c], t[2 * c + 1]])))
                .collect(),
        ),
        Format::RgbaF32 => TexelArray::RgbaF32(
            bytes
                .chunks_exact(16)
                .map(|t| {
                    std::array::from_fn(|c| {
                        f32::from_le_bytes(t[4 * c..4 * c + 4].try_into().unwrap())
                    })
                })
                .collect(),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn the_largest_images_go_to_the_cache_until_the_rest_fit_in_half_the_memory() {
        let mib = 3 << 20; // 4 MiB in memory with MIP levels
        // The last image is one no texture shows (or that could not be measured).
        let sizes = [10 * mib, mib, 4 * mib, mib, 6 * mib, 0];
        let fits = TexturePlan::within(100 << 20, &sizes, &[], true);
        assert!(fits.cache.is_none() && fits.notice("s").is_none());
        // 88 MiB needed, 64 MiB of texture memory: the 40 and 24 MiB images go (24 MiB
        // left, at most 32), the cache takes the other 40 MiB.
        let plan = TexturePlan::within(64 << 20, &sizes, &[], true);
        assert_eq!(plan.tiled, [true, false, false, false, true, false]);
        assert_eq!(plan.cache.as_ref().unwrap().capacity(), 40 << 20);
        assert!(plan.cache_of(0).is_some() && plan.cache_of(1).is_none());
        assert!(
            plan.notice("s").unwrap().contains("88.0 MiB")
                && plan
                    .notice("s")
                    .unwrap()
                    .contains("the 2 largest of 5 images are read")
        );
        // Without MIP pyramids the same images need 66 MiB, within 70.
        assert!(
            TexturePlan::within(70 << 20, &sizes, &[], false)
                .cache
                .is_none()
        );
        assert!(
            TexturePlan::within(70 << 20, &sizes, &[], true)
                .cache
                .is_some()
        );
        // A pinned image stays, however large; with little memory, all others go.
        let plan = TexturePlan::within(1 << 20, &sizes, &[true], true);
        assert_eq!(plan.tiled, [false, true, true, true, true, false]);
        assert_eq!(plan.cache.as_ref().unwrap().capacity(), 1 << 19);
    }

    #[test]
    fn copies_are_not_written_to_memory() {
        if Path::new("/dev/shm").is_dir() {
            assert!(crate::platform::in_memory(Path::new("/dev/shm")));
        }
        assert!(!crate::platform::in_memory(Path::new("/proc")));
        assert!(
            !crate::platform::in_memory(&folder_for_copies())
                || !crate::platform::in_memory(Path::new("/var/tmp"))
        );
    }

    #[test]
    fn levels_are_laid_out_in_tiles_written_on_first_use_and_read_back() {
        let cache = TextureCache::new(1 << 20);
        // 130 x 40 texels: tiles of 64 x 40, the last column padded; a level of 65 x 20.
        let base: Vec<[u8; 4]> = (0..130 * 40).map(|i| [(i % 251) as u8, 1, 2, 3]).collect();
        let image = cache
            .store(
                "t",
                &LevelImage {
                    width: 130,
                    height: 40,
                    texels: LevelTexels::Rgba8(&base),
                },
            )
            .unwrap();
        assert_eq!(cache.stats().bytes_on_disk, 4 * 3 * 64 * 40);
        let half = |srgb: u8| -> Vec<[u8; 4]> {
            (0..65 * 20).map(|i| [(i % 7) as u8, srgb, 5, 6]).collect()
        };
        let built = std::cell::Cell::new(0);
        let levels = |srgb: bool| {
            image.levels(srgb, |level0| {
                built.set(built.get() + 1);
                let TexelArray::Rgba8(t) = level0 else {
                    panic!("the image's format")
                };
                assert_eq!(t, base, "level 0 read back");
                vec![(65, 20, TexelArray::Rgba8(half(srgb as u8)))]
            })
        };
        let data = levels(false).to_vec();
        let colour = levels(true).to_vec();
        levels(true);
        assert_eq!(built.get(), 2, "each chain is written once");
        let sizes: Vec<_> = data.iter().map(|l| (l.width, l.height)).collect();
        assert_eq!(sizes, [(130, 40), (65, 20)]);
        assert_eq!(colour[0].offset, data[0].offset, "level 0 is shared");
        assert_ne!(colour[1].offset, data[1].offset);
        // Level 1 twice: 2 tiles of 64 x 20 each.
        assert_eq!(
            cache.stats().bytes_on_disk,
            4 * (3 * 64 * 40 + 2 * 2 * 64 * 20)
        );
        for (level, srgb) in [(&data[1], false), (&colour[1], true)] {
            let texel = image.texel(level, 64, 19, false);
            assert_eq!(texel.x, half(0)[19 * 65 + 64][0] as f32 / 255.0);
            assert_eq!(texel.y, srgb as u8 as f32 / 255.0);
        }
    }
}
