//! Geometry in render space: triangles, the BVH over them (four-wide, built by obvhs),
//! and the two ray queries the integrator needs: closest hit and occlusion.

pub mod frame;
pub mod instances;
pub mod quadric;
pub mod ray;
pub mod sphere;
pub mod triangle;
pub mod wide;

use glam::Vec3;
use obvhs::aabb::Aabb;
use ray::Ray;
use triangle::{RayShear, TriangleLanes};
use wide::{LeafResult, WideBvh};

/// A primitive the BVH holds.
#[derive(Clone, Copy, Debug)]
pub enum Primitive {
    /// A triangle, counter-clockwise from its front.
    Triangle([Vec3; 3]),
    /// A sphere; its front is the outside.
    Sphere { centre: Vec3, radius: f32 },
    /// A disk (front towards its normal) or an open cylinder (front outside).
    Quadric(quadric::Quadric),
}

impl Primitive {
    fn aabb(&self) -> Aabb {
        match *self {
            Self::Triangle([a, b, c]) => Aabb::new(a.min(b).min(c).into(), a.max(b).max(c).into()),
            Self::Sphere { centre, radius } => {
                Aabb::new((centre - radius).into(), (centre + radius).into())
            }
            Self::Quadric(q) => {
                let (lo, hi) = q.bounds();
                Aabb::new(lo.into(), hi.into())
            }
        }
    }
}

/// A primitive's intersection with a ray, before the caller's filter.
#[derive(Clone, Copy, Debug)]
pub struct PrimitiveHit {
    pub t: f32,
    /// Barycentric weights of triangle vertices 1 and 2 (vertex 0 has `1 - b1 - b2`); 0 for
    /// the analytic shapes.
    pub b1: f32,
    pub b2: f32,
    /// True when the ray arrives on the primitive's front (a triangle's counter-clockwise
    /// side, a sphere's outside).
    pub front: bool,
}

/// Intersection flag: the primitive is invisible from its back (glTF `doubleSided: false`).
pub const CULL_BACK: u8 = 1;
/// Intersection flag: the primitive's material has an alpha cut-out; the caller's filter
/// decides whether a hit counts.
pub const ALPHA_TESTED: u8 = 2;

/// A ray's closest accepted hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    /// Index of the primitive in the order given to [`Bvh::build`] (of the shared BVH for
    /// a placed hit).
    pub prim: u32,
    pub b1: f32,
    pub b2: f32,
    pub front: bool,
    /// The placement hit in an [`instances::InstancedBvh`], or [`NOT_PLACED`].
    pub instance: u32,
}

/// [`Hit::instance`] of a hit on geometry that is not placed through a shared BVH.
pub const NOT_PLACED: u32 = u32::MAX;

/// A primitive as a BVH leaf stores it: triangles laid out for the lane-wise test.
#[derive(Clone, Copy, Debug)]
enum LeafPrimitive {
    Triangle(TriangleLanes),
    Sphere { centre: Vec3, radius: f32 },
    Quadric(quadric::Quadric),
}

impl From<Primitive> for LeafPrimitive {
    fn from(p: Primitive) -> Self {
        match p {
            Primitive::Triangle(p) => Self::Triangle(TriangleLanes::new(p)),
            Primitive::Sphere { centre, radius } => Self::Sphere { centre, radius },
            Primitive::Quadric(q) => Self::Quadric(q),
        }
    }
}

/// A BVH over primitives with per-primitive flags, answering closest-hit and occlusion
/// queries.
pub struct Bvh {
    bvh: WideBvh,
    /// Primitives in BVH leaf order, so leaves read them without indirection.
    prims: Vec<LeafPrimitive>,
    flags: Vec<u8>,
}

impl Bvh {
    /// Builds the BVH over `prims` (render space) with their intersection `flags`. Runs on
    /// the current rayon pool.
    pub fn build(prims: &[Primitive], flags: &[u8]) -> Self {
        assert_eq!(prims.len(), flags.len());
        let aabbs: Vec<Aabb> = prims.iter().map(Primitive::aabb).collect();
        let bvh = WideBvh::build(&aabbs);
        drop(aabbs);
        Self {
            prims: bvh
                .order
                .iter()
                .map(|&i| prims[i as usize].into())
                .collect(),
            flags: bvh.order.iter().map(|&i| flags[i as usize]).collect(),
            bvh,
        }
    }

