//! The film: per-pixel accumulation of every requested AOV, in tiles so that threads own
//! disjoint memory. Samples of one pixel are summed in f64 in sample order before they
//! reach the tile, so a pixel's value does not depend on the thread count.

pub mod aov;
pub mod crypto;
pub mod denoise;
pub mod exr;
pub mod filter;
pub mod preview;

use crate::integrator::path::{Contribution, FirstHit, Recorder};
use aov::{Aov, AovSet, Router};
use glam::{DVec3, Vec3};

/// Tile edge in pixels.
pub const TILE_SIZE: u32 = 16;
/// Depth written where the camera saw nothing (as Cycles does).
pub const BACKGROUND_DEPTH: f32 = 1e10;

/// The data AOVs that are means of a first-hit vector over the pixel's samples, in the
/// order of [`mean_data`].
pub const MEAN_DATA: [Aov; 6] = [
    Aov::Albedo,
    Aov::Normal,
    Aov::Position,
    Aov::DiffuseColor,
    Aov::GlossyColor,
    Aov::TransmissionColor,
];

/// The values of [`MEAN_DATA`] at a first hit.
#[inline]
fn mean_data(hit: &FirstHit) -> [Vec3; 6] {
    let [diffuse, glossy, transmission] = hit.lobe_albedo;
    [
        hit.albedo,
        hit.normal,
        hit.position,
        diffuse,
        glossy,
        transmission,
    ]
}

/// What one camera sample produced, routed into light-AOV slots as it arrives. Without
/// `ROUTED` (the beauty is the only light layer) every contribution goes to slot 0 and the
/// routing table is never read.
pub struct SampleRecord<'r, const ROUTED: bool> {
    router: &'r Router,
    values: Vec<Vec3>,
    covered: bool,
    hit: Option<FirstHit>,
    discarded: u64,
}

impl<'r, const ROUTED: bool> SampleRecord<'r, ROUTED> {
    /// An empty record for `router`'s slots.
    pub fn new(router: &'r Router) -> Self {
        Self {
            router,
            values: vec![Vec3::ZERO; router.slots.len()],
            covered: false,
            hit: None,
            discarded: 0,
        }
    }

    /// Empties the record for the next sample.
    #[inline]
    pub fn clear(&mut self) {
        self.values.fill(Vec3::ZERO);
        self.covered = false;
        self.hit = None;
    }

    /// The value of light slot `slot` so far.
    pub fn value(&self, slot: usize) -> Vec3 {
        self.values[slot]
    }
}

impl<const ROUTED: bool> Recorder for SampleRecord<'_, ROUTED> {
    #[inline]
    fn wants_single_technique(&self) -> bool {
        ROUTED && self.router.single_technique.iter().any(Option::is_some)
    }

    #[inline]
    fn wants_lobes(&self) -> bool {
        ROUTED && self.router.wants_lobes()
    }

    #[inline]
    fn contribution(&mut self, c: Contribution) {
        // A non-finite contribution is dropped whole, from every AOV, and counted.
        let finite = c.value.is_finite()
            && c.single_technique
                .is_none_or(|s| s[0].is_finite() && s[1].is_finite());
        if !finite {
            self.discarded += 1;
            return;
        }
        if !ROUTED {
            self.values[0] += c.value;
            return;
        }
        for &slot in self.router.route(&c) {
            self.values[slot as usize] += c.value;
        }
        if let Some(single) = c.single_technique {
            for (value, slot) in single.iter().zip(self.router.single_technique) {
                if let Some(slot) = slot {
                    self.values[slot as usize] += *value;
                }
            }
        }
        if let Some(slot) = c
            .light
            .filter(|_| c.depth >= 1)
            .and_then(|l| self.router.light_group_slot(l))
        {
            self.values[slot as usize] += c.value;
        }
        if let Some(shares) = c.lobes.filter(|_| c.depth >= 1) {
            let indirect = usize::from(c.depth >= 2);
            for (share, slots) in shares.iter().zip(&self.router.lobes) {
                if let Some(slot) = slots[indirect] {
                    self.values[slot as usize] += c.value * *share;
                }
            }
        }
    }

    #[inline]
    fn first_hit(&mut self, hit: Option<FirstHit>) {
        let Some(hit) = hit else {
            self.covered = true;
            return;
        };
        let finite = mean_data(&hit).iter().all(|v| v.is_finite()) && hit.depth.is_finite();
        if finite {
            self.covered = true;
            self.hit = Some(hit);
        } else {
            self.discarded += 1;
        }
    }
}

