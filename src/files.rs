//! What lucerna agrees to read and to replace.
//!
//! Inputs (scenes, buffers, textures, settings, checkpoints, merge parts) must be regular
//! files: reading a FIFO or a device blocks or never ends. Outputs are checked before a
//! render starts, so an hour of rendering is not lost to a name that cannot be written: an
//! existing output must be a regular file (a device node, FIFO or directory is never
//! replaced: renaming over `/dev/null` as root would replace the device), and its directory
//! must accept a new file (a probe file is created and removed). Every file lucerna writes
//! is written atomically ([`write_atomically`]).

use crate::error::{Error, Result};
use std::path::Path;

/// Checks that `path` (symbolic links followed) is a regular file; the reason otherwise.
pub fn check_input(path: &Path) -> std::result::Result<(), String> {
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot read: {e}"))?;
    if meta.is_file() {
        Ok(())
    } else {
        Err(format!(
            "{} is {}, not a file",
            path.display(),
            crate::platform::file_kind(&meta)
        ))
    }
}

/// Reads the regular file `path`; the reason otherwise.
pub fn read_input(path: &Path) -> std::result::Result<Vec<u8>, String> {
    check_input(path)?;
    std::fs::read(path).map_err(|e| format!("cannot read: {e}"))
}

/// Checks that `path` resolves (through any symbolic links) to a place inside `base`, as
/// a relative path without `..` promises; the reason otherwise. A link out of the scene's
/// directory is refused like `..` is.
pub fn check_inside(path: &Path, base: &Path) -> std::result::Result<(), String> {
    let (Ok(real), Ok(real_base)) = (std::fs::canonicalize(path), std::fs::canonicalize(base))
    else {
        return Ok(()); // missing: reading it reports that
    };
    if real.starts_with(&real_base) {
        Ok(())
    } else {
        Err(format!(
            "{} leaves the scene's directory through a symbolic link (to {})",
            path.display(),
            real.display()
        ))
    }
}

/// Checks, before rendering, that `path` can be written: an existing `path` is a regular
/// file, and its directory (created if missing, and said so) takes a new file.
pub fn check_output(path: &Path, element: &str) -> Result<()> {
    if path.file_name().is_none() {
        return Err(Error::bad_input(path, element, "names no file"));
    }
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
    {
        return Err(Error::bad_input(
            path,
            element,
            format!(
                "is {}: an output must be a file, and this is never replaced",
                crate::platform::file_kind(&meta)
            ),
        ));
    }
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !dir.exists() {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::other(dir, element, format!("cannot create the directory: {e}")))?;
        log::info!("{}: created the directory for {element}", dir.display());
    }
    tempfile::Builder::new()
        .prefix(".lucerna-probe-")
        .tempfile_in(dir)
        .map_err(|e| Error::other(dir, element, format!("cannot write here: {e}")))?;
    Ok(())
}

/// Whether process `pid` is gone (no process of that number exists). A live process that
/// took the number over keeps what it might own: only the absence of a process is sure.
pub fn process_is_gone(pid: u32) -> bool {
    pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists()
}

/// Removes what processes that are gone left in `dir` under names `PREFIX<pid>` or
/// `PREFIX<pid>-...` (temporary files of an output, scratch folders of the USD plugin): a
/// process killed with SIGKILL cannot clean up after itself, so the next one does.
pub fn remove_stale(dir: &Path, prefix: &str) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(prefix)) else {
            continue;
        };
        let digits = rest.split('-').next().unwrap_or("");
        let Ok(pid) = digits.parse::<u32>() else {
            continue;
        };
        if process_is_gone(pid) {
            let path = entry.path();
            let removed = match entry.file_type() {
                Ok(t) if t.is_dir() => std::fs::remove_dir_all(&path),
                _ => std::fs::remove_file(&path),
            };
            if removed.is_ok() {
                log::info!(
                    "removed {}, left by process {pid}, which is gone",
                    path.display()
                );
            }
        }
    }
}

/// Writes a file atomically: `write` fills a temporary file next to `path`, which is then
/// renamed over `path`. A failed or killed write never leaves a partial file at `path`.
pub fn write_atomically<F>(path: &std::path::Path, write: F) -> crate::Result<()>
where
    F: FnOnce(&mut std::io::BufWriter<std::fs::File>) -> crate::Result<()>,
{
    let name = path
        .file_name()
        .ok_or_else(|| Error::other(path, "output", "not a file name"))?;
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let tmp = dir.join(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    remove_stale(dir, &format!(".{}.tmp-", name.to_string_lossy()));
    // Never rename over a device node, FIFO or directory (the render checked this before
    // it started; this holds for every writer).
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
    {
        return Err(Error::bad_input(
            path,
            "output",
            "exists and is not a regular file",
        ));
    }
    let _removed_on_signal = crate::interrupt::watch_scratch(tmp.clone());
    let result = (|| {
        let file =
            std::fs::File::create(&tmp).map_err(|e| Error::other(&tmp, "output", e.to_string()))?;
        let mut writer = std::io::BufWriter::new(file);
        write(&mut writer)?;
        let file = writer
            .into_inner()
            .map_err(|e| Error::other(&tmp, "output", e.to_string()))?;
        file.sync_all()
            .map_err(|e| Error::other(&tmp, "output", e.to_string()))?;
        std::fs::rename(&tmp, path).map_err(|e| Error::other(path, "output", e.to_string()))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn outputs_that_are_not_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        assert!(check_output(&dir.path().join("a/b/out.exr"), "output").is_ok());
        let e = check_output(dir.path(), "output").unwrap_err();
        assert!(e.reason.contains("directory"), "{e}");
        let e = check_output(Path::new("/dev/null"), "output").unwrap_err();
        assert!(e.reason.contains("device"), "{e}");
        let fifo = dir.path().join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: mkfifo(3) with a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        assert!(
            check_output(&fifo, "output")
                .unwrap_err()
                .reason
                .contains("FIFO")
        );
        assert!(read_input(&fifo).unwrap_err().contains("FIFO"));
        assert!(
            read_input(Path::new("/dev/zero"))
                .unwrap_err()
                .contains("device")
        );
    }

    #[test]
    fn links_out_of_the_base_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("scene");
        std::fs::create_dir(&scene).unwrap();
        std::fs::write(dir.path().join("secret"), b"x").unwrap();
        std::fs::write(scene.join("tex.png"), b"x").unwrap();
        std::os::unix::fs::symlink(dir.path().join("secret"), scene.join("link.png")).unwrap();
        assert!(check_inside(&scene.join("tex.png"), &scene).is_ok());
        assert!(check_inside(&scene.join("link.png"), &scene).is_err());
    }
}
