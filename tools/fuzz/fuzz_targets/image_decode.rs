//! Image decoding (textures and environment maps): any bytes must decode or give an error,
//! never panic, hang or exhaust memory. The corpus starts from KTX2 (Basis Universal), PNG,
//! JPEG, WebP, OpenEXR, HDR and TIFF images, so the fuzzer mutates every decoder's input.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(image) = lucerna::ingest::image::decode(data) {
        assert!(image.width > 0 && image.height > 0);
    }
});
