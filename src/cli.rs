//! The `lucerna` command line: parses the arguments and calls the library (src/job/ for
//! `render`, src/commands.rs for the others). The binary (src/main.rs) and the Python
//! package's `lucerna` command both run [`main_with`].
//!
//! Every `render` flag is also a settings-file key (the flag without `--`): the arguments
//! given on the command line are handed to [`crate::job::RenderJob::set`] one by one,
//! after the settings file, so both take one path and the command line wins.

use crate::error::{Error, Result};
use crate::job::RenderJob;
use clap::parser::ValueSource;
use clap::{ArgMatches, CommandFactory, FromArgMatches, Parser, Subcommand};
use std::ffi::OsString;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "lucerna",
    version,
    about = "A physically based path tracer: glTF and USD scenes to multi-layer EXR",
    after_help = "Run `lucerna render --help` for the render options. Environment: \
                  LUCERNA_PYTHON (the Python that runs the USD plugin), LUCERNA_OIDN (the \
                  Open Image Denoise library), LUCERNA_HOME (where `lucerna setup` installs)."
)]
struct Cli {
    /// How much lucerna says on stderr: error, warn, info or debug (progress lines follow
    /// --progress instead). [default: info]
    #[arg(long, global = true, value_name = "LEVEL", value_parser = crate::logging::parse_level)]
    log_level: Option<log::LevelFilter>,
    /// Start every message with its UTC time (RFC 3339), as farm logs want.
    #[arg(long, global = true)]
    log_timestamps: bool,
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
        /// AOVs of the request the plan is made for (as `render --aov`). [default: all]
        #[arg(long)]
        aov: Option<String>,
        /// auto, packet, scalar or general, as `render --plan`. [default: auto]
        #[arg(long)]
        plan: Option<String>,
        /// The memory limit the render would have, as `render --max-memory` (it decides the
        /// texture memory). [default: 80 % of the physical memory or of the cgroup's limit]
        #[arg(long)]
        max_memory: Option<String>,
        /// As `render --texture-memory`: textures that need more are shown read through a
        /// tile cache of this size. [default: half of --max-memory]
        #[arg(long)]
        texture_memory: Option<String>,
    },
    /// Run a job file's renders unattended: a child process and a log per frame, complete
    /// outputs skipped, checkpoints resumed, a JSON summary; exits 1 if any frame failed.
    Batch {
        /// The job (TOML: [settings] for all, then [[render]] entries; see the README).
        job: PathBuf,
        /// Directory of the per-frame logs. [default: JOB's name with `.logs`]
        #[arg(long)]
        logs: Option<PathBuf>,
        /// The JSON summary to write. [default: JOB's name with `.summary.json`]
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
    /// Add a `denoised` layer to a render (Open Image Denoise, guided by its albedo and
    /// normal layers): for renders merged from passes or tiles, denoised whole.
    Denoise {
        /// The EXR (with albedo and normal layers: render with --denoise or --aov
        /// albedo,normal).
        input: PathBuf,
        /// Where to write the result. [default: replace INPUT]
        #[arg(short, long)]
        output: Option<PathBuf>,
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
    /// Make lucerna's Python environment for USD stages (usd-core) and --denoise (Open
    /// Image Denoise), with pip. Needs python3 with venv and network access to PyPI.
    Setup {
        /// Where to make it. [default: $LUCERNA_HOME/venv, else ~/.local/share/lucerna/venv]
        #[arg(long)]
        venv: Option<PathBuf>,
        /// Leave out Open Image Denoise (pyoidn, about 90 MB).
        #[arg(long)]
        no_denoiser: bool,
    },
    /// Print a shell completion script: `lucerna completions bash > /etc/bash_completion.d/lucerna`.
    Completions {
        /// bash, zsh, fish, elvish or powershell.
        shell: clap_complete::Shell,
    },
    /// Write lucerna's man pages (lucerna.1, lucerna-render.1, ...) into DIR.
    Man {
        /// The folder to write them to, e.g. /usr/local/share/man/man1.
        dir: PathBuf,
    },
}

/// How to read the scene.
#[derive(clap::Args)]
#[command(next_help_heading = "Scene input")]
struct LoadArgs {
    /// Frame of an animated scene: a USD time code; in glTF the time FRAME / fps seconds.
    /// [default: the stage's start time code; glTF: the nodes' rest transforms]
    #[arg(long)]
    frame: Option<String>,
    /// Frames per second of glTF animations. [default: 24]
    #[arg(long)]
    fps: Option<String>,
    /// The shutter, OPEN,CLOSE in frames relative to the frame (-0.25,0.25: a 180-degree
    /// shutter): what moves while it is open is blurred. glTF animations are sampled over
    /// it (frame 0 without --frame). [default: closed: no motion blur]
    #[arg(long, allow_hyphen_values = true)]
    shutter: Option<String>,
    /// Render the frame's instant, not the blur over the shutter: what moves keeps its
    /// motion for the motion and velocity layers (Nuke's VectorBlur).
    #[arg(long)]
    no_motion_blur: bool,
    /// Skip usd-core's validators (USD stages; faster on large stages).
    #[arg(long, conflicts_with = "strict")]
    no_validate: bool,
    /// Refuse a USD stage on any validator error (default: findings are warnings, as in
    /// husk and usdview).
    #[arg(long)]
    strict: bool,
    /// Select variant NAME of variant set SET in every prim that has it
    /// (`/PRIM:SET=NAME`: in that prim); repeatable. USD stages. [default: the authored
    /// selections]
    #[arg(long, value_name = "SET=NAME")]
    variant: Vec<String>,
    /// Purposes rendered besides `default`, comma-separated: render, proxy, guide. USD
    /// stages. [default: render]
    #[arg(long)]
    purpose: Option<String>,
    /// Do not load a USD stage's payloads.
    #[arg(long)]
    no_payloads: bool,
    /// The USD RenderSettings prim whose camera, resolution, data window and products the
    /// render follows. [default: the stage's renderSettingsPrimPath, else its first
    /// RenderSettings prim]
    #[arg(long, value_name = "PRIM")]
    render_settings: Option<String>,
    /// Render glTF KHR_materials_variants variant NAME. [default: the default materials]
    #[arg(long, value_name = "NAME")]
    material_variant: Option<String>,
    /// The glTF animation that plays at --frame, by name or index (a character's walk, run,
    /// ...). [default: the file's animations; of clips that animate the same nodes, the
    /// first]
    #[arg(long, value_name = "NAME")]
    animation: Option<String>,
    /// Seconds the USD plugin may take to convert a stage before it is stopped.
    /// [default: 1800]
    #[arg(long, value_name = "SECONDS")]
    usd_timeout: Option<String>,
}

/// `lucerna render`. Every option is also a settings-file key; all are read through
/// [`RenderJob::set`] (see [`job_from`]), so the fields are only the help text.
#[derive(clap::Args)]
#[allow(dead_code)]
struct RenderArgs {
    /// A .gltf, .glb, .usd, .usda, .usdc, .usdz or .lucerna scene file. [default: the
    /// embedded Cornell box]
    scene: Option<PathBuf>,
    #[command(flatten)]
    load: LoadArgs,

    /// Output EXR file; the frame tokens `{frame}` (four digits), `####` (as many digits as
    /// `#`), `%04d`, `$F4` and `<F4>`, and `{scene}` (the file's stem) and `{camera}` are
    /// replaced, e.g. `out/{scene}.{camera}.####.exr`. [default: the render products a USD
    /// stage declares, else render.exr]
    #[arg(short, long, help_heading = "Output")]
    output: Option<PathBuf>,
    /// Frames to render, e.g. 1-24, 1-24x2 (every second), 1,5,10-12; the output needs a
    /// frame token (`{frame}`, `####`, ...). [default: one frame, --frame]
    #[arg(long, conflicts_with = "frame", help_heading = "Output")]
    frames: Option<String>,
    /// AOV layers to write besides the beauty, comma-separated (e.g.
    /// `direct,indirect,albedo`), or presets: `comp` (what a compositor usually wants:
    /// emission, the lobe layers and colours, light groups, albedo, normal, depth,
    /// position, Cryptomatte), `all`, `lobes`, `lightgroups`, `crypto`; per-depth layers
    /// `nee_dK`, `bsdf_dK`. [default: beauty]
    #[arg(long, help_heading = "Output")]
    aov: Option<String>,
    /// Image size, e.g. 640x480. [default: the camera's aspect ratio, long side 512]
    #[arg(long, value_name = "WxH", help_heading = "Output")]
    resolution: Option<String>,
    /// Camera to render through. [default: the scene's first camera]
    #[arg(long, help_heading = "Output")]
    camera: Option<String>,
    /// Render only pixels X0..X1 x Y0..Y1 of the image, e.g. 0,0,320,240 (ends excluded);
    /// the EXR's data window is the crop, its display window the whole image. [default: the
    /// whole image]
    #[arg(long, help_heading = "Output")]
    crop: Option<String>,
    /// Also render PIXELS beyond every edge of the image (or LEFT,TOP,RIGHT,BOTTOM), the
    /// view of the image itself unchanged: the EXR's data window reaches past its display
    /// window (for lens distortion, shake and blur in the composite). USD: a product's
    /// dataWindowNDC beyond 0..1. [default: none]
    #[arg(long, value_name = "PIXELS", help_heading = "Output")]
    overscan: Option<String>,
    /// Store the light layers (beauty, light and lobe layers, light groups, denoised) as
    /// 16-bit half floats; data layers, Cryptomatte, sample counts and variance stay 32-bit.
    #[arg(long, help_heading = "Output")]
    exr_half: bool,
    /// Also write the data layers under the names Karma, RenderMan and Nuke's tools expect:
    /// `N.X N.Y N.Z` (the normal), `P.X P.Y P.Z` (the position) and `Z` (the depth),
    /// alongside lucerna's `normal`, `position` and `depth`.
    #[arg(long, help_heading = "Output")]
    exr_aliases: bool,
    /// EXR compression: none, rle, zips, zip, piz, or lossy pxr24, b44, b44a,
    /// dwaa[:LEVEL], dwab[:LEVEL] (refused with data or Cryptomatte layers). [default: zip]
    #[arg(long, value_name = "NAME", help_heading = "Output")]
    exr_compression: Option<String>,
    /// EXR parts: single (every channel in one part), layer (a part per layer, `rgba` for
    /// the beauty) or group (parts `light`, `data` and `cryptomatte`); channel names are the
    /// same in every split. [default: single]
    #[arg(long, value_name = "SPLIT", help_heading = "Output")]
    exr_parts: Option<String>,
    /// Add a `denoised` layer: Open Image Denoise on the beauty, guided by the albedo and
    /// normal layers (prefiltered), which are written too. Every noisy layer is kept.
    #[arg(long, help_heading = "Output")]
    denoise: bool,
    /// Also write an sRGB PNG of the beauty (denoised with --denoise); frame tokens expand
    /// as in -o. [default: none]
    #[arg(long, value_name = "PNG", help_heading = "Output")]
    preview: Option<PathBuf>,
    /// The preview's exposure in stops. [default: 0]
    #[arg(
        long,
        value_name = "STOPS",
        allow_hyphen_values = true,
        help_heading = "Output"
    )]
    exposure: Option<String>,
    /// The preview's view transform: standard (values clip at 1), agx (highlights roll
    /// off to white, as Blender's AgX) or ocio (a display and view of an OpenColorIO
    /// config, through OpenImageIO: `lucerna setup` installs it). [default: standard]
    #[arg(long, value_name = "NAME", help_heading = "Output")]
    view_transform: Option<String>,
    /// The OCIO config of `--view-transform ocio`: a file or an `ocio://` URI. [default:
    /// $OCIO, else OCIO's built-in default, the ACES 2.0 CG config]
    #[arg(long, value_name = "CONFIG", help_heading = "Output")]
    ocio_config: Option<String>,
    /// The OCIO display. [default: the config's default display]
    #[arg(long, value_name = "NAME", help_heading = "Output")]
    ocio_display: Option<String>,
    /// The OCIO view. [default: the display's default view]
    #[arg(long, value_name = "NAME", help_heading = "Output")]
    ocio_view: Option<String>,
    /// Write the render's figures as JSON to FILE (counts as integers): image size, spp,
    /// samples, rays, NaN/Inf discarded, seconds, samples/s, peak memory, outputs. Frame
    /// tokens expand as in -o. [default: none]
    #[arg(long, value_name = "FILE", help_heading = "Output")]
    stats_json: Option<PathBuf>,

    /// Samples per pixel (with --time or --noise-threshold, the most to take). [default: 64]
    #[arg(long, help_heading = "Sampling")]
    spp: Option<String>,
    /// Time budget in seconds: render passes until it is spent. [default: none]
    #[arg(long, help_heading = "Sampling")]
    time: Option<String>,
    /// Adaptive sampling: the relative noise (square root of the predicted relMSE) at which
    /// sampling stops, e.g. 0.02. Pixels get samples where they lower the error most per
    /// ray; `--spp` caps a pixel and `--time` the whole render. [default: off]
    #[arg(long, help_heading = "Sampling")]
    noise_threshold: Option<String>,
    /// Samples every pixel takes before adaptive sampling decides. [default: 16]
    #[arg(long, help_heading = "Sampling")]
    min_spp: Option<String>,
    /// Random seed. [default: 0]
    #[arg(long, help_heading = "Sampling")]
    seed: Option<String>,
    /// Sample sequence: sobol (Owen-scrambled) or independent. [default: sobol]
    #[arg(long, help_heading = "Sampling")]
    sampler: Option<String>,
    /// Pixel filter: box, blackman-harris or blackman-harris:WIDTH. [default:
    /// blackman-harris, width 1.5]
    #[arg(long, help_heading = "Sampling")]
    filter: Option<String>,
    /// Take pass K of N (e.g. 2/4): the K-th of N disjoint ranges of every pixel's samples
    /// (needs --spp); `lucerna merge` of the N passes is the render with all the samples.
    /// [default: all the samples]
    #[arg(long, help_heading = "Sampling")]
    pass: Option<String>,

    /// MIS heuristic: balance, power[:BETA], maximum, cutoff[:ALPHA], nee-only, bsdf-only.
    /// [default: power:2]
    #[arg(long, help_heading = "Integrator")]
    mis: Option<String>,
    /// Russian roulette: off, fixed:P, throughput[:THRESHOLD], efficiency[:MAX_SPLIT]
    /// (learned roulette, and splitting up to MAX_SPLIT). [default: throughput:0.1]
    #[arg(long, help_heading = "Integrator")]
    rr: Option<String>,
    /// Maximum number of bounces (1 = direct light only), or `unlimited`. [default:
    /// unlimited]
    #[arg(long, help_heading = "Integrator")]
    max_depth: Option<String>,
    /// Light selection for light sampling: uniform, power, contribution (a light BVH), or
    /// learned (the light BVH mixed with what light samples found, occlusion included).
    /// [default: power]
    #[arg(long, help_heading = "Integrator")]
    light_select: Option<String>,
    /// Measure area lights are sampled in: auto (spheres in the cone they subtend, other
    /// shapes by area), area, or solid-angle (spherical triangles too). [default: auto]
    #[arg(long, help_heading = "Integrator")]
    light_sampling: Option<String>,
    /// Path guiding: off, on (directions learned from the first samples and mixed with BSDF
    /// sampling; runs in the scalar kernel), or auto (on where the scalar kernel runs anyway
    /// and the first samples find mostly indirect light). [default: off]
    #[arg(long, help_heading = "Integrator")]
    guiding: Option<String>,
    /// Texture lookups: bilinear (at a point, full resolution) or mip (filtered over the
    /// footprint of each sample's ray cone through MIP maps: no aliasing at few samples,
    /// 10-20 % more time a sample on textured assets). [default: bilinear]
    #[arg(long, help_heading = "Integrator")]
    texture_filter: Option<String>,
    /// Rough microfacet lobes (metals, specular, coats, rough glass): multiscatter (the
    /// energy single scattering loses between facets given back, as Cycles' Multiscatter
    /// GGX) or single (single-scattering GGX: glTF's appendix B, Mitsuba's rough models).
    /// [default: multiscatter]
    #[arg(long, help_heading = "Integrator")]
    microfacet: Option<String>,
    /// Shadow rays and BSDF samples at the first hit, e.g. nee=4,bsdf=1, or auto (learned
    /// from the first samples of every pixel). [default: nee=1,bsdf=1]
    #[arg(long, help_heading = "Integrator")]
    split: Option<String>,
    /// auto: the integrator leaves out what the scene and the AOVs do not use, and runs
    /// eight paths at a time in SIMD lanes (AVX2) where that pays; packet, scalar: the same
    /// with the packet kernel wherever it can run, or never; general: every feature on.
    /// [default: auto]
    #[arg(long, help_heading = "Integrator")]
    plan: Option<String>,

    /// Constant environment radiance, e.g. 0.5,0.6,0.8. [default: the scene's]
    #[arg(
        long,
        value_name = "R,G,B",
        conflicts_with = "env_map",
        help_heading = "Lighting"
    )]
    env: Option<String>,
    /// Lat-long environment map (OpenEXR, Radiance HDR, TIFF, PNG, JPEG or WebP).
    /// [default: the scene's]
    #[arg(long, value_name = "IMAGE", help_heading = "Lighting")]
    env_map: Option<PathBuf>,
    /// Multiplier of the environment map. [default: 1]
    #[arg(long, value_name = "R,G,B", help_heading = "Lighting")]
    env_scale: Option<String>,
    /// Render a scene without any light black (default: a warning, and a constant white
    /// environment of radiance 1, as scene viewers light such scenes).
    #[arg(long, help_heading = "Lighting")]
    no_default_light: bool,
    /// A light group: NAME=PATTERN[,PATTERN...] (repeatable; `*` and `?` wildcards) over the
    /// names of the emitters (instances, shapes, lights, `environment`); with `--aov
    /// lightgroups` each group gets an `lg_NAME` layer, the rest `lg_default`. [default:
    /// the scene's light groups]
    #[arg(long, value_name = "NAME=PATTERNS", help_heading = "Lighting")]
    light_group: Vec<String>,
    /// Refine every subdivision surface N levels (0: the control cage; at most 6).
    /// [default: by size on screen, until the cage's mean edge spans about 2 pixels]
    #[arg(long, value_name = "N", help_heading = "Lighting")]
    subdiv_level: Option<String>,

    /// A TOML settings file: every option of this command as a key, without `--` (e.g.
    /// `mis = "balance"`, `exr-half = true`, `variant = ["a=b"]`); the command line
    /// overrides it. [default: none]
    #[arg(long, help_heading = "Running")]
    settings: Option<PathBuf>,
    /// Worker threads. [default: all cores]
    #[arg(long, help_heading = "Running")]
    threads: Option<String>,
    /// Largest memory the render may need, e.g. 8G or 512M (binary units), or `off`; a scene
    /// estimated to need more fails before loading into the renderer. [default: 80 % of the
    /// physical memory or of the cgroup's limit]
    #[arg(long, help_heading = "Running")]
    max_memory: Option<String>,
    /// Most memory the textures may take, decoded and with their MIP levels, e.g. 4G, or
    /// `off`; textures that need more are read from tiled copies on disk through a cache of
    /// this size, more slowly. [default: half of --max-memory]
    #[arg(long, help_heading = "Running")]
    texture_memory: Option<String>,
    /// Continue the render in the output file (a checkpoint, or a finished render to take
    /// more samples); without the file, start afresh.
    #[arg(long, help_heading = "Running")]
    resume: bool,
    /// Write a checkpoint (the output EXR, resumable with --resume) every SECONDS while
    /// rendering, after the pass under way; SIGUSR1 writes one at any time. [default: only
    /// when a signal stops the render]
    #[arg(long, value_name = "SECONDS", help_heading = "Running")]
    checkpoint_interval: Option<String>,
    /// Progress display: auto (a bar on a terminal, lines otherwise), bar, lines (plain
    /// lines for logs), alfred (Tractor's ALF_PROGRESS lines), none. [default: auto]
    #[arg(long, value_name = "MODE", help_heading = "Running")]
    progress: Option<String>,
    /// Seconds between progress lines. [default: 5]
    #[arg(long, value_name = "SECONDS", help_heading = "Running")]
    progress_interval: Option<String>,
    /// No progress bar (progress lines for logs stay).
    #[arg(long, short, help_heading = "Running")]
    quiet: bool,
}

