//! Image decoding for textures and environment maps, into lucerna's texel storage: PNG and
//! JPEG (the glTF core formats), WebP (EXT_texture_webp), KTX2 with Basis Universal
//! payloads (KHR_texture_basisu: ETC1S and UASTC, transcoded at load), and the formats
//! production textures and HDRIs come in: OpenEXR, Radiance HDR and TIFF (8-bit, 16-bit and
//! float).
//! Every decoder reads the image's header first and checks its size against the pixel and
//! memory limits before it allocates the pixels.

use crate::scene::Texels;
use std::io::Cursor;
use std::path::Path;

/// A decoded image.
pub struct DecodedImage {
    pub width: u32,
    pub height: u32,
    pub texels: Texels,
}

/// Largest image accepted, in pixels (a 16k × 16k texture).
const MAX_PIXELS: u64 = 1 << 28;

/// Checks an image's declared size before anything is decoded: at most [`MAX_PIXELS`], and
/// its decoding peak (`bytes_per_pixel`: the decoder's buffer and lucerna's texels) within
/// the memory limit ([`crate::memory::check_allocation`]).
fn check_size(width: u32, height: u32, bytes_per_pixel: u64) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err("image has no pixels".into());
    }
    let pixels = width as u64 * height as u64;
    if pixels > MAX_PIXELS {
        return Err(format!(
            "image of {width}x{height} pixels is larger than the limit of {MAX_PIXELS} pixels"
        ));
    }
    crate::memory::check_allocation(
        pixels * bytes_per_pixel,
        &format!("an image of {width}x{height} pixels"),
    )
}

/// Decodes image bytes, recognised by their signature.
pub fn decode(bytes: &[u8]) -> Result<DecodedImage, String> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        decode_png(bytes)
    } else if bytes.starts_with(&[0xff, 0xd8]) {
        decode_jpeg(bytes)
    } else if bytes.len() >= 12 && bytes.starts_with(b"RIFF") && &bytes[8..12] == b"WEBP" {
        decode_webp(bytes)
    } else if bytes.starts_with(&EXR_MAGIC) {
        decode_exr(bytes)
    } else if bytes.starts_with(b"#?RADIANCE") || bytes.starts_with(b"#?RGBE") {
        decode_with_image(bytes, image::ImageFormat::Hdr, "Radiance HDR")
    } else if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        decode_with_image(bytes, image::ImageFormat::Tiff, "TIFF")
    } else if bytes.starts_with(KTX2_MAGIC) {
        decode_ktx2(bytes)
    } else {
        Err(
            "unsupported image format (PNG, JPEG, WebP, KTX2 with Basis Universal, OpenEXR, \
             Radiance HDR and TIFF are supported)"
                .into(),
        )
    }
}

/// The bytes the texels of the image `bytes` will hold once decoded, from its header alone
/// (without decoding it): what [`decode`] will return, so that a scene's textures can be
/// measured before any is decoded. `None` where the header cannot be read (decoding will
/// say why).
pub fn decoded_bytes(bytes: &[u8]) -> Option<u64> {
    let (width, height, texel_bytes) = if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        let reader = png::Decoder::new(Cursor::new(bytes)).read_info().ok()?;
        let info = reader.info();
        let sixteen = info.bit_depth == png::BitDepth::Sixteen;
        (info.width, info.height, if sixteen { 8 } else { 4 })
    } else if bytes.starts_with(&[0xff, 0xd8]) {
        let mut decoder = zune_jpeg::JpegDecoder::new(Cursor::new(bytes));
        decoder.decode_headers().ok()?;
        let (w, h) = decoder.dimensions()?;
        (w as u32, h as u32, 4)
    } else if bytes.len() >= 12 && bytes.starts_with(b"RIFF") && &bytes[8..12] == b"WEBP" {
        let decoder = image_webp::WebPDecoder::new(Cursor::new(bytes)).ok()?;
        let (w, h) = decoder.dimensions();
        (w, h, 4)
    } else if bytes.starts_with(&EXR_MAGIC) {
        let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).ok()?;
        let size = meta.headers.first()?.layer_size;
        (size.width() as u32, size.height() as u32, 16)
    } else if bytes.starts_with(b"#?RADIANCE") || bytes.starts_with(b"#?RGBE") {
        let format = image::ImageFormat::Hdr;
        let (w, h) = image::ImageReader::with_format(Cursor::new(bytes), format)
            .into_dimensions()
            .ok()?;
        (w, h, 16)
    } else if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        use image::ImageDecoder;
        let decoder = image::ImageReader::with_format(Cursor::new(bytes), image::ImageFormat::Tiff)
            .into_decoder()
            .ok()?;
        let (w, h) = decoder.dimensions();
        let colour = decoder.color_type();
        let texel_bytes = match colour.bytes_per_pixel() / colour.channel_count() {
            4 => 16,
            2 => 8,
            _ => 4,
        };
        (w, h, texel_bytes)
    } else if bytes.starts_with(KTX2_MAGIC) {
        // Basis Universal LDR payloads become 8-bit texels (HDR ones are rare in delivery).
        (le_u32(bytes, 20)?, le_u32(bytes, 24)?, 4)
    } else {
        return None;
    };
    // Headers may declare any size (decoding refuses what is too large): never overflow.
    Some((width as u64 * height as u64).saturating_mul(texel_bytes))
}

