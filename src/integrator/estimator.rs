//! What the scalar kernel (`path`) and the packet kernel (`packet`) both run: the state a
//! path carries from vertex to vertex, the emitters a ray finds (surfaces that emit, the
//! environment and distant lights at infinity), light samples for next-event estimation,
//! the density light sampling gives a direction that BSDF sampling found (the other half of
//! every MIS weight), and ray counts.
//!
//! The rule: the two kernels are one estimator. The packet kernel performs the scalar
//! kernel's operations in its order, sample for sample, so the paths are the scalar
//! kernel's to the bit; every piece of the estimator they share lives here (or in the
//! BSDFs, lights and sampler both call), never as a second copy. A new technique lands in
//! the scalar kernel first; the render plan (`render::plan::Kernel::packet`) keeps the packet
//! kernel out of renders that use it until its lanes exist, and `tests/it/plan.rs` compares
//! the two kernels' images.

use super::media::Media;
use super::settings::Settings;
use crate::geometry::cone::RayCone;
use crate::geometry::ray::Ray;
use crate::light::learned::LightLearning;
use crate::light::{Light, LightSample};
use crate::material::PerLobe;
use crate::world::{Interaction, World};
use glam::{Vec2, Vec3};

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
#[derive(Clone, Copy, Debug)]
pub(crate) struct PathState {
    /// Throughput: product of BSDF weights and roulette or splitting factors so far.
    pub(crate) beta: Vec3,
    /// Scattering events so far.
    pub(crate) depth: u32,
    /// Surfaces the path has met so far (scattering events and filter crossings): the
    /// vertex whose random numbers the next surface takes. Equal to `depth` until a
    /// filter is crossed.
    pub(crate) vertex: u32,
    /// Sample-dimension namespace of this path (0: the main path; branches get their own).
    pub(crate) branch: u32,
    /// The vertex the current ray left: where light selection and light densities are
    /// evaluated for MIS when the ray finds an emitter.
    pub(crate) prev_p: Vec3,
    pub(crate) prev_n: Vec3,
    /// Density of the BSDF sample that led here times the BSDF sample count there, and
    /// whether it came from a delta lobe.
    pub(crate) prev_pdf: f32,
    pub(crate) prev_delta: bool,
    /// Shadow rays sent from the previous vertex (light sampling's sample count there).
    pub(crate) prev_nee_count: u32,
    /// Lobe shares of the first scattering event (once there was one, and if wanted).
    pub(crate) lobes: PerLobe,
    /// The volumes the path is inside.
    pub(crate) media: Media,
    /// Distance travelled through filters since the previous vertex (render space): the
    /// part of the way from `prev_p` to the next surface that light densities must add.
    pub(crate) crossed: f32,
    /// The current ray's cone, which sizes texture footprints (`world::footprint`).
    pub(crate) cone: RayCone,
    /// Whether the camera's first surface has been recorded (data layers, coverage): the
    /// first one that is not an interface around a medium, which the camera sees through.
    pub(crate) first_hit_recorded: bool,
    /// The shutter time of the camera ray: every ray of the path is traced at it.
    pub(crate) time: f32,
}

impl PathState {
    /// The state of a camera path whose ray starts at `origin` with cone `cone`.
    pub(crate) fn camera(origin: Vec3, cone: RayCone) -> Self {
        Self {
            beta: Vec3::ONE,
            depth: 0,
            vertex: 0,
            branch: 0,
            prev_p: origin,
            prev_n: Vec3::ZERO,
            prev_pdf: 0.0,
            prev_delta: true,
            prev_nee_count: 1,
            lobes: [Vec3::ZERO; 3],
            media: Media::default(),
            crossed: 0.0,
            cone,
            first_hit_recorded: false,
            time: 0.0,
        }
    }

    /// The state past a filter crossed (a smooth thin wall, an interface) after a ray of
    /// length `arrived`: no scattering event, so depth, lobe shares and the MIS state carry
    /// on; the next random numbers, the way travelled added to the light densities' distance,
    /// the ray cone widened to the crossing.
    #[inline]
    pub(crate) fn past_filter(&self, arrived: f32) -> Self {
        Self {
            vertex: self.vertex + 1,
            crossed: self.crossed + arrived,
            cone: RayCone {
                width: self.cone.width_at(arrived),
                ..self.cone
            },
            ..*self
        }
    }

