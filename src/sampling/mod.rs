//! Sampling: random streams, samplers, warps from the unit square, and distributions.

pub mod distribution;
pub mod pcg;
pub mod sampler;
pub mod warp;
