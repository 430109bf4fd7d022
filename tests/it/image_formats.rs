//! Texture and environment image formats: Radiance HDR, TIFF (8-bit, 16-bit, float),
//! OpenEXR, 16-bit PNG and WebP decode to the values written, KTX2 (Basis Universal) to the
//! images it was made from; float images are linear in
//! every slot, integer ones are sRGB-decoded where the slot is a colour.

use crate::common;

use common::cli::temp_dir;
use glam::{Vec2, Vec3};
use lucerna::ingest;
use lucerna::scene::{Scene, Texels};
use std::path::Path;

/// 4 × 2 RGB test values above 1 and below, as HDRIs hold.
const VALUES: [[f32; 3]; 8] = [
    [0.0, 0.25, 0.5],
    [1.0, 2.0, 4.0],
    [8.0, 0.125, 0.0625],
    [0.5, 0.5, 0.5],
    [16.0, 1.5, 0.75],
    [0.03125, 0.0, 1.0],
    [3.0, 3.0, 0.0],
    [0.2, 0.4, 0.8],
];

fn environment_texels(path: &Path) -> (u32, u32, Vec<[f32; 4]>) {
    let mut scene = Scene::default();
    ingest::set_environment_map(&mut scene, path, Vec3::ONE).unwrap_or_else(|e| panic!("{e}"));
    let t = &scene.textures[0];
    match &*t.texels {
        Texels::RgbaF32(p) => (t.width, t.height, p.clone()),
        _ => panic!("environment texels are not linear floats"),
    }
}

fn float_image() -> image::Rgb32FImage {
    image::Rgb32FImage::from_fn(4, 2, |x, y| image::Rgb(VALUES[(y * 4 + x) as usize]))
}

#[test]
fn radiance_hdr_environment_reads_its_values() {
    let dir = temp_dir("hdr");
    let path = dir.join("sky.hdr");
    float_image().save(&path).unwrap();
    let (w, h, texels) = environment_texels(&path);
    assert_eq!((w, h), (4, 2));
    for (t, v) in texels.iter().zip(VALUES) {
        for c in 0..3 {
            // RGBE keeps 8 mantissa bits a pixel (the largest channel's exponent).
            let max = v.iter().cloned().fold(0.0, f32::max);
            assert!((t[c] - v[c]).abs() <= max / 128.0, "{t:?} vs {v:?}");
        }
    }
}

#[test]
fn float_tiff_and_openexr_environments_are_exact() {
    let dir = temp_dir("float-formats");
    let tiff = dir.join("sky.tif");
    image::DynamicImage::ImageRgb32F(float_image())
        .into_rgba32f()
        .save(&tiff)
        .unwrap();
    let exr_path = dir.join("sky.exr");
    exr::prelude::write_rgb_file(&exr_path, 4, 2, |x, y| {
        let v = VALUES[y * 4 + x];
        (v[0], v[1], v[2])
    })
    .unwrap();
    for path in [tiff, exr_path] {
        let (w, h, texels) = environment_texels(&path);
        assert_eq!((w, h), (4, 2), "{}", path.display());
        for (t, v) in texels.iter().zip(VALUES) {
            assert_eq!(t[..3], v[..], "{}", path.display());
        }
    }
}

/// Integer images are sRGB-encoded: 16-bit TIFF and PNG environments decode to linear as
/// 8-bit ones do, with 16-bit precision.
#[test]
fn sixteen_bit_images_are_srgb_decoded_with_full_precision() {
    let dir = temp_dir("sixteen");
    let encoded: [u16; 4] = [0, 1000, 32768, 65535];
    let img = image::ImageBuffer::<image::Rgba<u16>, Vec<u16>>::from_fn(4, 1, |x, _| {
        let v = encoded[x as usize];
        image::Rgba([v, v, v, 65535])
    });
    let srgb_to_linear = |v: f32| {
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    let tiff = dir.join("grey16.tif");
    img.save(&tiff).unwrap();
    let png_path = dir.join("grey16.png");
    let mut encoder = png::Encoder::new(std::fs::File::create(&png_path).unwrap(), 4, 1);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Sixteen);
    let samples: Vec<u8> = img.as_raw().iter().flat_map(|v| v.to_be_bytes()).collect();
    encoder
        .write_header()
        .unwrap()
        .write_image_data(&samples)
        .unwrap();
    for path in [tiff, png_path] {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let (_, _, texels) = environment_texels(&path);
        for (t, e) in texels.iter().zip(encoded) {
            let expected = srgb_to_linear(e as f32 / 65535.0);
            assert!(
                (t[0] - expected).abs() < 1e-6,
                "{name}: {} vs {expected}",
                t[0]
            );
        }
        // And as a texture: the 16-bit values are kept (8 bytes a texel).
        let decoded = ingest::image::decode(&std::fs::read(&path).unwrap()).unwrap();
        assert!(matches!(decoded.texels, Texels::Rgba16(_)), "{name}");
    }
}

