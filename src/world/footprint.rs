//! Texture footprints: how much of a surface one sample of a pixel stands for where its
//! path meets it, so that textures are looked up filtered over that area instead of at a
//! point (aliasing at few samples, and a MIP level that fits, as pbrt-v4, Cycles and
//! Arnold do).
//!
//! A path carries a ray cone (Akenine-Möller et al., "Improved Shader and Texture Level of
//! Detail Using Ray Cones", JCGT 2021): its width where the ray starts and its spread
//! angle. A camera ray starts as a point that spreads by the angle of a pixel (an
//! orthographic camera's, as wide as a pixel without spreading). A specular bounce keeps
//! the spread (a flat mirror's image; curvature is not followed, so a curved mirror's
//! reflection is filtered less than it could be, never more). A bounce off a lobe with
//! extent widens the spread to the half-angle of the cone that holds one sample's share of
//! the lobe: a sample of density `p` stands for a solid angle of `1 / p`, a cone of
//! half-angle `sqrt(1 / (π p))`, so diffuse bounces look textures up coarsely and sharp
//! glossy ones finely (the half-angle, not the full angle: the blur of lookups after a
//! bounce is a bias, kept small). Those lookups take the footprint as a circle: one probe.
//!
//! Where the cone meets a triangle, its circular cross-section projects to an ellipse on
//! the triangle's plane (stretched by `1 / |cos θ|` along the ray's direction in the plane),
//! which the triangle's texture coordinates map to the two axes of a footprint in texture
//! space for each UV set (`scene::texture` filters over it).
//!
//! Many samples per pixel average a pixel's texture detail themselves: filtering each over
//! the whole pixel would blur twice. As pbrt-v4 does with its ray differentials, the cones
//! are narrowed by `1 / sqrt(spp)`: at 4 samples a lookup covers half a pixel, at 1024 a
//! 32nd (no less than a 64th; a 32nd for renders without a sample count), so converged
//! images match full-resolution lookups while images of few samples lose their aliasing.
//! (pbrt-v4 stops at an eighth; on the checkerboard plane that blur is a bias twice the
//! error of 1024 bilinear samples.)

use crate::geometry::cone::RayCone;
use glam::{Vec2, Vec3};

/// How a render's paths size their texture footprints.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Footprints {
    /// The cone of a camera ray.
    pub camera: RayCone,
    /// What lobe cones are scaled by (zero: bounces do not widen cones).
    pub lobe_scale: f32,
}

impl Footprints {
    /// Textures looked up at points, as without filtering.
    pub const OFF: Footprints = Footprints {
        camera: RayCone::POINT,
        lobe_scale: 0.0,
    };

    /// Footprints for a render of `spp` samples per pixel (`None`: many) through a camera
    /// whose rays spread by `pixel` (the cone of one pixel, unscaled).
    pub fn for_samples(pixel: RayCone, spp: Option<u32>) -> Self {
        let scale = spp.map_or(1.0 / 32.0, |n| {
            (1.0 / (n.max(1) as f32).sqrt()).max(1.0 / 64.0)
        });
        Self {
            camera: RayCone {
                width: pixel.width * scale,
                spread: pixel.spread * scale,
            },
            lobe_scale: scale,
        }
    }

    /// True if rays carry cones at all.
    #[inline]
    pub fn on(&self) -> bool {
        self.camera != RayCone::POINT || self.lobe_scale > 0.0
    }
}

/// The footprint, in texture coordinates, of a cone of width `width` meeting the plane of
/// the triangle `p` (render space) with texture coordinates `uv` along unit direction
/// `dir`: the images of the projected ellipse's two axes (full widths), or with `isotropic`
/// of the circle around it (one probe instead of several: cones after a rough bounce,
/// whose detail that bounce blurs anyway). Zero for a degenerate triangle.
pub fn triangle_footprint(
    p: [Vec3; 3],
    uv: [Vec2; 3],
    dir: Vec3,
    width: f32,
    isotropic: bool,
) -> [Vec2; 2] {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let n = e1.cross(e2);
    let area2 = n.length();
    if !(area2 > 0.0) || !(width > 0.0) {
        return [Vec2::ZERO; 2];
    }
    let n = n / area2;
    let cos = n.dot(dir).abs().max(1e-4);
    // Across the ray's direction in the plane, and along it (stretched by 1 / cos).
    let across = n
        .cross(dir)
        .normalize_or(crate::geometry::frame::Frame::from_normal(n).s);
    let along = across.cross(n);
    let stretched = width / cos;
    let axes = [
        across * if isotropic { stretched } else { width },
        along * stretched,
    ];
    // In-plane vector v = s e1 + t e2: solved through the Gram matrix of the edges.
    let (g11, g12, g22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let det = g11 * g22 - g12 * g12;
    if !(det > 0.0) {
        return [Vec2::ZERO; 2];
    }
    let (duv1, duv2) = (uv[1] - uv[0], uv[2] - uv[0]);
    axes.map(|v| {
        let (a, b) = (e1.dot(v), e2.dot(v));
        let s = (g22 * a - g12 * b) / det;
        let t = (g11 * b - g12 * a) / det;
        let d = duv1 * s + duv2 * t;
        if d.is_finite() { d } else { Vec2::ZERO }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cone_seen_head_on_covers_its_width_in_texture_space() {
        // A unit square's triangle with uv = xy: a cone of width 0.1 seen along -z covers
        // 0.1 in both axes.
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let uv = [Vec2::ZERO, Vec2::X, Vec2::Y];
        let [a, b] = triangle_footprint(p, uv, -Vec3::Z, 0.1, false);
        assert!((a.length() - 0.1).abs() < 1e-6 && (b.length() - 0.1).abs() < 1e-6);
        assert!(a.dot(b).abs() < 1e-6);
    }

    #[test]
    fn a_grazing_cone_stretches_along_the_ray() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        // Scaled uv (2 per unit) on the plane, the ray at 60° from the normal in x-z.
        let uv = [Vec2::ZERO, Vec2::X * 2.0, Vec2::Y * 2.0];
        let dir = Vec3::new(60f32.to_radians().sin(), 0.0, -60f32.to_radians().cos());
        let [across, along] = triangle_footprint(p, uv, dir, 0.1, false);
        let [wide, _] = triangle_footprint(p, uv, dir, 0.1, true);
        assert!((wide.length() - 0.4).abs() < 1e-5, "isotropic: {wide}");
        assert!((across.length() - 0.2).abs() < 1e-5, "{across}");
        assert!((along.length() - 0.4).abs() < 1e-5, "{along}");
        assert!(
            along.y.abs() < 1e-6,
            "along the ray's direction in the plane: {along}"
        );
    }

    #[test]
    fn samples_narrow_the_cones() {
        let pixel = RayCone {
            width: 0.0,
            spread: 0.002,
        };
        assert_eq!(Footprints::for_samples(pixel, Some(1)).camera.spread, 0.002);
        assert_eq!(Footprints::for_samples(pixel, Some(4)).camera.spread, 0.001);
        assert_eq!(
            Footprints::for_samples(pixel, Some(1024)).camera.spread,
            0.0000625
        );
        assert_eq!(
            Footprints::for_samples(pixel, Some(1 << 20)).camera.spread,
            0.002 / 64.0
        );
        assert!(!Footprints::OFF.on());
    }
}
