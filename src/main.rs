//! The `lucerna` command line: `render`, `inspect` and `convert`.

use clap::{Parser, Subcommand};
use glam::Vec3;
use lucerna::error::{Error, Result};
use lucerna::film::aov::{Aov, AovSet};
use lucerna::film::exr::{Attribute, Header};
use lucerna::plan::{self, PlanMode, RenderPlan, SceneFeatures};
use lucerna::render::{self, RenderOptions};
use lucerna::scene::{LightKind, Scene};
use lucerna::sequence::{FrameList, output_path};
use lucerna::world::World;
use lucerna::{film, ingest, memory};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "lucerna",
    version,
    about = "A physically based path tracer: glTF and USD scenes to multi-layer EXR"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (the embedded Cornell box without SCENE) to a multi-layer EXR.
    Render(Box<RenderArgs>),
    /// Print a summary of a scene and what rendering it needs.
    Inspect {
        /// A .gltf, .glb, .usd, .usda, .usdc, .usdz or .lucerna scene file.
        scene: PathBuf,
        #[command(flatten)]
        load: LoadArgs,
        /// AOVs of the request the plan is made for (as `render --aov`; default all).
        #[arg(long)]
        aov: Option<String>,
        /// auto, packet, scalar or general, as `render --plan`.
        #[arg(long)]
        plan: Option<String>,
    },
    /// Run a job file's renders unattended: a child process and a log per frame, complete
    /// outputs skipped, checkpoints resumed, a JSON summary; exits 1 if any frame failed.
    Batch {
        /// The job (TOML: [settings] for all, then [[render]] entries; see the README).
        job: PathBuf,
        /// Directory of the per-frame logs (default: JOB's name with `.logs`).
        #[arg(long)]
        logs: Option<PathBuf>,
        /// The JSON summary to write (default: JOB's name with `.summary.json`).
        #[arg(long)]
        summary: Option<PathBuf>,
    },
    /// Combine the EXRs of a split render (sample passes and crop windows, in any mix) into
    /// one: sample-weighted means, pooled variance, summed sample counts.
    Merge {
        /// Partial renders (each with an `spp` layer where parts overlap).
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// The merged EXR to write.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Write a scene as a lucerna scene file (a JSON manifest and a binary buffer beside it),
    /// exactly as the renderer sees it.
    Convert {
        /// A .gltf, .glb, .usd, .usda, .usdc, .usdz or .lucerna scene file.
        scene: PathBuf,
        /// The manifest to write, e.g. shot.lucerna (its buffer goes to shot.lucerna.bin).
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        load: LoadArgs,
    },
}

/// How to read the scene.
#[derive(clap::Args)]
struct LoadArgs {
    /// Frame of an animated scene: a USD time code (default: the stage's start time code);
    /// in glTF the time FRAME / fps seconds (default: the nodes' rest transforms).
    #[arg(long, value_parser = parse_frame)]
    frame: Option<f64>,
    /// Frames per second of glTF animations.
    #[arg(long, default_value_t = ingest::DEFAULT_FPS, value_parser = parse_fps)]
    fps: f64,
    /// Skip usd-core's validators (USD stages; faster on large stages).
    #[arg(long, conflicts_with = "strict")]
    no_validate: bool,
    /// Refuse a USD stage on any validator error (default: findings are warnings, as in
    /// husk and usdview).
    #[arg(long)]
    strict: bool,
    /// Select variant NAME of variant set SET in every prim that has it
    /// (`/PRIM:SET=NAME`: in that prim); repeatable. USD stages.
    #[arg(long = "variant", value_name = "SET=NAME")]
    variants: Vec<String>,
    /// Purposes rendered besides `default`, comma-separated: render, proxy, guide. USD
    /// stages.
    #[arg(long, default_value = "render")]
    purpose: String,
    /// Do not load a USD stage's payloads.
    #[arg(long)]
    no_payloads: bool,
    /// The USD RenderSettings prim whose camera, resolution, data window and products
    /// (output files and their AOVs) the render follows (default: the stage's
    /// renderSettingsPrimPath, else its first RenderSettings prim).
    #[arg(long, value_name = "PRIM")]
    render_settings: Option<String>,
    /// Render glTF KHR_materials_variants variant NAME (default: the default materials).
    #[arg(long, value_name = "NAME")]
    material_variant: Option<String>,
    /// Seconds the USD plugin may take to convert a stage before it is stopped.
    #[arg(long, default_value_t = ingest::DEFAULT_PLUGIN_TIMEOUT.as_secs_f64(), value_parser = parse_timeout)]
    usd_timeout: f64,
}

impl LoadArgs {
    fn options(&self) -> ingest::LoadOptions {
        ingest::LoadOptions {
            frame: self.frame,
            fps: self.fps,
            validate: !self.no_validate,
            strict: self.strict,
            variants: self.variants.clone(),
            purpose: self.purpose.clone(),
            payloads: !self.no_payloads,
            render_settings: self.render_settings.clone(),
            material_variant: self.material_variant.clone(),
            plugin_timeout: std::time::Duration::from_secs_f64(self.usd_timeout),
        }
    }
}