/// Applies the options given on the command line in `matches` (a `render`, `inspect` or
/// `convert`) to `job` as settings: the flag's long name is the key.
fn apply_command_line(
    job: &mut RenderJob,
    matches: &ArgMatches,
    command: &clap::Command,
) -> Result<()> {
    for arg in command.get_arguments() {
        let id = arg.get_id().as_str();
        // The settings file is read first; logging options are global, not render settings.
        if matches!(id, "settings" | "log_level" | "log_timestamps")
            || matches.value_source(id) != Some(ValueSource::CommandLine)
        {
            continue;
        }
        let key = arg.get_long().unwrap_or(id);
        let values: Vec<String> = if arg.get_action().takes_values() {
            matches
                .get_raw(id)
                .into_iter()
                .flatten()
                .map(|v| v.to_string_lossy().into_owned())
                .collect()
        } else {
            vec!["true".into()]
        };
        for value in values {
            job.set(key, &value)
                .map_err(|e| Error::bad_input("", format!("--{key}"), e))?;
        }
    }
    Ok(())
}

/// The render job of `lucerna render`: defaults, the settings file, the command line.
fn job_from(matches: &ArgMatches, command: &clap::Command) -> Result<RenderJob> {
    let mut job = RenderJob::default();
    if let Some(path) = matches.get_one::<PathBuf>("settings") {
        job.load_settings_file(path)?;
    }
    apply_command_line(&mut job, matches, command)?;
    Ok(job)
}

