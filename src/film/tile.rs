//! Accumulation: a pixel's samples summed in f64 in sample order ([`PixelAccumulator`]),
//! then added to its tile ([`Tile`]), so that threads own disjoint memory and a pixel's
//! value does not depend on the thread count.

use super::RELATIVE_ERROR_FLOOR;
use super::aov::{Aov, AovSet, MEAN_DATA, mean_data};
use super::crypto;
use super::router::SampleRecord;
use glam::{DVec3, Vec3};

/// Sums of one pixel's samples over a range of sample indices, in double precision.
pub struct PixelAccumulator {
    light: Vec<DVec3>,
    beauty_squares: DVec3,
    coverage: f64,
    /// Sums of [`MEAN_DATA`].
    data: [DVec3; MEAN_DATA.len()],
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
            data: [DVec3::ZERO; MEAN_DATA.len()],
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
        self.data = [DVec3::ZERO; MEAN_DATA.len()];
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
    pub(super) light: Vec<Vec3>,
    /// Beauty sums and sums of squares in f64, for the variance AOV and adaptive sampling.
    pub(super) beauty_sum: Vec<DVec3>,
    pub(super) beauty_squares: Vec<DVec3>,
    /// Rays traced per pixel (adaptive sampling only).
    pub(super) rays: Vec<u64>,
    pub(super) coverage: Vec<f32>,
    /// Sums of [`MEAN_DATA`] (empty where not requested).
    pub(super) data: [Vec<Vec3>; MEAN_DATA.len()],
    /// Per pixel, samples per object and per material (empty without Cryptomatte).
    pub(super) crypto: [Vec<crypto::Counts>; 2],
    pub(super) depth: Vec<f32>,
    pub(super) samples: Vec<u32>,
    /// Contributions dropped for being NaN or infinite.
    pub discarded: u64,
}

impl Tile {
    pub(super) fn new(
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