/// Sums of one pixel's samples over a range of sample indices, in double precision.
pub struct PixelAccumulator {
    light: Vec<DVec3>,
    beauty_squares: DVec3,
    coverage: f64,
    /// Sums of [`MEAN_DATA`].
    data: [DVec3; 6],
    /// Samples per object and per material hit (Cryptomatte only).
    crypto: Option<[crypto::Counts; 2]>,
    depth: f32,
    samples: u32,
    /// Rays the samples traced (the pixel's cost, for adaptive sampling).
    pub rays: u64,
    discarded: u64,
}

impl PixelAccumulator {
    /// An empty accumulator for `slots` light slots; `crypto` also counts the objects and
    /// materials hit.
    pub fn new(slots: usize, crypto: bool) -> Self {
        Self {
            crypto: crypto.then(Default::default),
            light: vec![DVec3::ZERO; slots],
            beauty_squares: DVec3::ZERO,
            coverage: 0.0,
            data: [DVec3::ZERO; 6],
            depth: f32::INFINITY,
            samples: 0,
            rays: 0,
            discarded: 0,
        }
    }

    /// Empties the accumulator for the next pixel.
    pub fn clear(&mut self) {
        self.light.fill(DVec3::ZERO);
        self.beauty_squares = DVec3::ZERO;
        self.coverage = 0.0;
        self.data = [DVec3::ZERO; 6];
        if let Some(c) = &mut self.crypto {
            c[0].clear();
            c[1].clear();
        }
        self.depth = f32::INFINITY;
        self.samples = 0;
        self.rays = 0;
        self.discarded = 0;
    }

    /// Adds one sample of a render whose only light layer is the beauty (as the packet
    /// kernel produces them): its value, whether the camera ray hit a surface, and the
    /// contributions dropped for being non-finite.
    #[inline]
    pub fn add_sample(&mut self, value: Vec3, covered: bool, discarded: u64) {
        let b = value.as_dvec3();
        self.light[0] += b;
        self.beauty_squares += b * b;
        if covered {
            self.coverage += 1.0;
        }
        self.samples += 1;
        self.discarded += discarded;
    }

    /// Adds one sample and takes its discarded-contribution count.
    #[inline]
    pub fn add<const ROUTED: bool>(&mut self, rec: &mut SampleRecord<ROUTED>) {
        for (acc, v) in self.light.iter_mut().zip(&rec.values) {
            *acc += v.as_dvec3();
        }
        let b = rec.values[0].as_dvec3();
        self.beauty_squares += b * b;
        if rec.covered {
            self.coverage += 1.0;
        }
        if let Some(h) = &rec.hit {
            for (sum, v) in self.data.iter_mut().zip(mean_data(h)) {
                *sum += v.as_dvec3();
            }
            if let Some([objects, materials]) = &mut self.crypto {
                crypto::count(objects, h.object, 1);
                crypto::count(materials, h.material, 1);
            }
            self.depth = self.depth.min(h.depth);
        }
        self.samples += 1;
        self.discarded += rec.discarded;
        rec.discarded = 0;
    }
}

/// One tile's accumulated sums.
pub struct Tile {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
    /// Light slots, slot-major (`slot * pixels + pixel`).
    light: Vec<Vec3>,
    /// Beauty sums and sums of squares in f64, for the variance AOV and adaptive sampling.
    beauty_sum: Vec<DVec3>,
    beauty_squares: Vec<DVec3>,
    /// Rays traced per pixel (adaptive sampling only).
    rays: Vec<u64>,
    coverage: Vec<f32>,
    /// Sums of [`MEAN_DATA`] (empty where not requested).
    data: [Vec<Vec3>; 6],
    /// Per pixel, samples per object and per material (empty without Cryptomatte).
    crypto: [Vec<crypto::Counts>; 2],
    depth: Vec<f32>,
    samples: Vec<u32>,
    /// Contributions dropped for being NaN or infinite.
    pub discarded: u64,
}

