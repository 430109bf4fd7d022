//! What a scene contains that costs work or memory to render: its light kinds, the BSDF
//! lobes its materials can produce, textures, normal maps, alpha and vertex attributes.
//! The render plan (`render::plan`) adds the request to this analysis and chooses the
//! integrator's variant; `World` keeps it beside the geometry it describes. Vertex
//! attributes that no material reads are stripped here before a render
//! ([`strip_unused_attributes`]).

use super::material::{Reduced, SMOOTH_ALPHA};
use super::udim;
use super::{AlphaMode, BsdfModel, LightKind, Material, Scene};
use std::collections::BTreeSet;

/// The BSDF lobes a scene's materials can produce.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Lobes {
    pub diffuse: bool,
    /// Non-delta specular reflection (rough metals, Phong lobes, rough coats).
    pub glossy: bool,
    /// Delta reflection (smooth metals and coats): only BSDF sampling follows it.
    pub specular: bool,
    /// Transmission (glass: rough or smooth dielectrics, thin walls).
    pub transmission: bool,
}

impl Lobes {
    /// The lobes material `m` can produce at some surface point.
    pub fn of(m: &Material) -> Self {
        let rough = |roughness: f32| roughness * roughness >= SMOOTH_ALPHA;
        match m.model {
            BsdfModel::Lambert => Self {
                diffuse: true,
                ..Self::default()
            },
            BsdfModel::Phong { specular, .. } => Self {
                diffuse: true,
                glossy: specular.max_element() > 0.0,
                ..Self::default()
            },
            // Crossed in a straight line, as a clear filter is.
            BsdfModel::Interface => Self {
                transmission: true,
                ..Self::default()
            },
            BsdfModel::GltfPbr if m.reduced() == Some(Reduced::Lambert) => Self {
                diffuse: true,
                ..Self::default()
            },
            BsdfModel::GltfPbr => {
                // A roughness texture can lower the roughness to 0 anywhere.
                let textured = m.metallic_roughness_texture.is_some();
                // The coat's texture multiplies its factor.
                let coat = m.clearcoat > 0.0;
                // A transmission of 1 (untextured) leaves no diffuse base.
                let all_glass = m.transmission >= 1.0 && m.transmission_texture.is_none();
                Self {
                    diffuse: (m.metallic < 1.0 || textured) && !all_glass || m.sheen.is_some(),
                    glossy: rough(m.roughness) || (coat && rough(m.clearcoat_roughness)),
                    specular: !rough(m.roughness)
                        || textured
                        || (coat && !rough(m.clearcoat_roughness)),
                    transmission: m.transmits(),
                }
            }
        }
    }

    fn union(self, o: Self) -> Self {
        Self {
            diffuse: self.diffuse || o.diffuse,
            glossy: self.glossy || o.glossy,
            specular: self.specular || o.specular,
            transmission: self.transmission || o.transmission,
        }
    }
}

/// The lights of a scene by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LightKinds {
    /// Emissive triangles and analytic shapes (found by BSDF sampling too).
    pub area: usize,
    /// Point, spot and parallel directional lights (light sampling only).
    pub delta: usize,
    /// Directional lights with an angular size (reached by escaping rays).
    pub distant_cones: usize,
    pub environment: bool,
    /// Punctual lights of zero intensity: never sampled.
    pub zero_power: usize,
}

impl LightKinds {
    /// True if a BSDF-sampled ray can find an emitter, so that emitter lookups and MIS
    /// weights are needed.
    pub fn reachable_by_bsdf_sampling(&self) -> bool {
        self.area > 0 || self.distant_cones > 0 || self.environment
    }
}

