//! Light samples in lanes: lights selected (by power in lanes, else by the scalar code lane
//! by lane), points sampled on them, the first vertex's split points, the shadow rays
//! traced as a packet and the contributions weighed by MIS.

use super::super::estimator::{RayCounts, sample_chosen_light};
use super::super::mis::Technique;
use super::PacketTracer;
use super::shading::{Dim, ScalarLightSamples, Vertices};
use super::state::{PacketBuffers, PathLanes};
use super::weights::mis_weights;
use crate::geometry::ray::RayLanes;
use crate::geometry::triangle::Lanes;
use crate::sampling::sampler::{SamplerKind, SplitKind, first_split_sobol_lanes, sobol_4d_lanes};
use crate::simd::{F8, LANES, M8, U8, V3};
use glam::Vec2;

impl<'a, const EMITTERS: bool> PacketTracer<'a, EMITTERS> {
    /// Shadow rays towards the lights from every scattering lane (the first vertex's split
    /// count of them at depth 0, one deeper), each weighted by MIS against BSDF sampling.
    #[inline(always)]
    pub(super) fn light_samples(
        &self,
        lanes: &mut PathLanes,
        v: &Vertices,
        buffers: &mut PacketBuffers,
        rays: &mut RayCounts,
    ) {
        let world = self.world;
        let lights = &world.lights;
        if lights.is_empty() {
            return;
        }
        let nee_lanes = v.bsdf.non_delta(v.mask);
        let counts = self.split.at(0);
        let rounds = v.rounds(nee_lanes, counts.nee);
        let (n_nee, n_bsdf) = (v.counts(counts.nee), v.counts(counts.bsdf));
        let beta = lanes.beta;
        let area_lights = self.area_lights;
        for j in 0..rounds {
            let mut scalar = ScalarLightSamples::new();
            let round = v.round_lanes(nee_lanes, j, counts.nee);
            // The numbers of each lane's light sample: the point on the light, and the choice.
            let split = if counts.nee > 1 { round & v.first } else { 0 };
            let points = self.split_points(lanes, split, SplitKind::Light, j, buffers);
            let own = [Dim::LIGHT_X, Dim::LIGHT_Y, Dim::LIGHT_SELECT];
            let split_lanes = M8::from_bits(split);
            let mut u = [F8::ZERO; 3];
            for ((u, p), d) in u.iter_mut().zip(points).zip(own) {
                *u = F8::select(split_lanes, p, v.numbers[d]);
            }
            let (light, p_select, chosen) = self.select_lights(v, round, u[2]);
            // Lanes whose chosen light the lanes sample; the scalar code samples the others.
            let area = match area_lights {
                Some(table) => chosen & table.lanes_sample(light, self.lane_light_kinds),
                None => 0,
            };
            let (light_index, p_select_lanes) = (light.to_array(), p_select.to_array());
            for lane in Lanes::new(chosen & !area) {
                let u_light = Vec2::new(u[0].lane(lane), u[1].lane(lane));
                let (index, p) = (light_index[lane] as usize, p_select_lanes[lane]);
                self.scalar_light_sample(v, lane, index, p, u_light, &mut scalar);
            }
            // The lanes' own samples; lanes they leave to the scalar code take its samples.
            let area_samples = match area_lights {
                Some(table) if area != 0 => {
                    let s = table.sample(light, v.p, v.ng, [u[0], u[1]], area);
                    for lane in Lanes::new(s.scalar) {
                        let u_light = Vec2::new(u[0].lane(lane), u[1].lane(lane));
                        let (index, p) = (light_index[lane] as usize, p_select_lanes[lane]);
                        self.scalar_light_sample(v, lane, index, p, u_light, &mut scalar);
                    }
                    Some(s)
                }
                _ => None,
            };
            // The scalar code's samples in lanes, then the lanes' own samples over them. Every
            // shadow ray leaves its vertex's ray origin.
            let (mut wi, mut radiance, mut p_light, mut shadow) = if scalar.sampled != 0 {
                (
                    V3::from_lanes(&scalar.wi),
                    V3::from_lanes(&scalar.radiance),
                    F8::from_array(scalar.p_light),
                    RayLanes::of_rays(&scalar.shadow),
                )
            } else {
                let shadow = RayLanes {
                    origin: v.origin,
                    dir: V3::ZERO,
                    tmax: F8::ONE,
                };
                (V3::ZERO, V3::ZERO, F8::ONE, shadow)
            };
            if let Some(s) = area_samples {
                let valid = M8::from_bits(s.valid);
                wi = V3::select(valid, s.wi, wi);
                radiance = V3::select(valid, s.radiance, radiance);
                p_light = F8::select(valid, p_select * s.pdf, p_light);
                shadow.origin = v.origin;
                shadow.dir = V3::select(valid, s.target - v.origin, shadow.dir);
                shadow.tmax = F8::select(valid, F8::ONE, shadow.tmax);
                scalar.sampled |= s.valid;
            }
            let mut sampled = scalar.sampled;
            if sampled == 0 {
                continue;
            }
            let wi_local = v.to_local(wi);
            // SAFETY: this function runs inside `render_lanes`, on a CPU with AVX2 and FMA.
            let (f, pdf) = unsafe { v.bsdf.eval_pdf(v.wo, wi_local, sampled) };
            let zero = F8::ZERO;
            sampled &= (f.x.ne(zero) | f.y.ne(zero) | f.z.ne(zero)).bits();
            lanes.rays = lanes.rays - M8::from_bits(sampled).as_u8();
            if self.learning {
                for lane in Lanes::new(sampled) {
                    let slot = &mut buffers.slots[lanes.sample[lane] as usize];
                    self.count_part_ray(slot, lanes.depth.lane(lane), false);
                }
            }
            let (blocked, through) = world.transmittance_lanes(&shadow, sampled);
            let lit = sampled & !blocked;
            rays.shadow += sampled.count_ones() as u64;
            if lit == 0 {
                continue;
            }
            // What the filters the shadow rays crossed let through (thin glass).
            if let Some(through) = through {
                radiance = radiance * V3::from_lanes(&through);
            }
            let no_bsdf = if EMITTERS {
                M8::from_bits(scalar.delta)
            } else {
                M8::all()
            };
            let p_bsdf = F8::select(no_bsdf, zero, pdf);
            let own = p_light * n_nee;
            let value = (beta * f) * radiance / own;
            let w = mis_weights(self.settings.mis, Technique::Nee, own, p_bsdf * n_bsdf, lit);
            let value = value * w;
            // Kept where finite, dropped and counted where not (as `contribute` does).
            let infinity = F8::splat(f32::INFINITY);
            let finite = value.x.abs().lt(infinity)
                & value.y.abs().lt(infinity)
                & value.z.abs().lt(infinity);
            let lit_lanes = M8::from_bits(lit);
            lanes.value += V3::select(lit_lanes & finite, value, V3::ZERO);
            lanes.discarded = lanes.discarded - lit_lanes.and_not(finite).as_u8();
            if self.learning {
                for lane in Lanes::new(lit) {
                    let (depth, branch) = (lanes.depth.lane(lane), lanes.branch[lane]);
                    let slot = &mut buffers.slots[lanes.sample[lane] as usize];
                    // The first vertex's light estimate j, or the BSDF path a deeper vertex
                    // is on.
                    let current = if depth == 0 { j } else { branch };
                    self.learn(slot, value.lane(lane), depth + 1, true, current);
                }
            }
        }
    }

