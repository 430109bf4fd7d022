//! The render-ready scene: geometry moved into render space, the BVH, lights, the camera,
//! and what a hit point needs for shading.
//!
//! Render space is world space translated to the centre of the scene's bounds and scaled by
//! a power of two (exact in binary) so that the bounds fit in [-1, 1]. Both are applied in
//! double precision before rounding to f32, so a scene placed 1e7 units from the origin
//! renders like the same scene at the origin, and every absolute epsilon (ray offsets near
//! the origin) is relative to the scene's size.

use crate::camera::{self, Camera};
use crate::error::{Error, Result};
use crate::geometry::frame::Frame;
use crate::geometry::ray::Ray;
use crate::geometry::triangle::geometric_normal;
use crate::geometry::{ALPHA_TESTED, Bvh, CULL_BACK, Hit, Primitive, PrimitiveHit, sphere};
use crate::integrator::LightSelect;
use crate::light::environment::{Environment, EnvironmentMap};
use crate::light::{Light, LightSet, SphereLight, TriangleLight};
use crate::material::{self, SurfaceAttributes};
use crate::sampling::pcg::hash_u32;
use crate::scene::{self, AlphaMode, LightKind, Material, Mesh, Scene, Texture};
use glam::{DMat3, DMat4, DVec3, Vec2, Vec3, Vec4};

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
}

/// A sphere in render space.
#[derive(Clone, Copy, Debug)]
pub struct RenderSphere {
    pub centre: Vec3,
    pub radius: f32,
    pub material: u32,
}

/// What shading reads: meshes, spheres, materials, textures, and what each BVH primitive is.
#[derive(Clone, Debug)]
pub struct Surfaces {
    /// Every mesh instance, flattened into render space.
    pub meshes: Vec<Mesh>,
    pub spheres: Vec<RenderSphere>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    /// Primitive index (as given to the BVH) to what it is.
    pub prims: Vec<PrimRef>,
    /// Primitive index to the index of the light it is ([`NO_LIGHT`] for none); empty when
    /// nothing emits.
    pub prim_light: Vec<u32>,
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
    /// The BVH primitive hit.
    pub prim: u32,
    pub material: u32,
    /// True if the ray arrived on the primitive's front (counter-clockwise side, outside).
    pub front: bool,
}

