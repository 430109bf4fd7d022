//! The first step of a view's render: the frame's scene made ready (environment and default
//! light, subdivision refined for the view, unused attributes stripped), its memory
//! estimated and checked before anything large is built, the world built, and the film the
//! view renders into: empty, or restored from the checkpoint `--resume` continues. Whatever
//! can fail on the request (crop, light groups, channel names, the denoiser's library,
//! the checkpoint) fails here, before the first sample.

use super::checkpoint::read_checkpoint;
use super::request::{RenderJob, check_lossless_data};
use super::views::View;
use crate::error::{Error, Result};
use crate::film::Film;
use crate::film::aov::Aov;
use crate::integrator::settings::{MicrofacetModel, TextureFilter};
use crate::output::denoise::Denoiser;
use crate::output::exr;
use crate::render::RenderOptions;
use crate::render::plan::PlanMode;
use crate::scene::Scene;
use crate::scene::features::strip_unused_attributes;
use crate::world::World;
use crate::world::build::refine_subdivision_surfaces;
use crate::{ingest, memory};
use glam::Vec3;
use std::time::Instant;

/// Most light groups a render writes layers for.
const MAX_LIGHT_GROUPS: usize = 64;

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
    let (width, height) = options
        .overscan
        .extend(crate::camera::resolve_resolution(resolution, camera));
    let mut estimate = memory::MemoryEstimate {
        film: Film::estimated_bytes(
            width,
            height,
            &options.aovs,
            options.noise_threshold.is_some(),
        ),
        ..crate::world::build::estimate_memory(scene)
    };
    // MIP pyramids: a third of each image, in its format (one way of reading it).
    if options.settings.texture_filter == TextureFilter::Mip {
        estimate.scene += scene.texel_bytes() / 3;
    }
    estimate
}

/// A view ready to render (beside the film it renders into).
pub(super) struct Prepared {
    pub world: World,
    pub denoiser: Option<Denoiser>,
    /// The scene as the header names it, and its canonical path and fingerprint.
    pub source: String,
    pub identity: Option<(String, String)>,
    /// Seconds spent preparing the world.
    pub build_seconds: f64,
    /// Seconds the continued checkpoint had rendered.
    pub earlier_seconds: f64,
}

/// Prepares `scene` for `view` of `job` on `pool`, and the film it renders into: empty, or
/// restored from the checkpoint being continued.
pub(super) fn prepare(
    job: &RenderJob,
    view: &View,
    pool: &rayon::ThreadPool,
    mut scene: Scene,
) -> Result<(Prepared, Film)> {
    let options = &view.options;
    let output = &view.outputs[0].path;
    check_lossless_data(job.storage, &options.aovs)?;
    if let Some(radiance) = job.env {
        ingest::set_constant_environment(&mut scene, radiance);
    }
    if let Some(path) = &job.env_map {
        ingest::set_environment_map(&mut scene, path, job.env_scale)?;
    }
    let moving_emitters: Vec<&str> = scene
        .instances
        .iter()
        .filter(|i| {
            let mesh = &scene.meshes[i.mesh as usize];
            (crate::geometry::motion::keys_move(&i.motion)
                || mesh.deformation.as_ref().is_some_and(|d| d.moves()))
                && scene.materials[mesh.material as usize].is_emissive()
        })
        .map(|i| i.name.as_str())
        .collect();
    if !moving_emitters.is_empty() {
        log::warn!(
            "{}: {} emit light and move while the shutter is open: emitters are not blurred (they stay where they are at the frame)",
            scene.source,
            moving_emitters.join(", ")
        );
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
    if options.settings.microfacet == MicrofacetModel::Single {
        for material in &mut scene.materials {
            material.multiscatter = false;
        }
    }
    // Subdivision surfaces are refined for this view before the memory estimate counts them.
    scene.subdivision_level = job.subdiv_level;
    refine_subdivision_surfaces(&mut scene, view.camera.as_deref(), view.resolution)?;
    if options.plan != PlanMode::General {
        strip_unused_attributes(&mut scene);
    }
    let limit = job.max_memory.or_else(memory::default_limit);
    memory_estimate(&scene, view.camera.as_deref(), view.resolution, options)
        .check(limit, &scene.source)?;
    // The denoiser is loaded before rendering: a missing library fails at once.
    let denoiser = job.denoise.then(Denoiser::new).transpose()?;
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
    let mut world = world;
    world.set_footprints(
        options.settings.texture_filter == TextureFilter::Mip,
        options.spp,
    );
    let build_seconds = build_start.elapsed().as_secs_f64();
    let (width, height) = world.camera.display();
    world.camera = world.camera.clone().overscanned(options.overscan);
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
        let shutter = world.shutter.map(|s| s.describe());
        read_checkpoint(
            output,
            &source,
            identity.as_ref(),
            shutter.as_deref(),
            options,
        )?
    } else {
        None
    };
    if let Some(r) = &resumed {
        film.restore(&r.planes, r.discarded)
            .map_err(|e| Error::bad_input(output, "checkpoint", e))?;
        log::info!(
            "continuing {} from {} samples per pixel",
            output.display(),
            film.min_samples()
        );
    }
    let prepared = Prepared {
        world,
        denoiser,
        source,
        identity,
        build_seconds,
        earlier_seconds: resumed.as_ref().map_or(0.0, |r| r.seconds),
    };
    Ok((prepared, film))
}
