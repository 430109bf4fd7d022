//! One frame of a job: its scene read, its views chosen and their outputs checked, then
//! each view rendered in three steps: prepare (scene to world, film), render (the render
//! loop, with checkpoints), write (files and figures).

use super::checkpoint::Checkpoints;
use super::header::HeaderFacts;
use super::outcome::Outcome;
use super::prepare::prepare;
use super::request::RenderJob;
use super::views::{View, frame_views};
use super::write::write_view;
use crate::error::{Error, Result};
use crate::ingest;
use crate::render::{self, RenderOptions};
use crate::scene::Scene;
use crate::sequence::output_path;
use std::path::Path;
use std::time::Instant;

/// Renders one frame into `outcome`.
pub(super) fn render_frame(
    job: &RenderJob,
    options: &RenderOptions,
    pool: &rayon::ThreadPool,
    frame: Option<f64>,
    several_frames: bool,
    outcome: &mut Outcome,
) -> Result<()> {
    use crate::film::aov::Aov;
    let load = ingest::LoadOptions {
        frame,
        vectors: options.aovs.contains(Aov::Motion) || options.aovs.contains(Aov::Velocity),
        ..job.load.clone()
    };
    let mut scene = ingest::load_scene(job.scene.as_deref(), &load)?;
    let stem = job.stem();
    let settings = scene.render_settings.take().unwrap_or_default();
    let views = frame_views(job, options, &scene, &settings, frame, several_frames)?;
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

/// Renders `scene` as `view` says and writes its files into `outcome`.
fn render_view(
    job: &RenderJob,
    view: &View,
    pool: &rayon::ThreadPool,
    frame: Option<f64>,
    scene: Scene,
    preview: Option<&Path>,
    outcome: &mut Outcome,
) -> Result<()> {
    let (prepared, film) = prepare(job, view, pool, scene)?;
    let options = &view.options;
    let facts = HeaderFacts {
        job,
        options,
        world: &prepared.world,
        source: &prepared.source,
        identity: prepared.identity.as_ref(),
        frame,
    };
    // Checkpoints while sampling: every --checkpoint-interval seconds and on SIGUSR1, after
    // the pass under way.
    let mut checkpoints = Checkpoints {
        interval: job.checkpoint_interval,
        write_files: job.write_files,
        output: &view.outputs[0].path,
        facts: &facts,
        earlier_seconds: prepared.earlier_seconds,
        last: Instant::now(),
    };
    // From here a first signal stops sampling and the checkpoint is written; before, it ends
    // the process (src/interrupt.rs).
    let _sampling = crate::interrupt::defer();
    let (film, mut stats) = pool.install(|| {
        render::render_with(&prepared.world, options, film, &mut |film, stats| {
            checkpoints.after_pass(film, stats)
        })
    });
    if stats.interrupted && film.total_samples() == 0 {
        log::info!(
            "interrupted (signal {}) before the first sample; nothing written",
            crate::interrupt::received()
        );
        outcome.interrupted = Some(crate::interrupt::received());
        return Ok(());
    }
    stats.seconds += prepared.earlier_seconds;
    write_view(
        job, view, pool, frame, &prepared, &facts, film, stats, preview, outcome,
    )
}