const KTX2_MAGIC: &[u8] = b"\xabKTX 20\xbb\r\n\x1a\n";

/// The little-endian u32 at byte `at`, if the bytes reach that far.
fn le_u32(bytes: &[u8], at: usize) -> Option<u32> {
    bytes
        .get(at..at + 4)
        .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
}

/// Checks a KTX2 file's index before the transcoder reads it: every region it names (the
/// data format descriptor, key/value data, supercompression global data and each level)
/// lies inside the file, and no level claims to inflate to more than the largest payload
/// its size allows (16 bytes a 4 x 4 block per layer and face, UASTC's and ASTC's rate).
/// The transcoder trusts these numbers (a level's inflated size is allocated as written),
/// so a corrupt index would otherwise end the process.
fn check_ktx2_layout(bytes: &[u8], width: u32, height: u32) -> Result<(), String> {
    let invalid = |what: &str| Err(format!("invalid KTX2: {what}"));
    let u32_at = |at: usize| le_u32(bytes, at).map(u64::from);
    let u64_at = |at: usize| {
        bytes
            .get(at..at + 8)
            .map(|b| u64::from_le_bytes(b.try_into().unwrap()))
    };
    let (Some(layers), Some(faces), Some(levels)) = (u32_at(32), u32_at(36), u32_at(40)) else {
        return invalid("truncated header");
    };
    if faces != 1 && faces != 6 || layers > 2048 || levels > 32 {
        return invalid("the header's layer, face or level count is out of range");
    }
    let len = bytes.len() as u64;
    let inside = |offset: Option<u64>, length: Option<u64>| match (offset, length) {
        (Some(o), Some(l)) => o.checked_add(l).is_some_and(|end| end <= len),
        _ => false,
    };
    if !inside(u32_at(48), u32_at(52))
        || !inside(u32_at(56), u32_at(60))
        || !inside(u64_at(64), u64_at(72))
    {
        return invalid("a header region lies outside the file");
    }
    for level in 0..levels.max(1) {
        let at = 80 + 24 * level as usize;
        if !inside(u64_at(at), u64_at(at + 8)) {
            return invalid(&format!("level {level} lies outside the file"));
        }
        let blocks = |n: u32| ((n >> level).max(1) as u64).div_ceil(4);
        let most = blocks(width) * blocks(height) * 16 * layers.max(1) * faces;
        match u64_at(at + 16) {
            Some(inflated) if inflated <= most => {}
            _ => {
                return invalid(&format!(
                    "level {level} claims more data than its size holds"
                ));
            }
        }
    }
    Ok(())
}

