//! The render loop: passes of samples over tiles, tiles in parallel on the current rayon
//! pool, an optional time budget, a progress bar, and the figures of the run.

pub mod plan;

use crate::film::aov::AovSet;
use crate::film::filter::PixelFilter;
use crate::film::{Film, PixelAccumulator, SampleRecord, Window};
use crate::integrator::ears::{Ears, LEARNING_SAMPLES, Learning};
use crate::integrator::estimator::RayCounts;
use crate::integrator::path::PathTracer;
use crate::integrator::settings::{SETTING_NAMES, read_settings_toml, write_settings_toml};
use crate::integrator::split::{
    self, FirstSplit, LearningPixels, PixelParts, SampleParts, SplitStats,
};
use crate::integrator::{RussianRoulette, Settings, Split, SplitChoice};
use crate::light::groups::LightGroups;
use crate::sampling::sampler::Sampler;
use crate::world::World;
use glam::Vec2;
use plan::{PlanMode, RenderPlan};
use rayon::prelude::*;
use std::io::IsTerminal;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Samples per pixel of a pass without a time budget.
const PASS_SAMPLES: u32 = 16;
/// Samples per pixel when neither a count nor a time is given.
pub const DEFAULT_SPP: u32 = 64;
/// Most samples per pixel a time budget may take.
const MAX_SPP: u32 = 1 << 24;
/// Most samples per pixel adaptive sampling takes when no sample count is given.
pub const ADAPTIVE_MAX_SPP: u32 = 1 << 16;
/// Samples every pixel takes before adaptive sampling decides (`min-spp`).
pub const DEFAULT_MIN_SPP: u32 = 16;

/// What to render: samples or time, integrator settings, AOVs, pixel filter, plan.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Samples per pixel; with a time budget or a noise threshold, the most to take.
    pub spp: Option<u32>,
    /// Time budget in seconds: passes continue until it is spent.
    pub time: Option<f64>,
    /// Adaptive sampling's target: the relative noise (square root of the predicted
    /// relMSE) at which sampling stops; `None` samples every pixel alike.
    pub noise_threshold: Option<f32>,
    /// Samples every pixel takes before adaptive sampling decides.
    pub min_spp: u32,
    /// Specialise the integrator to the scene and request, or force every feature on.
    pub plan: PlanMode,
    pub settings: Settings,
    pub aovs: AovSet,
    pub filter: PixelFilter,
    /// Light groups of the request (`--light-group`), before the scene's own.
    pub light_groups: Vec<crate::scene::LightGroup>,
    /// Render only these pixels of the image (a tile of a split render).
    pub crop: Option<Window>,
    /// Take only pass K of N (1-based): the K-th of N disjoint ranges of each pixel's sample
    /// sequence, so that merging the N renders gives the render with all the samples.
    pub pass: Option<(u32, u32)>,
    /// Show a progress bar (only drawn when stderr is a terminal).
    pub progress: bool,
    /// Plain progress lines on stderr for logs (farm tasks, batch children), every
    /// `interval`: `None` prints none.
    pub progress_lines: Option<ProgressLines>,
    /// Set (by a signal handler) to stop the render early: what has accumulated is kept.
    pub interrupt: Option<std::sync::Arc<AtomicBool>>,
}

/// Progress lines for logs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProgressLines {
    pub interval: std::time::Duration,
    /// Pixar Tractor's `ALF_PROGRESS n%` lines (which Tractor-style managers parse) instead
    /// of lucerna's own.
    pub alfred: bool,
}

