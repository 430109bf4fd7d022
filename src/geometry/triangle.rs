//! Watertight ray/triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection"): rays never slip through shared edges or vertices of a closed mesh.

use super::PrimitiveHit;
use super::ray::Ray;
use glam::{DVec3, Vec3};

/// Per-ray constants of the watertight test: the axis permutation and shear that map the
/// ray onto +z, as three rows (`x' = row_x · p`, ...), so the test reads no vector by a
/// run-time index. Each row holds exactly 1 and 0 where the permutation puts them, so a
/// row's dot product rounds exactly like the permuted difference `p[kx] - sx p[kz]` of
/// Woop et al.: the transformed vertices, and with them the watertightness, are theirs.
#[derive(Clone, Copy, Debug)]
pub struct RayShear {
    origin: Vec3,
    row_x: Vec3,
    row_y: Vec3,
    row_z: Vec3,
}

impl RayShear {
    /// Precomputes the permutation and shear for `ray`.
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        let d = ray.dir;
        let a = d.abs();
        // The permutation (kx, ky, kz) as unit vectors: z along the largest component.
        let (mut ex, mut ey, ez) = if a.x > a.y {
            if a.x > a.z {
                (Vec3::Y, Vec3::Z, Vec3::X)
            } else {
                (Vec3::X, Vec3::Y, Vec3::Z)
            }
        } else if a.y > a.z {
            (Vec3::Z, Vec3::X, Vec3::Y)
        } else {
            (Vec3::X, Vec3::Y, Vec3::Z)
        };
        let dz = d.dot(ez);
        // Swapping keeps the winding of triangles seen along the ray.
        if dz < 0.0 {
            std::mem::swap(&mut ex, &mut ey);
        }
        // One reciprocal for the three ratios: watertightness needs every triangle tested
        // with the same shear, not the shear's exact rounding.
        let sz = 1.0 / dz;
        let (sx, sy) = (d.dot(ex) * sz, d.dot(ey) * sz);
        Self {
            origin: ray.origin,
            row_x: ex - sx * ez,
            row_y: ey - sy * ez,
            row_z: sz * ez,
        }
    }
}

/// Intersects the ray described by `shear` with triangle `p0 p1 p2` in `(0, tmax)`.
#[inline(always)]
pub fn intersect(s: &RayShear, p0: Vec3, p1: Vec3, p2: Vec3, tmax: f32) -> Option<PrimitiveHit> {
    let a = p0 - s.origin;
    let b = p1 - s.origin;
    let c = p2 - s.origin;
    let (ax, ay) = (a.dot(s.row_x), a.dot(s.row_y));
    let (bx, by) = (b.dot(s.row_x), b.dot(s.row_y));
    let (cx, cy) = (c.dot(s.row_x), c.dot(s.row_y));
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    // On an edge in single precision: decide it exactly in double precision.
    if u == 0.0 || v == 0.0 || w == 0.0 {
        let (ax, ay, bx, by, cx, cy) = (
            ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
        );
        u = (cx * by - cy * bx) as f32;
        v = (ax * cy - ay * cx) as f32;
        w = (bx * ay - by * ax) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let t_scaled = u * a.dot(s.row_z) + v * b.dot(s.row_z) + w * c.dot(s.row_z);
    let inv_det = 1.0 / det;
    let t = t_scaled * inv_det;
    // Positive comparisons: NaN fails them.
    if !(t > 0.0 && t < tmax) {
        return None;
    }
    Some(PrimitiveHit {
        t,
        b1: v * inv_det,
        b2: w * inv_det,
        front: det > 0.0,
    })
}

/// Geometric normal (unnormalised) of a counter-clockwise triangle, computed in double
/// precision so that thin triangles far from the origin keep a reliable direction.
#[inline]
pub fn geometric_normal(p0: Vec3, p1: Vec3, p2: Vec3) -> Vec3 {
    let e1 = (p1 - p0).as_dvec3();
    let e2 = (p2 - p0).as_dvec3();
    let n: DVec3 = e1.cross(e2);
    n.as_vec3()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shoot(o: Vec3, d: Vec3, p: [Vec3; 3]) -> Option<PrimitiveHit> {
        let ray = Ray::new(o, d);
        intersect(&RayShear::new(&ray), p[0], p[1], p[2], f32::INFINITY)
    }

    #[test]
    fn hit_distance_barycentrics_and_facing() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y]; // faces +z
        let h = shoot(Vec3::new(0.25, 0.5, 2.0), -Vec3::Z, tri).unwrap();
        assert!((h.t - 2.0).abs() < 1e-6);
        assert!((h.b1 - 0.25).abs() < 1e-6 && (h.b2 - 0.5).abs() < 1e-6);
        assert!(h.front);
        let h = shoot(Vec3::new(0.25, 0.5, -2.0), Vec3::Z, tri).unwrap();
        assert!(!h.front);
        // Facing agrees with the geometric normal for every dominant axis.
        for d in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z] {
            let n = -d;
            let (s, t) = n.any_orthonormal_pair();
            let c = d * 3.0;
            let tri = [c - s - t, c + s - t, c + t];
            let front_facing = geometric_normal(tri[0], tri[1], tri[2]).dot(d) < 0.0;
            let h = shoot(Vec3::ZERO, d, tri).unwrap();
            assert_eq!(h.front, front_facing, "dir {d}");
        }
        assert!(shoot(Vec3::new(0.6, 0.6, 2.0), -Vec3::Z, tri).is_none());
        assert!(shoot(Vec3::new(0.25, 0.5, 2.0), Vec3::Z, tri).is_none());
    }

    #[test]
    fn shared_edges_are_watertight() {
        // A quad split along its diagonal, hit exactly on the diagonal and the shared vertex.
        let q = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let mut misses = 0;
        for i in 0..=1000 {
            let x = i as f32 / 1000.0;
            let o = Vec3::new(x, x, 1.0);
            let d = Vec3::new(1e-3 * (i as f32).sin(), 1e-3 * (i as f32).cos(), -1.0);
            let a = shoot(o, d, [q[0], q[1], q[2]]);
            let b = shoot(o, d, [q[0], q[2], q[3]]);
            let inside = (o + d).x > 0.0 && (o + d).x < 1.0 && (o + d).y > 0.0 && (o + d).y < 1.0;
            if inside && a.is_none() && b.is_none() {
                misses += 1;
            }
        }
        assert_eq!(misses, 0);
    }

    #[test]
    fn nan_vertices_never_hit() {
        let tri = [Vec3::NAN, Vec3::X, Vec3::Y];
        assert!(shoot(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, tri).is_none());
    }
}
