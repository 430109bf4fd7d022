//! Textures: decoded images with their sampler state, looked up bilinearly at a point or
//! filtered over a footprint through a MIP pyramid.
//!
//! A lookup with a footprint (the two axes of an ellipse in texture coordinates, from the
//! ray's cone where it met the surface: `world::footprint`) takes trilinear probes at the
//! MIP level of the ellipse's minor axis, spread along its major axis (up to
//! [`MAX_ANISOTROPY`] of them): the anisotropic filtering of GPUs, which keeps a surface
//! seen at a grazing angle sharp where an isotropic level would blur it. A footprint of at
//! most one texel is the bilinear lookup of the full-resolution image, bit for bit.
//!
//! Pyramids are built on first use, by box filtering in linear values: one per image and
//! way of reading it (an 8- or 16-bit image read as sRGB colour averages decoded values and
//! stores them sRGB-encoded again, as GPUs do for sRGB formats; read as data, it averages
//! the stored values). A level keeps the base image's texel format, so a pyramid costs a
//! third of the image.

use super::texture_cache::{
    LevelImage, LevelLayout, LevelTexels, TexelArray, TextureCache, TiledImage,
};
use super::udim::Udim;
use crate::color::{linear_to_srgb, rgba8_to_linear, rgba16_to_linear};
use glam::{Vec2, Vec4};
use serde::{Deserialize, Serialize};
use std::sync::{Arc, OnceLock};

/// Texel storage. Integer images keep their stored values (8 or 16 bits a channel) and are
/// sRGB-decoded per lookup where the material slot says so, because one image may serve
/// both colour and data slots. Float images (OpenEXR, Radiance HDR, float TIFF) hold linear
/// values and are read as they are in every slot, as OpenImageIO-based renderers do. A
/// tiled image lies on disk with its MIP levels and is read through a cache of tiles
/// (`texture_cache`), for scenes whose textures do not fit in memory.
#[derive(Clone, Debug)]
pub enum Texels {
    Rgba8(Vec<[u8; 4]>),
    Rgba16(Vec<[u16; 4]>),
    RgbaF32(Vec<[f32; 4]>),
    Tiled(Arc<TiledImage>),
}

impl Texels {
    /// The `width` × `height` image of these texels (`name` in messages) moved to a tiled
    /// file, for reading through `cache` (its MIP levels are written on first use).
    pub fn to_tiled(
        &self,
        name: &str,
        width: u32,
        height: u32,
        cache: &Arc<TextureCache>,
    ) -> std::io::Result<Texels> {
        let texels = match self {
            Texels::Rgba8(t) => LevelTexels::Rgba8(t),
            Texels::Rgba16(t) => LevelTexels::Rgba16(t),
            Texels::RgbaF32(t) => LevelTexels::RgbaF32(t),
            Texels::Tiled(_) => return Ok(self.clone()),
        };
        let base = LevelImage {
            width,
            height,
            texels,
        };
        Ok(Texels::Tiled(Arc::new(cache.store(name, &base)?)))
    }
}

/// The levels of a tiled image for reading with `srgb` (0 first), its MIP levels built as
/// those of images in memory are ([`build_chain`]) and written on first use.
fn tiled_levels(image: &TiledImage, srgb: bool) -> &[LevelLayout] {
    image.levels(srgb, |base| {
        let (width, height) = (image.base().width, image.base().height);
        let levels = build_chain(&Texels::from(base), width, height, srgb);
        (levels.into_iter())
            .map(|l| {
                let texels = match l.texels {
                    Texels::Rgba8(t) => TexelArray::Rgba8(t),
                    Texels::Rgba16(t) => TexelArray::Rgba16(t),
                    Texels::RgbaF32(t) => TexelArray::RgbaF32(t),
                    Texels::Tiled(_) => unreachable!("levels are built in memory"),
                };
                (l.width, l.height, texels)
            })
            .collect()
    })
}

impl From<TexelArray> for Texels {
    fn from(array: TexelArray) -> Self {
        match array {
            TexelArray::Rgba8(t) => Texels::Rgba8(t),
            TexelArray::Rgba16(t) => Texels::Rgba16(t),
            TexelArray::RgbaF32(t) => Texels::RgbaF32(t),
        }
    }
}

