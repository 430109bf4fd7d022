//! lucerna's integration tests, as one test binary (one link, not one per file): each
//! module is the suite of one concern. `cargo nextest run` runs them in parallel, each test
//! in a process of its own; `-E 'test(/^chi2::/)'` selects one suite.

mod common;

mod animation;
mod aov;
mod bad_input;
mod batch;
mod chi2;
mod cli;
mod convergence;
mod deformation_blur;
mod determinism;
mod furnace;
mod fuzz_regressions;
mod gltf_delivery;
mod gltf_ingest;
mod image_formats;
mod instancing;
mod learned_split;
mod motion_blur;
mod pipeline;
mod plan;
mod quadric_lights;
mod scene_file;
mod split;
mod stress;
mod texture_cache;
mod texture_filter;
mod vdb;
