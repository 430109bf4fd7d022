//! What deformation blur keeps of a skinned or morphed mesh to pose it again at the keys
//! of the shutter (`Importer::pose_deforming` in `mesh`): its skin and its deformer.

use super::super::skinning::Deformer;
use glam::DMat4;
use std::collections::HashMap;

/// A skin: its joints (nodes) and their inverse bind matrices.
#[derive(Clone)]
pub(super) struct Skin {
    pub(super) joints: Vec<usize>,
    pub(super) inverse_bind: Vec<DMat4>,
}

impl Skin {
    /// The joint matrices with the nodes' world transforms `world` (every joint must be
    /// there): `world(joint) × inverseBindMatrix`.
    pub(super) fn matrices(&self, world: &HashMap<usize, DMat4>) -> Vec<DMat4> {
        (self.joints.iter().zip(&self.inverse_bind))
            .map(|(j, bind)| world[j] * *bind)
            .collect()
    }
}

/// A deformed mesh to pose again over the shutter.
pub(super) struct Deforming {
    /// The scene mesh.
    pub(super) mesh: u32,
    /// The node that places it, and its glTF mesh (for the node's morph weights).
    pub(super) node: usize,
    pub(super) gltf_mesh: usize,
    /// The primitive's element name, for warnings.
    pub(super) element: String,
    pub(super) skin: Option<Skin>,
    pub(super) deformer: Deformer,
}
