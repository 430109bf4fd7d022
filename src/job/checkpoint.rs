//! Checkpoints: the EXR a render writes while sampling (every `--checkpoint-interval`
//! seconds, on SIGUSR1, and when a signal stops it), with the sample counts that let
//! `--resume` continue it; and the check that a checkpoint is this render's before it is
//! continued.

use super::header::HeaderFacts;
use crate::error::{Error, Result};
use crate::film::Film;
use crate::film::aov::Aov;
use crate::film::planes::Planes;
use crate::output::exr;
use crate::render::{RenderOptions, RenderStats};
use std::path::Path;
use std::time::Instant;

/// What a checkpoint being resumed already holds.
pub(super) struct Resumed {
    pub planes: Planes,
    pub discarded: u64,
    pub seconds: f64,
}

/// Reads the render to continue from `path`, checking that it is this render's (same
/// scene, shutter, settings, AOVs, window and pass); `None` if there is no file yet.
pub(super) fn read_checkpoint(
    path: &Path,
    source: &str,
    identity: Option<&(String, String)>,
    shutter: Option<&str>,
    options: &RenderOptions,
) -> Result<Option<Resumed>> {
    if !path.exists() {
        log::info!(
            "{} does not exist yet; rendering from the start",
            path.display()
        );
        return Ok(None);
    }
    let (planes, header) = exr::read(path)?;
    let bad = |element: &str, reason: String| Error::bad_input(path, element, reason);
    if header.number("lucerna/samples") == Some(0.0) {
        log::info!(
            "{} holds no samples; rendering from the start",
            path.display()
        );
        return Ok(None);
    }
    // The same scene: by its content where both have a fingerprint (any path may name
    // it), else by canonical path, else as named.
    let same_scene = match (header.text("lucerna/scene_fingerprint"), identity) {
        (Some(theirs), Some((_, ours))) => theirs == ours,
        (None, Some((canonical, _))) => {
            header.text("lucerna/scene") == Some(source)
                || header
                    .text("lucerna/scene")
                    .and_then(|s| std::fs::canonicalize(s).ok())
                    .is_some_and(|c| c.to_string_lossy() == canonical.as_str())
        }
        _ => header.text("lucerna/scene") == Some(source),
    };
    if !same_scene {
        if let (Some(_), Some((canonical, _))) =
            (header.text("lucerna/scene_fingerprint"), identity)
            && header.text("lucerna/scene_path") == Some(canonical.as_str())
        {
            return Err(bad(
                "lucerna/scene_fingerprint",
                format!(
                    "{source:?} has changed since this checkpoint was written: it cannot be continued"
                ),
            ));
        }
        return Err(bad(
            "lucerna/scene",
            format!(
                "a render of {:?}, not of {source:?}",
                header.text("lucerna/scene").unwrap_or("an unknown scene")
            ),
        ));
    }
    // The same instants: another shutter (or blur) is another image.
    if header.text("lucerna/shutter") != shutter {
        let describe = |s: Option<&str>| s.map_or_else(|| "closed".to_string(), str::to_string);
        return Err(bad(
            "lucerna/shutter",
            format!(
                "it was rendered with the shutter {}, this render's is {}: it cannot be continued",
                describe(header.text("lucerna/shutter")),
                describe(shutter)
            ),
        ));
    }
    let mut earlier = RenderOptions::default();
    earlier
        .load_recorded_settings(header.text("lucerna/settings").unwrap_or_default())
        .map_err(|e| bad("lucerna/settings", e))?;
    if let Some(what) = earlier.differs_from(options) {
        return Err(bad(
            "lucerna/settings",
            format!(
                "its {what} differ from this render's: it cannot be continued with these options"
            ),
        ));
    }
    if options.pass.is_some() && earlier.spp != options.spp {
        return Err(bad(
            "lucerna/settings",
            "a pass keeps its total sample count (--spp) when it is continued".into(),
        ));
    }
    Ok(Some(Resumed {
        planes,
        discarded: header.number("lucerna/nan_inf_discarded").unwrap_or(0.0) as u64,
        seconds: header.number("lucerna/render_seconds").unwrap_or(0.0),
    }))
}

/// Writes the checkpoints of one render after its passes.
pub(super) struct Checkpoints<'a> {
    /// Seconds between checkpoints, if periodic.
    pub interval: Option<f64>,
    /// Whether files are written at all.
    pub write_files: bool,
    pub output: &'a Path,
    pub facts: &'a HeaderFacts<'a>,
    /// Seconds an earlier render (the checkpoint continued) spent.
    pub earlier_seconds: f64,
    pub last: Instant,
}

impl Checkpoints<'_> {
    /// After a pass: writes a checkpoint if one is due (the interval has passed, or
    /// SIGUSR1 asked for one). A failed checkpoint is a warning: the render goes on.
    pub(super) fn after_pass(&mut self, film: &Film, stats: &RenderStats) {
        let due = self
            .interval
            .is_some_and(|s| self.last.elapsed().as_secs_f64() >= s);
        if !(crate::interrupt::take_snapshot_request() || due) || !self.write_files {
            return;
        }
        self.last = Instant::now();
        let mut stats = *stats;
        stats.seconds += self.earlier_seconds;
        stats.interrupted = true;
        let header = self.facts.header(film, &stats);
        match exr::write(self.output, film, &header, &[Aov::Spp]) {
            Ok(()) => log::info!(
                "checkpoint: {} samples per pixel written to {}",
                film.min_samples(),
                self.output.display()
            ),
            Err(e) => log::warn!("checkpoint not written: {e}"),
        }
    }
}