#[derive(clap::Args)]
struct RenderArgs {
    /// A .gltf, .glb, .usd, .usda, .usdc, .usdz or .lucerna scene file; without it, the
    /// embedded Cornell box.
    scene: Option<PathBuf>,
    #[command(flatten)]
    load: LoadArgs,
    /// Output EXR file; `{frame}` (four digits), `{scene}` (the file's stem) and `{camera}`
    /// are replaced, e.g. `out/{scene}.{camera}.{frame}.exr`. Default: the render products a
    /// USD stage declares (its render settings), else `render.exr`.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Frames to render, e.g. 1-24, 1-24x2 (every second), 1,5,10-12; the output needs
    /// `{frame}`.
    #[arg(long, conflicts_with = "frame", value_parser = FrameList::parse)]
    frames: Option<FrameList>,
    /// A TOML settings file (keys as the flags below, e.g. `mis = "balance"`); flags given
    /// on the command line override it.
    #[arg(long)]
    settings: Option<PathBuf>,
    /// Samples per pixel (default 64; with --time, the most to take).
    #[arg(long)]
    spp: Option<String>,
    /// Time budget in seconds: render passes until it is spent.
    #[arg(long)]
    time: Option<String>,
    /// AOV layers to write besides the beauty, comma-separated (e.g.
    /// `direct,indirect,albedo`), or presets: `comp` (what a compositor usually wants:
    /// emission, the lobe layers and colours, light groups, albedo, normal, depth,
    /// position, Cryptomatte), `all`, `lobes`, `lightgroups`, `crypto`; per-depth layers
    /// `nee_dK`, `bsdf_dK`. [default: beauty]
    #[arg(long)]
    aov: Option<String>,
    /// Image size, e.g. 640x480 (default: from the camera's aspect ratio, long side 512).
    #[arg(long, value_parser = parse_resolution)]
    resolution: Option<(u32, u32)>,
    /// Camera to render through (default: the scene's first camera).
    #[arg(long)]
    camera: Option<String>,
    /// Random seed.
    #[arg(long)]
    seed: Option<String>,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    threads: Option<u32>,
    /// Constant environment radiance, e.g. 0.5,0.6,0.8.
    #[arg(long, value_parser = parse_rgb, conflicts_with = "env_map")]
    env: Option<Vec3>,
    /// Lat-long environment map (OpenEXR, Radiance HDR, TIFF, PNG, JPEG or WebP).
    #[arg(long)]
    env_map: Option<PathBuf>,
    /// Refine every subdivision surface N levels (0: the control cage; at most 6).
    /// Default: by size on screen, until the cage's mean edge spans about 2 pixels.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(0..=6))]
    subdiv_level: Option<u32>,
    /// Multiplier of the environment map.
    #[arg(long, default_value = "1", value_parser = parse_rgb)]
    env_scale: Vec3,
    /// Write the render's figures as JSON to FILE (counts as integers): image size, spp,
    /// samples, rays, NaN/Inf discarded, seconds, samples/s, peak memory, outputs. Frame
    /// tokens expand as in -o.
    #[arg(long, value_name = "FILE")]
    stats_json: Option<PathBuf>,
    /// Progress display: auto (a bar on a terminal, lines otherwise), bar, lines (plain
    /// lines for logs), alfred (Tractor's ALF_PROGRESS lines), none. `--quiet` drops the
    /// bar, not the lines a log reads. [default: auto]
    #[arg(long, value_name = "MODE", value_parser = ["auto", "bar", "lines", "alfred", "none"])]
    progress: Option<String>,
    /// Seconds between progress lines. [default: 5]
    #[arg(long, value_name = "SECONDS", default_value_t = 5.0, value_parser = parse_interval)]
    progress_interval: f64,
    /// Render a scene without any light black (default: a warning, and a constant white
    /// environment of radiance 1, as scene viewers light such scenes).
    #[arg(long)]
    no_default_light: bool,
    /// Store the light layers (beauty, light and lobe layers, light groups) as 16-bit half
    /// floats; data layers, Cryptomatte, sample counts and variance stay 32-bit.
    #[arg(long)]
    exr_half: bool,
    /// EXR compression: none, rle, zips, zip (default), piz, or lossy pxr24, b44, b44a,
    /// dwaa[:LEVEL], dwab[:LEVEL] (refused with data or Cryptomatte layers).
    #[arg(long, value_name = "NAME", value_parser = film::exr::parse_compression)]
    exr_compression: Option<film::exr::Compression>,
    /// Also write a tone-mapped sRGB PNG of the beauty.
    #[arg(long)]
    preview: Option<PathBuf>,
    /// Sample sequence: sobol (Owen-scrambled, default) or independent.
    #[arg(long)]
    sampler: Option<String>,
    /// MIS heuristic: balance, power[:β] (default power:2), maximum, cutoff[:α], nee-only,
    /// bsdf-only.
    #[arg(long)]
    mis: Option<String>,
    /// Russian roulette: off, fixed:P, throughput[:THRESHOLD] (default throughput:0.1),
    /// efficiency[:MAX_SPLIT] (learned roulette, and splitting up to MAX_SPLIT, default 1).
    #[arg(long)]
    rr: Option<String>,
    /// Maximum number of bounces (1 = direct light only), or `unlimited` (default).
    #[arg(long)]
    max_depth: Option<String>,
    /// Light selection for light sampling: uniform, power (default), contribution.
    #[arg(long)]
    light_select: Option<String>,
    /// Measure area lights are sampled in: auto (default: spheres in the cone they subtend,
    /// other shapes by area), area, or solid-angle (spherical triangles too).
    #[arg(long)]
    light_sampling: Option<String>,
    /// Shadow rays and BSDF samples at the first hit, e.g. nee=4,bsdf=1 (default 1 and 1),
    /// or auto (learned from the first samples of every pixel).
    #[arg(long)]
    split: Option<String>,
    /// Pixel filter: box, blackman-harris (width 1.5, default) or blackman-harris:WIDTH.
    #[arg(long)]
    filter: Option<String>,
    /// Adaptive sampling: the relative noise (square root of the predicted relMSE) at which
    /// sampling stops, e.g. 0.02. Pixels get samples where they lower the error most per
    /// ray; `--spp` caps a pixel (default 65536) and `--time` the whole render.
    #[arg(long)]
    noise_threshold: Option<String>,
    /// Samples every pixel takes before adaptive sampling decides (default 16).
    #[arg(long)]
    min_spp: Option<String>,
    /// A light group: NAME=PATTERN[,PATTERN...] (repeatable; `*` and `?` wildcards) over the
    /// names of the emitters (instances, shapes, lights, `environment`); with `--aov
    /// lightgroups` each group gets an `lg_NAME` layer, the rest `lg_default`.
    #[arg(long = "light-group")]
    light_group: Vec<String>,
    /// Render only pixels X0..X1 × Y0..Y1 of the image, e.g. 0,0,320,240 (ends excluded);
    /// the EXR's data window is the crop, its display window the whole image.
    #[arg(long)]
    crop: Option<String>,
    /// Take pass K of N (e.g. 2/4): the K-th of N disjoint ranges of every pixel's samples
    /// (needs --spp); `lucerna merge` of the N passes is the render with all the samples.
    #[arg(long)]
    pass: Option<String>,
    /// Continue the render in the output file (a checkpoint written on SIGINT or SIGTERM,
    /// or a finished render, to take more samples); without the file, start afresh.
    #[arg(long)]
    resume: bool,
    /// auto (default): the integrator leaves out what the scene and the AOVs do not use,
    /// and runs eight paths at a time in SIMD lanes (AVX2) where that pays; packet, scalar:
    /// the same with the packet kernel wherever it can run, or never; general: every
    /// feature on (for benchmarks and comparisons).
    #[arg(long)]
    plan: Option<String>,
    /// Largest memory the render may need, e.g. 8G or 512M (binary units), or `off`; a scene
    /// estimated to need more fails before loading into the renderer (default: 80 % of the
    /// physical memory or of the cgroup's limit).
    #[arg(long, value_parser = lucerna::memory::parse_limit)]
    max_memory: Option<u64>,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
}

