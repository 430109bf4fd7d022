//! The internal scene: the one representation every ingest path produces. World units,
//! right-handed, Y up (like glTF). Transforms are double precision so that a scene far from
//! the origin keeps its detail until [`crate::world`] moves it into render space.

pub mod features;
pub mod file;
pub mod grid;
pub mod material;
pub mod texture;
pub mod texture_cache;
pub mod udim;

use glam::{DMat4, DVec3, Vec2, Vec3, Vec4};
pub use grid::DensityGrid;
pub use material::{
    AlphaMode, Anisotropy, Blackbody, BsdfModel, DiffuseTransmission, EmissionField, Iridescence,
    Material, Reduced, Sheen, Specular, TextureRef, UvTransform, Volume,
};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
pub use texture::{MipChains, Texels, Texture, Wrap, share_mip_chains, udim_set};

/// A scene ready for [`crate::world::World::build`].
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// Where the scene came from (a path, or a name for built-in scenes).
    pub source: String,
    pub meshes: Vec<Mesh>,
    pub instances: Vec<Instance>,
    /// Analytic spheres (world space).
    pub spheres: Vec<Sphere>,
    /// Analytic disks (world space).
    pub disks: Vec<Disk>,
    /// Analytic open cylinders (world space).
    pub cylinders: Vec<Cylinder>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    /// Density grids of heterogeneous media (`Volume::density`).
    pub grids: Vec<DensityGrid>,
    pub lights: Vec<Light>,
    pub cameras: Vec<Camera>,
    pub environment: Option<Environment>,
    /// Light groups the scene declares (the `lg_<name>` AOVs).
    pub light_groups: Vec<LightGroup>,
    /// Problems that did not stop the import (unsupported features, repaired data).
    pub warnings: Vec<String>,
    /// The outputs the scene declares (USD render settings and products), used unless the
    /// command line names an output.
    pub render_settings: Option<RenderSettings>,
    /// Subdivision surfaces: each replaces its placeholder mesh (the cage, triangulated)
    /// when the world is built, refined to the level the camera needs.
    pub subdivision_surfaces: Vec<SubdivisionSurface>,
    /// A fixed refinement level for every subdivision surface (`--subdiv-level`); `None`
    /// chooses each surface's level by its size on screen.
    pub subdivision_level: Option<u32>,
    /// The interval the motion keys span (`Instance::motion`, `Camera::motion`), where the
    /// scene was read with one.
    pub shutter: Option<Shutter>,
}

/// The interval over which moving things have keys, in frames relative to the frame
/// (`open` < `close`), and whether the image is blurred over it: without blur the image is
/// the frame's instant, and the keys serve the motion and velocity layers alone.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Shutter {
    pub open: f64,
    pub close: f64,
    #[serde(default = "blurs")]
    pub blur: bool,
}

fn blurs() -> bool {
    true
}

impl Shutter {
    /// Frames from its opening to its closing.
    pub fn frames(&self) -> f64 {
        self.close - self.open
    }

    /// The shutter as the EXR header records it (`lucerna/shutter`): `OPEN,CLOSE` in frames,
    /// followed by ` without blur` where the image is the frame's instant.
    pub fn describe(&self) -> String {
        let blur = if self.blur { "" } else { " without blur" };
        format!("{},{}{blur}", self.open, self.close)
    }

    /// Where the frame lies in the shutter, as a shutter time (0 at its opening, 1 at its
    /// closing; outside that range for a shutter that does not contain the frame).
    pub fn frame_time(&self) -> f64 {
        -self.open / self.frames()
    }
}

/// A subdivision scheme (USD's subdivisionScheme; `none` meshes are plain meshes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SubdivisionScheme {
    CatmullClark,
    Loop,
    Bilinear,
}

/// What happens at a subdivision surface's boundary (USD's interpolateBoundary).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BoundaryInterpolation {
    /// Boundary edges are sharp, and so are boundary vertices of a single face (USD's
    /// default).
    EdgeAndCorner,
    /// Boundary edges are sharp; boundary vertices follow the boundary curve.
    EdgeOnly,
}

