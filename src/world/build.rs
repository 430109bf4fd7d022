//! Building a [`World`] from a scene: meshes moved into render space (flattened, or shared
//! and placed through a top-level BVH), the BVHs, the area lights (one per emitting
//! primitive) and punctual lights with their selection, the environment, the camera; and,
//! before any of it is allocated, the estimate of the memory it will take. Subdivision
//! surfaces are refined here, for the view they are seen from, before the estimate.

use super::placed::{NOT_SHARED, PlacedGeometry, flattened_uses, shared_mesh_indices};
use super::surfaces::{NO_LIGHT, PlacedMesh, PrimRef, RenderQuadric, RenderSphere, Surfaces};
use super::{Objects, World};
use crate::camera::{self, Camera};
use crate::error::{Error, Result};
use crate::geometry::deformation::Deformation;
use crate::geometry::instances::Placement;
use crate::geometry::motion::MotionTransform;
use crate::geometry::quadric::Quadric;
use crate::geometry::space::RenderSpace;
use crate::geometry::triangle::geometric_normal;
use crate::geometry::{ALPHA_TESTED, Bvh, CULL_BACK, Primitive, quadric};
use crate::light::LightSelect;
use crate::light::emission_texture::{self, EmissionPyramid, TriangleEmission};
use crate::light::environment::Environment;
use crate::light::{
    DirectionalLight, DistantCone, Light, LightSet, PointLight, QuadricLight, SphereLight,
    SpotLight, TriangleLight,
};
use crate::medium::Medium;
use crate::memory::MemoryEstimate;
use crate::scene::features::SceneFeatures;
use crate::scene::{self, AlphaMode, LightKind, Material, Mesh, Scene, Texture};
use glam::{DMat3, DMat4, DVec3, Vec2, Vec3};
use std::sync::Arc;

/// Pixels a refined subdivision edge spans on screen when chosen by size (the dicing rate
/// Cycles calls 1 px; 2 px keeps uniform refinement's face count in check).
const SUBDIVISION_EDGE_PIXELS: f64 = 2.0;

/// Replaces each subdivision surface's placeholder mesh by the surface refined to
/// `scene.subdivision_level`, or to the level that brings its mean cage edge to
/// [`SUBDIVISION_EDGE_PIXELS`] where its nearest instance is seen by the render camera;
/// refuses a refinement the memory limit cannot hold. Does nothing once refined.
pub fn refine_subdivision_surfaces(
    scene: &mut Scene,
    camera_name: Option<&str>,
    resolution: Option<(u32, u32)>,
) -> Result<()> {
    use crate::geometry::subdivision;
    let (lo, hi) = scene.bounds().unwrap_or((DVec3::ZERO, DVec3::ONE));
    let view = camera_name
        .and_then(|n| scene.camera(n))
        .or(scene.cameras.first())
        .cloned()
        .unwrap_or_else(|| camera::framing_camera(lo, hi));
    let (_, height) = camera::resolve_resolution(resolution, Some(&view));
    let eye = view.transform.transform_point3(DVec3::ZERO);
    // Pixels a world unit spans at distance d: height / (2 tan(fov/2) d), or per unit of
    // an orthographic view's height.
    let pixels_per_unit = |distance: f64| match view.projection {
        crate::scene::Projection::Perspective { yfov, .. } => {
            height as f64 / (2.0 * (yfov as f64 / 2.0).tan() * distance.max(1e-6))
        }
        crate::scene::Projection::Orthographic { ymag, .. } => height as f64 / (2.0 * ymag as f64),
    };
    let surfaces = std::mem::take(&mut scene.subdivision_surfaces);
    for surface in &surfaces {
        let placeholder = &scene.meshes[surface.mesh as usize];
        let level = match scene.subdivision_level {
            Some(level) => level.min(subdivision::MAX_LEVEL),
            None => {
                // The nearest instance decides: its scale and distance.
                let edge = subdivision::mean_edge_length(surface);
                scene
                    .instances
                    .iter()
                    .filter(|i| i.mesh == surface.mesh)
                    .map(|i| {
                        let scale =
                            i.transform.transform_vector3(DVec3::ONE).length() / 3f64.sqrt();
                        let (plo, phi) = placeholder.positions.iter().fold(
                            (DVec3::INFINITY, DVec3::NEG_INFINITY),
                            |(a, b), p| {
                                let w = i.transform.transform_point3(p.as_dvec3());
                                (a.min(w), b.max(w))
                            },
                        );
                        let distance = eye.clamp(plo, phi).distance(eye);
                        subdivision::level_for(
                            edge * scale,
                            pixels_per_unit(distance),
                            SUBDIVISION_EDGE_PIXELS,
                        )
                    })
                    .max()
                    .unwrap_or(1)
            }
        };
        // Bytes per refined face: four corners' positions, normals and attributes, and
        // two triangles, plus the refinement's working copies.
        let faces = subdivision::refined_face_count(surface, level);
        let keys = surface.point_keys.len() as u64;
        crate::memory::check_allocation(
            faces.saturating_mul(200 + 48 * keys),
            &format!("subdivision surface {} at level {level}", placeholder.name),
        )
        .map_err(|r| Error::bad_input(&scene.source, &placeholder.name, r))?;
        let mut refined =
            subdivision::refine(surface, level, &placeholder.name, placeholder.material);
        refined.deformation = refined_keys(surface, level, &refined);
        scene.meshes[surface.mesh as usize] = refined;
    }
    Ok(())
}

