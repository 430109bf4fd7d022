//! USD stages, read through the usd-core plugin (`plugins/usd`): Pixar's own composition,
//! validation with `pxr.UsdValidation`, conversion to a lucerna scene file that is then read
//! like any other (and validated again: the plugin's output is untrusted input too).
//!
//! The plugin runs as `PYTHON -m lucerna_usd convert STAGE -o TMP.lucerna [--frame F]
//! [--no-validate | --strict] [--variant SET=NAME]... [--purpose LIST] [--no-payloads]
//! [--render-settings PRIM] [--max-memory BYTES]` with the plugin folder on `PYTHONPATH`
//! (before any `PYTHONPATH` already set). The plugin is embedded in the binary; PYTHON and
//! the plugin folder are found as src/install.rs says.
//!
//! The plugin writes into a scratch folder made by `tempfile` (a unique name, mode 0700)
//! that is removed afterwards, also when a signal ends lucerna (src/interrupt.rs kills the
//! plugin first). A plugin still running after [`LoadOptions::plugin_timeout`] is killed
//! and the load fails (exit 1) saying so. Images the plugin decodes are held to lucerna's
//! memory limit (`--max-memory BYTES`). Its exit status: 0 converted, 2 bad stage, 3 missing Python
//! package; its error lines read `lucerna-usd: error: FILE: ELEMENT: REASON`.

use super::{LoadOptions, tangents};
use crate::error::{Error, Result};
use crate::scene::{self, Scene};
use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// File extensions read through the plugin.
pub const EXTENSIONS: [&str; 4] = ["usd", "usda", "usdc", "usdz"];

const ERROR_PREFIX: &str = "lucerna-usd: error: ";

/// Converts the stage at `path` with the plugin and reads the result.
pub fn load(path: &Path, options: &LoadOptions) -> Result<Scene> {
    crate::files::check_input(path).map_err(|e| Error::bad_input(path, "file", e))?;
    let plugin = crate::install::plugin_dir()?;
    let python = crate::install::python();
    log::debug!(
        "USD plugin: {} -m lucerna_usd, from {}",
        python.display(),
        plugin.display()
    );
    let install = format!(
        "{} -m pip install -r {}",
        python.display(),
        plugin.join("requirements.txt").display()
    );
    let scratch = tempfile::Builder::new()
        .prefix("lucerna-usd-")
        .tempdir()
        .map_err(|e| Error::other(path, "temporary folder", e.to_string()))?;
    let _removed_on_signal = crate::interrupt::watch_scratch(scratch.path().to_path_buf());
    let output = scratch
        .path()
        .join(format!("scene.{}", scene::file::EXTENSION));
    let mut python_path = std::ffi::OsString::from(plugin.as_os_str());
    if let Some(existing) = std::env::var_os("PYTHONPATH").filter(|p| !p.is_empty()) {
        python_path.push(":");
        python_path.push(existing);
    }
    let mut command = Command::new(&python);
    command
        .arg("-m")
        .arg("lucerna_usd")
        .arg("convert")
        .arg(path)
        .arg("-o")
        .arg(&output)
        .env("PYTHONPATH", python_path)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    if let Some(frame) = options.frame {
        command.arg("--frame").arg(frame.to_string());
    }
    if !options.validate {
        command.arg("--no-validate");
    }
    if options.strict {
        command.arg("--strict");
    }
    for variant in &options.variants {
        command.arg("--variant").arg(variant);
    }
    command.arg("--purpose").arg(&options.purpose);
    if !options.payloads {
        command.arg("--no-payloads");
    }
    if let Some(prim) = &options.render_settings {
        command.arg("--render-settings").arg(prim);
    }
    if let Some(limit) = crate::memory::process_limit() {
        command.arg("--max-memory").arg(limit.to_string());
    }
    let cannot_run = |e: std::io::Error| {
        Error::other(
            path,
            "usd plugin",
            format!(
                "cannot run Python ({}: {e}); USD needs Python 3 with usd-core: install \
                 python3, then run `lucerna setup` (or `{install}`, or point LUCERNA_PYTHON \
                 at a Python that has usd-core)",
                python.display()
            ),
        )
    };
    let mut child = command.spawn().map_err(cannot_run)?;
    let _killed_on_signal = crate::interrupt::watch_child(child.id());
    let mut pipe = child.stderr.take().expect("stderr is piped");
    let reader = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = pipe.read_to_end(&mut bytes);
        bytes
    });
    let start = Instant::now();
    let status = loop {
        match child.try_wait().map_err(cannot_run)? {
            Some(status) => break status,
            None if start.elapsed() > options.plugin_timeout => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(Error::other(
                    path,
                    "usd plugin",
                    format!(
                        "still converting after {} s: stopped (raise the limit with --usd-timeout)",
                        options.plugin_timeout.as_secs()
                    ),
                ));
            }
            None => std::thread::sleep(Duration::from_millis(20)),
        }
    };
    let stderr_bytes = reader.join().unwrap_or_default();
    let result = std::process::Output {
        status,
        stdout: Vec::new(),
        stderr: stderr_bytes,
    };
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
                    "usd-core or another package is missing for {}: run `lucerna setup` (or `{install}`)",
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
