//! The render-ready scene: geometry moved into render space, the BVH, lights, the camera,
//! and what a hit point needs for shading.
//!
//! Render space is world space translated to the centre of the scene's bounds and scaled by
//! a power of two (exact in binary) so that the bounds fit in [-1, 1]. Both are applied in
//! double precision before rounding to f32, so a scene placed 1e7 units from the origin
//! renders like the same scene at the origin, and every absolute epsilon (ray offsets near
//! the origin) is relative to the scene's size.

pub(crate) mod lanes;

use crate::camera::{self, Camera};
use crate::error::{Error, Result};
use crate::geometry::frame::Frame;
use crate::geometry::instances::{InstancedBvh, Placement, transformed_bounds};
use crate::geometry::quadric::Quadric;
use crate::geometry::ray::Ray;
#[cfg(target_arch = "x86_64")]
use crate::geometry::ray::RayLanes;
use crate::geometry::triangle::geometric_normal;
use crate::geometry::{
    ALPHA_TESTED, Bvh, CULL_BACK, Hit, NOT_PLACED, Primitive, PrimitiveHit, quadric, sphere,
};
use crate::integrator::LightSelect;
use crate::light::emission_texture::{self, EmissionPyramid, TriangleEmission};
use crate::light::environment::{Environment, EnvironmentMap};
use crate::light::{Light, LightSet, QuadricLight, SphereLight, TriangleLight};
use crate::material::{self, SurfaceAttributes};
use crate::memory::MemoryEstimate;
use crate::plan::SceneFeatures;
use crate::sampling::pcg::hash_u32;
use crate::scene::{self, AlphaMode, LightKind, Material, Mesh, Scene, Texture};
use glam::{Affine3A, DMat3, DMat4, DVec3, Mat3A, Vec2, Vec3, Vec4};
use std::sync::Arc;

/// World space to render space: `(p - centre) * scale`, `scale` a power of two.
#[derive(Clone, Copy, Debug)]
pub struct RenderSpace {
    pub centre: DVec3,
    pub scale: f64,
}

impl RenderSpace {
    /// The render space for world bounds `(lo, hi)`.
    pub fn from_bounds(lo: DVec3, hi: DVec3) -> Self {
        let centre = (lo + hi) * 0.5;
        let half_extent = ((hi - lo) * 0.5).max_element();
        let scale = if half_extent > 0.0 && half_extent.is_finite() {
            (-half_extent.log2().ceil()).exp2()
        } else {
            1.0
        };
        Self { centre, scale }
    }

    /// World to render space as a matrix.
    pub fn matrix(&self) -> DMat4 {
        DMat4::from_scale(DVec3::splat(self.scale)) * DMat4::from_translation(-self.centre)
    }

    /// A world point in render space.
    #[inline]
    pub fn point(&self, p: DVec3) -> Vec3 {
        ((p - self.centre) * self.scale).as_vec3()
    }

    /// A render-space point in world space.
    #[inline]
    pub fn to_world(&self, p: Vec3) -> DVec3 {
        p.as_dvec3() / self.scale + self.centre
    }
}

/// What a BVH primitive is in the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PrimRef {
    Triangle { mesh: u32, tri: u32 },
    Sphere(u32),
    Quadric(u32),
}

/// A sphere in render space.
#[derive(Clone, Copy, Debug)]
pub struct RenderSphere {
    pub centre: Vec3,
    pub radius: f32,
    pub material: u32,
}

/// A disk or cylinder in render space.
#[derive(Clone, Copy, Debug)]
pub struct RenderQuadric {
    pub quadric: Quadric,
    pub material: u32,
}

/// A placement of a shared (object-space) mesh, as shading needs it.
#[derive(Clone, Copy, Debug)]
pub struct PlacedMesh {
    /// Index into [`Surfaces::shared_meshes`].
    pub mesh: u32,
    /// Object space to render space.
    pub to_render: Affine3A,
    /// Transforms object-space normals to render space (the inverse transpose).
    pub normal_matrix: Mat3A,
}

/// What shading reads: meshes, spheres, materials, textures, and what each BVH primitive is.
#[derive(Clone, Debug)]
pub struct Surfaces {
    /// Mesh instances flattened into render space: meshes placed once, and emitters.
    pub meshes: Vec<Mesh>,
    /// Meshes placed several times, in object space, each stored once.
    pub shared_meshes: Vec<Mesh>,
    /// The placements of shared meshes, indexed by [`Hit::instance`].
    pub placements: Vec<PlacedMesh>,
    pub spheres: Vec<RenderSphere>,
    pub quadrics: Vec<RenderQuadric>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    /// Primitive index (as given to the BVH) to what it is.
    pub prims: Vec<PrimRef>,
    /// Primitive index to the index of the light it is ([`NO_LIGHT`] for none); empty when
    /// nothing emits.
    pub prim_light: Vec<u32>,
    /// By material, the absorption coefficient inside its volume per render-space unit
    /// (`None` for no volume, or a clear one).
    pub absorption: Vec<Option<Vec3>>,
    /// True if some material can be a filter that shadow rays cross
    /// ([`Material::can_filter`]).
    pub filters: bool,
    /// By material: whether it transmits or can be a filter, so that the packet kernel hands
    /// paths reaching it to the scalar code.
    pub scalar_only: Vec<bool>,
}

/// Marks a primitive that is not a light in [`Surfaces::prim_light`].
pub const NO_LIGHT: u32 = u32::MAX;

/// A shading point.
#[derive(Clone, Copy, Debug)]
pub struct Interaction {
    pub p: Vec3,
    /// Unit geometric normal on the side the ray came from.
    pub ng: Vec3,
    /// Shading frame; `frame.n` is on the same side as `ng` and sees the ray's origin.
    pub frame: Frame,
    pub attrs: SurfaceAttributes,
    /// The BVH primitive hit (in the shared mesh for a placed hit).
    pub prim: u32,
    /// The placement hit, or [`NOT_PLACED`].
    pub instance: u32,
    pub material: u32,
    /// True if the ray arrived on the primitive's front (counter-clockwise side, outside).
    pub front: bool,
    /// The tangent frame of a mesh with tangents (tangent, bitangent with the mesh's
    /// handedness, interpolated normal), turned with the shading normal to the ray's side:
    /// the frame of the coat's normal map and of anisotropy.
    pub tangents: Option<[Vec3; 3]>,
}