/// The deformation of subdivision surface `surface` refined at `level` into `refined`: each
/// of its point keys refined as its points were (the same topology gives the same vertices
/// in the same order), positions and normals; `None` for a cage that keeps its shape (or,
/// with a warning, whose keys refine to other vertices).
fn refined_keys(
    surface: &scene::SubdivisionSurface,
    level: u32,
    refined: &Mesh,
) -> Option<Deformation> {
    use crate::geometry::subdivision;
    if surface.point_keys.is_empty() {
        return None;
    }
    let (mut positions, mut normals) = (Vec::new(), Vec::new());
    for key in &surface.point_keys {
        let at_key = scene::SubdivisionSurface {
            points: key.clone(),
            point_keys: Vec::new(),
            ..surface.clone()
        };
        let mesh = subdivision::refine(&at_key, level, "", refined.material);
        positions.push(mesh.positions);
        normals.extend(mesh.normals);
    }
    let deformation = Deformation {
        normals: (normals.len() == positions.len() && refined.normals.is_some()).then_some(normals),
        positions,
    };
    if let Err(reason) = deformation.check(refined.positions.len(), refined.normals.is_some()) {
        log::warn!(
            "{}: its refined keys over the shutter do not match its refinement ({reason}): it keeps the frame's shape",
            refined.name
        );
        return None;
    }
    deformation.moves().then_some(deformation)
}

/// `mesh` moved by `to_render` (object space to render space), in place: positions, normals
/// and tangents transformed, the winding kept front-facing under a mirroring transform.
fn transform_mesh(mut mesh: Mesh, to_render: &DMat4) -> Mesh {
    let linear = DMat3::from_mat4(*to_render);
    let mirrored = linear.determinant() < 0.0;
    let normal_matrix = linear.inverse().transpose();
    if let Some(d) = &mut mesh.deformation {
        d.transform(to_render, &normal_matrix);
    }
    for p in &mut mesh.positions {
        *p = to_render.transform_point3(p.as_dvec3()).as_vec3();
    }
    for n in mesh.normals.iter_mut().flatten() {
        *n = (normal_matrix * n.as_dvec3()).normalize_or_zero().as_vec3();
    }
    for t in mesh.tangents.iter_mut().flatten() {
        let dir = (linear * t.truncate().as_dvec3())
            .normalize_or_zero()
            .as_vec3();
        // A mirroring transform flips the bitangent's handedness.
        *t = dir.extend(if mirrored { -t.w } else { t.w });
    }
    // A mirroring transform reverses the winding; swap two corners to keep fronts in front.
    if mirrored {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
    }
    mesh
}

/// Carries the keys of `deformation` (object space of an instance placed by `transform`)
/// along the instance's `motion` over the shutter: key `k` moves to where the motion puts
/// the object at its time, relative to `transform` (which places the mesh afterwards).
fn follow_motion(deformation: &mut Deformation, transform: &DMat4, motion: &[DMat4]) {
    let Some(motion) = MotionTransform::new(motion) else {
        return;
    };
    let keys = deformation.keys();
    let to_object = transform.inverse();
    for k in 0..keys {
        let m = to_object * motion.at(k as f32 / (keys - 1) as f32);
        let normal_matrix = DMat3::from_mat4(m).inverse().transpose();
        for p in &mut deformation.positions[k] {
            *p = m.transform_point3(p.as_dvec3()).as_vec3();
        }
        for n in deformation.normals.iter_mut().flat_map(|n| &mut n[k]) {
            *n = (normal_matrix * n.as_dvec3()).normalize_or_zero().as_vec3();
        }
    }
}

