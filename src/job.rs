//! A render job: what `lucerna render` does, as a library call. The command line, the
//! children of `lucerna batch` and the Python package all build a [`RenderJob`] (defaults,
//! then a settings file, then their own arguments, through [`RenderJob::set`]) and call
//! [`run`]; `main.rs` only parses arguments.
//!
//! A job reads the scene (once per frame), chooses its views (the command line's output, or
//! the render products a USD stage declares), renders each, and writes its files: the EXR(s)
//! atomically, the optional denoised layer, preview PNG and statistics JSON. Checkpoints
//! (`--checkpoint-interval`, SIGUSR1, a stopping signal) are EXRs that `--resume` continues.

use crate::error::{Error, Result};
use crate::film::aov::{Aov, AovSet};
use crate::film::planes::Planes;
use crate::film::{self, Film};
use crate::output::exr::{self, Attribute, Header};
use crate::output::preview::{Curve, ViewTransform};
use crate::output::{denoise, preview};
use crate::render::plan::PlanMode;
use crate::render::{self, ProgressLines, RenderOptions, RenderStats};
use crate::scene::Scene;
use crate::scene::features::strip_unused_attributes;
use crate::sequence::{FrameList, output_path};
use crate::world::World;
use crate::{ingest, memory};
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Everything one `lucerna render` is asked to do.
#[derive(Clone, Debug)]
pub struct RenderJob {
    /// The scene file; `None` renders the embedded Cornell box.
    pub scene: Option<PathBuf>,
    pub load: ingest::LoadOptions,
    /// Output pattern (`{frame}`, `{scene}`, `{camera}`); `None`: the stage's render
    /// products, else `render.exr`.
    pub output: Option<PathBuf>,
    pub frames: Option<FrameList>,
    pub options: RenderOptions,
    /// Whether the AOVs were asked for (they then replace the render products' own).
    pub aov_given: bool,
    pub resolution: Option<(u32, u32)>,
    pub camera: Option<String>,
    pub threads: Option<u32>,
    pub env: Option<Vec3>,
    pub env_map: Option<PathBuf>,
    pub env_scale: Vec3,
    pub subdiv_level: Option<u32>,
    pub stats_json: Option<PathBuf>,
    pub default_light: bool,
    pub storage: exr::Storage,
    pub preview: Option<PathBuf>,
    pub view: ViewTransform,
    pub denoise: bool,
    pub resume: bool,
    /// Seconds between checkpoints written while rendering.
    pub checkpoint_interval: Option<f64>,
    pub max_memory: Option<u64>,
    /// `auto`, `bar`, `lines`, `alfred` or `none`.
    pub progress: String,
    pub progress_interval: f64,
    pub quiet: bool,
    /// Write the files (the Python API renders into memory without).
    pub write_files: bool,
    /// Keep every view's film (and denoised beauty) in the result.
    pub keep_images: bool,
    /// The flag that stops the render (its checkpoint written); `None`: SIGINT and SIGTERM
    /// set it (src/interrupt.rs installs their handler).
    pub stop: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

impl Default for RenderJob {
    fn default() -> Self {
        Self {
            scene: None,
            load: ingest::LoadOptions::default(),
            output: None,
            frames: None,
            options: RenderOptions::command_line(),
            aov_given: false,
            resolution: None,
            camera: None,
            threads: None,
            env: None,
            env_map: None,
            env_scale: Vec3::ONE,
            subdiv_level: None,
            stats_json: None,
            default_light: true,
            storage: exr::Storage::default(),
            preview: None,
            view: ViewTransform::default(),
            denoise: false,
            resume: false,
            checkpoint_interval: None,
            max_memory: None,
            progress: "auto".into(),
            progress_interval: 5.0,
            quiet: false,
            write_files: true,
            keep_images: false,
            stop: None,
        }
    }
}

/// Settings of a job beyond [`RenderOptions`]'s (whose names [`RenderOptions::set`]
/// takes): the keys a settings file, a batch job's `settings` and the Python API accept, as
/// the command line's flags without `--`.
pub const JOB_SETTINGS: [&str; 39] = [
    "output",
    "frames",
    "frame",
    "fps",
    "no-validate",
    "strict",
    "variant",
    "purpose",
    "no-payloads",
    "render-settings",
    "material-variant",
    "animation",
    "usd-timeout",
    "resolution",
    "camera",
    "threads",
    "env",
    "env-map",
    "env-scale",
    "subdiv-level",
    "stats-json",
    "no-default-light",
    "exr-half",
    "exr-compression",
    "preview",
    "exposure",
    "view-transform",
    "ocio-config",
    "ocio-display",
    "ocio-view",
    "denoise",
    "resume",
    "checkpoint-interval",
    "max-memory",
    "progress",
    "progress-interval",
    "quiet",
    "light-group",
    "scene",
];

fn parse_bool(value: &str) -> std::result::Result<bool, String> {
    match value {
        "true" | "1" | "yes" | "on" => Ok(true),
        "false" | "0" | "no" | "off" => Ok(false),
        _ => Err(format!("true or false, got {value:?}")),
    }
}

/// A number of seconds in `least..=most`.
fn seconds(value: &str, least: f64, most: f64) -> std::result::Result<f64, String> {
    value
        .parse::<f64>()
        .ok()
        .filter(|s| s.is_finite() && *s > 0.0 && (least..=most).contains(s))
        .ok_or_else(|| format!("a number of seconds from {least} to {most}, got {value:?}"))
}

/// An image size `WxH`.
fn parse_resolution(s: &str) -> std::result::Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WIDTHxHEIGHT, got {s:?}"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|n| (1..=crate::camera::MAX_IMAGE_SIDE).contains(n))
            .ok_or_else(|| {
                format!(
                    "width and height are integers in 1..={}, got {v:?}",
                    crate::camera::MAX_IMAGE_SIDE
                )
            })
    };
    Ok((parse(w)?, parse(h)?))
}

