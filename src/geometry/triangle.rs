//! Watertight ray/triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection"): rays never slip through shared edges or vertices of a closed mesh.

use super::hit::PrimitiveHit;
use super::ray::Ray;
#[cfg(target_arch = "x86_64")]
use crate::simd::{F8, LANES, M8, V3};
use glam::{DVec3, Vec3, Vec4};

/// The set bits of a lane mask, lowest first.
#[derive(Clone, Copy, Debug)]
pub struct Lanes(u32);

impl Lanes {
    /// The set bits of `mask`, a mask of [`LANES`] lanes.
    #[inline(always)]
    pub fn new(mask: u32) -> Self {
        debug_assert!(mask >> LANES == 0, "lane mask {mask:#x}");
        Self(mask)
    }
}

impl Iterator for Lanes {
    type Item = usize;

    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        if self.0 == 0 {
            return None;
        }
        // Masked to the lanes (a no-op for a lane mask), so that indexing an array of LANES
        // by it needs no bounds check (0.6 % of the Cornell box's instructions).
        let lane = self.0.trailing_zeros() as usize & (LANES - 1);
        self.0 &= self.0 - 1;
        Some(lane)
    }
}

/// Up to four triangles as the lane-wise test reads them (Embree's Triangle4 layout): lane
/// i of `coords[v][axis]` is coordinate `axis` of vertex `v` of the block's i-th triangle. One
/// test of four lanes decides all four triangles for about the cost of one. Lanes without a
/// triangle hold NaN vertices, which no ray hits (every comparison with NaN fails).
#[derive(Clone, Copy, Debug)]
pub struct TriangleBlock {
    coords: [[Vec4; 3]; 3],
}

impl TriangleBlock {
    /// The block of `tris` (one to four, each counter-clockwise from its front).
    pub fn new(tris: &[[Vec3; 3]]) -> Self {
        assert!((1..=4).contains(&tris.len()));
        let mut coords = [[Vec4::NAN; 3]; 3];
        for (lane, tri) in tris.iter().enumerate() {
            for (v, p) in tri.iter().enumerate() {
                for axis in 0..3 {
                    coords[v][axis][lane] = p[axis];
                }
            }
        }
        Self { coords }
    }

    /// How many triangles the block holds (in its first lanes).
    #[inline(always)]
    pub fn triangles(&self) -> usize {
        4 - self.coords[0][0].is_nan_mask().bitmask().count_ones() as usize
    }
}

/// A ray's hits on the triangles of a [`TriangleBlock`], lane by lane.
#[derive(Clone, Copy, Debug)]
pub struct BlockHits {
    /// Bit i is set when the ray hits lane i's triangle in `(0, tmax)`.
    pub mask: u32,
    pub t: [f32; 4],
    pub b1: [f32; 4],
    pub b2: [f32; 4],
    /// Bit i is set when the ray arrives on lane i's front.
    pub front: u32,
}

impl BlockHits {
    /// The lanes hit, in lane order.
    #[inline(always)]
    pub fn lanes(&self) -> Lanes {
        Lanes(self.mask)
    }

    /// Lane `lane`'s hit (meaningful when its bit in `mask` is set).
    #[inline(always)]
    pub fn get(&self, lane: usize) -> PrimitiveHit {
        PrimitiveHit {
            t: self.t[lane],
            b1: self.b1[lane],
            b2: self.b2[lane],
            front: self.front & (1 << lane) != 0,
        }
    }
}

/// Per-ray constants of the watertight test: the axis permutation (kx, ky, kz) that puts
/// the ray's largest direction component on z, the origin's coordinates on those axes, and
/// the shear (sx, sy, sz) that maps the ray onto +z, each broadcast to four lanes.
#[derive(Clone, Copy, Debug, Default)]
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

