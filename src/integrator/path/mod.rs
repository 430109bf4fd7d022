//! The path tracer: next-event estimation and BSDF sampling combined by MIS at every
//! vertex, splitting at the first vertex, Russian roulette, and a record of every
//! contribution with its tags (path depth and technique) so that the film can route it to
//! each AOV that wants it.
//!
//! With `split nee=N,bsdf=M`, the first vertex seen from the camera sends N shadow rays and
//! M BSDF samples, each BSDF sample continuing as its own path; the MIS weights there use
//! the densities times the sample counts (N p_light against M p_bsdf), and each estimate is
//! divided by its count, which keeps the combination unbiased (Veach & Guibas 1995).
//!
//! Past each vertex's light sample, the continuation is decided once: the first vertex's
//! split, efficiency-aware roulette and splitting (`ears`) where its statistics know the
//! place, or the configured Russian roulette.
//!
//! Transmission: light samples at a surface that transmits are taken on both sides of it
//! (each from the side its shadow ray leaves, and only where the geometric and shading
//! normals agree on the side, so that no light leaks through a surface); a path that
//! refracts enters or leaves a volume (`media`), whose absorption weighs every segment it
//! travels inside; where the volume's medium scatters, the path may scatter inside it
//! before it reaches the next surface (`medium`: free flights, light samples and phase
//! sampling at medium vertices). Interfaces around media are filters that enter or leave
//! their medium when crossed, and the camera sees through them (its first surface, for
//! data layers and coverage, is the first that is not an interface). Shadow rays stop at glass, except at filters: a smooth thin wall's
//! straight-through transmission (a window pane) does not bend light, so a shadow ray can
//! cross it exactly, carrying its transmittance (`World::transmittance`). For the two
//! estimators of light through a filter to agree, a path that crosses a filter by its
//! straight lobe does not scatter there: its depth, lobe shares and MIS state (the previous
//! vertex, its densities) carry on, and the light it then finds is weighed by MIS against
//! the previous vertex's light samples, which crossed the same filter. It still takes new
//! random numbers (`PathState::vertex`).

mod light_sample;
mod medium;

use super::ears::{self, Ears, Learning, MAX_BRANCHES};
use super::estimator::{Emitter, PathState, RayCounts, emitters_at_infinity, surface_emitter};
use super::guiding::mixture::guided_sample;
use super::guiding::record::PathRecords;
use super::guiding::sdtree::Cell;
use super::guiding::{Distribution, GUIDE_PROBABILITY, Guide};
use super::media::Media;
use super::mis::{Mis, Technique};
use super::roulette::RussianRoulette;
use super::settings::Settings;
use super::split::{FirstSplit, SampleParts, SamplePoints};
use crate::color::luminance;
use crate::film::record::{Contribution, FirstHit, Recorder, Source};
use crate::geometry::Hit;
use crate::geometry::ray::{Ray, offset_past, offset_ray_origin_within};
use crate::light::learned::{LightLearning, LightRecords};
use crate::material::{self, Bsdf, BsdfStorage, Lobe, PerLobe};
use crate::medium::Medium;
use crate::sampling::sampler::{Sampler, SplitKind, VertexSample};
use crate::scene::{BsdfModel, Material};
use crate::world::{Interaction, World};
use glam::{Vec2, Vec3};

/// State of one pixel sample's walk through the scene: fixed choices and bookkeeping.
struct Walk<'l, 'g> {
    mis: Mis,
    single: bool,
    /// Whether contributions carry their lobe shares.
    lobes: bool,
    pixel: usize,
    /// Paths this pixel sample has branched into so far (1: no branching).
    paths: u32,
    /// Where efficiency-aware roulette records what this pass learns.
    learning: Option<&'l mut Learning>,
    /// Where learned splitting records what this sample's parts brought back.
    parts: Option<&'l mut SampleParts>,
    /// Where the sample's first-vertex split points lie.
    split_points: SamplePoints,
    /// Where a path-guiding training pass records the radiance found along continuations.
    guiding: Option<&'l mut PathRecords<'g>>,
    /// Where a training pass of learned light selection records what light samples find.
    lights: Option<&'l mut LightRecords>,
}

impl Walk<'_, '_> {
    /// The learning sample's parts, where the path is at its first vertex (the one that
    /// splits); `None` elsewhere and outside learning.
    #[inline]
    fn first_vertex_parts(&mut self, first: bool) -> Option<&mut SampleParts> {
        self.parts.as_deref_mut().filter(|_| first)
    }
}