    /// Point `j` of the first vertex's split samples of `kind` for the lanes of `mask`
    /// (each at its path's first vertex), one vector a dimension: the scalar code's points,
    /// the Sobol sampler's computed in lanes from each sample's pixel key and point (the
    /// other lanes' are never read).
    #[inline(always)]
    pub(super) fn split_points(
        &self,
        lanes: &PathLanes,
        mask: u32,
        kind: SplitKind,
        j: u32,
        buffers: &PacketBuffers,
    ) -> [F8; 4] {
        if mask == 0 {
            return [F8::ZERO; 4];
        }
        if self.settings.sampler == SamplerKind::Independent {
            let mut u = [[0.0f32; LANES]; 4];
            for lane in Lanes::new(mask) {
                let slot = &buffers.slots[lanes.sample[lane] as usize];
                let point = slot.split_points.point(kind, j);
                let p = slot.sampler.first_split_point(kind, point);
                for (dim, x) in u.iter_mut().zip(p) {
                    dim[lane] = x;
                }
            }
            return u.map(F8::from_array);
        }
        // Each lane's pixel key, stream and point in (low, high) halves, scrambled in lanes.
        let (mut key, mut stream, mut point) =
            ([[0u32; LANES]; 2], [0u32; LANES], [[0u32; LANES]; 2]);
        for lane in Lanes::new(mask) {
            let slot = &buffers.slots[lanes.sample[lane] as usize];
            let pixel_key = slot.sampler.split_pixel_key().unwrap_or_default();
            let (k, p) = slot.split_points.point(kind, j);
            (key[0][lane], key[1][lane]) = (pixel_key as u32, (pixel_key >> 32) as u32);
            (point[0][lane], point[1][lane]) = (p as u32, (p >> 32) as u32);
            stream[lane] = k;
        }
        let key = [U8::from_array(key[0]), U8::from_array(key[1])];
        let point = [U8::from_array(point[0]), U8::from_array(point[1])];
        let (rev, seed) = first_split_sobol_lanes(kind, key, U8::from_array(stream), point);
        sobol_4d_lanes(rev, seed)
    }