/// How coordinates outside [0, 1) map into the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Wrap {
    Repeat,
    MirroredRepeat,
    ClampToEdge,
}

/// The most probes a footprint lookup takes along its major axis: footprints longer than
/// this many times their width are widened (blurred) to this ratio, as pbrt-v4 clamps its
/// EWA filter's eccentricity and GPUs their anisotropy.
pub const MAX_ANISOTROPY: f32 = 8.0;

/// The MIP pyramids of one image (levels 1 and up; level 0 is the image), built on first
/// use: one for reading integer texels as sRGB colour, one for reading them as they are
/// (float images use the second for both). Textures that share texels share this.
#[derive(Debug, Default)]
pub struct MipChains {
    chains: [OnceLock<Vec<Level>>; 2],
}

/// One level of a MIP pyramid.
#[derive(Debug)]
struct Level {
    width: u32,
    height: u32,
    texels: Texels,
}

impl MipChains {
    /// Bytes held by the pyramids built so far.
    pub fn memory_bytes(&self) -> usize {
        self.chains
            .iter()
            .filter_map(OnceLock::get)
            .flatten()
            .map(|l| texels_bytes(&l.texels))
            .sum()
    }
}

/// A 2D image with its sampler.
#[derive(Clone, Debug)]
pub struct Texture {
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Shared: several textures (sampler variants) and the environment may use one image.
    pub texels: Arc<Texels>,
    /// The image's MIP pyramids, shared by the textures that share its texels (the world
    /// joins them: [`share_mip_chains`]).
    pub mips: Arc<MipChains>,
    pub wrap_u: Wrap,
    pub wrap_v: Wrap,
    /// Nearest-texel lookups instead of bilinear when magnified (glTF magFilter NEAREST).
    pub nearest: bool,
    /// Whether footprint lookups may use MIP levels (false where the sampler asks for none:
    /// glTF minFilter NEAREST or LINEAR): without, they are the point lookup.
    pub mipmaps: bool,
    /// For a UDIM texture set, its tiles; the texture's own image is then what coordinates
    /// without a tile read (the asset's fallback colour).
    pub udim: Option<Arc<Udim<Texture>>>,
}

#[inline]
fn wrap(i: i64, n: u32, mode: Wrap) -> usize {
    let n = n as i64;
    (match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let period = i.rem_euclid(2 * n);
            if period < n {
                period
            } else {
                2 * n - 1 - period
            }
        }
    }) as usize
}

/// Bytes `texels` hold in memory (a tiled image's tiles are the cache's).
pub fn texels_bytes(texels: &Texels) -> usize {
    match texels {
        Texels::Rgba8(t) => t.len() * 4,
        Texels::Rgba16(t) => t.len() * 8,
        Texels::RgbaF32(t) => t.len() * 16,
        Texels::Tiled(_) => 0,
    }
}

/// Texel `i` (row-major) of `texels`, linear (sRGB-decoded where `srgb` is set and the
/// texels are integers).
#[inline]
fn fetch(texels: &Texels, i: usize, srgb: bool) -> Vec4 {
    match texels {
        Texels::Rgba8(t) => rgba8_to_linear(t[i], srgb),
        Texels::Rgba16(t) => rgba16_to_linear(t[i], srgb),
        Texels::RgbaF32(t) => Vec4::from_array(t[i]),
        Texels::Tiled(image) => {
            let level = image.base();
            let width = level.width as usize;
            image.texel(level, i % width, i / width, srgb)
        }
    }
}

impl Texture {
    #[inline]
    fn texel(&self, x: usize, y: usize, srgb: bool) -> Vec4 {
        fetch(&self.texels, y * self.width as usize + x, srgb)
    }

