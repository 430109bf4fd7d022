//! What differs between operating systems, in one place: reading and writing a file at an
//! offset, what kind of non-file a path is, whether a folder lives in memory, signals (the
//! stop signals and the snapshot request) and signalling child processes.
//!
//! lucerna is built and tested on Linux; the rest of Unix shares its code. Elsewhere
//! (Windows) the same functions exist with what the platform offers: Ctrl-C and SIGTERM
//! stop a render (there is no snapshot signal: `--checkpoint-interval` writes snapshots
//! instead), a child is stopped by terminating it, and no folder counts as in memory.

use std::fs::File;
use std::io;

/// What kind of file system object `meta` is, for messages about a path that is not a
/// regular file.
pub fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        } else if t.is_char_device() || t.is_block_device() {
            return "a device";
        } else if t.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

/// Fills `out` from `file` at `offset`, without moving a shared cursor (threads read one
/// file at once).
pub fn read_exact_at(file: &File, out: &mut [u8], offset: u64) -> io::Result<()> {
    #[cfg(unix)]
    {
        std::os::unix::fs::FileExt::read_exact_at(file, out, offset)
    }
    #[cfg(windows)]
    {
        let (mut done, mut out) = (0u64, out);
        while !out.is_empty() {
            match std::os::windows::fs::FileExt::seek_read(file, out, offset + done) {
                Ok(0) => return Err(io::ErrorKind::UnexpectedEof.into()),
                Ok(n) => {
                    out = &mut out[n..];
                    done += n as u64;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

/// Writes some of `bytes` to `file` at `offset`; the number written.
pub fn write_at(file: &File, bytes: &[u8], offset: u64) -> io::Result<usize> {
    #[cfg(unix)]
    {
        std::os::unix::fs::FileExt::write_at(file, bytes, offset)
    }
    #[cfg(windows)]
    {
        std::os::windows::fs::FileExt::seek_write(file, bytes, offset)
    }
}

/// Whether the file system of `folder` keeps its files in memory (tmpfs, ramfs).
pub fn in_memory(folder: &std::path::Path) -> bool {
    #[cfg(target_os = "linux")]
    {
        const TMPFS_MAGIC: i64 = 0x0102_1994;
        const RAMFS_MAGIC: i64 = 0x8584_58f6;
        use std::os::unix::ffi::OsStrExt;
        let Ok(path) = std::ffi::CString::new(folder.as_os_str().as_bytes()) else {
            return false;
        };
        let mut stats: libc::statfs = unsafe { std::mem::zeroed() };
        // SAFETY: `path` is a NUL-terminated string and `stats` a buffer of the right type.
        if unsafe { libc::statfs(path.as_ptr(), &mut stats) } != 0 {
            return false;
        }
        matches!(stats.f_type as i64, TMPFS_MAGIC | RAMFS_MAGIC)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = folder;
        false
    }
}

/// The signal that asks a render for a snapshot of what it has so far (SIGUSR1), where the
/// platform has one.
#[cfg(unix)]
pub const SNAPSHOT_SIGNAL: Option<i32> = Some(signal_hook::consts::SIGUSR1);
#[cfg(not(unix))]
pub const SNAPSHOT_SIGNAL: Option<i32> = None;

/// Calls `handle` (on a thread of its own) with every stop signal (SIGINT, SIGTERM) and
/// snapshot request the process receives.
pub fn watch_signals(handle: fn(i32)) -> Result<(), String> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    #[cfg(unix)]
    {
        let mut signals =
            signal_hook::iterator::Signals::new([SIGINT, SIGTERM, signal_hook::consts::SIGUSR1])
                .map_err(|e| e.to_string())?;
        std::thread::Builder::new()
            .name("lucerna-signals".into())
            .spawn(move || {
                for signal in signals.forever() {
                    handle(signal);
                }
            })
            .map_err(|e| e.to_string())?;
    }
    #[cfg(not(unix))]
    {
        use std::sync::Arc;
        use std::sync::atomic::{AtomicBool, Ordering};
        let flags = [SIGINT, SIGTERM].map(|s| (s, Arc::new(AtomicBool::new(false))));
        for (signal, flag) in &flags {
            signal_hook::flag::register(*signal, flag.clone()).map_err(|e| e.to_string())?;
        }
        std::thread::Builder::new()
            .name("lucerna-signals".into())
            .spawn(move || {
                loop {
                    for (signal, flag) in &flags {
                        if flag.swap(false, Ordering::SeqCst) {
                            handle(*signal);
                        }
                    }
                    std::thread::sleep(std::time::Duration::from_millis(20));
                }
            })
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// What to ask of a child process.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request {
    /// Write a snapshot and go on (SIGUSR1; nothing where there is no such signal).
    Snapshot,
    /// Stop, writing what it has (SIGTERM; terminated where there are no signals).
    Stop,
}

/// Sends `request` to `child`.
pub fn ask(child: &mut std::process::Child, request: Request) {
    #[cfg(unix)]
    {
        let signal = match request {
            Request::Snapshot => libc::SIGUSR1,
            Request::Stop => libc::SIGTERM,
        };
        // SAFETY: kill(2) with the pid of a child this process has not yet reaped.
        unsafe { libc::kill(child.id() as libc::pid_t, signal) };
    }
    #[cfg(not(unix))]
    if request == Request::Stop {
        let _ = child.kill();
    }
}

/// Makes `command`'s child start with the snapshot signal ignored until its own handler
/// takes it over (SIGUSR1's default action would end it).
pub fn start_ignoring_snapshots(command: &mut std::process::Command) {
    #[cfg(unix)]
    // SAFETY: signal(2) is async-signal-safe, as code between fork and exec must be.
    unsafe {
        std::os::unix::process::CommandExt::pre_exec(command, || {
            libc::signal(libc::SIGUSR1, libc::SIG_IGN);
            Ok(())
        });
    }
    #[cfg(not(unix))]
    let _ = command;
}

/// Kills process `pid` (a child this process started and has not reaped) and waits until it
/// is gone.
pub fn kill_and_reap(pid: u32) {
    #[cfg(unix)]
    // SAFETY: kill(2) and waitpid(2) with a pid this process started and has not reaped yet.
    // Waiting makes sure the child is gone before this process exits (a killed process can
    // take a while to tear down on a loaded machine); where the thread that runs it reaps it
    // first, waitpid returns at once (ECHILD).
    unsafe {
        libc::kill(pid as libc::pid_t, libc::SIGKILL);
        libc::waitpid(pid as libc::pid_t, std::ptr::null_mut(), 0);
    }
    #[cfg(not(unix))]
    {
        let _ = std::process::Command::new("taskkill")
            .args(["/F", "/T", "/PID", &pid.to_string()])
            .output();
    }
}