/// An RGB radiance `R,G,B` (or one value for all three).
fn parse_rgb(s: &str) -> std::result::Result<Vec3, String> {
    let values: Vec<f32> = s
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f32>()
                .map_err(|_| format!("not a number: {v:?}"))
        })
        .collect::<std::result::Result<_, _>>()?;
    let c = match values[..] {
        [v] => Vec3::splat(v),
        [r, g, b] => Vec3::new(r, g, b),
        _ => return Err(format!("expected R,G,B or one value, got {s:?}")),
    };
    // Radiance beyond 1e18 leaves no headroom for f32 sums over samples and pixels.
    if c.is_finite() && c.min_element() >= 0.0 && c.max_element() <= 1e18 {
        Ok(c)
    } else {
        Err("values must be finite, non-negative and at most 1e18".into())
    }
}

/// A frame number of an animation.
fn parse_frame(s: &str) -> std::result::Result<f64, String> {
    s.parse::<f64>()
        .ok()
        .filter(|f| f.is_finite() && f.abs() <= 1e9)
        .ok_or_else(|| format!("a finite number, got {s:?}"))
}

impl RenderJob {
    /// Sets `name` from its textual value: a job setting ([`JOB_SETTINGS`]) or a render
    /// option.
    pub fn set(&mut self, name: &str, value: &str) -> std::result::Result<(), String> {
        let text = || Some(value.to_string());
        match name {
            "scene" => self.scene = Some(value.into()),
            "output" => self.output = Some(value.into()),
            "frames" => self.frames = Some(FrameList::parse(value)?),
            "frame" => self.load.frame = Some(parse_frame(value)?),
            "fps" => {
                self.load.fps = value
                    .parse::<f64>()
                    .ok()
                    .filter(|f| f.is_finite() && *f > 0.0)
                    .ok_or_else(|| {
                        format!("frames per second must be a positive number, got {value:?}")
                    })?
            }
            "no-validate" => self.load.validate = !parse_bool(value)?,
            "strict" => self.load.strict = parse_bool(value)?,
            "variant" => self.load.variants.push(value.into()),
            "purpose" => self.load.purpose = value.into(),
            "no-payloads" => self.load.payloads = !parse_bool(value)?,
            "render-settings" => self.load.render_settings = text(),
            "material-variant" => self.load.material_variant = text(),
            "animation" => self.load.animation = text(),
            "usd-timeout" => {
                self.load.plugin_timeout = Duration::from_secs_f64(seconds(value, 0.0, 1e7)?)
            }
            "resolution" => self.resolution = Some(parse_resolution(value)?),
            "camera" => self.camera = text(),
            "threads" => {
                self.threads = Some(
                    value
                        .parse::<u32>()
                        .ok()
                        .filter(|&n| n >= 1)
                        .ok_or_else(|| format!("a positive integer, got {value:?}"))?,
                )
            }
            "env" => self.env = Some(parse_rgb(value)?),
            "env-map" => self.env_map = Some(value.into()),
            "env-scale" => self.env_scale = parse_rgb(value)?,
            "subdiv-level" => {
                self.subdiv_level = Some(
                    value
                        .parse::<u32>()
                        .ok()
                        .filter(|&n| n <= 6)
                        .ok_or_else(|| format!("an integer in 0..=6, got {value:?}"))?,
                )
            }
            "stats-json" => self.stats_json = Some(value.into()),
            "no-default-light" => self.default_light = !parse_bool(value)?,
            "exr-half" => self.storage.half_light_layers = parse_bool(value)?,
            "exr-compression" => self.storage.compression = exr::parse_compression(value)?,
            "preview" => self.preview = Some(value.into()),
            "exposure" => {
                self.view.exposure = value
                    .parse::<f32>()
                    .ok()
                    .filter(|e| e.abs() <= 64.0)
                    .ok_or_else(|| format!("stops in [-64, 64], got {value:?}"))?
            }
            "view-transform" => self.view.curve = Curve::parse(value)?,
            "ocio-config" => self.view.ocio_config = text(),
            "ocio-display" => self.view.ocio_display = text(),
            "ocio-view" => self.view.ocio_view = text(),
            "denoise" => self.denoise = parse_bool(value)?,
            "resume" => self.resume = parse_bool(value)?,
            "checkpoint-interval" => self.checkpoint_interval = Some(seconds(value, 0.0, 1e7)?),
            "max-memory" => self.max_memory = Some(memory::parse_limit(value)?),
            "progress" => {
                if !["auto", "bar", "lines", "alfred", "none"].contains(&value) {
                    return Err(format!("auto, bar, lines, alfred or none, got {value:?}"));
                }
                self.progress = value.into();
            }
            "progress-interval" => self.progress_interval = seconds(value, 0.05, 86_400.0)?,
            "quiet" => self.quiet = parse_bool(value)?,
            "light-group" => {
                let mut groups = crate::light::groups::describe(&self.options.light_groups);
                if !groups.is_empty() {
                    groups.push(';');
                }
                groups.push_str(value);
                self.options.set("light-groups", &groups)?;
            }
            "aov" => {
                self.options.set(name, value)?;
                self.aov_given = true;
            }
            _ => self.options.set(name, value).map_err(|e| {
                if e.contains("unknown") {
                    format!("{e} (job settings: {})", JOB_SETTINGS.join(", "))
                } else {
                    e
                }
            })?,
        }
        Ok(())
    }