/// A subdivision surface's control cage and its sharp features, in the placeholder mesh's
/// space.
#[derive(Clone, Debug)]
pub struct SubdivisionSurface {
    /// The scene mesh this surface becomes (name and material are taken from it).
    pub mesh: u32,
    pub scheme: SubdivisionScheme,
    pub boundary: BoundaryInterpolation,
    pub points: Vec<Vec3>,
    /// Polygons: vertex counts, and their point indices counter-clockwise.
    pub face_counts: Vec<u32>,
    pub face_indices: Vec<u32>,
    /// Creased edges (point pairs) with their sharpness (10 and above: infinitely sharp).
    pub creases: Vec<([u32; 2], f32)>,
    /// Sharp vertices with their sharpness.
    pub corners: Vec<(u32, f32)>,
    /// Texture coordinates per face corner (in `face_indices` order).
    pub uvs: Option<Vec<Vec2>>,
    /// Colours per face corner.
    pub colors: Option<Vec<Vec4>>,
    /// Which faces are rendered (a material subset); all when `None`. The other faces
    /// still shape the surface.
    pub keep: Option<Vec<bool>>,
    /// The points at evenly spaced times of the shutter, where the cage changes shape over
    /// it (empty otherwise): each key is refined as `points` is, into the surface's
    /// deformation.
    pub point_keys: Vec<Vec<Vec3>>,
}

/// A scene's declared render: the settings prim it came from and its products.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RenderSettings {
    /// Where the settings came from (a USD RenderSettings prim path).
    pub path: String,
    /// The settings' own camera, size and pixel window: what a render without products
    /// (or with `--output`) takes where the command line gives none.
    #[serde(default)]
    pub camera: Option<String>,
    #[serde(default)]
    pub resolution: Option<[u32; 2]>,
    #[serde(default)]
    pub crop: Option<[u32; 4]>,
    /// Pixels `[left, top, right, bottom]` rendered beyond the image's edges (a data window
    /// beyond the display window).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overscan: Option<[u32; 4]>,
    pub products: Vec<RenderProduct>,
}

/// One output file of a declared render: what it sees, at what size, with which layers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderProduct {
    /// The file to write (frame tokens already expanded by the importer).
    pub output: String,
    /// The camera, by name; `None`: the scene's first.
    pub camera: Option<String>,
    /// Width and height in pixels; `None`: from the camera.
    pub resolution: Option<[u32; 2]>,
    /// Pixels `[x0, y0, x1, y1]` (ends excluded) of the image to render.
    pub crop: Option<[u32; 4]>,
    /// Pixels `[left, top, right, bottom]` rendered beyond the image's edges: with `crop`,
    /// the EXR's data window.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overscan: Option<[u32; 4]>,
    /// lucerna's AOV list (as `--aov` takes it) for this file's layers.
    pub aovs: String,
}

/// A light group: the emitters named in `members` (instances, analytic shapes, punctual
/// lights, `environment`), whose light goes to the `lg_<name>` AOV.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LightGroup {
    pub name: String,
    pub members: Vec<String>,
}

impl Scene {
    /// Whether anything lights the scene: a light, an environment, or an emissive surface
    /// or emitting medium some geometry uses.
    pub fn has_light(&self) -> bool {
        let emissive = |m: u32| {
            self.materials
                .get(m as usize)
                .is_some_and(|m| m.is_emissive() || m.volume.is_some_and(|v| v.emits()))
        };
        !self.lights.is_empty()
            || self.environment.is_some()
            || self
                .instances
                .iter()
                .any(|i| emissive(self.meshes[i.mesh as usize].material))
            || self.spheres.iter().any(|s| emissive(s.material))
            || self.disks.iter().any(|d| emissive(d.material))
            || self.cylinders.iter().any(|c| emissive(c.material))
    }

