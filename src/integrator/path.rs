//! The path tracer: next-event estimation and BSDF sampling combined by MIS at every
//! vertex, Russian roulette, and a record of every contribution with its tags (path depth
//! and technique) so that the film can route it to each AOV that wants it.

use super::mis::Technique;
use super::{Settings, mis::Mis};
use crate::color::luminance;
use crate::geometry::ray::{Ray, offset_ray_origin};
use crate::light::Light;
use crate::material::{self, Bsdf};
use crate::sampling::sampler::{Sampler, VertexSample};
use crate::world::{Interaction, World};
use glam::Vec3;

/// Where a contribution came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// An emitter (or the environment) seen directly by the camera.
    Emission,
    /// Light sampling at a path vertex.
    Nee,
    /// A BSDF-sampled direction that hit an emitter (or escaped to the environment).
    Bsdf,
}

/// Radiance a path adds to its pixel, with its tags.
#[derive(Clone, Copy, Debug)]
pub struct Contribution {
    /// The MIS-weighted contribution (what the beauty receives).
    pub value: Vec3,
    /// Number of scattering events before the light arrived (0 for emission seen
    /// directly, 1 for direct illumination).
    pub depth: u32,
    pub source: Source,
    /// The same contribution weighted for light sampling alone and BSDF sampling alone
    /// (each the unbiased single-technique estimator), when the recorder asks for them.
    pub single_technique: Option<[Vec3; 2]>,
}

/// What the camera ray saw first: the data AOVs.
#[derive(Clone, Copy, Debug)]
pub struct FirstHit {
    pub albedo: Vec3,
    /// World-space shading normal, facing the camera.
    pub normal: Vec3,
    /// Distance along the camera's viewing axis, world units.
    pub depth: f32,
    /// World-space position.
    pub position: Vec3,
}

/// Receives what a path produces.
pub trait Recorder {
    /// Whether to compute [`Contribution::single_technique`] for direct light.
    fn wants_single_technique(&self) -> bool;
    fn contribution(&mut self, c: Contribution);
    fn first_hit(&mut self, hit: FirstHit);
}

/// Ray counts of one or more paths.
#[derive(Clone, Copy, Debug, Default)]
pub struct RayCounts {
    /// Camera and continuation rays (closest hit).
    pub closest: u64,
    /// Shadow rays (any hit).
    pub shadow: u64,
}

impl RayCounts {
    /// Adds another count.
    pub fn add(&mut self, o: &RayCounts) {
        self.closest += o.closest;
        self.shadow += o.shadow;
    }
}

/// The state a path carries from vertex to vertex.
struct PathState {
    /// Throughput: product of BSDF weights and roulette compensations so far.
    beta: Vec3,
    /// Scattering events so far.
    depth: u32,
    /// Density of the BSDF sample that led to the current vertex, and whether it came from
    /// a delta lobe.
    prev_pdf: f32,
    prev_delta: bool,
}

impl PathState {
    /// The path reached an emitter of radiance `le`: seen directly by the camera, or found
    /// by BSDF sampling, weighted against light sampling's density `light_pdf` (unless a
    /// delta lobe led here, which light sampling cannot follow).
    #[inline]
    fn reached_emitter<R: Recorder>(
        &self,
        rec: &mut R,
        mis: Mis,
        le: Vec3,
        light_pdf: impl FnOnce() -> f32,
        single: bool,
    ) {
        if self.depth == 0 {
            rec.contribution(Contribution {
                value: self.beta * le,
                depth: 0,
                source: Source::Emission,
                single_technique: None,
            });
        } else {
            let p_light = if self.prev_delta { 0.0 } else { light_pdf() };
            record(
                rec,
                mis,
                Technique::Bsdf,
                self.beta * le,
                self.depth,
                self.prev_pdf,
                p_light,
                single,
            );
        }
    }
}

/// The path tracer over a world with given settings.
pub struct PathTracer<'a> {
    world: &'a World,
    settings: &'a Settings,
}

impl<'a> PathTracer<'a> {
    /// A path tracer for `world`.
    pub fn new(world: &'a World, settings: &'a Settings) -> Self {
        Self { world, settings }
    }