impl Interaction {
    /// The context its BSDF is built in, with `outside_ior` outside its volume.
    #[inline]
    pub fn shading_context(&self, outside_ior: f32) -> material::ShadingContext {
        material::ShadingContext {
            front: self.front,
            outside_ior,
            tangents: self
                .tangents
                .map(|axes| axes.map(|v| self.frame.to_local(v))),
        }
    }
}

/// What a surface hit yields before it is turned to the ray's side: point, front geometric
/// normal, front shading normal, attributes, material and tangent frame.
type SurfacePoint = (Vec3, Vec3, Vec3, SurfaceAttributes, u32, Option<[Vec3; 3]>);

/// The scene prepared for rendering.
pub struct World {
    /// The flattened geometry and spheres.
    pub bvh: Bvh,
    /// The placements of shared meshes, when the scene has any.
    pub placed: Option<InstancedBvh>,
    pub surfaces: Surfaces,
    pub lights: LightSet,
    pub camera: Camera,
    pub space: RenderSpace,
    /// Radius of the render-space bounding sphere around the origin.
    pub radius: f32,
    /// Seconds spent building the BVH.
    pub bvh_seconds: f64,
    /// What the scene contains that costs work (the scene half of the render plan).
    pub features: SceneFeatures,
    /// Name of the emitter each light of [`World::lights`] comes from: the instance,
    /// shape or punctual light, or `environment` (light groups match these).
    pub light_names: Vec<String>,
    /// The light groups the scene declares.
    pub light_groups: Vec<crate::scene::LightGroup>,
    /// The objects that hits belong to (Cryptomatte).
    pub objects: Objects,
    /// The lights as the packet kernel's lanes sample them, built when it first runs.
    #[cfg(target_arch = "x86_64")]
    area_lights: std::sync::OnceLock<crate::light::lanes::AreaLights>,
}

/// The named objects of the scene, and which object each hit primitive belongs to: the
/// instances (flattened or placed) in scene order, then the spheres, disks and cylinders.
#[derive(Clone, Debug, Default)]
pub struct Objects {
    pub names: Vec<String>,
    /// Flattened render mesh → object.
    meshes: Vec<u32>,
    /// Placement → object.
    placements: Vec<u32>,
    /// Objects of the first sphere and the first quadric.
    first_sphere: u32,
    first_quadric: u32,
}

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
        crate::memory::check_allocation(
            faces.saturating_mul(200),
            &format!("subdivision surface {} at level {level}", placeholder.name),
        )
        .map_err(|r| Error::bad_input(&scene.source, &placeholder.name, r))?;
        let refined = subdivision::refine(surface, level, &placeholder.name, placeholder.material);
        scene.meshes[surface.mesh as usize] = refined;
    }
    Ok(())
}

fn transform_mesh(mesh: &Mesh, to_render: &DMat4) -> Mesh {
    let linear = DMat3::from_mat4(*to_render);
    let mirrored = linear.determinant() < 0.0;
    let normal_matrix = linear.inverse().transpose();
    let positions = mesh
        .positions
        .iter()
        .map(|p| to_render.transform_point3(p.as_dvec3()).as_vec3())
        .collect();
    let normals = mesh.normals.as_ref().map(|ns| {
        ns.iter()
            .map(|n| (normal_matrix * n.as_dvec3()).normalize_or_zero().as_vec3())
            .collect()
    });
    let tangents = mesh.tangents.as_ref().map(|ts| {
        ts.iter()
            .map(|t| {
                let dir = (linear * t.truncate().as_dvec3())
                    .normalize_or_zero()
                    .as_vec3();
                // A mirroring transform flips the bitangent's handedness.
                dir.extend(if mirrored { -t.w } else { t.w })
            })
            .collect()
    });
    // A mirroring transform reverses the winding; swap two corners to keep fronts in front.
    let triangles = if mirrored {
        mesh.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect()
    } else {
        mesh.triangles.clone()
    };
    Mesh {
        name: mesh.name.clone(),
        positions,
        normals,
        tangents,
        uvs: mesh.uvs.clone(),
        colors: mesh.colors.clone(),
        triangles,
        material: mesh.material,
    }
}

