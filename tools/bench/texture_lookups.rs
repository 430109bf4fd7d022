//! Texture lookups through lucerna's tile cache, the half of the comparison with
//! OpenImageIO's texture system that `tools/bench/texture_cache_oiio.py` drives (its C++ twin,
//! `texture_lookups_oiio.cpp`, makes the same images, the same lookups in the same order and
//! prints the same JSON line).
//!
//!     cargo bench --bench texture_lookups -- --pattern coherent --cache-mib 32 --threads 2
//!
//! `--images` images of `--size`² 8-bit RGBA texels, generated from a formula (no files),
//! each written to a tiled file of the cache (and its MIP levels, for `trilinear`) before the
//! clock starts. Lookups come in work units that the threads take in order, each unit's
//! coordinates drawn from a generator seeded with its number (splitmix64), so both programs
//! look up the same points whatever the threads do:
//! - `coherent`: bilinear at full resolution, one lookup a texel: each image seen by a camera
//!   at one pixel a texel, 32 × 32-pixel buckets in order, a random position in each pixel;
//! - `incoherent`: bilinear at full resolution, units of 1024 lookups at random images and
//!   coordinates (diffuse bounces into a texture set);
//! - `trilinear`: each image seen at a quarter of its resolution (a footprint of 4 texels,
//!   MIP level 2), 4 lookups a pixel, filtered between levels.
//!
//! Prints one JSON line: lookups, seconds, lookups per second, a checksum of the results
//! (the two programs' agree where their filters do), tiles read and the peak resident memory.

use glam::{Vec2, Vec4};
use lucerna::render::peak_memory_bytes;
use lucerna::scene::texture_cache::{LevelImage, LevelTexels, TextureCache};
use lucerna::scene::{MipChains, Texels, Texture, Wrap};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Bucket side, in pixels, of the coherent patterns.
const BUCKET: usize = 32;
/// Lookups in a unit of the incoherent pattern.
const UNIT: usize = 1024;

struct Options {
    images: usize,
    size: usize,
    cache_mib: u64,
    threads: usize,
    pattern: String,
}

fn options() -> Options {
    let mut o = Options {
        images: 8,
        size: 2048,
        cache_mib: 32,
        threads: 1,
        pattern: "coherent".into(),
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        let value = || args.get(i + 1).cloned().unwrap_or_default();
        match args[i].as_str() {
            "--images" => o.images = value().parse().expect("--images N"),
            "--size" => o.size = value().parse().expect("--size N"),
            "--cache-mib" => o.cache_mib = value().parse().expect("--cache-mib N"),
            "--threads" => o.threads = value().parse().expect("--threads N"),
            "--pattern" => o.pattern = value(),
            "--bench" => {
                i += 1;
                continue;
            }
            other => panic!("unknown argument {other}"),
        }
        i += 2;
    }
    o
}

/// splitmix64, as the C++ twin has it.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A float in [0, 1) from the top 24 bits.
    fn float(&mut self) -> f32 {
        (self.next() >> 40) as f32 * (1.0 / 16_777_216.0)
    }
}

/// Texel (x, y) of image k, as the C++ twin makes it.
fn texel(k: usize, x: usize, y: usize) -> [u8; 4] {
    let mut h = SplitMix(((k * 4096 + y / 16) * 4096 + x / 16) as u64);
    [
        ((x * 7 + y * 3 + k * 50) & 255) as u8,
        ((x ^ y) & 255) as u8,
        (h.next() & 255) as u8,
        255,
    ]
}

/// One lookup: image, coordinates, footprint width (0: bilinear at full resolution).
type Lookup = (usize, f32, f32, f32);

/// Appends the lookups of one unit of work to a batch.
type Unit = Box<dyn Fn(usize, &mut Vec<Lookup>) + Sync>;