    /// Applies a settings file's text (TOML: keys as the flags, without `--`).
    pub fn load_settings(&mut self, text: &str) -> std::result::Result<(), String> {
        for (name, value) in crate::integrator::settings::read_settings_toml(text)? {
            self.set(&name, &value)
                .map_err(|e| format!("{name}: {e}"))?;
        }
        Ok(())
    }

    /// Applies the settings file at `path`.
    pub fn load_settings_file(&mut self, path: &Path) -> Result<()> {
        let text = crate::files::read_input(path)
            .and_then(|b| String::from_utf8(b).map_err(|_| "not UTF-8 text".to_string()))
            .map_err(|e| Error::bad_input(path, "file", e))?;
        self.load_settings(&text)
            .map_err(|e| Error::bad_input(path, "settings", e))
    }

    /// Checks the job as a whole and settles what depends on several settings (progress
    /// display, the layers denoising needs). Called by [`run`].
    pub fn finish(&mut self) -> Result<()> {
        use std::io::IsTerminal;
        let terminal = std::io::stderr().is_terminal();
        let lines = |alfred| {
            Some(ProgressLines {
                interval: Duration::from_secs_f64(self.progress_interval),
                alfred,
            })
        };
        self.options.progress = !self.quiet && matches!(self.progress.as_str(), "auto" | "bar");
        self.options.progress_lines = match self.progress.as_str() {
            "lines" => lines(false),
            "alfred" => lines(true),
            "auto" if !terminal => lines(false),
            _ => None,
        };
        if self.denoise {
            // The denoiser's guides.
            let mut names = self.options.aovs.describe();
            for guide in ["albedo", "normal"] {
                if !self.options.aovs.iter().any(|a| a.name() == guide) {
                    names.push(',');
                    names.push_str(guide);
                }
            }
            self.options
                .set("aov", &names)
                .map_err(|e| Error::bad_input("", "--denoise", e))?;
        }
        if self.env.is_some() && self.env_map.is_some() {
            return Err(Error::bad_input(
                "",
                "--env",
                "--env and --env-map cannot be given together",
            ));
        }
        if self.resume && self.options.decides_from_whole_image() {
            return Err(Error::bad_input(
                "",
                "--resume",
                "adaptive sampling, rr = efficiency and split = auto keep state an EXR does not hold; they cannot be resumed",
            ));
        }
        if self.checkpoint_interval.is_some() && self.options.decides_from_whole_image() {
            return Err(Error::bad_input(
                "",
                "--checkpoint-interval",
                "adaptive sampling, rr = efficiency and split = auto keep state an EXR does not hold; their checkpoints could not be continued",
            ));
        }
        check_lossless_data(self.storage, &self.options.aovs)?;
        if let Some(FrameList(frames)) = &self.frames
            && frames.len() > 1
            && self
                .output
                .as_ref()
                .is_some_and(|o| !o.to_string_lossy().contains("{frame}"))
        {
            return Err(Error::bad_input(
                "",
                "--output",
                "several frames need {frame} in the output name",
            ));
        }
        if let Some(p) = &self.output
            && !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"))
        {
            return Err(Error::bad_input(
                "",
                "--output",
                format!(
                    "{} is not an .exr file: lucerna writes multi-layer OpenEXR (--preview writes a PNG of the beauty)",
                    p.display()
                ),
            ));
        }
        if let Some(p) = &self.preview
            && !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"))
        {
            return Err(Error::bad_input(
                "",
                "--preview",
                format!("{} is not a .png file", p.display()),
            ));
        }
        self.options
            .settings
            .validate()
            .map_err(|e| Error::bad_input("", "settings", e))?;
        self.options
            .validate()
            .map_err(|e| Error::bad_input("", "settings", e))
    }

    fn stem(&self) -> String {
        self.scene
            .as_deref()
            .and_then(Path::file_stem)
            .map_or("default".into(), |s| s.to_string_lossy().into_owned())
    }
}

/// One rendered view of one frame.
pub struct Rendered {
    pub frame: Option<f64>,
    pub camera: Option<String>,
    /// The files written.
    pub outputs: Vec<PathBuf>,
    pub stats: RenderStats,
    /// With [`RenderJob::keep_images`]: the film, and the denoised beauty's planes.
    pub film: Option<Film>,
    pub denoised: Option<[Vec<f32>; 3]>,
}

