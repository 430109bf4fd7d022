//! `lucerna batch JOB.toml`: a list of renders (scene, camera, frames, settings, output
//! pattern) run unattended. Every frame is rendered by a child `lucerna render` process,
//! so that a crash, a panic or an exhausted memory fails that frame alone; its output goes
//! to a log file per frame. Outputs already complete are skipped and checkpoints of
//! interrupted renders are resumed, so rerunning a job after a crash finishes it. A JSON
//! summary lists every frame's status, seconds, samples and NaN/Inf count; the batch exits
//! non-zero if any frame failed.
//!
//! A job file:
//!
//! ```toml
//! [settings]              # render settings for every render (as a settings file)
//! spp = 64
//!
//! [[render]]
//! scene = "shots/a.glb"   # relative to the job file; omitted: the embedded Cornell box
//! output = "out/{scene}.{frame}.exr"
//! frames = "1-24"         # or frame = 12, or neither
//! camera = "main"         # optional, as are resolution = "640x360" and fps = 25
//! settings = { aov = "direct,indirect", mis = "balance" }
//! ```

use crate::error::{Error, Result};
use crate::film::exr;
use crate::render::RenderOptions;
use crate::sequence::{FrameList, output_path};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A job file.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Job {
    /// Settings every render starts from.
    #[serde(default)]
    settings: toml::Table,
    render: Vec<JobRender>,
}

/// One `[[render]]` of a job file.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct JobRender {
    scene: Option<PathBuf>,
    output: PathBuf,
    frames: Option<String>,
    frame: Option<f64>,
    camera: Option<String>,
    resolution: Option<String>,
    fps: Option<f64>,
    #[serde(default)]
    settings: toml::Table,
}

/// One frame to render: the child process's arguments and where its results go.
pub struct Task {
    pub scene: Option<PathBuf>,
    pub frame: Option<f64>,
    pub output: PathBuf,
    /// Arguments of `lucerna render`.
    pub args: Vec<String>,
    pub log: PathBuf,
}

/// How a frame ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Rendered (or resumed to completion) now.
    Rendered,
    /// Its output was already complete.
    Skipped,
    Failed,
}

/// A frame's line of the summary.
#[derive(Clone, Debug, Serialize)]
pub struct FrameReport {
    pub scene: String,
    pub frame: Option<f64>,
    pub output: PathBuf,
    pub status: Status,
    pub seconds: f64,
    pub samples: Option<f64>,
    pub spp: Option<f64>,
    pub nan_inf_discarded: Option<f64>,
    pub exit_code: Option<i32>,
    pub error: Option<String>,
    pub log: PathBuf,
}

/// The JSON summary of a batch.
#[derive(Debug, Serialize)]
pub struct Summary {
    pub job: PathBuf,
    pub seconds: f64,
    pub rendered: usize,
    pub skipped: usize,
    pub failed: usize,
    pub interrupted: bool,
    pub frames: Vec<FrameReport>,
}

/// Reads a job file and expands it into one task per frame; logs go to `logs`.
pub fn plan(job_path: &Path, logs: &Path) -> Result<Vec<Task>> {
    let text = std::fs::read_to_string(job_path)
        .map_err(|e| Error::bad_input(job_path, "file", format!("cannot read: {e}")))?;
    let job: Job = toml::from_str(&text)
        .map_err(|e| Error::bad_input(job_path, "job", e.message().to_string()))?;
    if job.render.is_empty() {
        return Err(Error::bad_input(
            job_path,
            "render",
            "the job has no [[render]]",
        ));
    }
    let base = job_path.parent().unwrap_or(Path::new(""));
    std::fs::create_dir_all(logs).map_err(|e| Error::other(logs, "logs", e.to_string()))?;
    let mut tasks = Vec::new();
    for (i, render) in job.render.iter().enumerate() {
        let element = |key: &str| format!("render[{i}].{key}");
        let bad = |key: &str, reason: String| Error::bad_input(job_path, element(key), reason);
        let mut settings = job.settings.clone();
        settings.extend(render.settings.clone());
        let settings_text =
            toml::to_string(&settings).map_err(|e| bad("settings", e.to_string()))?;
        RenderOptions::default()
            .load_settings(&settings_text)
            .map_err(|e| bad("settings", e))?;
        let frames = match (&render.frames, render.frame) {
            (Some(_), Some(_)) => {
                return Err(bad("frames", "give frames or frame, not both".into()));
            }
            (Some(list), None) => FrameList::parse(list)
                .map_err(|e| bad("frames", e))?
                .0
                .into_iter()
                .map(Some)
                .collect(),
            (None, frame) => vec![frame],
        };
        let pattern = base.join(&render.output);
        let pattern_text = pattern.to_string_lossy();
        if frames.len() > 1 && !pattern_text.contains("{frame}") {
            return Err(bad(
                "output",
                "several frames need {frame} in the output name".into(),
            ));
        }
        if pattern_text.contains("{camera}") && render.camera.is_none() {
            return Err(bad(
                "output",
                "{camera} in a batch output needs the render's camera key".into(),
            ));
        }
        let scene = render.scene.as_ref().map(|s| base.join(s));
        let stem = scene
            .as_deref()
            .and_then(Path::file_stem)
            .map_or("default".into(), |s| s.to_string_lossy().into_owned());
        let camera = render.camera.clone().unwrap_or_default();
        let settings_file = logs.join(format!("render{i}.settings.toml"));
        std::fs::write(&settings_file, &settings_text)
            .map_err(|e| Error::other(&settings_file, "logs", e.to_string()))?;
        for frame in frames {
            let output =
                output_path(&pattern, frame, &stem, &camera).map_err(|e| bad("output", e))?;
            let mut args: Vec<String> = vec!["render".into(), "--quiet".into()];
            if let Some(s) = &scene {
                args.push(s.to_string_lossy().into_owned());
            }
            args.extend([
                "--settings".into(),
                settings_file.to_string_lossy().into_owned(),
            ]);
            args.extend(["-o".into(), output.to_string_lossy().into_owned()]);
            if let Some(f) = frame {
                args.extend(["--frame".into(), f.to_string()]);
            }
            for (flag, value) in [
                ("--camera", render.camera.clone()),
                ("--resolution", render.resolution.clone()),
                ("--fps", render.fps.map(|f| f.to_string())),
            ] {
                if let Some(v) = value {
                    args.extend([flag.into(), v]);
                }
            }
            let name = output
                .file_name()
                .map_or("frame".into(), |n| n.to_string_lossy().into_owned());
            tasks.push(Task {
                scene: scene.clone(),
                frame,
                log: logs.join(format!("{name}.log")),
                output,
                args,
            });
        }
    }
    Ok(tasks)
}