/// The corners of the triangles of `meshes` that deform, at their keys (triangle by
/// triangle, key by key), and for each mesh the index there of its first triangle's first
/// key (`None` for a mesh that keeps its shape).
fn deforming_corners(meshes: &[Mesh]) -> (Vec<[Vec3; 3]>, Vec<Option<u32>>) {
    let mut corners = Vec::new();
    let firsts = meshes
        .iter()
        .map(|mesh| {
            let d = mesh.deformation.as_ref()?;
            let first = corners.len() as u32;
            for t in &mesh.triangles {
                corners.extend((d.positions.iter()).map(|key| t.map(|i| key[i as usize])));
            }
            Some(first)
        })
        .collect();
    (corners, firsts)
}

/// The mean emission of emitters with emissive textures, for their selection by power:
/// one pyramid per texture and factor (see `light::emission_texture`).
struct TexturedEmission<'t> {
    textures: &'t [Texture],
    pyramids: std::collections::HashMap<(u32, [u32; 3]), EmissionPyramid>,
}

impl<'t> TexturedEmission<'t> {
    fn new(textures: &'t [Texture]) -> Self {
        Self {
            textures,
            pyramids: Default::default(),
        }
    }

    /// The pyramid of material `m`'s emissive texture and the texture coordinates `uvs`
    /// after its texture transform, or `None` for untextured emission and UDIM sets.
    fn footprint(
        &mut self,
        m: &Material,
        uvs: Option<[Vec2; 3]>,
    ) -> Option<(&EmissionPyramid, Option<[Vec2; 3]>)> {
        let slot = m.emissive_texture?;
        let textures = self.textures;
        if textures[slot.texture as usize].udim.is_some() {
            // A UDIM set's tiles lie outside the unit square a pyramid covers: its
            // triangles are lights of the factor's power, sampled uniformly (unbiased, as
            // every power estimate is; only the choice of light samples is less informed).
            return None;
        }
        let pyramid = self
            .pyramids
            .entry((slot.texture, m.emissive.to_array().map(f32::to_bits)))
            .or_insert_with(|| EmissionPyramid::new(&textures[slot.texture as usize], m.emissive));
        let uvs = uvs.map(|uvs| uvs.map(|uv| slot.transform.map_or(uv, |t| t.apply(uv))));
        Some((pyramid, uvs))
    }

    /// Mean emitted radiance of material `m` over the texture coordinates of `uvs` (their
    /// bounding box; the whole texture for `None`), as a grey of the right luminance.
    fn mean(&mut self, m: &Material, uvs: Option<[Vec2; 3]>) -> Vec3 {
        let Some((pyramid, uvs)) = self.footprint(m, uvs) else {
            return m.emissive;
        };
        let (lo, hi) = match uvs {
            Some(uvs) => (
                uvs[0].min(uvs[1]).min(uvs[2]),
                uvs[0].max(uvs[1]).max(uvs[2]),
            ),
            None => (Vec2::ZERO, Vec2::ONE),
        };
        Vec3::splat(pyramid.mean_over(lo, hi))
    }

    /// The subdivision a triangle with texture coordinates `uvs` asks for (0 for
    /// untextured emission).
    fn depth(&mut self, m: &Material, uvs: [Vec2; 3]) -> u32 {
        self.footprint(m, Some(uvs))
            .and_then(|(pyramid, uvs)| Some(TriangleEmission::depth_for(pyramid, uvs?)))
            .unwrap_or(0)
    }

    /// The sampling tree of a triangle with texture coordinates `uvs`, subdivided at most
    /// `max_depth` times.
    fn tree(
        &mut self,
        m: &Material,
        uvs: [Vec2; 3],
        max_depth: u32,
    ) -> Option<Arc<TriangleEmission>> {
        let (pyramid, uvs) = self.footprint(m, Some(uvs))?;
        TriangleEmission::new(pyramid, uvs?, max_depth).map(Arc::new)
    }
}

/// The most memory the sampling trees of textured emitting triangles may take, in floats
/// (16 MiB): over it, every tree is subdivided less deeply.
const EMISSION_TREE_FLOATS: usize = 4 << 20;

/// Floats of a sampling tree of `depth` levels.
fn tree_floats(depth: u32) -> usize {
    if depth == 0 {
        0
    } else {
        ((1usize << (2 * (depth + 1))) - 1) / 3
    }
}