impl RenderArgs {
    /// The render options: defaults, then the settings file, then the flags.
    fn options(&self) -> Result<RenderOptions> {
        use std::io::IsTerminal;
        let terminal = std::io::stderr().is_terminal();
        let mode = self.progress.as_deref().unwrap_or("auto");
        let lines = |alfred| {
            Some(render::ProgressLines {
                interval: std::time::Duration::from_secs_f64(self.progress_interval),
                alfred,
            })
        };
        let mut options = RenderOptions {
            progress: !self.quiet && matches!(mode, "auto" | "bar"),
            progress_lines: match mode {
                "lines" => lines(false),
                "alfred" => lines(true),
                "auto" if !terminal => lines(false),
                _ => None,
            },
            ..RenderOptions::command_line()
        };
        if let Some(path) = &self.settings {
            let text = lucerna::files::read_input(path)
                .and_then(|b| String::from_utf8(b).map_err(|_| "not UTF-8 text".to_string()))
                .map_err(|e| Error::bad_input(path, "file", e))?;
            options
                .load_settings(&text)
                .map_err(|e| Error::bad_input(path, "settings", e))?;
        }
        let flags = [
            ("spp", &self.spp),
            ("time", &self.time),
            ("aov", &self.aov),
            ("seed", &self.seed),
            ("sampler", &self.sampler),
            ("mis", &self.mis),
            ("rr", &self.rr),
            ("max-depth", &self.max_depth),
            ("light-select", &self.light_select),
            ("light-sampling", &self.light_sampling),
            ("split", &self.split),
            ("filter", &self.filter),
            ("noise-threshold", &self.noise_threshold),
            ("min-spp", &self.min_spp),
            ("plan", &self.plan),
            ("crop", &self.crop),
            ("pass", &self.pass),
        ];
        let light_groups = (!self.light_group.is_empty()).then(|| self.light_group.join(";"));
        for (name, value) in flags.into_iter().chain([("light-groups", &light_groups)]) {
            if let Some(v) = value {
                options
                    .set(name, v)
                    .map_err(|e| Error::bad_input("", format!("--{name}"), e))?;
            }
        }
        options
            .settings
            .validate()
            .map_err(|e| Error::bad_input("", "settings", e))?;
        options
            .validate()
            .map_err(|e| Error::bad_input("", "settings", e))?;
        Ok(options)
    }
}