    /// The texels a bilinear lookup of `uv` in a `width` × `height` image blends (columns
    /// and rows, wrapped) and its weights across and down.
    #[inline(always)]
    fn corners(&self, (width, height): (u32, u32), uv: Vec2) -> ([usize; 2], [usize; 2], f32, f32) {
        let x = uv.x as f64 * width as f64 - 0.5;
        let y = uv.y as f64 * height as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        // Coordinates beyond i64 (texture coordinates near f32's limits) saturate, and the
        // next texel wraps round: any texel of the image is as good an answer there.
        let (x0, y0) = (x0 as i64, y0 as i64);
        let xs = [
            wrap(x0, width, self.wrap_u),
            wrap(x0.wrapping_add(1), width, self.wrap_u),
        ];
        let ys = [
            wrap(y0, height, self.wrap_v),
            wrap(y0.wrapping_add(1), height, self.wrap_v),
        ];
        (xs, ys, fx, fy)
    }

    /// Bilinear lookup of `uv` in an image of `width` × `height` `texels`.
    #[inline]
    fn bilinear(&self, texels: &Texels, (width, height): (u32, u32), uv: Vec2, srgb: bool) -> Vec4 {
        if let Texels::Tiled(image) = texels {
            return self.bilinear_tiled(image, image.base(), uv, srgb);
        }
        let ([xa, xb], [ya, yb], fx, fy) = self.corners((width, height), uv);
        let (ya, yb) = (ya * width as usize, yb * width as usize);
        // One match for the four texels, so that each format's loads are inlined together.
        let (c00, c10, c01, c11) = match texels {
            Texels::Rgba8(t) => (
                rgba8_to_linear(t[ya + xa], srgb),
                rgba8_to_linear(t[ya + xb], srgb),
                rgba8_to_linear(t[yb + xa], srgb),
                rgba8_to_linear(t[yb + xb], srgb),
            ),
            Texels::Rgba16(t) => (
                rgba16_to_linear(t[ya + xa], srgb),
                rgba16_to_linear(t[ya + xb], srgb),
                rgba16_to_linear(t[yb + xa], srgb),
                rgba16_to_linear(t[yb + xb], srgb),
            ),
            Texels::RgbaF32(t) => (
                Vec4::from_array(t[ya + xa]),
                Vec4::from_array(t[ya + xb]),
                Vec4::from_array(t[yb + xa]),
                Vec4::from_array(t[yb + xb]),
            ),
            Texels::Tiled(_) => unreachable!("tiled images are looked up above"),
        };
        c00.lerp(c10, fx).lerp(c01.lerp(c11, fx), fy)
    }

    /// Bilinear lookup of `uv` in `level` of the tiled `image`: the same blend of the same
    /// texels as [`Texture::bilinear`] in memory.
    fn bilinear_tiled(
        &self,
        image: &TiledImage,
        level: &LevelLayout,
        uv: Vec2,
        srgb: bool,
    ) -> Vec4 {
        let ([xa, xb], [ya, yb], fx, fy) = self.corners((level.width, level.height), uv);
        let c00 = image.texel(level, xa, ya, srgb);
        let c10 = image.texel(level, xb, ya, srgb);
        let c01 = image.texel(level, xa, yb, srgb);
        let c11 = image.texel(level, xb, yb, srgb);
        c00.lerp(c10, fx).lerp(c01.lerp(c11, fx), fy)
    }

    /// Looks up `uv` (glTF convention: (0, 0) is the image's top-left corner), decoding sRGB
    /// 8-bit texels to linear when `srgb` is set. Bilinear unless the sampler says nearest.
    pub fn sample(&self, uv: Vec2, srgb: bool) -> Vec4 {
        if let Some(udim) = &self.udim
            && let Some((tile, at)) = udim.tile(uv)
        {
            return tile.sample(at, srgb);
        }
        if !uv.is_finite() {
            return self.texel(0, 0, srgb);
        }
        if self.nearest {
            let x = uv.x as f64 * self.width as f64 - 0.5;
            let y = uv.y as f64 * self.height as f64 - 0.5;
            let xi = wrap((x + 0.5).floor() as i64, self.width, self.wrap_u);
            let yi = wrap((y + 0.5).floor() as i64, self.height, self.wrap_v);
            return self.texel(xi, yi, srgb);
        }
        self.bilinear(&self.texels, (self.width, self.height), uv, srgb)
    }