impl ProgressLines {
    /// The line for fraction `done` of the render after `elapsed` seconds, having taken
    /// `samples` samples (when counted).
    pub fn line(
        &self,
        done: f64,
        elapsed: f64,
        samples: Option<u64>,
        spp: Option<(f64, u32)>,
    ) -> String {
        let percent = (100.0 * done).clamp(0.0, 100.0);
        if self.alfred {
            return format!("ALF_PROGRESS {}%", percent.floor() as u32);
        }
        let eta = if done > 0.0 {
            format!("{:.0} s", elapsed * (1.0 - done) / done)
        } else {
            "unknown".into()
        };
        let rate = samples.map_or_else(String::new, |s| {
            format!(", {:.2} M samples/s", s as f64 / elapsed.max(1e-9) / 1e6)
        });
        let spp = spp.map_or_else(String::new, |(have, of)| format!(", {have:.1} of {of} spp"));
        format!("lucerna: progress {percent:.1}%{spp}, elapsed {elapsed:.0} s, eta {eta}{rate}")
    }
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            spp: None,
            time: None,
            noise_threshold: None,
            min_spp: DEFAULT_MIN_SPP,
            plan: PlanMode::Auto,
            settings: Settings::default(),
            aovs: AovSet::default(),
            filter: PixelFilter::blackman_harris(1.5),
            light_groups: Vec::new(),
            crop: None,
            pass: None,
            progress: false,
            progress_lines: None,
            interrupt: None,
        }
    }
}

impl RenderOptions {
    /// What `lucerna render` (and each render of a batch job) starts from before its
    /// settings file and flags: the defaults, writing the beauty only.
    pub fn command_line() -> Self {
        Self {
            aovs: AovSet::parse("beauty").expect("the beauty parses"),
            ..Default::default()
        }
    }

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
            "noise-threshold" => {
                let t = value
                    .parse::<f32>()
                    .ok()
                    .filter(|t| t.is_finite() && *t > 0.0);
                self.noise_threshold = Some(t.ok_or_else(|| {
                    format!(
                        "noise-threshold: a positive relative noise level, e.g. 0.01, got {value:?}"
                    )
                })?);
            }
            "min-spp" => {
                let n = value.parse().ok().filter(|s| (2..=MAX_SPP).contains(s));
                self.min_spp = n.ok_or_else(|| {
                    format!("min-spp: an integer in 2..={MAX_SPP}, got {value:?}")
                })?;
            }
            "plan" => self.plan = PlanMode::parse(value)?,
            "filter" => {
                self.filter = PixelFilter::parse(value).ok_or_else(|| {
                    format!(
                        "unknown filter {value:?} (box, blackman-harris, blackman-harris:WIDTH)"
                    )
                })?
            }
            "aov" => self.aovs = AovSet::parse(value)?,
            "crop" => self.crop = Some(Window::parse(value)?),
            "light-groups" => self.light_groups = crate::light::groups::parse(value)?,
            "pass" => {
                let pass = value
                    .split_once('/')
                    .and_then(|(k, n)| Some((k.trim().parse().ok()?, n.trim().parse().ok()?)))
                    .filter(|&(k, n): &(u32, u32)| (1..=n).contains(&k));
                self.pass = Some(pass.ok_or_else(|| {
                    format!("pass: K/N with 1 <= K <= N, e.g. 2/4, got {value:?}")
                })?);
            }
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

    /// Every setting as TOML, with `spp` the samples actually taken (a pass's total): the
    /// header's record of how an image was made, readable back as a settings file.
    pub fn to_toml(&self, spp_taken: u32) -> String {
        // A pass is recorded by its total and its index, which fix its range of samples.
        let spp = if self.pass.is_some() {
            self.target_spp()
        } else {
            spp_taken
        };
        let mut pairs: Vec<(String, String)> = vec![("spp".into(), spp.to_string())];
        if let Some(t) = self.time {
            pairs.push(("time".into(), t.to_string()));
        }
        if let Some(t) = self.noise_threshold {
            pairs.push(("noise-threshold".into(), t.to_string()));
            pairs.push(("min-spp".into(), self.min_spp.to_string()));
        }
        pairs.push(("filter".into(), self.filter.describe()));
        pairs.push(("aov".into(), self.aovs.describe()));
        pairs.push(("plan".into(), self.plan.name().into()));
        if !self.light_groups.is_empty() {
            pairs.push((
                "light-groups".into(),
                crate::light::groups::describe(&self.light_groups),
            ));
        }
        if let Some(window) = self.crop {
            pairs.push(("crop".into(), window.describe()));
        }
        if let Some((k, n)) = self.pass {
            pairs.push(("pass".into(), format!("{k}/{n}")));
        }
        for name in SETTING_NAMES {
            pairs.push((
                name.into(),
                self.settings.get(name).expect("listed settings exist"),
            ));
        }
        write_settings_toml(&pairs)
    }

