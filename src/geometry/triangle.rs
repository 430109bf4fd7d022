//! Watertight ray/triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection"): rays never slip through shared edges or vertices of a closed mesh.

use super::PrimitiveHit;
use super::ray::Ray;
use glam::{DVec3, Vec3, Vec4, Vec4Swizzles};

/// A triangle as the intersection test reads it: the x, y and z coordinates of its three
/// vertices, each axis's three in a row, so that one four-lane load reads a coordinate of
/// all three vertices (lane i is vertex i; lane 3 reads the next row's first value, or the
/// padding, and is ignored).
#[derive(Clone, Copy, Debug)]
pub struct TriangleLanes {
    coords: [f32; 10],
}

impl TriangleLanes {
    /// The triangle with vertices `p` (counter-clockwise from its front).
    pub fn new(p: [Vec3; 3]) -> Self {
        let mut coords = [0.0; 10];
        for axis in 0..3 {
            coords[3 * axis..3 * axis + 3].copy_from_slice(&p.map(|v| v[axis]));
        }
        Self { coords }
    }

    #[inline(always)]
    fn row(&self, axis: usize) -> Vec4 {
        Vec4::from_slice(&self.coords[3 * axis..])
    }
}

/// Per-ray constants of the watertight test: the axis permutation (kx, ky, kz) that puts
/// the ray's largest direction component on z, the origin's coordinates on those axes, and
/// the shear (sx, sy, sz) that maps the ray onto +z, each broadcast to four lanes.
#[derive(Clone, Copy, Debug)]
pub struct RayShear {
    axes: [usize; 3],
    origin: [Vec4; 3],
    shear: [Vec4; 3],
}

impl RayShear {
    /// Precomputes the permutation and shear for `ray`.
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        let a = ray.dir.abs();
        // The largest component's axis (the later axis on ties), without branches:
        // ray directions are random, so a branch on them would often be mispredicted.
        let (x_largest, y_over_z) = (a.x > a.y && a.x > a.z, a.x <= a.y && a.y > a.z);
        let kz = 2 - 2 * x_largest as usize - y_over_z as usize;
        // Read by index from arrays, not from the vectors (whose indexing is a match).
        let (d, o) = (ray.dir.to_array(), ray.origin.to_array());
        // Swapping keeps the winding of triangles seen along the ray.
        let swap = (d[kz] < 0.0) as usize;
        let (kx, ky) = ([1, 2, 0][kz], [2, 0, 1][kz]);
        let (kx, ky) = ([kx, ky][swap], [ky, kx][swap]);
        // One reciprocal for the three ratios: watertightness needs every triangle tested
        // with the same shear, not the shear's exact rounding.
        let sz = 1.0 / d[kz];
        Self {
            axes: [kx, ky, kz],
            origin: [kx, ky, kz].map(|k| Vec4::splat(o[k])),
            shear: [d[kx] * sz, d[ky] * sz, sz].map(Vec4::splat),
        }
    }
}

