//! The node hierarchy: transforms (a depth limit against malicious files), instancing
//! (EXT_mesh_gpu_instancing), and animation: channels sampled at the render's time, one
//! clip chosen (`--animation`), morph weights.

use super::super::animation::{Interpolation, Track};
use super::Importer;
use crate::error::Result;
use crate::scene::Instance;
use glam::{DMat4, DQuat, DVec3};
use gltf::accessor::{DataType, Dimensions};
use std::collections::HashMap;

/// Component types of rotation and morph-weight outputs: floats or normalized integers.
pub(super) const FLOAT_OR_NORMALIZED: &[DataType] = &[
    DataType::F32,
    DataType::I8,
    DataType::U8,
    DataType::I16,
    DataType::U16,
];

/// Transforms a moving instance gets over the shutter (`geometry::motion` interpolates
/// between them: linear motion exactly, turns by slerp).
pub(super) const MOTION_KEYS: usize = 9;

/// Deepest node hierarchy accepted (deeper ones are almost certainly malicious).
const MAX_NODE_DEPTH: usize = 1024;

impl<'a> Importer<'a> {
    /// Samples every animation channel at `time` seconds into [`Importer::pose`]: the
    /// chosen animation's alone (`--animation`), else all the file's together, an animation
    /// that animates what an earlier one does being a clip of one character that does not
    /// play (warned).
    pub(super) fn pose_at(&mut self, time: f64) -> Result<()> {
        use gltf::animation::Property;
        use gltf::animation::util::ReadOutputs;
        let mut animated: HashMap<(usize, &str), usize> = HashMap::new();
        // Animations that animate what an earlier one does: clips of one character (a
        // walk, a run); the earlier one plays.
        let mut clips = std::collections::BTreeSet::new();
        let chosen = self.animation;
        for animation in self
            .doc
            .animations()
            .filter(|a| chosen.is_none_or(|c| c == a.index()))
        {
            for channel in animation.channels() {
                let element = format!(
                    "animations[{}].channels[{}]",
                    animation.index(),
                    channel.index()
                );
                let sampler = channel.sampler();
                let interpolation = match sampler.interpolation() {
                    gltf::animation::Interpolation::Step => Interpolation::Step,
                    gltf::animation::Interpolation::Linear => Interpolation::Linear,
                    gltf::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
                };
                let property = channel.target().property();
                let (name, dims, types) = match property {
                    Property::Translation => {
                        ("translation", Dimensions::Vec3, &[DataType::F32][..])
                    }
                    Property::Scale => ("scale", Dimensions::Vec3, &[DataType::F32][..]),
                    Property::Rotation => ("rotation", Dimensions::Vec4, FLOAT_OR_NORMALIZED),
                    Property::MorphTargetWeights => {
                        let node = channel.target().node().index();
                        match animated.get(&(node, "weights")) {
                            Some(&earlier) if earlier != animation.index() => {
                                clips.insert(animation.index());
                            }
                            _ => {
                                animated.insert((node, "weights"), animation.index());
                                self.sample_weights(&channel, &element, interpolation, time)?;
                            }
                        }
                        continue;
                    }
                };
                let node = channel.target().node().index();
                match animated.get(&(node, name)) {
                    Some(&earlier) if earlier != animation.index() => {
                        clips.insert(animation.index());
                        continue;
                    }
                    _ => {
                        animated.insert((node, name), animation.index());
                    }
                }
                self.check_sampler(&sampler, &element, dims, types)?;
                let buffers = &self.buffers;
                let reader = channel.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
                let unreadable = || self.err(&element, "the sampler's data cannot be read");
                let times: Vec<f32> = reader.read_inputs().ok_or_else(unreadable)?.collect();
                let sample = |values: &[[f32; 4]]| {
                    let track = Track {
                        times: &times,
                        values,
                        interpolation,
                    };
                    track.check().map(|()| track.sample(time))
                };
                let sample3 = |values: &[[f32; 3]]| {
                    let track = Track {
                        times: &times,
                        values,
                        interpolation,
                    };
                    track.check().map(|()| track.sample(time).truncate())
                };
                let pose = match reader.read_outputs().ok_or_else(unreadable)? {
                    ReadOutputs::Translations(values) => {
                        let v = sample3(&values.collect::<Vec<_>>());
                        v.map(|v| (Some(v), None, None))
                    }
                    ReadOutputs::Scales(values) => {
                        let v = sample3(&values.collect::<Vec<_>>());
                        v.map(|v| (None, None, Some(v)))
                    }
                    ReadOutputs::Rotations(values) => {
                        let v = sample(&values.into_f32().collect::<Vec<_>>());
                        v.map(|q| (None, Some(DQuat::from_vec4(q)), None))
                    }
                    ReadOutputs::MorphTargetWeights(_) => unreachable!("skipped above"),
                }
                .map_err(|e| self.err(&element, e))?;
                let entry = self.pose.entry(node).or_default();
                match pose {
                    (Some(t), _, _) => entry.translation = Some(t),
                    (_, Some(r), _) => entry.rotation = Some(r),
                    (_, _, Some(s)) => entry.scale = Some(s),
                    _ => {}
                }
            }
        }
        if !clips.is_empty() {
            let name = |i: usize| {
                let a = self.doc.animations().nth(i).expect("animation index");
                a.name()
                    .map_or_else(|| format!("animations[{i}]"), |n| format!("{n:?}"))
            };
            let skipped: Vec<String> = clips.iter().map(|&i| name(i)).collect();
            let first = (0..self.doc.animations().count())
                .find(|i| !clips.contains(i))
                .map_or_else(String::new, name);
            self.warn(
                "animations",
                format!(
                    "{} animate the same nodes as {first} (clips of one animation); {first} is rendered (--animation NAME plays another)",
                    skipped.join(", ")
                ),
            );
        }
        Ok(())
    }