    /// The filtered value over the footprint centred on `uv` whose axes (full widths, in
    /// texture coordinates) are `axes`: anisotropic trilinear filtering (see the module
    /// notes); [`Texture::sample`] where the footprint is at most a texel.
    pub fn sample_footprint(&self, uv: Vec2, axes: [Vec2; 2], srgb: bool) -> Vec4 {
        if let Some(udim) = &self.udim
            && let Some((tile, at)) = udim.tile(uv)
        {
            return tile.sample_footprint(at, axes, srgb);
        }
        let size = Vec2::new(self.width as f32, self.height as f32);
        let (a, b) = (axes[0] * size, axes[1] * size);
        let (la, lb) = (a.length(), b.length());
        let (major, minor, along) = if la >= lb {
            (la, lb, axes[0])
        } else {
            (lb, la, axes[1])
        };
        if !(major > 1.0) || !major.is_finite() || !uv.is_finite() || !self.mipmaps {
            return self.sample(uv, srgb);
        }
        let minor = minor.max(major / MAX_ANISOTROPY).max(1.0);
        let lod = minor.log2();
        let probes = ((major / minor).ceil() as usize).clamp(1, MAX_ANISOTROPY as usize);
        let probe = |i: usize| uv + along * ((i as f32 + 0.5) / probes as f32 - 0.5);
        let mut sum = Vec4::ZERO;
        if let Texels::Tiled(image) = &*self.texels {
            let levels = tiled_levels(image, srgb);
            for i in 0..probes {
                let uv = probe(i);
                sum += trilinear(levels.len() - 1, lod, |l| {
                    self.bilinear_tiled(image, &levels[l], uv, srgb)
                });
            }
        } else {
            let chain = self.chain(srgb);
            for i in 0..probes {
                let uv = probe(i);
                sum += trilinear(chain.len(), lod, |l| match l {
                    0 => self.bilinear(&self.texels, (self.width, self.height), uv, srgb),
                    l => {
                        let l = &chain[l - 1];
                        self.bilinear(&l.texels, (l.width, l.height), uv, srgb)
                    }
                });
            }
        }
        sum / probes as f32
    }

    /// The MIP pyramid for reading the texels with `srgb`, built on first use.
    fn chain(&self, srgb: bool) -> &[Level] {
        let srgb = srgb && !matches!(*self.texels, Texels::RgbaF32(_));
        self.mips.chains[srgb as usize]
            .get_or_init(|| build_chain(&self.texels, self.width, self.height, srgb))
    }

    /// Builds the MIP pyramid for reading the texels with `srgb` now, if it is not built
    /// (a render builds those its materials read before it starts, in parallel, instead of
    /// stalling its threads on the first lookups).
    pub fn build_mips(&self, srgb: bool) {
        match &*self.texels {
            Texels::Tiled(image) => drop(tiled_levels(image, srgb)),
            _ => drop(self.chain(srgb)),
        }
        for tile in self.udim.iter().flat_map(|u| u.images()) {
            tile.build_mips(srgb);
        }
    }

    /// Whether the image, or a tile of its UDIM set, lies in a tiled file (`texture_cache`).
    pub fn is_tiled(&self) -> bool {
        matches!(*self.texels, Texels::Tiled(_))
            || (self.udim.iter().flat_map(|u| u.images())).any(Texture::is_tiled)
    }

    /// Mean linear value over the image (for light power estimates; a UDIM set's own image
    /// is its fallback).
    pub fn mean(&self, srgb: bool) -> Vec4 {
        let n = (self.width as usize * self.height as usize).max(1);
        let mut sum = glam::DVec4::ZERO;
        if let Texels::Tiled(image) = &*self.texels {
            // Tile by tile rather than row by row: each tile is read once.
            let level = image.base();
            for (x0, y0, x1, y1) in level.tiles() {
                for y in y0..y1 {
                    for x in x0..x1 {
                        sum += image.texel(level, x, y, srgb).as_dvec4();
                    }
                }
            }
            return (sum / n as f64).as_vec4();
        }
        for y in 0..self.height as usize {
            for x in 0..self.width as usize {
                sum += self.texel(x, y, srgb).as_dvec4();
            }
        }
        (sum / n as f64).as_vec4()
    }