/// What a scene contains that costs work or memory to render.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SceneFeatures {
    pub lights: LightKinds,
    /// Union of the lobes of every material some geometry uses.
    pub lobes: Lobes,
    /// Materials in use that read a texture (base colour, metal-roughness, emission).
    pub textured_materials: usize,
    pub normal_mapped_materials: usize,
    /// Materials in use with alpha cut-outs or blending (tested during traversal).
    pub alpha_materials: usize,
    /// Meshes that carry texture coordinates, tangents, vertex colours: interpolated at
    /// every hit on them.
    pub meshes_with_uvs: usize,
    pub meshes_with_tangents: usize,
    pub meshes_with_colors: usize,
    /// glTF PBR materials in use whose zero-weight lobes are skipped: they render as
    /// Lambert and as a conductor ([`Material::reduced`]).
    pub reduced_to_lambert: usize,
    pub reduced_to_conductor: usize,
    /// Materials in use whose BSDF has a GGX lobe (a rough glTF surface): work the packet
    /// kernel's lanes speed up.
    pub microfacet_materials: usize,
    /// Materials in use that bound a participating medium: one that scatters or emits, or
    /// any medium behind an interface (`BsdfModel::Interface`), which shadow rays cross.
    /// Media work (free-flight sampling, light samples in media, shadow rays through media)
    /// is done only where this is non-zero.
    pub participating_media: usize,
    /// Of those, the ones whose medium emits light (gathered along every segment).
    pub emitting_media: usize,
    /// Meshes placed once whose material is the same at every point and does not emit (no
    /// texture, no vertex colours): the packet kernel's lanes compute their shading points
    /// (`world::lanes`).
    pub uniform_meshes: usize,
    /// Instances that move over the shutter (transform motion blur): rays then carry a
    /// time, which only the scalar kernel follows.
    pub moving_instances: usize,
    /// The render camera moves over the shutter (the scene's first camera here; the world
    /// sets it for the camera it renders through).
    pub moving_camera: bool,
    /// Meshes placed by some instance that change shape over the shutter (deformation
    /// blur).
    pub deforming_meshes: usize,
}

impl SceneFeatures {
    /// True if something moves over the shutter: rays then carry a time.
    pub fn moves(&self) -> bool {
        self.moving_instances > 0 || self.moving_camera || self.deforming_meshes > 0
    }

    /// Analyses `scene`: only materials that some geometry uses count.
    pub fn of(scene: &Scene) -> Self {
        let mut used = vec![false; scene.materials.len()];
        let mut mark = |m: u32| {
            if let Some(u) = used.get_mut(m as usize) {
                *u = true;
            }
        };
        let mut placements = vec![0usize; scene.meshes.len()];
        for inst in &scene.instances {
            placements[inst.mesh as usize] += 1;
        }
        let instanced: Vec<bool> = placements.iter().map(|&n| n > 0).collect();
        let meshes: Vec<_> = scene
            .meshes
            .iter()
            .zip(&instanced)
            .filter(|(_, i)| **i)
            .map(|(m, _)| m)
            .collect();
        meshes.iter().for_each(|m| mark(m.material));
        scene.spheres.iter().for_each(|s| mark(s.material));
        scene.disks.iter().for_each(|d| mark(d.material));
        scene.cylinders.iter().for_each(|c| mark(c.material));
        let in_use = || {
            scene
                .materials
                .iter()
                .zip(&used)
                .filter(|(_, u)| **u)
                .map(|(m, _)| m)
        };
        let count = |f: &dyn Fn(&Material) -> bool| in_use().filter(|m| f(m)).count();
        let emissive = |material: u32| scene.materials[material as usize].is_emissive();
        let area = scene
            .instances
            .iter()
            .map(|i| &scene.meshes[i.mesh as usize])
            .filter(|m| emissive(m.material))
            .map(|m| m.triangles.len())
            .sum::<usize>()
            + scene
                .spheres
                .iter()
                .filter(|s| emissive(s.material))
                .count()
            + scene.disks.iter().filter(|d| emissive(d.material)).count()
            + scene
                .cylinders
                .iter()
                .filter(|c| emissive(c.material))
                .count();
        let mut lights = LightKinds {
            area,
            environment: scene.environment.is_some(),
            ..LightKinds::default()
        };
        for l in &scene.lights {
            let power = match &l.kind {
                LightKind::Point { intensity, .. } | LightKind::Spot { intensity, .. } => {
                    lights.delta += 1;
                    *intensity
                }
                LightKind::Directional {
                    irradiance, angle, ..
                } => {
                    if *angle > 0.0 {
                        lights.distant_cones += 1;
                    } else {
                        lights.delta += 1;
                    }
                    *irradiance
                }
            };
            if !(power.max_element() > 0.0) {
                lights.zero_power += 1;
            }
        }
        Self {
            lights,
            lobes: in_use().map(Lobes::of).fold(Lobes::default(), Lobes::union),
            textured_materials: count(&|m| {
                m.texture_slots().any(|(name, _)| name != "normal_texture")
            }),
            normal_mapped_materials: count(&|m| m.normal_texture.is_some()),
            alpha_materials: count(&|m| m.alpha_mode != AlphaMode::Opaque),
            meshes_with_uvs: meshes
                .iter()
                .filter(|m| m.uvs.iter().any(Option::is_some))
                .count(),
            meshes_with_tangents: meshes.iter().filter(|m| m.tangents.is_some()).count(),
            meshes_with_colors: meshes.iter().filter(|m| m.colors.is_some()).count(),
            reduced_to_lambert: count(&|m| m.reduced() == Some(Reduced::Lambert)),
            reduced_to_conductor: count(&|m| m.reduced() == Some(Reduced::Conductor)),
            microfacet_materials: count(&|m| m.model == BsdfModel::GltfPbr && Lobes::of(m).glossy),
            participating_media: count(&Material::bounds_participating_medium),
            emitting_media: count(&|m| m.volume.is_some_and(|v| v.emits())),
            uniform_meshes: scene
                .meshes
                .iter()
                .zip(&placements)
                .filter(|&(mesh, &n)| n == 1 && mesh.uniform_material(&scene.materials).is_some())
                .count(),
            moving_instances: scene
                .instances
                .iter()
                .filter(|i| crate::geometry::motion::keys_move(&i.motion))
                .count(),
            deforming_meshes: scene
                .meshes
                .iter()
                .zip(&instanced)
                .filter(|&(m, &placed)| {
                    // Emitters keep the frame's shape (`world::build`).
                    placed
                        && m.deformation.as_ref().is_some_and(|d| d.moves())
                        && !scene.materials[m.material as usize].is_emissive()
                })
                .count(),
            // The default camera's (the world sets the render camera's).
            moving_camera: scene
                .cameras
                .first()
                .is_some_and(|c| crate::geometry::motion::keys_move(&c.motion)),
        }
    }
}

