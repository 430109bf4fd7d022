//! Rays and robust ray origins.

#[cfg(target_arch = "x86_64")]
use crate::simd::{F8, LANES, V3};
use glam::Vec3;

/// A ray `origin + t * dir` for `t` in `(0, tmax)` at shutter time `time` (0 at the
/// shutter's opening, 1 at its closing: where moving geometry is, `geometry::motion`).
/// `dir` need not be normalised. Laid out as eight floats (origin, direction, bound, time),
/// which [`RayLanes::of_rays`] reads.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tmax: f32,
    pub time: f32,
}

/// Eight rays in lanes (lane i: ray i), as packet queries take them
/// (`World::intersect_lanes`, `World::occluded_lanes`). Only inside the packet kernel (see
/// `crate::simd`).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayLanes {
    pub origin: V3,
    pub dir: V3,
    pub tmax: F8,
}

#[cfg(target_arch = "x86_64")]
impl RayLanes {
    /// The rays of an array. Each ray's eight floats are one row of an 8×8 transpose, so
    /// that no component is copied on its own (24 scalar stores that the vector loads
    /// would wait for). The packet kernel renders only scenes that do not move, so the
    /// rays' times are not kept.
    #[inline(always)]
    pub(crate) fn of_rays(rays: &[Ray; LANES]) -> Self {
        const FLOATS: usize = std::mem::size_of::<Ray>() / 4;
        const { assert!(FLOATS == 8 && std::mem::align_of::<Ray>() == 4) };
        // SAFETY: Ray is repr(C) of eight f32s (checked above), so the array is 64 floats.
        let floats: &[f32; FLOATS * LANES] = unsafe { &*rays.as_ptr().cast() };
        let rows: [F8; LANES] = std::array::from_fn(|i| F8::load(floats, FLOATS * i));
        let [ox, oy, oz, dx, dy, dz, tmax, _] = F8::transpose(rows);
        Self {
            origin: V3::new(ox, oy, oz),
            dir: V3::new(dx, dy, dz),
            tmax,
        }
    }

    /// Lane `lane`'s ray, read where the lanes lie.
    #[inline(always)]
    pub(crate) fn ray(&self, lane: usize) -> Ray {
        Ray {
            origin: self.origin.lane(lane),
            dir: self.dir.lane(lane),
            tmax: self.tmax.lane(lane),
            time: 0.0,
        }
    }
}

impl Ray {
    /// A ray without an upper bound, at the shutter's opening.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir,
            tmax: f32::INFINITY,
            time: 0.0,
        }
    }

    /// The ray at shutter time `time`.
    #[inline]
    pub fn at_time(self, time: f32) -> Self {
        Self { time, ..self }
    }

    /// Point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + t * self.dir
    }

    /// The ray continued through the surface it met at `p` (geometric normal `ng`, computed
    /// from data of `magnitude`): from just beyond it towards the same end, the point at
    /// `tmax` of a bounded ray (then with `tmax` 1) or infinity.
    #[inline]
    pub fn continued_past(&self, p: Vec3, ng: Vec3, magnitude: f32) -> Self {
        let origin = offset_past(p, ng, self.dir, magnitude);
        if self.tmax.is_finite() {
            let end = self.at(self.tmax);
            Self {
                origin,
                dir: end - origin,
                tmax: 1.0,
                time: self.time,
            }
        } else {
            Self::new(origin, self.dir).at_time(self.time)
        }
    }
}

/// Where a ray of direction `dir` that crosses the surface at `p` (geometric normal `ng`,
/// computed from data of `magnitude`) goes on from: [`offset_ray_origin_within`] to the far
/// side.
#[inline]
pub fn offset_past(p: Vec3, ng: Vec3, dir: Vec3, magnitude: f32) -> Vec3 {
    offset_ray_origin_within(p, if dir.dot(ng) > 0.0 { ng } else { -ng }, magnitude)
}

/// [`offset_ray_origin`]'s constants: coordinates below `ORIGIN` move by `FLOAT_SCALE`
/// times the normal, larger ones by `INT_SCALE` times the normal in ulps (both of the first
/// two scaled by the magnitude of the point's data in [`offset_ray_origin_within`]).
const ORIGIN: f32 = 1.0 / 32.0;
const FLOAT_SCALE: f32 = 1.0 / 65536.0;
const INT_SCALE: f32 = 256.0;

