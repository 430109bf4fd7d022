//! Image decoding (textures and environment maps): any bytes must decode or give an error,
//! never panic, hang or exhaust memory; measuring an image from its header alone (what the
//! texture memory is decided by) must not panic either. The corpus starts from KTX2 (Basis Universal), PNG,
//! JPEG, WebP, OpenEXR, HDR and TIFF images, so the fuzzer mutates every decoder's input.
//!
//! lucerna catches panics inside the KTX2 transcoder (a young crate) and reports the file as
//! invalid, so a panic caught there is not a defect; libFuzzer's panic hook aborts on every
//! panic, caught or not, so it is replaced by a silent one. A panic that escapes lucerna still
//! aborts (libfuzzer-sys catches it at the target's boundary), and its input is kept; run it
//! through `cargo test --test it fuzz_regressions` for the message.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    static QUIET_HOOK: std::sync::Once = std::sync::Once::new();
    QUIET_HOOK.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let _ = lucerna::ingest::image::decoded_bytes(data);
    if let Ok(image) = lucerna::ingest::image::decode(data) {
        assert!(image.width > 0 && image.height > 0);
    }
});
