//! How the command line ends on SIGINT and SIGTERM.
//!
//! A farm manager that stops a task expects the process gone within about a second, whatever
//! it is doing, and a rerun to continue from what was saved. So:
//!
//! - While the scene is read, converted (the USD plugin) or prepared (BVH, lights), there is
//!   nothing worth saving: a signal ends the process at once with 128 + signal. The USD
//!   plugin's process is killed and scratch folders are removed first ([`spawn_watched`],
//!   [`watch_scratch`]).
//! - While samples are taken ([`defer`]), a signal only sets the stop flag: the render stops
//!   at its next tile and writes a checkpoint that `--resume` continues. A second signal ends
//!   the process at once.
//!
//! - SIGUSR1 asks for a snapshot: the render writes its checkpoint after the pass under way
//!   and goes on ([`take_snapshot_request`]); one received while the scene is read is
//!   answered after the first pass, and the other commands ignore it.
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
    /// SIGUSR1 received and not yet answered.
    snapshot: AtomicBool,
    /// What to undo before a signal ends the process, with the id of its guard.
    cleanups: Mutex<Vec<(u64, Cleanup)>>,
}

static STATE: OnceLock<State> = OnceLock::new();

fn state() -> &'static State {
    STATE.get_or_init(|| State {
        stop: Arc::new(AtomicBool::new(false)),
        received: AtomicUsize::new(0),
        deferred: AtomicUsize::new(0),
        snapshot: AtomicBool::new(false),
        cleanups: Mutex::new(Vec::new()),
    })
}

/// Starts watching SIGINT and SIGTERM (once per process; later calls return the same flag).
/// Returns the flag a signal sets, for [`crate::render::RenderOptions::interrupt`].
pub fn install() -> Result<Arc<AtomicBool>> {
    static INSTALLED: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    INSTALLED
        .get_or_init(|| {
            crate::platform::watch_signals(handle)?;
            Ok(())
        })
        .clone()
        .map_err(|e| Error::other("", "signals", e))?;
    Ok(state().stop.clone())
}

fn handle(signal: i32) {
    let s = state();
    if Some(signal) == crate::platform::SNAPSHOT_SIGNAL {
        s.snapshot.store(true, Ordering::SeqCst);
        return;
    }
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
    std::process::exit(exit_code(signal) as i32);
}

/// Kills registered child processes and removes registered scratch folders and files.
fn clean_up() {
    for (_, cleanup) in state()
        .cleanups
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
    {
        match cleanup {
            Cleanup::Child(pid) => crate::platform::kill_and_reap(*pid),
            Cleanup::Path(path) if path.is_dir() => {
                let _ = std::fs::remove_dir_all(path);
            }
            Cleanup::Path(path) => {
                let _ = std::fs::remove_file(path);
            }
        }
    }
}

/// The signal received (0 if none).
pub fn received() -> i32 {
    state().received.load(Ordering::SeqCst) as i32
}

/// The exit code of a process a signal stopped: 128 + the signal, as shells report it.
pub fn exit_code(signal: i32) -> u8 {
    (128 + signal.clamp(1, 127)) as u8
}

/// Whether SIGUSR1 asked for a snapshot since the last call (which answers it).
pub fn take_snapshot_request() -> bool {
    state().snapshot.swap(false, Ordering::SeqCst)
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

/// Something a signal that ends the process must undo first.
enum Cleanup {
    /// A child process to kill (the USD plugin).
    Child(u32),
    /// A scratch folder or temporary file to remove.
    Path(PathBuf),
}

/// Keeps its cleanup registered while alive; dropped, the owner has finished with it (the
/// child reaped, the folder removed or the file renamed).
pub struct CleanupGuard(u64);

/// Ids of cleanup guards.
static NEXT_CLEANUP: AtomicUsize = AtomicUsize::new(0);

fn register(cleanup: Cleanup) -> CleanupGuard {
    let id = NEXT_CLEANUP.fetch_add(1, Ordering::Relaxed) as u64;
    state()
        .cleanups
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push((id, cleanup));
    CleanupGuard(id)
}

impl Drop for CleanupGuard {
    fn drop(&mut self) {
        state()
            .cleanups
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .retain(|(id, _)| *id != self.0);
    }
}

/// Starts `command` and registers it to be killed if a signal ends this process, with the
/// signal handler held off in between: a signal that arrives while the child starts still
/// finds it registered (else the child would outlive this process).
pub fn spawn_watched(
    command: &mut std::process::Command,
) -> std::io::Result<(std::process::Child, CleanupGuard)> {
    let mut cleanups = state().cleanups.lock().unwrap_or_else(|e| e.into_inner());
    let child = command.spawn()?;
    let id = NEXT_CLEANUP.fetch_add(1, Ordering::Relaxed) as u64;
    cleanups.push((id, Cleanup::Child(child.id())));
    Ok((child, CleanupGuard(id)))
}

/// Removes scratch folder or temporary file `path` if a signal ends this process.
pub fn watch_scratch(path: PathBuf) -> CleanupGuard {
    register(Cleanup::Path(path))
}