fn build_environment(scene: &Scene) -> Option<Environment> {
    match scene.environment.as_ref()? {
        scene::Environment::Constant(l) => Some(Environment::Constant(*l)),
        scene::Environment::LatLong {
            texture,
            scale,
            rotation,
        } => {
            let to_world = DMat3::from_mat4(*rotation).as_mat3();
            Some(Environment::Map(Box::new(EnvironmentMap::new(
                scene.textures[*texture as usize].clone(),
                *scale,
                to_world,
            ))))
        }
    }
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
    /// after its texture transform, or `None` for untextured emission.
    fn footprint(
        &mut self,
        m: &Material,
        uvs: Option<[Vec2; 3]>,
    ) -> Option<(&EmissionPyramid, Option<[Vec2; 3]>)> {
        let slot = m.emissive_texture?;
        let textures = self.textures;
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

/// Every primitive for the BVH with its intersection flags and scene reference.
fn primitives(
    meshes: &[Mesh],
    spheres: &[RenderSphere],
    quadrics: &[RenderQuadric],
    materials: &[Material],
) -> (Vec<Primitive>, Vec<u8>, Vec<PrimRef>) {
    let count =
        meshes.iter().map(|m| m.triangles.len()).sum::<usize>() + spheres.len() + quadrics.len();
    let (mut prims, mut flags, mut refs) = (
        Vec::with_capacity(count),
        Vec::with_capacity(count),
        Vec::with_capacity(count),
    );
    for (mi, mesh) in meshes.iter().enumerate() {
        let f = intersection_flags(&materials[mesh.material as usize]);
        for (ti, t) in mesh.triangles.iter().enumerate() {
            prims.push(Primitive::Triangle(t.map(|i| mesh.positions[i as usize])));
            flags.push(f);
            refs.push(PrimRef::Triangle {
                mesh: mi as u32,
                tri: ti as u32,
            });
        }
    }
    for (si, s) in spheres.iter().enumerate() {
        prims.push(Primitive::Sphere {
            centre: s.centre,
            radius: s.radius,
        });
        flags.push(intersection_flags(&materials[s.material as usize]));
        refs.push(PrimRef::Sphere(si as u32));
    }
    for (qi, q) in quadrics.iter().enumerate() {
        prims.push(Primitive::Quadric(q.quadric));
        flags.push(intersection_flags(&materials[q.material as usize]));
        refs.push(PrimRef::Quadric(qi as u32));
    }
    (prims, flags, refs)
}

/// Marks a mesh that is flattened into render space in [`shared_mesh_indices`].
const NOT_SHARED: u32 = u32::MAX;

/// For each scene mesh, its index among the shared meshes, or [`NOT_SHARED`]. A mesh is
/// shared (traced once in object space, placed through the top-level BVH) when several
/// instances place it and it does not emit: emitters are flattened so that every emitting
/// triangle is a light of its own.
fn shared_mesh_indices(scene: &Scene) -> Vec<u32> {
    let mut uses = vec![0u32; scene.meshes.len()];
    for inst in &scene.instances {
        uses[inst.mesh as usize] += 1;
    }
    let mut next = 0;
    scene
        .meshes
        .iter()
        .zip(uses)
        .map(|(mesh, uses)| {
            if uses >= 2 && !scene.materials[mesh.material as usize].is_emissive() {
                next += 1;
                next - 1
            } else {
                NOT_SHARED
            }
        })
        .collect()
}

/// Bytes obvhs holds per primitive at the peak of a BVH build beyond the primitives
/// themselves: the bounds it is given, its PLOC nodes, sort keys and reinsertion state, and
/// the wide nodes. Measured: the peak of `lucerna render` on single meshes of 0.32, 2 and
/// 3.9 million triangles, less the scene and its render-space copy, is 304 to 319 bytes a
/// triangle, which this constant makes 326 (tools/stress checks the estimate).
const BVH_BUILD_BYTES_PER_PRIMITIVE: u64 = 240;

/// Bytes a light holds beyond its `Light`: its light-tree node and selection entries.
const LIGHT_SELECTION_BYTES: u64 = 96;

/// Estimated bytes of rendering `scene` before any of them is allocated: the scene itself and
/// what [`World::build`] adds (the film is the caller's: it depends on the request).
pub fn estimate_memory(scene: &Scene) -> MemoryEstimate {
    use std::mem::size_of;
    let shared = shared_mesh_indices(scene);
    let (mut geometry, mut flat_prims, mut shared_prims, mut placements, mut emitters) =
        (0, 0, 0, 0, 0);
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh as usize];
        if shared[inst.mesh as usize] == NOT_SHARED {
            geometry += mesh.data_bytes();
            flat_prims += mesh.triangles.len() as u64;
            if scene.materials[mesh.material as usize].is_emissive() {
                emitters += mesh.triangles.len() as u64;
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
    // The primitives and their flags as given to the build, its own state, and the result's
    // leaves (triangle blocks of one to four and shapes: about a copy of the primitives, their
    // flags and an index each; 80 bytes a triangle with the nodes on the sphere field).
    let per_primitive = 2 * (size_of::<Primitive>() as u64 + 1)
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

/// The shared meshes (object space) and their placements, before their BVHs are built.
struct PlacedGeometry {
    meshes: Vec<Mesh>,
    /// Per placement: the shared mesh and object space to render space (in double
    /// precision, so that the inverse is accurate too).
    placements: Vec<(u32, DMat4)>,
    /// Per placement: its render-space bounds.
    bounds: Vec<(Vec3, Vec3)>,
}

impl PlacedGeometry {
    /// Moves the shared meshes out of `scene` and collects their placements.
    fn new(scene: &mut Scene, shared_index: &[u32], to_render: &DMat4) -> Self {
        let mut meshes = Vec::new();
        for (mesh, &index) in scene.meshes.iter_mut().zip(shared_index) {
            if index != NOT_SHARED {
                meshes.push(std::mem::take(mesh));
            }
        }
        let object_bounds: Vec<Option<(Vec3, Vec3)>> = meshes.iter().map(Mesh::bounds).collect();
        let (mut placements, mut bounds) = (Vec::new(), Vec::new());
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
            bounds.push(transformed_bounds(
                lo,
                hi,
                &Affine3A::from_mat4(m.as_mat4()),
            ));
            placements.push((index, m));
        }
        Self {
            meshes,
            placements,
            bounds,
        }
    }

    /// One BVH per shared mesh, the top level over the placements, and the placements as
    /// shading reads them.
    fn build(&self, materials: &[Material]) -> (Option<InstancedBvh>, Vec<PlacedMesh>) {
        if self.placements.is_empty() {
            return (None, Vec::new());
        }
        let shared = self
            .meshes
            .iter()
            .map(|mesh| {
                let prims: Vec<Primitive> = mesh
                    .triangles
                    .iter()
                    .map(|t| Primitive::Triangle(t.map(|i| mesh.positions[i as usize])))
                    .collect();
                let flags =
                    vec![intersection_flags(&materials[mesh.material as usize]); prims.len()];
                Bvh::build(&prims, &flags)
            })
            .collect();
        let placements: Vec<Placement> = self
            .placements
            .iter()
            .map(|&(shared, to_render)| Placement {
                shared,
                to_object: Affine3A::from_mat4(to_render.inverse().as_mat4()),
            })
            .collect();
        let shading = self
            .placements
            .iter()
            .map(|&(mesh, to_render)| PlacedMesh {
                mesh,
                to_render: Affine3A::from_mat4(to_render.as_mat4()),
                normal_matrix: Mat3A::from(
                    DMat3::from_mat4(to_render).inverse().transpose().as_mat3(),
                ),
            })
            .collect();
        (
            Some(InstancedBvh::build(shared, &placements, &self.bounds)),
            shading,
        )
    }
}

/// The area lights: one per primitive whose material emits, and the primitive-to-light map.
fn area_lights(
    prims: &[Primitive],
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
    let mut prim_light = vec![NO_LIGHT; prims.len()];
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
    for (i, (prim, r)) in prims.iter().zip(refs).enumerate() {
        let m = &surfaces_materials[material_of(r) as usize];
        if !m.is_emissive() {
            continue;
        }
        prim_light[i] = lights.len() as u32;
        let uvs = texture_uvs(r, m);
        let mean_radiance = textured.mean(m, uvs);
        lights.push(match *prim {
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
            } => Light::Point {
                position: space.point(*position),
                intensity: *intensity * s2,
            },
            LightKind::Spot {
                position,
                direction,
                intensity,
                inner_cone,
                outer_cone,
            } => Light::Spot {
                position: space.point(*position),
                axis: direction.normalize().as_vec3(),
                intensity: *intensity * s2,
                cos_inner: inner_cone.cos(),
                cos_outer: outer_cone.cos(),
            },
            LightKind::Directional {
                direction,
                irradiance,
                angle,
            } if *angle > MIN_SOURCE_ANGLE => {
                // 1 - cos of the half-angle as 2 sin²(angle / 4), free of cancellation.
                let one_minus_cos = 2.0 * (*angle as f64 / 4.0).sin().powi(2);
                let sin2 = one_minus_cos * (2.0 - one_minus_cos);
                Light::DistantCone {
                    to_light: -direction.normalize().as_vec3(),
                    radiance: *irradiance / (std::f64::consts::PI * sin2) as f32,
                    one_minus_cos: one_minus_cos as f32,
                }
            }
            LightKind::Directional {
                direction,
                irradiance,
                ..
            } => Light::Directional {
                direction: direction.normalize().as_vec3(),
                irradiance: *irradiance,
            },
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
        let features = SceneFeatures::of(&scene);
        let space = RenderSpace::from_bounds(lo, hi);
        let to_render = space.matrix();
        let shared_index = shared_mesh_indices(&scene);
        let meshes: Vec<Mesh> = scene
            .instances
            .iter()
            .filter(|inst| shared_index[inst.mesh as usize] == NOT_SHARED)
            .map(|inst| {
                transform_mesh(
                    &scene.meshes[inst.mesh as usize],
                    &(to_render * inst.transform),
                )
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
            .flat_map(|m| m.positions.iter().map(|p| p.length()))
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

        let (prims, flags, refs) = primitives(&meshes, &spheres, &quadrics, &scene.materials);
        let (mut lights, prim_light) = area_lights(
            &prims,
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
        let bvh = Bvh::build(&prims, &flags);
        drop(prims);
        let (placed_bvh, placements) = placed.build(&scene.materials);
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
        let environment = build_environment(&scene);
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
                spheres,
                quadrics,
                absorption: scene
                    .materials
                    .iter()
                    .map(|m| {
                        m.volume
                            .map(|v| v.absorption / space.scale as f32)
                            .filter(|a| *a != Vec3::ZERO)
                    })
                    .collect(),
                filters: scene.materials.iter().any(Material::can_filter),
                scalar_only: scene
                    .materials
                    .iter()
                    .map(|m| m.transmits() || m.can_filter())
                    .collect(),
                materials: scene.materials,
                textures: scene.textures,
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
            #[cfg(target_arch = "x86_64")]
            area_lights: std::sync::OnceLock::new(),
        })
    }

    /// The area lights laid out for the packet kernel's lanes (built on first use).
    #[cfg(target_arch = "x86_64")]
    pub(crate) fn area_lights(&self) -> &crate::light::lanes::AreaLights {
        self.area_lights.get_or_init(|| {
            crate::light::lanes::AreaLights::new(&self.lights, |prim| {
                self.surfaces.untextured_emission(prim)
            })
        })
    }

    /// Closest surface along `ray`, honouring back-face culling and alpha.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let hit = self
            .bvh
            .intersect(ray, |prim, hit| self.surfaces.alpha_passes(prim, hit, ray));
        let Some(placed) = &self.placed else {
            return hit;
        };
        let nearer = Ray {
            tmax: hit.map_or(ray.tmax, |h| h.t),
            ..*ray
        };
        placed
            .intersect(&nearer, |placement, prim, hit, object_ray| {
                self.surfaces
                    .placed_alpha_passes(placement, prim, hit, object_ray)
            })
            .or(hit)
    }

    /// What arrives at `ray`'s origin of light leaving its end along it: zero if something
    /// opaque blocks it, else the product of the straight transmissions of the filters it
    /// crosses (thin smooth walls; one where there are none). Shadow rays ask this.
    #[inline]
    pub fn transmittance(&self, ray: &Ray) -> Vec3 {
        if !self.surfaces.filters {
            return if self.occluded(ray) {
                Vec3::ZERO
            } else {
                Vec3::ONE
            };
        }
        let mut through = Vec3::ONE;
        let surfaces = &self.surfaces;
        let blocked = self.bvh.occluded(ray, |prim, hit| {
            surfaces.blocks_shadow(prim, NOT_PLACED, hit, ray, &mut through)
        }) || self.placed.as_ref().is_some_and(|placed| {
            placed.occluded(ray, |placement, prim, hit, _| {
                surfaces.blocks_shadow(prim, placement, hit, ray, &mut through)
            })
        });
        if blocked { Vec3::ZERO } else { through }
    }

    /// True if something blocks `ray` before `ray.tmax`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.bvh
            .occluded(ray, |prim, hit| self.surfaces.alpha_passes(prim, hit, ray))
            || self.placed.as_ref().is_some_and(|placed| {
                placed.occluded(ray, |placement, prim, hit, object_ray| {
                    self.surfaces
                        .placed_alpha_passes(placement, prim, hit, object_ray)
                })
            })
    }

    /// [`World::intersect`] of the `mask` lanes of `rays`, the flattened geometry's BVH
    /// traversed by the rays as a packet (see `geometry::wide::WideBvh::traverse_lanes`):
    /// the same hits, lane by lane. Runs only inside the packet kernel.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) fn intersect_lanes(
        &self,
        rays: &RayLanes,
        mask: u32,
    ) -> [Option<Hit>; crate::simd::LANES] {
        let mut hits = self.bvh.intersect_lanes(rays, mask, |lane, prim, hit| {
            self.surfaces.alpha_passes(prim, hit, &rays.ray(lane))
        });
        if let Some(placed) = &self.placed {
            for lane in crate::geometry::triangle::Lanes::new(mask) {
                let ray = &rays.ray(lane);
                let nearer = Ray {
                    tmax: hits[lane].map_or(ray.tmax, |h| h.t),
                    ..*ray
                };
                let found = placed.intersect(&nearer, |placement, prim, hit, object_ray| {
                    self.surfaces
                        .placed_alpha_passes(placement, prim, hit, object_ray)
                });
                hits[lane] = found.or(hits[lane]);
            }
        }
        hits
    }

    /// [`World::occluded`] of the `mask` lanes of `rays`: the mask of those blocked. Runs
    /// only inside the packet kernel.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) fn occluded_lanes(&self, rays: &RayLanes, mask: u32) -> u32 {
        let mut occluded = self.bvh.occluded_lanes(rays, mask, |lane, prim, hit| {
            self.surfaces.alpha_passes(prim, hit, &rays.ray(lane))
        });
        if let Some(placed) = &self.placed {
            for lane in crate::geometry::triangle::Lanes::new(mask & !occluded) {
                let blocked =
                    placed.occluded(&rays.ray(lane), |placement, prim, hit, object_ray| {
                        self.surfaces
                            .placed_alpha_passes(placement, prim, hit, object_ray)
                    });
                occluded |= u32::from(blocked) << lane;
            }
        }
        occluded
    }

    /// [`World::transmittance`] of the `mask` lanes of `rays`: the lanes something opaque
    /// blocks, and where the scene has filters, what each lane's filters let through
    /// (`None` without filters: [`World::occluded_lanes`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) fn transmittance_lanes(
        &self,
        rays: &RayLanes,
        mask: u32,
    ) -> (u32, Option<[Vec3; crate::simd::LANES]>) {
        if !self.surfaces.filters {
            return (self.occluded_lanes(rays, mask), None);
        }
        let surfaces = &self.surfaces;
        let mut through = [Vec3::ONE; crate::simd::LANES];
        let mut blocked = self.bvh.occluded_lanes(rays, mask, |lane, prim, hit| {
            surfaces.blocks_shadow(prim, NOT_PLACED, hit, &rays.ray(lane), &mut through[lane])
        });
        if let Some(placed) = &self.placed {
            for lane in crate::geometry::triangle::Lanes::new(mask & !blocked) {
                let ray = rays.ray(lane);
                let lane_through = &mut through[lane];
                let hit = placed.occluded(&ray, |placement, prim, hit, _| {
                    surfaces.blocks_shadow(prim, placement, hit, &ray, lane_through)
                });
                blocked |= u32::from(hit) << lane;
            }
        }
        (blocked, Some(through))
    }

    /// How many of `rays` hit something (`occlusion`: are blocked), queried eight at a time
    /// as the packet kernel queries them ([`World::intersect_lanes`],
    /// [`World::occluded_lanes`]); `None` where the CPU lacks AVX2 and FMA. For the
    /// throughput benchmark, which sets these against the single-ray queries.
    pub fn count_hits_in_packets(&self, rays: &[Ray], occlusion: bool) -> Option<usize> {
        #[cfg(target_arch = "x86_64")]
        if crate::integrator::packet_kernel_available() {
            // SAFETY: the CPU has AVX2 and FMA.
            return Some(unsafe { self.count_hits_in_packets_avx2(rays, occlusion) });
        }
        let _ = (rays, occlusion);
        None
    }

    /// [`World::count_hits_in_packets`] on a CPU with AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn count_hits_in_packets_avx2(&self, rays: &[Ray], occlusion: bool) -> usize {
        use crate::simd::LANES;
        let mut hits = 0;
        for chunk in rays.chunks(LANES) {
            let packet: [Ray; LANES] = std::array::from_fn(|l| chunk[l.min(chunk.len() - 1)]);
            let packet = RayLanes::of_rays(&packet);
            let mask = (1u32 << chunk.len()) - 1;
            hits += if occlusion {
                self.occluded_lanes(&packet, mask).count_ones() as usize
            } else {
                let found = self.intersect_lanes(&packet, mask);
                found.iter().filter(|h| h.is_some()).count()
            };
        }
        hits
    }

    /// Primitives the renderer intersects: flattened triangles and spheres, plus every
    /// triangle of every placement.
    pub fn primitive_count(&self) -> usize {
        self.surfaces.prims.len()
            + self
                .surfaces
                .placements
                .iter()
                .map(|p| self.surfaces.shared_meshes[p.mesh as usize].triangles.len())
                .sum::<usize>()
    }

    /// Bytes of the acceleration structures (both levels).
    pub fn bvh_bytes(&self) -> usize {
        self.bvh.bytes() + self.placed.as_ref().map_or(0, InstancedBvh::bytes)
    }

    /// The shading point of `hit` along `ray`.
    #[inline]
    pub fn interaction(&self, ray: &Ray, hit: &Hit) -> Interaction {
        self.surfaces.interaction(ray, hit)
    }

    /// The materials' names, by index (Cryptomatte's material mattes).
    pub fn material_names(&self) -> Vec<String> {
        self.surfaces
            .materials
            .iter()
            .map(|m| m.name.clone())
            .collect()
    }

    /// The object (index into [`Objects::names`]) that `it` lies on.
    pub fn object_of(&self, it: &Interaction) -> u32 {
        let o = &self.objects;
        if it.instance != NOT_PLACED {
            return o.placements[it.instance as usize];
        }
        match self.surfaces.prims[it.prim as usize] {
            PrimRef::Triangle { mesh, .. } => o.meshes[mesh as usize],
            PrimRef::Sphere(i) => o.first_sphere + i,
            PrimRef::Quadric(i) => o.first_quadric + i,
        }
    }

    /// Index of the light that the primitive of `it` is, if it emits (emitters are never
    /// placed through a shared mesh).
    #[inline]
    pub fn light_index(&self, it: &Interaction) -> Option<usize> {
        if it.instance != NOT_PLACED {
            return None;
        }
        self.surfaces
            .prim_light
            .get(it.prim as usize)
            .filter(|&&l| l != NO_LIGHT)
            .map(|&l| l as usize)
    }
}

