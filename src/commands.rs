//! The commands besides `render` (src/job/) as library calls: `inspect`, `convert`,
//! `merge` and `batch`. The command line and the Python package call them. They do not
//! install signal handlers (the command line does: a signal then ends a conversion at once,
//! stopping the USD plugin, and a merge without leaving its temporary output).

use crate::error::{Error, Result};
use crate::ingest::load_scene;
use crate::job::memory_estimate;
use crate::render::RenderOptions;
use crate::render::plan::{PlanMode, RenderPlan};
use crate::scene::LightKind;
use crate::scene::features::{SceneFeatures, strip_unused_attributes};
use crate::{ingest, memory};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// `lucerna convert`: writes the scene at `path` as a lucerna scene file.
pub fn convert(path: &Path, output: &Path, load: &ingest::LoadOptions) -> Result<()> {
    let scene = load_scene(Some(path), load)?;
    crate::scene::file::write(&scene, output)?;
    log::info!(
        "wrote {} ({} meshes, {} materials, {} textures)",
        output.display(),
        scene.meshes.len(),
        scene.materials.len(),
        scene.textures.len()
    );
    Ok(())
}

/// `lucerna merge`: combines the EXRs of a split render into `output`.
pub fn merge(inputs: &[PathBuf], output: &Path) -> Result<()> {
    crate::files::check_output(output, "--output")?;
    let parts = inputs
        .iter()
        .map(|path| {
            let (planes, header) = crate::output::exr::read(path)?;
            Ok(crate::output::merge::Part {
                path: path.clone(),
                planes,
                header,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let (planes, header) = crate::output::merge::merge(&parts)?;
    let (window, display) = (planes.window, planes.display);
    crate::output::exr::write_planes(output, planes, &header)?;
    log::info!(
        "merged {} parts into {} (pixels {} of {}x{})",
        parts.len(),
        output.display(),
        window.describe(),
        display.0,
        display.1
    );
    Ok(())
}

/// `lucerna denoise`: adds (or replaces) the `denoised` layer of the EXR at `input`, from
/// its beauty, albedo and normal layers, and writes it to `output` (the input itself,
/// replaced atomically, when `None`): for renders merged from passes or tiles, which are
/// denoised whole.
pub fn denoise(input: &Path, output: Option<&Path>) -> Result<()> {
    use crate::output::denoise::{Denoiser, LAYER, Layers};
    let output = output.unwrap_or(input);
    crate::files::check_output(output, "--output")?;
    let (mut planes, header) = crate::output::exr::read(input)?;
    let channel = |n: &str| {
        planes.channel(n).ok_or_else(|| {
            Error::bad_input(
                input,
                "channels",
                format!("no channel {n}: render with --denoise, or with --aov albedo,normal"),
            )
        })
    };
    let layers = Layers {
        width: planes.window.width as usize,
        height: planes.window.height as usize,
        beauty: [channel("R")?, channel("G")?, channel("B")?, channel("A")?],
        albedo: [
            channel("albedo.R")?,
            channel("albedo.G")?,
            channel("albedo.B")?,
        ],
        normal: [
            channel("normal.X")?,
            channel("normal.Y")?,
            channel("normal.Z")?,
        ],
    };
    let rgb = Denoiser::new()?.denoise(&layers)?;
    let prefix = format!("{LAYER}.");
    planes.channels.retain(|(n, _)| !n.starts_with(&prefix));
    planes
        .channels
        .extend(crate::output::denoise::channels(rgb));
    crate::output::exr::write_planes(output, planes, &header)?;
    log::info!("wrote {} with a denoised layer", output.display());
    Ok(())
}

/// `lucerna batch`: runs a job file's renders with `lucerna` (the command that runs the
/// CLI: this binary, or a Python with the package), writes the summary; returns the exit
/// code (0, 1 if a frame failed, 128 + signal if interrupted).
pub fn batch(
    job: &Path,
    lucerna: &[OsString],
    logs: Option<PathBuf>,
    summary: Option<PathBuf>,
) -> Result<u8> {
    let beside = |suffix: &str| job.with_extension(suffix);
    let logs = logs.unwrap_or_else(|| beside("logs"));
    let summary_path = summary.unwrap_or_else(|| beside("summary.json"));
    let tasks = crate::batch::plan(job, &logs)?;
    let stop = crate::interrupt::install()?;
    // The children take their own signals; the batch forwards them and waits.
    let _forwarding = crate::interrupt::defer();
    let summary = crate::batch::run(job, lucerna, &tasks, &stop);
    let json = serde_json::to_string_pretty(&summary).expect("the summary serialises");
    crate::files::write_atomically(&summary_path, |w| {
        use std::io::Write;
        w.write_all(json.as_bytes())
            .map_err(|e| Error::other(&summary_path, "summary", e.to_string()))
    })?;
    log::info!(
        "batch {}: {} rendered, {} skipped (complete), {} failed{}; summary {}",
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
        crate::interrupt::exit_code(crate::interrupt::received())
    } else if summary.failed > 0 {
        1
    } else {
        0
    })
}

/// `lucerna inspect`: a summary of the scene at `path` and what rendering it needs.
pub fn inspect(
    path: &Path,
    load: &ingest::LoadOptions,
    aov: Option<&str>,
    plan_mode: Option<&str>,
) -> Result<String> {
    use std::fmt::Write;
    let mut out = String::new();
    let mut options = RenderOptions::default();
    for (name, value) in [("aov", aov), ("plan", plan_mode)] {
        if let Some(v) = value {
            options
                .set(name, v)
                .map_err(|e| Error::bad_input("", format!("--{name}"), e))?;
        }
    }
    let mut scene = load_scene(Some(path), load)?;
    if options.plan != PlanMode::General {
        strip_unused_attributes(&mut scene);
    }
    let triangles: usize = scene.meshes.iter().map(|m| m.triangles.len()).sum();
    let vertices: usize = scene.meshes.iter().map(|m| m.positions.len()).sum();
    let _ = writeln!(out, "scene: {}", scene.source);
    let _ = writeln!(
        out,
        "  geometry: {} meshes, {} instances, {} triangles ({} instanced), {} vertices",
        scene.meshes.len(),
        scene.instances.len(),
        triangles,
        scene.instanced_triangle_count(),
        vertices
    );
    if !(scene.spheres.is_empty() && scene.disks.is_empty() && scene.cylinders.is_empty()) {
        let _ = writeln!(
            out,
            "  analytic shapes: {} spheres, {} disks, {} cylinders",
            scene.spheres.len(),
            scene.disks.len(),
            scene.cylinders.len()
        );
    }
    if let Some((lo, hi)) = scene.bounds() {
        let _ = writeln!(
            out,
            "  bounds: [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}]",
            lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
        );
    }
    let mut models: Vec<&str> = scene.materials.iter().map(|m| m.model.name()).collect();
    models.sort();
    models.dedup();
    let count = |f: &dyn Fn(&crate::scene::Material) -> bool| {
        scene.materials.iter().filter(|m| f(m)).count()
    };
    let _ = writeln!(
        out,
        "  materials: {} ({}); {} emissive, {} normal-mapped, {} with alpha, {} double-sided",
        scene.materials.len(),
        models.join(", "),
        count(&|m| m.is_emissive()),
        count(&|m| m.normal_texture.is_some()),
        count(&|m| m.alpha_mode != crate::scene::AlphaMode::Opaque),
        count(&|m| m.double_sided),
    );
    let texel_bytes = scene.texel_bytes();
    let sets: Vec<usize> = scene
        .textures
        .iter()
        .filter_map(|t| t.udim.as_ref().map(|u| u.tiles.len()))
        .collect();
    let udim = match sets.len() {
        0 => String::new(),
        n => format!(
            ", {n} of them UDIM sets of {} tiles in all",
            sets.iter().sum::<usize>()
        ),
    };
    match scene.texture_cache() {
        None => {
            let _ = writeln!(
                out,
                "  textures: {}{udim} ({} bytes of texels; `--texture-filter mip` adds about {} bytes of MIP pyramids)",
                scene.textures.len(),
                texel_bytes,
                texel_bytes / 3
            );
        }
        Some(cache) => {
            let stats = cache.stats();
            let _ = writeln!(
                out,
                "  textures: {}{udim} (too large for the texture memory: {} images in tiled files of {} bytes, read through a tile cache of {} bytes; {} bytes of texels in memory)",
                scene.textures.len(),
                stats.images,
                stats.bytes_on_disk,
                cache.capacity(),
                texel_bytes
            );
        }
    }
    let emissive_triangles: usize = scene
        .instances
        .iter()
        .map(|i| &scene.meshes[i.mesh as usize])
        .filter(|m| scene.materials[m.material as usize].is_emissive())
        .map(|m| m.triangles.len())
        .sum();
    let kinds = |f: fn(&LightKind) -> bool| scene.lights.iter().filter(|l| f(&l.kind)).count();
    let _ = writeln!(
        out,
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
    let _ = writeln!(
        out,
        "  cameras: {}",
        if names.is_empty() {
            "none (one framing the scene is used)".to_string()
        } else {
            names.join(", ")
        }
    );
    let estimate = memory_estimate(&scene, None, None, &options);
    let _ = writeln!(
        out,
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
            crate::integrator::RussianRoulette::Efficiency(_)
        ),
    )
    .with_guiding(options.settings.guiding)
    .with_light_selection(options.settings.light_select);
    let _ = writeln!(out, "{plan}");
    Ok(out)
}
