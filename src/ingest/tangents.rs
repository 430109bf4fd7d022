//! Tangent generation with MikkTSpace (the algorithm the glTF specification prescribes when
//! a normal-mapped mesh has no tangents).

use crate::scene::Mesh;
use glam::{Vec2, Vec3, Vec4};
use std::collections::HashMap;

struct MikkInput<'a> {
    mesh: &'a Mesh,
    uvs: &'a [Vec2],
    face_normals: Vec<Vec3>,
    /// Per triangle corner.
    tangents: Vec<Vec4>,
}

impl bevy_mikktspace::Geometry for MikkInput<'_> {
    fn num_faces(&self) -> usize {
        self.mesh.triangles.len()
    }

    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.mesh.positions[self.mesh.triangles[face][vert] as usize].to_array()
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        match &self.mesh.normals {
            Some(n) => n[self.mesh.triangles[face][vert] as usize].to_array(),
            None => self.face_normals[face].to_array(),
        }
    }

    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        self.uvs[self.mesh.triangles[face][vert] as usize].to_array()
    }

    fn set_tangent(
        &mut self,
        tangent: Option<bevy_mikktspace::TangentSpace>,
        face: usize,
        vert: usize,
    ) {
        let t = tangent.unwrap_or_default().tangent_encoded();
        self.tangents[face * 3 + vert] = Vec4::from_array(t);
    }
}

/// Generates tangents from texture coordinate set `uv_set`. MikkTSpace gives one tangent
/// per triangle corner; vertices whose corners disagree (UV seams, mirrored UVs) are split.
/// Returns false if the mesh lacks that UV set.
pub fn generate(mesh: &mut Mesh, uv_set: usize) -> bool {
    let Some(uvs) = mesh.uvs[uv_set].as_ref() else {
        return false;
    };
    let face_normals = if mesh.normals.is_none() {
        mesh.triangles
            .iter()
            .map(|t| {
                let p = t.map(|i| mesh.positions[i as usize]);
                (p[1] - p[0]).cross(p[2] - p[0]).normalize_or(Vec3::Z)
            })
            .collect()
    } else {
        Vec::new()
    };
    let mut input = MikkInput {
        mesh,
        uvs,
        face_normals,
        tangents: vec![Vec4::new(1.0, 0.0, 0.0, 1.0); mesh.triangles.len() * 3],
    };
    // The error type is uninhabited: generation cannot fail.
    let _ = bevy_mikktspace::generate_tangents(&mut input);
    let corner_tangents = input.tangents;

    // Weld corners that share a vertex and a tangent.
    let mut remap: HashMap<(u32, [u32; 4]), u32> = HashMap::new();
    let mut source: Vec<u32> = Vec::new();
    let mut tangents: Vec<Vec4> = Vec::new();
    let mut triangles = mesh.triangles.clone();
    for (t, tri) in triangles.iter_mut().enumerate() {
        for (c, index) in tri.iter_mut().enumerate() {
            let tangent = corner_tangents[t * 3 + c];
            let key = (*index, tangent.to_array().map(f32::to_bits));
            *index = *remap.entry(key).or_insert_with(|| {
                source.push(*index);
                tangents.push(tangent);
                (source.len() - 1) as u32
            });
        }
    }
    fn gather<T: Copy>(v: &[T], source: &[u32]) -> Vec<T> {
        source.iter().map(|&i| v[i as usize]).collect()
    }
    mesh.positions = gather(&mesh.positions, &source);
    mesh.normals = mesh.normals.as_ref().map(|v| gather(v, &source));
    mesh.uvs = [0, 1].map(|s| mesh.uvs[s].as_ref().map(|v| gather(v, &source)));
    mesh.colors = mesh.colors.as_ref().map(|v| gather(v, &source));
    if let Some(d) = &mut mesh.deformation {
        fn keys(keys: &[Vec<Vec3>], source: &[u32]) -> Vec<Vec<Vec3>> {
            keys.iter().map(|k| gather(k, source)).collect()
        }
        d.positions = keys(&d.positions, &source);
        d.normals = d.normals.as_deref().map(|n| keys(n, &source));
    }
    mesh.tangents = Some(tangents);
    mesh.triangles = triangles;
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_planar_quad_gets_the_u_direction_as_tangent() {
        let mut mesh = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            uvs: [
                Some(vec![
                    Vec2::new(0.0, 1.0),
                    Vec2::new(1.0, 1.0),
                    Vec2::new(1.0, 0.0),
                    Vec2::ZERO,
                ]),
                None,
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        };
        assert!(generate(&mut mesh, 0));
        let tangents = mesh.tangents.as_ref().unwrap();
        assert_eq!(mesh.positions.len(), 4, "no seams, no split");
        for t in tangents {
            assert!((t.truncate() - Vec3::X).length() < 1e-4, "{t}");
        }
    }

    /// Two triangles sharing an edge whose texture coordinates run opposite ways (a mirrored
    /// seam): the shared vertices split, and a deformation's keys split with them.
    #[test]
    fn a_split_vertex_keeps_its_deformation_keys() {
        use crate::geometry::deformation::Deformation;
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)];
        let moved: Vec<Vec3> = positions.iter().map(|p| *p * 2.0 + Vec3::Z).collect();
        let mut mesh = Mesh {
            positions: positions.clone(),
            uvs: [
                Some(vec![Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::new(-1.0, 1.0)]),
                None,
            ],
            triangles: vec![[0, 1, 2], [2, 1, 3]],
            deformation: Some(Deformation {
                positions: vec![positions, moved],
                normals: None,
            }),
            ..Default::default()
        };
        assert!(generate(&mut mesh, 0));
        assert!(
            mesh.positions.len() > 4,
            "the mirrored seam splits vertices"
        );
        let d = mesh.deformation.as_ref().unwrap();
        assert_eq!(d.positions[0], mesh.positions);
        for (p, q) in mesh.positions.iter().zip(&d.positions[1]) {
            assert_eq!(*q, *p * 2.0 + Vec3::Z);
        }
    }
}