    /// Checks an animation sampler's accessors: float key times, and outputs of `dims` and
    /// one of `types` (integers normalized).
    pub(super) fn check_sampler(
        &self,
        sampler: &gltf::animation::Sampler,
        element: &str,
        dims: Dimensions,
        types: &[DataType],
    ) -> Result<()> {
        self.check_accessor(
            &sampler.input(),
            &format!("{element} input"),
            &[Dimensions::Scalar],
            &[DataType::F32],
            false,
        )?;
        self.check_accessor(
            &sampler.output(),
            &format!("{element} output"),
            &[dims],
            types,
            true,
        )
    }

    /// Samples a morph target weights channel at `time` into [`Importer::morph_weights`].
    pub(super) fn sample_weights(
        &mut self,
        channel: &gltf::animation::Channel,
        element: &str,
        interpolation: Interpolation,
        time: f64,
    ) -> Result<()> {
        let sampler = channel.sampler();
        self.check_sampler(&sampler, element, Dimensions::Scalar, FLOAT_OR_NORMALIZED)?;
        let buffers = &self.buffers;
        let reader = channel.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let unreadable = || self.err(element, "the sampler's data cannot be read");
        let times: Vec<f32> = reader.read_inputs().ok_or_else(unreadable)?.collect();
        let values: Vec<f32> = match reader.read_outputs().ok_or_else(unreadable)? {
            gltf::animation::util::ReadOutputs::MorphTargetWeights(w) => w.into_f32().collect(),
            _ => return Err(unreadable()),
        };
        let per_key = if interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
        if times.is_empty() || !values.len().is_multiple_of(times.len() * per_key) {
            return Err(self.err(
                element,
                format!(
                    "{} weights do not divide into {} keys",
                    values.len(),
                    times.len()
                ),
            ));
        }
        let targets = values.len() / (times.len() * per_key);
        let mut weights = Vec::with_capacity(targets);
        for t in 0..targets {
            // Output element k × targets + t is target t's value in slot k (a key, or an
            // in-tangent, value and out-tangent of one for cubic splines).
            let track_values: Vec<[f32; 1]> = (0..times.len() * per_key)
                .map(|k| [values[k * targets + t]])
                .collect();
            let track = Track {
                times: &times,
                values: &track_values,
                interpolation,
            };
            track.check().map_err(|e| self.err(element, e))?;
            weights.push(track.sample(time).x as f32);
        }
        let node = channel.target().node().index();
        self.morph_weights.insert(node, weights);
        Ok(())
    }