/// A scattering vertex: the shading point, its material and BSDF, the direction back along
/// the ray that found it (local frame), the origin every ray leaving it above the surface
/// starts from (computed once: its shadow rays and its continuation share it), and the
/// length of the ray that found it.
struct Vertex<'v> {
    it: &'v Interaction,
    material: &'v Material,
    bsdf: &'v Bsdf<'v>,
    wo: Vec3,
    origin: Vec3,
    arrived: f32,
    /// The learned distribution continuations mix with BSDF sampling here, if any.
    guide: Option<Distribution<'v>>,
    /// The vertex's cell of the guiding tree (while paths are guided or record).
    cell: Option<Cell>,
}

impl Vertex<'_> {
    /// Density with which the vertex's continuations are sampled in local direction `wi`
    /// (for MIS): the BSDF's, or its mixture with the guide's.
    #[inline]
    fn continuation_pdf(&self, wi: Vec3) -> f32 {
        let p_bsdf = self.bsdf.pdf(self.wo, wi);
        match &self.guide {
            Some(g) => {
                GUIDE_PROBABILITY * g.pdf(self.it.frame.to_world(wi))
                    + (1.0 - GUIDE_PROBABILITY) * p_bsdf
            }
            None => p_bsdf,
        }
    }

    /// Where a ray leaving the vertex starts: off the surface on the side it leaves to.
    #[inline]
    fn origin(&self, below: bool) -> Vec3 {
        if below {
            offset_ray_origin_within(self.it.p, -self.it.ng, self.it.magnitude)
        } else {
            self.origin
        }
    }
}

/// A scattering event inside a medium: the medium, where, the direction the light travelled
/// (unit) and how far from the ray's origin (render space).
struct MediumVertex<'m> {
    medium: &'m Medium,
    p: Vec3,
    dir: Vec3,
    arrived: f32,
}

/// What became of a path along a ray inside media.
enum Segment {
    /// The innermost medium does not scatter (its absorption is still to be applied).
    Clear,
    /// The light crossed the scattering medium to the ray's end (the weight applied); the
    /// numbers drawn for the vertex there, which its surface takes.
    Passed(VertexSample),
    /// It scattered in the medium and goes on along this ray (the path state updated).
    Scattered(Ray),
    /// The path ended in the medium.
    Ended,
}

/// How a path continues past a vertex.
#[derive(Clone, Copy, Debug)]
struct Continuation {
    /// Paths to continue with (0 ends the path).
    count: u32,
    /// Factor every continued path's throughput is multiplied by.
    weight: f32,
    /// BSDF sample count entering the MIS weights.
    mis_count: u32,
    /// Whether the configured Russian roulette still applies after the bounce.
    roulette: bool,
}

/// The path tracer over a world with given settings, in the variant a render plan chose
/// (see `render::plan::Kernel`): `EMITTERS` looks up and MIS-weighs emitters that BSDF-sampled rays
/// hit; `DATA` computes the first hit's data AOVs.
pub struct PathTracer<'a, const EMITTERS: bool, const DATA: bool> {
    world: &'a World,
    settings: &'a Settings,
    /// Learned statistics for efficiency-aware roulette (rr=efficiency only).
    ears: Option<&'a Ears>,
    /// How the first vertex splits in this pass.
    split: FirstSplit,
    /// The learned distributions continuations are guided by, if any.
    guide: Option<Guide<'a>>,
    /// Learned light selection, if lights are chosen by it.
    lights: Option<&'a LightLearning>,
    /// The media around the camera, where camera paths start.
    camera_media: Media,
}

impl PathState {
    /// A camera path (through filters at most) reached an unlit surface of colour
    /// `colour`: it is seen as emission (of no light: no light group takes it).
    fn reached_unlit<R: Recorder>(&self, walk: &mut Walk, rec: &mut R, colour: Vec3) {
        let value = self.beta * colour;
        if let Some(parts) = walk.parts.as_deref_mut() {
            parts.add(value, 0, false);
        }
        rec.contribution(Contribution {
            value,
            depth: 0,
            source: Source::Emission,
            single_technique: None,
            lobes: None,
            light: None,
        });
    }

