//! USD stages, read through the usd-core plugin (`plugins/usd`): Pixar's own composition,
//! validation with `pxr.UsdValidation`, conversion to a lucerna scene file that is then read
//! like any other (and validated again: the plugin's output is untrusted input too).
//!
//! The plugin runs as `PYTHON -m lucerna_usd convert STAGE -o TMP.lucerna [--frame F]
//! [--no-validate]` with the plugin folder on `PYTHONPATH`. PYTHON is `$LUCERNA_PYTHON`, else
//! the repository's `.venv` (where `tools/test.sh` installs the plugin's requirements), else
//! `python3`; the plugin folder is `$LUCERNA_USD_PLUGIN`, else `plugins/usd` of the source tree
//! this binary was built from. Its exit status: 0 converted, 2 bad stage, 3 missing Python
//! package; its error lines read `lucerna-usd: error: FILE: ELEMENT: REASON`.

use super::{LoadOptions, tangents};
use crate::error::{Error, Result};
use crate::scene::{self, Scene};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};

/// File extensions read through the plugin.
pub const EXTENSIONS: [&str; 4] = ["usd", "usda", "usdc", "usdz"];

const ERROR_PREFIX: &str = "lucerna-usd: error: ";

fn plugin_dir() -> PathBuf {
    std::env::var_os("LUCERNA_USD_PLUGIN").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("plugins/usd"),
        PathBuf::from,
    )
}

fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("LUCERNA_PYTHON") {
        return p.into();
    }
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    if venv.exists() {
        venv
    } else {
        "python3".into()
    }
}

/// A scratch folder for the plugin's scene file, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new() -> std::io::Result<Self> {
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        let dir = std::env::temp_dir().join(format!(
            "lucerna-usd-{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir)?;
        Ok(Self(dir))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Converts the stage at `path` with the plugin and reads the result.
pub fn load(path: &Path, options: &LoadOptions) -> Result<Scene> {
    if !path.is_file() {
        return Err(Error::bad_input(path, "file", "no such file"));
    }
    let plugin = plugin_dir();
    let python = python();
    let install = format!(
        "{} -m pip install -r {}",
        python.display(),
        plugin.join("requirements.txt").display()
    );
    let scratch =
        Scratch::new().map_err(|e| Error::other(path, "temporary folder", e.to_string()))?;
    let output = scratch.0.join(format!("scene.{}", scene::file::EXTENSION));
    let mut command = Command::new(&python);
    command
        .arg("-m")
        .arg("lucerna_usd")
        .arg("convert")
        .arg(path)
        .arg("-o")
        .arg(&output)
        .env("PYTHONPATH", &plugin);
    if let Some(frame) = options.frame {
        command.arg("--frame").arg(frame.to_string());
    }
    if !options.validate {
        command.arg("--no-validate");
    }
    let result = command.output().map_err(|e| {
        Error::other(
            path,
            "usd plugin",
            format!(
                "cannot run Python ({}: {e}); USD needs Python 3 with usd-core: install \
                 python3, then `{install}` (or point LUCERNA_PYTHON at a Python that has it)",
                python.display()
            ),
        )
    })?;
    let stderr = String::from_utf8_lossy(&result.stderr);
    let mut first_error = None;
    for line in stderr.lines() {
        match line.strip_prefix(ERROR_PREFIX) {
            Some(rest) if first_error.is_none() => first_error = Some(rest.to_string()),
            _ => eprintln!("{line}"),
        }
    }
    match result.status.code() {
        Some(0) => {}
        Some(2) => {
            let detail = first_error.unwrap_or_else(|| stderr.trim().to_string());
            // The plugin's line is FILE: ELEMENT: REASON; the file is `path`.
            let detail = detail
                .strip_prefix(&format!("{}: ", path.display()))
                .unwrap_or(&detail)
                .to_string();
            let (element, reason) = detail.split_once(": ").unwrap_or(("stage", &detail));
            return Err(Error::bad_input(path, element, reason));
        }
        Some(3) => {
            return Err(Error::other(
                path,
                "usd plugin",
                format!(
                    "usd-core or another package is missing for {}: run `{install}`",
                    python.display()
                ),
            ));
        }
        _ => {
            return Err(Error::other(
                path,
                "usd plugin",
                format!(
                    "the plugin failed ({}): {}",
                    result.status,
                    first_error.unwrap_or_else(|| stderr
                        .trim()
                        .lines()
                        .last()
                        .unwrap_or("")
                        .to_string())
                ),
            ));
        }
    }
    let mut scene = scene::file::read(&output)?;
    scene.source = path.display().to_string();
    add_tangents(&mut scene);
    Ok(scene)
}

/// MikkTSpace tangents for normal-mapped meshes (the plugin leaves them to the renderer,
/// as glTF files without tangents do).
fn add_tangents(scene: &mut Scene) {
    for mesh in &mut scene.meshes {
        let material = &scene.materials[mesh.material as usize];
        if let (Some(uv_set), None) = (material.tangent_uv_set(), &mesh.tangents)
            && !tangents::generate(mesh, uv_set)
        {
            scene.warnings.push(format!(
                "{}: normal map ignored: the mesh has no texture coordinates for it",
                mesh.name
            ));
        }
    }
}
