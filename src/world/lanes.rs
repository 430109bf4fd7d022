//! Shading points of triangle hits computed in eight SIMD lanes (the packet kernel's,
//! `integrator::packet`), for surfaces whose material is the same at every point: the
//! lanes gather each triangle's vertices and shading normals, and compute position,
//! geometric normal and shading frame with [`Surfaces::interaction`]'s operations in its
//! order, so that every lane is the scalar shading point to the bit. Only for code compiled
//! with AVX2 (see `crate::simd`).

use super::surfaces::Surfaces;
use crate::geometry::frame::frame_from_normal_lanes;
use crate::geometry::{Hit, NOT_PLACED};
use crate::material::{self, Bsdf, SurfaceAttributes};
use crate::scene::Mesh;
use crate::simd::{F8, LANES, M8, V3};
use glam::{Vec3, Vec4};

/// Eight lanes' shading points: position, geometric normal and shading frame `[s, t, n]`
/// as [`super::Interaction`] holds them.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ShadingLanes {
    pub p: V3,
    /// The magnitude `p`'s rounding error is relative to (`Interaction::magnitude`).
    pub magnitude: F8,
    pub ng: V3,
    pub frame: [V3; 3],
}

/// Triangle hits gathered lane by lane for [`TriangleHits::shading`]: the triangles' vertex
/// positions and shading normals, and the hits' barycentrics.
/// The largest absolute coordinate of each lane's point.
#[inline(always)]
fn largest_coordinate(v: V3) -> F8 {
    v.x.abs().max(v.y.abs()).max(v.z.abs())
}

pub(crate) struct TriangleHits {
    p: [[Vec3; LANES]; 3],
    n: [[Vec3; LANES]; 3],
    b: [[f32; LANES]; 2],
    /// Lanes whose mesh has shading normals.
    normals: u32,
}

impl TriangleHits {
    /// No hits yet.
    #[inline(always)]
    pub fn new() -> Self {
        Self {
            p: [[Vec3::ZERO; LANES]; 3],
            n: [[Vec3::Z; LANES]; 3],
            b: [[0.0; LANES]; 2],
            normals: 0,
        }
    }

    /// Lane `lane` holds `hit` on triangle `tri` of `mesh`.
    #[inline(always)]
    pub fn set(&mut self, lane: usize, mesh: &Mesh, tri: u32, hit: &Hit) {
        let tri = mesh.triangles[tri as usize];
        for (p, &i) in self.p.iter_mut().zip(&tri) {
            p[lane] = mesh.positions[i as usize];
        }
        if let Some(normals) = &mesh.normals {
            for (n, &i) in self.n.iter_mut().zip(&tri) {
                n[lane] = normals[i as usize];
            }
            self.normals |= 1 << lane;
        } else {
            self.normals &= !(1 << lane);
        }
        (self.b[0][lane], self.b[1][lane]) = (hit.b1, hit.b2);
    }

