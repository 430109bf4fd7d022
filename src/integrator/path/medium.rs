//! Scattering inside a medium: the vertices a path makes where its free flight through the
//! innermost medium (`crate::medium`) ends before the next surface.
//!
//! A medium vertex is a scattering event like a surface's, with the phase function in the
//! place of the BSDF and no surface: a light sample (its shadow ray through the media and
//! interfaces on the way, `Media::shadow_transmittance`) weighed by MIS against phase
//! sampling, and a continuation drawn from the phase function, which the configured Russian
//! roulette may end. The throughput already carries the flight's weight (albedo times
//! transmittance over density). Splitting, efficiency-aware roulette and path guiding act at
//! surface vertices only; a medium vertex sends one light sample and one continuation.
//! Light first scattered in a medium goes to the volume layers, not to a surface lobe's.
//! What a medium emits along a segment is added as the path enters the segment, whatever
//! its flight then does (`crate::medium`).

use super::super::estimator::{PathState, RayCounts, sample_chosen_light, select_light};
use super::super::mis::Technique;
use super::super::roulette::RussianRoulette;
use super::{MediumVertex, PathTracer, Segment, Walk, record};
use crate::color::luminance;
use crate::film::record::Recorder;
use crate::geometry::Hit;
use crate::geometry::ray::Ray;
use crate::material::PerLobe;
use crate::medium::Flight;
use crate::sampling::sampler::{Sampler, VertexSample};
use glam::Vec3;

/// Bounces a path may take at medium vertices before throughput roulette caps its survival
/// (`roulette::ROULETTE_CAP_DEPTH` counts from there).
const MEDIUM_UNCAPPED_BOUNCES: u32 = 1024;

/// The lobe shares of light first scattered in a medium: none of a surface's, which the
/// film reads as the medium's (the `volume_direct` and `volume_indirect` layers).
const MEDIUM_LOBES: PerLobe = [Vec3::ZERO; 3];