/// What a job did.
pub struct Outcome {
    pub rendered: Vec<Rendered>,
    /// The signal that stopped the job (its checkpoint written), if one did.
    pub interrupted: Option<i32>,
}

impl Outcome {
    /// The process exit code: 0, or 128 + the signal, as shells report it.
    pub fn exit_code(&self) -> u8 {
        self.interrupted.map_or(0, crate::interrupt::exit_code)
    }
}

/// Refuses lossy compression for a request with data layers (a render product's AOVs are
/// checked again when its view is made).
fn check_lossless_data(storage: exr::Storage, aovs: &AovSet) -> Result<()> {
    if let Some(lossy) = Some(storage.compression).filter(|&c| exr::is_lossy(c))
        && let Some(data) = aovs.iter().find(|a| !a.is_light())
    {
        return Err(Error::bad_input(
            "",
            "--exr-compression",
            format!(
                "{lossy} is lossy and layer {} holds data that must be stored exactly: use zip or piz, or leave it out of --aov",
                data.name()
            ),
        ));
    }
    Ok(())
}

/// Runs `job`: every frame, every view.
pub fn run(job: &RenderJob) -> Result<Outcome> {
    let mut job = job.clone();
    job.finish()?;
    if job.preview.is_some() && job.write_files {
        // An OCIO display or view that does not exist fails before the scene is read.
        preview::check(&job.view)?;
    }
    let mut options = job.options.clone();
    options.interrupt = Some(match &job.stop {
        Some(flag) => flag.clone(),
        None => crate::interrupt::install()?,
    });
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = job.threads {
        builder = builder.num_threads(n as usize);
    }
    let pool = builder
        .build()
        .map_err(|e| Error::other("", "threads", e.to_string()))?;
    let frames: Vec<Option<f64>> = match &job.frames {
        Some(FrameList(frames)) => frames.iter().map(|&f| Some(f)).collect(),
        None => vec![job.load.frame],
    };
    let several = frames.len() > 1;
    let mut outcome = Outcome {
        rendered: Vec::new(),
        interrupted: None,
    };
    for frame in frames {
        render_frame(&job, &options, &pool, frame, several, &mut outcome)?;
        if outcome.interrupted.is_some() {
            break;
        }
    }
    Ok(outcome)
}

/// Reads a scene (the embedded Cornell box without a path) and logs its warnings.
pub fn load_scene(path: Option<&Path>, load: &ingest::LoadOptions) -> Result<Scene> {
    let scene = match path {
        Some(p) => ingest::load(p, load)?,
        None => ingest::default_scene()?,
    };
    for w in &scene.warnings {
        log::warn!("{w}");
    }
    Ok(scene)
}

/// Most light groups a render writes layers for.
const MAX_LIGHT_GROUPS: usize = 64;

/// What a checkpoint being resumed already holds.
struct Resumed {
    planes: Planes,
    discarded: u64,
    seconds: f64,
}

/// Reads the render to continue from `path`, checking that it is this render's (same
/// scene, settings, AOVs, window and pass); `None` if there is no file yet.
fn read_checkpoint(
    path: &Path,
    source: &str,
    identity: Option<&(String, String)>,
    options: &RenderOptions,
) -> Result<Option<Resumed>> {
    if !path.exists() {
        log::info!(
            "{} does not exist yet; rendering from the start",
            path.display()
        );
        return Ok(None);
    }
    let (planes, header) = exr::read(path)?;
    let bad = |element: &str, reason: String| Error::bad_input(path, element, reason);
    if header.number("lucerna/samples") == Some(0.0) {
        log::info!(
            "{} holds no samples; rendering from the start",
            path.display()
        );
        return Ok(None);
    }
    // The same scene: by its content where both have a fingerprint (any path may name
    // it), else by canonical path, else as named.
    let same_scene = match (header.text("lucerna/scene_fingerprint"), identity) {
        (Some(theirs), Some((_, ours))) => theirs == ours,
        (None, Some((canonical, _))) => {
            header.text("lucerna/scene") == Some(source)
                || header
                    .text("lucerna/scene")
                    .and_then(|s| std::fs::canonicalize(s).ok())
                    .is_some_and(|c| c.to_string_lossy() == canonical.as_str())
        }
        _ => header.text("lucerna/scene") == Some(source),
    };
    if !same_scene {
        if let (Some(_), Some((canonical, _))) =
            (header.text("lucerna/scene_fingerprint"), identity)
            && header.text("lucerna/scene_path") == Some(canonical.as_str())
        {
            return Err(bad(
                "lucerna/scene_fingerprint",
                format!(
                    "{source:?} has changed since this checkpoint was written: it cannot be continued"
                ),
            ));
        }
        return Err(bad(
            "lucerna/scene",
            format!(
                "a render of {:?}, not of {source:?}",
                header.text("lucerna/scene").unwrap_or("an unknown scene")
            ),
        ));
    }
    let mut earlier = RenderOptions::default();
    earlier
        .load_settings(header.text("lucerna/settings").unwrap_or_default())
        .map_err(|e| bad("lucerna/settings", e))?;
    if let Some(what) = earlier.differs_from(options) {
        return Err(bad(
            "lucerna/settings",
            format!(
                "its {what} differ from this render's: it cannot be continued with these options"
            ),
        ));
    }
    if options.pass.is_some() && earlier.spp != options.spp {
        return Err(bad(
            "lucerna/settings",
            "a pass keeps its total sample count (--spp) when it is continued".into(),
        ));
    }
    Ok(Some(Resumed {
        planes,
        discarded: header.number("lucerna/nan_inf_discarded").unwrap_or(0.0) as u64,
        seconds: header.number("lucerna/render_seconds").unwrap_or(0.0),
    }))
}

