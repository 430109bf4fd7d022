//! Orthonormal frames for local shading coordinates (z = normal).

use crate::simd::{F8, V3};
use glam::Vec3;

/// An orthonormal basis `(s, t, n)`; local coordinates have `n` as +z.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    /// A frame around a unit normal, branchless and continuous except at one pole
    /// (Duff et al. 2017, "Building an Orthonormal Basis, Revisited").
    #[inline]
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Self {
            s: Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            t: Vec3::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }

    /// A frame around a unit normal whose first axis follows `tangent` (Gram-Schmidt);
    /// falls back to [`Frame::from_normal`] when the tangent is parallel to the normal.
    #[inline]
    pub fn from_normal_tangent(n: Vec3, tangent: Vec3) -> Self {
        let s = tangent - n * n.dot(tangent);
        let len2 = s.length_squared();
        if !(len2 > 1e-12) {
            return Self::from_normal(n);
        }
        let s = s / len2.sqrt();
        Self {
            s,
            t: n.cross(s),
            n,
        }
    }

    /// World vector to local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local coordinates to a world vector.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// [`Frame::from_normal`] of eight lanes' normals, to the bit: the axes `[s, t, n]` (the
/// packet kernel's shading points). Only for code compiled with AVX2 (see `crate::simd`).
#[inline(always)]
pub(crate) fn frame_from_normal_lanes(n: V3) -> [V3; 3] {
    let sign = F8::sign_of(n.z);
    let a = F8::splat(-1.0) / (sign + n.z);
    let b = n.x * n.y * a;
    let s = V3::new(F8::ONE + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let t = V3::new(b, sign + n.y * n.y * a, -n.y);
    [s, t, n]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lanes' frames are the scalar frames to the bit, at the poles and around them.
    #[test]
    fn lane_frames_are_the_scalar_frames() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let mut normals = vec![Vec3::Z, -Vec3::Z, Vec3::X, -Vec3::Y];
        normals.push(Vec3::new(0.0, 0.0, -1.0 + 1e-7).normalize());
        normals.push(Vec3::new(1e-20, -1e-20, -1.0));
        let mut state = 0x9e37_79b9u32;
        let mut next = || {
            state = state.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
            (state >> 8) as f32 / (1 << 24) as f32 * 2.0 - 1.0
        };
        normals.extend((0..4000).map(|_| Vec3::new(next(), next(), next()).normalize_or(Vec3::Z)));
        for chunk in normals.chunks(8) {
            let mut lanes = [Vec3::Z; 8];
            lanes[..chunk.len()].copy_from_slice(chunk);
            let [s, t, n] = frame_from_normal_lanes(V3::from_lanes(&lanes));
            for (lane, &normal) in chunk.iter().enumerate() {
                let f = Frame::from_normal(normal);
                for (axis, scalar) in [(s, f.s), (t, f.t), (n, f.n)] {
                    let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                    assert_eq!(bits(axis.lane(lane)), bits(scalar), "normal {normal}");
                }
            }
        }
    }

    #[test]
    fn frames_are_orthonormal_and_right_handed() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.0, 0.0, -1.0 + 1e-7).normalize(),
            Vec3::new(0.3, -0.4, 0.2).normalize(),
        ] {
            let f = Frame::from_normal(n);
            assert!((f.s.length() - 1.0).abs() < 1e-5);
            assert!((f.t.length() - 1.0).abs() < 1e-5);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(n).abs() < 1e-5);
            assert!((f.s.cross(f.t) - n).length() < 1e-4);
            let v = Vec3::new(0.1, 0.7, -0.2);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }
}
