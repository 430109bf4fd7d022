//! Mesh deformation as glTF 2.0 defines it (sections 3.7.3 and 3.8): morph targets add
//! weighted displacements to positions, normals and tangents; skinning then moves each
//! vertex by the weighted sum of its joints' matrices, `jointMatrix = globalTransform(joint)
//! × inverseBindMatrix`, which puts the vertex in world space (the skinned node's own
//! transform does not apply). Normals move by the blended matrix's inverse transpose and
//! tangents by the matrix itself, as renderers that skin on the GPU do.

use crate::scene::Mesh;
use glam::{DMat3, DMat4, DVec3, Vec3, Vec4};

/// One morph target's displacements (each `None` where the target leaves that attribute).
#[derive(Default)]
pub struct MorphTarget {
    pub positions: Option<Vec<Vec3>>,
    pub normals: Option<Vec<Vec3>>,
    pub tangents: Option<Vec<Vec3>>,
}

/// Adds `weights[t]` × target `t` to the mesh's attributes; normals are renormalised.
pub fn morph(mesh: &mut Mesh, targets: &[MorphTarget], weights: &[f32]) {
    for (target, &w) in targets.iter().zip(weights) {
        if w == 0.0 {
            continue;
        }
        if let Some(d) = &target.positions {
            for (p, d) in mesh.positions.iter_mut().zip(d) {
                *p += w * *d;
            }
        }
        if let (Some(n), Some(d)) = (&mut mesh.normals, &target.normals) {
            for (n, d) in n.iter_mut().zip(d) {
                *n += w * *d;
            }
        }
        if let (Some(t), Some(d)) = (&mut mesh.tangents, &target.tangents) {
            for (t, d) in t.iter_mut().zip(d) {
                *t += (w * *d).extend(0.0);
            }
        }
    }
    if let Some(normals) = &mut mesh.normals {
        for n in normals {
            *n = n.try_normalize().unwrap_or(Vec3::Z);
        }
    }
}

/// A vertex's joint influences: up to four (joint, weight) pairs from each
/// JOINTS_n/WEIGHTS_n set.
pub type Influences = Vec<(u16, f32)>;

/// Moves the mesh to world space by linear blend skinning. `influences` has one entry per
/// vertex; weights are renormalised to sum to one (exporters round them), and a vertex with
/// no weight keeps the first joint's matrix. Returns how many vertices named a joint outside
/// `joint_matrices` (those influences are dropped).
pub fn skin(mesh: &mut Mesh, influences: &[Influences], joint_matrices: &[DMat4]) -> usize {
    let mut bad = 0;
    let matrices: Vec<DMat4> = influences
        .iter()
        .map(|inf| {
            let mut sum = DMat4::ZERO;
            let mut total = 0.0f64;
            for &(joint, weight) in inf {
                if weight == 0.0 {
                    continue;
                }
                let Some(m) = joint_matrices.get(joint as usize) else {
                    bad += 1;
                    continue;
                };
                sum += *m * weight as f64;
                total += weight as f64;
            }
            if total > 0.0 {
                sum * (1.0 / total)
            } else {
                joint_matrices.first().copied().unwrap_or(DMat4::IDENTITY)
            }
        })
        .collect();
    for (p, m) in mesh.positions.iter_mut().zip(&matrices) {
        *p = m.transform_point3(p.as_dvec3()).as_vec3();
    }
    if let Some(normals) = &mut mesh.normals {
        for (n, m) in normals.iter_mut().zip(&matrices) {
            let normal_matrix = DMat3::from_mat4(*m).inverse().transpose();
            let moved = normal_matrix * n.as_dvec3();
            *n = moved.try_normalize().unwrap_or(DVec3::Z).as_vec3();
        }
    }
    if let Some(tangents) = &mut mesh.tangents {
        for (t, m) in tangents.iter_mut().zip(&matrices) {
            let moved = DMat3::from_mat4(*m) * t.truncate().as_dvec3();
            let moved = moved.try_normalize().unwrap_or(DVec3::X).as_vec3();
            *t = Vec4::new(moved.x, moved.y, moved.z, t.w);
        }
    }
    bad
}