    /// Traces the path of camera ray `ray` using `sampler`'s current pixel sample.
    pub fn trace<R: Recorder>(
        &self,
        mut ray: Ray,
        sampler: &mut Sampler,
        rec: &mut R,
        rays: &mut RayCounts,
    ) {
        let world = self.world;
        let mis = self.settings.mis;
        let max_depth = self.settings.max_depth.unwrap_or(u32::MAX);
        let single = rec.wants_single_technique();
        let mut path = PathState {
            beta: Vec3::ONE,
            depth: 0,
            prev_pdf: 0.0,
            prev_delta: true,
        };
        loop {
            rays.closest += 1;
            let Some(hit) = world.intersect(&ray) else {
                if let (Some(env), Some(index)) =
                    (&world.lights.environment, world.lights.environment_index)
                {
                    let light_pdf =
                        || world.lights.selection_probability(index as usize) * env.pdf(ray.dir);
                    path.reached_emitter(rec, mis, env.radiance(ray.dir), light_pdf, single);
                }
                return;
            };
            let it = world.interaction(&ray, &hit);
            let le = world.surfaces.emitted(&it);
            if le != Vec3::ZERO
                && let Some(index) = world.light_index(it.mesh, it.tri)
            {
                let Light::Triangle(tri) = &world.lights.lights[index] else {
                    unreachable!("emissive triangles map to triangle lights")
                };
                let light_pdf =
                    || world.lights.selection_probability(index) * tri.pdf(ray.dir, hit.t);
                path.reached_emitter(rec, mis, le, light_pdf, single);
            }
            if path.depth >= max_depth {
                return;
            }
            let surfaces = &world.surfaces;
            let bsdf = material::bsdf(
                &surfaces.materials[it.material as usize],
                &surfaces.textures,
                &it.attrs,
            );
            let wo = it.frame.to_local(-ray.dir);
            if path.depth == 0 {
                rec.first_hit(FirstHit {
                    albedo: bsdf.albedo(wo),
                    normal: it.frame.n,
                    depth: world.camera.depth(it.p),
                    position: world.space.to_world(it.p).as_vec3(),
                });
            }
            let vs = sampler.vertex(path.depth);
            if bsdf.has_non_delta() && !world.lights.is_empty() {
                rays.shadow +=
                    self.next_event(&it, &bsdf, wo, path.beta, path.depth + 1, &vs, rec, single);
            }

            let Some(bs) = bsdf.sample(wo, vs.lobe, vs.bsdf) else {
                return;
            };
            let wi = it.frame.to_world(bs.wi);
            // Reflection must leave on the side of the surface the path arrived from.
            if wi.dot(it.ng) <= 0.0 {
                return;
            }
            path.beta *= bs.weight;
            path.prev_pdf = bs.pdf;
            path.prev_delta = bs.is_delta();
            path.depth += 1;

            let survival = self.settings.rr.survival(luminance(path.beta), path.depth);
            if survival < 1.0 {
                if !(vs.rr < survival) {
                    return;
                }
                path.beta /= survival;
            }
            if !(path.beta.max_element() > 0.0) {
                return;
            }
            ray = Ray::new(offset_ray_origin(it.p, it.ng), wi);
        }
    }

    /// Light sampling at `it`: one light chosen by power, one point on it, one shadow ray.
    /// Returns the number of shadow rays traced.
    #[allow(clippy::too_many_arguments)]
    fn next_event<R: Recorder>(
        &self,
        it: &Interaction,
        bsdf: &Bsdf,
        wo: Vec3,
        beta: Vec3,
        depth: u32,
        vs: &VertexSample,
        rec: &mut R,
        single: bool,
    ) -> u64 {
        let world = self.world;
        let lights = &world.lights;
        let Some((index, p_select)) = lights.select(vs.light_select) else {
            return 0;
        };
        let Some(ls) = lights.lights[index].sample(it.p, lights.environment.as_ref(), vs.light)
        else {
            return 0;
        };
        let mut radiance = ls.radiance;
        if let Some((mesh, tri, b)) = ls.area_point {
            radiance *= world.surfaces.emission_at(mesh, tri, b);
        }
        if radiance == Vec3::ZERO || ls.wi.dot(it.ng) <= 0.0 {
            return 0;
        }
        let wi = it.frame.to_local(ls.wi);
        let f = bsdf.eval(wo, wi);
        if f == Vec3::ZERO {
            return 0;
        }
        let origin = offset_ray_origin(it.p, it.ng);
        let shadow = match ls.target {
            Some(target) => Ray {
                origin,
                dir: target - origin,
                tmax: 1.0,
            },
            None => Ray::new(origin, ls.wi),
        };
        if world.occluded(&shadow) {
            return 1;
        }
        let p_light = p_select * ls.pdf;
        // BSDF sampling cannot reach a delta light: its density there is 0.
        let p_bsdf = if ls.delta { 0.0 } else { bsdf.pdf(wo, wi) };
        let value = beta * f * radiance / p_light;
        record(
            rec,
            self.settings.mis,
            Technique::Nee,
            value,
            depth,
            p_light,
            p_bsdf,
            single,
        );
        1
    }
}

/// Records `value`, found by `technique` with density `own`, where the other technique's
/// density is `other` (0 where it cannot produce the path: delta lights, delta lobes, so
/// that every heuristic gives weight 1 there).
#[allow(clippy::too_many_arguments)]
#[inline]
fn record<R: Recorder>(
    rec: &mut R,
    mis: Mis,
    technique: Technique,
    value: Vec3,
    depth: u32,
    own: f32,
    other: f32,
    single: bool,
) {
    let weight = |h: Mis| h.weight(technique, own, other);
    rec.contribution(Contribution {
        value: value * weight(mis),
        depth,
        source: match technique {
            Technique::Nee => Source::Nee,
            Technique::Bsdf => Source::Bsdf,
        },
        single_technique: (single && depth == 1)
            .then(|| [value * weight(Mis::NeeOnly), value * weight(Mis::BsdfOnly)]),
    });
}
