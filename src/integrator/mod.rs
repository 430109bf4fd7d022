//! The integrator: one path tracer whose techniques are settings (`settings`), and the two
//! kernels that run it: `path`, one path at a time, and `packet`, eight paths at a time in
//! SIMD lanes. `estimator` holds what both kernels share, and the rule that keeps them
//! producing the same image (see docs/architecture.md, "The estimator").

pub mod ears;
pub mod estimator;
pub mod guiding;
pub(crate) mod media;
pub mod mis;
#[cfg(target_arch = "x86_64")]
pub(crate) mod packet;
mod parameter;
pub mod path;
pub mod roulette;
pub mod settings;
pub mod split;

pub use crate::light::{LightSampling, LightSelect};
pub use mis::{Mis, Technique};
pub use roulette::RussianRoulette;
pub use settings::{Settings, Split, SplitChoice};

/// Whether this CPU runs the packet kernel (`packet`: x86-64 with AVX2 and FMA).
pub fn packet_kernel_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        crate::simd::available()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