/// Intersects the ray described by `shear` with triangle `tri` in `(0, tmax)`. The three
/// vertices go through each step together, lane by lane, with the scalar test's operations
/// in its order (Woop et al.'s transformed vertices, edge functions and scaled distance):
/// hits, distances and barycentrics are theirs to the bit.
#[inline(always)]
pub fn intersect(s: &RayShear, tri: &TriangleLanes, tmax: f32) -> Option<PrimitiveHit> {
    let [kx, ky, kz] = s.axes;
    // Vertices relative to the origin, permuted and sheared: x = (ax, bx, cx), y likewise.
    let z = tri.row(kz) - s.origin[2];
    let x = (tri.row(kx) - s.origin[0]) - s.shear[0] * z;
    let y = (tri.row(ky) - s.origin[1]) - s.shear[1] * z;
    // Edge functions (u, v, w) = (cx by - cy bx, ax cy - ay cx, bx ay - by ax).
    let mut uvw = x.zxyw() * y.yzxw() - y.zxyw() * x.yzxw();
    // On an edge in single precision: decide it exactly in double precision.
    if uvw.cmpeq(Vec4::ZERO).bitmask() & 7 != 0 {
        let ([ax, bx, cx, _], [ay, by, cy, _]) = (x.to_array(), y.to_array());
        let (ax, ay, bx, by, cx, cy) = (
            ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
        );
        uvw = Vec4::new(
            (cx * by - cy * bx) as f32,
            (ax * cy - ay * cx) as f32,
            (bx * ay - by * ax) as f32,
            0.0,
        );
    }
    // Inside when no edge function has a sign opposite to another's (NaN has neither).
    if uvw.cmplt(Vec4::ZERO).bitmask() & 7 != 0 && uvw.cmpgt(Vec4::ZERO).bitmask() & 7 != 0 {
        return None;
    }
    let [u, v, w, _] = uvw.to_array();
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let [az, bz, cz, _] = (s.shear[2] * z).to_array();
    let t_scaled = u * az + v * bz + w * cz;
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
        intersect(&RayShear::new(&ray), &TriangleLanes::new(p), f32::INFINITY)
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

    /// Woop et al.'s test written out scalar, as in the paper: permute by run-time index,
    /// shear, edge functions (exact in double precision when one is zero), scaled distance.
    fn scalar_watertight(o: Vec3, d: Vec3, p: [Vec3; 3], tmax: f32) -> Option<PrimitiveHit> {
        let a = d.abs();
        let kz = if a.x > a.y {
            if a.x > a.z { 0 } else { 2 }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = 1.0 / d[kz];
        let (sx, sy) = (d[kx] * sz, d[ky] * sz);
        let [a, b, c] = p.map(|v| v - o);
        let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
        let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
        let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            let f = |x: f32| x as f64;
            u = (f(cx) * f(by) - f(cy) * f(bx)) as f32;
            v = (f(ax) * f(cy) - f(ay) * f(cx)) as f32;
            w = (f(bx) * f(ay) - f(by) * f(ax)) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let t_scaled = u * (sz * a[kz]) + v * (sz * b[kz]) + w * (sz * c[kz]);
        let inv_det = 1.0 / det;
        let t = t_scaled * inv_det;
        (t > 0.0 && t < tmax).then_some(PrimitiveHit {
            t,
            b1: v * inv_det,
            b2: w * inv_det,
            front: det > 0.0,
        })
    }

    /// The lane-wise test gives the scalar test's answer to the bit (hit, distance,
    /// barycentrics, facing) for oblique rays in every octant: at random points, at
    /// vertices and along edges (where the double-precision decision runs), and past the
    /// bound. The rays aim at known points, and the hit lies there.
    #[test]
    fn lanes_match_the_scalar_watertight_test_to_the_bit() {
        let mut rng = crate::sampling::pcg::Pcg32::new(17, 5);
        let mut unit = || rng.next_f32();
        let (mut hits, mut exact_edges) = (0, 0);
        for k in 0..20000 {
            let mut point = || Vec3::new(unit(), unit(), unit()) * 4.0 - Vec3::splat(2.0);
            let tri = [point(), point(), point()];
            let o = point() * 3.0;
            // Aim at a random barycentric point, a vertex, or an edge's midpoint.
            let (b1, b2) = match k % 4 {
                0 | 1 => {
                    let (r1, r2) = (unit(), unit());
                    if r1 + r2 > 1.0 {
                        (1.0 - r1, 1.0 - r2)
                    } else {
                        (r1, r2)
                    }
                }
                2 => (0.0, 0.0),
                _ => (0.5, 0.0),
            };
            let target = tri[0] * (1.0 - b1 - b2) + tri[1] * b1 + tri[2] * b2;
            let d = target - o;
            let tmax = if k % 5 == 0 { 0.5 } else { f32::INFINITY };
            let lanes = intersect(
                &RayShear::new(&Ray {
                    origin: o,
                    dir: d,
                    tmax,
                }),
                &TriangleLanes::new(tri),
                tmax,
            );
            let scalar = scalar_watertight(o, d, tri, tmax);
            let bits = |h: Option<PrimitiveHit>| {
                h.map(|h| (h.t.to_bits(), h.b1.to_bits(), h.b2.to_bits(), h.front))
            };
            assert_eq!(bits(lanes), bits(scalar), "ray {o} {d}, triangle {tri:?}");
            if let Some(h) = lanes {
                hits += 1;
                exact_edges += (h.b1 == 0.0 || h.b2 == 0.0) as u32;
                if k % 4 < 2 && tmax.is_infinite() {
                    assert!(
                        (h.t - 1.0).abs() < 1e-3,
                        "t {} for a ray aimed at t = 1",
                        h.t
                    );
                    assert!((h.b1 - b1).abs() < 1e-3 && (h.b2 - b2).abs() < 1e-3);
                }
            }
        }
        assert!(
            hits > 10000 && exact_edges > 1000,
            "{hits} hits, {exact_edges} on edges"
        );
    }
}