    /// Density with which light sampling at the previous vertex (its shadow rays
    /// together) produces the direction towards emitter `e`, which BSDF sampling found: the
    /// other technique's density in its MIS weight (0 after a delta lobe, which light
    /// sampling cannot follow).
    #[inline]
    pub(crate) fn light_density(
        &self,
        world: &World,
        settings: &Settings,
        learned: Option<&LightLearning>,
        e: &Emitter,
    ) -> f32 {
        if self.prev_delta {
            return 0.0;
        }
        let lights = &world.lights;
        let select = match learned {
            Some(l) => l.probability(lights, e.light, self.prev_p, self.prev_n),
            None => lights.selection_probability(e.light, self.prev_p, self.prev_n),
        };
        let density = match &lights.lights[e.light] {
            Light::Environment => lights
                .environment
                .as_ref()
                .map_or(0.0, |env| env.pdf(e.dir)),
            l => l.pdf(
                self.prev_p,
                e.dir,
                e.dist + self.crossed,
                settings.light_sampling,
            ),
        };
        select * density * self.prev_nee_count as f32
    }
}

/// An emitter a path ran into: radiance towards the path, light index, and where.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Emitter {
    pub le: Vec3,
    pub light: usize,
    /// Direction of the ray that found it and the distance along it (infinite for the
    /// environment).
    pub dir: Vec3,
    pub dist: f32,
}

/// The emitters a ray that left the scene along `dir` finds: the environment and the
/// distant lights whose cone contains the direction.
#[inline]
pub(crate) fn emitters_at_infinity(world: &World, dir: Vec3, mut found: impl FnMut(Emitter)) {
    if let (Some(env), Some(index)) = (&world.lights.environment, world.lights.environment_index) {
        found(Emitter {
            le: env.radiance(dir),
            light: index as usize,
            dir,
            dist: f32::INFINITY,
        });
    }
    let cones = &world.lights.distant_cones;
    let dir = if cones.is_empty() {
        dir
    } else {
        dir.normalize()
    };
    for &index in cones {
        let le = world.lights.lights[index as usize].radiance_at_infinity(dir);
        if le != Vec3::ZERO {
            found(Emitter {
                le,
                light: index as usize,
                dir,
                dist: f32::INFINITY,
            });
        }
    }
}

/// The emitter the surface point `it`, found by `ray` at distance `t`, is, if it emits
/// towards the ray.
#[inline]
pub(crate) fn surface_emitter(
    world: &World,
    it: &Interaction,
    ray: &Ray,
    t: f32,
) -> Option<Emitter> {
    let le = world.surfaces.emitted(it);
    if le == Vec3::ZERO {
        return None;
    }
    world.light_index(it).map(|light| Emitter {
        le,
        light,
        dir: ray.dir,
        dist: t * ray.dir.length(),
    })
}

/// A light sample for shading point `it`: a light chosen with `u_select` (its index and
/// selection probability) and a point on it from `u_light`, its radiance including the
/// emitter's surface emission; `None` where it cannot contribute (no light, zero radiance,
/// or below a surface that does not transmit, `both_sides` false).
#[inline]
pub(crate) fn sample_light(
    world: &World,
    settings: &Settings,
    (learned, region): (Option<&LightLearning>, Option<u32>),
    it: &Interaction,
    (u_select, u_light): (f32, Vec2),
    both_sides: bool,
) -> Option<(usize, f32, LightSample)> {
    let (index, p_select) = select_light(world, learned, region, u_select, it.p, it.frame.n)?;
    let ng = if both_sides { None } else { Some(it.ng) };
    let ls = sample_chosen_light(world, settings, it.p, ng, index, u_light)?;
    Some((index, p_select, ls))
}

/// A light chosen with `u` for point `p` with normal `n` (ZERO in media): by learned
/// selection `learned` (in region `region` of `p`) if there is one, else by the light set's
/// own selection; its index and probability.
#[inline]
pub(crate) fn select_light(
    world: &World,
    learned: Option<&LightLearning>,
    region: Option<u32>,
    u: f32,
    p: Vec3,
    n: Vec3,
) -> Option<(usize, f32)> {
    match learned {
        Some(l) => l.select(&world.lights, u, p, n, region),
        None => world.lights.select(u, p, n),
    }
}

/// [`sample_light`]'s sample of light `index`, once chosen, from point `p`; with a
/// geometric normal `ng`, only above the surface.
#[inline(always)]
pub(crate) fn sample_chosen_light(
    world: &World,
    settings: &Settings,
    p: Vec3,
    ng: Option<Vec3>,
    index: usize,
    u_light: Vec2,
) -> Option<LightSample> {
    let lights = &world.lights;
    let mut ls = lights.lights[index].sample(
        p,
        lights.environment.as_ref(),
        settings.light_sampling,
        u_light,
    )?;
    if let Some((prim, b)) = ls.area_point {
        ls.radiance *= world.surfaces.emission_at(prim, b);
    }
    let useless = ls.radiance == Vec3::ZERO || ng.is_some_and(|ng| ls.wi.dot(ng) <= 0.0);
    (!useless).then_some(ls)
}
