//! Pixel reconstruction filters, applied by filter importance sampling: each camera sample
//! is placed with a density proportional to the (non-negative) filter and counts fully for
//! its own pixel. Pixels stay independent, so per-pixel variance estimates and merging of
//! partial renders remain exact.

use crate::sampling::distribution::Distribution1D;
use glam::Vec2;

/// A pixel filter.
#[derive(Clone, Debug)]
pub enum PixelFilter {
    /// Uniform over the pixel (width 1).
    Box,
    /// The 4-term Blackman-Harris window over `width` pixels (Cycles' default, width 1.5).
    BlackmanHarris { width: f32, table: Distribution1D },
}

const TABLE_SIZE: usize = 256;

impl PixelFilter {
    /// The box filter.
    pub fn box_filter() -> Self {
        Self::Box
    }

    /// A Blackman-Harris filter `width` pixels wide.
    pub fn blackman_harris(width: f32) -> Self {
        let values: Vec<f32> = (0..TABLE_SIZE)
            .map(|i| {
                let x = (i as f64 + 0.5) / TABLE_SIZE as f64; // window position in [0, 1]
                let t = 2.0 * std::f64::consts::PI * x;
                (0.35875 - 0.48829 * t.cos() + 0.14128 * (2.0 * t).cos()
                    - 0.01168 * (3.0 * t).cos()) as f32
            })
            .collect();
        Self::BlackmanHarris {
            width,
            table: Distribution1D::new(&values),
        }
    }

    /// Parses `box`, `blackman-harris` or `blackman-harris:WIDTH`.
    pub fn parse(s: &str) -> Option<Self> {
        match s.split_once(':') {
            None if s == "box" => Some(Self::box_filter()),
            None if s == "blackman-harris" => Some(Self::blackman_harris(1.5)),
            Some(("blackman-harris", w)) => w
                .parse::<f32>()
                .ok()
                .filter(|w| w.is_finite() && *w > 0.0 && *w <= 16.0)
                .map(Self::blackman_harris),
            _ => None,
        }
    }

    /// Offset from the pixel centre for a uniform sample `u`.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Vec2 {
        match self {
            Self::Box => u - Vec2::splat(0.5),
            Self::BlackmanHarris { width, table } => {
                let x = table.sample(u.x).0;
                let y = table.sample(u.y).0;
                (Vec2::new(x, y) - Vec2::splat(0.5)) * *width
            }
        }
    }

    /// The textual form [`PixelFilter::parse`] reads.
    pub fn describe(&self) -> String {
        match self {
            Self::Box => "box".into(),
            Self::BlackmanHarris { width, .. } => format!("blackman-harris:{width}"),
        }
    }
}