    /// The sample count when no time budget or noise threshold stops earlier (of all
    /// passes, with `pass`).
    fn target_spp(&self) -> u32 {
        match (self.spp, self.time, self.noise_threshold) {
            (Some(s), _, _) => s,
            (None, Some(_), _) => MAX_SPP,
            (None, None, Some(_)) => ADAPTIVE_MAX_SPP,
            (None, None, None) => DEFAULT_SPP,
        }
    }

    /// The range of each pixel's sample sequence this render takes: all of it, or pass
    /// K of N's share, samples ⌊(K−1)·S/N⌋ up to ⌊K·S/N⌋.
    pub fn sample_range(&self) -> std::ops::Range<u32> {
        let total = self.target_spp();
        match self.pass {
            None => 0..total,
            Some((k, n)) => {
                let at = |i: u32| (i as u64 * total as u64 / n as u64) as u32;
                at(k - 1)..at(k)
            }
        }
    }

    /// Whether the render decides from the whole image and all its samples, keeping state
    /// an EXR does not hold (adaptive sampling, efficiency-aware roulette, learned
    /// splitting): such a render cannot be cropped, split into passes or resumed.
    pub fn decides_from_whole_image(&self) -> bool {
        self.noise_threshold.is_some()
            || matches!(self.settings.rr, RussianRoulette::Efficiency(_))
            || self.settings.split == SplitChoice::Auto
    }

    /// Rejects combinations a split render cannot honour: a pass must be a fixed range of
    /// samples, and a window must render exactly the pixels of the whole image (adaptive
    /// sampling and learned roulette decide from the whole image).
    pub fn validate(&self) -> Result<(), String> {
        if let Some((_, n)) = self.pass {
            if self.time.is_some() || self.noise_threshold.is_some() {
                return Err("pass: a pass is a fixed range of samples; it takes --spp, not --time or --noise-threshold".into());
            }
            if self.target_spp() < n {
                return Err(format!(
                    "pass: {} samples per pixel cannot be split into {n} passes",
                    self.target_spp()
                ));
            }
        }
        if (self.pass.is_some() || self.crop.is_some()) && self.decides_from_whole_image() {
            return Err("crop and pass: adaptive sampling, rr = efficiency and split = auto decide from the whole image and all its samples, so a split render would differ from the whole one".into());
        }
        Ok(())
    }

    /// The light groups of this request in `world`: the request's, the scene's, and
    /// `default`.
    pub fn light_groups(&self, world: &World) -> LightGroups {
        LightGroups::assign(&world.light_names, &self.light_groups, &world.light_groups)
    }

    /// What makes an image rendered with `self` differ from one rendered with `other`
    /// besides the samples taken: the first differing group of settings, if any. A
    /// checkpoint continues only under equal settings; a batch re-renders an output whose
    /// settings differ from its job's.
    pub fn differs_from(&self, other: &RenderOptions) -> Option<&'static str> {
        [
            ("integrator settings", self.settings != other.settings),
            ("AOVs", self.aovs != other.aovs),
            (
                "pixel filter",
                self.filter.describe() != other.filter.describe(),
            ),
            ("crop", self.crop != other.crop),
            ("light groups", self.light_groups != other.light_groups),
            ("pass", self.pass != other.pass),
            (
                "adaptive sampling",
                self.noise_threshold != other.noise_threshold,
            ),
        ]
        .into_iter()
        .find_map(|(what, differs)| differs.then_some(what))
    }

    /// The empty film this request renders into, for `world`'s camera, with a layer for
    /// each light group if they are requested.
    pub fn film(&self, world: &World) -> Film {
        let display = (world.camera.width(), world.camera.height());
        let groups = self
            .aovs
            .wants_light_groups()
            .then(|| self.light_groups(world));
        let aovs = match &groups {
            Some(g) => self.aovs.with_light_groups(&g.names),
            None => self.aovs.clone(),
        };
        let mut film = Film::cropped(
            display,
            self.crop.unwrap_or(Window::full(display.0, display.1)),
            aovs,
            self.noise_threshold.is_some(),
        );
        if let Some(g) = groups {
            film.router.set_light_groups(&g.of_light);
        }
        if film.aovs.wants_crypto() {
            film.crypto_ids =
                crate::film::crypto::Ids::new(&world.objects.names, &world.material_names());
        }
        film
    }

    /// The render plan for `world` with these options.
    pub fn render_plan(&self, world: &World) -> RenderPlan {
        RenderPlan::new(
            &world.features,
            &self.aovs,
            self.plan,
            self.noise_threshold.is_some(),
            matches!(self.settings.rr, RussianRoulette::Efficiency(_)),
        )
    }
}