#[cfg(test)]
impl Surfaces {
    /// Surfaces of `meshes` placed once (a primitive a triangle, mesh by mesh) with
    /// `materials`, nothing else.
    pub(crate) fn for_tests(meshes: Vec<Mesh>, materials: Vec<Material>) -> Self {
        let prims = meshes
            .iter()
            .enumerate()
            .flat_map(|(m, mesh)| {
                (0..mesh.triangles.len()).map(move |tri| PrimRef::Triangle {
                    mesh: m as u32,
                    tri: tri as u32,
                })
            })
            .collect();
        Self {
            meshes,
            shared_meshes: Vec::new(),
            placements: Vec::new(),
            spheres: Vec::new(),
            quadrics: Vec::new(),
            materials,
            textures: Vec::new(),
            prims,
            prim_light: Vec::new(),
            absorption: Vec::new(),
            filters: false,
            scalar_only: Vec::new(),
        }
    }
}

impl Surfaces {
    /// Interpolated attributes of triangle `tri` of `mesh` at barycentrics (b1, b2).
    #[inline]
    pub fn triangle_attributes(
        &self,
        mesh: &Mesh,
        tri: [u32; 3],
        b1: f32,
        b2: f32,
    ) -> SurfaceAttributes {
        let b0 = 1.0 - b1 - b2;
        let [i0, i1, i2] = tri.map(|i| i as usize);
        let uv = |set: &Option<Vec<Vec2>>| {
            set.as_ref()
                .map_or(Vec2::ZERO, |uv| uv[i0] * b0 + uv[i1] * b1 + uv[i2] * b2)
        };
        SurfaceAttributes {
            uv: [uv(&mesh.uvs[0]), uv(&mesh.uvs[1])],
            color: mesh
                .colors
                .as_ref()
                .map_or(Vec4::ONE, |c| c[i0] * b0 + c[i1] * b1 + c[i2] * b2),
        }
    }

