//! The packet kernel: the path tracer of [`super::path`] run on eight paths at a time, one
//! a SIMD lane (AVX2), for renders whose only light layer is the beauty. The render plan
//! chooses it where some material has a GGX lobe or some mesh a uniform material (see
//! `render::plan::Kernel::packet`); `--plan packet` and `--plan scalar` force one kernel or
//! the other.
//!
//! Why a second loop: one path at a time evaluates a BSDF, MIS weights and roulette for
//! one vertex with scalar instructions and a branch per decision. Eight paths in lanes do
//! it for eight vertices with one instruction stream, as Mitsuba 3's `llvm` variants and
//! pbrt-v4's wavefront integrator do at larger widths. In lanes are: the vertices' Sobol
//! sets (`sampling::sampler::sobol_4d_lanes`), light selection by power and the area
//! samples of triangle lights and sphere cones (`light::lanes`), the shading points of
//! meshes whose material is the same all over and does not emit (`world::lanes`), the
//! BSDFs of those materials (`material::lanes`), roulette and the MIS weights
//! (`weights`), the rays, traced as packets of eight (`World::intersect_lanes`,
//! `World::occluded_lanes`), and camera samples of a pinhole camera through the box filter
//! (`Camera::pinhole_rays_lanes`). The other shading points and the other lights' samples
//! go through the scalar code lane by lane, so every scene the scalar kernel renders
//! renders here too; paths that reach glass or a filter are handed to the scalar kernel.
//!
//! The estimator is the scalar kernel's, sample for sample (`integrator::estimator` states
//! the rule): every path takes the same random numbers (the sampler is a pure function of
//! pixel, sample index, depth and branch), the same first-vertex split and the same
//! roulette, and the lanes perform the scalar code's operations in its order (see
//! `material::lanes`), so the paths are the scalar kernel's to the bit and an image differs
//! only by the order in which a pixel's samples are summed; `tests/it/plan.rs` compares the
//! two.
//!
//! Lanes are refilled as paths end: first with the branches a split first vertex left
//! waiting, then with the next camera sample of the tile, so lanes stay busy whatever the
//! path lengths. Between bounces the paths stay in lanes (`state::PathLanes`, a field a
//! vector): a bounce reads rays and throughputs as vectors, and roulette and the
//! continuation are selects, not eight records gathered and written back. A camera
//! sample's value is complete when its last path ends; it then goes to its pixel's
//! accumulator as the scalar kernel's samples do.
//!
//! Files: this one (the kernel, its camera samples and their slots), `state` (paths in
//! lanes, samples in flight, a thread's buffers), `shading` (a bounce's shading points and
//! scattering vertices), `bounce` (shading, BSDF sampling and the continuation of a
//! bounce), `lights` (light selection, light samples and shadow rays in lanes), `weights`
//! (roulette and MIS in lanes).

mod bounce;
mod lights;
mod shading;
mod state;
mod weights;

use super::estimator::{Emitter, PathState, RayCounts};
use super::mis::Technique;
use super::path::PathTracer;
use super::settings::Settings;
use super::split::{FirstSplit, SampleParts};
use crate::film::filter::PixelFilter;
use crate::geometry::Hit;
use crate::geometry::ray::Ray;
use crate::light::lanes::{self as light_lanes, AreaLights, PowerSelection};
use crate::material::{Bsdf, BsdfStorage};
use crate::sampling::sampler::{Sampler, sobol_4d_lanes};
use crate::simd::{F8, LANES, U8};
use crate::world::World;
use glam::{Vec2, Vec3};
use shading::Shading;
use state::{CameraPaths, LaneState, NO_PATH, Path, PathLanes, SampleSlot, SlotRecorder};
pub use state::{PacketBuffers, PixelWork};
use std::sync::atomic::{AtomicBool, Ordering};

/// The packet kernel over a world with given settings; `EMITTERS` as in
/// [`super::path::PathTracer`].
pub struct PacketTracer<'a, const EMITTERS: bool> {
    world: &'a World,
    settings: &'a Settings,
    split: FirstSplit,
    /// The scalar kernel, which takes over the paths that reach glass or a filter.
    scalar: PathTracer<'a, EMITTERS, false>,
    filter: &'a PixelFilter,
    /// A sampler of the render's kind and seed, which camera samples start from.
    sampler: Sampler,
    /// The area lights the lanes sample; `None` where none is (no triangle or sphere light
    /// of untextured emission, or none of the kinds the lanes sample under the render's
    /// light sampling).
    area_lights: Option<&'a AreaLights>,
    /// The kinds of light the lanes sample (`light::lanes::TRIANGLES`, `SPHERES`):
    /// triangles unless sampled by solid angle, spheres where sampled in their cones.
    lane_light_kinds: u32,
    /// Where lights are selected by power: the lanes' selection (the scalar code's
    /// `LightSet::select` lane by lane otherwise).
    lane_selection: Option<&'a PowerSelection>,
    /// Whether the pass learns the split counts (`split` is then `FirstSplit::learning`):
    /// samples record their parts as the scalar kernel's do.
    learning: bool,
    /// By mesh, the BSDF of a mesh whose shading points the lanes compute
    /// (`Surfaces::uniform_bsdf`); the others go through `World::interaction` lane by lane.
    mesh_bsdfs: Vec<Option<Bsdf<'static>>>,
}