    /// Bytes held by the texels (the image; its MIP pyramids are counted by
    /// [`MipChains::memory_bytes`]).
    pub fn memory_bytes(&self) -> usize {
        texels_bytes(&self.texels)
    }

    /// Linear value of texel (`x`, `y`) without filtering (for building sampling tables).
    pub fn texel_linear(&self, x: u32, y: u32, srgb: bool) -> Vec4 {
        self.texel(x as usize, y as usize, srgb)
    }
}

/// The tile cache the tiled images among `textures` are read through, if any is tiled (a
/// scene's tiled images share one).
pub fn cache_of(textures: &[Texture]) -> Option<&Arc<TextureCache>> {
    textures.iter().find_map(|t| match &*t.texels {
        Texels::Tiled(image) => Some(image.cache()),
        _ => None,
    })
}

/// Trilinear blend at (fractional) MIP level `lod` ≥ 0 of a pyramid whose `top` level is
/// the coarsest, `at(level)` the bilinear lookup at an integer level.
#[inline]
fn trilinear(top: usize, lod: f32, at: impl Fn(usize) -> Vec4) -> Vec4 {
    let lod = lod.min(top as f32);
    let fine = lod.floor();
    let t = lod - fine;
    let fine_value = at(fine as usize);
    if t == 0.0 {
        return fine_value;
    }
    fine_value.lerp(at(fine as usize + 1), t)
}

/// MIP levels 1 and up of the `width` × `height` image `texels` read with `srgb`, each half
/// the size of the one before (rounded down, at least one texel), box-filtered from the one
/// before in linear values, as GPUs generate MIP maps: no level needs a copy of another at
/// higher precision, and an 8-bit level's rounding (half a step) is what the next one starts
/// from. A tiled image has its levels on disk: none here.
fn build_chain(texels: &Texels, width: u32, height: u32, srgb: bool) -> Vec<Level> {
    let (mut w, mut h) = (width as usize, height as usize);
    let mut levels: Vec<Level> = Vec::new();
    if matches!(texels, Texels::Tiled(_)) {
        return levels;
    }
    while w > 1 || h > 1 {
        let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
        let source = levels.last().map_or(texels, |l| &l.texels);
        let src = |i| fetch(source, i, srgb);
        let (from, to) = ((w, h), (nw, nh));
        let level = match texels {
            Texels::Rgba8(_) => Texels::Rgba8(box_downsample(src, from, to, |v| {
                encode(v, 255.0, srgb).map(|x| x as u8)
            })),
            Texels::Rgba16(_) => Texels::Rgba16(box_downsample(src, from, to, |v| {
                encode(v, 65535.0, srgb).map(|x| x as u16)
            })),
            Texels::RgbaF32(_) | Texels::Tiled(_) => {
                Texels::RgbaF32(box_downsample(src, from, to, |v| v.to_array()))
            }
        };
        (w, h) = (nw, nh);
        levels.push(Level {
            width: w as u32,
            height: h as u32,
            texels: level,
        });
    }
    levels
}

/// The UDIM set of `tiles` (tile number, index into `textures`): each tile's image must be
/// a texture of its own, not another set. Errors name the problem.
pub fn udim_set(tiles: Vec<(u32, u32)>, textures: &[Texture]) -> Result<Udim<Texture>, String> {
    Udim::new(tiles, |index| match textures.get(index as usize) {
        None => Err(format!("texture index {index} out of range")),
        Some(t) if t.udim.is_some() => Err(format!("texture {index} is itself a UDIM set")),
        Some(t) => Ok(t.clone()),
    })
}

/// Makes the textures that share texels share one set of MIP pyramids, so that sampler
/// variants of an image, and a UDIM tile used elsewhere too, build its pyramid once.
pub fn share_mip_chains(textures: &mut [Texture]) {
    let mut by_image: std::collections::HashMap<*const Texels, Arc<MipChains>> =
        std::collections::HashMap::new();
    let mut share = |t: &Texture| {
        let shared = by_image
            .entry(Arc::as_ptr(&t.texels))
            .or_insert_with(|| t.mips.clone());
        Texture {
            mips: shared.clone(),
            ..t.clone()
        }
    };
    for t in textures.iter_mut() {
        t.mips = share(t).mips;
    }
    for t in textures.iter_mut() {
        if let Some(udim) = &t.udim {
            t.udim = Some(Arc::new(udim.map_images(&mut share)));
        }
    }
}

