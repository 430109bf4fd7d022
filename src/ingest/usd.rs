//! USD stages, read through the usd-core plugin (`plugins/usd`): Pixar's own composition,
//! validation with `pxr.UsdValidation`, conversion to a lucerna scene file that is then read
//! like any other (and validated again: the plugin's output is untrusted input too).
//!
//! The plugin runs as `PYTHON -m lucerna_usd convert STAGE -o TMP.lucerna [--frame F]
//! [--no-validate | --strict] [--variant SET=NAME]... [--purpose LIST] [--no-payloads]
//! [--render-settings PRIM] [--shutter OPEN,CLOSE] [--vectors] [--max-memory BYTES]` with the
//! plugin folder on `PYTHONPATH` (before any `PYTHONPATH` already set). The plugin is
//! embedded in the binary; PYTHON and the plugin folder are found as src/install.rs says.
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
use std::io::BufRead;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// File extensions read through the plugin.
pub const EXTENSIONS: [&str; 4] = ["usd", "usda", "usdc", "usdz"];

const ERROR_PREFIX: &str = "lucerna-usd: error: ";
/// The plugin's sign of life (at most one a second, as it converts prims and images).
const HEARTBEAT: &str = "lucerna-usd: heartbeat";
/// A plugin silent for this long is stuck (its slowest single step, composing a stage or
/// decoding one image, takes far less), whatever `--usd-timeout` allows in all;
/// `$LUCERNA_USD_STALL_SECONDS` sets another limit.
const STALL_LIMIT: Duration = Duration::from_secs(300);

/// The stall limit: [`STALL_LIMIT`], or `$LUCERNA_USD_STALL_SECONDS`.
fn stall_limit() -> Duration {
    std::env::var("LUCERNA_USD_STALL_SECONDS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
        .map_or(STALL_LIMIT, Duration::from_secs_f64)
}

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
    // Scratch folders name their process, so that those of processes that are gone (killed
    // before they could remove theirs) are removed here.
    crate::files::remove_stale(&std::env::temp_dir(), "lucerna-usd-p");
    let scratch = tempfile::Builder::new()
        .prefix(&format!("lucerna-usd-p{}-", std::process::id()))
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
    if let Some((open, close)) = options.shutter {
        command.arg(format!("--shutter={open},{close}"));
    }
    if options.vectors {
        command.arg("--vectors");
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
    let (mut child, _killed_on_signal) =
        crate::interrupt::spawn_watched(&mut command).map_err(cannot_run)?;
    let pipe = child.stderr.take().expect("stderr is piped");
    let start = Instant::now();
    // Milliseconds after `start` of the plugin's last heartbeat (or other line).
    let alive = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let reader = {
        let alive = alive.clone();
        std::thread::spawn(move || {
            let mut lines = Vec::new();
            for line in std::io::BufReader::new(pipe)
                .split(b'\n')
                .map_while(|l| l.ok())
            {
                alive.store(
                    start.elapsed().as_millis() as u64,
                    std::sync::atomic::Ordering::Relaxed,
                );
                if line != HEARTBEAT.as_bytes() {
                    lines.extend_from_slice(&line);
                    lines.push(b'\n');
                }
            }
            lines
        })
    };
    let stall = stall_limit();
    let status = loop {
        let silent = start.elapsed().saturating_sub(Duration::from_millis(
            alive.load(std::sync::atomic::Ordering::Relaxed),
        ));
        let stopped = match child.try_wait().map_err(cannot_run)? {
            Some(status) => break status,
            None if start.elapsed() > options.plugin_timeout => format!(
                "still converting after {} s: stopped (raise the limit with --usd-timeout)",
                options.plugin_timeout.as_secs()
            ),
            None if silent > stall => format!(
                "no sign of progress for {} s: the conversion is stuck and was stopped",
                silent.as_secs()
            ),
            None => {
                std::thread::sleep(Duration::from_millis(20));
                continue;
            }
        };
        let _ = child.kill();
        let _ = child.wait();
        return Err(Error::other(path, "usd plugin", stopped));
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
    if !output.is_file() {
        return Err(Error::other(
            path,
            "usd plugin",
            "the plugin ended without error but wrote no scene file",
        ));
    }
    let mut scene = scene::file::read(&output).map_err(|e| stage_error(path, &output, e))?;
    scene.source = path.display().to_string();
    add_tangents(&mut scene);
    Ok(scene)
}

/// An error in the scene file the plugin wrote for stage `path`, told as the stage's: the
/// file is the stage, and an element of the scene file (`materials[3].emissive`) is named by
/// the prim it came from (elements carry their prim's path as their name), so that no
/// message points at the deleted temporary file.
fn stage_error(path: &Path, scene_file: &Path, e: Error) -> Error {
    let names = std::fs::read(scene_file)
        .ok()
        .and_then(|bytes| serde_json::from_slice::<serde_json::Value>(&bytes).ok());
    let prim = e.element.split_once('[').and_then(|(list, rest)| {
        let index: usize = rest.split_once(']')?.0.parse().ok()?;
        names
            .as_ref()?
            .get(list)?
            .get(index)?
            .get("name")?
            .as_str()
            .map(str::to_string)
    });
    let element = match prim {
        Some(prim) => format!("{prim} ({})", e.element),
        None => e.element.clone(),
    };
    let reason = if e.element == "manifest" {
        format!("the converted scene is unreadable: {}", e.reason)
    } else {
        e.reason.clone()
    };
    Error {
        file: path.display().to_string(),
        element,
        reason,
        ..e
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// What the renderer refuses in a converted scene is told against the stage and the
    /// prim the element came from, never the temporary scene file.
    #[test]
    fn scene_file_errors_name_the_stage_and_the_prim() {
        let dir = tempfile::tempdir().unwrap();
        let scene_file = dir.path().join("scene.lucerna");
        std::fs::write(
            &scene_file,
            r#"{"materials": [{"name": "displayColor"}, {"name": "/Looks/Hot"}]}"#,
        )
        .unwrap();
        let stage = Path::new("shot.usda");
        let e = stage_error(
            stage,
            &scene_file,
            Error::bad_input(&scene_file, "materials[1].emissive", "not finite"),
        );
        assert_eq!(
            e.to_string(),
            "shot.usda: /Looks/Hot (materials[1].emissive): not finite"
        );
        assert_eq!(e.exit_code(), 2);
        let e = stage_error(
            stage,
            &scene_file,
            Error::bad_input(&scene_file, "manifest", "number out of range at line 3"),
        );
        assert_eq!(
            e.to_string(),
            "shot.usda: manifest: the converted scene is unreadable: number out of range at line 3"
        );
    }
}