impl<'a, const EMITTERS: bool> PacketTracer<'a, EMITTERS> {
    /// The kernel for `world`; `split` says how the first vertex splits, `filter` places
    /// camera samples; `learning` passes record what the first vertex's parts bring back
    /// (into [`PacketBuffers::pixel_parts`] and [`PacketBuffers::split_stats`]).
    pub fn new(
        world: &'a World,
        settings: &'a Settings,
        split: FirstSplit,
        learning: bool,
        filter: &'a PixelFilter,
    ) -> Self {
        let sampling = settings.light_sampling;
        let lane_light_kinds = if sampling.triangles_by_solid_angle() {
            0
        } else {
            light_lanes::TRIANGLES
        } | if sampling.spheres_by_cone() {
            light_lanes::SPHERES
        } else {
            0
        };
        Self {
            world,
            settings,
            split,
            learning,
            filter,
            sampler: Sampler::new(settings.sampler, settings.seed),
            area_lights: Some(world.area_lights()).filter(|t| t.any(lane_light_kinds)),
            lane_light_kinds,
            lane_selection: world.area_lights().selection(),
            mesh_bsdfs: world
                .surfaces
                .meshes
                .iter()
                .map(|m| world.surfaces.uniform_bsdf(m))
                .collect(),
            scalar: PathTracer::new(world, settings, None, split),
        }
    }

    /// Lane `lane`'s path, whose ray `ray` found `hit` on glass or a filter, followed to its
    /// end by the scalar kernel (the same random numbers, so the same estimate): what it
    /// brings back, its rays and (in a pass that learns the split) its parts go to its
    /// sample's slot.
    #[inline(never)]
    fn hand_off(
        &self,
        lanes: &PathLanes,
        lane: usize,
        (ray, hit): (Ray, Hit),
        slot: &mut SampleSlot,
        rays: &mut RayCounts,
    ) {
        let state = lanes.state(lane);
        let mut rec = SlotRecorder::default();
        let mut walked = RayCounts::default();
        if self.learning && state.depth > 0 {
            slot.parts.current = state.branch as usize;
        }
        let parts = self.learning.then_some(&mut slot.parts);
        self.scalar.continue_from(
            ray,
            hit,
            state,
            (slot.pixel, slot.split_points),
            &mut slot.sampler,
            &mut rec,
            &mut walked,
            parts,
        );
        slot.value += rec.value;
        slot.discarded += rec.discarded;
        slot.covered |= rec.covered;
        let traced = walked.closest + walked.shadow;
        slot.rays += traced;
        rays.add(&walked);
        if self.learning {
            // The scalar walk marks its first vertex's light samples in the parts' rays.
            if state.depth == 0 {
                let [_, at_vertex, after_light, _] = slot.parts.rays;
                slot.part_rays[1] += after_light - at_vertex;
                slot.part_rays[2] += traced - (after_light - at_vertex);
            } else {
                slot.part_rays[2] += traced;
            }
        }
    }

    /// Takes the samples `work` lists, in pixel order, adding each finished sample to its
    /// pixel's accumulator in `buffers`; stops starting pixels once `interrupt` is set.
    /// Returns the samples taken. Panics where
    /// [`super::packet_kernel_available`] is false.
    pub fn render(
        &self,
        work: &[PixelWork],
        buffers: &mut PacketBuffers,
        rays: &mut RayCounts,
        interrupt: Option<&AtomicBool>,
    ) -> u64 {
        assert!(
            super::packet_kernel_available(),
            "the packet kernel needs AVX2 and FMA"
        );
        // SAFETY: the CPU has AVX2 and FMA (checked above), which is all `render_lanes`
        // and the `simd` types need.
        unsafe { self.render_lanes(work, buffers, rays, interrupt) }
    }