    /// Attributes of a point of an analytic shape from its texture coordinates (both UV
    /// sets).
    #[inline]
    fn shape_attributes(uv: Vec2) -> SurfaceAttributes {
        SurfaceAttributes {
            uv: [uv, uv],
            color: Vec4::ONE,
        }
    }

    /// Material and attributes of primitive `prim` at surface coordinates `b` (triangle
    /// barycentrics, sphere lat-long uv).
    #[inline]
    fn material_at(&self, prim: u32, b: Vec2) -> (&Material, SurfaceAttributes) {
        match self.prims[prim as usize] {
            PrimRef::Triangle { mesh, tri } => {
                let m = &self.meshes[mesh as usize];
                (
                    &self.materials[m.material as usize],
                    self.triangle_attributes(m, m.triangles[tri as usize], b.x, b.y),
                )
            }
            PrimRef::Sphere(s) => (
                &self.materials[self.spheres[s as usize].material as usize],
                Self::shape_attributes(b),
            ),
            PrimRef::Quadric(q) => (
                &self.materials[self.quadrics[q as usize].material as usize],
                Self::shape_attributes(b),
            ),
        }
    }

    /// Surface coordinates of a hit: barycentrics, or the sphere's uv at the hit point.
    #[inline]
    fn coords(&self, prim: u32, hit: &PrimitiveHit, ray: &Ray) -> Vec2 {
        match self.prims[prim as usize] {
            PrimRef::Triangle { .. } => Vec2::new(hit.b1, hit.b2),
            PrimRef::Sphere(s) => {
                let s = &self.spheres[s as usize];
                sphere::uv((ray.at(hit.t) - s.centre).normalize_or(Vec3::Y))
            }
            PrimRef::Quadric(q) => self.quadrics[q as usize].quadric.uv(ray.at(hit.t)),
        }
    }