/// Figures of a finished render.
#[derive(Clone, Copy, Debug)]
pub struct RenderStats {
    pub seconds: f64,
    /// Samples per pixel taken (the most any pixel took, with adaptive sampling).
    pub spp: u32,
    pub samples: u64,
    pub rays: RayCounts,
    /// Contributions dropped for being NaN or infinite.
    pub discarded: u64,
    /// Stopped early by [`RenderOptions::interrupt`].
    pub interrupted: bool,
    /// The split counts `split = auto` chose (once its learning samples were taken).
    pub learned_split: Option<Split>,
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
        ) + &self.learned_split.map_or(String::new(), |s| {
            format!(", split learned: {}", s.describe())
        })
    }
}

/// Peak resident memory of this process in bytes (Linux's VmHWM), if known.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The samples of the next pass, `left` being the most it may take: fixed-size passes
/// without a budget. With one (`elapsed` of `budget` seconds having gone to `rendered`
/// samples per pixel, on average over the pixels): one sample to measure, then the samples
/// that fit in what remains, in the fewest passes of at most a quarter of the budget, of
/// equal size; none when less than half a sample's time remains. Every pass costs a fixed
/// time (about 3 ms on the Cornell box at 256², 2 threads, where a sample takes 65 ms: 32
/// passes of one sample against one of 32), which budgets cut into twentieths paid about
/// 15 times a second; a pass of at most a quarter of the budget still ends near it if the
/// machine slows down.
fn next_pass(left: u32, budget: Option<f64>, elapsed: f64, rendered: f64) -> u32 {
    let Some(budget) = budget else {
        return left.min(PASS_SAMPLES);
    };
    if rendered <= 0.0 {
        return 1.min(left);
    }
    let per_sample = elapsed / rendered;
    let remaining = budget - elapsed;
    if remaining < 0.5 * per_sample {
        return 0;
    }
    let fit = (remaining / per_sample).round().max(1.0);
    let most = (budget / 4.0 / per_sample).floor().max(1.0);
    let passes = (fit / most).ceil();
    ((fit / passes).ceil() as u32).clamp(1, left)
}

/// Samples each pixel takes in one pass.
enum PassSamples {
    /// Up to this many in all, everywhere (a pixel behind, after an interrupted pass or a
    /// resumed one, catches up).
    UpTo(u32),
    /// Per pixel, row-major over the film (adaptive sampling).
    PerPixel(Vec<u32>),
}

impl PassSamples {
    /// The split learning's pass: `n` samples in each of `film`'s learning pixels.
    fn learning(film: &Film, pixels: LearningPixels, n: u32) -> Self {
        let w = film.window;
        Self::PerPixel(
            (w.y..w.y + w.height)
                .flat_map(|y| (w.x..w.x + w.width).map(move |x| (x, y)))
                .map(|(x, y)| if pixels.contains(x, y) { n } else { 0 })
                .collect(),
        )
    }

    /// Samples to take at film pixel `pixel`, which has taken `taken`.
    #[inline]
    fn at(&self, pixel: usize, taken: u32) -> u32 {
        match self {
            Self::UpTo(total) => total.saturating_sub(taken),
            Self::PerPixel(counts) => counts[pixel],
        }
    }
}

