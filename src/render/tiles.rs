//! One pass over the film's tiles, in parallel on the current rayon pool: each tile's pixels
//! take their samples of the pass through the kernel the plan chose (the scalar path tracer
//! in one of its monomorphised variants, or the packet kernel), and what the tiles learned
//! comes back in tile order.

use super::learning::TileLearning;
use super::options::RenderOptions;
use super::progress::TileProgress;
use super::schedule::PassSamples;
use crate::film::{Film, PixelAccumulator, SampleRecord};
use crate::integrator::ears::{Ears, Learning};
use crate::integrator::estimator::RayCounts;
use crate::integrator::guiding::Guide;
use crate::integrator::guiding::record::PathRecords;
use crate::integrator::guiding::sdtree::SdTree;
use crate::integrator::path::PathTracer;
use crate::integrator::split::{FirstSplit, PixelParts, SampleParts, SplitStats};
use crate::light::learned::{LightLearning, LightRecords};
use crate::sampling::sampler::Sampler;
use crate::world::World;
use glam::Vec2;
use rayon::prelude::*;
use std::sync::Mutex;
use std::sync::atomic::Ordering;

/// What every tile of a pass shares.
pub(super) struct PassArgs<'a> {
    pub world: &'a World,
    pub options: &'a RenderOptions,
    pub ears: Option<&'a Ears>,
    pub samples: &'a PassSamples,
    /// Index in each pixel's sample sequence of the render's first sample (a pass's
    /// share starts there).
    pub first_sample: u32,
    /// Whether efficiency-aware roulette learns in this pass.
    pub learning: bool,
    /// How the first vertex splits, and whether this pass learns the counts.
    pub split: FirstSplit,
    pub split_learning: bool,
    /// What paths are guided by, and where a guiding training pass records.
    pub guide: Option<Guide<'a>>,
    pub guiding_records: Option<&'a SdTree>,
    /// What learned light selection chooses lights by, and whether this pass records
    /// for it.
    pub lights: Option<&'a LightLearning>,
    pub light_records: bool,
    pub rays: &'a Mutex<RayCounts>,
    /// What finished tiles advance.
    pub progress: TileProgress<'a>,
}

/// Tiles a rayon job takes: one, so that a thread that runs out of tiles takes the next
/// one left. Rayon otherwise cuts the tiles into as many runs as threads and halves them
/// only for a thread that steals: with two threads, in runs of 64 tiles at 256², whose
/// unequal costs left one thread idle for 50-100 ms at the end of every pass of 16 samples
/// (perf samples by thread; 4 % of a 64-sample Cornell box).
const TILES_PER_JOB: usize = 1;

/// Renders one pass over every tile with the kernel variant `<ROUTED, EMITTERS, DATA>`
/// (see `render::plan::Kernel`); returns what each tile learned for efficiency-aware roulette and
/// for learned splitting.
pub(super) fn run_pass<const ROUTED: bool, const EMITTERS: bool, const DATA: bool>(
    film: &mut Film,
    args: &PassArgs,
) -> Vec<TileLearning> {
    let PassArgs {
        world,
        options,
        ears,
        samples,
        first_sample,
        learning,
        split,
        split_learning,
        guide,
        guiding_records,
        lights,
        light_records,
        rays: counts,
        progress,
    } = *args;
    let router = &film.router;
    let crypto = film.aovs.wants_crypto();
    let tracer = PathTracer::<EMITTERS, DATA>::new(world, &options.settings, ears, split)
        .guided_by(guide)
        .selecting_lights_by(lights);
    let window = film.window;
    let camera = &world.camera;
    // Rays carry a time in the shutter only where something moves: drawn per sample for
    // motion blur, else the frame's instant (the motion then serves the motion layers).
    let moving = world.features.moves();
    let instant = world
        .shutter
        .filter(|s| !s.blur)
        .map(|s| s.frame_time().clamp(0.0, 1.0) as f32);
    let interrupt = options.interrupt.as_deref();
    film.tiles
        .par_iter_mut()
        .with_max_len(TILES_PER_JOB)
        .map(|tile| {
            let mut sampler = Sampler::new(options.settings.sampler, options.settings.seed);
            let mut record = SampleRecord::<ROUTED>::new(router);
            let mut pixel = PixelAccumulator::new(router.slots.len(), crypto);
            let mut rays = RayCounts::default();
            let mut tile_learning = learning.then(Learning::default);
            let mut tile_split = split_learning.then(SplitStats::default);
            let mut tile_guiding = guiding_records.map(PathRecords::new);
            let mut tile_lights = light_records.then(LightRecords::default);
            let mut taken = 0u64;
            for ty in 0..tile.height {
                for tx in 0..tile.width {
                    let (x, y) = (tile.x0 + tx, tile.y0 + ty);
                    let index_in_image = window.index(x, y);
                    let in_tile = (ty * tile.width + tx) as usize;
                    let taken_here = tile.samples_at(in_tile);
                    let n = samples.at(index_in_image, taken_here);
                    if n == 0 || interrupt.is_some_and(|f| f.load(Ordering::Relaxed)) {
                        continue;
                    }
                    let first = first_sample + taken_here;
                    pixel.clear();
                    let mut pixel_parts = PixelParts::default();
                    let pixel_rays = rays.closest + rays.shadow;
                    // The pixel in the image's own coordinates: its samples and rays.
                    let (ix, iy) = camera.image_pixel(x, y);
                    let centre = Vec2::new(ix as f32 + 0.5, iy as f32 + 0.5);
                    for index in first..first + n {
                        sampler.start(ix as u32, iy as u32, index);
                        let cs = sampler.camera();
                        let film_position = centre + options.filter.sample(cs.film);
                        let ray = if moving {
                            let time = instant.unwrap_or_else(|| sampler.time());
                            camera.generate_ray_at(film_position, cs.lens, time)
                        } else {
                            camera.generate_ray(film_position, cs.lens)
                        };
                        record.clear();
                        let before = rays.closest + rays.shadow;
                        let mut parts = tile_split.is_some().then(|| SampleParts {
                            rays: [before; 4],
                            ..SampleParts::default()
                        });
                        tracer.trace(
                            ray,
                            index_in_image,
                            &mut sampler,
                            &mut record,
                            &mut rays,
                            tile_learning.as_mut(),
                            parts.as_mut(),
                            tile_guiding.as_mut(),
                            tile_lights.as_mut(),
                        );
                        if let (Some(stats), Some(parts)) = (tile_split.as_mut(), parts.as_mut()) {
                            parts.rays[3] = rays.closest + rays.shadow;
                            stats.add_rays(parts);
                            pixel_parts.add(parts);
                        }
                        if let Some(l) = tile_learning.as_mut() {
                            l.pixel_sample(
                                index_in_image as u32,
                                record.value(0),
                                rays.closest + rays.shadow - before,
                            );
                        }
                        pixel.add(&mut record);
                    }
                    if let Some(stats) = tile_split.as_mut() {
                        stats.add_pixel(&pixel_parts);
                    }
                    pixel.rays = rays.closest + rays.shadow - pixel_rays;
                    tile.add(in_tile, &pixel);
                    taken += n as u64;
                }
            }
            tile_done(counts, &rays, progress, taken);
            TileLearning {
                ears: tile_learning,
                split: tile_split,
                guiding: tile_guiding.map(|g| g.tile),
                lights: tile_lights,
            }
        })
        .collect()
}

