//! Image decoding for textures (PNG, JPEG) and environment maps (also OpenEXR), into
//! lucerna's texel storage.

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

fn check_size(width: u32, height: u32) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err("image has no pixels".into());
    }
    if width as u64 * height as u64 > MAX_PIXELS {
        return Err(format!(
            "image of {width}x{height} pixels is larger than the limit of {MAX_PIXELS} pixels"
        ));
    }
    Ok(())
}

/// Decodes PNG or JPEG bytes (recognised by their signature).
pub fn decode(bytes: &[u8]) -> Result<DecodedImage, String> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        decode_png(bytes)
    } else if bytes.starts_with(&[0xff, 0xd8]) {
        decode_jpeg(bytes)
    } else {
        Err("unsupported image format (PNG and JPEG are supported)".into())
    }
}

fn decode_png(bytes: &[u8]) -> Result<DecodedImage, String> {
    let mut decoder = png::Decoder::new(Cursor::new(bytes));
    decoder.set_limits(png::Limits { bytes: 1 << 31 });
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder
        .read_info()
        .map_err(|e| format!("invalid PNG: {e}"))?;
    let (width, height) = (reader.info().width, reader.info().height);
    check_size(width, height)?;
    let size = reader.output_buffer_size().ok_or("PNG too large")?;
    let mut buf = vec![0u8; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("invalid PNG: {e}"))?;
    let channels = info.color_type.samples();
    let n = (width * height) as usize;
    let texels = match info.bit_depth {
        png::BitDepth::Sixteen => {
            let value =
                |i: usize| u16::from_be_bytes([buf[2 * i], buf[2 * i + 1]]) as f32 / 65535.0;
            Texels::RgbaF32(
                (0..n)
                    .map(|p| expand(channels, |c| value(p * channels + c), 1.0))
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
    let pixels = decoder
        .decode()
        .map_err(|e| format!("invalid JPEG: {e:?}"))?;
    let info = decoder.info().ok_or("invalid JPEG: no header")?;
    let (width, height) = (info.width as u32, info.height as u32);
    check_size(width, height)?;
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

/// Reads an image file for an environment map: OpenEXR (linear), or PNG/JPEG.
pub fn read_file(path: &Path) -> Result<DecodedImage, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
    if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        return decode_exr(path);
    }
    decode(&bytes)
}

fn decode_exr(path: &Path) -> Result<DecodedImage, String> {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        path,
        |resolution, _| {
            let (w, h) = (resolution.width(), resolution.height());
            (w, vec![[0.0f32, 0.0, 0.0, 1.0]; w * h])
        },
        |(w, pixels): &mut (usize, Vec<[f32; 4]>), pos, (r, g, b, a): (f32, f32, f32, f32)| {
            pixels[pos.y() * *w + pos.x()] = [r, g, b, a];
        },
    )
    .map_err(|e| format!("invalid OpenEXR: {e}"))?;
    let size = image.layer_data.size;
    let (width, height) = (size.width() as u32, size.height() as u32);
    check_size(width, height)?;
    let texels = image.layer_data.channel_data.pixels.1;
    Ok(DecodedImage {
        width,
        height,
        texels: Texels::RgbaF32(texels),
    })
}
