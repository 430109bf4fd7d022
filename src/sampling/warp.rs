//! Warps from the unit square to directions and points, each with its density. Every warp
//! has a chi-square test in `tests/chi2.rs`.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// Concentric map of the square onto the unit disk (Shirley & Chiu 1997): area-preserving
/// up to a constant, low distortion. Density 1/π.
#[inline]
pub fn square_to_uniform_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, FRAC_PI_4 * (o.y / o.x))
    } else {
        (o.y, FRAC_PI_2 - FRAC_PI_4 * (o.x / o.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// Uniform direction on the unit sphere. Density 1/(4π).
#[inline]
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`square_to_uniform_sphere`].
pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform direction on the +z hemisphere. Density 1/(2π).
#[inline]
pub fn square_to_uniform_hemisphere(u: Vec2) -> Vec3 {
    let z = u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`square_to_uniform_hemisphere`] (zero below the horizon).
#[inline]
pub fn uniform_hemisphere_pdf(v: Vec3) -> f32 {
    if v.z > 0.0 { 1.0 / (2.0 * PI) } else { 0.0 }
}

/// Cosine-weighted direction on the +z hemisphere (Malley's method). Density cos θ / π.
#[inline]
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_uniform_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Density of [`square_to_cosine_hemisphere`].
#[inline]
pub fn cosine_hemisphere_pdf(v: Vec3) -> f32 {
    v.z.max(0.0) / PI
}

/// Direction about +z with density (n+1)/(2π) cos^n θ: the Phong lobe of
/// `../shared/seed-path-tracing.md` (cos θ = u^(1/(n+1)), φ = 2π u).
#[inline]
pub fn square_to_phong_lobe(u: Vec2, exponent: f32) -> Vec3 {
    let cos_theta = u.y.powf(1.0 / (exponent + 1.0));
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta)
}

/// Density of [`square_to_phong_lobe`] for a direction at `cos_theta` from the lobe axis.
#[inline]
pub fn phong_lobe_pdf(cos_theta: f32, exponent: f32) -> f32 {
    if cos_theta <= 0.0 {
        return 0.0;
    }
    (exponent + 1.0) / (2.0 * PI) * cos_theta.powf(exponent)
}

/// Direction about +z uniform in the cone of half-angle θmax, given as `1 - cos θmax` so
/// that tiny cones (the sun: 2e-5) keep their digits; density [`uniform_cone_pdf`].
#[inline]
pub fn square_to_uniform_cone(u: Vec2, one_minus_cos_max: f32) -> Vec3 {
    let one_minus_cos = u.x * one_minus_cos_max;
    let sin_theta = (one_minus_cos * (2.0 - one_minus_cos)).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(
        sin_theta * phi.cos(),
        sin_theta * phi.sin(),
        1.0 - one_minus_cos,
    )
}

/// Solid-angle density of [`square_to_uniform_cone`] inside the cone.
#[inline]
pub fn uniform_cone_pdf(one_minus_cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * one_minus_cos_max)
}

/// Uniform point on a triangle as barycentric weights `(b1, b2)` of vertices 1 and 2
/// (Heitz 2019, "A Low-Distortion Map Between Triangle and Square"). Density 1/area.
#[inline]
pub fn square_to_uniform_triangle(u: Vec2) -> Vec2 {
    let (b0, b1) = if u.x < u.y {
        let b0 = u.x / 2.0;
        (b0, u.y - b0)
    } else {
        let b1 = u.y / 2.0;
        (u.x - b1, b1)
    };
    // (b0, b1) are the weights of vertices 0 and 1; return those of vertices 1 and 2.
    Vec2::new(b1, 1.0 - b0 - b1)
}
