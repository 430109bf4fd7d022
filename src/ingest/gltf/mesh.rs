//! Meshes: triangle primitives (strips and fans converted; points and lines skipped) with
//! their attributes checked and repaired, spheres that lucerna's extras mark, skinning and
//! morph targets applied at the render's pose (and at the shutter's keys for deformation
//! blur), tangents completed.

use super::super::{skinning, tangents};
use super::Importer;
use super::accessors::finite_or;
use super::deformation::{Deforming, Skin};
use crate::error::Result;
use crate::geometry::deformation::Deformation;
use crate::scene::{self, Instance, Mesh};
use glam::{DMat4, DVec3, Vec2, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use std::collections::HashMap;

impl<'a> Importer<'a> {
    /// Whether the mesh's `extras` make it an analytic sphere:
    /// `{"lucerna": {"shape": "sphere"}}`.
    pub(super) fn is_sphere(&self, mesh: &gltf::Mesh) -> Result<bool> {
        let Some(raw) = mesh.extras() else {
            return Ok(false);
        };
        let e = format!("meshes[{}].extras.lucerna", mesh.index());
        let value: serde_json::Value =
            serde_json::from_str(raw.get()).map_err(|err| self.err(&e, err.to_string()))?;
        match value.get("lucerna").and_then(|l| l.get("shape")) {
            None => Ok(false),
            Some(shape) if shape == "sphere" => Ok(true),
            Some(other) => {
                Err(self.err(&e, format!("unknown shape {other} (expected \"sphere\")")))
            }
        }
    }

    /// Places the analytic sphere that bounds `mesh`'s vertices, with its first primitive's
    /// material. The node's transform must scale uniformly.
    pub(super) fn sphere(&mut self, mesh: &gltf::Mesh<'a>, world: DMat4, name: &str) -> Result<()> {
        let element = format!("meshes[{}]", mesh.index());
        let mut positions = Vec::new();
        let mut material = None;
        for primitive in mesh.primitives() {
            if let Some(m) = self.primitive(mesh, &primitive)? {
                let m = &self.scene.meshes[m as usize];
                positions.extend(m.positions.iter().map(|p| p.as_dvec3()));
                material.get_or_insert(m.material);
            }
        }
        let Some(material) = material else {
            return Err(self.err(&element, "a sphere mesh needs triangles to bound"));
        };
        let (lo, hi) = positions
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            });
        let centre = (lo + hi) * 0.5;
        let radius = positions
            .iter()
            .map(|p| p.distance(centre))
            .fold(0.0, f64::max);
        let axes = [DVec3::X, DVec3::Y, DVec3::Z].map(|a| world.transform_vector3(a).length());
        let scale = axes[0];
        if !(scale > 0.0) || axes.iter().any(|a| (a - scale).abs() > 1e-6 * scale) {
            return Err(self.err(
                format!("nodes \"{name}\""),
                "an analytic sphere needs a uniform scale",
            ));
        }
        self.scene.spheres.push(scene::Sphere {
            name: name.to_string(),
            centre: world.transform_point3(centre),
            radius: radius * scale,
            material,
        });
        Ok(())
    }

    /// Converts skinned node `index` (named `name`): its mesh posed by its joints' world
    /// transforms at the render's time, placed in world space.
    pub(super) fn skinned_node(&mut self, index: usize, name: &str) -> Result<()> {
        let doc = self.doc;
        let node = doc.nodes().nth(index).expect("visited node");
        let (Some(skin), Some(mesh)) = (node.skin(), node.mesh()) else {
            return Ok(());
        };
        let element = format!("skins[{}]", skin.index());
        let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        let inverse_bind: Vec<DMat4> = match skin.inverse_bind_matrices() {
            Some(acc) => {
                self.check_accessor(
                    &acc,
                    &format!("{element}.inverseBindMatrices"),
                    &[Dimensions::Mat4],
                    &[DataType::F32],
                    false,
                )?;
                if acc.count() < joints.len() {
                    return Err(self.err(
                        format!("{element}.inverseBindMatrices"),
                        format!("has {} matrices for {} joints", acc.count(), joints.len()),
                    ));
                }
                let buffers = &self.buffers;
                let reader = skin.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
                reader
                    .read_inverse_bind_matrices()
                    .ok_or_else(|| self.err(&element, "inverseBindMatrices cannot be read"))?
                    .map(|m| DMat4::from_cols_array_2d(&m.map(|c| c.map(f64::from))))
                    .collect()
            }
            None => vec![DMat4::IDENTITY; joints.len()],
        };
        if let Some(j) = joints.iter().position(|j| !self.world_of.contains_key(j)) {
            return Err(self.err(
                format!("{element}.joints[{j}]"),
                format!("node {} is not in the rendered scene", joints[j]),
            ));
        }
        let skin = Skin {
            joints,
            inverse_bind,
        };
        let joint_matrices = skin.matrices(&self.world_of);
        if joint_matrices.iter().any(|m| !m.is_finite()) {
            return Err(self.err(&element, "a joint matrix is not finite"));
        }
        let weights = self.node_weights(&node, &mesh);
        for primitive in mesh.primitives() {
            if let Some(m) = self.deformed(
                &node,
                &mesh,
                &primitive,
                &weights,
                Some((&skin, &joint_matrices)),
            )? {
                self.scene.instances.push(Instance {
                    name: name.to_string(),
                    mesh: m,
                    transform: DMat4::IDENTITY,
                    motion: Vec::new(),
                });
            }
        }
        Ok(())
    }

    /// A primitive converted for one node: morphed by `weights` and, with `joints` (the
    /// skin's joint matrices), skinned to world space. Not shared with other nodes.
    pub(super) fn deformed(
        &mut self,
        node: &gltf::Node,
        mesh: &gltf::Mesh,
        primitive: &gltf::Primitive,
        weights: &[f32],
        skin: Option<(&Skin, &[DMat4])>,
    ) -> Result<Option<u32>> {
        if !matches!(
            primitive.mode(),
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            return self.primitive(mesh, primitive); // Warned and skipped there.
        }
        let element = format!(
            "nodes[{}] meshes[{}].primitives[{}]",
            node.index(),
            mesh.index(),
            primitive.index()
        );
        let Some(mut out) = self.convert_primitive(mesh, primitive, &element)? else {
            return Ok(None);
        };
        let vertices = out.positions.len();
        // With the shutter open on an animation, the mesh is posed again at its keys.
        let sampled = self.samples_deformation();
        let rest = sampled.then(|| (out.positions.clone(), out.normals.clone()));
        let mut targets = Vec::new();
        let mut notes: Vec<String> = Vec::new();
        let buffers = &self.buffers;
        let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        if weights.iter().any(|&w| w != 0.0) || (sampled && primitive.morph_targets().len() > 0) {
            for (t, target) in primitive.morph_targets().enumerate() {
                for (name, acc) in [
                    ("POSITION", target.positions()),
                    ("NORMAL", target.normals()),
                    ("TANGENT", target.tangents()),
                ] {
                    if let Some(acc) = acc {
                        let e = format!("{element}.targets[{t}].{name}");
                        self.check_accessor(
                            &acc,
                            &e,
                            &[Dimensions::Vec3],
                            &[DataType::F32],
                            false,
                        )?;
                        if acc.count() != vertices {
                            return Err(self.err(
                                e,
                                format!("has {} elements for {vertices} vertices", acc.count()),
                            ));
                        }
                    }
                }
            }
            targets = reader
                .read_morph_targets()
                .map(|(p, n, t)| skinning::MorphTarget {
                    positions: p.map(|it| it.map(Vec3::from_array).collect()),
                    normals: n.map(|it| it.map(Vec3::from_array).collect()),
                    tangents: t.map(|it| it.map(Vec3::from_array).collect()),
                })
                .collect();
            if targets.len() != weights.len() {
                notes.push(format!(
                    "{} morph targets but {} weights; the missing weights are 0",
                    targets.len(),
                    weights.len()
                ));
            }
            skinning::morph(&mut out, &targets, weights);
        }
        let mut skinned = None;
        if let Some((skin, joints)) = skin {
            let mut influences: Vec<skinning::Influences> = vec![Vec::new(); vertices];
            let mut set = 0;
            while let (Some(j), Some(w)) = (
                primitive.get(&gltf::Semantic::Joints(set)),
                primitive.get(&gltf::Semantic::Weights(set)),
            ) {
                let je = format!("{element}.attributes.JOINTS_{set}");
                let we = format!("{element}.attributes.WEIGHTS_{set}");
                self.check_accessor(
                    &j,
                    &je,
                    &[Dimensions::Vec4],
                    &[DataType::U8, DataType::U16],
                    false,
                )?;
                self.check_accessor(
                    &w,
                    &we,
                    &[Dimensions::Vec4],
                    &[DataType::F32, DataType::U8, DataType::U16],
                    true,
                )?;
                for (e, acc) in [(&je, &j), (&we, &w)] {
                    if acc.count() != vertices {
                        return Err(self.err(
                            e,
                            format!("has {} elements for {vertices} vertices", acc.count()),
                        ));
                    }
                }
                let js = reader
                    .read_joints(set)
                    .ok_or_else(|| self.err(&je, "cannot be read"))?;
                let ws = reader
                    .read_weights(set)
                    .ok_or_else(|| self.err(&we, "cannot be read"))?;
                for ((inf, j), w) in influences.iter_mut().zip(js.into_u16()).zip(ws.into_f32()) {
                    inf.extend(
                        (0..4).map(|k| (j[k], if w[k].is_finite() { w[k].max(0.0) } else { 0.0 })),
                    );
                }
                set += 1;
            }
            if set == 0 {
                notes.push("the node has a skin but the primitive has no JOINTS_0/WEIGHTS_0; it is placed by the skin's first joint".into());
                influences.iter_mut().for_each(|i| i.push((0, 1.0)));
            }
            let bad = skinning::skin(&mut out, &influences, joints);
            if bad > 0 {
                notes.push(format!(
                    "{bad} joint influences name a joint the skin does not have and are ignored"
                ));
            }
            skinned = Some((skin.clone(), influences));
        }
        for note in notes {
            self.warn(&element, note);
        }
        let index = self.scene.meshes.len() as u32;
        match rest {
            // Tangents are completed once the keys are known (completing them may split
            // vertices, the keys' too).
            Some((positions, normals)) => {
                let (skin, influences) = skinned.unzip();
                self.deforming.push(Deforming {
                    mesh: index,
                    node: node.index(),
                    gltf_mesh: mesh.index(),
                    element,
                    skin,
                    deformer: skinning::Deformer {
                        positions,
                        normals,
                        targets,
                        influences,
                    },
                });
            }
            None => self.complete_tangents(&mut out, &element),
        }
        self.scene.meshes.push(out);
        Ok(Some(index))
    }

    pub(super) fn primitive(
        &mut self,
        mesh: &gltf::Mesh,
        primitive: &gltf::Primitive,
    ) -> Result<Option<u32>> {
        let key = (mesh.index(), primitive.index());
        if let Some(m) = self.meshes.get(&key) {
            return Ok(*m);
        }
        let element = format!("meshes[{}].primitives[{}]", mesh.index(), primitive.index());
        let mode = primitive.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            self.warn(
                &element,
                format!("{mode:?} primitive skipped (only triangles are rendered)"),
            );
            self.meshes.insert(key, None);
            return Ok(None);
        }
        let converted = self.convert_primitive(mesh, primitive, &element)?;
        let index = converted.map(|mut m| {
            self.complete_tangents(&mut m, &element);
            self.scene.meshes.push(m);
            (self.scene.meshes.len() - 1) as u32
        });
        self.meshes.insert(key, index);
        Ok(index)
    }

    pub(super) fn convert_primitive(
        &mut self,
        mesh: &gltf::Mesh,
        primitive: &gltf::Primitive,
        element: &str,
    ) -> Result<Option<Mesh>> {
        let f32_only = [DataType::F32];
        let uv_types = [DataType::F32, DataType::U8, DataType::U16];
        let position_acc = primitive
            .get(&gltf::Semantic::Positions)
            .ok_or_else(|| self.err(element, "has no POSITION attribute"))?;
        let pos_el = format!("{element}.attributes.POSITION");
        self.check_accessor(
            &position_acc,
            &pos_el,
            &[Dimensions::Vec3],
            &f32_only,
            false,
        )?;
        let checks: [(gltf::Semantic, &[Dimensions], &[DataType]); 5] = [
            (gltf::Semantic::Normals, &[Dimensions::Vec3], &f32_only),
            (gltf::Semantic::Tangents, &[Dimensions::Vec4], &f32_only),
            (gltf::Semantic::TexCoords(0), &[Dimensions::Vec2], &uv_types),
            (gltf::Semantic::TexCoords(1), &[Dimensions::Vec2], &uv_types),
            (
                gltf::Semantic::Colors(0),
                &[Dimensions::Vec3, Dimensions::Vec4],
                &uv_types,
            ),
        ];
        let vertex_count = position_acc.count();
        for (semantic, dims, types) in checks {
            if let Some(acc) = primitive.get(&semantic) {
                let el = format!("{element}.attributes.{}", semantic.to_string());
                self.check_accessor(&acc, &el, dims, types, true)?;
                if acc.count() != vertex_count {
                    return Err(self.err(
                        el,
                        format!(
                            "has {} elements but POSITION has {vertex_count}",
                            acc.count()
                        ),
                    ));
                }
            }
        }
        if let Some(acc) = primitive.indices() {
            self.check_accessor(
                &acc,
                &format!("{element}.indices"),
                &[Dimensions::Scalar],
                &[DataType::U8, DataType::U16, DataType::U32],
                false,
            )?;
        }

        let buffers = &self.buffers;
        let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or_else(|| self.err(&pos_el, "cannot read positions"))?
            .map(Vec3::from_array)
            .collect();
        let bad = positions.iter().filter(|p| !p.is_finite()).count();
        if bad > 0 {
            return Err(self.err(
                &pos_el,
                format!("{bad} of {} positions are NaN or infinite", positions.len()),
            ));
        }
        let mut repaired = 0usize;
        let normals = reader.read_normals().map(|it| {
            let ok = |n: &Vec3| n.is_finite() && n.length_squared() > 0.0;
            finite_or(it.map(Vec3::from_array), ok, Vec3::ZERO, &mut repaired)
        });
        let tangents: Option<Vec<Vec4>> = reader
            .read_tangents()
            .map(|it| it.map(Vec4::from_array).collect());
        let uvs = [0, 1].map(|set| {
            reader.read_tex_coords(set).map(|it| {
                let values = it.into_f32().map(Vec2::from_array);
                finite_or(values, |uv| uv.is_finite(), Vec2::ZERO, &mut repaired)
            })
        });
        let colors = reader.read_colors(0).map(|it| {
            let values = it.into_rgba_f32().map(Vec4::from_array);
            finite_or(values, |c| c.is_finite(), Vec4::ONE, &mut repaired)
        });
        let indices: Vec<u32> = match reader.read_indices() {
            Some(it) => it.into_u32().collect(),
            None => (0..vertex_count as u32).collect(),
        };
        if let Some((i, &bad)) = indices
            .iter()
            .enumerate()
            .find(|(_, i)| **i as usize >= vertex_count)
        {
            return Err(self.err(
                format!("{element}.indices"),
                format!("index {bad} at position {i} is out of range (the primitive has {vertex_count} vertices)"),
            ));
        }
        if repaired > 0 {
            self.warn(
                element,
                format!("{repaired} NaN/infinite normals, texture coordinates or colours replaced"),
            );
        }
        let triangles = assemble_triangles(primitive.mode(), &indices);
        if triangles.is_empty() {
            self.warn(element, "has no non-degenerate triangles and is skipped");
            return Ok(None);
        }
        let material = match self.variant_material(primitive) {
            Some(m) => self.material(m)?,
            None => self.material(primitive.material())?,
        };
        let mut out = Mesh {
            name: mesh
                .name()
                .map_or_else(|| format!("meshes[{}]", mesh.index()), str::to_string),
            positions,
            normals,
            tangents: None,
            uvs,
            colors,
            triangles,
            material,
            deformation: None,
        };
        // The file's tangents where a normal map or anisotropy needs them (MikkTSpace's
        // are made by complete_tangents, after any deformation: it splits vertices).
        if self.scene.materials[material as usize]
            .tangent_uv_set()
            .is_some()
        {
            out.tangents = tangents.filter(|t| t.iter().all(|t| t.is_finite()));
        }
        Ok(Some(out))
    }

    /// MikkTSpace tangents for a converted primitive whose material needs tangents and
    /// whose file gave none.
    pub(super) fn complete_tangents(&mut self, out: &mut Mesh, element: &str) {
        let Some(uv_set) = self.scene.materials[out.material as usize].tangent_uv_set() else {
            return;
        };
        if out.tangents.is_none() && !tangents::generate(out, uv_set) {
            self.warn(
                element,
                "normal map and anisotropy ignored: the mesh has no texture coordinates for their tangents",
            );
        }
    }
}