/// A float texture is linear in a colour slot: no sRGB decoding of values that are
/// already linear (and may exceed 1).
#[test]
fn float_textures_are_linear_in_colour_slots() {
    let t = lucerna::scene::Texture {
        name: "hdr".into(),
        width: 1,
        height: 1,
        texels: std::sync::Arc::new(Texels::RgbaF32(vec![[0.5, 2.0, 0.25, 1.0]])),
        mips: Default::default(),
        wrap_u: lucerna::scene::Wrap::Repeat,
        wrap_v: lucerna::scene::Wrap::Repeat,
        nearest: false,
        mipmaps: true,
        udim: None,
    };
    assert_eq!(
        t.sample(Vec2::splat(0.5), true).to_array(),
        [0.5, 2.0, 0.25, 1.0]
    );
}

/// Formats lucerna cannot read are refused naming the format; a KTX2 header without a
/// payload, and KTX2 images of a Vulkan format (not Basis Universal), are refused as such.
#[test]
fn unknown_and_broken_ktx2_images_are_refused_clearly() {
    let err = ingest::image::decode(b"\xabKTX 20\xbb\r\n\x1a\n....")
        .err()
        .unwrap();
    assert!(err.contains("KTX2"), "{err}");
    let mut vulkan = std::fs::read(ktx2_asset("uastc_orm.ktx2")).unwrap();
    vulkan[12..16].copy_from_slice(&37u32.to_le_bytes()); // VK_FORMAT_R8G8B8A8_UNORM
    let err = ingest::image::decode(&vulkan).err().unwrap();
    assert!(err.contains("Vulkan format 37"), "{err}");
    let err = ingest::image::decode(b"GIF89a....").err().unwrap();
    assert!(err.contains("unsupported image format"), "{err}");
}

fn ktx2_asset(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/assets/ktx2")
        .join(name)
}

/// The KTX2 images' RGB averaged over square blocks to 64 x 64, as the reference PNGs were
/// made from the source PNGs (tests/assets/ktx2/LICENSE.md).
fn block_means(width: u32, texels: &[[u8; 4]]) -> Vec<[f64; 3]> {
    let f = (width / 64) as usize;
    let w = width as usize;
    (0..64 * 64)
        .map(|i| {
            let (bx, by) = (i % 64, i / 64);
            let mut sum = [0.0f64; 3];
            for y in by * f..(by + 1) * f {
                for x in bx * f..(bx + 1) * f {
                    for c in 0..3 {
                        sum[c] += texels[y * w + x][c] as f64;
                    }
                }
            }
            sum.map(|s| s / (f * f) as f64)
        })
        .collect()
}