    /// Puts emitter `member` into light group `group`, creating the group.
    pub fn add_to_light_group(&mut self, group: &str, member: &str) {
        match self.light_groups.iter_mut().find(|g| g.name == group) {
            Some(g) => g.members.push(member.to_string()),
            None => self.light_groups.push(LightGroup {
                name: group.to_string(),
                members: vec![member.to_string()],
            }),
        }
    }
}

/// A triangle mesh in object space with one material.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub name: String,
    pub positions: Vec<Vec3>,
    /// Shading normals; `None` means flat shading with the geometric normal.
    pub normals: Option<Vec<Vec3>>,
    /// Tangents with the bitangent sign in w (glTF convention); present when a normal map
    /// needs them.
    pub tangents: Option<Vec<Vec4>>,
    /// Texture coordinate sets 0 and 1.
    pub uvs: [Option<Vec<Vec2>>; 2],
    /// Vertex colours (linear RGBA), multiplied into the base colour.
    pub colors: Option<Vec<Vec4>>,
    /// Counter-clockwise triangles (the front side faces the viewer).
    pub triangles: Vec<[u32; 3]>,
    pub material: u32,
    /// Positions (and normals) over the shutter of a mesh that changes shape while it is
    /// open; `positions` and `normals` are the frame's.
    pub deformation: Option<crate::geometry::deformation::Deformation>,
}

impl Mesh {
    /// Its material, where it is the same at every point of the mesh and does not emit: no
    /// texture (so no normal map either) and no vertex colours. The packet kernel computes
    /// such a mesh's shading points in lanes (`world::lanes`).
    pub fn uniform_material<'m>(&self, materials: &'m [Material]) -> Option<&'m Material> {
        let m = materials.get(self.material as usize)?;
        let textured = m.texture_slots().next().is_some();
        (!textured && self.colors.is_none() && !m.is_emissive()).then_some(m)
    }

    /// Bytes of its vertex and triangle data.
    pub fn data_bytes(&self) -> u64 {
        fn bytes<T>(v: &Option<Vec<T>>) -> usize {
            v.as_ref()
                .map_or(0, |v| std::mem::size_of_val(v.as_slice()))
        }
        (std::mem::size_of_val(self.positions.as_slice())
            + bytes(&self.normals)
            + bytes(&self.tangents)
            + self.uvs.iter().map(bytes).sum::<usize>()
            + bytes(&self.colors)
            + std::mem::size_of_val(self.triangles.as_slice())) as u64
            + self.deformation.as_ref().map_or(0, |d| d.bytes())
    }

    /// Object-space bounds of the vertices (at every key of a deformation too), or `None`
    /// for a mesh without any.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let keys = self
            .deformation
            .iter()
            .flat_map(|d| d.positions.iter().flatten());
        (!self.positions.is_empty()).then(|| {
            self.positions
                .iter()
                .chain(keys)
                .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(*p), hi.max(*p))
                })
        })
    }
}

/// A placement of a mesh in the world.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Instance {
    /// Name of the node or prim that placed it.
    pub name: String,
    pub mesh: u32,
    /// Object to world.
    pub transform: DMat4,
    /// Object to world over the shutter, at evenly spaced times from its opening to its
    /// closing (`geometry::motion`); empty where the instance does not move.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub motion: Vec<DMat4>,
}

/// An analytic sphere: exact silhouettes, and solid-angle sampling when it emits.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Sphere {
    pub name: String,
    pub centre: DVec3,
    pub radius: f64,
    pub material: u32,
}

/// An analytic disk, front towards `normal`: a disk light (UsdLux DiskLight) with an exact
/// outline and area.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Disk {
    pub name: String,
    pub centre: DVec3,
    /// Unit normal of the front side.
    pub normal: DVec3,
    pub radius: f64,
    pub material: u32,
}

/// An analytic open cylinder (no caps) around `axis` through `centre`, front outwards: a
/// cylinder light (UsdLux CylinderLight) with an exact shape and area.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Cylinder {
    pub name: String,
    pub centre: DVec3,
    /// Unit direction of the axis.
    pub axis: DVec3,
    pub radius: f64,
    /// Length along the axis (centred on `centre`).
    pub length: f64,
    pub material: u32,
}

