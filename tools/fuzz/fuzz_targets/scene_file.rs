//! Scene-file loader: the input is the manifest, a zero byte, then the buffer. Any bytes
//! must load or give an error, never panic, hang or exhaust memory; what loads must render.
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let split = data.iter().position(|&b| b == 0).unwrap_or(data.len());
    let (manifest, buffer) = (&data[..split], data.get(split + 1..).unwrap_or_default());
    let loaded = lucerna::scene::file::parse(Path::new("fuzz.lucerna"), manifest, |_| {
        Ok(buffer.to_vec().into())
    });
    if let Ok(scene) = loaded {
        common::render_a_few_pixels(scene);
    }
});