/// KTX2 images whose payload is Basis Universal (ETC1S with BasisLZ, UASTC with or without
/// Zstandard: what KHR_texture_basisu allows), transcoded by the pure-Rust `basisu`
/// transcoder: the base level to 8-bit RGBA (LDR sources) or half floats (UASTC HDR). The
/// texel values are the file's (sRGB-encoded colour stays encoded, as a PNG's does); the
/// material decides how a slot's texels are read. Other mip levels are not read.
///
/// The transcoder is young and corrupt files are what it is least tested on, so a panic
/// inside it is caught and reported as an invalid file rather than ending the render.
fn decode_ktx2(bytes: &[u8]) -> Result<DecodedImage, String> {
    use basisu::{DecodeFlags, SourceFormat, TargetFormat, Transcoder};
    // Fields of the 80-byte header: vkFormat at 12, pixelWidth and pixelHeight at 20 and 24.
    let field = |at: usize| le_u32(bytes, at);
    let vk_format = field(12).ok_or("invalid KTX2: truncated header")?;
    if vk_format != 0 {
        return Err(format!(
            "KTX2 image of Vulkan format {vk_format}: only Basis Universal payloads \
             (vkFormat 0, as KHR_texture_basisu requires) are supported"
        ));
    }
    // The declared size is checked before the transcoder parses (and allocates for) it.
    let (width, height) = match (field(20), field(24)) {
        (Some(w), Some(h)) => (w, h),
        _ => return Err("invalid KTX2: truncated header".into()),
    };
    check_size(width, height, 4 + 4)?;
    check_ktx2_layout(bytes, width, height)?;
    let outcome = std::panic::catch_unwind(|| -> Result<DecodedImage, String> {
        let invalid = |e: basisu::Error| format!("invalid KTX2 (Basis Universal): {e:?}");
        let transcoder = Transcoder::new(bytes).map_err(invalid)?;
        if transcoder.is_video() || transcoder.layer_count() > 1 || transcoder.face_count() > 1 {
            return Err(
                "KTX2 image is a video, an array or a cube map: only 2D textures are supported"
                    .into(),
            );
        }
        let info = transcoder.image_level_info(0).map_err(invalid)?;
        if (info.width, info.height) != (width, height) {
            return Err("invalid KTX2: the base level's size is not the header's".into());
        }
        let hdr = matches!(
            transcoder.source_format(),
            SourceFormat::UastcHdr4x4 | SourceFormat::AstcHdr6x6 | SourceFormat::UastcHdr6x6
        );
        // The transcoder's output and lucerna's texels.
        check_size(width, height, if hdr { 8 + 16 } else { 4 + 4 })?;
        let target = if hdr {
            TargetFormat::RgbaHalf
        } else {
            TargetFormat::Rgba32
        };
        let out = transcoder
            .transcode(0, target, DecodeFlags::NONE)
            .map_err(invalid)?;
        let texels = if hdr {
            Texels::RgbaF32(
                out.chunks_exact(8)
                    .map(|p| {
                        std::array::from_fn(|c| {
                            half::f16::from_le_bytes([p[2 * c], p[2 * c + 1]]).to_f32()
                        })
                    })
                    .collect(),
            )
        } else {
            Texels::Rgba8(
                out.chunks_exact(4)
                    .map(|p| [p[0], p[1], p[2], p[3]])
                    .collect(),
            )
        };
        Ok(DecodedImage {
            width,
            height,
            texels,
        })
    });
    outcome.unwrap_or_else(|_| {
        Err("invalid KTX2 (Basis Universal): the transcoder failed on its data".into())
    })
}

const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];

/// WebP (lossy or lossless, with or without alpha) with the `image-webp` decoder.
fn decode_webp(bytes: &[u8]) -> Result<DecodedImage, String> {
    let mut decoder = image_webp::WebPDecoder::new(Cursor::new(bytes))
        .map_err(|e| format!("invalid WebP: {e}"))?;
    let (width, height) = decoder.dimensions();
    let channels = if decoder.has_alpha() { 4 } else { 3 };
    check_size(width, height, channels as u64 + 4)?;
    let size = decoder
        .output_buffer_size()
        .ok_or("invalid WebP: image too large")?;
    let mut buf = vec![0u8; size];
    decoder
        .read_image(&mut buf)
        .map_err(|e| format!("invalid WebP: {e}"))?;
    let texels = buf
        .chunks_exact(channels)
        .map(|p| expand(channels, |c| p[c], 255))
        .collect();
    Ok(DecodedImage {
        width,
        height,
        texels: Texels::Rgba8(texels),
    })
}

/// Radiance HDR and TIFF through the `image` crate: 8-bit images stay 8-bit, 16-bit ones
/// 16-bit, float ones become linear floats.
fn decode_with_image(
    bytes: &[u8],
    format: image::ImageFormat,
    name: &str,
) -> Result<DecodedImage, String> {
    use image::ImageDecoder;
    let invalid = |e: image::ImageError| format!("invalid {name}: {e}");
    let mut reader = image::ImageReader::with_format(Cursor::new(bytes), format);
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(1 << 34);
    reader.limits(limits);
    let decoder = reader.into_decoder().map_err(invalid)?;
    let (width, height) = decoder.dimensions();
    let colour = decoder.color_type();
    let float = matches!(colour, image::ColorType::Rgb32F | image::ColorType::Rgba32F);
    let sixteen = colour.bytes_per_pixel() / colour.channel_count() == 2;
    let texel_bytes = if float {
        16
    } else if sixteen {
        8
    } else {
        4
    };
    check_size(width, height, colour.bytes_per_pixel() as u64 + texel_bytes)?;
    let image = image::DynamicImage::from_decoder(decoder).map_err(invalid)?;
    let texels = if float {
        Texels::RgbaF32(image.into_rgba32f().pixels().map(|p| p.0).collect())
    } else if sixteen {
        Texels::Rgba16(image.into_rgba16().pixels().map(|p| p.0).collect())
    } else {
        Texels::Rgba8(image.into_rgba8().pixels().map(|p| p.0).collect())
    };
    Ok(DecodedImage {
        width,
        height,
        texels,
    })
}

