//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod chi2;
pub mod cli;
pub mod gltf_builder;
pub mod scenes;