/// Adaptive sampling's next pass: the samples each pixel still needs, or all zero when
/// every pixel has stopped.
///
/// The allocation that minimises the image's relMSE for the time spent gives pixel p a
/// sample count n_p = K·sqrt(v_p / c_p) (v_p: per-sample relative variance, c_p: rays per
/// sample); K is set so that the predicted relMSE, mean of v_p / n_p, equals the threshold
/// squared. Equivalently, a pixel stops once one more sample would lower the error per ray
/// by less than an image-wide amount: it stops on its own variance estimate, against a
/// threshold derived from the noise target. v_p and c_p come from the pixel's eight
/// neighbours, not from its own samples, so that the decision to stop a pixel does not
/// depend directly on the values averaged into it; what remains (its share of K, and its
/// neighbours' sample counts) is second order, and `tests/plan.rs` measures the bias.
/// A pixel at most doubles its count in a pass, so that later passes decide on better
/// estimates, and deficits under a sixteenth of its count wait for a later pass.
fn adaptive_pass(film: &Film, threshold: f64, most: u32) -> Vec<u32> {
    let (w, h) = (film.width as usize, film.height as usize);
    let mut variance = vec![0.0f64; w * h];
    let mut cost = vec![1.0f64; w * h];
    let mut samples = vec![0u32; w * h];
    for tile in &film.tiles {
        for ty in 0..tile.height {
            for tx in 0..tile.width {
                let p = (ty * tile.width + tx) as usize;
                let out = film.index(tile.x0 + tx, tile.y0 + ty);
                samples[out] = tile.samples_at(p);
                if let Some((v, c)) = tile.pixel_statistics(p) {
                    variance[out] = v;
                    cost[out] = c.max(1.0);
                }
            }
        }
    }
    // Leave-one-out neighbourhood means (the pixel itself when it has no neighbour).
    let neighbourhood = |values: &[f64], x: usize, y: usize| {
        let (mut sum, mut n) = (0.0, 0u32);
        for ny in y.saturating_sub(1)..(y + 2).min(h) {
            for nx in x.saturating_sub(1)..(x + 2).min(w) {
                if (nx, ny) != (x, y) {
                    sum += values[ny * w + nx];
                    n += 1;
                }
            }
        }
        if n == 0 {
            values[y * w + x]
        } else {
            sum / n as f64
        }
    };
    let estimates: Vec<(f64, f64)> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            (neighbourhood(&variance, x, y), neighbourhood(&cost, x, y))
        })
        .collect();
    let k = estimates.iter().map(|(v, c)| (v * c).sqrt()).sum::<f64>()
        / ((w * h) as f64 * threshold * threshold);
    estimates
        .iter()
        .zip(&samples)
        .map(|(&(v, c), &n)| {
            let wanted = (k * (v / c).sqrt()).ceil().min(most as f64) as u32;
            let deficit = wanted.saturating_sub(n);
            if deficit == 0 || deficit < n / 16 {
                0
            } else {
                deficit.min(n.max(1))
            }
        })
        .collect()
}

