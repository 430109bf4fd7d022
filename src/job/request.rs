//! What a render job is asked to do ([`RenderJob`]) and its settings: the keys of the command
//! line, settings files, batch jobs and the Python API, parsed one by one and checked as a
//! whole ([`RenderJob::finish`]).

use crate::error::{Error, Result};
use crate::film::aov::AovSet;
use crate::output::exr;
use crate::output::preview::{Curve, ViewTransform};
use crate::render::{ProgressLines, RenderOptions};
use crate::sequence::FrameList;
use crate::{ingest, memory};
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::time::Duration;

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
    /// `--texture-memory` (`None`: half of the memory limit).
    pub texture_memory: Option<u64>,
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
            texture_memory: None,
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
pub const JOB_SETTINGS: [&str; 44] = [
    "output",
    "frames",
    "frame",
    "fps",
    "shutter",
    "no-motion-blur",
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
    "exr-aliases",
    "exr-compression",
    "exr-parts",
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
    "texture-memory",
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

/// A shutter interval `OPEN,CLOSE` in frames relative to the frame (USD's
/// `shutter:open`/`shutter:close`): `-0.25,0.25` is a 180-degree shutter centred on it.
fn parse_shutter(s: &str) -> std::result::Result<(f64, f64), String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let number = |p: &str| {
        p.parse::<f64>()
            .ok()
            .filter(|f| f.is_finite() && f.abs() <= 1e3)
    };
    match parts.as_slice() {
        [open, close] => match (number(open), number(close)) {
            (Some(open), Some(close)) if open <= close => Ok((open, close)),
            (Some(_), Some(_)) => Err(format!("the shutter closes before it opens: {s:?}")),
            _ => Err(format!(
                "OPEN,CLOSE in frames relative to the frame (finite, at most 1000), got {s:?}"
            )),
        },
        _ => Err(format!(
            "OPEN,CLOSE in frames relative to the frame (such as -0.25,0.25), got {s:?}"
        )),
    }
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
            "shutter" => self.load.shutter = Some(parse_shutter(value)?),
            "no-motion-blur" => self.load.motion_blur = !parse_bool(value)?,
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
            "exr-aliases" => self.storage.aliases = parse_bool(value)?,
            "exr-compression" => self.storage.compression = exr::parse_compression(value)?,
            "exr-parts" => self.storage.parts = exr::parse_parts(value)?,
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
            "texture-memory" => self.texture_memory = Some(memory::parse_limit(value)?),
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
    /// display, the layers denoising needs). Called by [`run`](super::run).
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
                "adaptive sampling, rr = efficiency, split = auto and guiding keep state an EXR does not hold; they cannot be resumed",
            ));
        }
        if self.checkpoint_interval.is_some() && self.options.decides_from_whole_image() {
            return Err(Error::bad_input(
                "",
                "--checkpoint-interval",
                "adaptive sampling, rr = efficiency, split = auto and guiding keep state an EXR does not hold; their checkpoints could not be continued",
            ));
        }
        check_lossless_data(self.storage, &self.options.aovs)?;
        if let Some(FrameList(frames)) = &self.frames
            && frames.len() > 1
            && self
                .output
                .as_ref()
                .is_some_and(|o| !crate::sequence::has_frame_token(&o.to_string_lossy()))
        {
            return Err(Error::bad_input(
                "",
                "--output",
                format!(
                    "several frames need a frame token ({}) in the output name",
                    crate::sequence::FRAME_TOKENS
                ),
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

    pub(super) fn stem(&self) -> String {
        self.scene
            .as_deref()
            .and_then(Path::file_stem)
            .map_or("default".into(), |s| s.to_string_lossy().into_owned())
    }
}

/// Refuses lossy compression for a request with data layers (a render product's AOVs are
/// checked again when its view is made).
pub(super) fn check_lossless_data(storage: exr::Storage, aovs: &AovSet) -> Result<()> {
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