/// Triangles of a primitive in counter-clockwise order, degenerate ones (repeated
/// indices) dropped. Strips and fans follow the glTF specification (§3.7.2.1).
pub(super) fn assemble_triangles(mode: Mode, indices: &[u32]) -> Vec<[u32; 3]> {
    let tris: Vec<[u32; 3]> = match mode {
        Mode::Triangles => indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
        Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
            .map(|i| {
                if i % 2 == 0 {
                    [indices[i], indices[i + 1], indices[i + 2]]
                } else {
                    [indices[i], indices[i + 2], indices[i + 1]]
                }
            })
            .collect(),
        Mode::TriangleFan => (1..indices.len().saturating_sub(1))
            .map(|i| [indices[i], indices[i + 1], indices[0]])
            .collect(),
        _ => Vec::new(),
    };
    tris.into_iter()
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .collect()
}

/// Deformation blur of skinned and morphed meshes: with the shutter open on an animation,
/// each deformed mesh is posed again at the keys of the shutter (the joints' world transforms
/// and the morph weights sampled there) into its `Deformation`; a mesh whose vertices do not
/// move keeps none. Tangents are completed after, so that the vertices they split are split
/// in every key alike.
impl<'a> Importer<'a> {
    /// Whether deformed meshes are posed at the shutter's keys: the shutter is open and the
    /// file is animated.
    pub(super) fn samples_deformation(&self) -> bool {
        self.shutter.is_some() && self.doc.animations().next().is_some()
    }