/// Scales a pass down to `allowed` samples in all (a time budget's share).
fn fit_pass(counts: &mut [u32], allowed: f64) {
    let total: u64 = counts.iter().map(|&c| c as u64).sum();
    if (total as f64) <= allowed {
        return;
    }
    let scale = allowed / total as f64;
    for c in counts {
        *c = (*c as f64 * scale).floor() as u32;
    }
}

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
    let mut ears = match options.settings.rr {
        RussianRoulette::Efficiency(max_split) => {
            Some(Ears::new(film.width, film.height, max_split))
        }
        _ => None,
    };
    // Learned splitting takes the first samples of its learning pixels split two and two,
    // then the counts chosen everywhere.
    let mut first_split = match options.settings.split {
        SplitChoice::Fixed(counts) => FirstSplit::fixed(counts),
        SplitChoice::Auto => FirstSplit::learning(),
    };
    let mut learned_split = None;
    let pixels = film.width as u64 * film.height as u64;
    let terminal_bar = options.progress && std::io::stderr().is_terminal();
    let bar = (terminal_bar || options.progress_lines.is_some()).then(|| {
        let (length, template) = match (options.time, adaptive) {
            (Some(t), _) => (
                (t * 1000.0) as u64,
                "{elapsed_precise} [{wide_bar}] {percent:>3}% of the time budget",
            ),
            (None, true) => (
                pixels,
                "{elapsed_precise} [{wide_bar}] {pos}/{len} pixels reached the noise threshold",
            ),
            (None, false) => (
                pixels * target as u64,
                "{elapsed_precise} [{wide_bar}] {percent:>3}% eta {eta}",
            ),
        };
        let bar = indicatif::ProgressBar::new(length);
        bar.set_style(
            indicatif::ProgressStyle::with_template(template).expect("the template is valid"),
        );
        if !terminal_bar {
            // Counted, not drawn: the progress lines read it.
            bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
        }
        bar
    });
    // A resumed render's samples so far (the other bars count time and pixels).
    if let (Some(bar), None, false) = (&bar, options.time, adaptive) {
        bar.set_position(film.total_samples());
    }
    let learning_pixels = LearningPixels::new(film.display.0, film.display.1);
    let counts = Mutex::new(RayCounts::default());
    let start = Instant::now();
    // Progress lines: a thread that reads the (hidden) bar every interval.
    let reporting = std::sync::Arc::new(AtomicBool::new(true));
    let reporter = match (&bar, options.progress_lines) {
        (Some(bar), Some(lines)) => {
            let (bar, reporting) = (bar.clone(), reporting.clone());
            let counts_samples = options.time.is_none() && !adaptive;
            let before = bar.position();
            Some(std::thread::spawn(move || {
                let mut next = lines.interval;
                while reporting.load(Ordering::Relaxed) {
                    std::thread::sleep(std::time::Duration::from_millis(20).min(lines.interval));
                    let elapsed = start.elapsed();
                    if elapsed < next {
                        continue;
                    }
                    next += lines.interval;
                    let done = bar.position() as f64 / bar.length().unwrap_or(1).max(1) as f64;
                    let samples = counts_samples.then(|| bar.position() - before);
                    let spp =
                        counts_samples.then(|| (bar.position() as f64 / pixels as f64, target));
                    eprintln!(
                        "{}{}",
                        crate::logging::stamp(),
                        lines.line(done, elapsed.as_secs_f64(), samples, spp)
                    );
                }
            }))
        }
        _ => None,
    };
    let resumed = film.min_samples().min(uniform_spp);
    let mut done = resumed;
    // What a time budget has rendered: the samples since the start, per pixel.
    let samples_before = film.total_samples();
    let rendered = |film: &Film| (film.total_samples() - samples_before) as f64 / pixels as f64;
    while !interrupted() {
        let elapsed = start.elapsed().as_secs_f64();
        // The samples each learning pixel takes, in the pass that learns the split counts.
        let split_learning = (options.settings.split == SplitChoice::Auto
            && learned_split.is_none()
            && done < uniform_spp)
            .then(|| split::LEARNING_SAMPLES.min(uniform_spp - done));
        let (pass, learning) = if let Some(n) = split_learning {
            (PassSamples::learning(&film, learning_pixels, n), false)
        } else if done < uniform_spp {
            let mut n = next_pass(uniform_spp - done, options.time, elapsed, rendered(&film));
            // Efficiency-aware roulette learns in passes of 1, 1, 2, 4, 8 samples, each
            // deciding with everything learned before it.
            let learning = ears.is_some() && done < LEARNING_SAMPLES;
            if learning {
                n = n.min(done.max(1));
            }
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
            if let Some(bar) = bar.as_ref().filter(|_| options.time.is_none()) {
                bar.set_position(counts.iter().filter(|&&c| c == 0).count() as u64);
            }
            if counts.iter().all(|&c| c == 0) {
                break;
            }
            (PassSamples::PerPixel(counts), false)
        } else {
            break;
        };
        let tracer_args = PassArgs {
            world,
            options,
            ears: ears.as_ref(),
            samples: &pass,
            first_sample: range.start,
            learning,
            split: first_split,
            split_learning: split_learning.is_some(),
            rays: &counts,
            progress: match (&bar, options.time, adaptive) {
                (Some(bar), Some(_), _) => Progress::Time(bar, start),
                (Some(bar), None, false) => Progress::Samples(bar),
                _ => Progress::Nothing,
            },
        };
        let k = plan.kernel;
        let learned = match (k.routing, k.emitter_hits, k.first_hit_data) {
            #[cfg(target_arch = "x86_64")]
            (false, emitters, false) if k.packet && !learning => {
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
        // In tile order, whatever the thread count: the next pass decides the same way.
        if let (Some(e), true) = (ears.as_mut(), learning) {
            for l in learned.iter().filter_map(|t| t.0.as_ref()) {
                e.merge(l);
            }
            e.refresh();
        }
        if let Some(n) = split_learning {
            let mut stats = SplitStats::default();
            for s in learned.iter().filter_map(|t| t.1.as_ref()) {
                stats.merge(s);
            }
            let counts = stats.choose();
            first_split = FirstSplit::after_learning(counts, n, learning_pixels);
            learned_split = Some(counts);
        }
        if let PassSamples::UpTo(total) = pass {
            done = total;
        }
        if !interrupted() {
            after_pass(
                &film,
                &RenderStats {
                    seconds: start.elapsed().as_secs_f64(),
                    spp: film.max_samples(),
                    samples: film.total_samples(),
                    rays: *counts.lock().expect("no thread panicked holding the lock"),
                    discarded: film.discarded(),
                    interrupted: false,
                    learned_split,
                },
            );
        }
    }
    reporting.store(false, Ordering::Relaxed);
    if let Some(reporter) = reporter {
        let _ = reporter.join();
    }
    if let (Some(lines), Some(bar)) = (options.progress_lines, &bar)
        && !interrupted()
    {
        let _ = bar;
        let samples = film.total_samples() - samples_before;
        let spp = (options.time.is_none() && !adaptive)
            .then(|| (film.total_samples() as f64 / pixels as f64, target));
        eprintln!(
            "{}{}",
            crate::logging::stamp(),
            lines.line(1.0, start.elapsed().as_secs_f64(), Some(samples), spp)
        );
    }
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    let stats = RenderStats {
        seconds: start.elapsed().as_secs_f64(),
        spp: film.max_samples(),
        samples: film.total_samples(),
        rays: *counts.lock().expect("no thread panicked holding the lock"),
        discarded: film.discarded(),
        interrupted: interrupted(),
        learned_split,
    };
    (film, stats)
}

/// What every tile of a pass shares.
struct PassArgs<'a> {
    world: &'a World,
    options: &'a RenderOptions,
    ears: Option<&'a Ears>,
    samples: &'a PassSamples,
    /// Index in each pixel's sample sequence of the render's first sample (a pass's
    /// share starts there).
    first_sample: u32,
    /// Whether efficiency-aware roulette learns in this pass.
    learning: bool,
    /// How the first vertex splits, and whether this pass learns the counts.
    split: FirstSplit,
    split_learning: bool,
    rays: &'a Mutex<RayCounts>,
    /// What finished tiles advance.
    progress: Progress<'a>,
}

