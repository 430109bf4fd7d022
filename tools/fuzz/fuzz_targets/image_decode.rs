//! Image decoding (textures and environment maps): any bytes must decode or give an error,
//! never panic, hang or exhaust memory; measuring an image from its header alone (what the
//! texture memory is decided by) must not panic either. The corpus starts from KTX2 (Basis Universal), PNG,
//! JPEG, WebP, OpenEXR, HDR and TIFF images, so the fuzzer mutates every decoder's input.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = lucerna::ingest::image::decoded_bytes(data);
    if let Ok(image) = lucerna::ingest::image::decode(data) {
        assert!(image.width > 0 && image.height > 0);
    }
});