/// Box filter of a `from`-sized image whose texel `i` (row-major) is `src(i)` to `to` (each
/// side at most as large as `from`'s), stored through `store`: every target texel the
/// area-weighted mean of the source texels it covers. Rows in parallel.
fn box_downsample<T: Copy + Default + Send>(
    src: impl Fn(usize) -> Vec4 + Sync,
    from: (usize, usize),
    to: (usize, usize),
    store: impl Fn(Vec4) -> T + Sync,
) -> Vec<T> {
    use rayon::prelude::*;
    let weights = |n: usize, m: usize| -> Vec<Vec<(usize, f32)>> {
        let scale = n as f64 / m as f64;
        (0..m)
            .map(|i| {
                let (lo, hi) = (i as f64 * scale, (i + 1) as f64 * scale);
                (lo.floor() as usize..(hi.ceil() as usize).min(n))
                    .map(|j| {
                        let cover = (hi.min(j as f64 + 1.0) - lo.max(j as f64)) / scale;
                        (j, cover as f32)
                    })
                    .filter(|(_, w)| *w > 0.0)
                    .collect()
            })
            .collect()
    };
    let (wx, wy) = (weights(from.0, to.0), weights(from.1, to.1));
    let mut out = vec![T::default(); to.0 * to.1];
    out.par_chunks_mut(to.0).zip(&wy).for_each(|(row, rows)| {
        for (texel, columns) in row.iter_mut().zip(&wx) {
            let mut sum = Vec4::ZERO;
            for &(y, wy) in rows {
                for &(x, wx) in columns {
                    sum += src(y * from.0 + x) * (wx * wy);
                }
            }
            *texel = store(sum);
        }
    });
    out
}

