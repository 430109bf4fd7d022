//! glTF ingest: any bytes, as a .glb or a .gltf (external files refused), must load or give
//! an error, never panic, hang or exhaust memory; what loads must render.
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(scene) = lucerna::ingest::gltf::import(data, "fuzz.gltf", None) {
        common::render_a_few_pixels(scene);
    }
});
