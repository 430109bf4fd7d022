//! A render job: what `lucerna render` does, as a library call. The command line, the
//! children of `lucerna batch` and the Python package all build a [`RenderJob`] (defaults,
//! then a settings file, then their own arguments, through [`RenderJob::set`]) and call
//! [`run`]; `main.rs` only parses arguments.
//!
//! A job reads the scene (once per frame), chooses its views (`views`: the command line's
//! output, or the render products a USD stage declares), and renders each view in three
//! steps (`frame`): `prepare` turns the scene into a world and an empty or restored film,
//! the render loop samples it while `checkpoint` writes checkpoints, and `write` writes its
//! files: the EXR(s) atomically, the optional denoised layer, preview PNG and statistics
//! JSON, under the header `header` makes. Checkpoints (`--checkpoint-interval`, SIGUSR1, a
//! stopping signal) are EXRs that `--resume` continues.

mod checkpoint;
mod frame;
mod header;
mod outcome;
mod prepare;
mod request;
mod run;
mod views;
mod write;

pub use outcome::{Outcome, Rendered};
pub use prepare::memory_estimate;
pub use request::{JOB_SETTINGS, RenderJob};
pub use run::run;