/// The load options of `inspect` and `convert`.
fn load_from(matches: &ArgMatches, command: &clap::Command) -> Result<crate::ingest::LoadOptions> {
    let mut job = RenderJob::default();
    let load_args: Vec<clap::Arg> = command
        .get_arguments()
        .filter(|a| {
            !matches!(
                a.get_id().as_str(),
                "scene" | "output" | "aov" | "plan" | "max_memory" | "texture_memory"
            )
        })
        .cloned()
        .collect();
    let only_load = clap::Command::new("load").args(load_args);
    apply_command_line(&mut job, matches, &only_load)?;
    Ok(job.load)
}

/// `--version`'s long form: the build's commit and date, and the kernel this CPU runs.
fn long_version() -> String {
    format!(
        "{} (commit {}, {})\nkernel: {}\ntarget: {}",
        env!("CARGO_PKG_VERSION"),
        env!("LUCERNA_COMMIT"),
        env!("LUCERNA_COMMIT_DATE"),
        if crate::integrator::packet_kernel_available() {
            "8-wide packets (AVX2 + FMA) and scalar"
        } else {
            "scalar (no AVX2 + FMA on this CPU)"
        },
        std::env::consts::ARCH
    )
}

fn command() -> clap::Command {
    Cli::command().long_version(long_version())
}

