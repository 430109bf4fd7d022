//! One bounce of the paths in lanes: their hits shaded (in lanes where the mesh allows,
//! else by the scalar code), light samples taken, BSDFs sampled, roulette played, and the
//! paths continued in their lanes or ended.

use super::super::estimator::{RayCounts, emitters_at_infinity, surface_emitter};
use super::PacketTracer;
use super::shading::{Dim, NO_BSDF, Shading, Vertices};
use super::state::{LaneState, PacketBuffers, Path, PathLanes};
use super::weights::roulette_survival;
use crate::geometry::cone::RayCone;
use crate::geometry::ray::{Ray, offset_ray_origin_lanes_within};
use crate::geometry::triangle::Lanes;
use crate::material::lanes::BsdfLanes;
use crate::material::{self, Bsdf, BsdfStorage};
use crate::sampling::sampler::{SamplerKind, SplitKind, sobol_4d_lanes, vertex_seeds_lanes};
use crate::simd::{F8, LANES, M8, U8, V3};
use glam::Vec3;

impl<'a, const EMITTERS: bool> PacketTracer<'a, EMITTERS> {
    /// Traces the active lanes' rays and takes their paths one bounce on: emitters found,
    /// light samples at the new vertices, and the continuations (into the same lane, or
    /// waiting for one when the first vertex splits).
    #[inline(always)]
    pub(super) fn bounce(
        &self,
        lanes: &mut PathLanes,
        active: &mut u32,
        shading: &mut Shading,
        layered: &mut [BsdfStorage; LANES],
        buffers: &mut PacketBuffers,
        rays: &mut RayCounts,
    ) {
        let world = self.world;
        let max_depth = self.settings.max_depth.unwrap_or(u32::MAX);
        rays.closest += active.count_ones() as u64;
        // A set mask lane is all ones, -1: subtracting it counts one ray.
        lanes.rays = lanes.rays - M8::from_bits(*active).as_u8();
        let mut bsdfs = [NO_BSDF; LANES];
        let mut storage = layered.each_mut().map(Some);
        let (mut scatter, mut lane_shaded) = (0u32, 0u32);
        let hits = world.intersect_lanes(&lanes.ray, *active);
        // Ray cones are followed only where textures are filtered by them.
        let cones = world.footprints.on();
        for lane in Lanes::new(*active) {
            let (sample, depth) = (lanes.sample[lane], lanes.depth.lane(lane));
            let slot = &mut buffers.slots[sample as usize];
            self.count_part_ray(slot, depth, true);
            let Some(hit) = hits[lane] else {
                if EMITTERS {
                    emitters_at_infinity(world, lanes.ray.dir.lane(lane), |e| {
                        self.reached_emitter(&lanes.state(lane), e, slot)
                    });
                }
                *active &= !(1 << lane);
                self.end_path(lanes, lane, buffers);
                continue;
            };
            let camera_ray = depth == 0 && lanes.branch[lane] == 0;
            if cones {
                lanes
                    .arrived
                    .set_lane(lane, hit.t * lanes.ray.dir.lane(lane).length());
            }
            if let Some((mesh, tri)) = world.surfaces.hit_triangle(&hit)
                && let Some(bsdf) = &self.mesh_bsdfs[mesh as usize]
            {
                // A surface of one BSDF that does not emit: its shading point is taken in
                // lanes (`vertices`); the other hits take the scalar code's below. (One path
                // for both, through an enum of the two, costs 3 % more instructions.)
                if depth >= max_depth {
                    *active &= !(1 << lane);
                    self.end_path(lanes, lane, buffers);
                    continue;
                }
                if camera_ray {
                    slot.covered = true;
                }
                let mesh = &world.surfaces.meshes[mesh as usize];
                shading.triangles.set(lane, mesh, tri, &hit);
                bsdfs[lane] = *bsdf;
                scatter |= 1 << lane;
                lane_shaded |= 1 << lane;
                continue;
            }
            let ray = lanes.ray.ray(lane);
            let width = if cones {
                lanes.cone_width.lane(lane)
                    + lanes.cone_spread.lane(lane) * lanes.arrived.lane(lane)
            } else {
                0.0
            };
            let rough = lanes.prev_delta & (1 << lane) == 0;
            let it = world.interaction_in_cone(&ray, &hit, width, rough);
            if world.surfaces.scalar_only[it.material as usize] {
                // Glass (volumes, refraction) and filters: the scalar code, lane by lane.
                self.hand_off(lanes, lane, (ray, hit), slot, rays);
                *active &= !(1 << lane);
                self.end_path(lanes, lane, buffers);
                continue;
            }
            if EMITTERS && let Some(e) = surface_emitter(world, &it, &ray, hit.t) {
                self.reached_emitter(&lanes.state(lane), e, slot);
            }
            let lane_storage = storage[lane].take();
            let bsdf = (depth < max_depth)
                .then_some(lane_storage)
                .flatten()
                .map(|storage| {
                    let surfaces = &world.surfaces;
                    let m = &surfaces.materials[it.material as usize];
                    material::bsdf(m, &surfaces.textures, &it.attrs, storage)
                });
            // Coverage, as the scalar kernel's first hit records it.
            if camera_ray && bsdf.is_some() {
                slot.covered = true;
            }
            match bsdf {
                Some(b) if !b.is_black() => {
                    shading.scalar.set(lane, &it);
                    bsdfs[lane] = b;
                    scatter |= 1 << lane;
                }
                _ => {
                    *active &= !(1 << lane);
                    self.end_path(lanes, lane, buffers);
                }
            }
        }
        if scatter == 0 {
            return;
        }
        shading.lane_shaded = lane_shaded;
        let v = self.vertices(lanes, shading, &bsdfs, scatter, buffers);
        self.light_samples(lanes, &v, buffers, rays);
        self.continue_paths(lanes, active, &v, buffers);
    }