/// Tiles a rayon job takes: one, so that a thread that runs out of tiles takes the next
/// one left. Rayon otherwise cuts the tiles into as many runs as threads and halves them
/// only for a thread that steals: with two threads, in runs of 64 tiles at 256², whose
/// unequal costs left one thread idle for 50-100 ms at the end of every pass of 16 samples
/// (perf samples by thread; 4 % of a 64-sample Cornell box).
const TILES_PER_JOB: usize = 1;

/// Renders one pass over every tile with the kernel variant `<ROUTED, EMITTERS, DATA>`
/// (see `plan::Kernel`); returns what each tile learned for efficiency-aware roulette and
/// for learned splitting.
fn run_pass<const ROUTED: bool, const EMITTERS: bool, const DATA: bool>(
    film: &mut Film,
    args: &PassArgs,
) -> Vec<(Option<Learning>, Option<SplitStats>)> {
    let PassArgs {
        world,
        options,
        ears,
        samples,
        first_sample,
        learning,
        split,
        split_learning,
        rays: counts,
        progress,
    } = *args;
    let router = &film.router;
    let crypto = film.aovs.wants_crypto();
    let tracer = PathTracer::<EMITTERS, DATA>::new(world, &options.settings, ears, split);
    let window = film.window;
    let camera = &world.camera;
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
                    for index in first..first + n {
                        sampler.start(x, y, index);
                        let cs = sampler.camera();
                        let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                        let ray =
                            camera.generate_ray(centre + options.filter.sample(cs.film), cs.lens);
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
            (tile_learning, tile_split)
        })
        .collect()
}

