//! Warps from the unit square to directions and points, each with its density. Every warp
//! has a chi-square test in `tests/chi2.rs`.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_2_PI, FRAC_PI_2, FRAC_PI_4, PI};

/// The constants of [`sin_cos`] (shared with the packet kernel's lane version).
pub(crate) mod sin_cos_constants {
    /// π/2 in three parts (Cody-Waite): q × each of the first two is exact for |q| < 2^12.
    pub const PI_2_HIGH: f32 = 1.570_312_5;
    pub const PI_2_MID: f32 = 4.837_513e-4;
    pub const PI_2_LOW: f32 = 7.549_79e-8;
    /// Cephes' minimax polynomials for sin and cos on [-π/4, π/4], highest degree first.
    pub const SIN: [f32; 3] = [-1.951_529_6e-4, 8.332_161e-3, -1.666_665_5e-1];
    pub const COS: [f32; 3] = [2.443_315_7e-5, -1.388_731_6e-3, 4.166_664_6e-2];
}

/// Sine and cosine of `x` (|x| up to a few thousand), within about two ulp of libm's:
/// reduced to [-π/4, π/4] by the nearest multiple of π/2 and evaluated by Cephes'
/// polynomials. Inlined, it costs less than libm's call; the packet kernel's lanes
/// (`simd::F8::sin_cos`) perform the same operations, so both kernels sample the same
/// directions to the bit.
#[inline]
pub fn sin_cos(x: f32) -> (f32, f32) {
    use sin_cos_constants::*;
    let q = (x * FRAC_2_PI).round_ties_even();
    let r = ((x - q * PI_2_HIGH) - q * PI_2_MID) - q * PI_2_LOW;
    let r2 = r * r;
    let s = ((r2 * SIN[0] + SIN[1]) * r2 + SIN[2]) * (r2 * r) + r;
    let c = ((r2 * COS[0] + COS[1]) * r2 + COS[2]) * (r2 * r2) + (1.0 - r2 * 0.5);
    let quadrant = q as i32;
    let (s, c) = if quadrant & 1 != 0 { (c, s) } else { (s, c) };
    (
        if quadrant & 2 != 0 { -s } else { s },
        if (quadrant + 1) & 2 != 0 { -c } else { c },
    )
}

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
    let (sin, cos) = sin_cos(theta);
    r * Vec2::new(cos, sin)
}

/// Uniform direction on the unit sphere. Density 1/(4π).
#[inline]
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    let (sin, cos) = sin_cos(phi);
    Vec3::new(r * cos, r * sin, z)
}

/// Density of [`square_to_uniform_sphere`].
pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform direction on the +z hemisphere. Density 1/(2π).
#[inline]
pub fn square_to_uniform_hemisphere(u: Vec2) -> Vec3 {
    let z = u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    let (sin, cos) = sin_cos(phi);
    Vec3::new(r * cos, r * sin, z)
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

/// Direction about +z with density (n+1)/(2π) cos^n θ: the modified Phong lobe
/// (`material::phong`; cos θ = u^(1/(n+1)), φ = 2π u).
#[inline]
pub fn square_to_phong_lobe(u: Vec2, exponent: f32) -> Vec3 {
    let cos_theta = u.y.powf(1.0 / (exponent + 1.0));
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    let (sin, cos) = sin_cos(phi);
    Vec3::new(sin_theta * cos, sin_theta * sin, cos_theta)
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
    let (sin, cos) = sin_cos(phi);
    Vec3::new(sin_theta * cos, sin_theta * sin, 1.0 - one_minus_cos)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `sin_cos` is within two ulp of the exact sine and cosine (of the f32 argument, from
    /// f64) over the angles the warps and frames use and well beyond.
    #[test]
    fn sin_cos_is_accurate() {
        let mut worst = 0.0f64;
        for i in 0..2_000_000 {
            let x = -100.0 + i as f32 * (200.0 / 2_000_000.0);
            let (s, c) = sin_cos(x);
            let (es, ec) = (x as f64).sin_cos();
            // Error in ulps of the result's magnitude (at least that of 2^-24 at 1).
            let ulp = |v: f64| {
                (v.abs().max(1e-30).log2().floor() - 23.0)
                    .exp2()
                    .max(2f64.powi(-40))
            };
            worst = worst
                .max((s as f64 - es).abs() / ulp(es))
                .max((c as f64 - ec).abs() / ulp(ec));
        }
        assert!(worst <= 2.0, "largest error {worst} ulp");
    }
}