    /// A node's local transform: its own, with the animated parts of its pose.
    pub(super) fn local_transform(&self, node: &gltf::Node) -> DMat4 {
        let Some(pose) = self.pose.get(&node.index()) else {
            return DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        };
        let (t, r, s) = node.transform().decomposed();
        DMat4::from_scale_rotation_translation(
            pose.scale.unwrap_or(DVec3::from(s.map(f64::from))),
            pose.rotation
                .unwrap_or(DQuat::from_array(r.map(f64::from)))
                .normalize(),
            pose.translation.unwrap_or(DVec3::from(t.map(f64::from))),
        )
    }

    pub(super) fn visit(
        &mut self,
        node: gltf::Node<'a>,
        parent: DMat4,
        path: &mut Vec<usize>,
    ) -> Result<()> {
        let element = format!("nodes[{}]", node.index());
        if path.contains(&node.index()) {
            return Err(self.err(&element, "node hierarchy contains a cycle"));
        }
        if path.len() >= MAX_NODE_DEPTH {
            return Err(self.err(
                &element,
                format!("node hierarchy deeper than {MAX_NODE_DEPTH}"),
            ));
        }
        let local = self.local_transform(&node);
        if !local.is_finite() {
            return Err(self.err(&element, "transform is not finite"));
        }
        let world = parent * local;
        let name = node.name().map_or_else(|| element.clone(), str::to_string);
        if let Some(group) = self.light_group(&node, &element)? {
            self.scene.add_to_light_group(&group, &name);
        }
        self.world_of.insert(node.index(), world);
        if let Some(mesh) = node.mesh() {
            let weights = self.node_weights(&node, &mesh);
            if node.skin().is_some() {
                // Skinned vertices are placed by their joints, whose transforms are known
                // once the whole scene has been visited.
                self.skinned.push((node.index(), name.clone()));
            } else if self.is_sphere(&mesh)? {
                self.sphere(&mesh, world, &name)?;
                if self.shutter.is_some() {
                    self.unblurred.push((node.index(), "the sphere"));
                }
            } else {
                let locals = self.instance_transforms(&node, DMat4::IDENTITY)?;
                for primitive in mesh.primitives() {
                    let morphs = weights.iter().any(|&w| w != 0.0)
                        || (self.samples_deformation() && primitive.morph_targets().len() > 0);
                    let m = if morphs {
                        self.deformed(&node, &mesh, &primitive, &weights, None)?
                    } else {
                        self.primitive(&mesh, &primitive)?
                    };
                    if let Some(m) = m {
                        for &local in &locals {
                            if self.shutter.is_some() {
                                self.placed
                                    .push((self.scene.instances.len(), node.index(), local));
                            }
                            self.scene.instances.push(Instance {
                                name: name.clone(),
                                mesh: m,
                                transform: world * local,
                                motion: Vec::new(),
                            });
                        }
                    }
                }
            }
        }
        if let Some(camera) = node.camera() {
            let cam = self.camera(&camera, world, &name)?;
            if self.shutter.is_some() {
                self.placed_cameras
                    .push((self.scene.cameras.len(), node.index()));
            }
            self.scene.cameras.push(cam);
        }
        if let Some(light) = node.light() {
            self.light(&light, world, &name)?;
            if self.shutter.is_some() {
                self.unblurred.push((node.index(), "the light"));
            }
        }
        path.push(node.index());
        for child in node.children() {
            self.visit(child, world, path)?;
        }
        path.pop();
        Ok(())
    }

