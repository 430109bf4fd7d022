//! lucerna: a physically based path tracer that renders glTF (and, through a plugin, USD)
//! scenes into one multi-layer EXR.
//!
//! Data flow (docs/architecture.md draws the layers): an ingest module turns a file into a
//! [`scene::Scene`] (world units, right-handed, Y up); [`world::World`] prepares it for
//! rendering (render space, BVH, lights, camera); [`render`] runs the [`integrator`] over
//! tiles and accumulates every requested AOV in a [`film::Film`]; [`output`] writes it (EXR,
//! preview, denoised beauty). A [`job`] does all of this for one `lucerna render`.

// `!(x > 0.0)` is deliberate throughout: unlike `x <= 0.0`, it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod batch;
pub mod camera;
pub mod cli;
pub mod color;
pub mod commands;
pub mod error;
pub mod files;
pub mod film;
pub mod geometry;
pub mod ingest;
pub mod install;
pub mod integrator;
pub mod interrupt;
pub mod job;
pub mod light;
pub mod logging;
pub mod material;
pub mod medium;
pub mod memory;
pub mod output;
pub mod platform;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod sequence;
#[cfg(target_arch = "x86_64")]
pub(crate) mod simd;
pub mod world;

pub use error::{Error, ErrorKind, Result};

/// Renderer name and version, as written into EXR headers.
pub const RENDERER: &str = concat!("lucerna ", env!("CARGO_PKG_VERSION"));
