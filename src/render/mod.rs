//! The render loop: passes of samples over tiles (`tiles`), tiles in parallel on the
//! current rayon pool, each pass's samples chosen by `schedule` (fixed passes, a time
//! budget, adaptive sampling), what the render learns between passes held by `learning`,
//! progress reported by `progress`, the figures of the run in `stats`. What to render is
//! `options`; `plan` decides which variant of the integrator a request needs.

pub(crate) mod learning;
pub mod options;
pub mod plan;
pub mod progress;
pub(crate) mod schedule;
pub mod stats;
pub(crate) mod tiles;

use crate::film::Film;
use crate::integrator::estimator::RayCounts;
use crate::world::World;
use learning::{LearnedState, PassLearning};
pub use options::{ADAPTIVE_MAX_SPP, DEFAULT_MIN_SPP, DEFAULT_SPP, RenderOptions};
use progress::Progress;
pub use progress::ProgressLines;
use schedule::{PassSamples, adaptive_pass, fit_pass, next_pass};
pub use stats::{RenderStats, peak_memory_bytes};
use std::sync::Mutex;
use std::sync::atomic::Ordering;
use std::time::Instant;
#[cfg(target_arch = "x86_64")]
use tiles::run_packet_pass;
use tiles::{PassArgs, run_pass};

/// Renders `world` on the current rayon pool. Without a time budget every pixel's value
/// depends only on the scene, the options and the seed, not on the number of threads.
pub fn render(world: &World, options: &RenderOptions) -> (Film, RenderStats) {
    render_into(world, options, options.film(world))
}

/// Renders into `film`: empty (from [`RenderOptions::film`]) or restored from a
/// checkpoint, whose pixels continue their sample sequences where they stopped, so that
/// the result is the image an uninterrupted render gives (up to float rounding).
pub fn render_into(world: &World, options: &RenderOptions, film: Film) -> (Film, RenderStats) {
    render_with(world, options, film, &mut |_, _| {})
}

/// [`render_into`], calling `after_pass` with the film and the figures so far after every
/// pass (passes take at most 16 samples per pixel, or a time budget's share): where
/// periodic checkpoints and snapshots are written.
pub fn render_with(
    world: &World,
    options: &RenderOptions,
    mut film: Film,
    after_pass: &mut dyn FnMut(&Film, &RenderStats),
) -> (Film, RenderStats) {
    let plan = options.render_plan(world);
    let adaptive = options.noise_threshold.is_some();
    let range = options.sample_range();
    let target = range.end - range.start;
    let interrupted = || {
        options
            .interrupt
            .as_ref()
            .is_some_and(|flag| flag.load(Ordering::Relaxed))
    };
    let uniform_spp = if adaptive {
        options.min_spp.min(target)
    } else {
        target
    };
    let mut learned = LearnedState::new(&options.settings, plan.guiding, world, &film);
    let pixels = film.width as u64 * film.height as u64;
    let counts = Mutex::new(RayCounts::default());
    let start = Instant::now();
    let progress = Progress::start(
        options.progress,
        options.progress_lines,
        options.time,
        adaptive,
        pixels,
        target,
        film.total_samples(),
        start,
    );
    let resumed = film.min_samples().min(uniform_spp);
    let mut done = resumed;
    // What a time budget has rendered: the samples since the start, per pixel.
    let samples_before = film.total_samples();
    let rendered = |film: &Film| (film.total_samples() - samples_before) as f64 / pixels as f64;
    let stats = |film: &Film,
                 counts: &Mutex<RayCounts>,
                 learned: &LearnedState,
                 interrupted: bool| RenderStats {
        seconds: start.elapsed().as_secs_f64(),
        spp: film.max_samples(),
        samples: film.total_samples(),
        rays: *counts.lock().expect("no thread panicked holding the lock"),
        discarded: film.discarded(),
        interrupted,
        learned_split: learned.learned_split(),
    };
    while !interrupted() {
        let elapsed = start.elapsed().as_secs_f64();
        let (pass, learning) = if let Some(n) = learned.split_learning_pass(done, uniform_spp) {
            let learning = PassLearning {
                ears: false,
                split: Some(n),
                guiding: None,
                lights: false,
            };
            (learned.split_learning_samples(&film, n), learning)
        } else if done < uniform_spp {
            let n = next_pass(uniform_spp - done, options.time, elapsed, rendered(&film));
            let (n, learning) = learned.limit_pass(done, n);
            if n == 0 {
                break;
            }
            (PassSamples::UpTo(done + n), learning)
        } else if let Some(threshold) = options.noise_threshold {
            let mut counts = adaptive_pass(&film, threshold as f64, target);
            if let Some(budget) = options.time {
                let per_sample = elapsed / film.total_samples().max(1) as f64;
                fit_pass(
                    &mut counts,
                    (budget - elapsed).min(budget / 20.0) / per_sample,
                );
            }
            progress.pixels_done(counts.iter().filter(|&&c| c == 0).count() as u64);
            if counts.iter().all(|&c| c == 0) {
                break;
            }
            (PassSamples::PerPixel(counts), PassLearning::default())
        } else {
            break;
        };
        let tracer_args = PassArgs {
            world,
            options,
            ears: learned.ears(),
            samples: &pass,
            first_sample: range.start,
            learning: learning.ears,
            split: learned.first_split(),
            split_learning: learning.split.is_some(),
            guide: learned.guide(),
            guiding_records: learning.guiding.and(learned.guiding_tree()),
            lights: learned.lights(),
            light_records: learning.lights,
            rays: &counts,
            progress: progress.tiles(),
        };
        let k = plan.kernel;
        let packet = k.packet && !learning.ears;
        let tiles = match (k.routing, k.emitter_hits, k.first_hit_data) {
            #[cfg(target_arch = "x86_64")]
            (false, emitters, false) if packet => {
                if emitters {
                    run_packet_pass::<true>(&mut film, &tracer_args)
                } else {
                    run_packet_pass::<false>(&mut film, &tracer_args)
                }
            }
            (false, false, false) => run_pass::<false, false, false>(&mut film, &tracer_args),
            (false, false, true) => run_pass::<false, false, true>(&mut film, &tracer_args),
            (false, true, false) => run_pass::<false, true, false>(&mut film, &tracer_args),
            (false, true, true) => run_pass::<false, true, true>(&mut film, &tracer_args),
            (true, false, false) => run_pass::<true, false, false>(&mut film, &tracer_args),
            (true, false, true) => run_pass::<true, false, true>(&mut film, &tracer_args),
            (true, true, false) => run_pass::<true, true, false>(&mut film, &tracer_args),
            (true, true, true) => run_pass::<true, true, true>(&mut film, &tracer_args),
        };
        learned.absorb(learning, &tiles);
        if let PassSamples::UpTo(total) = pass {
            done = total;
        }
        if !interrupted() {
            after_pass(&film, &stats(&film, &counts, &learned, false));
        }
    }
    progress.finish(
        film.total_samples() - samples_before,
        film.total_samples(),
        interrupted(),
    );
    let stats = stats(&film, &counts, &learned, interrupted());
    (film, stats)
}