fn run(matches: &ArgMatches, lucerna: &[OsString]) -> Result<u8> {
    let cli = Cli::from_arg_matches(matches)
        .map_err(|e| Error::bad_input("", "arguments", e.to_string()))?;
    crate::logging::init(
        cli.log_level.unwrap_or(log::LevelFilter::Info),
        cli.log_timestamps,
    );
    let (name, sub) = matches.subcommand().expect("a subcommand is required");
    if matches!(
        name,
        "render" | "inspect" | "convert" | "merge" | "batch" | "denoise"
    ) {
        crate::interrupt::install()?;
    }
    let definition = command();
    let sub_definition = definition
        .find_subcommand(name)
        .expect("the subcommand is defined");
    match cli.command {
        Command::Render(_) => {
            let job = job_from(sub, sub_definition)?;
            Ok(crate::job::run(&job)?.exit_code())
        }
        Command::Inspect {
            scene,
            aov,
            plan,
            max_memory,
            texture_memory,
            ..
        } => {
            let limit = |value: Option<String>, option: &str| {
                value
                    .map(|v| crate::memory::parse_limit(&v))
                    .transpose()
                    .map_err(|reason| Error::bad_input("", option, reason))
            };
            let max_memory = limit(max_memory, "--max-memory")?;
            crate::memory::set_process_limit(max_memory.or_else(crate::memory::default_limit));
            // As a render with the default texture filter (bilinear: no MIP pyramids).
            crate::memory::set_texture_memory(limit(texture_memory, "--texture-memory")?, false);
            let load = load_from(sub, sub_definition)?;
            print!(
                "{}",
                crate::commands::inspect(&scene, &load, aov.as_deref(), plan.as_deref())?
            );
            Ok(0)
        }
        Command::Convert { scene, output, .. } => {
            crate::memory::set_process_limit(crate::memory::default_limit());
            let load = load_from(sub, sub_definition)?;
            crate::commands::convert(&scene, &output, &load)?;
            Ok(0)
        }
        Command::Denoise { input, output } => {
            crate::commands::denoise(&input, output.as_deref())?;
            Ok(0)
        }
        Command::Merge { inputs, output } => {
            crate::commands::merge(&inputs, &output)?;
            Ok(0)
        }
        Command::Batch { job, logs, summary } => {
            crate::commands::batch(&job, lucerna, logs, summary)
        }
        Command::Setup { venv, no_denoiser } => {
            let venv = crate::install::setup(venv.as_deref(), !no_denoiser)?;
            log::info!("Python environment ready: {}", venv.display());
            log::info!(
                "OpenImageIO's command line, to look into EXRs: {}",
                venv.join("bin/oiiotool").display()
            );
            Ok(0)
        }
        Command::Completions { shell } => {
            clap_complete::generate(shell, &mut command(), "lucerna", &mut std::io::stdout());
            Ok(0)
        }
        Command::Man { dir } => {
            std::fs::create_dir_all(&dir)
                .and_then(|()| clap_mangen::generate_to(command(), &dir))
                .map_err(|e| Error::other(&dir, "man pages", e.to_string()))?;
            log::info!("man pages written to {}", dir.display());
            Ok(0)
        }
    }
}