fn parse_interval(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && (0.05..=86_400.0).contains(&v) => Ok(v),
        _ => Err(format!(
            "{s:?} is not a number of seconds from 0.05 to 86400"
        )),
    }
}

fn parse_fps(s: &str) -> std::result::Result<f64, String> {
    s.parse::<f64>()
        .ok()
        .filter(|f| f.is_finite() && *f > 0.0)
        .ok_or_else(|| format!("frames per second must be a positive number, got {s:?}"))
}

fn parse_frame(s: &str) -> std::result::Result<f64, String> {
    s.parse::<f64>()
        .ok()
        .filter(|f| f.is_finite() && f.abs() < 1e9)
        .ok_or_else(|| format!("a frame is a finite number, got {s:?}"))
}

fn parse_timeout(s: &str) -> std::result::Result<f64, String> {
    s.parse::<f64>()
        .ok()
        .filter(|t| t.is_finite() && *t > 0.0 && *t < 1e7)
        .ok_or_else(|| format!("a timeout is a positive number of seconds, got {s:?}"))
}

fn parse_resolution(s: &str) -> std::result::Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or("expected WIDTHxHEIGHT, e.g. 640x480")?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=lucerna::camera::MAX_IMAGE_SIDE).contains(v))
    };
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err("width and height must be integers in 1..=65536".into()),
    }
}
fn parse_rgb(s: &str) -> std::result::Result<Vec3, String> {
    let values: Vec<f32> = s
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f32>()
                .map_err(|_| format!("{v:?} is not a number"))
        })
        .collect::<std::result::Result<_, _>>()?;
    let c = match values[..] {
        [g] => Vec3::splat(g),
        [r, g, b] => Vec3::new(r, g, b),
        _ => return Err("expected one value or R,G,B".into()),
    };
    // Radiance beyond 1e18 leaves no headroom for f32 sums over samples and pixels.
    if c.is_finite() && c.min_element() >= 0.0 && c.max_element() <= 1e18 {
        Ok(c)
    } else {
        Err("values must be finite, non-negative and at most 1e18".into())
    }
}

fn load_scene(path: Option<&Path>, load: &ingest::LoadOptions) -> Result<Scene> {
    let scene = match path {
        Some(p) => ingest::load(p, load)?,
        None => ingest::default_scene()?,
    };
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}
fn thread_pool(threads: Option<u32>) -> Result<rayon::ThreadPool> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        builder = builder.num_threads(n as usize);
    }
    builder
        .build()
        .map_err(|e| Error::other("", "threads", e.to_string()))
}

/// 128 + the signal that stopped the process, as shells report it.
fn interrupted_exit_code() -> u8 {
    (128 + lucerna::interrupt::received().clamp(1, 127)) as u8
}

/// Most light groups a render writes layers for.
const MAX_LIGHT_GROUPS: usize = 64;