    #[target_feature(enable = "avx2,fma")]
    fn render_lanes(
        &self,
        work: &[PixelWork],
        buffers: &mut PacketBuffers,
        rays: &mut RayCounts,
        interrupt: Option<&AtomicBool>,
    ) -> u64 {
        let mut lanes = PathLanes::new();
        let mut cameras = CameraPaths::new();
        let mut shading = Shading::new();
        // Where lanes the scalar code shades build a layered BSDF, reused bounce to bounce.
        let mut layered: [BsdfStorage; LANES] = Default::default();
        let mut active = 0u32;
        let (mut item, mut next) = (0usize, 0u32);
        // Checked at every pixel's start, as the scalar loop does.
        let interrupted = || interrupt.is_some_and(|f| f.load(Ordering::Relaxed));
        let mut stopped = interrupted();
        let mut taken = 0u64;
        loop {
            let mut free = !active & 0xff;
            while free != 0 {
                let lane = free.trailing_zeros() as usize;
                let path = match buffers.waiting.pop() {
                    Some(p) => p,
                    None => {
                        if cameras.is_empty() {
                            // The next camera samples, up to eight, started at once: the
                            // next of this pixel, or of the next pixels.
                            let mut starts = [(0usize, 0u32); LANES];
                            let mut count = 0;
                            while count < LANES {
                                while !stopped && item < work.len() && next == work[item].count {
                                    (item, next) = (item + 1, 0);
                                    stopped = interrupted();
                                }
                                if stopped || item == work.len() {
                                    break;
                                }
                                starts[count] = (item, work[item].first + next);
                                (next, count) = (next + 1, count + 1);
                            }
                            taken += count as u64;
                            self.camera_paths(work, &starts[..count], buffers, &mut cameras);
                        }
                        match cameras.pop() {
                            Some(p) => p,
                            None => break,
                        }
                    }
                };
                let sampler = &buffers.slots[path.sample as usize].sampler;
                lanes.set(lane, &path, sampler.sobol_key().unwrap_or_default());
                active |= 1 << lane;
                free &= free - 1;
            }
            if active == 0 {
                return taken;
            }
            self.bounce(
                &mut lanes,
                &mut active,
                &mut shading,
                &mut layered,
                buffers,
                rays,
            );
        }
    }

    /// Starts the camera samples `starts` (items of `work` and sample indices), in order,
    /// into `out`: their slots, their numbers (Sobol sets in lanes) and their camera rays
    /// (in lanes for a pinhole camera and the box filter).
    #[inline(always)]
    fn camera_paths(
        &self,
        work: &[PixelWork],
        starts: &[(usize, u32)],
        buffers: &mut PacketBuffers,
        out: &mut CameraPaths,
    ) {
        let mut u = [[0.0f32; LANES]; 4];
        let (mut rev, mut seed) = ([0u32; LANES], [0u32; LANES]);
        let mut centre = [[0.0f32; LANES]; 2];
        let mut sample = [0u32; LANES];
        for (lane, &(item, index)) in starts.iter().enumerate() {
            let w = &work[item];
            let mut sampler = self.sampler.clone();
            let (ix, iy) = self.world.camera.image_pixel(w.x, w.y);
            sampler.start(ix as u32, iy as u32, index);
            if let Some((r, s)) = sampler.camera_sobol() {
                (rev[lane], seed[lane]) = (r, s);
            } else {
                let cs = sampler.camera();
                (u[0][lane], u[1][lane]) = (cs.film.x, cs.film.y);
                (u[2][lane], u[3][lane]) = (cs.lens.x, cs.lens.y);
            }
            (centre[0][lane], centre[1][lane]) = (ix as f32 + 0.5, iy as f32 + 0.5);
            sample[lane] = self.start_slot(w, index, sampler, buffers);
        }
        let u = if self.sampler.camera_sobol().is_some() {
            sobol_4d_lanes(U8::from_array(rev), U8::from_array(seed))
        } else {
            u.map(F8::from_array)
        };
        let (x, y) = match self.filter {
            PixelFilter::Box => {
                let half = F8::splat(0.5);
                let (cx, cy) = (F8::from_array(centre[0]), F8::from_array(centre[1]));
                (cx + (u[0] - half), cy + (u[1] - half))
            }
            filter => {
                let (ux, uy) = (u[0].to_array(), u[1].to_array());
                let (mut x, mut y) = ([0.0f32; LANES], [0.0f32; LANES]);
                for lane in 0..starts.len() {
                    let offset = filter.sample(Vec2::new(ux[lane], uy[lane]));
                    let film = Vec2::new(centre[0][lane], centre[1][lane]) + offset;
                    (x[lane], y[lane]) = (film.x, film.y);
                }
                (F8::from_array(x), F8::from_array(y))
            }
        };
        let camera = &self.world.camera;
        let mut rays = [NO_PATH.ray; LANES];
        if let Some((origin, dir, tmax)) = camera.pinhole_rays_lanes(x, y) {
            let (origin, dir, tmax) = (origin.to_lanes(), dir.to_lanes(), tmax.to_array());
            for (lane, ray) in rays.iter_mut().enumerate().take(starts.len()) {
                *ray = Ray {
                    origin: origin[lane],
                    dir: dir[lane],
                    tmax: tmax[lane],
                    time: 0.0,
                };
            }
        } else {
            let (x, y) = (x.to_array(), y.to_array());
            let (lens_x, lens_y) = (u[2].to_array(), u[3].to_array());
            for (lane, ray) in rays.iter_mut().enumerate().take(starts.len()) {
                let lens = Vec2::new(lens_x[lane], lens_y[lane]);
                *ray = camera.generate_ray(Vec2::new(x[lane], y[lane]), lens);
            }
        }
        out.fill(starts.len(), |lane| Path {
            ray: rays[lane],
            state: LaneState::camera(rays[lane].origin, self.world.footprints.camera),
            sample: sample[lane],
        });
    }

