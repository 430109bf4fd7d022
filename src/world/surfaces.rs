//! What shading reads ([`Surfaces`]: meshes, shapes, materials, textures, and what each BVH
//! primitive is) and the shading point a hit becomes ([`Interaction`]): attributes
//! interpolated, shading normals corrected towards the viewer, alpha decided for traversal.

use super::footprint;
use crate::geometry::frame::Frame;
use crate::geometry::quadric::Quadric;
use crate::geometry::ray::Ray;
use crate::geometry::triangle::geometric_normal;
use crate::geometry::{Hit, NOT_PLACED, PrimitiveHit, sphere};
use crate::material::{self, SurfaceAttributes};
use crate::medium::Medium;
use crate::sampling::pcg::hash_u32;
use crate::scene::{AlphaMode, Material, Mesh, Texture};
use glam::{Affine3A, Mat3A, Vec2, Vec3, Vec4};

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
    /// Index into [`Surfaces::motions`] of a placement that moves over the shutter (its
    /// transforms then come from there at the ray's time), or `geometry::instances::STILL`.
    pub motion: u32,
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
    /// The moving placements' transforms over the shutter (object space to render space).
    pub motions: Vec<crate::geometry::motion::MotionTransform>,
    pub spheres: Vec<RenderSphere>,
    pub quadrics: Vec<RenderQuadric>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    /// Primitive index (as given to the BVH) to what it is.
    pub prims: Vec<PrimRef>,
    /// Primitive index to the index of the light it is ([`NO_LIGHT`] for none); empty when
    /// nothing emits.
    pub prim_light: Vec<u32>,
    /// By material, the medium inside its volume in render-space units (`None` for no
    /// volume, or a clear one).
    pub media: Vec<Option<Medium>>,
    /// True if some material bounds a participating medium
    /// ([`Material::bounds_participating_medium`]): paths sample free flights and shadow
    /// rays cross media only then.
    pub participating: bool,
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
    /// The largest coordinate (render space) of the data `p` was computed from: the
    /// primitive's corners, or a sphere's centre and radius. Its rounding error is relative
    /// to this, so rays leaving `p` are offset by it (`geometry::ray::offset_ray_origin`)
    /// rather than by the scene's size: a small object far from the scene's bounds keeps
    /// offsets as small as its own precision allows (subsurface walks of a millimetre's
    /// mean free path in a room-sized scene).
    pub magnitude: f32,
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

/// A ray's cone where it meets a surface: the ray's render-space direction, the cone's
/// width there, and whether its footprint is taken as a circle.
#[derive(Clone, Copy, Debug)]
struct Cone {
    dir: Vec3,
    width: f32,
    isotropic: bool,
}