/// Removes vertex attributes that no material reads: texture coordinate sets no texture
/// of the mesh's material samples, and tangents without a normal map. They would only be
/// stored, copied and interpolated at every hit. Returns the number of arrays dropped.
pub fn strip_unused_attributes(scene: &mut Scene) -> usize {
    let mut dropped = 0;
    for mesh in &mut scene.meshes {
        let Some(m) = scene.materials.get(mesh.material as usize) else {
            continue;
        };
        for (set, uvs) in mesh.uvs.iter_mut().enumerate() {
            let read = m
                .texture_slots()
                .any(|(_, t)| (t.tex_coord as usize).min(1) == set);
            if !read && uvs.take().is_some() {
                dropped += 1;
            }
        }
        if !m.needs_tangents() && mesh.tangents.take().is_some() {
            dropped += 1;
        }
    }
    dropped
}

/// One warning per UDIM texture whose meshes reach tiles it has no image for, naming the
/// texture and those tiles (a triangle reaches the tile under its centroid's coordinates,
/// after the slot's texture transform; there the fallback is read).
pub fn missing_tile_warnings(scene: &Scene) -> Vec<String> {
    let mut missing: Vec<BTreeSet<u32>> = vec![BTreeSet::new(); scene.textures.len()];
    for mesh in &scene.meshes {
        let Some(material) = scene.materials.get(mesh.material as usize) else {
            continue;
        };
        for (_, slot) in material.texture_slots() {
            let Some(udim) = scene
                .textures
                .get(slot.texture as usize)
                .and_then(|t| t.udim.as_deref())
            else {
                continue;
            };
            let Some(uvs) = &mesh.uvs[(slot.tex_coord as usize).min(1)] else {
                continue;
            };
            for tri in &mesh.triangles {
                let [Some(a), Some(b), Some(c)] = tri.map(|v| uvs.get(v as usize).copied()) else {
                    continue;
                };
                let centroid = (a + b + c) / 3.0;
                let uv = slot.transform.map_or(centroid, |t| t.apply(centroid));
                if let Some(number) = udim::number_at(uv)
                    && !udim.has(number)
                {
                    missing[slot.texture as usize].insert(number);
                }
            }
        }
    }
    missing
        .iter()
        .zip(&scene.textures)
        .filter(|(tiles, _)| !tiles.is_empty())
        .map(|(tiles, texture)| {
            let list: Vec<String> = tiles.iter().map(u32::to_string).collect();
            format!(
                "UDIM texture {}: no image for tile{} {} that meshes reach: the fallback is read there",
                texture.name,
                if tiles.len() == 1 { "" } else { "s" },
                list.join(", ")
            )
        })
        .collect()
}