/// What a checkpoint being resumed already holds.
struct Resumed {
    planes: film::exr::Planes,
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
        eprintln!(
            "lucerna: {} does not exist yet; rendering from the start",
            path.display()
        );
        return Ok(None);
    }
    let (planes, header) = film::exr::read(path)?;
    let bad = |element: &str, reason: String| Error::bad_input(path, element, reason);
    if header.number("lucerna/samples") == Some(0.0) {
        eprintln!(
            "lucerna: {} holds no samples; rendering from the start",
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

fn render_command(args: RenderArgs) -> Result<ExitCode> {
    let mut options = args.options()?;
    options.interrupt = Some(lucerna::interrupt::install()?);
    if args.resume && options.decides_from_whole_image() {
        return Err(Error::bad_input(
            "",
            "--resume",
            "adaptive sampling, rr = efficiency and split = auto keep state an EXR does not hold; they cannot be resumed",
        ));
    }
    let pool = thread_pool(args.threads)?;
    let frames = match &args.frames {
        Some(FrameList(frames)) => {
            if frames.len() > 1
                && args
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
            frames.iter().map(|&f| Some(f)).collect()
        }
        None => vec![args.load.frame],
    };
    let several = frames.len() > 1;
    for frame in frames {
        if let Some(code) = render_frame(&args, &options, &pool, frame, several)? {
            return Ok(ExitCode::from(code));
        }
    }
    Ok(ExitCode::SUCCESS)
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

/// Renders one frame; `Some(exit code)` if a signal stopped it (its checkpoint written).
fn render_frame(
    args: &RenderArgs,
    options: &RenderOptions,
    pool: &rayon::ThreadPool,
    frame: Option<f64>,
    several_frames: bool,
) -> Result<Option<u8>> {
    let load = ingest::LoadOptions {
        frame,
        ..args.load.options()
    };
    let mut scene = load_scene(args.scene.as_deref(), &load)?;
    let stem = args
        .scene
        .as_deref()
        .and_then(Path::file_stem)
        .map_or("default".into(), |s| s.to_string_lossy().into_owned());
    let settings = scene.render_settings.take().unwrap_or_default();
    let views = match &args.output {
        None if !settings.products.is_empty() => declared_views(args, options, &settings)?,
        _ => {
            let pattern = args.output.clone().unwrap_or_else(|| "render.exr".into());
            if several_frames && !pattern.to_string_lossy().contains("{frame}") {
                return Err(Error::bad_input(
                    "",
                    "--output",
                    "several frames need {frame} in the output name",
                ));
            }
            // The settings' camera, size and window apply where the command line gives none.
            let camera = args.camera.clone().or(settings.camera.clone());
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
            if let (None, None, Some(crop)) = (options.crop, args.resolution, settings.crop) {
                view_options.crop = Some(pixel_window(crop));
            }
            vec![View {
                camera,
                resolution: args.resolution.or(settings.resolution.map(|[w, h]| (w, h))),
                options: view_options,
                outputs: vec![ViewOutput { path, aovs: None }],
            }]
        }
    };
    // Every output is checked (and its directory made) before rendering, so an impossible
    // output fails at once.
    for output in views.iter().flat_map(|v| &v.outputs) {
        lucerna::files::check_output(&output.path, "--output")?;
    }
    let preview = args
        .preview
        .as_ref()
        .map(|p| {
            let camera = views[0].camera.clone().unwrap_or_else(|| "default".into());
            output_path(p, frame, &stem, &camera)
        })
        .transpose()
        .map_err(|e| Error::bad_input("", "--preview", e))?;
    if let Some(png) = &preview {
        lucerna::files::check_output(png, "--preview")?;
    }
    let count = views.len();
    for (i, view) in views.into_iter().enumerate() {
        let scene = if i + 1 == count {
            std::mem::take(&mut scene)
        } else {
            scene.clone()
        };
        let preview = if i == 0 { preview.as_deref() } else { None };
        if let Some(code) = render_view(args, &view, pool, frame, scene, preview)? {
            return Ok(Some(code));
        }
    }
    Ok(None)
}

/// The views of a scene's declared render products: products that share camera, size and
/// data window are rendered once, with the union of their AOVs, and each file gets its own
/// layers. Command-line `--camera`, `--resolution`, `--crop` and `--aov` apply to all.
fn declared_views(
    args: &RenderArgs,
    options: &RenderOptions,
    settings: &lucerna::scene::RenderSettings,
) -> Result<Vec<View>> {
    // Products that agree on camera, resolution and pixel window share a render; each
    // group keeps its products' AOV lists, whose union the render takes.
    type Shared = (Option<String>, Option<(u32, u32)>, Option<[u32; 4]>);
    let mut groups: Vec<(Shared, View, Vec<&str>)> = Vec::new();
    for (i, product) in settings.products.iter().enumerate() {
        let element = format!("{}: product {i}", settings.path);
        let camera = args.camera.clone().or_else(|| product.camera.clone());
        let resolution = args.resolution.or(product.resolution.map(|[w, h]| (w, h)));
        // A declared window is in the declared resolution's pixels.
        let crop = if options.crop.is_some() || args.resolution.is_some() {
            None
        } else {
            product.crop
        };
        let own = if args.aov.is_some() {
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
        if args.aov.is_none() {
            view.options.aovs = AovSet::parse(&aovs.join(","))
                .map_err(|e| Error::bad_input("", settings.path.as_str(), e))?;
        }
        views.push(view);
    }
    if args.resume && views.iter().any(|v| v.outputs.len() > 1) {
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
fn pixel_window([x0, y0, x1, y1]: [u32; 4]) -> lucerna::film::Window {
    lucerna::film::Window {
        x: x0,
        y: y0,
        width: x1 - x0,
        height: y1 - y0,
    }
}

/// Renders `scene` as `view` says and writes its files; `Some(exit code)` if a signal
/// stopped it (its checkpoint written).
fn render_view(
    args: &RenderArgs,
    view: &View,
    pool: &rayon::ThreadPool,
    frame: Option<f64>,
    mut scene: Scene,
    preview: Option<&Path>,
) -> Result<Option<u8>> {
    let options = &view.options;
    let output = view.outputs[0].path.clone();
    if let Some(radiance) = args.env {
        ingest::set_constant_environment(&mut scene, radiance);
    }
    if let Some(path) = &args.env_map {
        ingest::set_environment_map(&mut scene, path, args.env_scale)?;
    }
    if !scene.has_light() {
        if args.no_default_light {
            eprintln!(
                "lucerna: warning: {}: the scene has no light: it renders black",
                scene.source
            );
        } else {
            eprintln!(
                "lucerna: warning: {}: the scene has no light: it is lit by a constant white environment (--env R,G,B or --env-map to choose one, --no-default-light to render it black)",
                scene.source
            );
            ingest::set_constant_environment(&mut scene, Vec3::ONE);
        }
    }
    if let Some(lossy) = args.exr_compression.filter(|&c| film::exr::is_lossy(c))
        && let Some(data) = options.aovs.iter().find(|a| !a.is_light())
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
    // Subdivision surfaces are refined for this view before the memory estimate counts them.
    scene.subdivision_level = args.subdiv_level;
    lucerna::world::refine_subdivision_surfaces(
        &mut scene,
        view.camera.as_deref(),
        view.resolution,
    )?;
    if options.plan != PlanMode::General {
        plan::strip_unused_attributes(&mut scene);
    }
    let limit = args.max_memory.or_else(memory::default_limit);
    memory_estimate(&scene, view.camera.as_deref(), view.resolution, options)
        .check(limit, &scene.source)?;
    let source = scene.source.clone();
    let identity = ingest::scene_identity(args.scene.as_deref());
    let build_start = std::time::Instant::now();
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
    film::exr::check_names(
        film::exr::channel_names(&film, &[Aov::Spp])
            .iter()
            .map(|n| n.as_str()),
    )
    .map_err(|reason| Error::bad_input(&source, "light groups", reason))?;
    let resumed = if args.resume {
        read_checkpoint(&output, &source, identity.as_ref(), options)?
    } else {
        None
    };
    if let Some(r) = &resumed {
        film.restore(&r.planes, r.discarded)
            .map_err(|e| Error::bad_input(&output, "checkpoint", e))?;
        eprintln!(
            "lucerna: continuing {} from {} samples per pixel",
            output.display(),
            film.min_samples()
        );
    }
    // From here a first signal stops sampling and the checkpoint is written; before, it ends
    // the process (src/interrupt.rs).
    let _sampling = lucerna::interrupt::defer();
    let (film, mut stats) = pool.install(|| render::render_into(&world, options, film));
    if stats.interrupted && film.total_samples() == 0 {
        eprintln!(
            "lucerna: interrupted (signal {}) before the first sample; nothing written",
            lucerna::interrupt::received()
        );
        return Ok(Some(interrupted_exit_code()));
    }
    stats.seconds += resumed.as_ref().map_or(0.0, |r| r.seconds);

    // glam's column-major listing of a column-vector matrix is the row-major listing of
    // its transpose: exactly Imath's row-vector convention.
    let imath = |m: glam::DMat4| m.as_mat4().to_cols_array();
    let mut header = Header {
        storage: film::exr::Storage {
            compression: args
                .exr_compression
                .unwrap_or(film::exr::Storage::default().compression),
            half_light_layers: args.exr_half,
        },
        frames_per_second: frame.map(|_| args.load.fps),
        world_to_camera: Some(imath(world.camera.world_to_camera)),
        world_to_ndc: Some(imath(world.camera.world_to_ndc)),
        attributes: vec![
            (
                "lucerna/renderer".into(),
                Attribute::Text(lucerna::RENDERER.into()),
            ),
            ("lucerna/scene".into(), Attribute::Text(source.clone())),
            (
                "lucerna/settings".into(),
                Attribute::Text(options.to_toml(stats.spp)),
            ),
            (
                "lucerna/seed".into(),
                Attribute::Int(options.settings.seed as i32),
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
    if let Some((canonical, fingerprint)) = identity {
        header.set("lucerna/scene_path", Attribute::Text(canonical));
        header.set("lucerna/scene_fingerprint", Attribute::Text(fingerprint));
    }
    if let Some(f) = frame {
        header.set("lucerna/frame", Attribute::Double(f));
    }
    if let Some(split) = stats.learned_split {
        header.set("lucerna/split_learned", Attribute::Text(split.describe()));
    }
    if film.aovs.wants_crypto() {
        use lucerna::film::crypto::{Kind, header_attributes};
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
    // Whatever can be continued or merged carries its per-pixel sample counts.
    let extra: &[Aov] = if stats.interrupted || options.pass.is_some() {
        &[Aov::Spp]
    } else {
        &[]
    };
    for out in &view.outputs {
        match &out.aovs {
            None => film::exr::write(&out.path, &film, &header, extra)?,
            Some(own) => film::exr::write_layers(&out.path, &film, &header, extra, |aov| {
                own.contains(aov) || (matches!(aov, Aov::LightGroup(_)) && own.wants_light_groups())
            })?,
        }
    }
    if let Some(pattern) = &args.stats_json {
        let stem = args
            .scene
            .as_deref()
            .and_then(Path::file_stem)
            .map_or("default".into(), |s| s.to_string_lossy().into_owned());
        let path = output_path(pattern, frame, &stem, "")
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
        });
        film::write_atomically(&path, |w| {
            use std::io::Write;
            serde_json::to_writer_pretty(&mut *w, &json)
                .map_err(|e| Error::other(&path, "write", e.to_string()))?;
            w.write_all(b"\n")
                .map_err(|e| Error::other(&path, "write", e.to_string()))
        })?;
    }
    if stats.interrupted {
        eprintln!(
            "lucerna: interrupted (signal {}): wrote the {} samples taken so far to {}; continue with --resume",
            lucerna::interrupt::received(),
            stats.samples,
            output.display()
        );
        return Ok(Some(interrupted_exit_code()));
    }
    if let Some(png) = preview {
        film::preview::write(png, &film)?;
    }
    let peak = render::peak_memory_bytes().map_or(String::new(), |b| {
        format!(", peak memory {:.1} MB", b as f64 / 1e6)
    });
    let written: Vec<String> = view
        .outputs
        .iter()
        .map(|o| o.path.display().to_string())
        .collect();
    eprintln!(
        "lucerna: wrote {} ({}x{}, {} threads): scene prepared in {:.2} s ({} primitives{}, BVH built in {:.2} s); rendered in {}{peak}",
        written.join(", "),
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
    Ok(None)
}

fn batch_command(job: &Path, logs: Option<PathBuf>, summary: Option<PathBuf>) -> Result<ExitCode> {
    let beside = |suffix: &str| job.with_extension(suffix);
    let logs = logs.unwrap_or_else(|| beside("logs"));
    let summary_path = summary.unwrap_or_else(|| beside("summary.json"));
    let tasks = lucerna::batch::plan(job, &logs)?;
    let stop = lucerna::interrupt::install()?;
    // The children take their own signals; the batch forwards them and waits.
    let _forwarding = lucerna::interrupt::defer();
    let exe = std::env::current_exe().map_err(|e| Error::other("", "batch", e.to_string()))?;
    let summary = lucerna::batch::run(job, &exe, &tasks, &stop);
    let json = serde_json::to_string_pretty(&summary).expect("the summary serialises");
    film::write_atomically(&summary_path, |w| {
        use std::io::Write;
        w.write_all(json.as_bytes())
            .map_err(|e| Error::other(&summary_path, "summary", e.to_string()))
    })?;
    eprintln!(
        "lucerna: batch {}: {} rendered, {} skipped (complete), {} failed{}; summary {}",
        job.display(),
        summary.rendered,
        summary.skipped,
        summary.failed,
        if summary.interrupted {
            ", interrupted"
        } else {
            ""
        },
        summary_path.display()
    );
    Ok(if summary.interrupted {
        ExitCode::from(interrupted_exit_code())
    } else if summary.failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}

fn merge_command(inputs: &[PathBuf], output: &Path) -> Result<ExitCode> {
    // A signal ends the merge at once, removing its temporary output.
    lucerna::interrupt::install()?;
    lucerna::files::check_output(output, "--output")?;
    let parts = inputs
        .iter()
        .map(|path| {
            let (planes, header) = film::exr::read(path)?;
            Ok(lucerna::merge::Part {
                path: path.clone(),
                planes,
                header,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let (planes, header) = lucerna::merge::merge(&parts)?;
    let (window, display) = (planes.window, planes.display);
    film::exr::write_planes(output, planes, &header)?;
    eprintln!(
        "lucerna: merged {} parts into {} (pixels {} of {}x{})",
        parts.len(),
        output.display(),
        window.describe(),
        display.0,
        display.1
    );
    Ok(ExitCode::SUCCESS)
}

/// What rendering `scene` through `camera` at `resolution` with `aovs` will need.
fn memory_estimate(
    scene: &Scene,
    camera: Option<&str>,
    resolution: Option<(u32, u32)>,
    options: &RenderOptions,
) -> memory::MemoryEstimate {
    let camera = camera
        .and_then(|name| scene.camera(name))
        .or(scene.cameras.first());
    let (width, height) = lucerna::camera::resolve_resolution(resolution, camera);
    memory::MemoryEstimate {
        film: film::Film::estimated_bytes(
            width,
            height,
            &options.aovs,
            options.noise_threshold.is_some(),
        ),
        ..lucerna::world::estimate_memory(scene)
    }
}

fn convert_command(path: &Path, output: &Path, load: &LoadArgs) -> Result<ExitCode> {
    // A signal ends the conversion at once, stopping the USD plugin (src/interrupt.rs).
    lucerna::interrupt::install()?;
    let scene = load_scene(Some(path), &load.options())?;
    lucerna::scene::file::write(&scene, output)?;
    eprintln!(
        "lucerna: wrote {} ({} meshes, {} materials, {} textures)",
        output.display(),
        scene.meshes.len(),
        scene.materials.len(),
        scene.textures.len()
    );
    Ok(ExitCode::SUCCESS)
}

fn inspect_command(
    path: &Path,
    load: &LoadArgs,
    aov: Option<&str>,
    plan_mode: Option<&str>,
) -> Result<ExitCode> {
    lucerna::interrupt::install()?;
    let mut options = RenderOptions::default();
    for (name, value) in [("aov", aov), ("plan", plan_mode)] {
        if let Some(v) = value {
            options
                .set(name, v)
                .map_err(|e| Error::bad_input("", format!("--{name}"), e))?;
        }
    }
    let mut scene = load_scene(Some(path), &load.options())?;
    if options.plan != PlanMode::General {
        plan::strip_unused_attributes(&mut scene);
    }
    let triangles: usize = scene.meshes.iter().map(|m| m.triangles.len()).sum();
    let vertices: usize = scene.meshes.iter().map(|m| m.positions.len()).sum();
    println!("scene: {}", scene.source);
    println!(
        "  geometry: {} meshes, {} instances, {} triangles ({} instanced), {} vertices",
        scene.meshes.len(),
        scene.instances.len(),
        triangles,
        scene.instanced_triangle_count(),
        vertices
    );
    if !(scene.spheres.is_empty() && scene.disks.is_empty() && scene.cylinders.is_empty()) {
        println!(
            "  analytic shapes: {} spheres, {} disks, {} cylinders",
            scene.spheres.len(),
            scene.disks.len(),
            scene.cylinders.len()
        );
    }
    if let Some((lo, hi)) = scene.bounds() {
        println!(
            "  bounds: [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}]",
            lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
        );
    }
    let mut models: Vec<&str> = scene.materials.iter().map(|m| m.model.name()).collect();
    models.sort();
    models.dedup();
    let count = |f: &dyn Fn(&lucerna::scene::Material) -> bool| {
        scene.materials.iter().filter(|m| f(m)).count()
    };
    println!(
        "  materials: {} ({}); {} emissive, {} normal-mapped, {} with alpha, {} double-sided",
        scene.materials.len(),
        models.join(", "),
        count(&|m| m.is_emissive()),
        count(&|m| m.normal_texture.is_some()),
        count(&|m| m.alpha_mode != lucerna::scene::AlphaMode::Opaque),
        count(&|m| m.double_sided),
    );
    let texel_bytes: usize = scene.textures.iter().map(|t| t.memory_bytes()).sum();
    println!(
        "  textures: {} ({} bytes of texels)",
        scene.textures.len(),
        texel_bytes
    );
    let emissive_triangles: usize = scene
        .instances
        .iter()
        .map(|i| &scene.meshes[i.mesh as usize])
        .filter(|m| scene.materials[m.material as usize].is_emissive())
        .map(|m| m.triangles.len())
        .sum();
    let kinds = |f: fn(&LightKind) -> bool| scene.lights.iter().filter(|l| f(&l.kind)).count();
    println!(
        "  lights: {} emissive triangles, {} point, {} spot, {} directional, environment: {}",
        emissive_triangles,
        kinds(|k| matches!(k, LightKind::Point { .. })),
        kinds(|k| matches!(k, LightKind::Spot { .. })),
        kinds(|k| matches!(k, LightKind::Directional { .. })),
        if scene.environment.is_some() {
            "yes"
        } else {
            "no"
        }
    );
    let names: Vec<&str> = scene.cameras.iter().map(|c| c.name.as_str()).collect();
    println!(
        "  cameras: {}",
        if names.is_empty() {
            "none (one framing the scene is used)".to_string()
        } else {
            names.join(", ")
        }
    );
    let estimate = memory_estimate(&scene, None, None, &options);
    println!(
        "  memory (default resolution, AOVs {}): about {} ({estimate})",
        options.aovs.describe(),
        memory::Bytes(estimate.total())
    );
    let plan = RenderPlan::new(
        &SceneFeatures::of(&scene),
        &options.aovs,
        options.plan,
        false,
        matches!(
            options.settings.rr,
            lucerna::integrator::RussianRoulette::Efficiency(_)
        ),
    );
    println!("{plan}");
    Ok(ExitCode::SUCCESS)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    lucerna::memory::set_process_limit(match &cli.command {
        Command::Render(args) => args.max_memory.or_else(lucerna::memory::default_limit),
        _ => lucerna::memory::default_limit(),
    });
    let result = match cli.command {
        Command::Render(args) => render_command(*args),
        Command::Inspect {
            scene,
            load,
            aov,
            plan,
        } => inspect_command(&scene, &load, aov.as_deref(), plan.as_deref()),
        Command::Convert {
            scene,
            output,
            load,
        } => convert_command(&scene, &output, &load),
        Command::Merge { inputs, output } => merge_command(&inputs, &output),
        Command::Batch { job, logs, summary } => batch_command(&job, logs, summary),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}