    /// The lights the lanes of `round` choose with numbers `u_select` (in lanes where
    /// lights are selected by power, else lane by lane), their selection probabilities, and
    /// the lanes that chose one.
    #[inline(always)]
    pub(super) fn select_lights(&self, v: &Vertices, round: u32, u_select: F8) -> (U8, F8, u32) {
        if let Some(selection) = self.lane_selection {
            let (light, p) = selection.select(u_select);
            return (light, p, round);
        }
        let (mut light, mut p_select, mut chosen) = ([0u32; LANES], [0.0f32; LANES], 0u32);
        for lane in Lanes::new(round) {
            let (p, n) = (v.p.lane(lane), v.frame[2].lane(lane));
            if let Some((index, p)) = self.world.lights.select(u_select.lane(lane), p, n) {
                (light[lane], p_select[lane]) = (index as u32, p);
                chosen |= 1 << lane;
            }
        }
        (U8::from_array(light), F8::from_array(p_select), chosen)
    }

    /// The scalar code's sample of light `index` (chosen with probability `p_select`) at
    /// numbers `u_light` for scattering lane `lane`, into `out`.
    #[inline(always)]
    pub(super) fn scalar_light_sample(
        &self,
        v: &Vertices,
        lane: usize,
        index: usize,
        p_select: f32,
        u_light: Vec2,
        out: &mut ScalarLightSamples,
    ) {
        let (p, ng) = (v.p.lane(lane), v.ng.lane(lane));
        let Some(ls) = sample_chosen_light(self.world, self.settings, p, Some(ng), index, u_light)
        else {
            return;
        };
        (out.wi[lane], out.radiance[lane]) = (ls.wi, ls.radiance);
        out.p_light[lane] = p_select * ls.pdf;
        let origin = v.origin.lane(lane);
        out.shadow[lane] = ls.shadow_ray(origin, 0.0);
        if ls.delta {
            out.delta |= 1 << lane;
        }
        out.sampled |= 1 << lane;
    }
}