/// What a surface hit yields before it is turned to the ray's side: point, front geometric
/// normal, front shading normal, attributes, material and tangent frame.
/// Position, front geometric normal, front shading normal, attributes, material, tangent
/// frame and the magnitude the position's rounding error is relative to.
type SurfacePoint = (
    Vec3,
    Vec3,
    Vec3,
    SurfaceAttributes,
    u32,
    Option<[Vec3; 3]>,
    f32,
);

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
            motions: Vec::new(),
            spheres: Vec::new(),
            quadrics: Vec::new(),
            materials,
            textures: Vec::new(),
            prims,
            prim_light: Vec::new(),
            media: Vec::new(),
            participating: false,
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
            footprint: [[Vec2::ZERO; 2]; 2],
        }
    }

    /// Attributes of a point of an analytic shape from its texture coordinates (both UV
    /// sets).
    #[inline]
    fn shape_attributes(uv: Vec2) -> SurfaceAttributes {
        SurfaceAttributes {
            uv: [uv, uv],
            color: Vec4::ONE,
            footprint: [[Vec2::ZERO; 2]; 2],
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
    pub(super) fn alpha_passes(&self, prim: u32, hit: &PrimitiveHit, ray: &Ray) -> bool {
        let (mat, attrs) = self.material_at(prim, self.coords(prim, hit, ray));
        self.alpha_decides(mat, &attrs, prim, hit, ray)
    }

    /// [`Surfaces::alpha_passes`] for a hit on triangle `prim` of placement `placement`,
    /// found along the object-space ray `ray`.
    pub(super) fn placed_alpha_passes(
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
    pub(super) fn blocks_shadow(
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
        match self.straight_transmission(&it, ray) {
            Some(straight) => {
                *through *= straight;
                *through == Vec3::ZERO
            }
            None => true,
        }
    }

    /// What crosses the surface at `it` in a straight line along `ray` (its filter's
    /// straight transmission); `None` where the material is no filter (light does not pass
    /// it unbent).
    pub fn straight_transmission(&self, it: &Interaction, ray: &Ray) -> Option<Vec3> {
        let m = &self.materials[it.material as usize];
        if !m.can_filter() {
            return None;
        }
        let mut storage = material::BsdfStorage::default();
        let ctx = it.shading_context(1.0);
        let bsdf = material::bsdf_in(m, &self.textures, &it.attrs, &ctx, &mut storage);
        Some(bsdf.straight_transmission(it.frame.to_local(-ray.dir.normalize())))
    }

    /// The medium (in render-space units) inside the volume of material `material`, where
    /// it absorbs or scatters.
    #[inline]
    pub fn medium(&self, material: u32) -> Option<&Medium> {
        self.media.get(material as usize).and_then(Option::as_ref)
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

    /// The shading point of `hit` along `ray`, its textures looked up at the point.
    pub fn interaction(&self, ray: &Ray, hit: &Hit) -> Interaction {
        self.interaction_in_cone(ray, hit, 0.0, false)
    }

    /// The shading point of `hit` along `ray`, whose cone is `width` wide there: the
    /// textures of triangles are filtered over the footprint (`world::footprint`; a circle
    /// with `isotropic`); those of spheres and quadrics are looked up at the point.
    pub fn interaction_in_cone(
        &self,
        ray: &Ray,
        hit: &Hit,
        width: f32,
        isotropic: bool,
    ) -> Interaction {
        let wo = -ray.dir.normalize();
        let cone = (width > 0.0).then_some(Cone {
            dir: -wo,
            width,
            isotropic,
        });
        let (p, n_front, ns_front, attrs, material, tangents, magnitude) =
            if hit.instance != NOT_PLACED {
                self.placed_surface(hit, cone, ray.time)
            } else {
                match self.prims[hit.prim as usize] {
                    PrimRef::Triangle { mesh, tri } => self.triangle_surface(
                        &self.meshes[mesh as usize],
                        tri,
                        hit,
                        cone,
                        None,
                        ray.time,
                    ),
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
                            s.centre.abs().max_element() + s.radius,
                        )
                    }
                    PrimRef::Quadric(q) => {
                        let q = &self.quadrics[q as usize];
                        let (p, n) = q.quadric.surface(ray.at(hit.t));
                        let attrs = Self::shape_attributes(q.quadric.uv(p));
                        // Quadrics keep the offsets relative to the scene's size.
                        (p, n, n, attrs, q.material, None, 1.0)
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
            magnitude,
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
    /// space into render space (where it is at shutter time `time`, if it moves).
    fn placed_surface(&self, hit: &Hit, cone: Option<Cone>, time: f32) -> SurfacePoint {
        let mut placed = &self.placements[hit.instance as usize];
        let moved;
        if placed.motion != crate::geometry::instances::STILL {
            // The transform traversal entered the placement with.
            let m = self.motions[placed.motion as usize].affine_at(time);
            moved = PlacedMesh {
                to_render: m,
                normal_matrix: m.matrix3.inverse().transpose(),
                ..*placed
            };
            placed = &moved;
        }
        let mesh = &self.shared_meshes[placed.mesh as usize];
        let (p, n, ns, attrs, material, tangents, magnitude) =
            self.triangle_surface(mesh, hit.prim, hit, cone, Some(&placed.to_render), time);
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
            magnitude,
        )
    }

    /// Position, front geometric normal, front shading normal (interpolated, then
    /// normal-mapped), attributes, material and tangent frame (where the mesh has tangents)
    /// of a triangle hit. With `cone` (the render-space ray direction and the cone's width),
    /// the attributes carry the footprint of each UV set; `to_render` places an object-space
    /// mesh. A mesh that deforms is taken where it is at shutter time `time`.
    fn triangle_surface(
        &self,
        mesh: &Mesh,
        tri: u32,
        hit: &Hit,
        cone: Option<Cone>,
        to_render: Option<&Affine3A>,
        time: f32,
    ) -> SurfacePoint {
        let tri = mesh.triangles[tri as usize];
        let ([p0, p1, p2], deformed_normals) = match &mesh.deformation {
            None => (tri.map(|i| mesh.positions[i as usize]), None),
            Some(d) => deformed_corners(d, tri, time),
        };
        // The corners in render space (where the placement moves them): the magnitude of
        // the point's data, and the footprint's triangle.
        let corners = match to_render {
            Some(m) => [p0, p1, p2].map(|p| m.transform_point3(p)),
            None => [p0, p1, p2],
        };
        let magnitude = corners
            .iter()
            .map(|c| c.abs().max_element())
            .fold(0.0f32, f32::max);
        let (b1, b2) = (hit.b1, hit.b2);
        let b0 = 1.0 - b1 - b2;
        let p = p0 * b0 + p1 * b1 + p2 * b2;
        let n_front = geometric_normal(p0, p1, p2).normalize();
        let mut attrs = self.triangle_attributes(mesh, tri, b1, b2);
        let mat = &self.materials[mesh.material as usize];
        let [i0, i1, i2] = tri.map(|i| i as usize);
        if let Some(cone) = cone {
            for (set, uvs) in mesh.uvs.iter().enumerate() {
                if let Some(uvs) = uvs {
                    let uv = [uvs[i0], uvs[i1], uvs[i2]];
                    attrs.footprint[set] = footprint::triangle_footprint(
                        corners,
                        uv,
                        cone.dir,
                        cone.width,
                        cone.isotropic,
                    );
                }
            }
        }
        let interpolated = match deformed_normals {
            Some(n) => Some((n[0] * b0 + n[1] * b1 + n[2] * b2).normalize_or_zero()),
            None => (mesh.normals.as_ref())
                .map(|n| (n[i0] * b0 + n[i1] * b1 + n[i2] * b2).normalize_or_zero()),
        };
        let mut ns = interpolated.filter(|n| *n != Vec3::ZERO).unwrap_or(n_front);
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
        (p, n_front, ns, attrs, mesh.material, frame, magnitude)
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
    #[inline(always)]
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

/// The corners of triangle `tri` of a mesh that deforms by `d`, and their shading normals
/// where it has them, at shutter time `time`. Out of line: still meshes never call it.
#[cold]
#[inline(never)]
fn deformed_corners(
    d: &crate::geometry::deformation::Deformation,
    tri: [u32; 3],
    time: f32,
) -> ([Vec3; 3], Option<[Vec3; 3]>) {
    d.triangle(tri, time)
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
