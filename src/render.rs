//! The render loop: passes of samples over tiles, tiles in parallel on the current rayon
//! pool, an optional time budget, a progress bar, and the figures of the run.

use crate::film::aov::AovSet;
use crate::film::filter::PixelFilter;
use crate::film::{Film, PixelAccumulator, SampleRecord};
use crate::integrator::ears::{Ears, LEARNING_SAMPLES, Learning};
use crate::integrator::path::{PathTracer, RayCounts};
use crate::integrator::settings::{SETTING_NAMES, read_settings_toml, write_settings_toml};
use crate::integrator::{RussianRoulette, Settings};
use crate::sampling::sampler::Sampler;
use crate::world::World;
use glam::Vec2;
use rayon::prelude::*;
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Instant;

/// Samples per pixel of a pass without a time budget.
const PASS_SAMPLES: u32 = 16;
/// Samples per pixel when neither a count nor a time is given.
pub const DEFAULT_SPP: u32 = 64;
/// Most samples per pixel a time budget may take.
const MAX_SPP: u32 = 1 << 24;

/// What to render: samples or time, integrator settings, AOVs, pixel filter.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Samples per pixel; with a time budget, the most to take.
    pub spp: Option<u32>,
    /// Time budget in seconds: passes continue until it is spent.
    pub time: Option<f64>,
    pub settings: Settings,
    pub aovs: AovSet,
    pub filter: PixelFilter,
    /// Show a progress bar (only drawn when stderr is a terminal).
    pub progress: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            spp: None,
            time: None,
            settings: Settings::default(),
            aovs: AovSet::default(),
            filter: PixelFilter::blackman_harris(1.5),
            progress: false,
        }
    }
}

/// Names of the render-level settings (besides the integrator's).
const RENDER_NAMES: [&str; 4] = ["spp", "time", "filter", "aov"];

impl RenderOptions {
    /// Sets `name` (a render or integrator setting) from its textual value: the one path
    /// for the command line and settings files.
    pub fn set(&mut self, name: &str, value: &str) -> Result<(), String> {
        match name {
            "spp" => {
                let spp = value.parse().ok().filter(|s| (1..=MAX_SPP).contains(s));
                self.spp =
                    Some(spp.ok_or_else(|| {
                        format!("spp: an integer in 1..={MAX_SPP}, got {value:?}")
                    })?);
            }
            "time" => {
                let t = value
                    .parse::<f64>()
                    .ok()
                    .filter(|t| t.is_finite() && *t > 0.0);
                self.time =
                    Some(t.ok_or_else(|| {
                        format!("time: a positive number of seconds, got {value:?}")
                    })?);
            }
            "filter" => {
                self.filter = PixelFilter::parse(value).ok_or_else(|| {
                    format!(
                        "unknown filter {value:?} (box, blackman-harris, blackman-harris:WIDTH)"
                    )
                })?
            }
            "aov" => self.aovs = AovSet::parse(value)?,
            _ => self.settings.set(name, value)?,
        }
        Ok(())
    }

    /// Applies a TOML settings file's keys.
    pub fn load_settings(&mut self, text: &str) -> Result<(), String> {
        for (name, value) in read_settings_toml(text)? {
            self.set(&name, &value)
                .map_err(|e| format!("{name}: {e}"))?;
        }
        Ok(())
    }

    /// Every setting as TOML, with `spp` the samples actually taken: the header's record
    /// of how an image was made, readable back as a settings file.
    pub fn to_toml(&self, spp_taken: u32) -> String {
        let mut pairs: Vec<(String, String)> = vec![("spp".into(), spp_taken.to_string())];
        if let Some(t) = self.time {
            pairs.push(("time".into(), t.to_string()));
        }
        pairs.push(("filter".into(), self.filter.describe()));
        pairs.push(("aov".into(), self.aovs.describe()));
        for name in SETTING_NAMES {
            pairs.push((
                name.into(),
                self.settings.get(name).expect("listed settings exist"),
            ));
        }
        debug_assert!(
            RENDER_NAMES
                .iter()
                .all(|n| pairs.iter().any(|(k, _)| k == n))
        );
        write_settings_toml(&pairs)
    }

    /// The sample count when no time budget limits it.
    fn target_spp(&self) -> u32 {
        match (self.spp, self.time) {
            (Some(s), _) => s,
            (None, Some(_)) => MAX_SPP,
            (None, None) => DEFAULT_SPP,
        }
    }
}