/// One render of a frame: the camera, size and AOVs it takes (in its options) and the files
/// it writes. The first output is where a checkpoint goes and what `--resume` continues.
struct View {
    camera: Option<String>,
    resolution: Option<(u32, u32)>,
    options: RenderOptions,
    outputs: Vec<ViewOutput>,
}

/// A file a view writes: `aovs` selects its layers (`None`: all the render's).
struct ViewOutput {
    path: PathBuf,
    aovs: Option<AovSet>,
}

/// Renders one frame into `outcome`.
fn render_frame(
    job: &RenderJob,
    options: &RenderOptions,
    pool: &rayon::ThreadPool,
    frame: Option<f64>,
    several_frames: bool,
    outcome: &mut Outcome,
) -> Result<()> {
    let load = ingest::LoadOptions {
        frame,
        ..job.load.clone()
    };
    let mut scene = load_scene(job.scene.as_deref(), &load)?;
    let stem = job.stem();
    let settings = scene.render_settings.take().unwrap_or_default();
    let views = match &job.output {
        None if !settings.products.is_empty() => declared_views(job, options, &settings)?,
        _ => {
            let pattern = job.output.clone().unwrap_or_else(|| "render.exr".into());
            if several_frames && !pattern.to_string_lossy().contains("{frame}") {
                return Err(Error::bad_input(
                    "",
                    "--output",
                    "several frames need {frame} in the output name",
                ));
            }
            // The settings' camera, size and window apply where the job gives none.
            let camera = job.camera.clone().or(settings.camera.clone());
            let camera_name = match &camera {
                Some(name) => name.clone(),
                None => scene
                    .cameras
                    .first()
                    .map_or("default".into(), |c| c.name.clone()),
            };
            let path = output_path(&pattern, frame, &stem, &camera_name)
                .map_err(|e| Error::bad_input("", "--output", e))?;
            let mut view_options = options.clone();
            if let (None, None, Some(crop)) = (options.crop, job.resolution, settings.crop) {
                view_options.crop = Some(pixel_window(crop));
            }
            vec![View {
                camera,
                resolution: job.resolution.or(settings.resolution.map(|[w, h]| (w, h))),
                options: view_options,
                outputs: vec![ViewOutput { path, aovs: None }],
            }]
        }
    };
    // Every output is checked (and its directory made) before rendering, so an impossible
    // output fails at once.
    if job.write_files {
        for output in views.iter().flat_map(|v| &v.outputs) {
            crate::files::check_output(&output.path, "--output")?;
        }
    }
    let preview = job
        .preview
        .as_ref()
        .filter(|_| job.write_files)
        .map(|p| {
            let camera = views[0].camera.clone().unwrap_or_else(|| "default".into());
            output_path(p, frame, &stem, &camera)
        })
        .transpose()
        .map_err(|e| Error::bad_input("", "--preview", e))?;
    if let Some(png) = &preview {
        crate::files::check_output(png, "--preview")?;
    }
    let count = views.len();
    for (i, view) in views.into_iter().enumerate() {
        let scene = if i + 1 == count {
            std::mem::take(&mut scene)
        } else {
            scene.clone()
        };
        let preview = if i == 0 { preview.as_deref() } else { None };
        render_view(job, &view, pool, frame, scene, preview, outcome)?;
        if outcome.interrupted.is_some() {
            break;
        }
    }
    Ok(())
}

/// The views of a scene's declared render products: products that share camera, size and
/// data window are rendered once, with the union of their AOVs, and each file gets its own
/// layers. The job's camera, resolution, crop and AOVs apply to all.
fn declared_views(
    job: &RenderJob,
    options: &RenderOptions,
    settings: &crate::scene::RenderSettings,
) -> Result<Vec<View>> {
    type Shared = (Option<String>, Option<(u32, u32)>, Option<[u32; 4]>);
    let mut groups: Vec<(Shared, View, Vec<&str>)> = Vec::new();
    for (i, product) in settings.products.iter().enumerate() {
        let element = format!("{}: product {i}", settings.path);
        let camera = job.camera.clone().or_else(|| product.camera.clone());
        let resolution = job.resolution.or(product.resolution.map(|[w, h]| (w, h)));
        // A declared window is in the declared resolution's pixels.
        let crop = if options.crop.is_some() || job.resolution.is_some() {
            None
        } else {
            product.crop
        };
        let own = if job.aov_given {
            None
        } else {
            Some(AovSet::parse(&product.aovs).map_err(|e| Error::bad_input("", &element, e))?)
        };
        let output = ViewOutput {
            path: PathBuf::from(&product.output),
            aovs: own,
        };
        let key = (camera.clone(), resolution, crop);
        match groups.iter_mut().find(|(k, ..)| *k == key) {
            Some((_, view, aovs)) => {
                view.outputs.push(output);
                aovs.push(&product.aovs);
            }
            None => {
                let mut view_options = options.clone();
                if let Some(window) = crop.map(pixel_window) {
                    view_options.crop = Some(window);
                }
                let view = View {
                    camera,
                    resolution,
                    options: view_options,
                    outputs: vec![output],
                };
                groups.push((key, view, vec![&product.aovs]));
            }
        }
    }
    let mut views = Vec::with_capacity(groups.len());
    for (_, mut view, aovs) in groups {
        if !job.aov_given {
            let mut names = aovs.join(",");
            if job.denoise {
                names.push_str(",albedo,normal");
            }
            view.options.aovs = AovSet::parse(&names)
                .map_err(|e| Error::bad_input("", settings.path.as_str(), e))?;
        }
        views.push(view);
    }
    if (job.resume || job.checkpoint_interval.is_some())
        && views.iter().any(|v| v.outputs.len() > 1)
    {
        return Err(Error::bad_input(
            "",
            "--resume",
            "render products that share one render cannot be resumed (each file holds only its own layers)",
        ));
    }
    Ok(views)
}

