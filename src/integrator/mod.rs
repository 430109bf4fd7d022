//! The integrator: one path tracer whose techniques are settings (see `../shared/design.md`,
//! "Render settings"), and the records it produces.

pub mod ears;
pub mod mis;
pub mod path;
pub mod settings;
pub mod split;

pub use mis::{Mis, Technique};
pub use settings::{LightSampling, LightSelect, RussianRoulette, Settings, Split, SplitChoice};
