//! Running a job: its thread pool and stop flag, then every frame (the scene read once per
//! frame).

use super::frame::render_frame;
use super::outcome::Outcome;
use super::request::RenderJob;
use crate::error::{Error, Result};
use crate::sequence::FrameList;

/// Runs `job`: every frame, every view.
pub fn run(job: &RenderJob) -> Result<Outcome> {
    let mut job = job.clone();
    job.finish()?;
    // The limits readers hold to (images checked before decoding, textures beyond the
    // texture memory read through a tile cache), for the command line, batch children and
    // the Python package alike.
    crate::memory::set_process_limit(job.max_memory.or_else(crate::memory::default_limit));
    let pyramids =
        job.options.settings.texture_filter == crate::integrator::settings::TextureFilter::Mip;
    crate::memory::set_texture_memory(job.texture_memory, pyramids);
    if job.preview.is_some() && job.write_files {
        // An OCIO display or view that does not exist fails before the scene is read.
        crate::output::preview::check(&job.view)?;
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
