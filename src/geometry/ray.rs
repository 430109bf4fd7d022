//! Rays and robust ray origins.

use glam::Vec3;

/// A ray `origin + t * dir` for `t` in `(0, tmax)`. `dir` need not be normalised.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tmax: f32,
}

impl Ray {
    /// A ray without an upper bound.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir,
            tmax: f32::INFINITY,
        }
    }

    /// Point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + t * self.dir
    }
}

/// Moves a surface point off its surface along the geometric normal `n` (pointing to the side
/// the new ray leaves towards), so that the new ray cannot hit the surface it starts on.
///
/// Wächter & Binder, "A Fast and Robust Method for Avoiding Self-Intersection" (Ray Tracing
/// Gems, ch. 6): the offset is a fixed number of ulps of the coordinate, so it scales with the
/// magnitude of the point, with an absolute offset near the origin where ulps vanish. Render
/// space is normalised to the scene's size (see `world::RenderSpace`), which makes the absolute
/// part relative to the scene too.
#[inline]
pub fn offset_ray_origin(p: Vec3, n: Vec3) -> Vec3 {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    let offset_axis = |p: f32, n: f32| -> f32 {
        if p.abs() < ORIGIN {
            p + FLOAT_SCALE * n
        } else {
            let of_i = (INT_SCALE * n) as i32;
            let of_i = if p < 0.0 { -of_i } else { of_i };
            f32::from_bits((p.to_bits() as i32).wrapping_add(of_i) as u32)
        }
    };
    Vec3::new(
        offset_axis(p.x, n.x),
        offset_axis(p.y, n.y),
        offset_axis(p.z, n.z),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_moves_to_the_normal_side_at_every_magnitude() {
        for scale in [1e-3f32, 0.02, 0.5, 1.0, 7.0, 1e3] {
            let p = Vec3::new(0.3, -0.7, 0.9) * scale;
            for n in [Vec3::X, -Vec3::Y, Vec3::new(1.0, 1.0, 1.0).normalize()] {
                let q = offset_ray_origin(p, n);
                assert!((q - p).dot(n) > 0.0, "scale {scale} n {n}");
                assert!((q - p).length() < 1e-3 * scale.max(1.0));
            }
        }
    }
}