    /// The shading points of the hits, for rays of directions `dir` (only the lanes given
    /// to [`TriangleHits::set`], `mask`, are meaningful): `Surfaces::triangle_surface` and
    /// `Surfaces::interaction` without a normal map.
    #[inline(always)]
    pub fn shading(&self, dir: V3, mask: u32) -> ShadingLanes {
        let (b1, b2) = (F8::from_array(self.b[0]), F8::from_array(self.b[1]));
        let b0 = F8::ONE - b1 - b2;
        let [p0, p1, p2] = &self.p;
        let (p0, p1, p2) = (V3::from_lanes(p0), V3::from_lanes(p1), V3::from_lanes(p2));
        let p = p0 * b0 + p1 * b1 + p2 * b2;
        let magnitude = largest_coordinate(p0)
            .max(largest_coordinate(p1))
            .max(largest_coordinate(p2));
        let n_front = (p1 - p0).cross_in_f64(p2 - p0).normalize();
        let [n0, n1, n2] = &self.n;
        let (n0, n1, n2) = (V3::from_lanes(n0), V3::from_lanes(n1), V3::from_lanes(n2));
        let (interpolated, finite) = (n0 * b0 + n1 * b1 + n2 * b2).normalize_or(V3::ZERO);
        let zero = F8::ZERO;
        let vanished = interpolated.x.eq(zero) & interpolated.y.eq(zero) & interpolated.z.eq(zero);
        let interpolated_used = M8::from_bits(self.normals) & finite & !vanished;
        let ns_front = V3::select(interpolated_used, interpolated, n_front);
        let wo = -dir.normalize();
        let front = n_front.dot(wo).gt(zero);
        let ng = V3::select(front, n_front, -n_front);
        let ns = V3::select(front, ns_front, -ns_front);
        let ns = V3::select(ns.dot(ng).lt(zero), -ns, ns);
        // facing_shading_normal: both branches and a select.
        let (a, b) = (ns.dot(wo), ng.dot(wo));
        let target = (b * 0.5).min(F8::splat(0.01));
        let keep = target.le(a) | b.le(zero);
        let t = (target - a) / (b - a);
        let (bent, _) = (ns * (F8::ONE - t) + ng * t).normalize_or(ng);
        let mut ns = V3::select(keep, ns, bent);
        // valid_reflection_normal, lane by lane where the reflection may leave too low (the
        // lanes' test is a margin looser, and the scalar code decides exactly); a normal
        // that is the geometric one never needs it.
        let interpolated = interpolated_used.bits() & mask;
        if interpolated != 0 {
            let iz = wo.dot(ng);
            let threshold = (iz * 0.9).min(F8::splat(0.01));
            let leaves = ns.dot(wo) * 2.0 * ns.dot(ng) - iz;
            let low = (leaves.lt(threshold + F8::splat(1e-4)) & iz.gt(zero)).bits() & interpolated;
            for lane in crate::geometry::triangle::Lanes::new(low) {
                let (n, g, w) = (ns.lane(lane), ng.lane(lane), wo.lane(lane));
                ns.set_lane(lane, super::surfaces::valid_reflection_normal(n, g, w));
            }
        }
        ShadingLanes {
            p,
            magnitude,
            ng,
            frame: frame_from_normal_lanes(ns),
        }
    }
}