    /// Gives each instance and camera that moves while the shutter (`open`, `close`,
    /// seconds) is open its transforms at [`MOTION_KEYS`] evenly spaced times of it: the
    /// animations sampled there, the node hierarchy composed again; skinned and morphed
    /// meshes are posed again at the same times (`deformation`). Lights and analytic spheres
    /// keep the frame's, with a warning where they move; the frame's pose is restored after.
    pub(super) fn sample_motion(
        &mut self,
        scene: gltf::Scene<'a>,
        (open, close): (f64, f64),
    ) -> Result<()> {
        if self.placed.is_empty()
            && self.placed_cameras.is_empty()
            && self.unblurred.is_empty()
            && self.deforming.is_empty()
        {
            return Ok(());
        }
        // Sampling again would repeat the frame's warnings about clips.
        let warnings = self.scene.warnings.len();
        let (pose, weights) = (
            std::mem::take(&mut self.pose),
            std::mem::take(&mut self.morph_weights),
        );
        let mut keys = vec![Vec::with_capacity(MOTION_KEYS); self.placed.len()];
        let mut camera_keys = vec![Vec::with_capacity(MOTION_KEYS); self.placed_cameras.len()];
        let mut unblurred_keys = vec![Vec::with_capacity(MOTION_KEYS); self.unblurred.len()];
        let mut deformation_keys = vec![Default::default(); self.deforming.len()];
        for k in 0..MOTION_KEYS {
            let time = open + (close - open) * k as f64 / (MOTION_KEYS - 1) as f64;
            self.pose.clear();
            self.pose_at(time)?;
            let mut world = HashMap::new();
            let mut stack: Vec<(gltf::Node, DMat4)> =
                scene.nodes().map(|n| (n, DMat4::IDENTITY)).collect();
            while let Some((node, parent)) = stack.pop() {
                let m = parent * self.local_transform(&node);
                stack.extend(node.children().map(|c| (c, m)));
                world.insert(node.index(), m);
            }
            for (&(_, node, local), keys) in self.placed.iter().zip(&mut keys) {
                keys.push(world[&node] * local);
            }
            for (&(_, node), keys) in self.placed_cameras.iter().zip(&mut camera_keys) {
                keys.push(world[&node]);
            }
            for (&(node, _), keys) in self.unblurred.iter().zip(&mut unblurred_keys) {
                keys.push(world[&node]);
            }
            self.pose_deforming(&world, &mut deformation_keys);
        }
        self.scene.warnings.truncate(warnings);
        (self.pose, self.morph_weights) = (pose, weights);
        self.finish_deforming(deformation_keys);
        for ((camera, node), keys) in std::mem::take(&mut self.placed_cameras)
            .into_iter()
            .zip(camera_keys)
        {
            self.scene.cameras[camera].motion = self.motion_of(node, keys)?;
        }
        for ((instance, node, _), keys) in std::mem::take(&mut self.placed).into_iter().zip(keys) {
            self.scene.instances[instance].motion = self.motion_of(node, keys)?;
        }
        for ((node, what), keys) in std::mem::take(&mut self.unblurred)
            .into_iter()
            .zip(unblurred_keys)
        {
            if crate::geometry::motion::keys_move(&keys) {
                self.warn(
                    format!("nodes[{node}]"),
                    format!("{what} moves while the shutter is open: lights and analytic spheres are not blurred, it stays where it is at the frame"),
                );
            }
        }
        Ok(())
    }

    /// The motion of what node `node` places, from its transforms `keys` over the shutter:
    /// none where they do not change, or (with a warning) where they cannot be interpolated
    /// (a scale of zero); an error where they are not finite.
    fn motion_of(&mut self, node: usize, keys: Vec<DMat4>) -> Result<Vec<DMat4>> {
        use crate::geometry::motion::{MotionTransform, keys_move};
        let element = format!("nodes[{node}]");
        if !keys.iter().all(DMat4::is_finite) {
            return Err(self.err(element, "the transform over the shutter is not finite"));
        }
        if !keys_move(&keys) {
            return Ok(Vec::new());
        }
        if MotionTransform::new(&keys).is_none() {
            self.warn(
                element,
                "its transform is singular during the shutter; it is not blurred",
            );
            return Ok(Vec::new());
        }
        Ok(keys)
    }

    /// Chooses the animation that plays, by name or index; an unknown one is refused with
    /// the file's animations listed.
    pub(super) fn select_animation(&mut self, wanted: Option<&str>) -> Result<()> {
        let Some(wanted) = wanted else {
            return Ok(());
        };
        let names: Vec<String> = self
            .doc
            .animations()
            .map(|a| {
                a.name()
                    .map_or_else(|| format!("{}", a.index()), |n| format!("{n:?}"))
            })
            .collect();
        let found = self
            .doc
            .animations()
            .position(|a| a.name() == Some(wanted))
            .or_else(|| wanted.parse::<usize>().ok().filter(|&i| i < names.len()));
        match found {
            Some(i) => {
                self.animation = Some(i);
                Ok(())
            }
            None if names.is_empty() => Err(self.err(
                "animations",
                format!("animation {wanted:?} requested, but the file has no animations"),
            )),
            None => Err(self.err(
                "animations",
                format!(
                    "has no animation {wanted:?} (it has {}; give a name or an index)",
                    names.join(", ")
                ),
            )),
        }
    }

