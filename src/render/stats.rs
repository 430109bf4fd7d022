//! The figures of a render: time, samples, rays, discarded contributions, and what learned
//! techniques chose; and the process's peak memory.

use crate::integrator::Split;
use crate::integrator::estimator::RayCounts;

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