/// The deepest subdivision that keeps trees of the wanted `depths` within
/// [`EMISSION_TREE_FLOATS`].
fn tree_depth_limit(depths: &[u32]) -> u32 {
    (0..=emission_texture::MAX_DEPTH)
        .rev()
        .find(|&limit| {
            depths
                .iter()
                .map(|&d| tree_floats(d.min(limit)))
                .sum::<usize>()
                <= EMISSION_TREE_FLOATS
        })
        .unwrap_or(0)
}

/// The BVH intersection flags of primitives made of material `m`: back faces are culled
/// on one-sided materials unless they transmit (a volume's inside and a thin wall's back
/// must be seen); hits go through the caller's filter where alpha decides them or where
/// shadow rays may cross the surface ([`Material::can_filter`]).
fn intersection_flags(m: &Material) -> u8 {
    let mut f = 0;
    if !m.double_sided && !m.transmits() {
        f |= CULL_BACK;
    }
    if m.alpha_mode != AlphaMode::Opaque || m.can_filter() {
        f |= ALPHA_TESTED;
    }
    f
}

/// Every primitive for the BVH: its intersection flags and scene reference (the primitive
/// itself is [`primitive`] of the reference, made when needed).
fn primitives(
    meshes: &[Mesh],
    spheres: &[RenderSphere],
    quadrics: &[RenderQuadric],
    materials: &[Material],
) -> (Vec<u8>, Vec<PrimRef>) {
    let count =
        meshes.iter().map(|m| m.triangles.len()).sum::<usize>() + spheres.len() + quadrics.len();
    let (mut flags, mut refs) = (Vec::with_capacity(count), Vec::with_capacity(count));
    for (mi, mesh) in meshes.iter().enumerate() {
        let f = intersection_flags(&materials[mesh.material as usize]);
        for ti in 0..mesh.triangles.len() {
            flags.push(f);
            refs.push(PrimRef::Triangle {
                mesh: mi as u32,
                tri: ti as u32,
            });
        }
    }
    for (si, s) in spheres.iter().enumerate() {
        flags.push(intersection_flags(&materials[s.material as usize]));
        refs.push(PrimRef::Sphere(si as u32));
    }
    for (qi, q) in quadrics.iter().enumerate() {
        flags.push(intersection_flags(&materials[q.material as usize]));
        refs.push(PrimRef::Quadric(qi as u32));
    }
    (flags, refs)
}

/// The render-space primitive `r` refers to.
#[inline]
fn primitive(
    r: PrimRef,
    meshes: &[Mesh],
    spheres: &[RenderSphere],
    quadrics: &[RenderQuadric],
) -> Primitive {
    match r {
        PrimRef::Triangle { mesh, tri } => {
            let mesh = &meshes[mesh as usize];
            Primitive::Triangle(mesh.triangles[tri as usize].map(|i| mesh.positions[i as usize]))
        }
        PrimRef::Sphere(s) => {
            let s = &spheres[s as usize];
            Primitive::Sphere {
                centre: s.centre,
                radius: s.radius,
            }
        }
        PrimRef::Quadric(q) => Primitive::Quadric(quadrics[q as usize].quadric),
    }
}

/// Bytes obvhs holds per primitive at the peak of a BVH build beyond the primitives'
/// flags and leaves: the bounds it is given, its PLOC nodes, sort keys and reinsertion
/// state, and the wide nodes. Measured: the peak of `lucerna render` on single meshes of 1,
/// 10 and 30 million triangles, less the program, the scene and its render-space copy, is
/// 262, 240 and 241 bytes a triangle (tools/bench/scale.py), which this constant makes 256
/// (tools/experiments/stress checks the estimate).
const BVH_BUILD_BYTES_PER_PRIMITIVE: u64 = 210;

/// Bytes a light holds beyond its `Light`: its light-tree node and selection entries.
const LIGHT_SELECTION_BYTES: u64 = 96;

