//! The last step of a view's render: the EXR of every output (with the denoised beauty when
//! asked), the statistics JSON, the preview PNG, and the line that says what was done.

use super::header::HeaderFacts;
use super::outcome::{Outcome, Rendered};
use super::prepare::Prepared;
use super::request::RenderJob;
use super::views::View;
use crate::error::{Error, Result};
use crate::film::Film;
use crate::film::aov::Aov;
use crate::output::{denoise, exr, preview};
use crate::render::{self, RenderStats};
use crate::scene::texture_cache::CacheStats;
use crate::sequence::output_path;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Writes what `view` of `job` rendered (`film`, `stats`) and records it in `outcome`.
#[allow(clippy::too_many_arguments)]
pub(super) fn write_view(
    job: &RenderJob,
    view: &View,
    pool: &rayon::ThreadPool,
    frame: Option<f64>,
    prepared: &Prepared,
    facts: &HeaderFacts,
    film: Film,
    stats: RenderStats,
    preview: Option<&Path>,
    outcome: &mut Outcome,
) -> Result<()> {
    let header = facts.header(&film, &stats);
    let denoised = match (&prepared.denoiser, stats.interrupted) {
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
    let extra: &[Aov] = if stats.interrupted || view.options.pass.is_some() {
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
            &prepared.source,
            &film,
            &stats,
            prepared.build_seconds,
            pool,
            texture_cache_stats(&prepared.world),
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
            view.outputs[0].path.display()
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
            prepared.build_seconds,
            prepared.world.primitive_count(),
            match prepared.world.surfaces.placements.len() {
                0 => String::new(),
                n => format!(
                    ", {n} placements of {} shared meshes",
                    prepared.world.surfaces.shared_meshes.len()
                ),
            },
            prepared.world.bvh_seconds,
            stats.summary()
        );
        if let Some(c) = texture_cache_stats(&prepared.world) {
            use crate::memory::Bytes;
            log::info!(
                "texture cache: {} images in tiled files of {}; {} tiles read ({}), {} resident at the end",
                c.images,
                Bytes(c.bytes_on_disk),
                c.tiles_read,
                Bytes(c.bytes_read),
                Bytes(c.resident)
            );
        }
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

/// What the tile cache of the world's textures did, if they are read through one.
fn texture_cache_stats(world: &crate::world::World) -> Option<CacheStats> {
    crate::scene::texture::cache_of(&world.surfaces.textures).map(|cache| cache.stats())
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
    texture_cache: Option<CacheStats>,
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
        "texture_cache": texture_cache.map(|c| serde_json::json!({
            "images": c.images,
            "bytes_on_disk": c.bytes_on_disk,
            "tiles_read": c.tiles_read,
            "bytes_read": c.bytes_read,
            "resident_bytes": c.resident,
        })),
    });
    crate::files::write_atomically(&path, |w| {
        use std::io::Write;
        serde_json::to_writer_pretty(&mut *w, &json)
            .map_err(|e| Error::other(&path, "write", e.to_string()))?;
        w.write_all(b"\n")
            .map_err(|e| Error::other(&path, "write", e.to_string()))
    })
}
