//! The film: per-pixel accumulation of every requested AOV, in tiles so that threads own
//! disjoint memory. Samples of one pixel are summed in f64 in sample order before they
//! reach the tile, so a pixel's value does not depend on the thread count.
//!
//! The film defines what it accepts (`record`: tagged contributions and first-hit data,
//! handed over through a `Recorder`), routes contributions to the AOVs that want them
//! (`aov`, `router`), accumulates them (`tile`) and gives its layers out as named planes
//! (`planes`), from which it can also be restored. Writing files is `output`'s job.

pub mod aov;
pub mod crypto;
pub mod filter;
pub mod planes;
pub mod record;
pub mod router;
pub mod tile;
pub mod window;

use crate::camera::Overscan;
use aov::{Aov, AovSet, MEAN_DATA};
use glam::{DVec3, Vec3};
use planes::Planes;
pub use router::{Router, SampleRecord};
pub use tile::{PixelAccumulator, Tile};
pub use window::Window;

/// Tile edge in pixels.
pub const TILE_SIZE: u32 = 16;
/// Depth written where the camera saw nothing (as Cycles does).
pub const BACKGROUND_DEPTH: f32 = 1e10;

/// The constant relMSE adds to the squared reference in its denominator, so that dark
/// pixels do not dominate (relMSE = mean of (x - ref)² / (ref² + 0.01); see
/// docs/architecture.md, "Accuracy and speed").
pub const RELATIVE_ERROR_FLOOR: f64 = 0.01;

/// All tiles of an image's window plus the AOV set and routing. Tiles, and the sample
/// sequences of their pixels, are placed in image coordinates, so that a window renders
/// exactly the pixels the whole image would.
pub struct Film {
    /// Size of the window (the pixels this film holds).
    pub width: u32,
    pub height: u32,
    /// Where those pixels lie in the image.
    pub window: Window,
    /// Size of the whole image rendered, overscan included (the EXR's display window
    /// grown by the overscan).
    pub display: (u32, u32),
    /// Pixels of `display` beyond the edges of the image proper.
    pub overscan: Overscan,
    pub aovs: AovSet,
    pub router: Router,
    pub tiles: Vec<Tile>,
    /// Cryptomatte ids of the objects and materials, by index (set with the Cryptomatte
    /// layers).
    pub crypto_ids: crypto::Ids,
}

impl Film {
    /// An empty film of `width` × `height` pixels for `aovs`; `adaptive` also keeps what
    /// adaptive sampling decides from (sums of squares, rays per pixel).
    pub fn new(width: u32, height: u32, aovs: AovSet, adaptive: bool) -> Self {
        Self::cropped((width, height), Window::full(width, height), aovs, adaptive)
    }

    /// An empty film holding `window` of a `display`-sized image.
    pub fn cropped(display: (u32, u32), window: Window, aovs: AovSet, adaptive: bool) -> Self {
        let router = Router::new(&aovs);
        let mut tiles = Vec::new();
        let (x_end, y_end) = (window.x + window.width, window.y + window.height);
        for y0 in (window.y..y_end).step_by(TILE_SIZE as usize) {
            for x0 in (window.x..x_end).step_by(TILE_SIZE as usize) {
                let (w, h) = (TILE_SIZE.min(x_end - x0), TILE_SIZE.min(y_end - y0));
                tiles.push(Tile::new(x0, y0, w, h, router.slots.len(), &aovs, adaptive));
            }
        }
        Self {
            width: window.width,
            height: window.height,
            overscan: Overscan::default(),
            window,
            display,
            aovs,
            router,
            tiles,
            crypto_ids: crypto::Ids::default(),
        }
    }

    /// Row-major index in the film of image pixel (`x`, `y`).
    #[inline]
    pub fn index(&self, x: u32, y: u32) -> usize {
        self.window.index(x, y)
    }