/// What an existing output holds: `Some(true)` complete, `Some(false)` a checkpoint to
/// resume, `None` nothing usable (absent or unreadable: rendered from the start).
fn output_state(path: &Path) -> Option<bool> {
    if !path.exists() {
        return None;
    }
    let header = exr::read_header(path).ok()?;
    header.number("lucerna/complete").map(|c| c == 1.0)
}

/// Runs `task` with the `lucerna` binary `exe`; `stop` (set by a signal) forwards SIGTERM
/// to the child, which writes its checkpoint.
fn run_task(exe: &Path, task: &Task, stop: &AtomicBool) -> FrameReport {
    let scene = task
        .scene
        .as_ref()
        .map_or("<default>".into(), |s| s.display().to_string());
    let mut report = FrameReport {
        scene,
        frame: task.frame,
        output: task.output.clone(),
        status: Status::Failed,
        seconds: 0.0,
        samples: None,
        spp: None,
        nan_inf_discarded: None,
        exit_code: None,
        error: None,
        log: task.log.clone(),
    };
    let state = output_state(&task.output);
    if state == Some(true) {
        report.status = Status::Skipped;
    } else {
        let mut args = task.args.clone();
        if state == Some(false) {
            args.push("--resume".into());
        }
        let start = Instant::now();
        match spawn_and_wait(exe, &args, &task.log, stop) {
            Ok(status) => {
                report.exit_code = status.code();
                if status.success() {
                    report.status = Status::Rendered;
                } else {
                    report.error = Some(
                        last_error_line(&task.log)
                            .unwrap_or_else(|| format!("lucerna render ended with {status}")),
                    );
                }
            }
            Err(e) => report.error = Some(e),
        }
        report.seconds = start.elapsed().as_secs_f64();
    }
    if report.status != Status::Failed
        && let Ok(header) = exr::read_header(&task.output)
    {
        report.samples = header.number("lucerna/samples");
        report.spp = header.number("lucerna/spp");
        report.nan_inf_discarded = header.number("lucerna/nan_inf_discarded");
    }
    report
}

/// Starts `exe args` with its output in `log` and waits for it, passing SIGTERM on when
/// `stop` is set.
fn spawn_and_wait(
    exe: &Path,
    args: &[String],
    log: &Path,
    stop: &AtomicBool,
) -> std::result::Result<std::process::ExitStatus, String> {
    use std::io::Write;
    let mut file =
        std::fs::File::create(log).map_err(|e| format!("cannot write {}: {e}", log.display()))?;
    let quoted: Vec<String> = args.iter().map(|a| format!("{a:?}")).collect();
    let _ = writeln!(file, "$ {} {}", exe.display(), quoted.join(" "));
    let err = file
        .try_clone()
        .map_err(|e| format!("cannot write {}: {e}", log.display()))?;
    let mut child = Command::new(exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(file)
        .stderr(err)
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", exe.display()))?;
    let mut forwarded = false;
    loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            return Ok(status);
        }
        if stop.load(Ordering::Relaxed) && !forwarded {
            // SAFETY: kill(2) with the pid of a child this process has not yet reaped.
            unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
            forwarded = true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The last line of `log` that starts with `error:`, without the prefix.
fn last_error_line(log: &Path) -> Option<String> {
    let text = std::fs::read_to_string(log).ok()?;
    text.lines()
        .rev()
        .find_map(|l| l.strip_prefix("error: "))
        .map(str::to_string)
}

/// Runs every task in order with the `lucerna` binary `exe`, printing a line per frame;
/// stops launching frames once `stop` is set.
pub fn run(job: &Path, exe: &Path, tasks: &[Task], stop: &AtomicBool) -> Summary {
    let start = Instant::now();
    let mut frames = Vec::new();
    for (i, task) in tasks.iter().enumerate() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let report = run_task(exe, task, stop);
        let what = match report.status {
            Status::Rendered => format!("rendered in {:.2} s", report.seconds),
            Status::Skipped => "complete already, skipped".into(),
            Status::Failed => format!(
                "FAILED: {} (log: {})",
                report.error.as_deref().unwrap_or("unknown error"),
                report.log.display()
            ),
        };
        eprintln!(
            "[{}/{}] {}: {what}",
            i + 1,
            tasks.len(),
            report.output.display()
        );
        frames.push(report);
    }
    let count = |s: Status| frames.iter().filter(|f| f.status == s).count();
    Summary {
        job: job.to_path_buf(),
        seconds: start.elapsed().as_secs_f64(),
        rendered: count(Status::Rendered),
        skipped: count(Status::Skipped),
        failed: count(Status::Failed),
        interrupted: frames.len() < tasks.len() || stop.load(Ordering::Relaxed),
        frames,
    }
}