    /// The slot of sample `index` of pixel `work`, whose numbers `sampler` gives.
    #[inline(always)]
    fn start_slot(
        &self,
        work: &PixelWork,
        index: u32,
        sampler: Sampler,
        buffers: &mut PacketBuffers,
    ) -> u32 {
        let slot = SampleSlot {
            pixel: work.in_tile,
            sampler,
            value: Vec3::ZERO,
            covered: false,
            paths: 1,
            rays: 0,
            discarded: 0,
            parts: SampleParts::default(),
            part_rays: [0; 3],
            split_points: self.split.sample_points((work.x, work.y), index),
        };
        match buffers.free.pop() {
            Some(i) => {
                buffers.slots[i as usize] = slot;
                i
            }
            None => {
                buffers.slots.push(slot);
                (buffers.slots.len() - 1) as u32
            }
        }
    }

    /// The path in lane `lane` ended: what it gathered goes to its sample, and the sample
    /// to its pixel once it has no path left.
    #[inline(always)]
    fn end_path(&self, lanes: &PathLanes, lane: usize, buffers: &mut PacketBuffers) {
        let sample = lanes.sample[lane];
        let slot = &mut buffers.slots[sample as usize];
        slot.value += lanes.value.lane(lane);
        slot.rays += u64::from(lanes.rays.lane(lane));
        slot.discarded += u64::from(lanes.discarded.lane(lane));
        slot.paths -= 1;
        if slot.paths == 0 {
            let pixel = &mut buffers.pixels[slot.pixel];
            pixel.add_sample(slot.value, slot.covered, slot.discarded);
            pixel.rays += slot.rays;
            if self.learning {
                // The scalar kernel's ray marks, as if the parts had been traced in turn.
                let [camera, nee, bsdf] = slot.part_rays;
                slot.parts.rays = [0, camera, camera + nee, camera + nee + bsdf];
                buffers.split_stats.add_rays(&slot.parts);
                buffers.pixel_parts[slot.pixel].add(&slot.parts);
            }
            buffers.free.push(sample);
        }
    }

    /// In a learning pass, adds a contribution to the sample's parts (as the scalar
    /// kernel's `record` does, before dropping a non-finite one): `depth` and `by_light`
    /// as `SampleParts::add` takes them, `current` the first vertex's light estimate or
    /// BSDF path it belongs to.
    #[inline(always)]
    fn learn(&self, slot: &mut SampleSlot, value: Vec3, depth: u32, by_light: bool, current: u32) {
        if self.learning {
            slot.parts.current = current as usize;
            slot.parts.add(value, depth, by_light);
        }
    }

    /// In a learning pass, counts a ray of a path at `depth` to its part: a closest-hit ray
    /// (`closest`) or a light sample's shadow ray.
    #[inline(always)]
    fn count_part_ray(&self, slot: &mut SampleSlot, depth: u32, closest: bool) {
        if self.learning {
            let part = match (depth, closest) {
                (0, true) => 0,
                (0, false) => 1,
                _ => 2,
            };
            slot.part_rays[part] += 1;
        }
    }

    /// Adds a contribution to its sample; a non-finite one is dropped and counted, as the
    /// scalar kernel's record does.
    #[inline(always)]
    fn contribute(slot: &mut SampleSlot, value: Vec3) {
        if value.is_finite() {
            slot.value += value;
        } else {
            slot.discarded += 1;
        }
    }

    /// The path reached emitter `e`: seen directly, or found by BSDF sampling and weighted
    /// against light sampling (as `path::PathState::reached_emitter`).
    #[inline(always)]
    fn reached_emitter(&self, path: &PathState, e: Emitter, slot: &mut SampleSlot) {
        let value = path.beta * e.le;
        if path.depth == 0 {
            self.learn(slot, value, 0, false, 0);
            Self::contribute(slot, value);
            return;
        }
        let p_light = path.light_density(self.world, self.settings, None, &e);
        let w = self
            .settings
            .mis
            .weight(Technique::Bsdf, path.prev_pdf, p_light);
        self.learn(slot, value * w, path.depth, false, path.branch);
        Self::contribute(slot, value * w);
    }
}