/// Moves a surface point off its surface along the geometric normal `n` (pointing to the side
/// the new ray leaves towards), so that the new ray cannot hit the surface it starts on.
///
/// Wächter & Binder, "A Fast and Robust Method for Avoiding Self-Intersection" (Ray Tracing
/// Gems, ch. 6): the offset is a fixed number of ulps of the coordinate, so it scales with the
/// magnitude of the point, with an absolute offset near the origin where ulps vanish. Render
/// space is normalised to the scene's size (see `geometry::space::RenderSpace`), which makes the absolute
/// part relative to the scene too: this is the offset of a point whose data may be as large
/// as the scene.
#[inline]
pub fn offset_ray_origin(p: Vec3, n: Vec3) -> Vec3 {
    offset_ray_origin_within(p, n, 1.0)
}

/// The smallest magnitude [`offset_ray_origin_within`] scales to (a primitive at the origin
/// with no extent still gets an offset of normal numbers).
const MIN_MAGNITUDE: f32 = 1.0 / 1048576.0;

/// [`offset_ray_origin`] for a point computed from data (a primitive's corners, a sphere's
/// centre and radius) whose coordinates are at most `magnitude` (render space, at most 1):
/// its rounding error is relative to that, so the absolute offset near the origin and the
/// region where it applies shrink with it. An object small against the scene's bounds and
/// near their centre (a 9 cm shader ball in a room, a millimetre subsurface walk) is then
/// offset by its own precision, not by the room's; at magnitude 1 it is
/// [`offset_ray_origin`] exactly.
#[inline]
pub fn offset_ray_origin_within(p: Vec3, n: Vec3, magnitude: f32) -> Vec3 {
    let m = if magnitude > MIN_MAGNITUDE {
        magnitude.min(1.0)
    } else {
        MIN_MAGNITUDE
    };
    let (origin, float_scale) = (ORIGIN * m, FLOAT_SCALE * m);
    let offset_axis = |p: f32, n: f32| -> f32 {
        if p.abs() < origin {
            p + float_scale * n
        } else {
            // `n` is a unit normal; a degenerate one (huge components from a scene's broken
            // data) is held to it, so that negating the offset cannot overflow.
            let of_i = (INT_SCALE * n.clamp(-1.0, 1.0)) as i32;
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

/// [`offset_ray_origin`] in eight lanes, to the bit (the packet kernel's light samples).
/// Only for code compiled with AVX2 (see `crate::simd`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn offset_ray_origin_lanes(p: crate::simd::V3, n: crate::simd::V3) -> crate::simd::V3 {
    offset_ray_origin_lanes_within(p, n, crate::simd::F8::ONE)
}

/// [`offset_ray_origin_within`] in eight lanes, to the bit (the packet kernel's bounces).
/// Only for code compiled with AVX2 (see `crate::simd`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn offset_ray_origin_lanes_within(
    p: crate::simd::V3,
    n: crate::simd::V3,
    magnitude: crate::simd::F8,
) -> crate::simd::V3 {
    use crate::simd::{F8, U8, V3};
    let least = F8::splat(MIN_MAGNITUDE);
    // NaN fails the comparison and takes the least, as in the scalar offset.
    let m = F8::select(magnitude.gt(least), magnitude.min(F8::ONE), least);
    let (origin, float_scale) = (F8::splat(ORIGIN) * m, F8::splat(FLOAT_SCALE) * m);
    // A function, not a closure: closures do not inherit the caller's target features, and
    // their intrinsics would not be inlined.
    #[inline(always)]
    fn axis(p: F8, n: F8, origin: F8, float_scale: F8) -> F8 {
        let near = p + float_scale * n;
        // `as i32` truncates, as the conversion does; NaN gives 0 there, i32::MIN here. The
        // normal is held to [-1, 1] as in the scalar offset.
        let held = n.max(F8::splat(-1.0)).min(F8::splat(1.0));
        let of_i = (F8::splat(INT_SCALE) * held).to_i32() & n.eq(n).as_u8();
        let of_i = U8::select(p.lt(F8::ZERO), U8::splat(0) - of_i, of_i);
        let far = F8::from_bits(p.to_bits() + of_i);
        F8::select(p.abs().lt(origin), near, far)
    }
    V3::new(
        axis(p.x, n.x, origin, float_scale),
        axis(p.y, n.y, origin, float_scale),
        axis(p.z, n.z, origin, float_scale),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_degenerate_normal_offsets_as_a_unit_one() {
        // A normal of huge components (a scene's broken data, found by fuzzing): negating
        // its integer offset overflowed; it is held to the unit normal's offset.
        let p = Vec3::new(-0.5, 0.25, -3.0);
        let huge = Vec3::new(-3e38, 1e30, f32::MAX);
        let unit = Vec3::new(-1.0, 1.0, 1.0);
        assert_eq!(
            offset_ray_origin(p, huge).to_array().map(f32::to_bits),
            offset_ray_origin(p, unit).to_array().map(f32::to_bits)
        );
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_or_skip() {
            use crate::simd::V3;
            let lanes = offset_ray_origin_lanes(V3::splat(p), V3::splat(huge));
            assert_eq!(
                lanes.lane(3).to_array().map(f32::to_bits),
                offset_ray_origin(p, huge).to_array().map(f32::to_bits)
            );
        }
    }

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

    /// Every other triangle, by its first corner's bits.
    fn rng_half(corners: &[Vec3; 3]) -> bool {
        corners[0].x.to_bits() & 1 == 0
    }

    /// The barycentrics (b1, b2) of the point of the triangle's plane nearest the origin,
    /// where it lies inside the triangle.
    fn nearest_to_origin(c: &[Vec3; 3]) -> Option<(f32, f32)> {
        let d = c.map(|v| v.as_dvec3());
        let (e1, e2) = (d[1] - d[0], d[2] - d[0]);
        let n = e1.cross(e2);
        let q = n * (d[0].dot(n) / n.length_squared());
        let w = q - d[0];
        let (a, b, cc) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let (x, y) = (w.dot(e1), w.dot(e2));
        let det = a * cc - b * b;
        let (b1, b2) = ((cc * x - b * y) / det, (a * y - b * x) / det);
        (b1 >= 0.0 && b2 >= 0.0 && b1 + b2 <= 1.0).then_some((b1 as f32, b2 as f32))
    }

    /// A point computed in single precision from a triangle's corners, offset within the
    /// corners' magnitude, lies on the normal's side of the exact plane (the offset clears
    /// the rounding error), for triangles of every size around the origin and away from it.
    #[test]
    fn offsets_within_a_magnitude_clear_the_points_rounding() {
        let mut rng = crate::sampling::pcg::Pcg32::new(7, 11);
        let mut u = || rng.next_f32() * 2.0 - 1.0;
        for m in [1e-5f32, 1e-3, 0.03, 0.3, 1.0] {
            for _ in 0..20_000 {
                let shift = Vec3::new(u(), u(), u()) * m * 0.05;
                let corners: [Vec3; 3] =
                    std::array::from_fn(|_| shift + Vec3::new(u(), u(), u()) * m * 0.5);
                let magnitude = corners
                    .iter()
                    .map(|c| c.abs().max_element())
                    .fold(0.0f32, f32::max);
                let (b1, b2) = (u().abs(), u().abs());
                let (b1, b2) = if b1 + b2 > 1.0 {
                    (1.0 - b1, 1.0 - b2)
                } else {
                    (b1, b2)
                };
                // Half the points where the plane passes the origin closest: coordinates far
                // below the corners', where the offset's absolute part must clear them.
                let (b1, b2) = if rng_half(&corners) {
                    nearest_to_origin(&corners).unwrap_or((b1, b2))
                } else {
                    (b1, b2)
                };
                let b0 = 1.0 - b1 - b2;
                let p = corners[0] * b0 + corners[1] * b1 + corners[2] * b2;
                let n = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
                let Some(n) = n.try_normalize() else { continue };
                let d = corners.map(|c| c.as_dvec3());
                let exact_n = (d[1] - d[0]).cross(d[2] - d[0]).normalize();
                for side in [n, -n] {
                    let q = offset_ray_origin_within(p, side, magnitude).as_dvec3();
                    let distance = (q - d[0]).dot(exact_n) * side.as_dvec3().dot(exact_n).signum();
                    assert!(distance > 0.0, "m {m}: {p} offset to {q}, {distance}");
                }
            }
        }
    }

    /// Lane i of the packet is ray i: origin, direction and bound, bit for bit (NaN,
    /// infinity and signed zero included; the last ray is read apart from the others).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn ray_lanes_are_the_rays() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let special = [f32::NAN, f32::INFINITY, -0.0, 1e-40];
        let rays: [Ray; 8] = std::array::from_fn(|i| {
            let c = |k: usize| (7 * i + k) as f32 * if k.is_multiple_of(2) { 1.0 } else { -0.5 };
            Ray {
                origin: Vec3::new(c(0), c(1), c(2)),
                dir: Vec3::new(c(3), c(4), special[i % 4]),
                tmax: if i == 7 { f32::INFINITY } else { c(6) },
                time: 0.0,
            }
        });
        let lanes = RayLanes::of_rays(&rays);
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        for (i, ray) in rays.iter().enumerate() {
            let lane = lanes.ray(i);
            assert_eq!(bits(lane.origin), bits(ray.origin), "origin {i}");
            assert_eq!(bits(lane.dir), bits(ray.dir), "direction {i}");
            assert_eq!(lane.tmax.to_bits(), ray.tmax.to_bits(), "bound {i}");
        }
    }

    /// The lanes' offset is the scalar one to the bit, at every magnitude and sign
    /// (including NaN and infinite coordinates, and NaN normals).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn offset_lanes_are_the_scalar_offsets() {
        use crate::simd::V3;
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let mut rng = crate::sampling::pcg::Pcg32::new(4, 4);
        let mut value = |i: usize| match i % 11 {
            0 => f32::NAN,
            1 => f32::INFINITY,
            2 => -0.0,
            _ => (rng.next_f32() - 0.5) * 10f32.powi((rng.next_u32() % 16) as i32 - 8),
        };
        for round in 0..20_000 {
            let ps: [Vec3; 8] = std::array::from_fn(|l| {
                Vec3::new(value(round + l), value(round + 3 * l), value(round + 5 * l))
            });
            let ns: [Vec3; 8] = std::array::from_fn(|l| {
                let n = Vec3::new(value(l + 1), value(l + 2), value(l + 4)).normalize_or(Vec3::Z);
                if round % 97 == 0 {
                    Vec3::new(f32::NAN, n.y, n.z)
                } else {
                    n
                }
            });
            let lanes = offset_ray_origin_lanes(V3::from_lanes(&ps), V3::from_lanes(&ns));
            // Magnitudes of every size, beyond 1, below the least, NaN.
            let ms: [f32; 8] = std::array::from_fn(|l| match (round + l) % 13 {
                0 => f32::NAN,
                1 => 3.0,
                2 => 0.0,
                k => (0.5 + (round % 7) as f32) / 8.0 * 10f32.powi(-((k % 8) as i32)),
            });
            let within = offset_ray_origin_lanes_within(
                V3::from_lanes(&ps),
                V3::from_lanes(&ns),
                crate::simd::F8::from_array(ms),
            );
            for l in 0..8 {
                let (got, want) = (lanes.lane(l), offset_ray_origin(ps[l], ns[l]));
                assert_eq!(
                    got.to_array().map(f32::to_bits),
                    want.to_array().map(f32::to_bits),
                    "p {} n {}",
                    ps[l],
                    ns[l]
                );
                let (got, want) = (
                    within.lane(l),
                    offset_ray_origin_within(ps[l], ns[l], ms[l]),
                );
                assert_eq!(
                    got.to_array().map(f32::to_bits),
                    want.to_array().map(f32::to_bits),
                    "p {} n {} magnitude {}",
                    ps[l],
                    ns[l],
                    ms[l]
                );
            }
        }
    }
}