fn decode_png(bytes: &[u8]) -> Result<DecodedImage, String> {
    let mut decoder = png::Decoder::new(Cursor::new(bytes));
    decoder.set_limits(png::Limits { bytes: 1 << 31 });
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder
        .read_info()
        .map_err(|e| format!("invalid PNG: {e}"))?;
    let (width, height) = (reader.info().width, reader.info().height);
    let size = reader.output_buffer_size().ok_or("PNG too large")?;
    // The decoded buffer, then RGBA texels of 8 or 16 bits a channel.
    let texel_bytes = if reader.info().bit_depth == png::BitDepth::Sixteen {
        8
    } else {
        4
    };
    check_size(
        width,
        height,
        (size as u64).div_ceil(width.max(1) as u64 * height.max(1) as u64) + texel_bytes,
    )?;
    let mut buf = vec![0u8; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("invalid PNG: {e}"))?;
    let channels = info.color_type.samples();
    let n = (width * height) as usize;
    let texels = match info.bit_depth {
        png::BitDepth::Sixteen => {
            let value = |i: usize| u16::from_be_bytes([buf[2 * i], buf[2 * i + 1]]);
            Texels::Rgba16(
                (0..n)
                    .map(|p| expand(channels, |c| value(p * channels + c), u16::MAX))
                    .collect(),
            )
        }
        _ => Texels::Rgba8(
            (0..n)
                .map(|p| expand(channels, |c| buf[p * channels + c], 255))
                .collect(),
        ),
    };
    Ok(DecodedImage {
        width,
        height,
        texels,
    })
}

/// Grey, grey+alpha, RGB or RGBA samples to RGBA.
fn expand<T: Copy>(channels: usize, get: impl Fn(usize) -> T, opaque: T) -> [T; 4] {
    match channels {
        1 => [get(0), get(0), get(0), opaque],
        2 => [get(0), get(0), get(0), get(1)],
        3 => [get(0), get(1), get(2), opaque],
        _ => [get(0), get(1), get(2), get(3)],
    }
}

fn decode_jpeg(bytes: &[u8]) -> Result<DecodedImage, String> {
    use zune_jpeg::zune_core::{colorspace::ColorSpace, options::DecoderOptions};
    let options = DecoderOptions::default()
        .jpeg_set_out_colorspace(ColorSpace::RGBA)
        .set_max_width(1 << 16)
        .set_max_height(1 << 16);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(Cursor::new(bytes), options);
    decoder
        .decode_headers()
        .map_err(|e| format!("invalid JPEG: {e:?}"))?;
    let info = decoder.info().ok_or("invalid JPEG: no header")?;
    // The decoder's RGBA output, then as many bytes of texels.
    check_size(info.width as u32, info.height as u32, 8)?;
    let pixels = decoder
        .decode()
        .map_err(|e| format!("invalid JPEG: {e:?}"))?;
    let info = decoder.info().ok_or("invalid JPEG: no header")?;
    let (width, height) = (info.width as u32, info.height as u32);
    if pixels.len() < (width * height * 4) as usize {
        return Err("invalid JPEG: truncated pixel data".into());
    }
    let texels = pixels
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect();
    Ok(DecodedImage {
        width,
        height,
        texels: Texels::Rgba8(texels),
    })
}

/// Reads an image file (an environment map), in any format [`decode`] reads.
pub fn read_file(path: &Path) -> Result<DecodedImage, String> {
    decode(&crate::files::read_input(path)?)
}

/// OpenEXR: the first RGBA layer, as linear floats.
fn decode_exr(bytes: &[u8]) -> Result<DecodedImage, String> {
    use exr::prelude::*;
    // The header first: the data window decides what decoding allocates.
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false)
        .map_err(|e| format!("invalid OpenEXR: {e}"))?;
    for header in &meta.headers {
        let size = header.layer_size;
        let (w, h) = (size.width() as u64, size.height() as u64);
        if w > u32::MAX as u64 || h > u32::MAX as u64 {
            return Err(format!(
                "OpenEXR data window of {w}x{h} pixels is too large"
            ));
        }
        // Float RGBA texels, and the decoder's lines of up to 4 float channels.
        check_size(w as u32, h as u32, 32)?;
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |resolution, _| {
                let (w, h) = (resolution.width(), resolution.height());
                (w, vec![[0.0f32, 0.0, 0.0, 1.0]; w * h])
            },
            |(w, pixels): &mut (usize, Vec<[f32; 4]>), pos, (r, g, b, a): (f32, f32, f32, f32)| {
                pixels[pos.y() * *w + pos.x()] = [r, g, b, a];
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| format!("invalid OpenEXR: {e}"))?;
    let size = image.layer_data.size;
    let (width, height) = (size.width() as u32, size.height() as u32);
    let texels = image.layer_data.channel_data.pixels.1;
    Ok(DecodedImage {
        width,
        height,
        texels: Texels::RgbaF32(texels),
    })
}
