//! Sampling area lights uniformly in the solid angle they subtend: spherical triangles
//! (Arvo 1995, "Stratified Sampling of Spherical Triangles") and the cone of a sphere.
//!
//! A spherical triangle too small or too large for floats (under 3e-4 sr or over 6.22 sr,
//! pbrt-v4's bounds) is sampled by area instead; [`triangle_uses_solid_angle`] decides, and
//! sampling and density evaluation both ask it, so the two always agree.

use crate::geometry::frame::Frame;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Smallest spherical triangle sampled by solid angle.
pub const MIN_SOLID_ANGLE: f32 = 3e-4;
/// Largest spherical triangle sampled by solid angle.
pub const MAX_SOLID_ANGLE: f32 = 6.22;

/// Solid angle of triangle `t` seen from `p` (Van Oosterom & Strackee 1983).
#[inline]
pub fn triangle_solid_angle(p: Vec3, t: &[Vec3; 3]) -> f32 {
    let a = (t[0] - p).normalize_or_zero();
    let b = (t[1] - p).normalize_or_zero();
    let c = (t[2] - p).normalize_or_zero();
    let numerator = a.dot(b.cross(c)).abs();
    let denominator = 1.0 + a.dot(b) + b.dot(c) + c.dot(a);
    (2.0 * numerator.atan2(denominator)).abs()
}

/// Whether triangle `t` is sampled by solid angle from `p` (else by area).
#[inline]
pub fn triangle_uses_solid_angle(p: Vec3, t: &[Vec3; 3]) -> Option<f32> {
    let omega = triangle_solid_angle(p, t);
    (omega.is_finite() && (MIN_SOLID_ANGLE..=MAX_SOLID_ANGLE).contains(&omega)).then_some(omega)
}

/// A direction from `p` uniform over the spherical triangle of `t` (Arvo's algorithm).
pub fn sample_spherical_triangle(p: Vec3, t: &[Vec3; 3], u: Vec2) -> Option<Vec3> {
    let a = (t[0] - p).normalize();
    let b = (t[1] - p).normalize();
    let c = (t[2] - p).normalize();
    // Normals of the great circles through each pair of vertices.
    let n_ab = a.cross(b).normalize_or_zero();
    let n_bc = b.cross(c).normalize_or_zero();
    let n_ca = c.cross(a).normalize_or_zero();
    if n_ab == Vec3::ZERO || n_bc == Vec3::ZERO || n_ca == Vec3::ZERO {
        return None;
    }
    // Interior angles.
    let angle = |n0: Vec3, n1: Vec3| (-n0.dot(n1)).clamp(-1.0, 1.0).acos();
    let alpha = angle(n_ab, n_ca);
    let beta = angle(n_bc, n_ab);
    let gamma = angle(n_ca, n_bc);
    let area = alpha + beta + gamma - PI;
    if !(area > 0.0) {
        return None;
    }
    // Choose the sub-triangle A B C' whose area is u.x of the whole.
    let area_hat = u.x * area;
    let (s, tt) = (area_hat - alpha).sin_cos();
    let cos_alpha = alpha.cos();
    let sin_alpha = alpha.sin();
    let cos_c = a.dot(b);
    let uu = tt - cos_alpha;
    let v = s + sin_alpha * cos_c;
    let q =
        (((v * tt - uu * s) * cos_alpha - v) / ((v * s + uu * tt) * sin_alpha)).clamp(-1.0, 1.0);
    let c_perp = (c - c.dot(a) * a).normalize_or_zero();
    let c_hat = q * a + (1.0 - q * q).max(0.0).sqrt() * c_perp;
    // Then a point on the arc B C' with the right distribution.
    let z = 1.0 - u.y * (1.0 - c_hat.dot(b));
    let b_perp = (c_hat - c_hat.dot(b) * b).normalize_or_zero();
    let w = z * b + (1.0 - z * z).max(0.0).sqrt() * b_perp;
    w.is_finite().then(|| w.normalize())
}