    /// Bytes a film of `width` × `height` pixels for `aovs` holds once written: its tiles'
    /// accumulators and, while the EXR is written, one f32 plane per output channel.
    pub fn estimated_bytes(width: u32, height: u32, aovs: &AovSet, adaptive: bool) -> u64 {
        let slots = Router::new(aovs).slots.len() as u64;
        let vec3 = std::mem::size_of::<Vec3>() as u64;
        let mut per_pixel = slots * vec3 + 4 + 4; // light slots, coverage, sample count
        if aovs.contains(Aov::Variance) || adaptive {
            per_pixel += 2 * std::mem::size_of::<DVec3>() as u64;
        }
        if adaptive {
            per_pixel += 8; // rays
        }
        for aov in MEAN_DATA {
            per_pixel += if aovs.contains(aov) { vec3 } else { 0 };
        }
        per_pixel += if aovs.contains(Aov::Depth) { 4 } else { 0 };
        if aovs.wants_crypto() {
            // Two lists a pixel; their length varies: counted for four objects each.
            let list = std::mem::size_of::<crypto::Counts>() as u64;
            per_pixel += 2 * (list + 4 * 8);
        }
        let channels: u64 = aovs.iter().map(|aov| aov.channels().len() as u64).sum();
        width as u64 * height as u64 * (per_pixel + 4 * channels)
    }

    /// Continues from an earlier render of the same window and AOVs (a checkpoint read
    /// back): `planes` must hold every AOV of this film and `spp`. The sums are rebuilt as
    /// mean × samples (exact up to float rounding); sums of squares, where this film keeps
    /// them, from the `variance` layer. `discarded` is the checkpoint's NaN/Inf count.
    pub fn restore(&mut self, planes: &Planes, discarded: u64) -> Result<(), String> {
        if planes.display != self.display || planes.window != self.window {
            return Err(format!(
                "it holds pixels {} of a {}x{} image; this render is pixels {} of {}x{}",
                planes.window.describe(),
                planes.display.0,
                planes.display.1,
                self.window.describe(),
                self.display.0,
                self.display.1
            ));
        }
        let channel = |name: &str| {
            planes
                .channel(name)
                .ok_or_else(|| format!("it has no channel {name}"))
        };
        let layer = |aov: Aov| -> Result<Vec<&[f32]>, String> {
            self.aovs
                .channel_names(aov)
                .iter()
                .map(|n| channel(n))
                .collect()
        };
        // Values that would poison every later sample: refused.
        for (name, plane) in &planes.channels {
            if let Some(i) = plane.iter().position(|v| !v.is_finite()) {
                return Err(format!("channel {name} holds {} at pixel {i}", plane[i]));
            }
        }
        let spp = channel("spp.Y")?;
        if let Some(i) = spp.iter().position(|v| *v < 0.0 || v.fract() != 0.0) {
            return Err(format!(
                "spp.Y holds {} at pixel {i}: sample counts are whole and not negative",
                spp[i]
            ));
        }
        let light: Vec<Vec<&[f32]>> = self
            .router
            .slots
            .iter()
            .map(|&a| layer(a))
            .collect::<Result<_, _>>()?;
        let data = |aov: Aov| -> Result<Option<Vec<&[f32]>>, String> {
            if self.aovs.contains(aov) {
                layer(aov).map(Some)
            } else {
                Ok(None)
            }
        };
        let means = MEAN_DATA
            .iter()
            .map(|&aov| data(aov))
            .collect::<Result<Vec<_>, _>>()?;
        let depth = data(Aov::Depth)?;
        if self.aovs.wants_crypto() {
            return Err("Cryptomatte keeps every object's sample count, more than its six ranks in the EXR: a render with crypto layers cannot be continued".into());
        }
        let keeps_squares = self.tiles.first().is_some_and(|t| !t.beauty_sum.is_empty());
        if keeps_squares && !self.aovs.contains(Aov::Variance) {
            return Err(
                "adaptive sampling cannot continue a render without its variance layer".into(),
            );
        }
        let variance = data(Aov::Variance)?;
        if let Some(bad) = spp
            .iter()
            .find(|n| !(n.is_finite() && **n >= 0.0 && n.fract() == 0.0 && **n < 2e9))
        {
            return Err(format!("its spp layer holds {bad}, not a sample count"));
        }
        let window = self.window;
        for tile in &mut self.tiles {
            let tn = tile.pixel_count();
            for ty in 0..tile.height {
                for tx in 0..tile.width {
                    let p = (ty * tile.width + tx) as usize;
                    let i = window.index(tile.x0 + tx, tile.y0 + ty);
                    let n = spp[i];
                    // Two-channel layers (motion) leave z at zero.
                    let vec3 = |planes: &[&[f32]]| {
                        Vec3::new(
                            planes[0][i],
                            planes[1][i],
                            planes.get(2).map_or(0.0, |p| p[i]),
                        )
                    };
                    tile.samples[p] = n as u32;
                    for (slot, planes) in light.iter().enumerate() {
                        tile.light[slot * tn + p] = vec3(planes) * n;
                    }
                    tile.coverage[p] = light[0][3][i] * n;
                    for (sums, planes) in tile.data.iter_mut().zip(&means) {
                        if let Some(planes) = planes {
                            sums[p] = vec3(planes) * n;
                        }
                    }
                    if let Some(d) = &depth {
                        let d = d[0][i];
                        tile.depth[p] = if d >= BACKGROUND_DEPTH {
                            f32::INFINITY
                        } else {
                            d
                        };
                    }
                    if keeps_squares {
                        let n = n as f64;
                        let sum = vec3(&light[0]).as_dvec3() * n;
                        let var = variance
                            .as_ref()
                            .map_or(DVec3::ZERO, |v| vec3(v).as_dvec3());
                        tile.beauty_sum[p] = sum;
                        tile.beauty_squares[p] = if n > 0.0 {
                            var * n * (n - 1.0) + sum * sum / n
                        } else {
                            DVec3::ZERO
                        };
                    }
                }
            }
            tile.discarded = 0;
        }
        if let Some(first) = self.tiles.first_mut() {
            first.discarded = discarded;
        }
        Ok(())
    }