/// Estimated bytes of rendering `scene` before any of them is allocated: the scene itself and
/// what [`World::build`] adds (the film is the caller's: it depends on the request).
pub fn estimate_memory(scene: &Scene) -> MemoryEstimate {
    use std::mem::size_of;
    let shared = shared_mesh_indices(scene);
    let flat_uses = flattened_uses(scene, &shared);
    let (mut geometry, mut flat_prims, mut shared_prims, mut placements, mut emitters) =
        (0, 0, 0, 0, 0);
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh as usize];
        if shared[inst.mesh as usize] == NOT_SHARED {
            // A mesh placed once moves into render space; others are copied.
            if flat_uses[inst.mesh as usize] > 1 {
                geometry += mesh.data_bytes();
            }
            flat_prims += mesh.triangles.len() as u64;
            if scene.materials[mesh.material as usize].is_emissive() {
                emitters += mesh.triangles.len() as u64;
            } else if let Some(d) = &mesh.deformation {
                // The BVH's copy of each triangle's corners at every key.
                geometry += (mesh.triangles.len() * d.keys() * size_of::<[Vec3; 3]>()) as u64;
            }
        } else {
            // The placement as traced and as shaded, and its bounds.
            geometry += (size_of::<Placement>() + size_of::<PlacedMesh>() + 24) as u64;
            placements += 1;
        }
    }
    // Shared meshes are moved out of the scene, not copied: only their primitives count.
    for (mesh, &index) in scene.meshes.iter().zip(&shared) {
        if index != NOT_SHARED {
            shared_prims += mesh.triangles.len() as u64;
        }
    }
    let shape_materials: Vec<u32> = (scene.spheres.iter().map(|s| s.material))
        .chain(scene.disks.iter().map(|d| d.material))
        .chain(scene.cylinders.iter().map(|c| c.material))
        .collect();
    flat_prims += shape_materials.len() as u64;
    emitters += shape_materials
        .iter()
        .filter(|&&m| scene.materials[m as usize].is_emissive())
        .count() as u64
        + scene.lights.len() as u64;
    // Per flattened primitive: what it refers to and its light.
    geometry += flat_prims * (size_of::<PrimRef>() + size_of::<u32>()) as u64;
    // The primitives' flags as given to the build (the primitives themselves are made from
    // the geometry when needed), its own state, and the result's leaves (triangle blocks of
    // one to four and shapes: about a copy of the primitives, their flags and an index each;
    // 80 bytes a triangle with the nodes on the sphere field).
    let per_primitive = 1
        + (size_of::<Primitive>() as u64 + 1)
        + size_of::<u32>() as u64
        + BVH_BUILD_BYTES_PER_PRIMITIVE;
    let bvh = (flat_prims + shared_prims + placements) * per_primitive;
    let environment_texels = match &scene.environment {
        Some(scene::Environment::LatLong { texture, .. }) => scene
            .textures
            .get(*texture as usize)
            .map_or(0, |t| t.width as u64 * t.height as u64),
        _ => 0,
    };
    // Sampling trees of textured emitting triangles: at most the budget.
    let textured_emitters: u64 = scene
        .instances
        .iter()
        .map(|inst| &scene.meshes[inst.mesh as usize])
        .filter(|mesh| {
            let m = &scene.materials[mesh.material as usize];
            m.is_emissive() && m.emissive_texture.is_some()
        })
        .map(|mesh| mesh.triangles.len() as u64)
        .sum();
    let trees = (textured_emitters * tree_floats(emission_texture::MAX_DEPTH) as u64)
        .min(EMISSION_TREE_FLOATS as u64)
        * 4;
    MemoryEstimate {
        program: crate::memory::PROGRAM_BYTES,
        scene: scene.data_bytes(),
        geometry,
        bvh,
        // The environment's sampling distribution holds about two floats a texel.
        lights: emitters * (size_of::<Light>() as u64 + LIGHT_SELECTION_BYTES)
            + environment_texels * 8
            + trees,
        film: 0,
    }
}