    /// The path's throughput brings `emitted`, the light a medium emits along the segment
    /// it enters, to the pixel: seen directly at depth 0 (the emission layers), otherwise
    /// found by path sampling alone (light sampling does not sample media: no MIS weight),
    /// of no light (no light group takes it).
    fn reached_medium_emission<R: Recorder>(&self, walk: &mut Walk, rec: &mut R, emitted: Vec3) {
        let value = self.beta * emitted;
        if !(value.max_element() > 0.0) {
            return;
        }
        if let Some(parts) = walk.parts.as_deref_mut() {
            parts.add(value, self.depth, false);
        }
        if let Some(learning) = walk.learning.as_deref_mut() {
            learning.gathered(value, self.depth);
        }
        if let Some(guiding) = walk.guiding.as_deref_mut() {
            guiding.gathered(value, self.depth, Technique::Bsdf);
        }
        let direct = self.depth == 0;
        rec.contribution(Contribution {
            value,
            depth: self.depth,
            source: if direct {
                Source::Emission
            } else {
                Source::Bsdf
            },
            single_technique: (walk.single && self.depth == 1).then_some([value, value]),
            lobes: (walk.lobes && !direct).then_some(self.lobes),
            light: None,
        });
    }

    /// The path reached emitter `e`: seen directly by the camera, or found by BSDF
    /// sampling and weighted against light sampling's density there (unless a delta lobe
    /// led here, which light sampling cannot follow).
    #[inline]
    fn reached_emitter<R: Recorder, const EMITTERS: bool, const DATA: bool>(
        &self,
        tracer: &PathTracer<EMITTERS, DATA>,
        walk: &mut Walk,
        rec: &mut R,
        e: Emitter,
    ) {
        let Emitter { le, light, .. } = e;
        if self.depth == 0 {
            if let Some(parts) = walk.parts.as_deref_mut() {
                parts.add(self.beta * le, 0, false);
            }
            rec.contribution(Contribution {
                value: self.beta * le,
                depth: 0,
                source: Source::Emission,
                single_technique: None,
                lobes: None,
                light: Some(light as u32),
            });
            return;
        }
        let p_light = self.light_density(tracer.world, tracer.settings, tracer.lights, &e);
        record(
            rec,
            walk,
            Technique::Bsdf,
            self.beta * le,
            (self.depth, self.lobes, light),
            self.prev_pdf,
            p_light,
        );
    }
}

impl<'a, const EMITTERS: bool, const DATA: bool> PathTracer<'a, EMITTERS, DATA> {
    /// A path tracer for `world`; `ears` holds the statistics of efficiency-aware roulette,
    /// `split` how the first vertex splits.
    pub fn new(
        world: &'a World,
        settings: &'a Settings,
        ears: Option<&'a Ears>,
        split: FirstSplit,
    ) -> Self {
        // Only interfaces' media are found around the camera (see `Media::around`).
        let camera_media = if world.surfaces.participating {
            Media::around(world, world.camera.origin())
        } else {
            Media::EMPTY
        };
        Self {
            world,
            settings,
            ears,
            split,
            guide: None,
            lights: None,
            camera_media,
        }
    }

    /// The same tracer, its continuations guided by `guide`.
    pub fn guided_by(self, guide: Option<Guide<'a>>) -> Self {
        Self { guide, ..self }
    }

    /// The same tracer, its lights chosen by learned selection `lights` (the light set's
    /// own selection where `None`).
    pub fn selecting_lights_by(self, lights: Option<&'a LightLearning>) -> Self {
        Self { lights, ..self }
    }

    /// Traces the paths of camera ray `ray` for pixel `pixel` using `sampler`'s current
    /// pixel sample; `learning` receives statistics for efficiency-aware roulette, `parts`
    /// what the sample's parts bring back for learned splitting, `guiding` what a
    /// path-guiding training pass learns, `lights` what learned light selection learns.
    #[allow(clippy::too_many_arguments)]
    pub fn trace<R: Recorder>(
        &self,
        ray: Ray,
        pixel: usize,
        sampler: &mut Sampler,
        rec: &mut R,
        rays: &mut RayCounts,
        learning: Option<&mut Learning>,
        parts: Option<&mut SampleParts>,
        guiding: Option<&mut PathRecords>,
        lights: Option<&mut LightRecords>,
    ) {
        let mut walk = Walk {
            mis: self.settings.mis,
            single: rec.wants_single_technique(),
            lobes: rec.wants_lobes(),
            pixel,
            paths: 1,
            learning,
            parts,
            split_points: self
                .split
                .sample_points(sampler.pixel(), sampler.sample_index()),
            guiding,
            lights,
        };
        let camera = PathState {
            media: self.camera_media,
            time: ray.time,
            ..PathState::camera(ray.origin, self.world.footprints.camera)
        };
        self.trace_from(ray, camera, None, &mut walk, sampler, rec, rays);
    }