    /// Contributions dropped as NaN or infinite, over the whole image.
    pub fn discarded(&self) -> u64 {
        self.tiles.iter().map(|t| t.discarded).sum()
    }

    /// The most samples any pixel took.
    pub fn max_samples(&self) -> u32 {
        self.tiles
            .iter()
            .flat_map(|t| &t.samples)
            .copied()
            .max()
            .unwrap_or(0)
    }

    /// The fewest samples any pixel took.
    pub fn min_samples(&self) -> u32 {
        self.tiles
            .iter()
            .flat_map(|t| &t.samples)
            .copied()
            .min()
            .unwrap_or(0)
    }

    /// Total samples taken.
    pub fn total_samples(&self) -> u64 {
        self.tiles
            .iter()
            .flat_map(|t| &t.samples)
            .map(|&s| s as u64)
            .sum()
    }

    /// The final image of `aov`: one row-major plane per channel.
    pub fn planes(&self, aov: Aov) -> Vec<Vec<f32>> {
        let channels = aov.channels().len();
        let n = (self.width * self.height) as usize;
        let mut planes = vec![vec![0.0f32; n]; channels];
        let slot = self.router.slots.iter().position(|&a| a == aov);
        let mean_slot = MEAN_DATA.iter().position(|&a| a == aov);
        for tile in &self.tiles {
            let tn = tile.pixel_count();
            for ty in 0..tile.height {
                for tx in 0..tile.width {
                    let p = (ty * tile.width + tx) as usize;
                    let out = self.index(tile.x0 + tx, tile.y0 + ty);
                    let spp = tile.samples[p] as f32;
                    let mean = |v: Vec3| if spp > 0.0 { v / spp } else { Vec3::ZERO };
                    let value: [f32; 4] = match (aov, slot) {
                        (Aov::Beauty, Some(s)) => mean(tile.light[s * tn + p])
                            .extend(if spp > 0.0 {
                                tile.coverage[p] / spp
                            } else {
                                0.0
                            })
                            .to_array(),
                        (_, Some(s)) => mean(tile.light[s * tn + p]).extend(0.0).to_array(),
                        (_, None) if mean_slot.is_some() => {
                            let sums = &tile.data[mean_slot.expect("checked")];
                            mean(sums[p]).extend(0.0).to_array()
                        }
                        (Aov::Depth, _) => {
                            let d = tile.depth[p];
                            [
                                if d.is_finite() { d } else { BACKGROUND_DEPTH },
                                0.0,
                                0.0,
                                0.0,
                            ]
                        }
                        (Aov::Spp, _) => [spp, 0.0, 0.0, 0.0],
                        (Aov::Crypto(kind, layer), _) => {
                            let k = match kind {
                                crypto::Kind::Object => 0,
                                crypto::Kind::Material => 1,
                            };
                            let ranks = crypto::ranks(
                                &tile.crypto[k][p],
                                self.crypto_ids.of(kind),
                                tile.samples[p],
                            );
                            let rank = |r: usize| {
                                ranks
                                    .get(r)
                                    .map_or((0.0, 0.0), |&(id, c)| (f32::from_bits(id), c))
                            };
                            let (a, b) = (rank(2 * layer as usize), rank(2 * layer as usize + 1));
                            [a.0, a.1, b.0, b.1]
                        }
                        (Aov::Variance, _) => {
                            let n = tile.samples[p] as f64;
                            let v = if n > 1.0 {
                                let s = tile.beauty_sum[p];
                                ((tile.beauty_squares[p] - s * s / n) / (n * (n - 1.0)))
                                    .max(DVec3::ZERO)
                            } else {
                                DVec3::ZERO
                            };
                            v.as_vec3().extend(0.0).to_array()
                        }
                        _ => unreachable!("light AOVs have slots"),
                    };
                    for (c, plane) in planes.iter_mut().enumerate() {
                        plane[out] = value[c];
                    }
                }
            }
        }
        planes
    }