/// Renders one pass over every tile with the packet kernel (see `plan::Kernel::packet`):
/// the beauty only, and no roulette learning. Returns what a pass that learns the split
/// counts learned, tile by tile in tile order, as [`run_pass`] does.
#[cfg(target_arch = "x86_64")]
fn run_packet_pass<const EMITTERS: bool>(
    film: &mut Film,
    args: &PassArgs,
) -> Vec<(Option<Learning>, Option<SplitStats>)> {
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
            (None, split_learning.then_some(buffers.split_stats))
        })
        .collect()
}

/// What a finished tile advances on the progress bar.
#[derive(Clone, Copy)]
enum Progress<'a> {
    Nothing,
    /// The samples taken (fixed sample counts).
    Samples(&'a indicatif::ProgressBar),
    /// The milliseconds of a time budget spent since the render started: passes are up to
    /// a quarter of the budget, too coarse a step for the bar.
    Time(&'a indicatif::ProgressBar, Instant),
}

/// Adds a finished tile's ray counts to the render's and advances the progress bar by its
/// `taken` samples.
fn tile_done(counts: &Mutex<RayCounts>, rays: &RayCounts, progress: Progress, taken: u64) {
    counts
        .lock()
        .expect("no thread panicked holding the lock")
        .add(rays);
    match progress {
        Progress::Nothing => {}
        Progress::Samples(bar) => bar.inc(taken),
        Progress::Time(bar, start) => bar.set_position(start.elapsed().as_millis() as u64),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every render setting a header records reads back to the same options.
    #[test]
    fn settings_round_trip_through_the_header() {
        let mut options = RenderOptions::default();
        for (name, value) in [
            ("time", "2.5"),
            ("noise-threshold", "0.02"),
            ("min-spp", "8"),
            ("plan", "general"),
            ("filter", "box"),
            ("aov", "albedo,spp,lobes,lightgroups"),
            ("mis", "balance"),
            ("light-groups", "key=lamp_*,sun;sky=environment"),
            ("crop", "1,2,30,40"),
        ] {
            options.set(name, value).unwrap();
        }
        let mut read = RenderOptions::default();
        read.load_settings(&options.to_toml(40)).unwrap();
        assert_eq!(read.spp, Some(40));
        assert_eq!(read.time, options.time);
        assert_eq!(read.noise_threshold, options.noise_threshold);
        assert_eq!(read.min_spp, 8);
        assert_eq!(read.plan, PlanMode::General);
        assert_eq!(read.aovs, options.aovs);
        assert_eq!(read.filter.describe(), "box");
        assert_eq!(read.settings, options.settings);
        assert_eq!(read.light_groups, options.light_groups);
        assert_eq!(read.crop, options.crop);
    }

    #[test]
    fn passes_fit_the_budget() {
        assert_eq!(next_pass(100, None, 0.0, 0.0), 16);
        assert_eq!(next_pass(4, None, 0.0, 0.0), 4);
        assert_eq!(next_pass(MAX_SPP, Some(10.0), 0.0, 0.0), 1);
        // 0.1 s a sample, 10 s budget: 90 samples left, in four passes of at most 25.
        assert_eq!(next_pass(MAX_SPP, Some(10.0), 1.0, 10.0), 23);
        // 0.07 s a sample, 1 s budget: 13 samples left, in five passes of at most 3.
        assert_eq!(next_pass(MAX_SPP, Some(1.0), 0.07, 1.0), 3);
        assert_eq!(next_pass(MAX_SPP, Some(1.0), 0.7, 10.0), 2);
        // A learning pass that took a quarter of the pixels' first 4 samples counts as one.
        assert_eq!(next_pass(MAX_SPP, Some(1.0), 0.07, 0.25 * 4.0), 3);
        // Near the end: what fits, then nothing.
        assert_eq!(next_pass(MAX_SPP, Some(10.0), 9.7, 97.0), 3);
        assert_eq!(next_pass(MAX_SPP, Some(10.0), 9.97, 100.0), 0);
        // The sample count still caps a budget.
        assert_eq!(next_pass(2, Some(10.0), 0.1, 62.0), 2);
    }
}