impl Surfaces {
    /// The BSDF of every point of `mesh` where its shading points can be taken in lanes
    /// ([`TriangleHits`]): its material is uniform (`Mesh::uniform_material`), reflects
    /// something, transmits nothing and is not the layered glTF model. `None` otherwise:
    /// such a mesh's points go through [`Surfaces::interaction`] (and paths reaching glass
    /// to the scalar code).
    pub(crate) fn uniform_bsdf(&self, mesh: &Mesh) -> Option<Bsdf<'static>> {
        let m = mesh
            .uniform_material(&self.materials)
            .filter(|m| !m.transmits() && !m.can_filter())?;
        let attrs = SurfaceAttributes {
            uv: [glam::Vec2::ZERO; 2],
            color: Vec4::ONE,
            footprint: [[glam::Vec2::ZERO; 2]; 2],
        };
        material::compact_bsdf(m, &self.textures, &attrs, &Default::default())
            .filter(|b| !b.is_black())
    }

    /// The mesh and triangle of `hit` where it lies on a mesh placed once (not through a
    /// shared BVH).
    #[inline(always)]
    pub(crate) fn hit_triangle(&self, hit: &Hit) -> Option<(u32, u32)> {
        if hit.instance != NOT_PLACED {
            return None;
        }
        match self.prims[hit.prim as usize] {
            super::PrimRef::Triangle { mesh, tri } => Some((mesh, tri)),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::ray::Ray;
    use crate::material::lambert::Lambert;
    use crate::scene::Material;

    /// A small xorshift stream in [-1, 1) (fixed seed).
    fn stream(seed: u32) -> impl FnMut() -> f32 {
        let mut s = seed;
        move || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s >> 8) as f32 / (1 << 23) as f32 - 1.0
        }
    }

    /// Every lane's shading point is `Surfaces::interaction`'s to the bit: random triangles
    /// with and without shading normals (some pointing away from the winding, some grazing
    /// so that the shading normal is bent towards the viewer), hit from either side.
    #[test]
    fn lane_shading_points_are_the_scalar_interactions() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let mut u = stream(0x2545_f491);
        let v3 = |u: &mut dyn FnMut() -> f32| Vec3::new(u(), u(), u());
        let mut meshes = Vec::new();
        for m in 0..64 {
            let positions: Vec<Vec3> = (0..3).map(|_| v3(&mut u)).collect();
            let normals = (m % 3 != 0).then(|| {
                let e = positions[0] - positions[1];
                let n = e.cross(positions[2] - positions[1]);
                // Normals near the face normal, and some far from it or flipped.
                let spread = if m % 3 == 1 { 0.2 } else { 3.0 };
                (0..3)
                    .map(|_| n.normalize() + v3(&mut u) * spread)
                    .collect()
            });
            meshes.push(Mesh {
                name: format!("m{m}"),
                positions,
                normals,
                tangents: None,
                uvs: [None, None],
                colors: None,
                triangles: vec![[0, 1, 2]],
                material: 0,
                deformation: None,
            });
        }
        let surfaces = Surfaces::for_tests(meshes, vec![Material::default()]);
        let (mut checked, mut bent) = (0, 0);
        for round in 0..400 {
            let mut hits = TriangleHits::new();
            let mut dirs = [Vec3::Z; LANES];
            let mut scalar = Vec::new();
            for (lane, dir) in dirs.iter_mut().enumerate() {
                let mesh = (round * LANES + lane) % surfaces.meshes.len();
                let (b1, b2) = ((u() + 1.0) * 0.5, (u() + 1.0) * 0.5);
                let (b1, b2) = if b1 + b2 > 1.0 {
                    (1.0 - b1, 1.0 - b2)
                } else {
                    (b1, b2)
                };
                let hit = Hit {
                    t: 1.0,
                    prim: mesh as u32,
                    b1,
                    b2,
                    front: true,
                    instance: NOT_PLACED,
                };
                *dir = v3(&mut u) * 3.0;
                let ray = Ray::new(Vec3::ZERO, *dir);
                hits.set(lane, &surfaces.meshes[mesh], 0, &hit);
                scalar.push(surfaces.interaction(&ray, &hit));
            }
            let lanes = hits.shading(V3::from_lanes(&dirs), 0xff);
            let bits = |v: Vec3| v.to_array().map(f32::to_bits);
            for (lane, it) in scalar.iter().enumerate() {
                assert_eq!(bits(lanes.p.lane(lane)), bits(it.p), "p, round {round}");
                assert_eq!(bits(lanes.ng.lane(lane)), bits(it.ng), "ng, round {round}");
                let [s, t, n] = lanes.frame;
                assert_eq!(bits(s.lane(lane)), bits(it.frame.s), "s, round {round}");
                assert_eq!(bits(t.lane(lane)), bits(it.frame.t), "t, round {round}");
                assert_eq!(bits(n.lane(lane)), bits(it.frame.n), "n, round {round}");
                checked += 1;
                // Bent towards the viewer (the shading normal ends at the target angle) or
                // until its mirror reflection leaves the surface (at the threshold).
                let (n, wo) = (it.frame.n, -dirs[lane].normalize());
                let target = (0.5 * it.ng.dot(wo)).min(0.01);
                let reflected = (n * (2.0 * n.dot(wo)) - wo).dot(it.ng);
                let threshold = crate::world::surfaces::reflection_threshold(it.ng.dot(wo));
                bent += usize::from(
                    (n.dot(wo) - target).abs() < 1e-4 || (reflected - threshold).abs() < 2e-3,
                );
            }
        }
        assert_eq!(checked, 400 * LANES);
        assert!(bent > 50, "{bent} bent shading normals");
    }

    /// Only untextured, non-emissive meshes without vertex colours have a uniform BSDF.
    #[test]
    fn uniform_bsdfs_are_those_of_constant_materials() {
        let lambert = Material {
            model: crate::scene::BsdfModel::Lambert,
            base_color: Vec4::new(0.5, 0.25, 0.125, 1.0),
            ..Material::default()
        };
        let emissive = Material {
            emissive: Vec3::ONE,
            ..lambert.clone()
        };
        let black = Material {
            base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
            ..lambert.clone()
        };
        let mesh = |material: u32| Mesh {
            name: "m".into(),
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: None,
            tangents: None,
            uvs: [None, None],
            colors: None,
            triangles: vec![[0, 1, 2]],
            material,
            deformation: None,
        };
        let surfaces = Surfaces::for_tests(vec![], vec![lambert, emissive, black]);
        match surfaces.uniform_bsdf(&mesh(0)) {
            Some(Bsdf::Lambert(Lambert { albedo })) => {
                assert_eq!(albedo, Vec3::new(0.5, 0.25, 0.125))
            }
            other => panic!("{other:?}"),
        }
        assert!(surfaces.uniform_bsdf(&mesh(1)).is_none());
        assert!(surfaces.uniform_bsdf(&mesh(2)).is_none());
        let coloured = Mesh {
            colors: Some(vec![Vec4::ONE; 3]),
            ..mesh(0)
        };
        assert!(surfaces.uniform_bsdf(&coloured).is_none());
    }
}