/// A punctual light. Photometric glTF units are taken as radiometric ones (1 cd = 1 W/sr),
/// consistent with emissive surfaces whose emission is read as radiance.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Light {
    pub name: String,
    pub kind: LightKind,
}

/// The kinds of punctual light.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightKind {
    /// Radiant intensity `intensity` in every direction from `position`.
    Point { position: DVec3, intensity: Vec3 },
    /// A point light restricted to a cone around `direction` with the glTF
    /// (KHR_lights_punctual) smooth falloff between the cone angles.
    Spot {
        position: DVec3,
        direction: DVec3,
        intensity: Vec3,
        inner_cone: f32,
        outer_cone: f32,
    },
    /// Light from infinitely far away travelling along `direction`, with irradiance
    /// `irradiance` on a surface facing it. `angle` is the angular diameter of the source in
    /// radians (the sun: 0.0093): 0 is a parallel light with sharp shadows; a wider source
    /// has uniform radiance over that disc of directions and gives soft shadows.
    Directional {
        direction: DVec3,
        irradiance: Vec3,
        #[serde(default)]
        angle: f32,
    },
}

/// Light arriving from infinitely far away.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Environment {
    /// The same radiance from every direction.
    Constant(Vec3),
    /// A latitude-longitude radiance map (`texture`, linear) times `scale`. The image's
    /// top row is +Y, its centre column looks along -Z, u grows towards +X (see
    /// `light::environment`). `rotation` turns the map into the world.
    LatLong {
        texture: u32,
        scale: Vec3,
        rotation: DMat4,
    },
}

/// A camera: projection and placement (camera to world, looking down -Z, +Y up).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Camera {
    pub name: String,
    pub projection: Projection,
    pub transform: DMat4,
    /// Thin-lens aperture radius in world units (0: pinhole).
    pub aperture_radius: f64,
    /// Distance to the plane in focus, world units.
    pub focus_distance: f64,
    /// Near clipping distance along the viewing axis (world units): nothing closer is seen.
    pub clip_near: f64,
    /// Far clipping distance, if any.
    pub clip_far: Option<f64>,
    /// How the view fits an image whose aspect differs from the camera's.
    #[serde(default)]
    pub fit: CameraFit,
    /// Camera to world over the shutter, at evenly spaced times from its opening to its
    /// closing (`geometry::motion`); empty where the camera does not move.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub motion: Vec<DMat4>,
}

/// How a camera's view fits an image of another aspect ratio.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraFit {
    /// Keep the vertical field of view (glTF's rule).
    #[default]
    Vertical,
    /// Keep the whole aperture in view: the vertical field of view, or the horizontal one
    /// where the image is narrower than the aperture (USD's expandAperture, the default
    /// aspectRatioConformPolicy).
    ExpandAperture,
}

/// Camera projections.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Projection {
    /// Vertical field of view in radians and, if the scene gives one, width / height.
    Perspective { yfov: f32, aspect: Option<f32> },
    /// Half width and half height of the view volume in world units.
    Orthographic { xmag: f32, ymag: f32 },
}

impl Scene {
    /// Number of triangles over all instances.
    pub fn instanced_triangle_count(&self) -> usize {
        self.instances
            .iter()
            .map(|i| self.meshes[i.mesh as usize].triangles.len())
            .sum()
    }

    /// Bytes of its texels held in memory (shared texels once; tiled ones are the cache's).
    pub fn texel_bytes(&self) -> u64 {
        let mut seen = std::collections::HashSet::new();
        self.textures
            .iter()
            .filter(|t| seen.insert(Arc::as_ptr(&t.texels)))
            .map(|t| t.memory_bytes() as u64)
            .sum()
    }

