//! Next-event estimation at a surface vertex: a light chosen by the selection strategy
//! (learned selection too, which records what the sample finds during its training passes),
//! a point on it, a shadow ray through the media and filters on the way, and the
//! contribution weighed by MIS against BSDF sampling.

use super::super::estimator::{PathState, sample_light};
use super::super::mis::Technique;
use super::{PathTracer, Vertex, Walk, record};
use crate::color::luminance;
use crate::film::record::Recorder;
use crate::material;
use glam::{Vec2, Vec3};

impl<const EMITTERS: bool, const DATA: bool> PathTracer<'_, EMITTERS, DATA> {
    /// One light sample at vertex `v`: a light chosen by the selection strategy, a point on
    /// it, a shadow ray. Returns the number of shadow rays traced.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn next_event<R: Recorder>(
        &self,
        v: &Vertex,
        path: &PathState,
        walk: &mut Walk,
        (n_nee, n_bsdf): (u32, u32),
        u_light: Vec2,
        u_select: f32,
        rec: &mut R,
    ) -> u64 {
        let Vertex { it, bsdf, wo, .. } = *v;
        let world = self.world;
        let transmits = bsdf.transmits();
        let region = self.lights.and_then(|l| l.region(it.p, it.frame.n));
        if let (Some(records), Some(region)) = (walk.lights.as_deref_mut(), region) {
            records.sample(region);
        }
        let Some((index, p_select, ls)) = sample_light(
            world,
            self.settings,
            (self.lights, region),
            it,
            (u_select, u_light),
            transmits,
        ) else {
            return 0;
        };
        let mut radiance = ls.radiance;
        let wi = it.frame.to_local(ls.wi);
        let below = transmits && ls.wi.dot(it.ng) < 0.0;
        // Light through the surface only where the shading frame agrees it crosses.
        if below != (wi.z < 0.0) && transmits {
            return 0;
        }
        // At the first vertex the lobe layers need f split by lobe: evaluated once, split.
        let (f, lobes) = if walk.lobes && path.depth == 0 {
            let parts = bsdf.eval_lobes(wo, wi);
            (parts[0] + parts[1] + parts[2], material::shares(parts))
        } else {
            (bsdf.eval(wo, wi), path.lobes)
        };
        if f == Vec3::ZERO {
            return 0;
        }
        let origin = v.origin(below);
        let shadow = ls.shadow_ray(origin, path.time);
        let media = path.media.beyond(it, v.material, below);
        let mut traced = 1;
        let through = if world.surfaces.participating {
            traced = 0;
            media.shadow_transmittance(world, &shadow, &mut traced)
        } else {
            let length = ls.target.map_or(f32::INFINITY, |t| (t - origin).length());
            world.transmittance(&shadow) * media.transmittance(&world.surfaces, &shadow, length)
        };
        if through == Vec3::ZERO {
            return traced;
        }
        radiance *= through;
        let p_light = p_select * ls.pdf;
        // BSDF sampling cannot reach a delta light (nor any light, in a kernel without
        // emitter lookups): its density there is 0, and the light sample's weight 1.
        let p_bsdf = if ls.delta || !EMITTERS {
            0.0
        } else {
            v.continuation_pdf(wi)
        };
        if let (Some(records), Some(region), Some(learning)) =
            (walk.lights.as_deref_mut(), region, self.lights)
        {
            records.found(learning, region, index, luminance(f * radiance) / p_light);
        }
        let value = path.beta * f * radiance / (p_light * n_nee as f32);
        record(
            rec,
            walk,
            Technique::Nee,
            value,
            (path.depth + 1, lobes, index),
            p_light * n_nee as f32,
            p_bsdf * n_bsdf as f32,
        );
        traced
    }
}
