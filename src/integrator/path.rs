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
        let mut beta = Vec3::ONE;
        let mut depth = 0u32;
        // Density of the BSDF sample that led here, and whether it was a delta lobe.
        let mut prev_pdf = 0.0f32;
        let mut prev_delta = true;
        loop {
            rays.closest += 1;
            let Some(hit) = world.intersect(&ray) else {
                if let (Some(env), Some(index)) =
                    (&world.lights.environment, world.lights.environment_index)
                {
                    let le = env.radiance(ray.dir);
                    if depth == 0 {
                        emit(rec, beta * le);
                    } else {
                        let p_light =
                            world.lights.selection_probability(index as usize) * env.pdf(ray.dir);
                        bsdf_hit(
                            rec,
                            mis,
                            beta * le,
                            depth,
                            prev_pdf,
                            prev_delta,
                            p_light,
                            single,
                        );
                    }
                }
                return;
            };
            let it = world.interaction(&ray, &hit);
            let le = world.surfaces.emitted(&it);
            if le != Vec3::ZERO {
                if depth == 0 {
                    emit(rec, beta * le);
                } else if let Some(index) = world.light_index(it.mesh, it.tri) {
                    let Light::Triangle(tri) = &world.lights.lights[index] else {
                        unreachable!("emissive triangles map to triangle lights")
                    };
                    let p_light =
                        world.lights.selection_probability(index) * tri.pdf(ray.dir, hit.t);
                    bsdf_hit(
                        rec,
                        mis,
                        beta * le,
                        depth,
                        prev_pdf,
                        prev_delta,
                        p_light,
                        single,
                    );
                }
            }
            if depth >= max_depth {
                return;
            }
            let surfaces = &world.surfaces;
            let bsdf = material::bsdf(
                &surfaces.materials[it.material as usize],
                &surfaces.textures,
                &it.attrs,
            );
            let wo = it.frame.to_local(-ray.dir);
            if depth == 0 {
                rec.first_hit(FirstHit {
                    albedo: bsdf.albedo(wo),
                    normal: it.frame.n,
                    depth: world.camera.depth(it.p),
                    position: world.space.to_world(it.p).as_vec3(),
                });
            }
            let vs = sampler.vertex(depth);
            if bsdf.has_non_delta() && !world.lights.is_empty() {
                rays.shadow += self.next_event(&it, &bsdf, wo, beta, depth + 1, &vs, rec, single);
            }

            let Some(bs) = bsdf.sample(wo, vs.lobe, vs.bsdf) else {
                return;
            };
            let wi = it.frame.to_world(bs.wi);
            // Reflection must leave on the side of the surface the path arrived from.
            if wi.dot(it.ng) <= 0.0 {
                return;
            }
            beta *= bs.weight;
            prev_pdf = bs.pdf;
            prev_delta = bs.is_delta();
            depth += 1;

            let survival = self.settings.rr.survival(luminance(beta), depth);
            if survival < 1.0 {
                if !(vs.rr < survival) {
                    return;
                }
                beta /= survival;
            }
            if !(beta.max_element() > 0.0) {
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
        let value = beta * f * radiance / p_light;
        let (weight, single_weights) = if ls.delta {
            (1.0, [1.0, 1.0])
        } else {
            let p_bsdf = bsdf.pdf(wo, wi);
            let mis = self.settings.mis;
            (
                mis.weight(Technique::Nee, p_light, p_bsdf),
                [
                    Mis::NeeOnly.weight(Technique::Nee, p_light, p_bsdf),
                    Mis::BsdfOnly.weight(Technique::Nee, p_light, p_bsdf),
                ],
            )
        };
        rec.contribution(Contribution {
            value: value * weight,
            depth,
            source: Source::Nee,
            single_technique: (single && depth == 1).then(|| single_weights.map(|w| value * w)),
        });
        1
    }
}

/// Emission seen directly by the camera.
#[inline]
fn emit<R: Recorder>(rec: &mut R, value: Vec3) {
    rec.contribution(Contribution {
        value,
        depth: 0,
        source: Source::Emission,
        single_technique: None,
    });
}

/// A BSDF-sampled direction reached an emitter whose light-sampling density is `p_light`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn bsdf_hit<R: Recorder>(
    rec: &mut R,
    mis: Mis,
    value: Vec3,
    depth: u32,
    prev_pdf: f32,
    prev_delta: bool,
    p_light: f32,
    single: bool,
) {
    let (weight, single_weights) = if prev_delta {
        (1.0, [1.0, 1.0])
    } else {
        (
            mis.weight(Technique::Bsdf, prev_pdf, p_light),
            [
                Mis::NeeOnly.weight(Technique::Bsdf, prev_pdf, p_light),
                Mis::BsdfOnly.weight(Technique::Bsdf, prev_pdf, p_light),
            ],
        )
    };
    rec.contribution(Contribution {
        value: value * weight,
        depth,
        source: Source::Bsdf,
        single_technique: (single && depth == 1).then(|| single_weights.map(|w| value * w)),
    });
}
