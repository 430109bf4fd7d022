//! The integrator: one path tracer whose techniques are settings (see `../shared/design.md`,
//! "Render settings"), and the records it produces.

pub mod ears;
pub(crate) mod media;
pub mod mis;
#[cfg(target_arch = "x86_64")]
pub(crate) mod packet;
pub mod path;
pub mod settings;
pub mod split;

pub use mis::{Mis, Technique};
pub use settings::{LightSampling, LightSelect, RussianRoulette, Settings, Split, SplitChoice};

/// Whether this CPU runs the packet kernel (`packet`: x86-64 with AVX2 and FMA).
pub fn packet_kernel_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
