//! Rays and robust ray origins.

#[cfg(target_arch = "x86_64")]
use crate::simd::{F8, LANES, V3};
use glam::Vec3;

/// A ray `origin + t * dir` for `t` in `(0, tmax)`. `dir` need not be normalised.
/// Laid out as seven floats (origin, direction, bound), which [`RayLanes::of_rays`] reads.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tmax: f32,
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
    /// The rays of an array. Each ray's seven floats are one row of an 8×8 transpose, so
    /// that no component is copied on its own (24 scalar stores that the vector loads
    /// would wait for).
    #[inline(always)]
    pub(crate) fn of_rays(rays: &[Ray; LANES]) -> Self {
        const FLOATS: usize = std::mem::size_of::<Ray>() / 4;
        const { assert!(FLOATS == 7 && std::mem::align_of::<Ray>() == 4) };
        // SAFETY: Ray is repr(C) of seven f32s (checked above), so the array is 56 floats.
        let floats: &[f32; FLOATS * LANES] = unsafe { &*rays.as_ptr().cast() };
        let mut rows = [F8::ZERO; LANES];
        for (i, row) in rows.iter_mut().enumerate().take(LANES - 1) {
            *row = F8::load(floats, FLOATS * i);
        }
        // The last ray's floats end the array: read from one float earlier and shift down.
        rows[LANES - 1] = F8::load(floats, FLOATS * (LANES - 1) - 1).shift_down();
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
        }
    }
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

    /// The ray continued through the surface it met at `p` (geometric normal `ng`): from
    /// just beyond it towards the same end, the point at `tmax` of a bounded ray (then with
    /// `tmax` 1) or infinity.
    #[inline]
    pub fn continued_past(&self, p: Vec3, ng: Vec3) -> Self {
        let origin = offset_past(p, ng, self.dir);
        if self.tmax.is_finite() {
            let end = self.at(self.tmax);
            Self {
                origin,
                dir: end - origin,
                tmax: 1.0,
            }
        } else {
            Self::new(origin, self.dir)
        }
    }
}

/// Where a ray of direction `dir` that crosses the surface at `p` (geometric normal `ng`)
/// goes on from: [`offset_ray_origin`] to the far side.
#[inline]
pub fn offset_past(p: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
    offset_ray_origin(p, if dir.dot(ng) > 0.0 { ng } else { -ng })
}

/// [`offset_ray_origin`]'s constants: coordinates below `ORIGIN` move by `FLOAT_SCALE`
/// times the normal, larger ones by `INT_SCALE` times the normal in ulps.
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
/// part relative to the scene too.
#[inline]
pub fn offset_ray_origin(p: Vec3, n: Vec3) -> Vec3 {
    let offset_axis = |p: f32, n: f32| -> f32 {
        if p.abs() < ORIGIN {
            p + FLOAT_SCALE * n
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
    use crate::simd::{F8, U8, V3};
    #[inline(always)]
    fn axis(p: F8, n: F8) -> F8 {
        let near = p + F8::splat(FLOAT_SCALE) * n;
        // `as i32` truncates, as the conversion does; NaN gives 0 there, i32::MIN here. The
        // normal is held to [-1, 1] as in the scalar offset.
        let held = n.max(F8::splat(-1.0)).min(F8::splat(1.0));
        let of_i = (F8::splat(INT_SCALE) * held).to_i32() & n.eq(n).as_u8();
        let of_i = U8::select(p.lt(F8::ZERO), U8::splat(0) - of_i, of_i);
        let far = F8::from_bits(p.to_bits() + of_i);
        F8::select(p.abs().lt(F8::splat(ORIGIN)), near, far)
    }
    V3::new(axis(p.x, n.x), axis(p.y, n.y), axis(p.z, n.z))
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
            for l in 0..8 {
                let (got, want) = (lanes.lane(l), offset_ray_origin(ps[l], ns[l]));
                assert_eq!(
                    got.to_array().map(f32::to_bits),
                    want.to_array().map(f32::to_bits),
                    "p {} n {}",
                    ps[l],
                    ns[l]
                );
            }
        }
    }
}
