//! A tone-mapped preview: the beauty clamped to [0, 1] and sRGB-encoded into an 8-bit PNG.

use super::Film;
use super::aov::Aov;
use crate::color::linear_to_srgb;
use crate::error::{Error, Result};
use std::path::Path;

/// Writes the beauty of `film` as an sRGB PNG at `path`, atomically.
pub fn write(path: &Path, film: &Film) -> Result<()> {
    let planes = film.planes(Aov::Beauty);
    let n = (film.width * film.height) as usize;
    let mut bytes = Vec::with_capacity(n * 3);
    for i in 0..n {
        for plane in &planes[..3] {
            let v = linear_to_srgb(plane[i].clamp(0.0, 1.0));
            bytes.push((v * 255.0 + 0.5) as u8);
        }
    }
    super::write_atomically(path, |file| {
        let err = |e: png::EncodingError| Error::other(path, "PNG", e.to_string());
        let mut encoder = png::Encoder::new(file, film.width, film.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = encoder.write_header().map_err(err)?;
        writer.write_image_data(&bytes).map_err(err)?;
        writer.finish().map_err(err)
    })
}