impl Tile {
    fn new(
        x0: u32,
        y0: u32,
        width: u32,
        height: u32,
        slots: usize,
        aovs: &AovSet,
        adaptive: bool,
    ) -> Self {
        let n = (width * height) as usize;
        let vec3s = |aov: Aov| {
            if aovs.contains(aov) {
                vec![Vec3::ZERO; n]
            } else {
                Vec::new()
            }
        };
        let with_variance = aovs.contains(Aov::Variance) || adaptive;
        Self {
            x0,
            y0,
            width,
            height,
            light: vec![Vec3::ZERO; slots * n],
            beauty_sum: if with_variance {
                vec![DVec3::ZERO; n]
            } else {
                Vec::new()
            },
            beauty_squares: if with_variance {
                vec![DVec3::ZERO; n]
            } else {
                Vec::new()
            },
            rays: if adaptive { vec![0; n] } else { Vec::new() },
            coverage: vec![0.0; n],
            data: MEAN_DATA.map(vec3s),
            crypto: if aovs.wants_crypto() {
                [vec![Vec::new(); n], vec![Vec::new(); n]]
            } else {
                Default::default()
            },
            depth: if aovs.contains(Aov::Depth) {
                vec![f32::INFINITY; n]
            } else {
                Vec::new()
            },
            samples: vec![0; n],
            discarded: 0,
        }
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        (self.width * self.height) as usize
    }

    /// Adds a pixel's accumulated samples; `pixel` indexes the tile row-major.
    pub fn add(&mut self, pixel: usize, acc: &PixelAccumulator) {
        let n = self.pixel_count();
        for (slot, sum) in acc.light.iter().enumerate() {
            self.light[slot * n + pixel] += sum.as_vec3();
        }
        if !self.beauty_sum.is_empty() {
            self.beauty_sum[pixel] += acc.light[0];
            self.beauty_squares[pixel] += acc.beauty_squares;
        }
        if !self.rays.is_empty() {
            self.rays[pixel] += acc.rays;
        }
        self.coverage[pixel] += acc.coverage as f32;
        for (sums, sum) in self.data.iter_mut().zip(acc.data) {
            if !sums.is_empty() {
                sums[pixel] += sum.as_vec3();
            }
        }
        if let Some(counts) = &acc.crypto {
            for (tile_counts, pixel_counts) in self.crypto.iter_mut().zip(counts) {
                for &(index, n) in pixel_counts {
                    crypto::count(&mut tile_counts[pixel], index, n);
                }
            }
        }
        if !self.depth.is_empty() {
            self.depth[pixel] = self.depth[pixel].min(acc.depth);
        }
        self.samples[pixel] += acc.samples;
        self.discarded += acc.discarded;
    }

    /// Samples taken so far at `pixel` (row-major in the tile): the index of its next one.
    pub fn samples_at(&self, pixel: usize) -> u32 {
        self.samples[pixel]
    }

    /// What adaptive sampling knows of `pixel`: its per-sample variance of the beauty,
    /// relative as relMSE weighs it (mean over channels of s² / (mean² + 0.01)), and its
    /// rays per sample. `None` before two samples, or without the sums of squares.
    pub fn pixel_statistics(&self, pixel: usize) -> Option<(f64, f64)> {
        let n = self.samples[pixel] as f64;
        if n < 2.0 || self.beauty_sum.is_empty() || self.rays.is_empty() {
            return None;
        }
        let s = self.beauty_sum[pixel];
        let mean = s / n;
        let var = ((self.beauty_squares[pixel] - s * mean) / (n - 1.0)).max(DVec3::ZERO);
        let relative = var / (mean * mean + DVec3::splat(RELATIVE_ERROR_FLOOR));
        Some((relative.element_sum() / 3.0, self.rays[pixel] as f64 / n))
    }
}

/// The constant relMSE adds to the squared reference in its denominator, so that dark
/// pixels do not dominate (`../shared/design.md`, "Accuracy and speed").
pub const RELATIVE_ERROR_FLOOR: f64 = 0.01;