    /// Bytes the structure holds: wide nodes, and per primitive its data, flags and index.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.bvh.bytes() + self.prims.len() * (size_of::<LeafPrimitive>() + size_of::<u8>())
    }

    /// Tests one leaf primitive; `accept` is consulted only for alpha-tested ones.
    #[inline(always)]
    fn test<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        leaf: usize,
        ray: &Ray,
        shear: &RayShear,
        tmax: f32,
        accept: &mut F,
    ) -> Option<PrimitiveHit> {
        let hit = match self.prims[leaf] {
            LeafPrimitive::Triangle(ref t) => triangle::intersect(shear, t, tmax)?,
            LeafPrimitive::Sphere { centre, radius } => {
                sphere::intersect(ray, centre, radius, tmax)?
            }
            LeafPrimitive::Quadric(q) => q.intersect(ray, tmax)?,
        };
        let flags = self.flags[leaf];
        if flags != 0 {
            if flags & CULL_BACK != 0 && !hit.front {
                return None;
            }
            if flags & ALPHA_TESTED != 0 && !accept(self.bvh.order[leaf], &hit) {
                return None;
            }
        }
        Some(hit)
    }

    /// Closest hit along `ray` in `(0, ray.tmax)`. `accept(prim, hit)` filters hits on
    /// alpha-tested triangles.
    pub fn intersect<F: FnMut(u32, &PrimitiveHit) -> bool>(
        &self,
        ray: &Ray,
        mut accept: F,
    ) -> Option<Hit> {
        let shear = RayShear::new(ray);
        let mut best: Option<(usize, PrimitiveHit)> = None;
        let mut best_prim = u32::MAX;
        self.bvh.traverse(ray, |leaves, tmax| {
            let mut result = LeafResult::Miss;
            let mut tmax = tmax;
            for leaf in leaves {
                // A hit at exactly the closest distance so far wins if its primitive was
                // given first: coincident primitives resolve to the same one whatever the
                // BVH's layout and traversal order.
                let bound = if best.is_some() { tmax.next_up() } else { tmax };
                if let Some(hit) = self.test(leaf, ray, &shear, bound, &mut accept) {
                    let prim = self.bvh.order[leaf];
                    if hit.t < tmax || prim < best_prim {
                        tmax = hit.t;
                        best_prim = prim;
                        result = LeafResult::Closer(hit.t);
                        best = Some((leaf, hit));
                    }
                }
            }
            result
        });
        best.map(|(leaf, h)| Hit {
            t: h.t,
            prim: self.bvh.order[leaf],
            b1: h.b1,
            b2: h.b2,
            front: h.front,
            instance: NOT_PLACED,
        })
    }

    /// True if anything accepted lies along `ray` in `(0, ray.tmax)`; stops at the first hit.
    pub fn occluded<F: FnMut(u32, &PrimitiveHit) -> bool>(&self, ray: &Ray, mut accept: F) -> bool {
        let shear = RayShear::new(ray);
        let mut occluded = false;
        self.bvh.traverse(ray, |leaves, _| {
            for leaf in leaves {
                if self
                    .test(leaf, ray, &shear, ray.tmax, &mut accept)
                    .is_some()
                {
                    occluded = true;
                    return LeafResult::Stop;
                }
            }
            LeafResult::Miss
        });
        occluded
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prims(tris: &[[Vec3; 3]]) -> Vec<Primitive> {
        tris.iter().map(|&t| Primitive::Triangle(t)).collect()
    }

    #[test]
    fn spheres_and_triangles_share_the_bvh() {
        let mut p = prims(&cube());
        p.push(Primitive::Sphere {
            centre: Vec3::new(3.0, 0.5, 0.5),
            radius: 0.5,
        });
        let bvh = Bvh::build(&p, &vec![0; p.len()]);
        let hit = bvh
            .intersect(&Ray::new(Vec3::new(5.0, 0.5, 0.5), -Vec3::X), |_, _| true)
            .unwrap();
        assert_eq!(hit.prim, 12);
        assert!((hit.t - 1.5).abs() < 1e-6 && hit.front);
        let hit = bvh
            .intersect(&Ray::new(Vec3::new(2.9, 0.5, 0.5), -Vec3::X), |_, _| true)
            .unwrap();
        assert!(
            hit.prim == 12 && (hit.t - 0.4).abs() < 1e-5 && !hit.front,
            "the sphere's inside"
        );
        let hit = bvh
            .intersect(&Ray::new(Vec3::new(2.4, 0.5, 0.5), -Vec3::X), |_, _| true)
            .unwrap();
        assert!(
            hit.prim < 12 && (hit.t - 1.4).abs() < 1e-5,
            "past the sphere, the cube"
        );
    }

    /// A closed unit cube of 12 triangles, wound outwards.
    pub(super) fn cube() -> Vec<[Vec3; 3]> {
        let c = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let quads = [
            [c(0., 0., 0.), c(0., 1., 0.), c(1., 1., 0.), c(1., 0., 0.)],
            [c(0., 0., 1.), c(1., 0., 1.), c(1., 1., 1.), c(0., 1., 1.)],
            [c(0., 0., 0.), c(1., 0., 0.), c(1., 0., 1.), c(0., 0., 1.)],
            [c(0., 1., 0.), c(0., 1., 1.), c(1., 1., 1.), c(1., 1., 0.)],
            [c(0., 0., 0.), c(0., 0., 1.), c(0., 1., 1.), c(0., 1., 0.)],
            [c(1., 0., 0.), c(1., 1., 0.), c(1., 1., 1.), c(1., 0., 1.)],
        ];
        quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect()
    }

    /// A soup of 3,000 random triangles (sizes over three decades, with exact duplicates)
    /// against brute force, for random rays from inside and outside it with random bounds:
    /// the same closest hit (distance, and the first-given primitive of coincident ones) and
    /// the same occlusion answer. This exercises multi-level nodes, nearest-first order and
    /// pruning by the closest hit.
    #[test]
    fn closest_hits_and_occlusion_match_brute_force() {
        let mut rng = crate::sampling::pcg::Pcg32::new(11, 3);
        let mut point = |scale: f32| {
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 * scale
                - Vec3::splat(scale)
        };
        let mut tris = Vec::new();
        for i in 0..3000 {
            let size = [0.01, 0.1, 1.0][i % 3];
            let c = point(4.0);
            tris.push([c + point(size), c + point(size), c + point(size)]);
            if i % 50 == 0 {
                tris.push(tris[tris.len() - 1]);
            }
        }
        let bvh = Bvh::build(&prims(&tris), &vec![0; tris.len()]);
        let mut hits = 0;
        for k in 0..4000 {
            let origin = point(6.0);
            let dir = point(1.0);
            let tmax = if k % 2 == 0 { f32::INFINITY } else { 4.0 };
            let ray = Ray { origin, dir, tmax };
            let shear = RayShear::new(&ray);
            let brute = tris
                .iter()
                .enumerate()
                .filter_map(|(i, t)| {
                    Some((
                        triangle::intersect(&shear, &TriangleLanes::new(*t), tmax)?,
                        i,
                    ))
                })
                .min_by(|a, b| a.0.t.total_cmp(&b.0.t).then(a.1.cmp(&b.1)));
            let hit = bvh.intersect(&ray, |_, _| true);
            assert_eq!(
                hit.map(|h| (h.t, h.prim)),
                brute.map(|(h, i)| (h.t, i as u32)),
                "ray {ray:?}"
            );
            assert_eq!(bvh.occluded(&ray, |_, _| true), brute.is_some());
            hits += brute.is_some() as u32;
        }
        assert!(hits > 1000, "only {hits} rays hit");
    }

    #[test]
    fn rays_from_inside_a_closed_cube_always_hit_it() {
        let tris = cube();
        let bvh = Bvh::build(&prims(&tris), &vec![0; tris.len()]);
        let mut rng = crate::sampling::pcg::Pcg32::new(7, 0);
        for _ in 0..20000 {
            let o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let u = glam::Vec2::new(rng.next_f32(), rng.next_f32());
            let d = crate::sampling::warp::square_to_uniform_sphere(u);
            let hit = bvh
                .intersect(&Ray::new(o, d), |_, _| true)
                .expect("escaped the cube");
            assert!(!hit.front, "the inside sees back faces");
            // Brute force agrees on the distance.
            let shear = RayShear::new(&Ray::new(o, d));
            let best = tris
                .iter()
                .filter_map(|t| triangle::intersect(&shear, &TriangleLanes::new(*t), f32::INFINITY))
                .map(|h| h.t)
                .fold(f32::INFINITY, f32::min);
            assert_eq!(hit.t, best);
        }
    }

    /// Geometry nested over every float exponent (clusters of 64 triangles at 2^-120 ..
    /// 2^119 along a line) needs more than the inline stack when a ray runs along it: the
    /// traversal descends into the small end first, pushing the larger clusters (45 groups
    /// deep). With only clusters from scale 2^`first` on accepted (as alpha testing would),
    /// the closest accepted hit lies in pushed groups. The stack spills, and the BVH finds
    /// what brute force finds. (obvhs's overwriting stack happens to pass this too: the
    /// groups it drops here hold no accepted hit; `traversal_stack_spills_in_order` checks
    /// the spill itself.)
    #[test]
    fn deep_traversals_lose_nothing() {
        const PER_SCALE: u32 = 64;
        let mut tris = Vec::new();
        for k in -120..120 {
            let x = 2f32.powi(k);
            for j in 0..PER_SCALE {
                let s = x * 0.1 * (1.0 + j as f32 * 0.01);
                let c = Vec3::new(x * (1.0 + j as f32 * 0.001), 0.0, 0.0);
                tris.push([
                    c - Vec3::new(0.0, s, s),
                    c + Vec3::new(0.0, s, -s),
                    c + Vec3::Z * s,
                ]);
            }
        }
        let bvh = Bvh::build(&prims(&tris), &vec![ALPHA_TESTED; tris.len()]);
        wide::SPILLED.store(false, std::sync::atomic::Ordering::Relaxed);
        let ray = Ray::new(Vec3::new(-1.0, 0.0, 0.0), Vec3::X);
        let shear = RayShear::new(&ray);
        let mut found = 0;
        for first in -120..120 {
            let accepted = |prim: u32| prim / PER_SCALE >= (first + 120) as u32;
            let best = (0..tris.len() as u32)
                .filter(|&p| accepted(p))
                .filter_map(|p| {
                    triangle::intersect(
                        &shear,
                        &TriangleLanes::new(tris[p as usize]),
                        f32::INFINITY,
                    )
                })
                .map(|h| h.t)
                .fold(f32::INFINITY, f32::min);
            let hit = bvh.intersect(&ray, |p, _| accepted(p));
            assert_eq!(hit.map_or(f32::INFINITY, |h| h.t), best, "from 2^{first}");
            let short = Ray {
                tmax: best * 1.0001,
                ..ray
            };
            assert_eq!(
                bvh.occluded(&short, |p, _| accepted(p)),
                best.is_finite(),
                "from 2^{first}"
            );
            found += best.is_finite() as u32;
        }
        assert!(found > 100, "only {found} rays hit");
        assert!(
            wide::SPILLED.load(std::sync::atomic::Ordering::Relaxed),
            "never spilled"
        );
    }

    #[test]
    fn contact_hits_and_culling_and_occlusion() {
        let tris = cube();
        let mut flags = vec![0; tris.len()];
        let bvh = Bvh::build(&prims(&tris), &flags);
        // A ray starting 1e-6 in front of a face still sees it.
        let o = Vec3::new(0.5, 0.5, 1.0 + 1e-6);
        let hit = bvh.intersect(&Ray::new(o, -Vec3::Z), |_, _| true).unwrap();
        assert!(hit.front && (hit.t - 1e-6).abs() < 1e-6);
        // Culling back faces lets rays from inside escape.
        flags.iter_mut().for_each(|f| *f = CULL_BACK);
        let culled = Bvh::build(&prims(&tris), &flags);
        let inside = Ray::new(Vec3::splat(0.5), Vec3::Y);
        assert!(culled.intersect(&inside, |_, _| true).is_none());
        assert!(bvh.occluded(&inside, |_, _| true));
        let short = Ray {
            tmax: 0.49,
            ..inside
        };
        assert!(!bvh.occluded(&short, |_, _| true));
    }
}
