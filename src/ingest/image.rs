//! Image decoding for textures and environment maps, into lucerna's texel storage: PNG and
//! JPEG (the glTF core formats), WebP (EXT_texture_webp), and the formats production
//! textures and HDRIs come in: OpenEXR, Radiance HDR and TIFF (8-bit, 16-bit and float).
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
    } else if bytes.starts_with(b"\xabKTX 20\xbb") {
        Err(
            "KTX2 (Basis Universal) images cannot be decoded: lucerna has no Basis \
             Universal transcoder; export PNG, JPEG or WebP textures"
                .into(),
        )
    } else {
        Err(
            "unsupported image format (PNG, JPEG, WebP, OpenEXR, Radiance HDR and TIFF are \
             supported)"
                .into(),
        )
    }
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