    /// Whether a hit on alpha-tested primitive `prim` counts: cut-outs compare alpha with
    /// the cutoff; blended surfaces are hit with probability alpha, decided by a hash of the
    /// ray so that the decision is deterministic.
    fn alpha_passes(&self, prim: u32, hit: &PrimitiveHit, ray: &Ray) -> bool {
        let (mat, attrs) = self.material_at(prim, self.coords(prim, hit, ray));
        self.alpha_decides(mat, &attrs, prim, hit, ray)
    }

    /// [`Surfaces::alpha_passes`] for a hit on triangle `prim` of placement `placement`,
    /// found along the object-space ray `ray`.
    fn placed_alpha_passes(
        &self,
        placement: u32,
        prim: u32,
        hit: &PrimitiveHit,
        ray: &Ray,
    ) -> bool {
        let mesh = &self.shared_meshes[self.placements[placement as usize].mesh as usize];
        let attrs = self.triangle_attributes(mesh, mesh.triangles[prim as usize], hit.b1, hit.b2);
        let key = prim ^ hash_u32(placement);
        self.alpha_decides(
            &self.materials[mesh.material as usize],
            &attrs,
            key,
            hit,
            ray,
        )
    }

    /// Whether a shadow ray's hit on primitive `prim` (of placement `placement`, or
    /// [`NOT_PLACED`]) blocks the world-space shadow ray `ray`: not where alpha removes the
    /// surface; where it is a filter, only once the product `through` of the straight
    /// transmissions it has crossed (multiplied here) reaches zero. Traversal reports every
    /// hit once, in any order, and the product does not depend on the order.
    fn blocks_shadow(
        &self,
        prim: u32,
        placement: u32,
        hit: &PrimitiveHit,
        ray: &Ray,
        through: &mut Vec3,
    ) -> bool {
        let counts = if placement == NOT_PLACED {
            self.alpha_passes(prim, hit, ray)
        } else {
            let mesh = &self.shared_meshes[self.placements[placement as usize].mesh as usize];
            let attrs =
                self.triangle_attributes(mesh, mesh.triangles[prim as usize], hit.b1, hit.b2);
            let key = prim ^ hash_u32(placement);
            self.alpha_decides(
                &self.materials[mesh.material as usize],
                &attrs,
                key,
                hit,
                ray,
            )
        };
        if !counts {
            return false;
        }
        let surface = Hit {
            t: hit.t,
            prim,
            b1: hit.b1,
            b2: hit.b2,
            front: hit.front,
            instance: placement,
        };
        let it = self.interaction(ray, &surface);
        let m = &self.materials[it.material as usize];
        if !m.can_filter() {
            return true;
        }
        let mut storage = material::BsdfStorage::default();
        let ctx = it.shading_context(1.0);
        let bsdf = material::bsdf_in(m, &self.textures, &it.attrs, &ctx, &mut storage);
        *through *= bsdf.straight_transmission(it.frame.to_local(-ray.dir.normalize()));
        *through == Vec3::ZERO
    }

    /// The absorption coefficient (per render-space unit) inside the volume of material
    /// `material`, where it absorbs.
    #[inline]
    pub fn absorption(&self, material: u32) -> Option<Vec3> {
        self.absorption.get(material as usize).copied().flatten()
    }

    /// The alpha decision for a hit with surface attributes `attrs`; `key` identifies the
    /// primitive in the hash of a blended surface.
    fn alpha_decides(
        &self,
        mat: &Material,
        attrs: &SurfaceAttributes,
        key: u32,
        hit: &PrimitiveHit,
        ray: &Ray,
    ) -> bool {
        if mat.alpha_mode == AlphaMode::Opaque {
            return true;
        }
        let alpha = material::alpha(mat, &self.textures, attrs);
        match mat.alpha_mode {
            AlphaMode::Opaque => true,
            AlphaMode::Mask { cutoff } => alpha >= cutoff,
            AlphaMode::Blend => {
                let h = hash_u32(
                    key ^ hash_u32(
                        ray.origin.x.to_bits() ^ hash_u32(ray.dir.y.to_bits() ^ hit.t.to_bits()),
                    ),
                );
                ((h >> 8) as f32 * (1.0 / 16_777_216.0)) < alpha
            }
        }
    }