/// The film window of a declared pixel window `[x0, y0, x1, y1]` (ends excluded; the scene
/// file guarantees x0 < x1 and y0 < y1).
fn pixel_window([x0, y0, x1, y1]: [u32; 4]) -> film::Window {
    film::Window {
        x: x0,
        y: y0,
        width: x1 - x0,
        height: y1 - y0,
    }
}

/// What rendering `scene` through `camera` at `resolution` with `options` will need.
pub fn memory_estimate(
    scene: &Scene,
    camera: Option<&str>,
    resolution: Option<(u32, u32)>,
    options: &RenderOptions,
) -> memory::MemoryEstimate {
    let camera = camera
        .and_then(|name| scene.camera(name))
        .or(scene.cameras.first());
    let (width, height) = crate::camera::resolve_resolution(resolution, camera);
    memory::MemoryEstimate {
        film: Film::estimated_bytes(
            width,
            height,
            &options.aovs,
            options.noise_threshold.is_some(),
        ),
        ..crate::world::build::estimate_memory(scene)
    }
}

/// The EXR header of a view's render: how it was made, for the compositor, `--resume`,
/// `lucerna merge` and the batch runner.
struct HeaderFacts<'a> {
    job: &'a RenderJob,
    options: &'a RenderOptions,
    world: &'a World,
    source: &'a str,
    identity: Option<&'a (String, String)>,
    frame: Option<f64>,
}

impl HeaderFacts<'_> {
    fn header(&self, film: &Film, stats: &RenderStats) -> Header {
        // glam's column-major listing of a column-vector matrix is the row-major listing of
        // its transpose: exactly Imath's row-vector convention.
        let imath = |m: glam::DMat4| m.as_mat4().to_cols_array();
        let world = self.world;
        let mut header = Header {
            storage: self.job.storage,
            frames_per_second: self.frame.map(|_| self.job.load.fps),
            world_to_camera: Some(imath(world.camera.world_to_camera)),
            world_to_ndc: Some(imath(world.camera.world_to_ndc)),
            attributes: vec![
                (
                    "lucerna/renderer".into(),
                    Attribute::Text(crate::RENDERER.into()),
                ),
                ("lucerna/scene".into(), Attribute::Text(self.source.into())),
                (
                    "lucerna/settings".into(),
                    Attribute::Text(self.options.to_toml(stats.spp)),
                ),
                (
                    "lucerna/seed".into(),
                    Attribute::Int(self.options.settings.seed as i32),
                ),
                ("lucerna/spp".into(), Attribute::Int(stats.spp as i32)),
                (
                    "lucerna/samples".into(),
                    Attribute::Double(stats.samples as f64),
                ),
                (
                    "lucerna/render_seconds".into(),
                    Attribute::Double(stats.seconds),
                ),
                (
                    "lucerna/nan_inf_discarded".into(),
                    Attribute::Double(stats.discarded as f64),
                ),
                (
                    "lucerna/complete".into(),
                    Attribute::Int(!stats.interrupted as i32),
                ),
            ],
        };
        if let Some((canonical, fingerprint)) = self.identity {
            header.set("lucerna/scene_path", Attribute::Text(canonical.clone()));
            header.set(
                "lucerna/scene_fingerprint",
                Attribute::Text(fingerprint.clone()),
            );
        }
        if let Some(f) = self.frame {
            header.set("lucerna/frame", Attribute::Double(f));
        }
        if let Some(split) = stats.learned_split {
            header.set("lucerna/split_learned", Attribute::Text(split.describe()));
        }
        if film.aovs.wants_crypto() {
            use crate::film::crypto::{Kind, header_attributes};
            let materials = world.material_names();
            for (kind, names) in [
                (Kind::Object, &world.objects.names),
                (Kind::Material, &materials),
            ] {
                for (name, value) in header_attributes(kind, names) {
                    header.set(&name, Attribute::Text(value));
                }
            }
        }
        header
    }
}