    /// Follows the path of state `path` whose ray `ray` found `hit` (already traced and
    /// counted) to its end: the packet kernel hands the paths that reach a surface it does
    /// not shade in lanes (glass, filters) to this. `parts`, the pixel `pixel` and the
    /// sample's first-vertex split points `split_points` are as for [`PathTracer::trace`];
    /// no roulette learns.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn continue_from<R: Recorder>(
        &self,
        ray: Ray,
        hit: Hit,
        path: PathState,
        (pixel, split_points): (usize, SamplePoints),
        sampler: &mut Sampler,
        rec: &mut R,
        rays: &mut RayCounts,
        parts: Option<&mut SampleParts>,
    ) {
        let mut walk = Walk {
            mis: self.settings.mis,
            single: rec.wants_single_technique(),
            lobes: rec.wants_lobes(),
            pixel,
            paths: 1,
            learning: None,
            parts,
            split_points,
            guiding: None,
            lights: None,
        };
        self.trace_from(ray, path, Some(hit), &mut walk, sampler, rec, rays);
    }

    /// Follows a path from `ray` (whose hit may be known already) until it ends; paths
    /// split off from it are traced by recursion. The vertices it opens for learning are
    /// closed when it ends.
    #[allow(clippy::too_many_arguments)]
    fn trace_from<R: Recorder>(
        &self,
        ray: Ray,
        path: PathState,
        hit: Option<Hit>,
        walk: &mut Walk,
        sampler: &mut Sampler,
        rec: &mut R,
        rays: &mut RayCounts,
    ) {
        let mark = walk.learning.as_ref().map(|l| l.mark());
        let guide_mark = walk.guiding.as_ref().map(|g| g.mark());
        self.walk_path(ray, path, hit, walk, sampler, rec, rays);
        if let (Some(learning), Some(mark)) = (walk.learning.as_deref_mut(), mark) {
            learning.close(mark, rays.closest + rays.shadow);
        }
        if let (Some(guiding), Some(mark)) = (walk.guiding.as_deref_mut(), guide_mark) {
            guiding.close(mark);
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn walk_path<R: Recorder>(
        &self,
        mut ray: Ray,
        mut path: PathState,
        mut known_hit: Option<Hit>,
        walk: &mut Walk,
        sampler: &mut Sampler,
        rec: &mut R,
        rays: &mut RayCounts,
    ) {
        let world = self.world;
        let max_depth = self.settings.max_depth.unwrap_or(u32::MAX);
        loop {
            let hit = known_hit.take().or_else(|| {
                rays.closest += 1;
                world.intersect(&ray)
            });
            // The way to the hit through a medium that scatters: the light may interact
            // before it (see `medium`). Only in scenes with participating media.
            // The numbers of the vertex reached, where a flight through a medium drew them.
            let mut drawn = None;
            if world.surfaces.participating && !path.media.is_empty() {
                match self.through_medium(&ray, hit.as_ref(), &mut path, sampler, walk, rec, rays) {
                    Segment::Clear => {}
                    Segment::Passed(vs) => drawn = Some(vs),
                    Segment::Scattered(next) => {
                        ray = next;
                        continue;
                    }
                    Segment::Ended => return,
                }
            }
            let Some(hit) = hit else {
                if EMITTERS {
                    emitters_at_infinity(world, ray.dir, |e| {
                        path.reached_emitter(self, walk, rec, e)
                    });
                }
                return;
            };
            let arrived = hit.t * ray.dir.length();
            if !path.media.is_empty() && drawn.is_none() {
                path.beta *= path.media.transmittance(&world.surfaces, &ray, arrived);
            }
            // After a rough bounce, footprints are circles (one texture probe).
            let it = world.interaction_in_cone(
                &ray,
                &hit,
                path.cone.width_at(arrived),
                !path.prev_delta,
            );
            if EMITTERS && let Some(e) = surface_emitter(world, &it, &ray, hit.t) {
                path.reached_emitter(self, walk, rec, e);
            }
            if path.depth >= max_depth {
                return;
            }
            let surfaces = &world.surfaces;
            let m = &surfaces.materials[it.material as usize];
            if m.model == BsdfModel::Interface {
                // Crossed as a clear filter is, without a scattering event (see the module
                // notes), into or out of its medium; no BSDF to build or sample.
                path = PathState {
                    media: path.media.beyond(&it, m, true),
                    ..path.past_filter(arrived)
                };
                ray = Ray::new(offset_past(it.p, it.ng, ray.dir, it.magnitude), ray.dir)
                    .at_time(path.time);
                continue;
            }
            let ctx = it.shading_context(path.media.outside_ior(surfaces, &it));
            let mut storage = BsdfStorage::default();
            let bsdf = material::bsdf_in(m, &surfaces.textures, &it.attrs, &ctx, &mut storage);
            let wo = it.frame.to_local(-ray.dir);
            // The camera's first surface (interfaces, crossed above, are not surfaces).
            if !path.first_hit_recorded && path.branch == 0 {
                path.first_hit_recorded = true;
                rec.first_hit(DATA.then(|| {
                    let lobe_albedo = bsdf.albedo_lobes(wo);
                    let (motion, velocity) = world.motion_of(&it, path.time);
                    FirstHit {
                        albedo: lobe_albedo.iter().sum(),
                        normal: it.frame.n,
                        depth: world.camera.depth(it.p),
                        position: world.space.to_world(it.p).as_vec3(),
                        motion,
                        velocity,
                        lobe_albedo,
                        object: world.object_of(&it),
                        material: it.material,
                    }
                }));
            }
            // An unlit surface shows its colour to the camera and ends the path there; every
            // other ray crosses it (its BSDF is a clear filter).
            if m.unlit && path.depth == 0 {
                let colour = material::base_color(m, &surfaces.textures, &it.attrs).truncate();
                path.reached_unlit(walk, rec, colour);
                return;
            }
            // Light samples and continuations from a black surface would add nothing.
            if bsdf.is_black() {
                return;
            }
            // The region efficiency-aware roulette keeps statistics for (only in that mode).
            let cell = self.ears.map(|_| ears::cell(it.p, it.ng));
            if let (Some(learning), Some(cell)) = (walk.learning.as_deref_mut(), cell) {
                learning.open(
                    cell,
                    path.depth,
                    luminance(path.beta),
                    rays.closest + rays.shadow,
                );
            }
            // The vertex's cell of the guiding tree, where paths are guided or record.
            let guide_cell = if self.guide.is_some() || walk.guiding.is_some() {
                let n = facing(it.ng, ray.dir);
                match (&self.guide, walk.guiding.as_deref()) {
                    (Some(g), _) => Some(g.cell(it.p, n)),
                    (None, Some(r)) => Some(r.cell(it.p, n)),
                    (None, None) => None,
                }
            } else {
                None
            };
            let vertex = Vertex {
                it: &it,
                material: m,
                bsdf: &bsdf,
                wo,
                origin: offset_ray_origin_within(it.p, it.ng, it.magnitude),
                arrived,
                guide: guide_cell.and_then(|c| self.guide.and_then(|g| g.at(c))),
                cell: guide_cell,
            };
            let vs = drawn.unwrap_or_else(|| sampler.vertex(path.vertex, path.branch));
            let first = path.vertex == 0;
            let n_nee = self.split.at(path.vertex).nee;
            let continuation = self.continuation(&path, walk, cell, vs.rr);
            if let Some(parts) = walk.first_vertex_parts(first) {
                parts.split = true;
                parts.rays[1] = rays.closest + rays.shadow;
            }

            if bsdf.has_non_delta() && !world.lights.is_empty() {
                for j in 0..n_nee {
                    let (u_light, u_select) = if n_nee == 1 {
                        (vs.light, vs.light_select)
                    } else {
                        let point = walk.split_points.point(SplitKind::Light, j);
                        let p = sampler.first_split_point(SplitKind::Light, point);
                        (Vec2::new(p[0], p[1]), p[2])
                    };
                    if let Some(parts) = walk.first_vertex_parts(first) {
                        parts.current = j as usize;
                    }
                    rays.shadow += self.next_event(
                        &vertex,
                        &path,
                        walk,
                        (n_nee, continuation.mis_count),
                        u_light,
                        u_select,
                        rec,
                    );
                }
            }

            if let Some(parts) = walk.first_vertex_parts(first) {
                parts.rays[2] = rays.closest + rays.shadow;
            }

            // Continue: the last path in this loop, the others as branches of their own.
            let mut next = None;
            for k in 0..continuation.count {
                if let Some(parts) = walk.first_vertex_parts(first) {
                    parts.current = k as usize;
                }
                let sample = if continuation.count == 1 {
                    vs
                } else {
                    // The first vertex's split takes the same count at every sample;
                    // efficiency-aware splitting's count varies.
                    let p = match (first, self.split.counts.bsdf > 1) {
                        (true, true) => {
                            let point = walk.split_points.point(SplitKind::Bsdf, k);
                            sampler.first_split_point(SplitKind::Bsdf, point)
                        }
                        (true, false) => sampler.split_point(SplitKind::Bsdf, 0, k),
                        (false, _) => {
                            let key = 1 + path.branch * 4096 + path.depth;
                            sampler.split_point(SplitKind::Bsdf, key, k)
                        }
                    };
                    VertexSample {
                        bsdf: Vec2::new(p[0], p[1]),
                        lobe: p[2],
                        rr: p[3],
                        ..vs
                    }
                };
                let branch = if k == 0 {
                    path.branch
                } else {
                    walk.paths += 1;
                    walk.paths - 1
                };
                // A branch's continuation record closes with the branch; the last
                // continuation's, with the path.
                let guide_mark = walk.guiding.as_ref().map(|g| g.mark());
                let Some(child) =
                    self.scatter(&vertex, &path, walk, &sample, &continuation, n_nee, branch)
                else {
                    continue;
                };
                if k + 1 == continuation.count {
                    next = Some(child);
                } else {
                    self.trace_from(child.0, child.1, None, walk, sampler, rec, rays);
                    if let (Some(guiding), Some(mark)) = (walk.guiding.as_deref_mut(), guide_mark) {
                        guiding.close(mark);
                    }
                }
            }
            let Some((next_ray, next_path)) = next else {
                return;
            };
            ray = next_ray;
            path = next_path;
        }
    }

    /// How the path continues past its current vertex (after the light samples there).
    fn continuation(
        &self,
        path: &PathState,
        walk: &Walk,
        cell: Option<u32>,
        u: f32,
    ) -> Continuation {
        let split = self.split.at(path.vertex).bsdf;
        if split > 1 {
            return Continuation {
                count: split,
                weight: 1.0 / split as f32,
                mis_count: split,
                roulette: true,
            };
        }
        let learned = match (self.settings.rr, self.ears, cell) {
            (RussianRoulette::Efficiency(_), Some(e), Some(cell)) => {
                e.factor(walk.pixel, cell, luminance(path.beta))
            }
            _ => None,
        };
        match learned {
            Some(q) => {
                // No more splitting once the pixel sample has branched enough.
                let q = if walk.paths >= MAX_BRANCHES {
                    q.min(1.0)
                } else {
                    q
                };
                let count = q.floor() as u32 + u32::from(u < q.fract());
                Continuation {
                    count: count.min(MAX_BRANCHES),
                    weight: 1.0 / q,
                    mis_count: 1,
                    roulette: false,
                }
            }
            None => Continuation {
                count: 1,
                weight: 1.0,
                mis_count: 1,
                roulette: true,
            },
        }
    }

    /// Samples the BSDF at vertex `v` for one continued path, applying the continuation's
    /// weight and, where it still applies, Russian roulette; `None` if the path ends there.
    #[allow(clippy::too_many_arguments)]
    fn scatter(
        &self,
        v: &Vertex,
        path: &PathState,
        walk: &mut Walk,
        vs: &VertexSample,
        c: &Continuation,
        n_nee: u32,
        branch: u32,
    ) -> Option<(Ray, PathState)> {
        let Vertex { it, bsdf, wo, .. } = *v;
        let bs = match &v.guide {
            Some(guide) => guided_sample(bsdf, wo, &it.frame, guide, vs)?,
            None => bsdf.sample(wo, vs.lobe, vs.bsdf)?,
        };
        let wi = it.frame.to_world(bs.wi);
        // Reflection must leave on the side of the surface the path arrived from, and
        // transmission cross it, by the geometric normal too.
        let crossing = bs.is_transmission();
        if (wi.dot(it.ng) > 0.0) == crossing {
            return None;
        }
        let mut beta = path.beta * bs.weight * c.weight;
        let origin = v.origin(crossing);
        if bs.lobe == Lobe::StraightTransmission {
            // A filter crossed: no scattering event (see the module notes).
            if !(beta.max_element() > 0.0) {
                return None;
            }
            let next = PathState {
                beta,
                branch,
                ..path.past_filter(v.arrived)
            };
            return Some((Ray::new(origin, wi).at_time(path.time), next));
        }
        let depth = path.depth + 1;
        let media = path.media.beyond(it, v.material, crossing);
        if c.roulette {
            let rr = match self.settings.rr {
                // Efficiency mode where its statistics are missing: throughput roulette.
                RussianRoulette::Efficiency(_) => RussianRoulette::Throughput(0.01),
                rr => rr,
            };
            let mut throughput = luminance(beta);
            if !media.is_empty() {
                throughput *= media.radiance_scale(&self.world.surfaces);
            }
            let survival = rr.survival(throughput, depth);
            if survival < 1.0 {
                if !(vs.rr < survival) {
                    return None;
                }
                beta /= survival;
            }
        }
        if !(beta.max_element() > 0.0) {
            return None;
        }
        // The first scattering event decides the lobe shares of all the path brings back.
        let lobes = if walk.lobes && path.depth == 0 {
            bsdf.lobe_shares(wo, &bs)
        } else {
            path.lobes
        };
        if let Some(guiding) = walk.guiding.as_deref_mut()
            && let Some(cell) = v.cell
            && !bs.is_delta()
        {
            guiding.open(
                cell,
                wi.normalize(),
                path.depth,
                luminance(beta),
                bs.pdf / bs.wi.z.abs(),
            );
        }
        let next = PathState {
            beta,
            depth,
            vertex: path.vertex + 1,
            branch,
            prev_p: it.p,
            prev_n: it.frame.n,
            prev_pdf: bs.pdf * c.mis_count as f32,
            prev_delta: bs.is_delta(),
            prev_nee_count: n_nee,
            lobes,
            media,
            crossed: 0.0,
            cone: path.cone.scattered(
                v.arrived,
                bs.pdf,
                bs.is_delta(),
                self.world.footprints.lobe_scale,
            ),
            first_hit_recorded: true,
            time: path.time,
        };
        Some((Ray::new(origin, wi).at_time(path.time), next))
    }
}

/// Geometric normal `ng` turned to the side a ray of direction `dir` arrives from.
#[inline]
fn facing(ng: Vec3, dir: Vec3) -> Vec3 {
    if ng.dot(dir) > 0.0 { -ng } else { ng }
}

/// Records `value`, found by `technique` with density `own`, where the other technique's
/// density is `other` (densities times sample counts; 0 where a technique cannot produce
/// the path: delta lights, delta lobes, so that every heuristic gives weight 1 there), with
/// the path's depth and lobe shares.
#[inline]
fn record<R: Recorder>(
    rec: &mut R,
    walk: &mut Walk,
    technique: Technique,
    value: Vec3,
    (depth, lobes, light): (u32, PerLobe, usize),
    own: f32,
    other: f32,
) {
    let weight = |h: Mis| h.weight(technique, own, other);
    let weighted = value * weight(walk.mis);
    if let Some(parts) = walk.parts.as_deref_mut() {
        parts.add(weighted, depth, technique == Technique::Nee);
    }
    if let Some(learning) = walk.learning.as_deref_mut() {
        learning.gathered(weighted, depth);
    }
    if let Some(guiding) = walk.guiding.as_deref_mut() {
        guiding.gathered(weighted, depth, technique);
    }
    rec.contribution(Contribution {
        value: weighted,
        depth,
        source: match technique {
            Technique::Nee => Source::Nee,
            Technique::Bsdf => Source::Bsdf,
        },
        single_technique: (walk.single && depth == 1)
            .then(|| [value * weight(Mis::NeeOnly), value * weight(Mis::BsdfOnly)]),
        lobes: walk.lobes.then_some(lobes),
        light: Some(light as u32),
    });
}
