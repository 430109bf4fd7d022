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
use crate::job::RenderJob;
use crate::output::exr;
use crate::render::RenderOptions;
use crate::sequence::{FrameList, output_path};
use serde::{Deserialize, Serialize};
use std::ffi::OsString;
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
    /// The render's settings (TOML), its resolution if the job gives one.
    pub settings: String,
    pub resolution: Option<String>,
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
    pub samples: Option<u64>,
    pub spp: Option<u32>,
    pub nan_inf_discarded: Option<u64>,
    pub exit_code: Option<i32>,
    pub error: Option<String>,
    /// Why an existing output was rendered again (settings changed, unreadable, ...).
    pub note: Option<String>,
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
    let text = crate::files::read_input(job_path)
        .and_then(|b| String::from_utf8(b).map_err(|_| "not UTF-8 text".to_string()))
        .map_err(|e| Error::bad_input(job_path, "file", e))?;
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
    let mut tasks: Vec<Task> = Vec::new();
    // Each output's file, as `normal_file` names it, and the task writing it.
    let mut writers: std::collections::HashMap<PathBuf, usize> = Default::default();
    for (i, render) in job.render.iter().enumerate() {
        let element = |key: &str| format!("render[{i}].{key}");
        let bad = |key: &str, reason: String| Error::bad_input(job_path, element(key), reason);
        let mut settings = job.settings.clone();
        settings.extend(render.settings.clone());
        let settings_text =
            toml::to_string(&settings).map_err(|e| bad("settings", e.to_string()))?;
        for key in [
            "scene",
            "output",
            "frames",
            "frame",
            "camera",
            "resolution",
            "fps",
            "resume",
        ] {
            if settings.contains_key(key) {
                return Err(bad(
                    "settings",
                    format!("{key} is a key of the [[render]] entry, not of its settings"),
                ));
            }
        }
        RenderJob::default()
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
        if frames.len() > 1 && !crate::sequence::has_frame_token(&pattern_text) {
            return Err(bad(
                "output",
                format!(
                    "several frames need a frame token ({}) in the output name",
                    crate::sequence::FRAME_TOKENS
                ),
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
            let mut args: Vec<String> =
                vec!["render".into(), "--quiet".into(), "--log-timestamps".into()];
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
            // Render index and frame make the name unique (outputs in different folders
            // may share a file name).
            let log = match frame {
                Some(f) => logs.join(format!("render{i}.frame{f}.{name}.log")),
                None => logs.join(format!("render{i}.{name}.log")),
            };
            if let Some(&k) = writers.get(&normal_file(&output)) {
                let earlier = &tasks[k];
                return Err(bad(
                    "output",
                    format!(
                        "{} is also the output of {}{}: two renders cannot write one file",
                        output.display(),
                        earlier.log.file_name().map_or(String::new(), |n| {
                            n.to_string_lossy()
                                .split('.')
                                .next()
                                .unwrap_or("")
                                .to_string()
                        }),
                        earlier
                            .frame
                            .map_or(String::new(), |f| format!(" frame {f}"))
                    ),
                ));
            }
            writers.insert(normal_file(&output), tasks.len());
            tasks.push(Task {
                scene: scene.clone(),
                frame,
                log,
                output,
                args,
                settings: settings_text.clone(),
                resolution: render.resolution.clone(),
            });
        }
    }
    Ok(tasks)
}

/// The file an output path names, one spelling per file: absolute, `.` and `..` resolved
/// lexically, and its directory's links resolved where it exists.
fn normal_file(p: &Path) -> PathBuf {
    let mut absolute = PathBuf::new();
    for part in std::path::absolute(p)
        .unwrap_or_else(|_| p.to_path_buf())
        .components()
    {
        match part {
            std::path::Component::ParentDir => {
                absolute.pop();
            }
            std::path::Component::CurDir => {}
            other => absolute.push(other),
        }
    }
    let dir = absolute
        .parent()
        .and_then(|d| std::fs::canonicalize(d).ok())
        .unwrap_or_else(|| absolute.parent().unwrap_or(Path::new("")).to_path_buf());
    dir.join(absolute.file_name().unwrap_or_default())
}

/// What an existing output is to the job.
#[derive(Debug, PartialEq)]
enum OutputState {
    Absent,
    /// Complete and made as the job asks: skipped.
    Complete,
    /// A checkpoint of this job's render: resumed.
    Checkpoint,
    /// Unreadable, or made otherwise than the job asks: rendered again from the start.
    Stale(String),
}

/// Reads the output of `task` back whole (header and every pixel) and compares how it was
/// made with what the job asks: settings, shutter, scene file (by content), frame and
/// resolution.
fn output_state(task: &Task) -> OutputState {
    let path = &task.output;
    if !path.exists() {
        return OutputState::Absent;
    }
    let (planes, header) = match exr::read(path) {
        Ok(read) => read,
        Err(e) => return OutputState::Stale(format!("the existing file is unreadable ({e})")),
    };
    let mut asked = RenderJob::default();
    let mut made = RenderOptions::command_line();
    if asked.load_settings(&task.settings).is_err()
        || asked.finish().is_err()
        || made
            .load_recorded_settings(header.text("lucerna/settings").unwrap_or_default())
            .is_err()
    {
        return OutputState::Stale("its settings cannot be read".into());
    }
    // A shutter the job names must be the one the output was made with (a stage's own
    // shutter, which only the stage knows, is not checked here).
    if let Some((open, close)) = asked.load.shutter {
        let wanted = (close > open).then(|| {
            crate::scene::Shutter {
                open,
                close,
                blur: asked.load.motion_blur,
            }
            .describe()
        });
        if header.text("lucerna/shutter") != wanted.as_deref() {
            return OutputState::Stale("it was rendered with another shutter".into());
        }
    }
    let job = asked.options;
    let complete = header.number("lucerna/complete") == Some(1.0);
    if let Some(what) = job.differs_from(&made) {
        return OutputState::Stale(format!("its {what} differ from the job's"));
    }
    if complete
        && job.time.is_none()
        && job.noise_threshold.is_none()
        && job.spp.is_some_and(|s| Some(s) != made.spp)
    {
        return OutputState::Stale(format!(
            "it has {} samples per pixel, the job asks for {}",
            made.spp.unwrap_or(0),
            job.spp.unwrap_or(0)
        ));
    }
    if let (Some(theirs), Some((_, ours))) = (
        header.text("lucerna/scene_fingerprint"),
        crate::ingest::scene_identity(task.scene.as_deref()),
    ) && theirs != ours
    {
        return OutputState::Stale("the scene file has changed".into());
    }
    if header.number("lucerna/frame") != task.frame {
        return OutputState::Stale("it is another frame".into());
    }
    if let Some(resolution) = &task.resolution {
        let (w, h) = planes.display;
        if !resolution.eq_ignore_ascii_case(&format!("{w}x{h}")) {
            return OutputState::Stale(format!("it is {w}x{h}, the job asks for {resolution}"));
        }
    }
    if complete {
        OutputState::Complete
    } else {
        OutputState::Checkpoint
    }
}

/// Runs `task` with the `lucerna` command `exe` (program and leading arguments); `stop`
/// (set by a signal) forwards SIGTERM
/// to the child, which writes its checkpoint.
fn run_task(exe: &[OsString], task: &Task, stop: &AtomicBool) -> FrameReport {
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
        note: None,
        log: task.log.clone(),
    };
    let state = output_state(task);
    if state == OutputState::Complete {
        report.status = Status::Skipped;
    } else {
        let mut args = task.args.clone();
        match state {
            OutputState::Checkpoint => args.push("--resume".into()),
            OutputState::Stale(why) => {
                log::info!("batch: rendering {} again: {why}", task.output.display());
                report.note = Some(format!("rendered again: {why}"));
            }
            _ => {}
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
        report.samples = header.number("lucerna/samples").map(|n| n as u64);
        report.spp = header.number("lucerna/spp").map(|n| n as u32);
        report.nan_inf_discarded = header.number("lucerna/nan_inf_discarded").map(|n| n as u64);
    }
    report
}

/// Starts `exe args` with its output in `log` and waits for it, passing SIGTERM on when
/// `stop` is set and SIGUSR1 (a snapshot) when the batch receives it.
fn spawn_and_wait(
    exe: &[OsString],
    args: &[String],
    log: &Path,
    stop: &AtomicBool,
) -> std::result::Result<std::process::ExitStatus, String> {
    use std::io::Write;
    let mut file =
        std::fs::File::create(log).map_err(|e| format!("cannot write {}: {e}", log.display()))?;
    let quoted: Vec<String> = args.iter().map(|a| format!("{a:?}")).collect();
    let program: Vec<String> = exe
        .iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let _ = writeln!(file, "$ {} {}", program.join(" "), quoted.join(" "));
    let err = file
        .try_clone()
        .map_err(|e| format!("cannot write {}: {e}", log.display()))?;
    let mut command = Command::new(&exe[0]);
    command
        .args(&exe[1..])
        .args(args)
        .stdin(Stdio::null())
        .stdout(file)
        .stderr(err);
    // The child starts with SIGUSR1 ignored, until its own handler takes it over: a
    // snapshot request forwarded in its first milliseconds must not end it.
    crate::platform::start_ignoring_snapshots(&mut command);
    let mut child = command
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", program.join(" ")))?;
    let mut forwarded = false;
    loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            return Ok(status);
        }
        if crate::interrupt::take_snapshot_request() {
            // SIGUSR1 to the batch: the frame being rendered writes a snapshot.
            crate::platform::ask(&mut child, crate::platform::Request::Snapshot);
        }
        if stop.load(Ordering::Relaxed) && !forwarded {
            crate::platform::ask(&mut child, crate::platform::Request::Stop);
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
        .find_map(|l| {
            // After the timestamp `--log-timestamps` puts first.
            let l = match l.split_once(' ') {
                Some((stamp, rest)) if stamp.ends_with('Z') && stamp.contains('T') => rest,
                _ => l,
            };
            l.strip_prefix("error: ")
        })
        .map(str::to_string)
}

/// Runs every task in order with the `lucerna` command `exe` (the binary, or a Python
/// running the package's CLI, with its leading arguments), printing a line per frame;
/// stops launching frames once `stop` is set.
pub fn run(job: &Path, exe: &[OsString], tasks: &[Task], stop: &AtomicBool) -> Summary {
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
            "{}[{}/{}] {}: {what}",
            crate::logging::stamp(),
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