/// Renders `scene` as `view` says and writes its files into `outcome`.
fn render_view(
    job: &RenderJob,
    view: &View,
    pool: &rayon::ThreadPool,
    frame: Option<f64>,
    mut scene: Scene,
    preview: Option<&Path>,
    outcome: &mut Outcome,
) -> Result<()> {
    let options = &view.options;
    let output = view.outputs[0].path.clone();
    check_lossless_data(job.storage, &options.aovs)?;
    if let Some(radiance) = job.env {
        ingest::set_constant_environment(&mut scene, radiance);
    }
    if let Some(path) = &job.env_map {
        ingest::set_environment_map(&mut scene, path, job.env_scale)?;
    }
    if !scene.has_light() {
        if job.default_light {
            log::warn!(
                "{}: the scene has no light: it is lit by a constant white environment (--env R,G,B or --env-map to choose one, --no-default-light to render it black)",
                scene.source
            );
            ingest::set_constant_environment(&mut scene, Vec3::ONE);
        } else {
            log::warn!("{}: the scene has no light: it renders black", scene.source);
        }
    }
    // Subdivision surfaces are refined for this view before the memory estimate counts them.
    scene.subdivision_level = job.subdiv_level;
    crate::world::build::refine_subdivision_surfaces(
        &mut scene,
        view.camera.as_deref(),
        view.resolution,
    )?;
    if options.plan != PlanMode::General {
        strip_unused_attributes(&mut scene);
    }
    let limit = job.max_memory.or_else(memory::default_limit);
    memory_estimate(&scene, view.camera.as_deref(), view.resolution, options)
        .check(limit, &scene.source)?;
    // The denoiser is loaded before rendering: a missing library fails at once.
    let denoiser = job.denoise.then(denoise::Denoiser::new).transpose()?;
    if let Some(d) = &denoiser {
        log::debug!("Open Image Denoise from {}", d.path.display());
    }
    let source = scene.source.clone();
    let identity = ingest::scene_identity(job.scene.as_deref());
    let build_start = Instant::now();
    let world = pool.install(|| {
        World::build(
            scene,
            view.camera.as_deref(),
            view.resolution,
            options.settings.light_select,
        )
    })?;
    let build_seconds = build_start.elapsed().as_secs_f64();
    let (width, height) = (world.camera.width(), world.camera.height());
    if let Some(crop) = options.crop.filter(|c| !c.fits(width, height)) {
        return Err(Error::bad_input(
            "",
            "--crop",
            format!(
                "{} lies outside the {width}x{height} image",
                crop.describe()
            ),
        ));
    }
    if options.aovs.wants_light_groups() {
        let groups = options.light_groups(&world).names;
        if groups.len() > MAX_LIGHT_GROUPS {
            return Err(Error::bad_input(
                "",
                "light groups",
                format!(
                    "{} groups; at most {MAX_LIGHT_GROUPS} get layers of their own",
                    groups.len()
                ),
            ));
        }
    }
    let mut film = options.film(&world);
    // Names come from the scene (light groups): refused now rather than after the render.
    exr::check_names(film.channel_names(&[Aov::Spp]).iter().map(|n| n.as_str()))
        .map_err(|reason| Error::bad_input(&source, "light groups", reason))?;
    let resumed = if job.resume {
        read_checkpoint(&output, &source, identity.as_ref(), options)?
    } else {
        None
    };
    if let Some(r) = &resumed {
        film.restore(&r.planes, r.discarded)
            .map_err(|e| Error::bad_input(&output, "checkpoint", e))?;
        log::info!(
            "continuing {} from {} samples per pixel",
            output.display(),
            film.min_samples()
        );
    }
    let earlier_seconds = resumed.as_ref().map_or(0.0, |r| r.seconds);
    let facts = HeaderFacts {
        job,
        options,
        world: &world,
        source: &source,
        identity: identity.as_ref(),
        frame,
    };
    // Checkpoints while sampling: every --checkpoint-interval seconds and on SIGUSR1, after
    // the pass under way. A failed checkpoint is a warning: the render goes on.
    let mut last_checkpoint = Instant::now();
    let mut checkpoint = |film: &Film, stats: &RenderStats| {
        let due = job
            .checkpoint_interval
            .is_some_and(|s| last_checkpoint.elapsed().as_secs_f64() >= s);
        if !(crate::interrupt::take_snapshot_request() || due) || !job.write_files {
            return;
        }
        last_checkpoint = Instant::now();
        let mut stats = *stats;
        stats.seconds += earlier_seconds;
        stats.interrupted = true;
        let header = facts.header(film, &stats);
        match exr::write(&output, film, &header, &[Aov::Spp]) {
            Ok(()) => log::info!(
                "checkpoint: {} samples per pixel written to {}",
                film.min_samples(),
                output.display()
            ),
            Err(e) => log::warn!("checkpoint not written: {e}"),
        }
    };
    // From here a first signal stops sampling and the checkpoint is written; before, it ends
    // the process (src/interrupt.rs).
    let _sampling = crate::interrupt::defer();
    let (film, mut stats) =
        pool.install(|| render::render_with(&world, options, film, &mut checkpoint));
    if stats.interrupted && film.total_samples() == 0 {
        log::info!(
            "interrupted (signal {}) before the first sample; nothing written",
            crate::interrupt::received()
        );
        outcome.interrupted = Some(crate::interrupt::received());
        return Ok(());
    }
    stats.seconds += earlier_seconds;
    let header = facts.header(&film, &stats);
    let denoised = match (&denoiser, stats.interrupted) {
        (Some(d), false) => {
            let start = Instant::now();
            let (beauty, albedo, normal) = (
                film.planes(Aov::Beauty),
                film.planes(Aov::Albedo),
                film.planes(Aov::Normal),
            );
            let rgb = d.denoise(&denoise::Layers {
                width: film.width as usize,
                height: film.height as usize,
                beauty: std::array::from_fn(|c| beauty[c].as_slice()),
                albedo: std::array::from_fn(|c| albedo[c].as_slice()),
                normal: std::array::from_fn(|c| normal[c].as_slice()),
            })?;
            log::info!("denoised in {:.2} s", start.elapsed().as_secs_f64());
            Some(rgb)
        }
        _ => None,
    };
    // Whatever can be continued or merged carries its per-pixel sample counts.
    let extra: &[Aov] = if stats.interrupted || options.pass.is_some() {
        &[Aov::Spp]
    } else {
        &[]
    };
    if job.write_files {
        for out in &view.outputs {
            let keep = |aov: Aov| match &out.aovs {
                None => true,
                Some(own) => {
                    own.contains(aov)
                        || (matches!(aov, Aov::LightGroup(_)) && own.wants_light_groups())
                }
            };
            let mut planes = film.to_planes(extra, keep);
            if let Some(d) = &denoised {
                planes.channels.extend(denoise::channels(d.clone()));
            }
            exr::write_planes(&out.path, planes, &header)?;
        }
    }
    if let Some(pattern) = job.stats_json.as_ref().filter(|_| job.write_files) {
        write_stats_json(
            pattern,
            job,
            view,
            frame,
            &source,
            &film,
            &stats,
            build_seconds,
            pool,
        )?;
    }
    let outputs: Vec<PathBuf> = if job.write_files {
        view.outputs.iter().map(|o| o.path.clone()).collect()
    } else {
        Vec::new()
    };
    if stats.interrupted {
        log::info!(
            "interrupted (signal {}): wrote the {} samples taken so far to {}; continue with --resume",
            crate::interrupt::received(),
            stats.samples,
            output.display()
        );
        outcome.interrupted = Some(crate::interrupt::received());
    } else {
        if let Some(png) = preview {
            match &denoised {
                Some(d) => preview::write_rgb(
                    png,
                    (film.width, film.height),
                    [&d[0], &d[1], &d[2]],
                    &job.view,
                )?,
                None => preview::write(png, &film, &job.view)?,
            }
        }
        let peak = render::peak_memory_bytes().map_or(String::new(), |b| {
            format!(", peak memory {:.1} MB", b as f64 / 1e6)
        });
        let written: Vec<String> = outputs.iter().map(|o| o.display().to_string()).collect();
        log::info!(
            "{} ({}x{}, {} threads): scene prepared in {:.2} s ({} primitives{}, BVH built in {:.2} s); rendered in {}{peak}",
            if written.is_empty() {
                "rendered".to_string()
            } else {
                format!("wrote {}", written.join(", "))
            },
            film.width,
            film.height,
            pool.current_num_threads(),
            build_seconds,
            world.primitive_count(),
            match world.surfaces.placements.len() {
                0 => String::new(),
                n => format!(
                    ", {n} placements of {} shared meshes",
                    world.surfaces.shared_meshes.len()
                ),
            },
            world.bvh_seconds,
            stats.summary()
        );
    }
    outcome.rendered.push(Rendered {
        frame,
        camera: view.camera.clone(),
        outputs,
        stats,
        film: job.keep_images.then_some(film),
        denoised: denoised.filter(|_| job.keep_images),
    });
    Ok(())
}