/// The area lights: one per primitive whose material emits, and the primitive-to-light map.
fn area_lights(
    refs: &[PrimRef],
    surfaces_materials: &[Material],
    meshes: &[Mesh],
    spheres: &[RenderSphere],
    quadrics: &[RenderQuadric],
    textures: &[Texture],
) -> (Vec<Light>, Vec<u32>) {
    let material_of = |r: &PrimRef| match *r {
        PrimRef::Triangle { mesh, .. } => meshes[mesh as usize].material,
        PrimRef::Sphere(s) => spheres[s as usize].material,
        PrimRef::Quadric(q) => quadrics[q as usize].material,
    };
    if !refs
        .iter()
        .any(|r| surfaces_materials[material_of(r) as usize].is_emissive())
    {
        return (Vec::new(), Vec::new());
    }
    let mut lights = Vec::new();
    let mut prim_light = vec![NO_LIGHT; refs.len()];
    let mut textured = TexturedEmission::new(textures);
    // The texture coordinates of an emitting triangle with an emissive texture.
    let texture_uvs = |r: &PrimRef, m: &Material| match (*r, m.emissive_texture) {
        (PrimRef::Triangle { mesh, tri }, Some(slot)) => {
            let mesh = &meshes[mesh as usize];
            let set = (slot.tex_coord as usize).min(1);
            Some(mesh.triangles[tri as usize].map(|v| {
                mesh.uvs[set]
                    .as_ref()
                    .map_or(Vec2::ZERO, |uv| uv[v as usize])
            }))
        }
        _ => None,
    };
    // How deeply textured triangles may be subdivided for sampling, within the budget.
    let wanted: Vec<u32> = refs
        .iter()
        .filter_map(|r| {
            let m = &surfaces_materials[material_of(r) as usize];
            let uvs = texture_uvs(r, m).filter(|_| m.is_emissive())?;
            Some(textured.depth(m, uvs))
        })
        .collect();
    let max_depth = tree_depth_limit(&wanted);
    for (i, r) in refs.iter().enumerate() {
        let m = &surfaces_materials[material_of(r) as usize];
        if !m.is_emissive() {
            continue;
        }
        prim_light[i] = lights.len() as u32;
        let uvs = texture_uvs(r, m);
        let mean_radiance = textured.mean(m, uvs);
        lights.push(match primitive(*r, meshes, spheres, quadrics) {
            Primitive::Triangle(p) => {
                let n = geometric_normal(p[0], p[1], p[2]);
                Light::Triangle(TriangleLight {
                    prim: i as u32,
                    p,
                    n: n.normalize_or_zero(),
                    area: 0.5 * n.length(),
                    two_sided: m.double_sided,
                    mean_radiance,
                    emission: uvs.and_then(|uvs| textured.tree(m, uvs, max_depth)),
                })
            }
            Primitive::Sphere { centre, radius } => Light::Sphere(SphereLight {
                prim: i as u32,
                centre,
                radius,
                two_sided: m.double_sided,
                textured: m.emissive_texture.is_some(),
                mean_radiance,
            }),
            Primitive::Quadric(quadric) => Light::Quadric(QuadricLight {
                prim: i as u32,
                quadric,
                two_sided: m.double_sided,
                mean_radiance,
            }),
            Primitive::Deforming { .. } => unreachable!("`primitive` makes still triangles"),
        });
    }
    (lights, prim_light)
}

/// The scene's disks and cylinders in render space.
fn render_quadrics(scene: &Scene, space: &RenderSpace) -> Vec<RenderQuadric> {
    let length = |l: f64| (l * space.scale) as f32;
    let disks = scene.disks.iter().map(|d| RenderQuadric {
        quadric: Quadric::Disk(quadric::Disk {
            centre: space.point(d.centre),
            normal: d.normal.normalize().as_vec3(),
            radius: length(d.radius),
        }),
        material: d.material,
    });
    let cylinders = scene.cylinders.iter().map(|c| RenderQuadric {
        quadric: Quadric::Cylinder(quadric::Cylinder {
            centre: space.point(c.centre),
            axis: c.axis.normalize().as_vec3(),
            radius: length(c.radius),
            half_length: length(0.5 * c.length),
        }),
        material: c.material,
    });
    disks.chain(cylinders).collect()
}

/// Angular diameter (radians, 0.2 arc seconds) below which a directional light is taken as
/// parallel: its shadows cannot differ visibly from sharp ones, and far smaller cones would
/// overflow their radiance in single precision.
const MIN_SOURCE_ANGLE: f32 = 1e-6;

/// The punctual lights in render space: radiant intensity scales with the square of lengths.
fn punctual_lights(scene: &Scene, space: &RenderSpace) -> Vec<Light> {
    let s2 = (space.scale * space.scale) as f32;
    scene
        .lights
        .iter()
        .map(|l| match &l.kind {
            LightKind::Point {
                position,
                intensity,
            } => Light::Point(PointLight {
                position: space.point(*position),
                intensity: *intensity * s2,
            }),
            LightKind::Spot {
                position,
                direction,
                intensity,
                inner_cone,
                outer_cone,
            } => Light::Spot(SpotLight {
                position: space.point(*position),
                axis: direction.normalize().as_vec3(),
                intensity: *intensity * s2,
                cos_inner: inner_cone.cos(),
                cos_outer: outer_cone.cos(),
            }),
            LightKind::Directional {
                direction,
                irradiance,
                angle,
            } if *angle > MIN_SOURCE_ANGLE => {
                // 1 - cos of the half-angle as 2 sin²(angle / 4), free of cancellation.
                let one_minus_cos = 2.0 * (*angle as f64 / 4.0).sin().powi(2);
                let sin2 = one_minus_cos * (2.0 - one_minus_cos);
                Light::DistantCone(DistantCone {
                    to_light: -direction.normalize().as_vec3(),
                    radiance: *irradiance / (std::f64::consts::PI * sin2) as f32,
                    one_minus_cos: one_minus_cos as f32,
                })
            }
            LightKind::Directional {
                direction,
                irradiance,
                ..
            } => Light::Directional(DirectionalLight {
                direction: direction.normalize().as_vec3(),
                irradiance: *irradiance,
            }),
        })
        .collect()
}

