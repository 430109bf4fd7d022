//! Which meshes are placed rather than flattened into render space, and the placed
//! geometry before its BVHs are built: shared meshes in object space, their placements (and
//! the motions of those that move over the shutter), and the render-space box of each.

use super::surfaces::PlacedMesh;
use crate::geometry::instances::{InstancedBvh, Placement, STILL, transformed_bounds};
use crate::geometry::motion::{self, MotionTransform};
use crate::geometry::{Bvh, Primitive};
use crate::scene::{Material, Mesh, Scene};
use glam::{Affine3A, DMat3, DMat4, Mat3A, Vec3};

/// Marks a mesh that is flattened into render space in [`shared_mesh_indices`].
pub(super) const NOT_SHARED: u32 = u32::MAX;

/// For each scene mesh, its index among the shared meshes, or [`NOT_SHARED`]. A mesh is
/// shared (traced once in object space, placed through the top-level BVH) when several
/// instances place it and it does not emit: emitters are flattened so that every emitting
/// triangle is a light of its own, and so are meshes that deform (their triangles move
/// each on its own).
pub(super) fn shared_mesh_indices(scene: &Scene) -> Vec<u32> {
    let mut uses = vec![0u32; scene.meshes.len()];
    for inst in &scene.instances {
        // A moving instance is placed (it moves with its ray's time), whatever its uses.
        uses[inst.mesh as usize] += if inst.motion.is_empty() { 1 } else { 2 };
    }
    let mut next = 0;
    scene
        .meshes
        .iter()
        .zip(uses)
        .map(|(mesh, uses)| {
            if uses >= 2
                && !scene.materials[mesh.material as usize].is_emissive()
                && mesh.deformation.is_none()
            {
                next += 1;
                next - 1
            } else {
                NOT_SHARED
            }
        })
        .collect()
}

/// How many times each mesh of `scene` is flattened into render space (placed and not
/// shared: [`shared_mesh_indices`]).
pub(super) fn flattened_uses(scene: &Scene, shared_index: &[u32]) -> Vec<u32> {
    let mut uses = vec![0u32; scene.meshes.len()];
    for inst in &scene.instances {
        if shared_index[inst.mesh as usize] == NOT_SHARED {
            uses[inst.mesh as usize] += 1;
        }
    }
    uses
}

/// The shared meshes (object space) and their placements, before their BVHs are built.
pub(super) struct PlacedGeometry {
    pub(super) meshes: Vec<Mesh>,
    /// Per placement: the shared mesh, object space to render space (in double precision,
    /// so that the inverse is accurate too) and the index of its motion, or [`STILL`].
    placements: Vec<(u32, DMat4, u32)>,
    /// Per placement: its render-space bounds (over its whole motion).
    pub(super) bounds: Vec<(Vec3, Vec3)>,
    /// The moving placements' transforms over the shutter, render space.
    pub(super) motions: Vec<MotionTransform>,
}

impl PlacedGeometry {
    /// Moves the shared meshes out of `scene` and collects their placements.
    pub(super) fn new(scene: &mut Scene, shared_index: &[u32], to_render: &DMat4) -> Self {
        let mut meshes = Vec::new();
        for (mesh, &index) in scene.meshes.iter_mut().zip(shared_index) {
            if index != NOT_SHARED {
                meshes.push(std::mem::take(mesh));
            }
        }
        let object_bounds: Vec<Option<(Vec3, Vec3)>> = meshes.iter().map(Mesh::bounds).collect();
        let (mut placements, mut bounds, mut motions) = (Vec::new(), Vec::new(), Vec::new());
        for inst in &scene.instances {
            let index = shared_index[inst.mesh as usize];
            if index == NOT_SHARED {
                continue;
            }
            // A placement of a mesh without vertices has nothing to hit.
            let Some((lo, hi)) = object_bounds[index as usize] else {
                continue;
            };
            let m = *to_render * inst.transform;
            let keys: Vec<DMat4> = inst.motion.iter().map(|k| *to_render * *k).collect();
            // The scene file's checks refuse keys that do not decompose.
            match MotionTransform::new(&keys).filter(|_| motion::keys_move(&keys)) {
                Some(moving) => {
                    bounds.push(moving.bounds(lo, hi));
                    placements.push((index, m, motions.len() as u32));
                    motions.push(moving);
                }
                None => {
                    bounds.push(transformed_bounds(
                        lo,
                        hi,
                        &Affine3A::from_mat4(m.as_mat4()),
                    ));
                    placements.push((index, m, STILL));
                }
            }
        }
        Self {
            meshes,
            placements,
            bounds,
            motions,
        }
    }

    /// One BVH per shared mesh (its primitives flagged by `flags` of their material), the
    /// top level over the placements, and the placements as shading reads them.
    pub(super) fn build(
        &self,
        materials: &[Material],
        flags: fn(&Material) -> u8,
    ) -> (Option<InstancedBvh>, Vec<PlacedMesh>) {
        if self.placements.is_empty() {
            return (None, Vec::new());
        }
        let shared = self
            .meshes
            .iter()
            .map(|mesh| {
                let flags = vec![flags(&materials[mesh.material as usize]); mesh.triangles.len()];
                Bvh::build_from(&flags, |t| {
                    let t = mesh.triangles[t as usize];
                    Primitive::Triangle(t.map(|i| mesh.positions[i as usize]))
                })
            })
            .collect();
        let placements: Vec<Placement> = self
            .placements
            .iter()
            .map(|&(shared, to_render, motion)| Placement {
                shared,
                to_object: Affine3A::from_mat4(to_render.inverse().as_mat4()),
                motion,
            })
            .collect();
        let shading = self
            .placements
            .iter()
            .map(|&(mesh, to_render, motion)| PlacedMesh {
                mesh,
                to_render: Affine3A::from_mat4(to_render.as_mat4()),
                normal_matrix: Mat3A::from(
                    DMat3::from_mat4(to_render).inverse().transpose().as_mat3(),
                ),
                motion,
            })
            .collect();
        (
            Some(InstancedBvh::build(
                shared,
                &placements,
                &self.bounds,
                self.motions.clone(),
            )),
            shading,
        )
    }
}