/// A rectangle of pixels of an image: a crop window, and the EXR data window it becomes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Window {
    /// The whole of a `width` × `height` image.
    pub fn full(width: u32, height: u32) -> Self {
        Self {
            x: 0,
            y: 0,
            width,
            height,
        }
    }

    /// Parses `X0,Y0,X1,Y1`: pixel columns X0..X1 and rows Y0..Y1 (ends excluded, origin at
    /// the top left), e.g. `0,0,320,240` for the top-left quarter of a 640x480 image.
    pub fn parse(text: &str) -> Result<Self, String> {
        let numbers: Vec<u32> = text
            .split(',')
            .map(|v| v.trim().parse::<u32>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("expected X0,Y0,X1,Y1 in pixels, got {text:?}"))?;
        match numbers[..] {
            [x0, y0, x1, y1] if x1 > x0 && y1 > y0 => Ok(Self {
                x: x0,
                y: y0,
                width: x1 - x0,
                height: y1 - y0,
            }),
            [_, _, _, _] => Err(format!(
                "the window {text:?} is empty (X1 <= X0 or Y1 <= Y0)"
            )),
            _ => Err(format!("expected X0,Y0,X1,Y1 in pixels, got {text:?}")),
        }
    }

    /// `X0,Y0,X1,Y1`, as [`Window::parse`] reads it.
    pub fn describe(&self) -> String {
        format!(
            "{},{},{},{}",
            self.x,
            self.y,
            self.x + self.width,
            self.y + self.height
        )
    }

    /// True if the window lies inside a `width` × `height` image.
    pub fn fits(&self, width: u32, height: u32) -> bool {
        self.x as u64 + self.width as u64 <= width as u64
            && self.y as u64 + self.height as u64 <= height as u64
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Row-major index in the window of image pixel (`x`, `y`), which must lie inside it.
    #[inline]
    pub fn index(&self, x: u32, y: u32) -> usize {
        (y - self.y) as usize * self.width as usize + (x - self.x) as usize
    }
}

/// All tiles of an image's window plus the AOV set and routing. Tiles, and the sample
/// sequences of their pixels, are placed in image coordinates, so that a window renders
/// exactly the pixels the whole image would.
pub struct Film {
    /// Size of the window (the pixels this film holds).
    pub width: u32,
    pub height: u32,
    /// Where those pixels lie in the image.
    pub window: Window,
    /// Size of the whole image (the EXR display window).
    pub display: (u32, u32),
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
    pub fn restore(&mut self, planes: &exr::Planes, discarded: u64) -> Result<(), String> {
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
                    let vec3 =
                        |planes: &[&[f32]]| Vec3::new(planes[0][i], planes[1][i], planes[2][i]);
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
}

/// Writes a file atomically: `write` fills a temporary file next to `path`, which is then
/// renamed over `path`. A failed or killed write never leaves a partial file at `path`.
/// Interleaves planes (one per channel) into row-major pixels: what OIDN and numpy take.
pub fn interleave(planes: &[&[f32]]) -> Vec<f32> {
    let n = planes.first().map_or(0, |p| p.len());
    let mut pixels = Vec::with_capacity(n * planes.len());
    for i in 0..n {
        pixels.extend(planes.iter().map(|p| p[i]));
    }
    pixels
}

pub fn write_atomically<F>(path: &std::path::Path, write: F) -> crate::Result<()>
where
    F: FnOnce(&mut std::io::BufWriter<std::fs::File>) -> crate::Result<()>,
{
    use crate::error::Error;
    let name = path
        .file_name()
        .ok_or_else(|| Error::other(path, "output", "not a file name"))?;
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let tmp = dir.join(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    // Never rename over a device node, FIFO or directory (the render checked this before
    // it started; this holds for every writer).
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
    {
        return Err(Error::bad_input(
            path,
            "output",
            "exists and is not a regular file",
        ));
    }
    let _removed_on_signal = crate::interrupt::watch_scratch(tmp.clone());
    let result = (|| {
        let file =
            std::fs::File::create(&tmp).map_err(|e| Error::other(&tmp, "output", e.to_string()))?;
        let mut writer = std::io::BufWriter::new(file);
        write(&mut writer)?;
        let file = writer
            .into_inner()
            .map_err(|e| Error::other(&tmp, "output", e.to_string()))?;
        file.sync_all()
            .map_err(|e| Error::other(&tmp, "output", e.to_string()))?;
        std::fs::rename(&tmp, path).map_err(|e| Error::other(path, "output", e.to_string()))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
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
