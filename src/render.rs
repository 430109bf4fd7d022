//! The render loop: passes of samples over tiles, tiles in parallel on the current rayon
//! pool, a progress bar, and the figures of the run.

use crate::film::aov::AovSet;
use crate::film::filter::PixelFilter;
use crate::film::{Film, PixelAccumulator, SampleRecord};
use crate::integrator::Settings;
use crate::integrator::path::{PathTracer, RayCounts};
use crate::sampling::sampler::Sampler;
use crate::world::World;
use glam::Vec2;
use rayon::prelude::*;
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Instant;

/// Samples per pixel rendered in one pass over the image.
const PASS_SAMPLES: u32 = 16;

/// What to render.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub spp: u32,
    pub settings: Settings,
    pub aovs: AovSet,
    pub filter: PixelFilter,
    /// Show a progress bar (only drawn when stderr is a terminal).
    pub progress: bool,
}

/// Figures of a finished render.
#[derive(Clone, Copy, Debug)]
pub struct RenderStats {
    pub seconds: f64,
    pub samples: u64,
    pub rays: RayCounts,
    /// Contributions dropped for being NaN or infinite.
    pub discarded: u64,
}

impl RenderStats {
    /// The final line a render prints.
    pub fn summary(&self) -> String {
        let total_rays = self.rays.closest + self.rays.shadow;
        format!(
            "{:.2} s, {} samples ({:.3} M samples/s), {} rays ({:.2} M rays/s: {:.2} M closest + {:.2} M shadow), {} NaN/Inf contributions discarded",
            self.seconds,
            self.samples,
            self.samples as f64 / self.seconds / 1e6,
            total_rays,
            total_rays as f64 / self.seconds / 1e6,
            self.rays.closest as f64 / self.seconds / 1e6,
            self.rays.shadow as f64 / self.seconds / 1e6,
            self.discarded,
        )
    }
}

/// Peak resident memory of this process in bytes (Linux's VmHWM), if known.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Renders `world` on the current rayon pool. Every pixel's value depends only on the
/// scene, the options and the seed, not on the number of threads.
pub fn render(world: &World, options: &RenderOptions) -> (Film, RenderStats) {
    let camera = &world.camera;
    let mut film = Film::new(camera.width(), camera.height(), options.aovs.clone());
    let tracer = PathTracer::new(world, &options.settings);
    let total = film.width as u64 * film.height as u64 * options.spp as u64;
    let bar = (options.progress && std::io::stderr().is_terminal()).then(|| {
        let bar = indicatif::ProgressBar::new(total);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{elapsed_precise} [{wide_bar}] {percent:>3}% eta {eta}",
            )
            .expect("the template is valid"),
        );
        bar
    });
    let counts = Mutex::new(RayCounts::default());
    let start = Instant::now();
    let mut done = 0;
    while done < options.spp {
        let pass = done..(done + PASS_SAMPLES).min(options.spp);
        let router = &film.router;
        film.tiles.par_iter_mut().for_each(|tile| {
            let mut sampler = Sampler::new(options.settings.sampler, options.settings.seed);
            let mut record = SampleRecord::new(router);
            let mut pixel = PixelAccumulator::new(router.slots.len());
            let mut rays = RayCounts::default();
            for ty in 0..tile.height {
                for tx in 0..tile.width {
                    let (x, y) = (tile.x0 + tx, tile.y0 + ty);
                    pixel.clear();
                    for index in pass.clone() {
                        sampler.start(x, y, index);
                        let cs = sampler.camera();
                        let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                        let ray =
                            camera.generate_ray(centre + options.filter.sample(cs.film), cs.lens);
                        record.clear();
                        tracer.trace(ray, &mut sampler, &mut record, &mut rays);
                        pixel.add(&mut record);
                    }
                    tile.add((ty * tile.width + tx) as usize, &pixel);
                }
            }
            counts
                .lock()
                .expect("no thread panicked holding the lock")
                .add(&rays);
            if let Some(bar) = &bar {
                bar.inc(tile.pixel_count() as u64 * pass.len() as u64);
            }
        });
        done = pass.end;
    }
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    let stats = RenderStats {
        seconds: start.elapsed().as_secs_f64(),
        samples: film.total_samples(),
        rays: *counts.lock().expect("no thread panicked holding the lock"),
        discarded: film.discarded(),
    };
    (film, stats)
}
