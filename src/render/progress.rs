//! Progress of a render: the bar drawn on a terminal, and plain progress lines for logs
//! (lucerna's own or Tractor's `ALF_PROGRESS`), read from the same counter by a thread of
//! their own.

use std::io::IsTerminal;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

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

/// The progress of one render: a bar (drawn on a terminal; counted but hidden where only
/// lines are wanted), and the thread that prints progress lines from it every interval.
pub(super) struct Progress {
    bar: Option<indicatif::ProgressBar>,
    lines: Option<ProgressLines>,
    reporting: Arc<AtomicBool>,
    reporter: Option<JoinHandle<()>>,
    time: Option<f64>,
    adaptive: bool,
    pixels: u64,
    target: u32,
    start: Instant,
}

impl Progress {
    /// Starts reporting a render of `pixels` pixels that takes `target` samples each (or
    /// spends `time` seconds, or samples adaptively), begun at `start`, whose film already
    /// holds `samples_so_far` samples (a resumed render).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn start(
        bar_wanted: bool,
        lines: Option<ProgressLines>,
        time: Option<f64>,
        adaptive: bool,
        pixels: u64,
        target: u32,
        samples_so_far: u64,
        start: Instant,
    ) -> Self {
        let terminal_bar = bar_wanted && std::io::stderr().is_terminal();
        let bar = (terminal_bar || lines.is_some()).then(|| {
            let (length, template) = match (time, adaptive) {
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
        if let (Some(bar), None, false) = (&bar, time, adaptive) {
            bar.set_position(samples_so_far);
        }
        // Progress lines: a thread that reads the (hidden) bar every interval.
        let reporting = Arc::new(AtomicBool::new(true));
        let reporter = match (&bar, lines) {
            (Some(bar), Some(lines)) => {
                let (bar, reporting) = (bar.clone(), reporting.clone());
                let counts_samples = time.is_none() && !adaptive;
                let before = bar.position();
                Some(std::thread::spawn(move || {
                    let mut next = lines.interval;
                    while reporting.load(Ordering::Relaxed) {
                        std::thread::sleep(Duration::from_millis(20).min(lines.interval));
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
        Self {
            bar,
            lines,
            reporting,
            reporter,
            time,
            adaptive,
            pixels,
            target,
            start,
        }
    }

    /// What each finished tile of a pass advances.
    pub(super) fn tiles(&self) -> TileProgress<'_> {
        match (&self.bar, self.time, self.adaptive) {
            (Some(bar), Some(_), _) => TileProgress::Time(bar, self.start),
            (Some(bar), None, false) => TileProgress::Samples(bar),
            _ => TileProgress::Nothing,
        }
    }

    /// Adaptive sampling without a time budget: `n` pixels have reached the threshold.
    pub(super) fn pixels_done(&self, n: u64) {
        if let Some(bar) = self.bar.as_ref().filter(|_| self.time.is_none()) {
            bar.set_position(n);
        }
    }

    /// Ends the report: stops the lines' thread, prints the last line (this render took
    /// `samples`, the film holds `total`) unless the render was interrupted, clears the bar.
    pub(super) fn finish(self, samples: u64, total: u64, interrupted: bool) {
        self.reporting.store(false, Ordering::Relaxed);
        if let Some(reporter) = self.reporter {
            let _ = reporter.join();
        }
        if let (Some(lines), Some(_)) = (self.lines, &self.bar)
            && !interrupted
        {
            let spp = (self.time.is_none() && !self.adaptive)
                .then(|| (total as f64 / self.pixels as f64, self.target));
            eprintln!(
                "{}{}",
                crate::logging::stamp(),
                lines.line(1.0, self.start.elapsed().as_secs_f64(), Some(samples), spp)
            );
        }
        if let Some(bar) = self.bar {
            bar.finish_and_clear();
        }
    }
}

/// What a finished tile advances on the progress bar.
#[derive(Clone, Copy)]
pub(super) enum TileProgress<'a> {
    Nothing,
    /// The samples taken (fixed sample counts).
    Samples(&'a indicatif::ProgressBar),
    /// The milliseconds of a time budget spent since the render started: passes are up to
    /// a quarter of the budget, too coarse a step for the bar.
    Time(&'a indicatif::ProgressBar, Instant),
}

impl TileProgress<'_> {
    /// A tile that took `taken` samples is done.
    pub(super) fn advance(self, taken: u64) {
        match self {
            Self::Nothing => {}
            Self::Samples(bar) => bar.inc(taken),
            Self::Time(bar, start) => bar.set_position(start.elapsed().as_millis() as u64),
        }
    }
}
