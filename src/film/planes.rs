//! The film's layers as named 32-bit float planes over its window: what `output` writes to
//! an EXR and reads back from one, and what a film is restored from.

use super::window::Window;

/// An image's pixels as lucerna reads and writes them: named 32-bit float planes over a
/// data window of the whole image (the display window, whose origin is 0, 0).
#[derive(Clone, Debug)]
pub struct Planes {
    /// Size of the whole image, overscan included.
    pub display: (u32, u32),
    /// The pixels present (all of the image but for crop renders), in `display`.
    pub window: Window,
    /// Pixels of `display` beyond the edges of the image proper (the EXR's display window
    /// is `display` without them; its data window reaches into them).
    pub overscan: crate::camera::Overscan,
    /// Channel name (`layer.C`, the beauty unprefixed) and its row-major plane over the
    /// window.
    pub channels: Vec<(String, Vec<f32>)>,
}

impl Planes {
    /// The plane of channel `name`, if the image has it.
    pub fn channel(&self, name: &str) -> Option<&[f32]> {
        self.channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, p)| p.as_slice())
    }
}

/// Interleaves planes (one per channel) into row-major pixels: what OIDN and numpy take.
pub fn interleave(planes: &[&[f32]]) -> Vec<f32> {
    let n = planes.first().map_or(0, |p| p.len());
    let mut pixels = Vec::with_capacity(n * planes.len());
    for i in 0..n {
        pixels.extend(planes.iter().map(|p| p[i]));
    }
    pixels
}