/// The scene prepared for rendering.
pub struct World {
    pub bvh: Bvh,
    pub surfaces: Surfaces,
    pub lights: LightSet,
    pub camera: Camera,
    pub space: RenderSpace,
    /// Radius of the render-space bounding sphere around the origin.
    pub radius: f32,
    /// Seconds spent building the BVH.
    pub bvh_seconds: f64,
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

/// Mean emitted radiance of material `m` (the emissive texture's mean, if any).
fn mean_emission(m: &Material, textures: &[Texture]) -> Vec3 {
    m.emissive
        * m.emissive_texture.map_or(Vec3::ONE, |t| {
            textures[t.texture as usize].mean(true).truncate()
        })
}

/// Every primitive for the BVH with its intersection flags and scene reference.
fn primitives(
    meshes: &[Mesh],
    spheres: &[RenderSphere],
    materials: &[Material],
) -> (Vec<Primitive>, Vec<u8>, Vec<PrimRef>) {
    let flags_of = |m: &Material| {
        let mut f = 0;
        if !m.double_sided {
            f |= CULL_BACK;
        }
        if m.alpha_mode != AlphaMode::Opaque {
            f |= ALPHA_TESTED;
        }
        f
    };
    let count = meshes.iter().map(|m| m.triangles.len()).sum::<usize>() + spheres.len();
    let (mut prims, mut flags, mut refs) = (
        Vec::with_capacity(count),
        Vec::with_capacity(count),
        Vec::with_capacity(count),
    );
    for (mi, mesh) in meshes.iter().enumerate() {
        let f = flags_of(&materials[mesh.material as usize]);
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
        flags.push(flags_of(&materials[s.material as usize]));
        refs.push(PrimRef::Sphere(si as u32));
    }
    (prims, flags, refs)
}

/// The area lights: one per primitive whose material emits, and the primitive-to-light map.
fn area_lights(
    prims: &[Primitive],
    refs: &[PrimRef],
    surfaces_materials: &[Material],
    meshes: &[Mesh],
    spheres: &[RenderSphere],
    textures: &[Texture],
) -> (Vec<Light>, Vec<u32>) {
    let material_of = |r: &PrimRef| match *r {
        PrimRef::Triangle { mesh, .. } => meshes[mesh as usize].material,
        PrimRef::Sphere(s) => spheres[s as usize].material,
    };
    if !refs
        .iter()
        .any(|r| surfaces_materials[material_of(r) as usize].is_emissive())
    {
        return (Vec::new(), Vec::new());
    }
    let mut lights = Vec::new();
    let mut prim_light = vec![NO_LIGHT; prims.len()];
    for (i, (prim, r)) in prims.iter().zip(refs).enumerate() {
        let m = &surfaces_materials[material_of(r) as usize];
        if !m.is_emissive() {
            continue;
        }
        prim_light[i] = lights.len() as u32;
        let mean_radiance = mean_emission(m, textures);
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
                })
            }
            Primitive::Sphere { centre, radius } => Light::Sphere(SphereLight {
                prim: i as u32,
                centre,
                radius,
                two_sided: m.double_sided,
                mean_radiance,
            }),
        });
    }
    (lights, prim_light)
}

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
        scene: Scene,
        camera_name: Option<&str>,
        resolution: Option<(u32, u32)>,
        light_select: LightSelect,
    ) -> Result<Self> {
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
        let space = RenderSpace::from_bounds(lo, hi);
        let to_render = space.matrix();
        let meshes: Vec<Mesh> = scene
            .instances
            .iter()
            .map(|inst| {
                transform_mesh(
                    &scene.meshes[inst.mesh as usize],
                    &(to_render * inst.transform),
                )
            })
            .collect();
        let spheres: Vec<RenderSphere> = scene
            .spheres
            .iter()
            .map(|s| RenderSphere {
                centre: space.point(s.centre),
                radius: (s.radius * space.scale) as f32,
                material: s.material,
            })
            .collect();
        let radius = meshes
            .iter()
            .flat_map(|m| m.positions.iter().map(|p| p.length()))
            .chain(spheres.iter().map(|s| s.centre.length() + s.radius))
            .fold(0.0f32, f32::max);

        let (prims, flags, refs) = primitives(&meshes, &spheres, &scene.materials);
        let (mut lights, prim_light) = area_lights(
            &prims,
            &refs,
            &scene.materials,
            &meshes,
            &spheres,
            &scene.textures,
        );
        lights.extend(punctual_lights(&scene, &space));
        let bvh_start = std::time::Instant::now();
        let bvh = Bvh::build(&prims, &flags);
        let bvh_seconds = bvh_start.elapsed().as_secs_f64();
        drop(prims);

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
        let environment = build_environment(&scene);
        Ok(Self {
            bvh,
            lights: LightSet::new(lights, environment, radius.max(1e-6), light_select),
            surfaces: Surfaces {
                meshes,
                spheres,
                materials: scene.materials,
                textures: scene.textures,
                prims: refs,
                prim_light,
            },
            camera,
            space,
            radius,
            bvh_seconds,
        })
    }

    /// Closest surface along `ray`, honouring back-face culling and alpha.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.bvh
            .intersect(ray, |prim, hit| self.surfaces.alpha_passes(prim, hit, ray))
    }

    /// True if something blocks `ray` before `ray.tmax`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.bvh
            .occluded(ray, |prim, hit| self.surfaces.alpha_passes(prim, hit, ray))
    }

    /// The shading point of `hit` along `ray`.
    #[inline]
    pub fn interaction(&self, ray: &Ray, hit: &Hit) -> Interaction {
        self.surfaces.interaction(ray, hit)
    }

    /// Index of the light that primitive `prim` is, if it emits.
    #[inline]
    pub fn light_index(&self, prim: u32) -> Option<usize> {
        self.surfaces
            .prim_light
            .get(prim as usize)
            .filter(|&&l| l != NO_LIGHT)
            .map(|&l| l as usize)
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

    /// Attributes of a sphere point from its lat-long coordinates (both UV sets).
    #[inline]
    fn sphere_attributes(uv: Vec2) -> SurfaceAttributes {
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
                Self::sphere_attributes(b),
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
        }
    }

    /// Whether a hit on alpha-tested primitive `prim` counts: cut-outs compare alpha with
    /// the cutoff; blended surfaces are hit with probability alpha, decided by a hash of the
    /// ray so that the decision is deterministic.
    fn alpha_passes(&self, prim: u32, hit: &PrimitiveHit, ray: &Ray) -> bool {
        let (mat, attrs) = self.material_at(prim, self.coords(prim, hit, ray));
        let alpha = material::alpha(mat, &self.textures, &attrs);
        match mat.alpha_mode {
            AlphaMode::Opaque => true,
            AlphaMode::Mask { cutoff } => alpha >= cutoff,
            AlphaMode::Blend => {
                let h = hash_u32(
                    prim ^ hash_u32(
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
        let (p, n_front, ns_front, attrs, material) = match self.prims[hit.prim as usize] {
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
                    Self::sphere_attributes(sphere::uv(n)),
                    s.material,
                )
            }
        };
        let front = n_front.dot(wo) > 0.0;
        let ng = if front { n_front } else { -n_front };
        // Onto the side the ray came from; normals that disagree with the winding are
        // taken as flipped.
        let mut ns = if front { ns_front } else { -ns_front };
        if ns.dot(ng) < 0.0 {
            ns = -ns;
        }
        let ns = facing_shading_normal(ns, ng, wo);
        Interaction {
            p,
            ng,
            frame: Frame::from_normal(ns),
            attrs,
            prim: hit.prim,
            material,
            front,
        }
    }

    /// Position, front geometric normal, front shading normal (interpolated, then
    /// normal-mapped), attributes and material of a triangle hit.
    fn triangle_surface(
        &self,
        mesh: &Mesh,
        tri: u32,
        hit: &Hit,
    ) -> (Vec3, Vec3, Vec3, SurfaceAttributes, u32) {
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
        if let (Some(tangents), Some(ts_normal)) = (
            mesh.tangents.as_ref(),
            material::tangent_space_normal(mat, &self.textures, &attrs),
        ) {
            let t = (tangents[i0] * b0 + tangents[i1] * b1 + tangents[i2] * b2).truncate();
            let tangent_frame = Frame::from_normal_tangent(ns, t);
            let sign = if tangents[i0].w < 0.0 { -1.0 } else { 1.0 };
            let mapped = tangent_frame.s * ts_normal.x
                + tangent_frame.t * (sign * ts_normal.y)
                + tangent_frame.n * ts_normal.z;
            ns = mapped.normalize_or(n_front);
        }
        (p, n_front, ns, attrs, mesh.material)
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

    /// Emitted radiance of primitive `prim` at surface coordinates `b` (for light samples,
    /// which already checked the side).
    #[inline]
    pub fn emission_at(&self, prim: u32, b: Vec2) -> Vec3 {
        let (mat, attrs) = self.material_at(prim, b);
        if mat.emissive_texture.is_none() {
            return mat.emissive;
        }
        material::emission(mat, &self.textures, &attrs)
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

#[cfg(test)]
mod tests {
    use super::*;

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