/// Figures of a finished render.
#[derive(Clone, Copy, Debug)]
pub struct RenderStats {
    pub seconds: f64,
    /// Samples per pixel taken.
    pub spp: u32,
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
            "{:.2} s, {} spp, {} samples ({:.3} M samples/s), {} rays ({:.2} M rays/s: {:.2} M closest + {:.2} M shadow), {} NaN/Inf contributions discarded",
            self.seconds,
            self.spp,
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

/// The samples of the next pass: fixed-size passes without a budget; with one, passes
/// sized to about a twentieth of the budget from the measured time per sample, shortened
/// to fit what remains, and none when less than half a sample's time remains.
fn next_pass(done: u32, target: u32, budget: Option<f64>, elapsed: f64) -> u32 {
    let left = target - done;
    let Some(budget) = budget else {
        return left.min(PASS_SAMPLES);
    };
    if done == 0 {
        return 1;
    }
    let per_sample = elapsed / done as f64;
    let remaining = budget - elapsed;
    if remaining < 0.5 * per_sample {
        return 0;
    }
    let fit = (remaining / per_sample).round().max(1.0);
    let slice = (budget / 20.0 / per_sample).max(1.0);
    (fit.min(slice) as u32).clamp(1, left)
}

/// Renders `world` on the current rayon pool. Without a time budget every pixel's value
/// depends only on the scene, the options and the seed, not on the number of threads.
pub fn render(world: &World, options: &RenderOptions) -> (Film, RenderStats) {
    let camera = &world.camera;
    let mut film = Film::new(camera.width(), camera.height(), options.aovs.clone());
    let target = options.target_spp();
    let mut ears = match options.settings.rr {
        RussianRoulette::Efficiency(max_split) => {
            Some(Ears::new(film.width, film.height, max_split))
        }
        _ => None,
    };
    let pixels = film.width as u64 * film.height as u64;
    let bar = (options.progress && std::io::stderr().is_terminal()).then(|| {
        let (length, template) = match options.time {
            Some(t) => (
                (t * 1000.0) as u64,
                "{elapsed_precise} [{wide_bar}] {percent:>3}% of the time budget",
            ),
            None => (
                pixels * target as u64,
                "{elapsed_precise} [{wide_bar}] {percent:>3}% eta {eta}",
            ),
        };
        let bar = indicatif::ProgressBar::new(length);
        bar.set_style(
            indicatif::ProgressStyle::with_template(template).expect("the template is valid"),
        );
        bar
    });
    let counts = Mutex::new(RayCounts::default());
    let start = Instant::now();
    let mut done = 0;
    while done < target {
        let mut n = next_pass(done, target, options.time, start.elapsed().as_secs_f64());
        // Efficiency-aware roulette learns in passes of 1, 1, 2, 4, 8 samples, each
        // deciding with everything learned before it.
        let learning = ears.is_some() && done < LEARNING_SAMPLES;
        if learning {
            n = n.min(done.max(1));
        }
        if n == 0 {
            break;
        }
        let pass = done..done + n;
        let router = &film.router;
        let tracer = PathTracer::new(world, &options.settings, ears.as_ref());
        let width = film.width;
        let learned: Vec<Option<Learning>> = film
            .tiles
            .par_iter_mut()
            .map(|tile| {
                let mut sampler = Sampler::new(options.settings.sampler, options.settings.seed);
                let mut record = SampleRecord::new(router);
                let mut pixel = PixelAccumulator::new(router.slots.len());
                let mut rays = RayCounts::default();
                let mut tile_learning = learning.then(Learning::default);
                for ty in 0..tile.height {
                    for tx in 0..tile.width {
                        let (x, y) = (tile.x0 + tx, tile.y0 + ty);
                        let index_in_image = (y * width + x) as usize;
                        pixel.clear();
                        for index in pass.clone() {
                            sampler.start(x, y, index);
                            let cs = sampler.camera();
                            let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                            let ray = camera
                                .generate_ray(centre + options.filter.sample(cs.film), cs.lens);
                            record.clear();
                            let before = rays.closest + rays.shadow;
                            tracer.trace(
                                ray,
                                index_in_image,
                                &mut sampler,
                                &mut record,
                                &mut rays,
                                tile_learning.as_mut(),
                            );
                            if let Some(l) = tile_learning.as_mut() {
                                l.pixel_sample(
                                    index_in_image as u32,
                                    record.value(0),
                                    rays.closest + rays.shadow - before,
                                );
                            }
                            pixel.add(&mut record);
                        }
                        tile.add((ty * tile.width + tx) as usize, &pixel);
                    }
                }
                counts
                    .lock()
                    .expect("no thread panicked holding the lock")
                    .add(&rays);
                if let (Some(bar), None) = (&bar, options.time) {
                    bar.inc(tile.pixel_count() as u64 * pass.len() as u64);
                }
                tile_learning
            })
            .collect();
        // In tile order, whatever the thread count: the next pass decides the same way.
        if let (Some(e), true) = (ears.as_mut(), learning) {
            for l in learned.iter().flatten() {
                e.merge(l);
            }
            e.refresh();
        }
        done = pass.end;
        if let (Some(bar), Some(_)) = (&bar, options.time) {
            bar.set_position(start.elapsed().as_millis() as u64);
        }
    }
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    let stats = RenderStats {
        seconds: start.elapsed().as_secs_f64(),
        spp: done,
        samples: film.total_samples(),
        rays: *counts.lock().expect("no thread panicked holding the lock"),
        discarded: film.discarded(),
    };
    (film, stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_fit_the_budget() {
        assert_eq!(next_pass(0, 100, None, 0.0), 16);
        assert_eq!(next_pass(96, 100, None, 0.0), 4);
        assert_eq!(next_pass(0, MAX_SPP, Some(10.0), 0.0), 1);
        // 0.1 s a sample, 10 s budget: passes of 5 (half a second).
        assert_eq!(next_pass(10, MAX_SPP, Some(10.0), 1.0), 5);
        // Near the end: what fits, then nothing.
        assert_eq!(next_pass(97, MAX_SPP, Some(10.0), 9.7), 3);
        assert_eq!(next_pass(100, MAX_SPP, Some(10.0), 9.97), 0);
        // The sample count still caps a budget.
        assert_eq!(next_pass(62, 64, Some(10.0), 0.1), 2);
    }
}