    /// The tile cache its textures are read through, when they are too large to be held in
    /// memory (`texture_cache`).
    pub fn texture_cache(&self) -> Option<&Arc<texture_cache::TextureCache>> {
        texture::cache_of(&self.textures)
    }

    /// Bytes of its bulk data: meshes, texels (shared texels once; for tiled ones, the tile
    /// cache's capacity and the tiles each thread keeps), instances and shapes.
    pub fn data_bytes(&self) -> u64 {
        use std::mem::size_of;
        self.meshes.iter().map(Mesh::data_bytes).sum::<u64>()
            + self.texel_bytes()
            // Density grids and their majorants (a float per 8³ voxels).
            + self
                .grids
                .iter()
                .map(|g| g.values.len() as u64 * 4 * 513 / 512)
                .sum::<u64>()
            + self.texture_cache().map_or(0, |c| {
                c.capacity() + c.bytes_per_thread() * rayon::current_num_threads() as u64
            })
            + (self.instances.len() * size_of::<Instance>()
                + self.spheres.len() * size_of::<Sphere>()
                + self.disks.len() * size_of::<Disk>()
                + self.cylinders.len() * size_of::<Cylinder>()) as u64
    }

    /// World-space bounds of all instanced geometry and spheres, or `None` when there is
    /// none. A mesh placed once contributes its transformed vertices; a mesh placed several
    /// times contributes the transformed corners of its object-space box, so that the cost
    /// grows with the instance count, not with instances times vertices.
    pub fn bounds(&self) -> Option<(DVec3, DVec3)> {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        let mut uses = vec![0u32; self.meshes.len()];
        for inst in &self.instances {
            uses[inst.mesh as usize] += 1;
        }
        let object_boxes: Vec<Option<[DVec3; 8]>> = self
            .meshes
            .iter()
            .zip(&uses)
            .map(|(m, &uses)| {
                let (a, b) = m.bounds().filter(|_| uses >= 2)?;
                let (a, b) = (a.as_dvec3(), b.as_dvec3());
                Some(std::array::from_fn(|c| {
                    DVec3::new(
                        if c & 1 == 0 { a.x } else { b.x },
                        if c & 2 == 0 { a.y } else { b.y },
                        if c & 4 == 0 { a.z } else { b.z },
                    )
                }))
            })
            .collect();
        for inst in &self.instances {
            let mesh = inst.mesh as usize;
            let mut add = |p: DVec3| {
                let w = inst.transform.transform_point3(p);
                lo = lo.min(w);
                hi = hi.max(w);
            };
            match &object_boxes[mesh] {
                Some(corners) => corners.iter().for_each(|&c| add(c)),
                None => self.meshes[mesh]
                    .positions
                    .iter()
                    .for_each(|p| add(p.as_dvec3())),
            }
        }
        for s in &self.spheres {
            lo = lo.min(s.centre - s.radius);
            hi = hi.max(s.centre + s.radius);
        }
        // Disks and cylinders by their bounding spheres: a little loose, always enclosing.
        let shapes = self.disks.iter().map(|d| (d.centre, d.radius)).chain(
            self.cylinders
                .iter()
                .map(|c| (c.centre, c.radius.hypot(0.5 * c.length))),
        );
        for (centre, radius) in shapes {
            lo = lo.min(centre - radius);
            hi = hi.max(centre + radius);
        }
        (lo.x <= hi.x).then_some((lo, hi))
    }

    /// The same scene with a mesh of its own for every instance, so that the renderer
    /// flattens every placement into one BVH instead of sharing meshes placed several
    /// times: the reference that benchmarks and tests compare the two-level BVH with.
    pub fn unshared(mut self) -> Self {
        for i in 0..self.instances.len() {
            let mesh = self.meshes[self.instances[i].mesh as usize].clone();
            self.instances[i].mesh = self.meshes.len() as u32;
            self.meshes.push(mesh);
        }
        self
    }

    /// Finds a camera by name.
    pub fn camera(&self, name: &str) -> Option<&Camera> {
        self.cameras.iter().find(|c| c.name == name)
    }
}