/// Renders one pass over every tile with the packet kernel (see `render::plan::Kernel::packet`):
/// the beauty only, and no roulette learning. Returns what a pass that learns the split
/// counts learned, tile by tile in tile order, as [`run_pass`] does.
#[cfg(target_arch = "x86_64")]
pub(super) fn run_packet_pass<const EMITTERS: bool>(
    film: &mut Film,
    args: &PassArgs,
) -> Vec<TileLearning> {
    use crate::film::TILE_SIZE;
    use crate::integrator::packet::{PacketBuffers, PacketTracer, PixelWork};
    let PassArgs {
        world,
        options,
        samples,
        first_sample,
        split,
        split_learning,
        rays: counts,
        progress,
        ..
    } = *args;
    let tracer = PacketTracer::<EMITTERS>::new(
        world,
        &options.settings,
        split,
        split_learning,
        &options.filter,
    );
    let window = film.window;
    let interrupt = options.interrupt.as_deref();
    // Each thread's buffers, made once a pass (with a job a tile, `map_init` would make
    // them for every tile): the pool's workers', and the calling thread's last, which runs
    // the tiles itself where rayon does not split them (a single tile).
    let pixels = (TILE_SIZE * TILE_SIZE) as usize;
    let workers = rayon::current_num_threads();
    let pool: Vec<_> = (0..=workers)
        .map(|_| Mutex::new((PacketBuffers::new(pixels), Vec::with_capacity(pixels))))
        .collect();
    film.tiles
        .par_iter_mut()
        .with_max_len(TILES_PER_JOB)
        .map(|tile| {
            let thread = rayon::current_thread_index().unwrap_or(workers);
            let mut guard = pool[thread].lock().expect("no thread panicked holding it");
            let (buffers, work) = &mut *guard;
            work.clear();
            buffers.split_stats = SplitStats::default();
            for ty in 0..tile.height {
                for tx in 0..tile.width {
                    let (x, y) = (tile.x0 + tx, tile.y0 + ty);
                    let in_tile = (ty * tile.width + tx) as usize;
                    let taken = tile.samples_at(in_tile);
                    let count = samples.at(window.index(x, y), taken);
                    if count > 0 {
                        buffers.pixels[in_tile].clear();
                        buffers.pixel_parts[in_tile] = PixelParts::default();
                        work.push(PixelWork {
                            in_tile,
                            x,
                            y,
                            first: first_sample + taken,
                            count,
                        });
                    }
                }
            }
            let mut rays = RayCounts::default();
            let taken = tracer.render(work, buffers, &mut rays, interrupt);
            for w in work.iter() {
                tile.add(w.in_tile, &buffers.pixels[w.in_tile]);
                if split_learning {
                    buffers
                        .split_stats
                        .add_pixel(&buffers.pixel_parts[w.in_tile]);
                }
            }
            tile_done(counts, &rays, progress, taken);
            TileLearning {
                ears: None,
                split: split_learning.then_some(buffers.split_stats),
                guiding: None,
                lights: None,
            }
        })
        .collect()
}

/// Adds a finished tile's ray counts to the render's and advances the progress by its
/// `taken` samples.
fn tile_done(counts: &Mutex<RayCounts>, rays: &RayCounts, progress: TileProgress, taken: u64) {
    counts
        .lock()
        .expect("no thread panicked holding the lock")
        .add(rays);
    progress.advance(taken);
}