/// Runs the command line `args` (the program name first) and returns the exit code.
/// `lucerna` is the command that runs this command line again (program and leading
/// arguments), for the children of `lucerna batch`.
pub fn main_with(args: impl IntoIterator<Item = OsString>, lucerna: &[OsString]) -> u8 {
    let matches = match command().try_get_matches_from(args) {
        Ok(m) => m,
        Err(e) => {
            let _ = e.print();
            return e.exit_code() as u8;
        }
    };
    match run(&matches, lucerna) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("{}error: {e}", crate::logging::stamp());
            e.exit_code() as u8
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every option of `render` is also a settings-file key: none is "unknown" to
    /// [`RenderJob::set`] (whatever its value's own checks say of a placeholder).
    #[test]
    fn every_render_option_is_a_settings_key() {
        let definition = command();
        let render = definition.find_subcommand("render").unwrap();
        let mut keys = 0;
        for arg in render.get_arguments() {
            let key = arg.get_long().unwrap_or(arg.get_id().as_str());
            if matches!(key, "settings" | "help" | "log-level" | "log-timestamps") {
                continue;
            }
            keys += 1;
            let value = if arg.get_action().takes_values() {
                "1"
            } else {
                "true"
            };
            if let Err(e) = RenderJob::default().set(key, value) {
                assert!(!e.contains("unknown setting"), "--{key}: {e}");
            }
        }
        assert!(keys >= 50, "{keys}");
    }
}