/// Barycentric weights (b1, b2) of vertices 1 and 2 of the point of triangle `t` nearest
/// to `y` in its plane, clamped to the triangle.
pub fn barycentrics(t: &[Vec3; 3], y: Vec3) -> Vec2 {
    let (e1, e2, d) = (t[1] - t[0], t[2] - t[0], y - t[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if !(det > 0.0) {
        return Vec2::splat(1.0 / 3.0);
    }
    let b1 = ((d22 * d1 - d12 * d2) / det).max(0.0);
    let b2 = ((d11 * d2 - d12 * d1) / det).max(0.0);
    let sum = b1 + b2;
    if sum > 1.0 {
        Vec2::new(b1 / sum, b2 / sum)
    } else {
        Vec2::new(b1, b2)
    }
}

/// Below this `sin² θmax`, [`sphere_cone`] takes `1 - cos θmax` from its series.
pub(crate) const SPHERE_CONE_SMALL: f32 = 1e-3;

/// The cone a sphere (centre `c`, radius `r`) subtends from outside point `p`:
/// `1 - cos θmax`, computed without cancellation for small spheres; `None` from inside.
#[inline]
pub fn sphere_cone(p: Vec3, c: Vec3, r: f32) -> Option<f32> {
    let d2 = (c - p).length_squared();
    let sin2 = r * r / d2;
    if !(sin2 < 1.0) {
        return None;
    }
    // For small cones 1 - sqrt(1 - x) ≈ x/2 + x²/8 keeps the digits the subtraction loses.
    let one_minus_cos = if sin2 < SPHERE_CONE_SMALL {
        0.5 * sin2 + 0.125 * sin2 * sin2
    } else {
        1.0 - (1.0 - sin2).sqrt()
    };
    (one_minus_cos > 0.0).then_some(one_minus_cos)
}

/// Samples the sphere's cone from `p` uniformly in solid angle: returns the unit normal of
/// the visible point hit by the sampled direction (the point is `c + r n`), pbrt-v4's
/// construction that avoids intersecting the sphere.
pub fn sample_sphere_cone(p: Vec3, c: Vec3, r: f32, one_minus_cos_max: f32, u: Vec2) -> Vec3 {
    let dc = (c - p).length();
    let sin2_max = (r / dc) * (r / dc);
    let sin_max = sin2_max.sqrt();
    let one_minus_cos = u.x * one_minus_cos_max;
    let cos_theta = 1.0 - one_minus_cos;
    let sin2_theta = (one_minus_cos * (2.0 - one_minus_cos)).max(0.0);
    // Angle at the sphere's centre between the axis and the hit point.
    let cos_alpha =
        sin2_theta / sin_max + cos_theta * (1.0 - sin2_theta / sin2_max).max(0.0).sqrt();
    let sin_alpha = (1.0 - cos_alpha * cos_alpha).max(0.0).sqrt();
    // The shared sine and cosine, so that the packet kernel's lanes (`light::lanes`) take
    // the same points.
    let (sin_phi, cos_phi) = crate::sampling::warp::sin_cos(2.0 * PI * u.y);
    let local = Vec3::new(sin_alpha * cos_phi, sin_alpha * sin_phi, cos_alpha);
    let frame = Frame::from_normal(((c - p) / dc).normalize());
    -frame.to_world(local)
}

/// Solid-angle density of [`sample_sphere_cone`].
#[inline]
pub fn sphere_cone_pdf(one_minus_cos_max: f32) -> f32 {
    crate::sampling::warp::uniform_cone_pdf(one_minus_cos_max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octant_triangle_has_an_eighth_of_the_sphere() {
        let t = [Vec3::X, Vec3::Y, Vec3::Z];
        let omega = triangle_solid_angle(Vec3::ZERO, &t);
        assert!((omega - 4.0 * PI / 8.0).abs() < 1e-5);
        let w = sample_spherical_triangle(Vec3::ZERO, &t, Vec2::new(0.3, 0.8)).unwrap();
        assert!(
            w.min_element() >= -1e-6 && (w.length() - 1.0).abs() < 1e-5,
            "{w}"
        );
    }

    #[test]
    fn cone_points_are_on_the_visible_cap() {
        let (p, c, r) = (Vec3::ZERO, Vec3::new(0.0, 0.0, 4.0), 1.0);
        let omc = sphere_cone(p, c, r).unwrap();
        assert!((omc - (1.0 - (15.0f32 / 16.0).sqrt())).abs() < 1e-6);
        for u in [
            Vec2::new(0.0, 0.3),
            Vec2::new(0.5, 0.7),
            Vec2::new(0.999, 0.1),
        ] {
            let n = sample_sphere_cone(p, c, r, omc, u);
            let y = c + r * n;
            assert!(n.dot(p - y) >= -1e-5, "the point faces p");
        }
        assert!(sphere_cone(c, c, r).is_none());
    }
}