    /// The channel names of the film's layers, with `extra` AOVs.
    pub fn channel_names(&self, extra: &[Aov]) -> Vec<String> {
        let mut aovs: Vec<Aov> = self.aovs.iter().collect();
        aovs.extend(extra.iter().filter(|a| !self.aovs.contains(**a)));
        aovs.into_iter()
            .flat_map(|aov| self.aovs.channel_names(aov))
            .collect()
    }

    /// The film's layers as planes: those that `keep` accepts (the beauty always; a render
    /// product of several that share a render keeps its own) and `extra` (say, the sample
    /// counts of a checkpoint).
    pub fn to_planes(&self, extra: &[Aov], keep: impl Fn(Aov) -> bool) -> Planes {
        let mut channels = Vec::new();
        let mut aovs: Vec<Aov> = self.aovs.iter().collect();
        aovs.extend(extra.iter().filter(|a| !self.aovs.contains(**a)));
        aovs.retain(|&a| a == Aov::Beauty || extra.contains(&a) || keep(a));
        for aov in aovs {
            channels.extend(
                self.aovs
                    .channel_names(aov)
                    .into_iter()
                    .zip(self.planes(aov)),
            );
        }
        Planes {
            display: self.display,
            window: self.window,
            overscan: self.overscan,
            channels,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The memory estimate of a film is what its tiles allocate, plus a f32 plane per output
    /// channel.
    #[test]
    fn estimated_bytes_match_the_allocation() {
        use std::mem::size_of_val;
        for (aovs, adaptive) in [
            (AovSet::default(), false),
            (AovSet::parse("").unwrap(), false),
            (AovSet::parse("").unwrap(), true),
            (AovSet::parse("variance,depth").unwrap(), false),
        ] {
            let film = Film::new(37, 23, aovs.clone(), adaptive);
            let tiles: usize = film
                .tiles
                .iter()
                .map(|t| {
                    size_of_val(t.light.as_slice())
                        + size_of_val(t.beauty_sum.as_slice())
                        + size_of_val(t.beauty_squares.as_slice())
                        + size_of_val(t.rays.as_slice())
                        + size_of_val(t.coverage.as_slice())
                        + t.data
                            .iter()
                            .map(|d| size_of_val(d.as_slice()))
                            .sum::<usize>()
                        + size_of_val(t.depth.as_slice())
                        + size_of_val(t.samples.as_slice())
                })
                .sum();
            let planes: usize = aovs
                .iter()
                .flat_map(|aov| film.planes(aov))
                .map(|p| size_of_val(p.as_slice()))
                .sum();
            assert_eq!(
                Film::estimated_bytes(37, 23, &aovs, adaptive),
                (tiles + planes) as u64,
                "{}",
                aovs.describe()
            );
        }
    }
}