    /// The shading point of `hit` along `ray`.
    pub fn interaction(&self, ray: &Ray, hit: &Hit) -> Interaction {
        let wo = -ray.dir.normalize();
        let (p, n_front, ns_front, attrs, material, tangents) = if hit.instance != NOT_PLACED {
            self.placed_surface(hit)
        } else {
            match self.prims[hit.prim as usize] {
                PrimRef::Triangle { mesh, tri } => {
                    self.triangle_surface(&self.meshes[mesh as usize], tri, hit)
                }
                PrimRef::Sphere(s) => {
                    let s = &self.spheres[s as usize];
                    // Back onto the sphere: the hit point along the ray carries t's rounding.
                    let n = (ray.at(hit.t) - s.centre).normalize_or(Vec3::Y);
                    (
                        s.centre + s.radius * n,
                        n,
                        n,
                        Self::shape_attributes(sphere::uv(n)),
                        s.material,
                        None,
                    )
                }
                PrimRef::Quadric(q) => {
                    let q = &self.quadrics[q as usize];
                    let (p, n) = q.quadric.surface(ray.at(hit.t));
                    let attrs = Self::shape_attributes(q.quadric.uv(p));
                    (p, n, n, attrs, q.material, None)
                }
            }
        };
        let front = n_front.dot(wo) > 0.0;
        let ng = if front { n_front } else { -n_front };
        // Onto the side the ray came from; normals that disagree with the winding are
        // taken as flipped.
        let mut ns = if front { ns_front } else { -ns_front };
        let mut flipped = !front;
        if ns.dot(ng) < 0.0 {
            ns = -ns;
            flipped = !flipped;
        }
        let ns = facing_shading_normal(ns, ng, wo);
        // A normal that is the geometric one never needs the reflection's correction.
        let ns = if ns == ng {
            ns
        } else {
            valid_reflection_normal(ns, ng, wo)
        };
        Interaction {
            p,
            ng,
            frame: Frame::from_normal(ns),
            attrs,
            prim: hit.prim,
            instance: hit.instance,
            material,
            front,
            tangents: tangents.map(|axes| if flipped { axes.map(|v| -v) } else { axes }),
        }
    }

    /// [`Surfaces::triangle_surface`] of a placed hit, moved from the shared mesh's object
    /// space into render space.
    fn placed_surface(&self, hit: &Hit) -> SurfacePoint {
        let placed = &self.placements[hit.instance as usize];
        let mesh = &self.shared_meshes[placed.mesh as usize];
        let (p, n, ns, attrs, material, tangents) = self.triangle_surface(mesh, hit.prim, hit);
        let n = (placed.normal_matrix * n).normalize_or_zero();
        let tangents = tangents.map(|[t, b, normal]| {
            let linear = |v: Vec3| placed.to_render.transform_vector3(v).normalize_or_zero();
            [
                linear(t),
                linear(b),
                (placed.normal_matrix * normal).normalize_or(n),
            ]
        });
        (
            placed.to_render.transform_point3(p),
            n,
            (placed.normal_matrix * ns).normalize_or(n),
            attrs,
            material,
            tangents,
        )
    }

    /// Position, front geometric normal, front shading normal (interpolated, then
    /// normal-mapped), attributes, material and tangent frame (where the mesh has tangents)
    /// of a triangle hit.
    fn triangle_surface(&self, mesh: &Mesh, tri: u32, hit: &Hit) -> SurfacePoint {
        let tri = mesh.triangles[tri as usize];
        let [p0, p1, p2] = tri.map(|i| mesh.positions[i as usize]);
        let (b1, b2) = (hit.b1, hit.b2);
        let b0 = 1.0 - b1 - b2;
        let p = p0 * b0 + p1 * b1 + p2 * b2;
        let n_front = geometric_normal(p0, p1, p2).normalize();
        let attrs = self.triangle_attributes(mesh, tri, b1, b2);
        let mat = &self.materials[mesh.material as usize];
        let [i0, i1, i2] = tri.map(|i| i as usize);
        let mut ns = mesh
            .normals
            .as_ref()
            .map(|n| (n[i0] * b0 + n[i1] * b1 + n[i2] * b2).normalize_or_zero())
            .filter(|n| *n != Vec3::ZERO)
            .unwrap_or(n_front);
        let mut frame = None;
        if let Some(tangents) = mesh.tangents.as_ref() {
            let t = (tangents[i0] * b0 + tangents[i1] * b1 + tangents[i2] * b2).truncate();
            let tangent_frame = Frame::from_normal_tangent(ns, t);
            let sign = if tangents[i0].w < 0.0 { -1.0 } else { 1.0 };
            frame = Some([tangent_frame.s, tangent_frame.t * sign, tangent_frame.n]);
            if let Some(ts_normal) = material::tangent_space_normal(mat, &self.textures, &attrs) {
                let mapped = tangent_frame.s * ts_normal.x
                    + tangent_frame.t * (sign * ts_normal.y)
                    + tangent_frame.n * ts_normal.z;
                ns = mapped.normalize_or(n_front);
            }
        }
        (p, n_front, ns, attrs, mesh.material, frame)
    }

    /// Radiance emitted from `it` back along the ray that found it (zero for the back of
    /// a one-sided emitter).
    #[inline]
    pub fn emitted(&self, it: &Interaction) -> Vec3 {
        let mat = &self.materials[it.material as usize];
        if !mat.is_emissive() || !(it.front || mat.double_sided) {
            return Vec3::ZERO;
        }
        material::emission(mat, &self.textures, &it.attrs)
    }

    /// The emitted radiance of primitive `prim` where its emission is not textured (then
    /// [`Surfaces::emission_at`] returns it at every point).
    #[inline]
    pub fn untextured_emission(&self, prim: u32) -> Option<Vec3> {
        let mat = &self.materials[self.material_of(prim) as usize];
        mat.emissive_texture.is_none().then_some(mat.emissive)
    }

    /// The material of primitive `prim`.
    #[inline]
    fn material_of(&self, prim: u32) -> u32 {
        match self.prims[prim as usize] {
            PrimRef::Triangle { mesh, .. } => self.meshes[mesh as usize].material,
            PrimRef::Sphere(s) => self.spheres[s as usize].material,
            PrimRef::Quadric(q) => self.quadrics[q as usize].material,
        }
    }

