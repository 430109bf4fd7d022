//! The `lucerna` command line: `render`, `inspect` and `convert`.

use clap::{Parser, Subcommand};
use glam::Vec3;
use lucerna::error::{Error, Result};
use lucerna::film::exr::{Attribute, Header};
use lucerna::plan::{self, PlanMode, RenderPlan, SceneFeatures};
use lucerna::render::{self, RenderOptions};
use lucerna::scene::{LightKind, Scene};
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
        /// auto or general, as `render --plan`.
        #[arg(long)]
        plan: Option<String>,
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

/// How to read the scene (USD stages use these).
#[derive(clap::Args)]
struct LoadArgs {
    /// Time code of an animated USD stage (default: the stage's start time code).
    #[arg(long)]
    frame: Option<f64>,
    /// Convert a USD stage even if usd-core's validators report errors.
    #[arg(long)]
    no_validate: bool,
}

impl LoadArgs {
    fn options(&self) -> ingest::LoadOptions {
        ingest::LoadOptions {
            frame: self.frame,
            validate: !self.no_validate,
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
    /// Output EXR file.
    #[arg(short, long, default_value = "render.exr")]
    output: PathBuf,
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
    /// AOV layers to write, comma-separated (e.g. `direct,indirect,albedo`), `all`, or
    /// per-depth layers `nee_dK`, `bsdf_dK`. The beauty is always written.
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
    /// Lat-long environment map (OpenEXR, PNG or JPEG).
    #[arg(long)]
    env_map: Option<PathBuf>,
    /// Multiplier of the environment map.
    #[arg(long, default_value = "1", value_parser = parse_rgb)]
    env_scale: Vec3,
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
    /// Measure area lights are sampled in: area (default) or solid-angle.
    #[arg(long)]
    light_sampling: Option<String>,
    /// Shadow rays and BSDF samples at the first hit, e.g. nee=4,bsdf=1 (default 1 and 1).
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
    /// auto (default): the integrator leaves out what the scene and the AOVs do not use;
    /// general: every feature on (for benchmarks and comparisons).
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
        let mut options = RenderOptions {
            progress: !self.quiet,
            ..Default::default()
        };
        if let Some(path) = &self.settings {
            let text = std::fs::read_to_string(path)
                .map_err(|e| Error::bad_input(path, "file", format!("cannot read: {e}")))?;
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
        ];
        for (name, value) in flags {
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
        Ok(options)
    }
}

fn parse_resolution(s: &str) -> std::result::Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or("expected WIDTHxHEIGHT, e.g. 640x480")?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=65536).contains(v))
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
    if c.is_finite() && c.min_element() >= 0.0 {
        Ok(c)
    } else {
        Err("values must be finite and non-negative".into())
    }
}

fn load_scene(path: Option<&Path>, load: &LoadArgs) -> Result<Scene> {
    let scene = match path {
        Some(p) => ingest::load(p, &load.options())?,
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

fn render_command(args: RenderArgs) -> Result<()> {
    let options = args.options()?;
    let pool = thread_pool(args.threads)?;
    let mut scene = load_scene(args.scene.as_deref(), &args.load)?;
    if let Some(radiance) = args.env {
        ingest::set_constant_environment(&mut scene, radiance);
    }
    if let Some(path) = &args.env_map {
        ingest::set_environment_map(&mut scene, path, args.env_scale)?;
    }
    if options.plan == PlanMode::Auto {
        plan::strip_unused_attributes(&mut scene);
    }
    let limit = args.max_memory.or_else(memory::default_limit);
    memory_estimate(&scene, args.camera.as_deref(), args.resolution, &options)
        .check(limit, &scene.source)?;
    let source = scene.source.clone();
    let build_start = std::time::Instant::now();
    let world = pool.install(|| {
        World::build(
            scene,
            args.camera.as_deref(),
            args.resolution,
            options.settings.light_select,
        )
    })?;
    let build_seconds = build_start.elapsed().as_secs_f64();
    let (film, stats) = pool.install(|| render::render(&world, &options));

    // glam's column-major listing of a column-vector matrix is the row-major listing of
    // its transpose: exactly Imath's row-vector convention.
    let imath = |m: glam::DMat4| m.as_mat4().to_cols_array();
    let header = Header {
        world_to_camera: Some(imath(world.camera.world_to_camera)),
        world_to_ndc: Some(imath(world.camera.world_to_ndc)),
        attributes: vec![
            (
                "lucerna/renderer".into(),
                Attribute::Text(lucerna::RENDERER.into()),
            ),
            ("lucerna/scene".into(), Attribute::Text(source)),
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
        ],
    };
    film::exr::write(&args.output, &film, &header)?;
    if let Some(png) = &args.preview {
        film::preview::write(png, &film)?;
    }
    let peak = render::peak_memory_bytes().map_or(String::new(), |b| {
        format!(", peak memory {:.1} MB", b as f64 / 1e6)
    });
    eprintln!(
        "lucerna: wrote {} ({}x{}, {} threads): scene prepared in {:.2} s ({} primitives{}, BVH built in {:.2} s); rendered in {}{peak}",
        args.output.display(),
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
    Ok(())
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

fn convert_command(path: &Path, output: &Path, load: &LoadArgs) -> Result<()> {
    let scene = load_scene(Some(path), load)?;
    lucerna::scene::file::write(&scene, output)?;
    eprintln!(
        "lucerna: wrote {} ({} meshes, {} materials, {} textures)",
        output.display(),
        scene.meshes.len(),
        scene.materials.len(),
        scene.textures.len()
    );
    Ok(())
}

fn inspect_command(
    path: &Path,
    load: &LoadArgs,
    aov: Option<&str>,
    plan_mode: Option<&str>,
) -> Result<()> {
    let mut options = RenderOptions::default();
    for (name, value) in [("aov", aov), ("plan", plan_mode)] {
        if let Some(v) = value {
            options
                .set(name, v)
                .map_err(|e| Error::bad_input("", format!("--{name}"), e))?;
        }
    }
    let mut scene = load_scene(Some(path), load)?;
    if options.plan == PlanMode::Auto {
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
    );
    println!("{plan}");
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
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
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}