/// Intersects the ray described by `shear` with the triangles of `block` in `(0, tmax)`;
/// `None` when it hits none. Each lane runs Woop et al.'s scalar test's operations in its
/// order (transformed vertices, edge functions, scaled distance): hits, distances and
/// barycentrics are the scalar test's to the bit.
#[inline(always)]
pub fn intersect(s: &RayShear, block: &TriangleBlock, tmax: f32) -> Option<BlockHits> {
    let [kx, ky, kz] = s.axes;
    let (origin, shear) = (&s.origin, &s.shear);
    // Vertex v relative to the origin, permuted and sheared, for the four triangles.
    let vertex = |v: usize| {
        let c = &block.coords[v];
        let z = c[kz] - origin[2];
        let x = (c[kx] - origin[0]) - shear[0] * z;
        let y = (c[ky] - origin[1]) - shear[1] * z;
        (x, y, z)
    };
    let ((ax, ay, az), (bx, by, bz), (cx, cy, cz)) = (vertex(0), vertex(1), vertex(2));
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    // On an edge in single precision: decide it exactly in double precision.
    let on_edge = (u.cmpeq(Vec4::ZERO) | v.cmpeq(Vec4::ZERO) | w.cmpeq(Vec4::ZERO)).bitmask();
    if on_edge != 0 {
        (u, v, w) = exact_edge_functions(on_edge, [ax, ay, bx, by, cx, cy], [u, v, w]);
    }
    // Inside when no edge function has a sign opposite to another's. NaN fails both
    // comparisons, so empty lanes and NaN vertices end here.
    let zero = Vec4::ZERO;
    let non_negative = u.cmpge(zero) & v.cmpge(zero) & w.cmpge(zero);
    let non_positive = u.cmple(zero) & v.cmple(zero) & w.cmple(zero);
    let inside = (non_negative | non_positive).bitmask();
    if inside == 0 {
        return None;
    }
    let det = u + v + w;
    let sz = shear[2];
    let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
    let inv_det = Vec4::ONE / det;
    let t = t_scaled * inv_det;
    // Positive comparisons: NaN fails them.
    let valid = det.cmpne(Vec4::ZERO) & t.cmpgt(Vec4::ZERO) & t.cmplt(Vec4::splat(tmax));
    let mask = inside & valid.bitmask();
    (mask != 0).then(|| BlockHits {
        mask,
        t: t.to_array(),
        b1: (v * inv_det).to_array(),
        b2: (w * inv_det).to_array(),
        front: det.cmpgt(Vec4::ZERO).bitmask(),
    })
}

/// The edge functions of the `lanes` whose single-precision ones have a zero, recomputed in
/// double precision from the transformed vertices `[ax, ay, bx, by, cx, cy]`.
#[cold]
#[inline(never)]
fn exact_edge_functions(lanes: u32, xy: [Vec4; 6], uvw: [Vec4; 3]) -> (Vec4, Vec4, Vec4) {
    let [ax, ay, bx, by, cx, cy] = xy.map(|c| c.to_array().map(f64::from));
    let [mut u, mut v, mut w] = uvw.map(|c| c.to_array());
    for l in (0..4).filter(|l| lanes & (1 << l) != 0) {
        u[l] = (cx[l] * by[l] - cy[l] * bx[l]) as f32;
        v[l] = (ax[l] * cy[l] - ay[l] * cx[l]) as f32;
        w[l] = (bx[l] * ay[l] - by[l] * ax[l]) as f32;
    }
    (Vec4::from(u), Vec4::from(v), Vec4::from(w))
}

/// Eight rays' constants of the watertight test, one a lane: [`RayShear`]s transposed, for
/// testing one triangle against a packet ([`intersect_lanes`]).
#[cfg(target_arch = "x86_64")]
pub(crate) struct ShearLanes {
    /// Per permuted axis (kx, ky, kz): the lanes where it is the x axis, and where it is the
    /// y axis (the z axis elsewhere).
    is_x: [M8; 3],
    is_y: [M8; 3],
    origin: [F8; 3],
    shear: [F8; 3],
}