impl<const EMITTERS: bool, const DATA: bool> PathTracer<'_, EMITTERS, DATA> {
    /// The free flight of `path` along `ray` (whose first surface is `hit`, if any) through
    /// the innermost medium, where it scatters; the path's state is updated for what
    /// happened. Kept out of line: scenes without media never call it, and the surface
    /// loop stays as small as it was.
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn through_medium<R: Recorder>(
        &self,
        ray: &Ray,
        hit: Option<&Hit>,
        path: &mut PathState,
        sampler: &mut Sampler,
        walk: &mut Walk,
        rec: &mut R,
        rays: &mut RayCounts,
    ) -> Segment {
        let Some(medium) = path.media.medium(&self.world.surfaces) else {
            return Segment::Clear;
        };
        let length = hit.map_or(f32::INFINITY, |h| h.t * ray.dir.length());
        let dir = ray.dir.normalize();
        if medium.emits() {
            let emitted = medium.emitted(ray.origin, dir, length);
            path.reached_medium_emission(walk, rec, emitted);
        }
        if !medium.needs_flight() {
            return Segment::Clear;
        }
        let vs = sampler.vertex(path.vertex, path.branch);
        match path.media.fly(medium, ray.origin, dir, vs.medium, length) {
            Flight::Scatter { t, weight } => {
                path.beta *= weight;
                let scattered = MediumVertex {
                    medium,
                    p: ray.origin + dir * t,
                    dir,
                    arrived: t,
                };
                match self.medium_vertex(&scattered, path, &vs, walk, rec, rays) {
                    Some((next_ray, next_path)) => {
                        *path = next_path;
                        Segment::Scattered(next_ray)
                    }
                    None => Segment::Ended,
                }
            }
            Flight::Pass { weight } => {
                path.beta *= weight;
                if path.beta.max_element() > 0.0 {
                    Segment::Passed(vs)
                } else {
                    Segment::Ended
                }
            }
        }
    }

    /// The light sample at medium vertex `v` of `path` and the path's continuation from it
    /// (`None` where the path ends there), with `vs`'s numbers.
    pub(super) fn medium_vertex<R: Recorder>(
        &self,
        v: &MediumVertex,
        path: &PathState,
        vs: &VertexSample,
        walk: &mut Walk,
        rec: &mut R,
        rays: &mut RayCounts,
    ) -> Option<(Ray, PathState)> {
        if path.depth >= self.settings.max_depth.unwrap_or(u32::MAX) {
            return None;
        }
        let lobes = if walk.lobes && path.depth == 0 {
            MEDIUM_LOBES
        } else {
            path.lobes
        };
        if !self.world.lights.is_empty() {
            rays.shadow += self.medium_light_sample(v, path, vs, lobes, walk, rec);
        }
        let (wi, pdf) = v.medium.phase().sample(v.dir, vs.bsdf);
        let depth = path.depth + 1;
        let mut beta = path.beta;
        let rr = match self.settings.rr {
            RussianRoulette::Efficiency(_) => RussianRoulette::Throughput(0.01),
            rr => rr,
        };
        let throughput = luminance(beta) * path.media.radiance_scale(&self.world.surfaces);
        // A walk through a dense medium of albedo near 1 (subsurface scattering of a bright
        // colour) takes hundreds of steps before it leaves; the roulette's cap on survival
        // after a few bounces would end nearly all of them and weigh the rare survivors by
        // 0.95^-n (fireflies). Medium vertices count towards the cap only after
        // MEDIUM_UNCAPPED_BOUNCES; throughput still ends absorbing walks.
        let survival = rr.survival(throughput, depth.saturating_sub(MEDIUM_UNCAPPED_BOUNCES));
        if survival < 1.0 {
            if !(vs.rr < survival) {
                return None;
            }
            beta /= survival;
        }
        if !(beta.max_element() > 0.0 && pdf > 0.0) {
            return None;
        }
        let next = PathState {
            beta,
            depth,
            vertex: path.vertex + 1,
            prev_p: v.p,
            // No surface: light selection and densities take no normal.
            prev_n: Vec3::ZERO,
            prev_pdf: pdf,
            prev_delta: false,
            prev_nee_count: 1,
            lobes,
            crossed: 0.0,
            cone: path
                .cone
                .scattered(v.arrived, pdf, false, self.world.footprints.lobe_scale),
            ..*path
        };
        Some((Ray::new(v.p, wi).at_time(path.time), next))
    }

    /// One light sample at medium vertex `v`: returns the rays it traced.
    fn medium_light_sample<R: Recorder>(
        &self,
        v: &MediumVertex,
        path: &PathState,
        vs: &VertexSample,
        lobes: PerLobe,
        walk: &mut Walk,
        rec: &mut R,
    ) -> u64 {
        let world = self.world;
        let region = self.lights.and_then(|l| l.region(v.p, Vec3::ZERO));
        let Some((index, p_select)) =
            select_light(world, self.lights, region, vs.light_select, v.p, Vec3::ZERO)
        else {
            return 0;
        };
        let Some(ls) = sample_chosen_light(world, self.settings, v.p, None, index, vs.light) else {
            return 0;
        };
        let phase = v.medium.phase().eval(v.dir.dot(ls.wi.normalize()));
        let shadow = ls.shadow_ray(v.p, path.time);
        let mut traced = 0;
        let through = path.media.shadow_transmittance(world, &shadow, &mut traced);
        if through == Vec3::ZERO {
            return traced;
        }
        let p_light = p_select * ls.pdf;
        // Phase sampling cannot reach a delta light (nor any light, without emitter lookups).
        let p_phase = if ls.delta || !EMITTERS { 0.0 } else { phase };
        let value = path.beta * phase * ls.radiance * through / p_light;
        record(
            rec,
            walk,
            Technique::Nee,
            value,
            (path.depth + 1, lobes, index),
            p_light,
            p_phase,
        );
        traced
    }
}
