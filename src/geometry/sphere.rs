//! Analytic spheres: ray intersection with the precision improvements of Haines et al.
//! ("Precision Improvements for Ray/Sphere Intersection", Ray Tracing Gems ch. 7), and the
//! surface parameterisation used for texture coordinates.

use super::hit::PrimitiveHit;
use super::ray::Ray;
#[cfg(target_arch = "x86_64")]
use super::triangle::LaneHits;
#[cfg(target_arch = "x86_64")]
use crate::simd::{F8, V3};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Nearest intersection of `ray` with the sphere in `(0, tmax)`; `front` when the ray
/// arrives from outside.
#[inline]
pub fn intersect(ray: &Ray, centre: Vec3, radius: f32, tmax: f32) -> Option<PrimitiveHit> {
    let length = ray.dir.length();
    let d = ray.dir / length;
    let o = ray.origin - centre;
    let b = -o.dot(d);
    // Squared distance of the line from the centre, computed from the closest point rather
    // than as b² - c, which cancels catastrophically for distant spheres.
    let f = o + b * d;
    let r2 = radius * radius;
    let discriminant = r2 - f.length_squared();
    if !(discriminant >= 0.0) {
        return None;
    }
    let c = o.length_squared() - r2;
    let q = b + b.signum() * discriminant.sqrt();
    let (mut t0, mut t1) = if q != 0.0 { (c / q, q) } else { (0.0, 0.0) };
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    // Ray parameters (the direction was normalised above).
    let (t0, t1) = (t0 / length, t1 / length);
    let t = if t0 > 0.0 { t0 } else { t1 };
    if !(t > 0.0 && t < tmax) {
        return None;
    }
    // Arriving from outside: the outward normal opposes the ray.
    let front = (o + t * length * d).dot(d) < 0.0;
    Some(PrimitiveHit {
        t,
        b1: 0.0,
        b2: 0.0,
        front,
    })
}

/// Eight rays' [`intersect`] with one sphere (origins `origin`, directions `dir`) for the
/// lanes of `mask`, each bounded by its lane of `tmax`: each lane's hit is the scalar
/// test's to the bit (the same operations lane by lane). Only for code compiled with AVX2
/// (see `crate::simd`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn intersect_lanes(
    origin: V3,
    dir: V3,
    centre: Vec3,
    radius: f32,
    tmax: F8,
    mask: u32,
) -> LaneHits {
    let zero = F8::ZERO;
    let length = dir.length_squared().sqrt();
    let d = dir / length;
    let o = origin - V3::splat(centre);
    let b = -o.dot(d);
    let f = o + d * b;
    let r2 = radius * radius;
    let discriminant = F8::splat(r2) - f.length_squared();
    let c = o.length_squared() - r2;
    let q = b + F8::sign_of(b) * discriminant.sqrt();
    let nonzero = q.ne(zero);
    let (t0, t1) = (
        F8::select(nonzero, c / q, zero),
        F8::select(nonzero, q, zero),
    );
    let swap = t0.gt(t1);
    let (t0, t1) = (F8::select(swap, t1, t0), F8::select(swap, t0, t1));
    let (t0, t1) = (t0 / length, t1 / length);
    let t = F8::select(t0.gt(zero), t0, t1);
    let hit = zero.le(discriminant) & t.gt(zero) & t.lt(tmax);
    let front = (o + d * (t * length)).dot(d).lt(zero);
    LaneHits::of_shape(hit.bits() & mask, t, front.bits())
}

/// Texture coordinates of the point with outward unit normal `n`: the lat-long convention
/// of environment maps (u around +Y from -Z, v from the top).
#[inline]
pub fn uv(n: Vec3) -> Vec2 {
    let u = 0.5 + n.x.atan2(-n.z) / (2.0 * PI);
    Vec2::new(u.rem_euclid(1.0), n.y.clamp(-1.0, 1.0).acos() / PI)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hits_from_outside_and_inside_and_far_away() {
        let h = intersect(
            &Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z),
            Vec3::ZERO,
            1.0,
            f32::INFINITY,
        )
        .unwrap();
        assert!((h.t - 4.0).abs() < 1e-6 && h.front);
        let h = intersect(
            &Ray::new(Vec3::ZERO, Vec3::X * 2.0),
            Vec3::ZERO,
            1.0,
            f32::INFINITY,
        )
        .unwrap();
        assert!(
            (h.t - 0.5).abs() < 1e-6 && !h.front,
            "unnormalised direction, from inside"
        );
        assert!(
            intersect(
                &Ray::new(Vec3::new(0.0, 2.0, 5.0), -Vec3::Z),
                Vec3::ZERO,
                1.0,
                f32::INFINITY
            )
            .is_none()
        );
        assert!(
            intersect(
                &Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::Z),
                Vec3::ZERO,
                1.0,
                f32::INFINITY
            )
            .is_none()
        );
        // A small sphere far away: b² - c would lose every digit of the discriminant.
        let far = Vec3::new(0.0, 0.0, -1e5);
        let h = intersect(
            &Ray::new(Vec3::new(0.0, 0.9e-3, 0.0), -Vec3::Z),
            far,
            1e-3,
            f32::INFINITY,
        )
        .unwrap();
        assert!(
            (h.t - (1e5 - (1e-6f32 - 0.81e-6).sqrt())).abs() < 0.05,
            "{}",
            h.t
        );
    }
}