/// What a deformed mesh is made from, so that it can be posed again at other times (the
/// keys of its deformation over the shutter): its vertices at rest, its morph targets and
/// its joint influences.
pub struct Deformer {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub targets: Vec<MorphTarget>,
    /// Per vertex, for a skinned mesh.
    pub influences: Option<Vec<Influences>>,
}

impl Deformer {
    /// The positions and normals with morph target `weights`, skinned by `joint_matrices`
    /// (for a skinned mesh).
    pub fn pose(
        &self,
        weights: &[f32],
        joint_matrices: Option<&[DMat4]>,
    ) -> (Vec<Vec3>, Option<Vec<Vec3>>) {
        let mut mesh = Mesh {
            positions: self.positions.clone(),
            normals: self.normals.clone(),
            ..Mesh::default()
        };
        if !self.targets.is_empty() {
            morph(&mut mesh, &self.targets, weights);
        }
        if let (Some(influences), Some(joints)) = (&self.influences, joint_matrices) {
            skin(&mut mesh, influences, joints);
        }
        (mesh.positions, mesh.normals)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    fn one_vertex(p: Vec3, n: Vec3) -> Mesh {
        Mesh {
            name: "v".into(),
            positions: vec![p],
            normals: Some(vec![n]),
            tangents: None,
            uvs: [None, None],
            colors: None,
            triangles: vec![],
            material: 0,
            deformation: None,
        }
    }

    #[test]
    fn blends_joint_matrices_by_weight() {
        // Joint 0 stays put, joint 1 turns 90° about z around the origin: half of each
        // moves (1, 0, 0) to the mean of (1, 0, 0) and (0, 1, 0).
        let turn = DMat4::from_quat(DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2));
        let mut mesh = one_vertex(Vec3::X, Vec3::X);
        skin(
            &mut mesh,
            &[vec![(0, 0.5), (1, 0.5)]],
            &[DMat4::IDENTITY, turn],
        );
        assert!(mesh.positions[0].distance(Vec3::new(0.5, 0.5, 0.0)) < 1e-6);
        let n = mesh.normals.as_ref().unwrap()[0];
        assert!(n.distance(Vec3::new(1.0, 1.0, 0.0).normalize()) < 1e-6);
    }

    #[test]
    fn weights_are_renormalised_and_bad_joints_dropped() {
        let shift = DMat4::from_translation(DVec3::new(0.0, 2.0, 0.0));
        let mut mesh = one_vertex(Vec3::ZERO, Vec3::Z);
        let bad = skin(&mut mesh, &[vec![(0, 0.3), (7, 0.5)]], &[shift]);
        assert_eq!(bad, 1);
        assert!(mesh.positions[0].distance(Vec3::new(0.0, 2.0, 0.0)) < 1e-6);
    }

    #[test]
    fn normals_follow_the_inverse_transpose_under_non_uniform_scale() {
        // A 45° slope's normal under x-scale 2 leans towards y.
        let scale = DMat4::from_scale(DVec3::new(2.0, 1.0, 1.0));
        let mut mesh = one_vertex(Vec3::ONE, Vec3::new(1.0, 1.0, 0.0).normalize());
        skin(&mut mesh, &[vec![(0, 1.0)]], &[scale]);
        let n = mesh.normals.as_ref().unwrap()[0];
        assert!(n.distance(Vec3::new(0.5, 1.0, 0.0).normalize()) < 1e-6);
        assert!(mesh.positions[0].distance(Vec3::new(2.0, 1.0, 1.0)) < 1e-6);
    }

    #[test]
    fn morph_targets_add_weighted_displacements() {
        let mut mesh = one_vertex(Vec3::ZERO, Vec3::Z);
        let targets = [
            MorphTarget {
                positions: Some(vec![Vec3::X]),
                ..Default::default()
            },
            MorphTarget {
                positions: Some(vec![Vec3::Y]),
                normals: Some(vec![Vec3::X]),
                ..Default::default()
            },
        ];
        morph(&mut mesh, &targets, &[0.25, 1.0]);
        assert!(mesh.positions[0].distance(Vec3::new(0.25, 1.0, 0.0)) < 1e-6);
        let n = mesh.normals.as_ref().unwrap()[0];
        assert!(n.distance(Vec3::new(1.0, 0.0, 1.0).normalize()) < 1e-6);
    }
}
