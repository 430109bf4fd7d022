//! Where lucerna finds what runs beside it, wherever the binary was installed: the USD
//! plugin, a Python that has usd-core, and the Open Image Denoise library.
//!
//! - **The plugin** is part of the binary: its sources are embedded at build time
//!   (build.rs) and written on first use to `CACHE/usd-plugin-HASH` (HASH of their
//!   contents, so binaries of different versions never share a folder; written to a
//!   temporary folder and renamed, so concurrent renders never see half a plugin).
//!   `$LUCERNA_USD_PLUGIN` names a plugin folder to use instead (plugin development).
//! - **Python**: `$LUCERNA_PYTHON`, else the environment `lucerna setup` made
//!   (`DATA/venv`), else the `.venv` of the checkout this binary was built in (a
//!   development build, where `tools/test.sh` installs the plugin's requirements), else
//!   `python3`. An installed copy of the binary (`cargo install`) never reads the checkout.
//! - CACHE is `$XDG_CACHE_HOME/lucerna` (default `~/.cache/lucerna`); DATA is
//!   `$LUCERNA_HOME`, else `$XDG_DATA_HOME/lucerna` (default `~/.local/share/lucerna`).

use crate::error::{Error, Result};
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::process::Command;

include!(concat!(env!("OUT_DIR"), "/plugin_files.rs"));

/// The Python package that carries Open Image Denoise's library (`lucerna setup` installs
/// it; `output::denoise` looks for the library inside it).
pub const DENOISER_PACKAGE: &str = "pyoidn==2.5.1.0";

fn home() -> Option<PathBuf> {
    std::env::var_os("HOME")
        .filter(|h| !h.is_empty())
        .map(PathBuf::from)
}

fn xdg(variable: &str, fallback: &str) -> PathBuf {
    std::env::var_os(variable)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| home().map(|h| h.join(fallback)))
        .unwrap_or_else(std::env::temp_dir)
        .join("lucerna")
}

/// lucerna's data folder (where `lucerna setup` puts its Python environment).
pub fn data_dir() -> PathBuf {
    std::env::var_os("LUCERNA_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| xdg("XDG_DATA_HOME", ".local/share"))
}

/// lucerna's cache folder (the written-out plugin).
pub fn cache_dir() -> PathBuf {
    xdg("XDG_CACHE_HOME", ".cache")
}

/// The Python environment `lucerna setup` makes by default.
pub fn default_venv() -> PathBuf {
    data_dir().join("venv")
}

/// The `.venv` of the checkout this binary was built in, for a development build: a
/// binary that runs from inside its checkout (its `target` folder). A copy installed
/// elsewhere never looks at the checkout.
fn checkout_python() -> Option<PathBuf> {
    let checkout = Path::new(env!("CARGO_MANIFEST_DIR"));
    let exe = std::env::current_exe().ok()?;
    if !exe.starts_with(checkout) {
        return None;
    }
    let python = checkout.join(".venv/bin/python");
    python.exists().then_some(python)
}

/// The Pythons lucerna would use, best first (those that exist).
pub fn known_pythons() -> Vec<PathBuf> {
    let mut found = Vec::new();
    if let Some(p) = std::env::var_os("LUCERNA_PYTHON").filter(|p| !p.is_empty()) {
        found.push(PathBuf::from(p));
    }
    let setup = default_venv().join("bin/python");
    if setup.exists() {
        found.push(setup);
    }
    found.extend(checkout_python());
    found
}

/// The Python that runs the USD plugin.
pub fn python() -> PathBuf {
    known_pythons()
        .into_iter()
        .next()
        .unwrap_or_else(|| "python3".into())
}

/// The folder to put on `PYTHONPATH` for `python -m lucerna_usd`: the embedded plugin,
/// written out once, or `$LUCERNA_USD_PLUGIN`.
pub fn plugin_dir() -> Result<PathBuf> {
    if let Some(dir) = std::env::var_os("LUCERNA_USD_PLUGIN").filter(|v| !v.is_empty()) {
        return Ok(dir.into());
    }
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    PLUGIN_FILES.hash(&mut hasher);
    let cache = cache_dir();
    let dir = cache.join(format!("usd-plugin-{:016x}", hasher.finish()));
    if dir.join("lucerna_usd/__main__.py").exists() {
        return Ok(dir);
    }
    let failed = |e: std::io::Error| {
        Error::other(
            &cache,
            "USD plugin",
            format!(
                "cannot write the plugin into lucerna's cache folder: {e} (set XDG_CACHE_HOME to a writable folder)"
            ),
        )
    };
    std::fs::create_dir_all(&cache).map_err(failed)?;
    let scratch = tempfile::Builder::new()
        .prefix(".usd-plugin-")
        .tempdir_in(&cache)
        .map_err(failed)?;
    for (path, contents) in PLUGIN_FILES {
        let file = scratch.path().join(path);
        if let Some(parent) = file.parent() {
            std::fs::create_dir_all(parent).map_err(failed)?;
        }
        std::fs::write(&file, contents).map_err(failed)?;
    }
    // Another process may have written it meanwhile: theirs is identical.
    if std::fs::rename(scratch.path(), &dir).is_err() && !dir.join("lucerna_usd").exists() {
        return Err(failed(std::io::Error::other("the rename failed")));
    }
    log::debug!("USD plugin written to {}", dir.display());
    Ok(dir)
}

/// `lucerna setup`: makes the Python environment `venv` (default [`default_venv`]) with
/// the plugin's requirements (usd-core, OpenImageIO, MaterialX) and, with `denoiser`,
/// Open Image Denoise (pyoidn), then checks that usd-core imports.
pub fn setup(venv: Option<&Path>, denoiser: bool) -> Result<PathBuf> {
    let venv = venv.map_or_else(default_venv, Path::to_path_buf);
    let python = venv.join("bin/python");
    let run = |command: &mut Command, what: &str| -> Result<()> {
        log::info!("{what}");
        let status = command
            .status()
            .map_err(|e| Error::other(&venv, "setup", format!("{what}: {e}")))?;
        if status.success() {
            Ok(())
        } else {
            Err(Error::other(
                &venv,
                "setup",
                format!("{what} failed ({status})"),
            ))
        }
    };
    if !python.exists() {
        run(
            Command::new("python3").args(["-m", "venv"]).arg(&venv),
            &format!("making the Python environment {}", venv.display()),
        )?;
    }
    let plugin = plugin_dir()?;
    let mut pip = Command::new(&python);
    pip.args(["-m", "pip", "install", "--disable-pip-version-check", "-r"])
        .arg(plugin.join("requirements.txt"));
    if denoiser {
        pip.arg(DENOISER_PACKAGE);
    }
    run(
        &mut pip,
        "installing usd-core and the plugin's other packages (pip)",
    )?;
    run(
        Command::new(&python)
            .args(["-c", "import pxr.Usd"])
            .env("PYTHONPATH", &plugin),
        "checking that usd-core imports",
    )?;
    Ok(venv)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_whole_plugin_is_embedded() {
        let names: Vec<&str> = PLUGIN_FILES.iter().map(|(n, _)| *n).collect();
        for needed in [
            "lucerna_usd/__main__.py",
            "lucerna_usd/convert.py",
            "requirements.txt",
        ] {
            assert!(names.contains(&needed), "{names:?}");
        }
        let on_disk = std::fs::read_dir(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("plugins/usd/lucerna_usd"),
        )
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "py")
        })
        .count();
        assert_eq!(names.len(), on_disk + 1);
    }
}