    /// The morph target weights of `node`'s mesh at the render's time: animated, else the
    /// node's, else the mesh's (empty: no targets).
    pub(super) fn node_weights(&self, node: &gltf::Node, mesh: &gltf::Mesh) -> Vec<f32> {
        if let Some(w) = self.morph_weights.get(&node.index()) {
            return w.clone();
        }
        node.weights()
            .or_else(|| mesh.weights())
            .map(<[f32]>::to_vec)
            .unwrap_or_default()
    }

    /// The world transforms a node's mesh is drawn at: `world`, or one for each instance of
    /// its EXT_mesh_gpu_instancing attributes (TRANSLATION, ROTATION, SCALE; float or, with
    /// KHR_mesh_quantization, normalized integers), each applied before the node's own.
    pub(super) fn instance_transforms(
        &self,
        node: &gltf::Node,
        world: DMat4,
    ) -> Result<Vec<DMat4>> {
        let Some(ext) = node
            .extensions()
            .and_then(|e| e.get("EXT_mesh_gpu_instancing"))
        else {
            return Ok(vec![world]);
        };
        let element = format!("nodes[{}].extensions.EXT_mesh_gpu_instancing", node.index());
        let attributes = ext.get("attributes").and_then(serde_json::Value::as_object);
        let read = |name: &str, width: usize| -> Result<Option<Vec<f32>>> {
            let Some(a) = attributes.and_then(|a| a.get(name)) else {
                return Ok(None);
            };
            let e = format!("{element}.attributes.{name}");
            let a = a
                .as_u64()
                .ok_or_else(|| self.err(&e, "is not an accessor index"))?;
            let values =
                super::delivery::read_floats(self.doc.as_json(), &self.buffers, a as usize)
                    .map_err(|r| self.err(&e, r))?;
            let ty = self.doc.as_json().accessors[a as usize].type_;
            let expected = if width == 4 {
                gltf::json::accessor::Type::Vec4
            } else {
                gltf::json::accessor::Type::Vec3
            };
            if ty != gltf::json::validation::Checked::Valid(expected) {
                return Err(self.err(&e, format!("must be a {expected:?} accessor")));
            }
            if values.iter().any(|v| !v.is_finite()) {
                return Err(self.err(&e, "holds a value that is not finite"));
            }
            Ok(Some(values))
        };
        let translation = read("TRANSLATION", 3)?;
        let rotation = read("ROTATION", 4)?;
        let scale = read("SCALE", 3)?;
        let counts: Vec<usize> = [(&translation, 3), (&rotation, 4), (&scale, 3)]
            .iter()
            .filter_map(|(v, w)| v.as_ref().map(|v| v.len() / w))
            .collect();
        let Some(&count) = counts.first() else {
            return Err(self.err(&element, "has no TRANSLATION, ROTATION or SCALE attribute"));
        };
        if counts.iter().any(|&c| c != count) {
            return Err(self.err(
                &element,
                format!("its attributes have different counts {counts:?}"),
            ));
        }
        let v3 = |v: &Option<Vec<f32>>, i: usize, default: DVec3| {
            v.as_ref().map_or(default, |v| {
                DVec3::new(v[3 * i] as f64, v[3 * i + 1] as f64, v[3 * i + 2] as f64)
            })
        };
        Ok((0..count)
            .map(|i| {
                let r = rotation.as_ref().map_or(DQuat::IDENTITY, |r| {
                    DQuat::from_xyzw(
                        r[4 * i] as f64,
                        r[4 * i + 1] as f64,
                        r[4 * i + 2] as f64,
                        r[4 * i + 3] as f64,
                    )
                    .normalize()
                });
                world
                    * DMat4::from_scale_rotation_translation(
                        v3(&scale, i, DVec3::ONE),
                        r,
                        v3(&translation, i, DVec3::ZERO),
                    )
            })
            .collect())
    }
}