impl World {
    /// Prepares `scene` for rendering through camera `camera_name` (else the first camera,
    /// else one framing the scene) at `resolution` (else from the camera's aspect ratio),
    /// choosing lights for light sampling by `light_select`.
    pub fn build(
        mut scene: Scene,
        camera_name: Option<&str>,
        resolution: Option<(u32, u32)>,
        light_select: LightSelect,
    ) -> Result<Self> {
        if !scene.subdivision_surfaces.is_empty() {
            refine_subdivision_surfaces(&mut scene, camera_name, resolution)?;
        }
        let (lo, hi) = scene
            .bounds()
            .ok_or_else(|| Error::bad_input(&scene.source, "scene", "contains no geometry"))?;
        if !(lo.is_finite() && hi.is_finite()) {
            return Err(Error::bad_input(
                &scene.source,
                "scene",
                "geometry is not finite",
            ));
        }
        // Emitters keep the frame's shape (their light samples are made from it), and so
        // do meshes whose keys are all alike.
        for mesh in &mut scene.meshes {
            if mesh.deformation.as_ref().is_some_and(|d| {
                !d.moves() || scene.materials[mesh.material as usize].is_emissive()
            }) {
                mesh.deformation = None;
            }
        }
        let mut features = SceneFeatures::of(&scene);
        let space = RenderSpace::from_bounds(lo, hi);
        let to_render = space.matrix();
        let shared_index = shared_mesh_indices(&scene);
        // A mesh placed once moves into render space in place; one placed several times
        // and not shared (an emitter's: each placement is a light of its own) is copied for
        // each placement.
        let flat_uses = flattened_uses(&scene, &shared_index);
        let meshes: Vec<Mesh> = scene
            .instances
            .iter()
            .filter(|inst| shared_index[inst.mesh as usize] == NOT_SHARED)
            .map(|inst| {
                let mesh = &mut scene.meshes[inst.mesh as usize];
                let mut mesh = match flat_uses[inst.mesh as usize] {
                    1 => std::mem::take(mesh),
                    _ => mesh.clone(),
                };
                if let Some(d) = &mut mesh.deformation
                    && !inst.motion.is_empty()
                {
                    follow_motion(d, &inst.transform, &inst.motion);
                }
                transform_mesh(mesh, &(to_render * inst.transform))
            })
            .collect();
        let placed = PlacedGeometry::new(&mut scene, &shared_index, &to_render);
        let spheres: Vec<RenderSphere> = scene
            .spheres
            .iter()
            .map(|s| RenderSphere {
                centre: space.point(s.centre),
                radius: (s.radius * space.scale) as f32,
                material: s.material,
            })
            .collect();
        let quadrics = render_quadrics(&scene, &space);
        let radius = meshes
            .iter()
            .filter_map(Mesh::bounds)
            .map(|(lo, hi)| lo.abs().max(hi.abs()).length())
            .chain(spheres.iter().map(|s| s.centre.length() + s.radius))
            .chain(quadrics.iter().map(|q| {
                let (lo, hi) = q.quadric.bounds();
                lo.abs().max(hi.abs()).length()
            }))
            .chain(
                placed
                    .bounds
                    .iter()
                    .map(|(lo, hi)| lo.abs().max(hi.abs()).length()),
            )
            .fold(0.0f32, f32::max);

        let (flags, refs) = primitives(&meshes, &spheres, &quadrics, &scene.materials);
        let (mut lights, prim_light) = area_lights(
            &refs,
            &scene.materials,
            &meshes,
            &spheres,
            &quadrics,
            &scene.textures,
        );
        // The emitters' names, in the order of `lights`: area lights by primitive, then
        // the punctual lights, then the environment.
        let flattened: Vec<&str> = scene
            .instances
            .iter()
            .filter(|inst| shared_index[inst.mesh as usize] == NOT_SHARED)
            .map(|inst| inst.name.as_str())
            .collect();
        let quadric_names: Vec<&str> = (scene.disks.iter().map(|d| d.name.as_str()))
            .chain(scene.cylinders.iter().map(|c| c.name.as_str()))
            .collect();
        let mut light_names: Vec<String> = refs
            .iter()
            .zip(&prim_light)
            .filter(|&(_, &l)| l != NO_LIGHT)
            .map(|(r, _)| match *r {
                PrimRef::Triangle { mesh, .. } => flattened[mesh as usize].to_string(),
                PrimRef::Sphere(i) => scene.spheres[i as usize].name.clone(),
                PrimRef::Quadric(i) => quadric_names[i as usize].to_string(),
            })
            .collect();
        lights.extend(punctual_lights(&scene, &space));
        light_names.extend(scene.lights.iter().map(|l| l.name.clone()));
        let bvh_start = std::time::Instant::now();
        let (corners, deforming) = deforming_corners(&meshes);
        let bvh = Bvh::build_deforming(
            &flags,
            |i| match refs[i as usize] {
                PrimRef::Triangle { mesh, tri } if let Some(first) = deforming[mesh as usize] => {
                    let keys = meshes[mesh as usize]
                        .deformation
                        .as_ref()
                        .map_or(0, |d| d.keys());
                    Primitive::Deforming {
                        first: first + tri * keys as u32,
                        keys: keys as u32,
                    }
                }
                r => primitive(r, &meshes, &spheres, &quadrics),
            },
            corners,
        );
        let (placed_bvh, placements) = placed.build(&scene.materials, intersection_flags);
        let bvh_seconds = bvh_start.elapsed().as_secs_f64();

        let scene_camera = match camera_name {
            Some(name) => scene.camera(name).cloned().ok_or_else(|| {
                let names: Vec<&str> = scene.cameras.iter().map(|c| c.name.as_str()).collect();
                Error::bad_input(
                    &scene.source,
                    format!("camera {name:?}"),
                    format!("no such camera (the scene has: {})", names.join(", ")),
                )
            })?,
            None => scene
                .cameras
                .first()
                .cloned()
                .unwrap_or_else(|| camera::framing_camera(lo, hi)),
        };
        let (width, height) = camera::resolve_resolution(resolution, Some(&scene_camera));
        let camera = Camera::new(&scene_camera, &space, width, height);
        features.moving_camera = camera.moves();
        let objects = {
            let mut names: Vec<String> = scene.instances.iter().map(|i| i.name.clone()).collect();
            let (meshes, placements) = (0..scene.instances.len() as u32).partition(|&i| {
                shared_index[scene.instances[i as usize].mesh as usize] == NOT_SHARED
            });
            let first_sphere = names.len() as u32;
            names.extend(scene.spheres.iter().map(|s| s.name.clone()));
            let first_quadric = names.len() as u32;
            names.extend(quadric_names.iter().map(|n| n.to_string()));
            Objects {
                names,
                meshes,
                placements,
                first_sphere,
                first_quadric,
            }
        };
        let environment = Environment::of_scene(&scene);
        if environment.is_some() {
            light_names.push("environment".into());
        }
        Ok(Self {
            bvh,
            placed: placed_bvh,
            lights: LightSet::new(lights, environment, radius.max(1e-6), light_select),
            surfaces: Surfaces {
                meshes,
                shared_meshes: placed.meshes,
                placements,
                motions: placed.motions,
                spheres,
                quadrics,
                media: scene
                    .materials
                    .iter()
                    .map(|m| Medium::inside(m, &scene.grids, &space))
                    .collect(),
                participating: scene
                    .materials
                    .iter()
                    .any(Material::bounds_participating_medium),
                filters: scene.materials.iter().any(Material::can_filter),
                scalar_only: scene
                    .materials
                    .iter()
                    .map(|m| m.transmits() || m.can_filter())
                    .collect(),
                materials: scene.materials,
                textures: {
                    let mut textures = scene.textures;
                    crate::scene::share_mip_chains(&mut textures);
                    textures
                },
                prims: refs,
                prim_light,
            },
            camera,
            space,
            radius,
            bvh_seconds,
            features,
            light_names,
            light_groups: std::mem::take(&mut scene.light_groups),
            objects,
            footprints: super::footprint::Footprints::OFF,
            shutter: scene.shutter,
            #[cfg(target_arch = "x86_64")]
            area_lights: std::sync::OnceLock::new(),
        })
    }
}