/// Units of work of `pattern`, and a function giving unit `u`'s lookups.
fn pattern(o: &Options) -> (usize, Unit) {
    let (images, size) = (o.images, o.size);
    match o.pattern.as_str() {
        "coherent" | "trilinear" => {
            let trilinear = o.pattern == "trilinear";
            let (screen, spp, width) = if trilinear {
                (size / 4, 4, 4.0 / size as f32)
            } else {
                (size, 1, 0.0)
            };
            let across = screen.div_ceil(BUCKET);
            let units = images * across * across;
            let unit = move |u: usize, out: &mut Vec<Lookup>| {
                let mut rng = SplitMix(u as u64);
                let (k, b) = (u / (across * across), u % (across * across));
                let (bx, by) = (b % across * BUCKET, b / across * BUCKET);
                for py in by..(by + BUCKET).min(screen) {
                    for px in bx..(bx + BUCKET).min(screen) {
                        for _ in 0..spp {
                            let s = (px as f32 + rng.float()) / screen as f32;
                            let t = (py as f32 + rng.float()) / screen as f32;
                            out.push((k, s, t, width));
                        }
                    }
                }
            };
            (units, Box::new(unit))
        }
        "incoherent" => {
            let units = images * size * size / 4 / UNIT;
            let unit = move |u: usize, out: &mut Vec<Lookup>| {
                let mut rng = SplitMix(u as u64);
                for _ in 0..UNIT {
                    let k = (rng.next() % images as u64) as usize;
                    out.push((k, rng.float(), rng.float(), 0.0));
                }
            };
            (units, Box::new(unit))
        }
        other => panic!("unknown pattern {other}"),
    }
}

fn main() {
    let o = options();
    let cache = TextureCache::new(o.cache_mib << 20);
    let textures: Vec<Texture> = (0..o.images)
        .map(|k| {
            let texels: Vec<[u8; 4]> = (0..o.size * o.size)
                .map(|i| texel(k, i % o.size, i / o.size))
                .collect();
            let base = LevelImage {
                width: o.size as u32,
                height: o.size as u32,
                texels: LevelTexels::Rgba8(&texels),
            };
            let tiled = cache
                .store(&format!("image {k}"), &base)
                .expect("tiled file");
            let texture = Texture {
                name: format!("image {k}"),
                width: o.size as u32,
                height: o.size as u32,
                texels: Arc::new(Texels::Tiled(Arc::new(tiled))),
                mips: Arc::new(MipChains::default()),
                wrap_u: Wrap::Repeat,
                wrap_v: Wrap::Repeat,
                nearest: false,
                mipmaps: true,
                udim: None,
            };
            if o.pattern == "trilinear" {
                texture.build_mips(false);
            }
            texture
        })
        .collect();
    let before = cache.stats();
    let (units, unit) = pattern(&o);
    let next = AtomicUsize::new(0);
    let start = Instant::now();
    let (lookups, checksum) = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..o.threads)
            .map(|_| {
                scope.spawn(|| {
                    let (mut n, mut sum) = (0usize, 0.0f64);
                    let mut batch = Vec::with_capacity(BUCKET * BUCKET * 4);
                    loop {
                        let u = next.fetch_add(1, Ordering::Relaxed);
                        if u >= units {
                            break (n, sum);
                        }
                        batch.clear();
                        unit(u, &mut batch);
                        let mut acc = Vec4::ZERO;
                        for &(k, s, t, width) in &batch {
                            let uv = Vec2::new(s, t);
                            acc += if width > 0.0 {
                                let axes = [Vec2::new(width, 0.0), Vec2::new(0.0, width)];
                                textures[k].sample_footprint(uv, axes, false)
                            } else {
                                textures[k].sample(uv, false)
                            };
                        }
                        n += batch.len();
                        sum += (acc.x + acc.y + acc.z) as f64;
                    }
                })
            })
            .collect();
        (workers.into_iter().map(|w| w.join().unwrap()))
            .fold((0, 0.0), |(n, s), (m, t)| (n + m, s + t))
    });
    let seconds = start.elapsed().as_secs_f64();
    let after = cache.stats();
    println!(
        "{{\"renderer\": \"lucerna\", \"pattern\": \"{}\", \"threads\": {}, \"cache_mib\": {}, \
         \"lookups\": {lookups}, \"seconds\": {seconds:.4}, \"lookups_per_second\": {:.0}, \
         \"checksum\": {:.6}, \"tiles_read\": {}, \"mib_read\": {:.1}, \"peak_mib\": {:.1}}}",
        o.pattern,
        o.threads,
        o.cache_mib,
        lookups as f64 / seconds,
        checksum / lookups as f64,
        after.tiles_read - before.tiles_read,
        (after.bytes_read - before.bytes_read) as f64 / (1 << 20) as f64,
        peak_memory_bytes().unwrap_or(0) as f64 / (1 << 20) as f64,
    );
}