/// `--stats-json`: the render's figures, counts as integers.
#[allow(clippy::too_many_arguments)]
fn write_stats_json(
    pattern: &Path,
    job: &RenderJob,
    view: &View,
    frame: Option<f64>,
    source: &str,
    film: &Film,
    stats: &RenderStats,
    build_seconds: f64,
    pool: &rayon::ThreadPool,
) -> Result<()> {
    let path = output_path(pattern, frame, &job.stem(), "")
        .map_err(|e| Error::bad_input("", "--stats-json", e))?;
    let json = serde_json::json!({
        "outputs": view.outputs.iter().map(|o| o.path.display().to_string()).collect::<Vec<_>>(),
        "scene": source,
        "frame": frame,
        "width": film.width,
        "height": film.height,
        "spp": stats.spp,
        "samples": stats.samples,
        "rays_closest": stats.rays.closest,
        "rays_shadow": stats.rays.shadow,
        "nan_inf_discarded": stats.discarded,
        "prepare_seconds": build_seconds,
        "render_seconds": stats.seconds,
        "samples_per_second": (stats.samples as f64 / stats.seconds.max(1e-9)).round() as u64,
        "peak_memory_bytes": render::peak_memory_bytes(),
        "threads": pool.current_num_threads(),
        "interrupted": stats.interrupted,
        "denoised": job.denoise && !stats.interrupted,
    });
    crate::files::write_atomically(&path, |w| {
        use std::io::Write;
        serde_json::to_writer_pretty(&mut *w, &json)
            .map_err(|e| Error::other(&path, "write", e.to_string()))?;
        w.write_all(b"\n")
            .map_err(|e| Error::other(&path, "write", e.to_string()))
    })
}
