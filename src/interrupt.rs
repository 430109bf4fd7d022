//! How the command line ends on SIGINT and SIGTERM.
//!
//! A farm manager that stops a task expects the process gone within about a second, whatever
//! it is doing, and a rerun to continue from what was saved. So:
//!
//! - While the scene is read, converted (the USD plugin) or prepared (BVH, lights), there is
//!   nothing worth saving: a signal ends the process at once with 128 + signal. The USD
//!   plugin's process is killed and scratch folders are removed first ([`ChildGuard`],
//!   [`ScratchGuard`]).
//! - While samples are taken ([`defer`]), a signal only sets the stop flag: the render stops
//!   at its next tile and writes a checkpoint that `--resume` continues. A second signal ends
//!   the process at once.
//!
//! The handler runs on a thread of its own (signal-hook's iterator), so it may take locks and
//! print; library users that never call [`install`] keep the default behaviour of signals.

use crate::error::{Error, Result};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

struct State {
    stop: Arc<AtomicBool>,
    received: AtomicUsize,
    /// Number of live [`Deferred`] guards: while positive, the first signal only stops.
    deferred: AtomicUsize,
    children: Mutex<Vec<u32>>,
    scratch: Mutex<Vec<PathBuf>>,
}

static STATE: OnceLock<State> = OnceLock::new();

fn state() -> &'static State {
    STATE.get_or_init(|| State {
        stop: Arc::new(AtomicBool::new(false)),
        received: AtomicUsize::new(0),
        deferred: AtomicUsize::new(0),
        children: Mutex::new(Vec::new()),
        scratch: Mutex::new(Vec::new()),
    })
}

/// Starts watching SIGINT and SIGTERM (once per process; later calls return the same flag).
/// Returns the flag a signal sets, for [`crate::render::RenderOptions::interrupt`].
pub fn install() -> Result<Arc<AtomicBool>> {
    static INSTALLED: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    INSTALLED
        .get_or_init(|| {
            use signal_hook::consts::{SIGINT, SIGTERM};
            let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM])
                .map_err(|e| e.to_string())?;
            std::thread::Builder::new()
                .name("lucerna-signals".into())
                .spawn(move || {
                    for signal in signals.forever() {
                        handle(signal);
                    }
                })
                .map_err(|e| e.to_string())?;
            Ok(())
        })
        .clone()
        .map_err(|e| Error::other("", "signals", e))?;
    Ok(state().stop.clone())
}

fn handle(signal: i32) {
    let s = state();
    let first = s.received.swap(signal as usize, Ordering::SeqCst) == 0;
    s.stop.store(true, Ordering::SeqCst);
    if first && s.deferred.load(Ordering::SeqCst) > 0 {
        return;
    }
    clean_up();
    // Not eprintln!: a closed stderr must not keep this thread from ending the process.
    use std::io::Write;
    let _ = writeln!(
        std::io::stderr(),
        "lucerna: interrupted (signal {signal}){}; nothing written",
        if first { " before any result" } else { "" }
    );
    std::process::exit(128 + signal);
}

/// Kills registered child processes and removes registered scratch folders.
fn clean_up() {
    let s = state();
    for &pid in s.children.lock().unwrap_or_else(|e| e.into_inner()).iter() {
        // SAFETY: kill(2) with a pid this process started and has not reaped yet.
        unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) };
    }
    for path in s.scratch.lock().unwrap_or_else(|e| e.into_inner()).iter() {
        if path.is_dir() {
            let _ = std::fs::remove_dir_all(path);
        } else {
            let _ = std::fs::remove_file(path);
        }
    }
}

/// The signal received (0 if none).
pub fn received() -> i32 {
    state().received.load(Ordering::SeqCst) as i32
}

/// Whether a signal has been received.
pub fn stopping() -> bool {
    state().stop.load(Ordering::SeqCst)
}

/// While alive, a first signal sets the stop flag instead of ending the process.
pub struct Deferred(());

/// Defers signals for the life of the guard (sampling, a batch forwarding signals to its
/// children).
pub fn defer() -> Deferred {
    state().deferred.fetch_add(1, Ordering::SeqCst);
    Deferred(())
}

impl Drop for Deferred {
    fn drop(&mut self) {
        state().deferred.fetch_sub(1, Ordering::SeqCst);
    }
}

/// A child process killed if a signal ends this process; unregistered when dropped.
pub struct ChildGuard(u32);

/// Registers child `pid` (call before waiting for it).
pub fn watch_child(pid: u32) -> ChildGuard {
    state()
        .children
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(pid);
    ChildGuard(pid)
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        state()
            .children
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .retain(|&p| p != self.0);
    }
}

/// A scratch folder or temporary file removed if a signal ends this process; unregistered
/// when dropped (its owner removes or renames it then).
pub struct ScratchGuard(PathBuf);

/// Registers scratch folder or temporary file `dir`.
pub fn watch_scratch(dir: PathBuf) -> ScratchGuard {
    state()
        .scratch
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(dir.clone());
    ScratchGuard(dir)
}

impl Drop for ScratchGuard {
    fn drop(&mut self) {
        state()
            .scratch
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .retain(|d| *d != self.0);
    }
}