    /// The scattering lanes' shading points in lanes, their BSDFs and random numbers.
    #[inline(always)]
    pub(super) fn vertices<'b>(
        &self,
        lanes: &PathLanes,
        shading: &Shading,
        bsdfs: &'b [Bsdf<'b>; LANES],
        mask: u32,
        buffers: &mut PacketBuffers,
    ) -> Vertices<'b> {
        let first = lanes.depth.eq(U8::splat(0)).bits() & mask;
        if self.learning {
            for lane in Lanes::new(first) {
                buffers.slots[lanes.sample[lane] as usize].parts.split = true;
            }
        }
        // Every lane's numbers (those of lanes outside `mask` are never read).
        let numbers = if self.settings.sampler == SamplerKind::Sobol {
            let branch = U8::from_array(lanes.branch);
            let [a, b] = vertex_seeds_lanes(lanes.sobol_seed, lanes.depth, branch);
            let a = sobol_4d_lanes(lanes.sobol_rev, a);
            let b = sobol_4d_lanes(lanes.sobol_rev, b);
            // VertexSample::from_sets: set a's four numbers, then set b's first three.
            [a[0], a[1], a[2], a[3], b[0], b[1], b[2]]
        } else {
            let mut scalar = [[0.0f32; LANES]; Dim::COUNT];
            for lane in Lanes::new(mask) {
                let slot = &mut buffers.slots[lanes.sample[lane] as usize];
                let (depth, branch) = (lanes.depth.lane(lane), lanes.branch[lane]);
                Dim::set(&mut scalar, lane, &slot.sampler.vertex(depth, branch));
            }
            scalar.map(F8::from_array)
        };
        // The other lanes' directions as +z (never read, but finite).
        let dir = V3::select(M8::from_bits(mask), lanes.ray.dir, V3::splat(Vec3::Z));
        let points = shading.lanes(mask, dir);
        let origin = offset_ray_origin_lanes_within(points.p, points.ng, points.magnitude);
        let mut v = Vertices {
            mask,
            first,
            p: points.p,
            origin,
            ng: points.ng,
            frame: points.frame,
            wo: V3::ZERO,
            bsdf: BsdfLanes::new(bsdfs, mask),
            numbers,
        };
        v.wo = v.to_local(-dir);
        v
    }

    /// Samples the BSDF at every scattering lane for its continuations (the first vertex's
    /// split count at depth 0), with Russian roulette: the first continuation takes over its
    /// parent's lane (updated in place), the others wait for a lane; lanes whose paths end
    /// are freed.
    #[inline(always)]
    pub(super) fn continue_paths(
        &self,
        lanes: &mut PathLanes,
        active: &mut u32,
        v: &Vertices,
        buffers: &mut PacketBuffers,
    ) {
        let counts = self.split.at(0);
        let footprints = self.world.footprints;
        let rounds = v.rounds(v.mask, counts.bsdf);
        // The parents' throughputs: the first round updates their lanes.
        let beta = lanes.beta;
        let n_bsdf = v.counts(counts.bsdf);
        let weight = F8::ONE / n_bsdf;
        // Shadow rays each vertex sent (the first vertex's split count, one deeper).
        let nee_count = U8::select(M8::from_bits(v.first), U8::splat(counts.nee), U8::splat(1));
        let mut continued = 0u32;
        for k in 0..rounds {
            let round = v.round_lanes(v.mask, k, counts.bsdf);
            let split = if counts.bsdf > 1 { round & v.first } else { 0 };
            let points = self.split_points(lanes, split, SplitKind::Bsdf, k, buffers);
            let own = [Dim::BSDF_X, Dim::BSDF_Y, Dim::LOBE, Dim::RR];
            let split_lanes = M8::from_bits(split);
            let mut u = [F8::ZERO; 4];
            for ((u, p), d) in u.iter_mut().zip(points).zip(own) {
                *u = F8::select(split_lanes, p, v.numbers[d]);
            }
            // SAFETY: this function runs inside `render_lanes`, on a CPU with AVX2 and FMA.
            let s = unsafe { v.bsdf.sample(v.wo, u[2], [u[0], u[1]], round) };
            let wi = v.to_world(s.wi);
            let ok = (s.valid & wi.dot(v.ng).gt(F8::ZERO)).bits() & round;
            let new_beta = beta * s.weight * weight;
            // Rounds past the first are the first vertex's: their children are at depth 1.
            let depth = if k == 0 {
                lanes.depth + U8::splat(1)
            } else {
                U8::splat(1)
            };
            // Roulette, as the scalar kernel's: a lane survives with probability `survival`
            // where it is below 1, its throughput divided by it, and only a throughput with a
            // positive channel goes on.
            let survival = roulette_survival(self.settings.rr, new_beta.luminance(), depth);
            let roulette = survival.lt(F8::ONE);
            let b = V3::select(roulette, new_beta / survival, new_beta);
            let zero = F8::ZERO;
            let positive = b.x.gt(zero) | b.y.gt(zero) | b.z.gt(zero);
            let alive = ok & ((!roulette | u[3].lt(survival)) & positive).bits();
            let (pdf, delta) = (s.pdf * n_bsdf, s.delta.bits());
            // The continued rays' cones (`RayCone::scattered` in lanes).
            let (cone_width, cone_spread) = if footprints.on() {
                let lobe = (F8::splat(std::f32::consts::FRAC_1_PI) / s.pdf).sqrt()
                    * F8::splat(footprints.lobe_scale);
                let widened = F8::select(
                    s.pdf.gt(F8::ZERO),
                    lanes.cone_spread.max(lobe),
                    lanes.cone_spread,
                );
                (
                    lanes.cone_width + lanes.cone_spread * lanes.arrived,
                    F8::select(s.delta, lanes.cone_spread, widened),
                )
            } else {
                (lanes.cone_width, lanes.cone_spread)
            };
            if k == 0 {
                // The paths go on in their lanes.
                let m = M8::from_bits(alive);
                lanes.ray.origin.merge(m, v.origin);
                lanes.ray.dir.merge(m, wi);
                lanes.ray.tmax.merge(m, F8::splat(f32::INFINITY));
                lanes.beta.merge(m, b);
                lanes.prev_p.merge(m, v.p);
                lanes.prev_n.merge(m, v.frame[2]);
                lanes.prev_pdf.merge(m, pdf);
                lanes.prev_delta = (lanes.prev_delta & !alive) | (delta & alive);
                lanes.depth.merge(m, depth);
                lanes.prev_nee_count.merge(m, nee_count);
                if footprints.on() {
                    lanes.cone_width.merge(m, cone_width);
                    lanes.cone_spread.merge(m, cone_spread);
                }
                continued = alive;
                continue;
            }
            // The first vertex's further BSDF paths wait for lanes.
            for lane in Lanes::new(alive) {
                let sample = lanes.sample[lane];
                buffers.slots[sample as usize].paths += 1;
                buffers.waiting.push(Path {
                    ray: Ray::new(v.origin.lane(lane), wi.lane(lane)),
                    state: LaneState {
                        beta: b.lane(lane),
                        depth: 1,
                        branch: k,
                        prev_p: v.p.lane(lane),
                        prev_n: v.frame[2].lane(lane),
                        prev_pdf: pdf.lane(lane),
                        prev_delta: delta & (1 << lane) != 0,
                        prev_nee_count: counts.nee,
                        cone: RayCone {
                            width: cone_width.lane(lane),
                            spread: cone_spread.lane(lane),
                        },
                    },
                    sample,
                });
            }
        }
        for lane in Lanes::new(v.mask & !continued) {
            *active &= !(1 << lane);
            self.end_path(lanes, lane, buffers);
        }
    }
}