    /// Emitted radiance of primitive `prim` at surface coordinates `b` (for light samples,
    /// which already checked the side).
    #[inline]
    pub fn emission_at(&self, prim: u32, b: Vec2) -> Vec3 {
        self.untextured_emission(prim).unwrap_or_else(|| {
            let (mat, attrs) = self.material_at(prim, b);
            material::emission(mat, &self.textures, &attrs)
        })
    }
}

/// Bends a shading normal towards the geometric normal until the viewer is above its
/// hemisphere (cos > 0): interpolated and normal-mapped normals can face away from a
/// viewer the geometry faces, which would make the BSDF black or reflect into the surface.
#[inline]
fn facing_shading_normal(ns: Vec3, ng: Vec3, wo: Vec3) -> Vec3 {
    let a = ns.dot(wo);
    let b = ng.dot(wo);
    let target = (0.5 * b).min(0.01);
    if a >= target || b <= 0.0 {
        return ns;
    }
    let t = (target - a) / (b - a);
    (ns * (1.0 - t) + ng * t).normalize_or(ng)
}

/// The steepest a mirror reflection of `wo` about a shading normal may leave the geometric
/// surface: the threshold of [`valid_reflection_normal`] for a viewer at cos `iz` to it.
#[inline]
pub(crate) fn reflection_threshold(iz: f32) -> f32 {
    (0.9 * iz).min(0.01)
}

/// Tilts shading normal `ns` towards the geometric normal `ng` (in the plane of the two)
/// just enough that the mirror reflection of the viewer `wo` about it leaves the surface
/// at least at the threshold [`reflection_threshold`] (as steeply as the viewer arrives,
/// up to cos 0.01). Strongly tilted normal maps and coarse interpolated normals otherwise
/// reflect glossy and mirror lobes into the surface, where the path ends: black rims.
/// This is the correction of Keller et al., "The Iray Light Transport Simulation and
/// Rendering System" (2017), which Cycles applies to its BSDFs' normals too.
#[inline]
pub(crate) fn valid_reflection_normal(ns: Vec3, ng: Vec3, wo: Vec3) -> Vec3 {
    let iz = wo.dot(ng);
    let threshold = reflection_threshold(iz);
    let z0 = ns.dot(ng);
    if iz <= 0.0 || 2.0 * ns.dot(wo) * z0 - iz >= threshold {
        return ns;
    }
    // The tilt n = z ng + x X (X: the direction of ns's tangential part) whose reflection of
    // wo leaves at exactly the threshold solves 2 z (x ix + z iz) - iz = threshold; squared,
    // a quadratic in z².
    let Some(axis) = (ns - ng * z0).try_normalize() else {
        return ng;
    };
    let ix = wo.dot(axis);
    let a = ix * ix + iz * iz;
    let b = 2.0 * (a + iz * threshold);
    let c = (threshold + iz) * (threshold + iz);
    let root = (b * b - 4.0 * a * c).max(0.0).sqrt();
    // Of the roots that solve the unsquared equation, the least tilt away from ns; the
    // geometric normal (always valid) when rounding leaves none.
    let mut best = (f32::INFINITY, ng);
    for z2 in [0.25 * (b - root) / a, 0.25 * (b + root) / a] {
        let z = z2.clamp(0.0, 1.0).sqrt();
        let x = (1.0 - z * z).max(0.0).sqrt();
        let n = ng * z + axis * x;
        let leaves = 2.0 * n.dot(wo) * z - iz;
        if (leaves - threshold).abs() <= 1e-3 && z >= z0 && z < best.0 {
            best = (z, n);
        }
    }
    best.1.normalize_or(ng)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mirror reflections about the corrected normal leave the surface at least at the
    /// threshold, exactly at it where a correction was needed, and normals that need none
    /// are left alone.
    #[test]
    fn reflections_about_corrected_normals_leave_the_surface() {
        let ng = Vec3::Z;
        let mut rng = crate::sampling::pcg::Pcg32::new(5, 0);
        let mut corrected = 0;
        for _ in 0..20_000 {
            let d = |rng: &mut crate::sampling::pcg::Pcg32| {
                crate::sampling::warp::square_to_uniform_hemisphere(glam::Vec2::new(
                    rng.next_f32(),
                    rng.next_f32(),
                ))
            };
            let (ns, wo) = (d(&mut rng), d(&mut rng));
            let ns = facing_shading_normal(ns, ng, wo);
            let fixed = valid_reflection_normal(ns, ng, wo);
            let threshold = reflection_threshold(wo.z);
            let r = fixed * (2.0 * fixed.dot(wo)) - wo;
            assert!((fixed.length() - 1.0).abs() < 1e-4);
            assert!(r.z >= threshold - 2e-3, "ns {ns} wo {wo}: reflection {r}");
            let before = ns * (2.0 * ns.dot(wo)) - wo;
            if before.z >= threshold {
                assert_eq!(fixed, ns);
            } else {
                corrected += 1;
                assert!((r.z - threshold).abs() < 2e-3 || fixed == ng, "{r}");
                // The tilt only moves towards the geometric normal.
                assert!(fixed.z >= ns.z - 1e-5);
            }
        }
        assert!(corrected > 1000, "{corrected}");
    }

    #[test]
    fn render_space_is_centred_and_scaled_by_a_power_of_two() {
        let s = RenderSpace::from_bounds(
            DVec3::new(1e7, 1e7, 1e7),
            DVec3::new(1e7 + 0.5, 1e7 + 0.3, 1e7 + 0.1),
        );
        assert_eq!(s.scale, 4.0);
        let p = s.point(DVec3::new(1e7 + 0.5, 1e7, 1e7 + 0.05));
        assert!((p - Vec3::new(1.0, -0.6, 0.0)).length() < 1e-6, "{p}");
        assert!((s.to_world(p) - DVec3::new(1e7 + 0.5, 1e7, 1e7 + 0.05)).length() < 1e-7);
    }

    #[test]
    fn shading_normal_is_bent_to_face_the_viewer() {
        let ng = Vec3::Z;
        let ns = Vec3::new(0.9, 0.0, 0.1).normalize();
        let wo = Vec3::new(-0.8, 0.0, 0.6).normalize();
        assert!(ns.dot(wo) < 0.0);
        let fixed = facing_shading_normal(ns, ng, wo);
        assert!(fixed.dot(wo) > 0.0 && (fixed.length() - 1.0).abs() < 1e-5);
        assert_eq!(facing_shading_normal(ng, ng, wo), ng);
    }
}