#[cfg(target_arch = "x86_64")]
impl ShearLanes {
    /// The constants of the rays from `origin` along `dir` (one a lane): [`RayShear::new`]'s
    /// operations in lanes, so each lane's are its ray's to the bit.
    #[inline(always)]
    pub(crate) fn of_rays(origin: V3, dir: V3) -> Self {
        let (ox, oy, oz) = (origin.x, origin.y, origin.z);
        let (dx, dy, dz) = (dir.x, dir.y, dir.z);
        let (ax, ay, az) = (dx.abs(), dy.abs(), dz.abs());
        // kz is x where x is largest, y where y is above x and z, z otherwise.
        let kz_x = ay.lt(ax) & az.lt(ax);
        let kz_y = ax.le(ay) & az.lt(ay);
        let kz_z = !(kz_x | kz_y);
        let dkz = F8::select(kz_x, dx, F8::select(kz_y, dy, dz));
        // kx follows kz cyclically (z, x, y for x, y, z), ky after it; swapped where the
        // ray runs down kz.
        let swap = dkz.lt(F8::ZERO);
        let (kx_x, kx_y) = (kz_z, kz_x);
        let (ky_x, ky_y) = (kz_y, kz_z);
        let mut lanes = Self {
            is_x: [
                (swap & ky_x) | kx_x.and_not(swap),
                (swap & kx_x) | ky_x.and_not(swap),
                kz_x,
            ],
            is_y: [
                (swap & ky_y) | kx_y.and_not(swap),
                (swap & kx_y) | ky_y.and_not(swap),
                kz_y,
            ],
            origin: [F8::ZERO; 3],
            shear: [F8::ZERO; 3],
        };
        let sz = F8::ONE / dkz;
        for k in 0..3 {
            lanes.origin[k] = lanes.pick(k, ox, oy, oz);
        }
        lanes.shear = [
            lanes.pick(0, dx, dy, dz) * sz,
            lanes.pick(1, dx, dy, dz) * sz,
            sz,
        ];
        lanes
    }

    /// Lane `lane`'s constants, for its single-ray tests.
    #[inline(always)]
    pub(crate) fn lane(&self, lane: usize) -> RayShear {
        let mut shear = RayShear::default();
        // Plain loops: closures would compile outside the packet kernel's AVX2 context.
        for k in 0..3 {
            let (is_x, is_y) = (
                self.is_x[k].bits() >> lane & 1,
                self.is_y[k].bits() >> lane & 1,
            );
            shear.axes[k] = (2 - 2 * is_x - is_y) as usize;
            shear.origin[k] = Vec4::splat(self.origin[k].lane(lane));
            shear.shear[k] = Vec4::splat(self.shear[k].lane(lane));
        }
        shear
    }

    /// Coordinate `k` of the permutation of `(x, y, z)` in each lane.
    #[inline(always)]
    fn pick(&self, k: usize, x: F8, y: F8, z: F8) -> F8 {
        F8::select(self.is_x[k], x, F8::select(self.is_y[k], y, z))
    }

    /// Vertex `(x, y, z)` relative to each lane's origin, permuted and sheared.
    #[inline(always)]
    fn vertex(&self, x: f32, y: f32, z: f32) -> [F8; 3] {
        let (x, y, z) = (F8::splat(x), F8::splat(y), F8::splat(z));
        let sz = self.pick(2, x, y, z) - self.origin[2];
        let sx = (self.pick(0, x, y, z) - self.origin[0]) - self.shear[0] * sz;
        let sy = (self.pick(1, x, y, z) - self.origin[1]) - self.shear[1] * sz;
        [sx, sy, sz]
    }
}

/// A packet's hits on one triangle, lane by lane.
#[cfg(target_arch = "x86_64")]
pub(crate) struct LaneHits {
    /// Lanes that hit the triangle within their bound.
    pub mask: u32,
    t: F8,
    b1: F8,
    b2: F8,
    /// Lanes that arrive on the triangle's front.
    front: u32,
}

