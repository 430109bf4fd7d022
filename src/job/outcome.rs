//! What a job did: the views it rendered, the files it wrote, and the signal that stopped it.

use crate::film::Film;
use crate::render::RenderStats;
use std::path::PathBuf;

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
