//! The render-ready scene: geometry moved into render space (`geometry::space`), the BVH
//! over it, the lights, the camera, and what a hit point needs for shading.
//!
//! [`World`] answers the ray queries of both kernels (closest hit, occlusion, transmittance
//! through filters, in lanes too) and names what a hit belongs to (objects, lights). It is
//! built from a scene by `build` (render space, BVHs, lights, the memory estimate made
//! before any of it is allocated; `placed` decides which meshes are placed through the
//! top-level BVH and gathers them); `surfaces` holds what shading reads and turns a hit into
//! a shading point; `lanes` does so for eight hits at a time.

pub mod build;
pub mod footprint;
pub(crate) mod lanes;
mod placed;
pub mod surfaces;

use crate::camera::Camera;
use crate::geometry::instances::InstancedBvh;
use crate::geometry::ray::Ray;
#[cfg(target_arch = "x86_64")]
use crate::geometry::ray::RayLanes;
use crate::geometry::space::RenderSpace;
use crate::geometry::{Bvh, Hit, NOT_PLACED};
use crate::light::LightSet;
use crate::scene::features::SceneFeatures;
use glam::Vec3;
pub use surfaces::{Interaction, NO_LIGHT, PlacedMesh, PrimRef, Surfaces};

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
    /// How paths size their texture footprints (off until a render sets them:
    /// [`World::set_footprints`]).
    pub footprints: footprint::Footprints,
    /// The interval the motion keys span and whether the image blurs over it.
    pub shutter: Option<crate::scene::Shutter>,
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

impl World {
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

    /// Sizes texture footprints for a render of `spp` samples per pixel (`None`: many), or
    /// turns them off (`filter` false, or a scene without textures, where they would cost
    /// without changing a pixel).
    pub fn set_footprints(&mut self, filter: bool, spp: Option<u32>) {
        self.footprints = if filter && !self.surfaces.textures.is_empty() {
            footprint::Footprints::for_samples(self.camera.pixel_cone(), spp)
        } else {
            footprint::Footprints::OFF
        };
        if self.footprints.on() {
            self.build_mips();
        }
    }

    /// Builds the MIP pyramids the materials read (each image once per way it is read:
    /// colour slots sRGB-decode integer texels, the others do not), in parallel for images
    /// in memory.
    fn build_mips(&self) {
        use rayon::prelude::*;
        let textures = &self.surfaces.textures;
        let mut wanted: Vec<(usize, bool)> = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for m in &self.surfaces.materials {
            for (name, slot) in m.texture_slots() {
                let Some(t) = textures.get(slot.texture as usize) else {
                    continue;
                };
                let srgb = crate::scene::Material::is_colour_slot(name);
                if seen.insert((std::sync::Arc::as_ptr(&t.mips), srgb)) {
                    wanted.push((slot.texture as usize, srgb));
                }
            }
        }
        // Images in tiled files are read back whole to build their levels: one at a time,
        // so that no more than one is in memory.
        let (tiled, in_memory): (Vec<_>, Vec<_>) = wanted
            .into_iter()
            .partition(|&(t, _)| textures[t].is_tiled());
        in_memory
            .par_iter()
            .for_each(|&(t, srgb)| textures[t].build_mips(srgb));
        for (t, srgb) in tiled {
            textures[t].build_mips(srgb);
        }
    }

    /// How shading point `it`, met at shutter time `time`, moves while the shutter is
    /// open: on screen in pixels a frame (u right, v up: Nuke's motion vectors) and in the
    /// world in units a frame, from the shutter's opening to its closing (the point carried
    /// by its placement's motion, seen by the camera where it is then). Zero without a
    /// shutter, and on screen for a point behind the camera at either end.
    pub fn motion_of(&self, it: &Interaction, time: f32) -> (glam::Vec2, Vec3) {
        let Some(shutter) = self.shutter else {
            return (glam::Vec2::ZERO, Vec3::ZERO);
        };
        let moving = (it.instance != NOT_PLACED)
            .then(|| self.surfaces.placements[it.instance as usize].motion)
            .filter(|&m| m != crate::geometry::instances::STILL)
            .map(|m| &self.surfaces.motions[m as usize]);
        let (open, close) = match moving {
            Some(motion) => {
                let object = motion.at(time).inverse().transform_point3(it.p.as_dvec3());
                (
                    motion.at(0.0).transform_point3(object).as_vec3(),
                    motion.at(1.0).transform_point3(object).as_vec3(),
                )
            }
            None => self.deformed_ends(it, time).unwrap_or((it.p, it.p)),
        };
        let frames = shutter.frames();
        let velocity =
            ((self.space.to_world(close) - self.space.to_world(open)) / frames).as_vec3();
        let screen = match (
            self.camera.film_position_at(open, 0.0),
            self.camera.film_position_at(close, 1.0),
        ) {
            (Some(a), Some(b)) => {
                let d = (b - a) / frames as f32;
                // Film y grows downwards; Nuke's v upwards.
                glam::Vec2::new(d.x, -d.y)
            }
            _ => glam::Vec2::ZERO,
        };
        (screen, velocity)
    }

    /// Where shading point `it` of a deforming mesh, met at shutter time `time`, is at the
    /// shutter's opening and closing: the same barycentrics on its triangle then. `None`
    /// for a point of a mesh that keeps its shape.
    fn deformed_ends(&self, it: &Interaction, time: f32) -> Option<(Vec3, Vec3)> {
        if it.instance != NOT_PLACED {
            return None;
        }
        let PrimRef::Triangle { mesh, tri } = self.surfaces.prims[it.prim as usize] else {
            return None;
        };
        let mesh = &self.surfaces.meshes[mesh as usize];
        let d = mesh.deformation.as_ref()?;
        let corners = mesh.triangles[tri as usize];
        let ([a, b, c], _) = d.triangle(corners, time);
        // Barycentrics of the point from the areas it spans with the edges.
        let n = (b - a).cross(c - a);
        let area = n.length_squared();
        if !(area > 0.0) {
            return None;
        }
        let b1 = (it.p - a).cross(c - a).dot(n) / area;
        let b2 = (b - a).cross(it.p - a).dot(n) / area;
        let at = |time: f32| {
            let ([a, b, c], _) = d.triangle(corners, time);
            a * (1.0 - b1 - b2) + b * b1 + c * b2
        };
        Some((at(0.0), at(1.0)))
    }

    /// The shading point of `hit` along `ray`, its textures looked up at the point.
    #[inline]
    pub fn interaction(&self, ray: &Ray, hit: &Hit) -> Interaction {
        self.surfaces.interaction(ray, hit)
    }

    /// The shading point of `hit` along `ray`, whose cone is `width` wide there (textures
    /// filtered over its footprint; a circle with `isotropic`).
    #[inline]
    pub fn interaction_in_cone(
        &self,
        ray: &Ray,
        hit: &Hit,
        width: f32,
        isotropic: bool,
    ) -> Interaction {
        self.surfaces
            .interaction_in_cone(ray, hit, width, isotropic)
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