/// A linear value as integer steps of `max`, rounded: colour channels sRGB-encoded where
/// `srgb` is set, alpha never.
#[inline]
fn encode(v: Vec4, max: f32, srgb: bool) -> [f32; 4] {
    let c = |x: f32| {
        let x = if srgb { linear_to_srgb(x) } else { x };
        (x.clamp(0.0, 1.0) * max).round()
    };
    [c(v.x), c(v.y), c(v.z), (v.w.clamp(0.0, 1.0) * max).round()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_modes() {
        assert_eq!(wrap(-1, 4, Wrap::Repeat), 3);
        assert_eq!(wrap(5, 4, Wrap::Repeat), 1);
        assert_eq!(wrap(-1, 4, Wrap::ClampToEdge), 0);
        assert_eq!(wrap(9, 4, Wrap::ClampToEdge), 3);
        assert_eq!(wrap(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(-1, 4, Wrap::MirroredRepeat), 0);
        assert_eq!(wrap(8, 4, Wrap::MirroredRepeat), 0);
    }

    #[test]
    fn coordinates_at_the_limits_of_f32_read_a_texel() {
        // Found by fuzzing: the texel index saturates at i64::MAX; the next one wrapped
        // with an overflow.
        for wrap_mode in [Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge] {
            let t = Texture {
                wrap_u: wrap_mode,
                wrap_v: wrap_mode,
                ..grey(5, 3, |x, y| (x * 40 + y) as u8)
            };
            for uv in [
                Vec2::new(3e38, -3e38),
                Vec2::splat(f32::MAX),
                Vec2::splat(f32::MIN),
            ] {
                assert!(t.sample(uv, true).is_finite());
                assert!(
                    t.sample_footprint(uv, [Vec2::X, Vec2::Y], false)
                        .is_finite()
                );
            }
        }
    }

    #[test]
    fn bilinear_lookup_interpolates_between_texel_centres() {
        let t = Texture {
            name: String::new(),
            width: 2,
            height: 1,
            texels: Arc::new(Texels::RgbaF32(vec![[0.0; 4], [1.0; 4]])),
            mips: Default::default(),
            wrap_u: Wrap::ClampToEdge,
            wrap_v: Wrap::ClampToEdge,
            nearest: false,
            mipmaps: true,
            udim: None,
        };
        assert!((t.sample(Vec2::new(0.25, 0.5), false).x - 0.0).abs() < 1e-6);
        assert!((t.sample(Vec2::new(0.5, 0.5), false).x - 0.5).abs() < 1e-6);
        assert!((t.sample(Vec2::new(0.75, 0.5), false).x - 1.0).abs() < 1e-6);
    }

    /// A `w` × `h` 8-bit image of `value(x, y)` grey texels.
    fn grey(w: u32, h: u32, value: impl Fn(u32, u32) -> u8) -> Texture {
        let texels = (0..w * h).map(|i| [value(i % w, i / w); 4]).collect();
        Texture {
            name: String::new(),
            width: w,
            height: h,
            texels: Arc::new(Texels::Rgba8(texels)),
            mips: Default::default(),
            wrap_u: Wrap::Repeat,
            wrap_v: Wrap::Repeat,
            nearest: false,
            mipmaps: true,
            udim: None,
        }
    }

    #[test]
    fn pyramids_average_in_linear_values_down_to_one_texel() {
        // Black and white checks: the sRGB colour level averages decoded values (0.5,
        // stored sRGB-encoded as 188), the data level the stored ones (0.5 of 255: 128).
        let t = grey(4, 4, |x, y| if (x + y) % 2 == 1 { 255 } else { 0 });
        let colour = t.chain(true);
        assert_eq!(colour.len(), 2);
        let Texels::Rgba8(c) = &colour[1].texels else {
            panic!("levels keep the image's format")
        };
        assert_eq!(c[0][0], 188);
        assert_eq!(c[0][3], 128, "alpha is never sRGB-encoded");
        let Texels::Rgba8(d) = &t.chain(false)[1].texels else {
            panic!()
        };
        assert_eq!(d[0][0], 128);
    }

    #[test]
    fn odd_sizes_are_box_filtered_by_area() {
        // 3 texels to 1: each covers a third.
        let out = box_downsample(|i| Vec4::splat(i as f32), (3, 1), (1, 1), |v| v);
        assert!((out[0].x - 1.0).abs() < 1e-6);
        // 5 × 3 to 2 × 1: the middle column is shared half and half; the mean is kept.
        let src = |i: usize| Vec4::splat((i * 7 % 11) as f32);
        let out = box_downsample(src, (5, 3), (2, 1), |v| v);
        let mean_in = (0..15).map(|i| src(i).x).sum::<f32>() / 15.0;
        assert!(((out[0].x + out[1].x) / 2.0 - mean_in).abs() < 1e-5);
        let t = grey(5, 3, |x, _| 50 * x as u8);
        let sizes: Vec<(u32, u32)> = t.chain(false).iter().map(|l| (l.width, l.height)).collect();
        assert_eq!(sizes, [(2, 1), (1, 1)]);
    }

    #[test]
    fn footprints_of_a_texel_or_less_are_bilinear_lookups() {
        let t = grey(8, 8, |x, y| (x * 30 + y * 3) as u8);
        for uv in [Vec2::new(0.3, 0.7), Vec2::new(-1.2, 5.01)] {
            let small = [Vec2::new(0.1, 0.0), Vec2::new(0.0, 0.05)];
            assert_eq!(t.sample_footprint(uv, small, true), t.sample(uv, true));
            assert_eq!(
                t.sample_footprint(uv, [Vec2::ZERO; 2], true),
                t.sample(uv, true)
            );
        }
        // A sampler without MIP levels looks up the point whatever the footprint.
        let point = Texture {
            mipmaps: false,
            ..t.clone()
        };
        let uv = Vec2::new(0.3, 0.7);
        assert_eq!(
            point.sample_footprint(uv, [Vec2::X, Vec2::Y], true),
            t.sample(uv, true)
        );
    }

    #[test]
    fn wide_footprints_see_the_mean_and_long_ones_only_along_their_axis() {
        // Vertical stripes, one texel each: a footprint as wide as the image is their mean;
        // one long in v and a texel wide in u keeps them apart (probes along v, a fine
        // level), where an isotropic one of its length would blur them.
        let t = grey(64, 64, |x, _| if x % 2 == 1 { 255 } else { 0 });
        let mean = t.mean(false).x;
        let wide = t
            .sample_footprint(Vec2::splat(0.5), [Vec2::X, Vec2::Y], false)
            .x;
        assert!((wide - mean).abs() < 1e-2, "{wide} against {mean}");
        let uv = Vec2::new(1.5 / 64.0, 0.5);
        let long = [Vec2::new(1.0 / 64.0, 0.0), Vec2::new(0.0, 8.0 / 64.0)];
        let along = t.sample_footprint(uv, long, false).x;
        assert!((along - 1.0).abs() < 1e-6, "stripe kept: {along}");
    }

    /// A `w` × `h` image of 8-bit, 16-bit or float texels (`kind` 0, 1, 2) that differ
    /// everywhere.
    fn varied(kind: u32, w: u32, h: u32) -> Texels {
        let value = |i: u32, c: u32| ((i * 37 + c * 101) % 251) as f32 / 250.0;
        let n = w * h;
        match kind {
            0 => Texels::Rgba8(
                (0..n)
                    .map(|i| std::array::from_fn(|c| (value(i, c as u32) * 255.0) as u8))
                    .collect(),
            ),
            1 => Texels::Rgba16(
                (0..n)
                    .map(|i| std::array::from_fn(|c| (value(i, c as u32) * 65535.0) as u16))
                    .collect(),
            ),
            _ => Texels::RgbaF32(
                (0..n)
                    .map(|i| std::array::from_fn(|c| value(i, c as u32) * 4.0))
                    .collect(),
            ),
        }
    }

    #[test]
    fn lookups_through_the_tile_cache_equal_lookups_in_memory_bit_for_bit() {
        // A cache of a few tiles, so that tiles are evicted and read again while looking up.
        let cache = TextureCache::new(6 * 64 * 64 * 16);
        let mut rng = crate::sampling::pcg::Pcg32::new(7, 1);
        let mut next = || rng.next_f32();
        for kind in 0..3 {
            for (w, h, wrap) in [
                (150, 70, Wrap::Repeat),
                (64, 64, Wrap::MirroredRepeat),
                (300, 1, Wrap::ClampToEdge),
            ] {
                let memory = Texture {
                    wrap_u: wrap,
                    texels: Arc::new(varied(kind, w, h)),
                    ..grey(w, h, |_, _| 0)
                };
                let tiled = memory.texels.to_tiled("t", w, h, &cache).unwrap();
                let on_disk = Texture {
                    texels: Arc::new(tiled),
                    mips: Default::default(),
                    ..memory.clone()
                };
                for srgb in [false, true] {
                    assert_eq!(on_disk.mean(srgb), memory.mean(srgb));
                    for _ in 0..2000 {
                        let uv = Vec2::new(next() * 3.0 - 1.0, next() * 3.0 - 1.0);
                        let scale = 2f32.powf(next() * 12.0 - 10.0);
                        let axes = [
                            Vec2::new(next() - 0.5, next() - 0.5) * scale,
                            Vec2::new(next() - 0.5, next() - 0.5) * scale * next(),
                        ];
                        assert_eq!(on_disk.sample(uv, srgb), memory.sample(uv, srgb));
                        assert_eq!(
                            on_disk.sample_footprint(uv, axes, srgb),
                            memory.sample_footprint(uv, axes, srgb),
                            "kind {kind} {w}x{h} uv {uv} axes {axes:?} srgb {srgb}"
                        );
                    }
                }
                let Texels::Tiled(image) = &*on_disk.texels else {
                    unreachable!()
                };
                let back = Texels::from(image.read_all());
                let texels = |t: &Texels| -> Vec<Vec4> {
                    (0..(w * h) as usize).map(|i| fetch(t, i, false)).collect()
                };
                assert_eq!(texels(&back), texels(&memory.texels));
            }
        }
        let stats = cache.stats();
        assert_eq!(stats.images, 9);
        assert!(stats.resident <= cache.capacity(), "{stats:?}");
        assert!(
            stats.tiles_read > 100,
            "a small cache reads tiles again: {stats:?}"
        );
    }
}
