//! Render space: world space translated to the centre of the scene's bounds and scaled by a
//! power of two (exact in binary) so that the bounds fit in [-1, 1]. Both are applied in
//! double precision before rounding to f32, so a scene placed 1e7 units from the origin
//! renders like the same scene at the origin, and every absolute epsilon (ray offsets near
//! the origin) is relative to the scene's size.

use glam::{DMat4, DVec3, Vec3};

/// World space to render space: `(p - centre) * scale`, `scale` a power of two.
#[derive(Clone, Copy, Debug)]
pub struct RenderSpace {
    pub centre: DVec3,
    pub scale: f64,
}

impl RenderSpace {
    /// The render space for world bounds `(lo, hi)`.
    pub fn from_bounds(lo: DVec3, hi: DVec3) -> Self {
        let centre = (lo + hi) * 0.5;
        let half_extent = ((hi - lo) * 0.5).max_element();
        let scale = if half_extent > 0.0 && half_extent.is_finite() {
            (-half_extent.log2().ceil()).exp2()
        } else {
            1.0
        };
        Self { centre, scale }
    }

    /// World to render space as a matrix.
    pub fn matrix(&self) -> DMat4 {
        DMat4::from_scale(DVec3::splat(self.scale)) * DMat4::from_translation(-self.centre)
    }

    /// A world point in render space.
    #[inline]
    pub fn point(&self, p: DVec3) -> Vec3 {
        ((p - self.centre) * self.scale).as_vec3()
    }

    /// A render-space point in world space.
    #[inline]
    pub fn to_world(&self, p: Vec3) -> DVec3 {
        p.as_dvec3() / self.scale + self.centre
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_space_is_centred_and_scaled_by_a_power_of_two() {
        let s = RenderSpace::from_bounds(
            DVec3::new(1e7, 1e7, 1e7),
            DVec3::new(1e7 + 0.5, 1e7 + 0.3, 1e7 + 0.1),
        );
        assert_eq!(s.scale, 4.0);
        let p = s.point(DVec3::new(1e7 + 0.5, 1e7, 1e7 + 0.05));
        assert!((p - Vec3::new(1.0, -0.6, 0.0)).length() < 1e-6, "{p}");
        assert!((s.to_world(p) - DVec3::new(1e7 + 0.5, 1e7, 1e7 + 0.05)).length() < 1e-7);
    }
}