#[cfg(target_arch = "x86_64")]
impl LaneHits {
    /// Hits of an analytic shape, which have no barycentric coordinates: the lanes of `mask`
    /// at distances `t`, arriving on the front in the lanes of `front`.
    #[inline(always)]
    pub fn of_shape(mask: u32, t: F8, front: u32) -> Self {
        Self {
            mask,
            t,
            b1: F8::ZERO,
            b2: F8::ZERO,
            front,
        }
    }

    /// Lane `lane`'s hit (meaningful when its bit in `mask` is set).
    #[inline(always)]
    pub fn get(&self, lane: usize) -> PrimitiveHit {
        PrimitiveHit {
            t: self.t.lane(lane),
            b1: self.b1.lane(lane),
            b2: self.b2.lane(lane),
            front: self.front & (1 << lane) != 0,
        }
    }
}

/// Intersects triangle `tri` of `block` with the `active` lanes of a packet, each within
/// `(0, tmax)` of its lane. Each lane runs [`intersect`]'s operations in its order: its
/// hit, distance and barycentrics are those [`intersect`] gives its ray, to the bit. Runs
/// only inside the packet kernel (AVX2 and FMA; see `crate::simd`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn intersect_lanes(
    s: &ShearLanes,
    block: &TriangleBlock,
    tri: usize,
    tmax: F8,
    active: u32,
) -> Option<LaneHits> {
    // No closures over vectors here: one would compile outside the packet kernel's AVX2
    // context.
    // Read as arrays: a vector's index is a match.
    let c = |v: usize, axis: usize| AsRef::<[f32; 4]>::as_ref(&block.coords[v][axis])[tri];
    let [ax, ay, az] = s.vertex(c(0, 0), c(0, 1), c(0, 2));
    let [bx, by, bz] = s.vertex(c(1, 0), c(1, 1), c(1, 2));
    let [cx, cy, cz] = s.vertex(c(2, 0), c(2, 1), c(2, 2));
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    let zero = F8::ZERO;
    let on_edge = (u.eq(zero) | v.eq(zero) | w.eq(zero)).bits() & active;
    if on_edge != 0 {
        let xy = [ax, ay, bx, by, cx, cy].map(F8::to_array);
        let [eu, ev, ew] = exact_edge_functions_lanes(on_edge, xy, [u, v, w].map(F8::to_array));
        (u, v, w) = (F8::from_array(eu), F8::from_array(ev), F8::from_array(ew));
    }
    let non_negative = zero.le(u) & zero.le(v) & zero.le(w);
    let non_positive = u.le(zero) & v.le(zero) & w.le(zero);
    let inside = (non_negative | non_positive).bits() & active;
    if inside == 0 {
        return None;
    }
    let det = u + v + w;
    let sz = s.shear[2];
    let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
    let inv_det = F8::ONE / det;
    let t = t_scaled * inv_det;
    let valid = det.ne(zero) & t.gt(zero) & t.lt(tmax);
    let mask = inside & valid.bits();
    if mask == 0 {
        return None;
    }
    Some(LaneHits {
        mask,
        t,
        b1: v * inv_det,
        b2: w * inv_det,
        front: det.gt(zero).bits(),
    })
}