    /// Each deformed mesh's positions and normals with the pose at one key of the shutter
    /// (the nodes' world transforms `world`, the morph weights sampled with them), appended
    /// to its `keys`.
    pub(super) fn pose_deforming(&self, world: &HashMap<usize, DMat4>, keys: &mut [Deformation]) {
        for (d, keys) in self.deforming.iter().zip(keys) {
            let node = self.doc.nodes().nth(d.node).expect("visited node");
            let mesh = self.doc.meshes().nth(d.gltf_mesh).expect("the node's mesh");
            let weights = self.node_weights(&node, &mesh);
            let joints = d.skin.as_ref().map(|s| s.matrices(world));
            let (p, n) = d.deformer.pose(&weights, joints.as_deref());
            keys.positions.push(p);
            if let Some(n) = n {
                keys.normals.get_or_insert_with(Vec::new).push(n);
            }
        }
    }

    /// Gives each deformed mesh its `keys` (from [`Importer::pose_deforming`]) where its
    /// vertices move, then completes its tangents.
    pub(super) fn finish_deforming(&mut self, keys: Vec<Deformation>) {
        let deforming = std::mem::take(&mut self.deforming);
        let mut keys = keys.into_iter();
        for d in deforming {
            let mut mesh = std::mem::take(&mut self.scene.meshes[d.mesh as usize]);
            if let Some(deformation) = keys.next() {
                let vertices = mesh.positions.len();
                match deformation.check(vertices, mesh.normals.is_some()) {
                    Ok(()) if deformation.moves() => mesh.deformation = Some(deformation),
                    Ok(()) => {}
                    Err(reason) => self.warn(
                        &d.element,
                        format!("its deformation over the shutter is not blurred: {reason}"),
                    ),
                }
            }
            self.complete_tangents(&mut mesh, &d.element);
            self.scene.meshes[d.mesh as usize] = mesh;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_follow_the_specification() {
        assert_eq!(
            assemble_triangles(Mode::TriangleStrip, &[0, 1, 2, 3, 4]),
            vec![[0, 1, 2], [1, 3, 2], [2, 3, 4]]
        );
        assert_eq!(
            assemble_triangles(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![[1, 2, 0], [2, 3, 0]]
        );
        assert_eq!(
            assemble_triangles(Mode::Triangles, &[0, 1, 2, 3, 3, 4, 5]),
            vec![[0, 1, 2]]
        );
    }
}
