//! What lucerna tells its user on stderr while it works: warnings, what it wrote, progress
//! lines. Messages go through the `log` facade; this module is its backend.
//!
//! Lines read `lucerna: MESSAGE` (info), `lucerna: warning: MESSAGE`, `lucerna: debug:
//! MESSAGE`; `--log-level` (error, warn, info, debug) chooses how much is said, and
//! `--log-timestamps` starts every line with its UTC time (RFC 3339, milliseconds), as farm
//! logs that interleave many tasks want. The final `error: FILE: ELEMENT: REASON` line of a
//! failed command is printed by the command itself and always shown.

use log::{Level, LevelFilter, Log, Metadata, Record};
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

static TIMESTAMPS: AtomicBool = AtomicBool::new(false);

struct StderrLogger;

static LOGGER: StderrLogger = StderrLogger;

impl Log for StderrLogger {
    fn enabled(&self, metadata: &Metadata) -> bool {
        metadata.level() <= log::max_level()
    }

    fn log(&self, record: &Record) {
        if !self.enabled(record.metadata()) {
            return;
        }
        let kind = match record.level() {
            Level::Error => "error: ",
            Level::Warn => "warning: ",
            Level::Info => "",
            Level::Debug | Level::Trace => "debug: ",
        };
        // One write per line, so that lines of several threads do not interleave.
        let line = format!("{}lucerna: {kind}{}\n", stamp(), record.args());
        let _ = std::io::stderr().lock().write_all(line.as_bytes());
    }

    fn flush(&self) {}
}

/// The time prefix of a line (empty without `--log-timestamps`).
pub fn stamp() -> String {
    if TIMESTAMPS.load(Ordering::Relaxed) {
        format!(
            "{} ",
            humantime::format_rfc3339_millis(std::time::SystemTime::now())
        )
    } else {
        String::new()
    }
}

/// Parses a `--log-level` value.
pub fn parse_level(text: &str) -> Result<LevelFilter, String> {
    match text {
        "error" => Ok(LevelFilter::Error),
        "warn" | "warning" => Ok(LevelFilter::Warn),
        "info" => Ok(LevelFilter::Info),
        "debug" => Ok(LevelFilter::Debug),
        _ => Err(format!("one of error, warn, info, debug, got {text:?}")),
    }
}

/// Installs the stderr logger (once per process; later calls only change level and
/// timestamps).
pub fn init(level: LevelFilter, timestamps: bool) {
    let _ = log::set_logger(&LOGGER);
    log::set_max_level(level);
    TIMESTAMPS.store(timestamps, Ordering::Relaxed);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_parse_and_bad_ones_are_named() {
        assert_eq!(parse_level("debug"), Ok(LevelFilter::Debug));
        assert_eq!(parse_level("warning"), Ok(LevelFilter::Warn));
        assert!(parse_level("loud").unwrap_err().contains("\"loud\""));
    }

    #[test]
    fn timestamps_are_rfc3339_utc() {
        TIMESTAMPS.store(true, Ordering::Relaxed);
        let s = stamp();
        TIMESTAMPS.store(false, Ordering::Relaxed);
        // 2026-12-03T22:40:01.123Z and a space.
        assert_eq!(s.len(), 25, "{s}");
        assert!(s.ends_with("Z "), "{s}");
        assert_eq!(&s[10..11], "T");
    }
}