/// [`exact_edge_functions`] for the `lanes` of a packet (arrays, not vectors: this cold
/// function compiles outside the packet kernel's AVX2 context).
#[cfg(target_arch = "x86_64")]
#[cold]
#[inline(never)]
fn exact_edge_functions_lanes(
    lanes: u32,
    xy: [[f32; LANES]; 6],
    uvw: [[f32; LANES]; 3],
) -> [[f32; LANES]; 3] {
    let [ax, ay, bx, by, cx, cy] = xy.map(|c| c.map(f64::from));
    let [mut u, mut v, mut w] = uvw;
    for l in Lanes(lanes) {
        u[l] = (cx[l] * by[l] - cy[l] * bx[l]) as f32;
        v[l] = (ax[l] * cy[l] - ay[l] * cx[l]) as f32;
        w[l] = (bx[l] * ay[l] - by[l] * ax[l]) as f32;
    }
    [u, v, w]
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
        intersect(
            &RayShear::new(&ray),
            &TriangleBlock::new(&[p]),
            f32::INFINITY,
        )
        .map(|h| h.get(0))
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
    /// barycentrics, facing) on every lane of blocks of one to four triangles, for oblique
    /// rays in every octant: at random points, at vertices and along edges (where the
    /// double-precision decision runs), and past the bound. The rays aim at a known point of
    /// one of the block's triangles, and the hit lies there.
    #[test]
    fn lanes_match_the_scalar_watertight_test_to_the_bit() {
        let mut rng = crate::sampling::pcg::Pcg32::new(17, 5);
        let mut unit = || rng.next_f32();
        let (mut hits, mut exact_edges, mut other_lanes) = (0, 0, 0);
        for k in 0..20000 {
            let mut point = || Vec3::new(unit(), unit(), unit()) * 4.0 - Vec3::splat(2.0);
            let lanes = 1 + (k / 4) % 4;
            let tris: Vec<[Vec3; 3]> = (0..lanes).map(|_| [point(), point(), point()]).collect();
            let aimed = (k / 16) % lanes;
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
            let tri = tris[aimed];
            let target = tri[0] * (1.0 - b1 - b2) + tri[1] * b1 + tri[2] * b2;
            let d = target - o;
            let tmax = if k % 5 == 0 { 0.5 } else { f32::INFINITY };
            let ray = Ray {
                origin: o,
                dir: d,
                tmax,
                time: 0.0,
            };
            let block = intersect(&RayShear::new(&ray), &TriangleBlock::new(&tris), tmax);
            let bits = |h: Option<PrimitiveHit>| {
                h.map(|h| (h.t.to_bits(), h.b1.to_bits(), h.b2.to_bits(), h.front))
            };
            for (lane, &tri) in tris.iter().enumerate() {
                let lane_hit = block
                    .filter(|b| b.mask & (1 << lane) != 0)
                    .map(|b| b.get(lane));
                let scalar = scalar_watertight(o, d, tri, tmax);
                assert_eq!(
                    bits(lane_hit),
                    bits(scalar),
                    "ray {o} {d}, triangle {tri:?}"
                );
                if lane != aimed {
                    other_lanes += lane_hit.is_some() as u32;
                }
            }
            assert_eq!(
                block.map_or(0, |b| b.mask) >> lanes,
                0,
                "empty lanes never hit"
            );
            if let Some(h) = block
                .filter(|b| b.mask & (1 << aimed) != 0)
                .map(|b| b.get(aimed))
            {
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
            hits > 10000 && exact_edges > 1000 && other_lanes > 1000,
            "{hits} hits, {exact_edges} on edges, {other_lanes} on lanes not aimed at"
        );
    }

    /// The packet test ([`intersect_lanes`]) gives each lane's ray what the single-ray
    /// block test gives it, to the bit, for every triangle of blocks of one to four (and
    /// the lanes' constants are each ray's [`RayShear`], to the bit): eight
    /// rays from anywhere, each aimed at a random point, a vertex or an edge's midpoint of
    /// one of the triangles (where the double-precision decision runs), with their own
    /// bounds (some exactly at the hit) and random idle lanes.
    #[test]
    fn packet_test_matches_the_block_test_to_the_bit() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let mut rng = crate::sampling::pcg::Pcg32::new(23, 7);
        let point = |rng: &mut crate::sampling::pcg::Pcg32| {
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - Vec3::splat(2.0)
        };
        let (mut hits, mut edges) = (0, 0);
        for k in 0..5000 {
            let count = 1 + k % 4;
            let tris: Vec<[Vec3; 3]> = (0..count)
                .map(|_| [point(&mut rng), point(&mut rng), point(&mut rng)])
                .collect();
            let block = TriangleBlock::new(&tris);
            let mut rays: [Ray; LANES] = std::array::from_fn(|lane| {
                let tri = tris[lane % count];
                let (b1, b2) = match (k + lane) % 4 {
                    0 | 1 => (0.3 * rng.next_f32(), 0.6 * rng.next_f32()),
                    2 => (0.0, 0.0),
                    _ => (0.5, 0.0),
                };
                let target = tri[0] * (1.0 - b1 - b2) + tri[1] * b1 + tri[2] * b2;
                let origin = point(&mut rng) * 3.0;
                let tmax = if (k + lane) % 5 == 0 {
                    0.5
                } else {
                    f32::INFINITY
                };
                Ray {
                    origin,
                    dir: target - origin,
                    tmax,
                    time: 0.0,
                }
            });
            let active = if k % 3 == 0 {
                0xff
            } else {
                rng.next_u32() >> 24
            };
            let shears = rays.each_ref().map(RayShear::new);
            // SAFETY: the CPU has AVX2 and FMA.
            let lanes = unsafe { shear_lanes(&rays) };
            for (lane, shear) in shears.iter().enumerate() {
                let l = lanes.lane(lane);
                assert_eq!(l.axes, shear.axes, "packet {k}");
                let bits = |v: [Vec4; 3]| v.map(|v| v.to_array().map(f32::to_bits));
                assert_eq!(bits(l.origin), bits(shear.origin));
                assert_eq!(bits(l.shear), bits(shear.shear));
            }
            // Some lanes bounded at exactly their aimed triangle's distance, which is out.
            for (lane, ray) in rays.iter_mut().enumerate() {
                if (k + lane) % 5 == 1
                    && let Some(b) = intersect(&shears[lane], &block, f32::INFINITY)
                    && b.mask & (1 << (lane % count)) != 0
                {
                    ray.tmax = b.get(lane % count).t;
                }
            }
            assert_eq!(block.triangles(), count);
            for tri in 0..count {
                // SAFETY: the CPU has AVX2 and FMA.
                let lanes = unsafe { packet_test(&block, tri, &rays, active) };
                for (lane, ray) in rays.iter().enumerate() {
                    let single = intersect(&shears[lane], &block, ray.tmax)
                        .filter(|b| b.mask & (1 << tri) != 0)
                        .map(|b| b.get(tri));
                    let expected = single.filter(|_| active & (1 << lane) != 0);
                    let bits = |h: Option<PrimitiveHit>| {
                        h.map(|h| (h.t.to_bits(), h.b1.to_bits(), h.b2.to_bits(), h.front))
                    };
                    assert_eq!(bits(lanes[lane]), bits(expected), "packet {k}, lane {lane}");
                    hits += expected.is_some() as u32;
                    edges += (expected.is_some() && (k + lane) % 4 >= 2) as u32;
                }
            }
        }
        assert!(
            hits > 10000 && edges > 3000,
            "{hits} hits, {edges} at vertices and edges"
        );
    }

    /// [`ShearLanes::of_rays`] of `rays`, compiled for AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    fn shear_lanes(rays: &[Ray; LANES]) -> ShearLanes {
        let (origin, dir) = (rays.map(|r| r.origin), rays.map(|r| r.dir));
        ShearLanes::of_rays(V3::from_lanes(&origin), V3::from_lanes(&dir))
    }

    /// [`intersect_lanes`] of triangle `tri` for the packet `rays`, compiled for AVX2 and
    /// FMA, as each lane's hit.
    #[target_feature(enable = "avx2,fma")]
    fn packet_test(
        block: &TriangleBlock,
        tri: usize,
        rays: &[Ray; LANES],
        active: u32,
    ) -> [Option<PrimitiveHit>; LANES] {
        let mut tmax = [0.0; LANES];
        for (t, ray) in tmax.iter_mut().zip(rays) {
            *t = ray.tmax;
        }
        let hits = intersect_lanes(&shear_lanes(rays), block, tri, F8::from_array(tmax), active);
        let mut out = [None; LANES];
        if let Some(h) = hits {
            for lane in Lanes(h.mask) {
                out[lane] = Some(h.get(lane));
            }
        }
        out
    }
}