/// KHR_texture_basisu's payloads decode to the images they were made from: an ETC1S
/// (BasisLZ) and a UASTC (Zstandard) texture of Khronos' StainedGlassLamp against its PNG
/// textures, both averaged over blocks to 64 x 64 (block averages take out the codecs'
/// per-texel error and the KTX2 files' lower resolution). What remains is the codecs'
/// error, deterministic: 0.86 of 255 on average for ETC1S, 0.14 for UASTC; the bounds are
/// about twice that, while a wrong channel order, colour space or block layout is tens off.
#[test]
fn ktx2_basis_textures_decode_to_the_images_they_were_made_from() {
    for (ktx2, reference, size, mean_bound) in [
        ("etc1s_basecolor.ktx2", "etc1s_basecolor_64.png", 512, 2.0),
        ("uastc_orm.ktx2", "uastc_orm_64.png", 256, 0.3),
    ] {
        let bytes = std::fs::read(ktx2_asset(ktx2)).unwrap();
        let image = ingest::image::decode(&bytes).unwrap_or_else(|e| panic!("{ktx2}: {e}"));
        assert_eq!((image.width, image.height), (size, size), "{ktx2}");
        let Texels::Rgba8(texels) = &image.texels else {
            panic!("{ktx2}: not 8-bit texels");
        };
        assert!(texels.iter().all(|t| t[3] == 255), "{ktx2}: opaque");
        let png = ingest::image::decode(&std::fs::read(ktx2_asset(reference)).unwrap()).unwrap();
        let Texels::Rgba8(png) = &png.texels else {
            panic!("{reference}: not 8-bit texels");
        };
        let ours = block_means(image.width, texels);
        let (mut sum, mut worst) = (0.0f64, 0.0f64);
        for (i, p) in png.iter().enumerate() {
            for c in 0..3 {
                let d = (ours[i][c] - p[c] as f64).abs();
                sum += d;
                worst = worst.max(d);
            }
        }
        let mean = sum / (64.0 * 64.0 * 3.0);
        eprintln!("{ktx2}: mean |difference| {mean:.2}, largest {worst:.1} (of 255)");
        assert!(mean < mean_bound, "{ktx2}: mean difference {mean}");
    }
}

/// Corrupt and truncated KTX2 files end in an error, never a panic or a hang; a declared
/// size beyond the pixel limit is refused before anything is allocated.
#[test]
fn corrupt_ktx2_files_are_errors() {
    for name in ["etc1s_basecolor.ktx2", "uastc_orm.ktx2"] {
        let good = std::fs::read(ktx2_asset(name)).unwrap();
        for end in (0..good.len()).step_by(97) {
            assert!(
                ingest::image::decode(&good[..end]).is_err(),
                "{name} truncated to {end} bytes decoded"
            );
        }
        for bad in crate::common::damaged_copies(&good, 400) {
            if let Ok(image) = ingest::image::decode(&bad) {
                assert!(image.width * image.height > 0, "{name}");
            }
        }
        let mut huge = good.clone();
        huge[20..24].copy_from_slice(&65_536u32.to_le_bytes());
        huge[24..28].copy_from_slice(&65_536u32.to_le_bytes());
        let err = ingest::image::decode(&huge).err().unwrap();
        assert!(err.contains("65536x65536"), "{name}: {err}");
    }
}

/// What the texture memory is decided by: an image's decoded size from its header alone,
/// equal to what decoding gives, and never an overflow whatever the header declares.
#[test]
fn decoded_sizes_are_read_from_headers_alone() {
    use lucerna::ingest::image::{decode, decoded_bytes};
    let bytes_of = |texels: &Texels| match texels {
        Texels::Rgba8(t) => t.len() as u64 * 4,
        Texels::Rgba16(t) => t.len() as u64 * 8,
        Texels::RgbaF32(t) => t.len() as u64 * 16,
        Texels::Tiled(_) => unreachable!("decoding gives texels in memory"),
    };
    let mut png16 = Vec::new();
    let mut encoder = png::Encoder::new(&mut png16, 3, 2);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Sixteen);
    (encoder.write_header().unwrap())
        .write_image_data(&[7; 3 * 2 * 6])
        .unwrap();
    let files = [
        png16,
        std::fs::read(ktx2_asset("etc1s_basecolor.ktx2")).unwrap(),
        std::fs::read(ktx2_asset("etc1s_basecolor_64.png")).unwrap(),
    ];
    for bytes in &files {
        let image = decode(bytes).unwrap();
        assert_eq!(decoded_bytes(bytes), Some(bytes_of(&image.texels)));
    }
    assert_eq!(decoded_bytes(&files[0]), Some(3 * 2 * 8));
    // A KTX2 header declaring 2^32 - 1 texels a side: the most a u64 holds, not a wrap.
    let mut huge = files[1].clone();
    huge[20..28].copy_from_slice(&[0xff; 8]);
    assert_eq!(decoded_bytes(&huge), Some(u64::MAX));
    assert_eq!(decoded_bytes(b"not an image"), None);
}
