//! The packet kernel: the path tracer of [`super::path`] run on eight paths at a time, one
//! a SIMD lane (AVX2), for renders whose only light layer is the beauty. The render plan
//! chooses it where some material has a GGX lobe (see `render::plan::Kernel::packet`); `--plan
//! packet` and `--plan scalar` force one kernel or the other.
//!
//! Why a second loop: one path at a time evaluates a BSDF, MIS weights and roulette for
//! one vertex with scalar instructions and a branch per decision. Eight paths in lanes do
//! it for eight vertices with one instruction stream, as Mitsuba 3's `llvm` variants and
//! pbrt-v4's wavefront integrator do at larger widths; on the MIS plates (GGX plates, five
//! shadow rays a first vertex) that saves 13 % of the instructions. The vertices' Sobol
//! sets (`sampling::sampler::sobol_4d_lanes`) and the area samples of triangle lights
//! (`light::lanes`) are taken in lanes too: 6 % fewer of the Cornell box's instructions
//! (`--plan packet`), though its time stays within the noise of the scalar kernel's. So are
//! the shading points of triangles whose material is the same all over and does not emit
//! (`world::lanes`): with the mends around them, 17 % fewer of the Cornell box's
//! instructions (988 M to 823 M at 64×64, 16 spp), and 17 % less time than the scalar
//! kernel. The lanes' rays are traced as packets of eight (`World::intersect_lanes`,
//! `World::occluded_lanes`): 5.6 % fewer of the Cornell box's instructions, with the same
//! hits. Sphere lights are sampled in their cones in lanes too (`light::lanes`): 15 % fewer
//! of the MIS plates' instructions, 23 % less time; and lights are selected by power in
//! lanes: 3.8 % fewer of the Cornell box's instructions, 3 % fewer of the plates'. Camera
//! samples start eight at a time (their Sobol sets, and a pinhole camera's rays through
//! the box filter, in lanes; `Camera::pinhole_rays_lanes`) and wait for lanes in order:
//! 4.7 % fewer of the plates' instructions, 1.6 % fewer of the Cornell box's. The other
//! shading points and the other lights' samples go through the scalar code lane by lane,
//! so every scene the scalar kernel renders renders here too.
//!
//! The estimator is the scalar kernel's, sample for sample: every path takes the same
//! random numbers (the sampler is a pure function of pixel, sample index, depth and
//! branch), the same first-vertex split and the same roulette, and the lanes perform the
//! scalar code's operations in its order (see `material::lanes`), so the paths are the
//! scalar kernel's to the bit and an image differs only by the order in which a pixel's
//! samples are summed; `tests/plan.rs` compares the two.
//!
//! Lanes are refilled as paths end: first with the branches a split first vertex left
//! waiting, then with the next camera sample of the tile, so lanes stay busy whatever the
//! path lengths. Between bounces the paths stay in lanes (`PathLanes`, a field a vector):
//! a bounce reads rays and throughputs as vectors, and roulette and the continuation are
//! selects, not eight records gathered and written back (the Cornell box: 5 % fewer
//! instructions, the MIS plates 2 %). A camera sample's value is complete when its last
//! path ends; it then goes to its pixel's accumulator as the scalar kernel's samples do.

use super::estimator::{
    Emitter, PathState, RayCounts, emitters_at_infinity, sample_chosen_light, surface_emitter,
};
use super::media::Media;
use super::mis::{Mis, Technique};
use super::path::PathTracer;
use super::roulette::{ROULETTE_CAP, ROULETTE_CAP_DEPTH, RussianRoulette};
use super::settings::Settings;
use super::split::{FirstSplit, PixelParts, SampleParts, SamplePoints, SplitStats};
use crate::film::PixelAccumulator;
use crate::film::filter::PixelFilter;
use crate::film::record::{Contribution, FirstHit, Recorder};
use crate::geometry::Hit;
use crate::geometry::ray::{Ray, RayLanes, offset_ray_origin_lanes};
use crate::geometry::triangle::Lanes;
use crate::light::lanes::{self as light_lanes, AreaLights, PowerSelection};
use crate::material::lambert::Lambert;
use crate::material::lanes::BsdfLanes;
use crate::material::{self, Bsdf, BsdfStorage};
use crate::sampling::sampler::{
    Sampler, SamplerKind, SplitKind, VertexSample, first_split_sobol_lanes, sobol_4d_lanes,
    vertex_seeds_lanes,
};
use crate::simd::{F8, LANES, M8, U8, V3};
use crate::world::lanes::{ShadingLanes, TriangleHits};
use crate::world::{Interaction, World};
use glam::{Vec2, Vec3};
use std::sync::atomic::{AtomicBool, Ordering};

/// A pixel's share of a pass: where it lies and which of its samples to take.
#[derive(Clone, Copy, Debug)]
pub struct PixelWork {
    /// Index in the tile, row-major.
    pub in_tile: usize,
    pub x: u32,
    pub y: u32,
    /// Index of its first sample, and how many.
    pub first: u32,
    pub count: u32,
}

/// A path waiting for a lane (a camera sample's, or a branch of a split first vertex): the
/// ray it follows, its state, and the camera sample it belongs to.
#[derive(Clone, Copy, Debug)]
struct Path {
    ray: Ray,
    state: LaneState,
    sample: u32,
}

/// The part of the scalar kernel's `PathState` that a path in a lane has: paths in lanes
/// record no lobe shares (the packet kernel renders the beauty alone) and meet no
/// transmissive surface, so they are in no volume and cross no filter.
#[derive(Clone, Copy, Debug)]
struct LaneState {
    beta: Vec3,
    depth: u32,
    branch: u32,
    prev_p: Vec3,
    prev_n: Vec3,
    prev_pdf: f32,
    prev_delta: bool,
    prev_nee_count: u32,
}

impl LaneState {
    /// The state of a camera path whose ray starts at `origin` (`PathState::camera`'s).
    #[inline(always)]
    fn camera(origin: Vec3) -> Self {
        let s = PathState::camera(origin);
        Self {
            beta: s.beta,
            depth: s.depth,
            branch: s.branch,
            prev_p: s.prev_p,
            prev_n: s.prev_n,
            prev_pdf: s.prev_pdf,
            prev_delta: s.prev_delta,
            prev_nee_count: s.prev_nee_count,
        }
    }
}

/// What idle lanes hold (never read).
const NO_PATH: Path = Path {
    ray: Ray {
        origin: Vec3::ZERO,
        dir: Vec3::Z,
        tmax: 0.0,
    },
    state: LaneState {
        beta: Vec3::ZERO,
        depth: 0,
        branch: 0,
        prev_p: Vec3::ZERO,
        prev_n: Vec3::ZERO,
        prev_pdf: 0.0,
        prev_delta: true,
        prev_nee_count: 1,
    },
    sample: 0,
};

/// The paths in the eight lanes, a field a vector (or an array of eight): what a bounce
/// reads in lanes (rays, throughputs, the previous vertices) is not gathered from eight
/// records, and a path continues in its lane by selects. Lanes are filled from [`Path`]
/// records (camera samples, split branches); the scalar code gets a lane's state back
/// ([`PathLanes::state`]). The packet kernel renders the beauty alone, so no lane records
/// lobe shares (`PathState::lobes` stays zero).
struct PathLanes {
    ray: RayLanes,
    beta: V3,
    prev_p: V3,
    prev_n: V3,
    prev_pdf: F8,
    /// Lanes whose previous vertex sampled a delta lobe.
    prev_delta: u32,
    depth: U8,
    branch: [u32; LANES],
    prev_nee_count: U8,
    /// Sample slot of each lane's path.
    sample: [u32; LANES],
    /// Each lane's sample's Sobol key ([`Sampler::sobol_key`]): its bit-reversed index and
    /// its pixel's seed (zero with the independent sampler).
    sobol_rev: U8,
    sobol_seed: U8,
    /// What each lane's path has brought back by light sampling, the rays it traced and
    /// the non-finite contributions it dropped, since it took its lane: added to its sample
    /// when it ends ([`PacketTracer::end_path`]) instead of lane by lane at every bounce.
    value: V3,
    rays: U8,
    discarded: U8,
}

impl PathLanes {
    /// Lanes holding [`NO_PATH`].
    #[inline(always)]
    fn new() -> Self {
        let mut lanes = Self {
            ray: RayLanes {
                origin: V3::ZERO,
                dir: V3::ZERO,
                tmax: F8::ZERO,
            },
            beta: V3::ZERO,
            prev_p: V3::ZERO,
            prev_n: V3::ZERO,
            prev_pdf: F8::ZERO,
            prev_delta: 0,
            depth: U8::splat(0),
            branch: [0; LANES],
            prev_nee_count: U8::splat(0),
            sample: [0; LANES],
            sobol_rev: U8::splat(0),
            sobol_seed: U8::splat(0),
            value: V3::ZERO,
            rays: U8::splat(0),
            discarded: U8::splat(0),
        };
        for lane in 0..LANES {
            lanes.set(lane, &NO_PATH, (0, 0));
        }
        lanes
    }

    /// Puts `path` in lane `lane`, with its sample's Sobol key `(rev, seed)`
    /// ([`Sampler::sobol_key`]).
    #[inline(always)]
    fn set(&mut self, lane: usize, path: &Path, (rev, seed): (u32, u32)) {
        let state = &path.state;
        self.ray.origin.set_lane(lane, path.ray.origin);
        self.ray.dir.set_lane(lane, path.ray.dir);
        self.ray.tmax.set_lane(lane, path.ray.tmax);
        self.beta.set_lane(lane, state.beta);
        self.prev_p.set_lane(lane, state.prev_p);
        self.prev_n.set_lane(lane, state.prev_n);
        self.prev_pdf.set_lane(lane, state.prev_pdf);
        let bit = 1 << lane;
        self.prev_delta = if state.prev_delta {
            self.prev_delta | bit
        } else {
            self.prev_delta & !bit
        };
        self.depth.set_lane(lane, state.depth);
        self.branch[lane] = state.branch;
        self.prev_nee_count.set_lane(lane, state.prev_nee_count);
        self.sample[lane] = path.sample;
        self.sobol_rev.set_lane(lane, rev);
        self.sobol_seed.set_lane(lane, seed);
        self.value.set_lane(lane, Vec3::ZERO);
        self.rays.set_lane(lane, 0);
        self.discarded.set_lane(lane, 0);
    }

    /// Lane `lane`'s path state, as the scalar code takes it.
    #[inline(always)]
    fn state(&self, lane: usize) -> PathState {
        PathState {
            beta: self.beta.lane(lane),
            depth: self.depth.lane(lane),
            branch: self.branch[lane],
            prev_p: self.prev_p.lane(lane),
            prev_n: self.prev_n.lane(lane),
            prev_pdf: self.prev_pdf.lane(lane),
            prev_delta: self.prev_delta & (1 << lane) != 0,
            prev_nee_count: self.prev_nee_count.lane(lane),
            lobes: [Vec3::ZERO; 3],
            // Paths in lanes meet no transmissive surface: their vertices are scattering
            // events in air.
            vertex: self.depth.lane(lane),
            media: Media::EMPTY,
            crossed: 0.0,
        }
    }
}

/// A camera sample in flight: its pixel, its random numbers and what its paths have
/// brought back so far.
#[derive(Clone, Debug)]
struct SampleSlot {
    /// Index in the tile.
    pixel: usize,
    sampler: Sampler,
    value: Vec3,
    covered: bool,
    /// Paths of the sample still running or waiting.
    paths: u32,
    rays: u64,
    discarded: u64,
    /// In a pass that learns the split counts: what the sample's parts brought back, and
    /// the rays of its camera ray, of its first vertex's light samples and of the rest.
    parts: SampleParts,
    part_rays: [u64; 3],
    /// Where its first vertex's split points lie.
    split_points: SamplePoints,
}

/// What a thread reuses from tile to tile: samples in flight, waiting paths, and the
/// tile's pixel accumulators.
pub struct PacketBuffers {
    slots: Vec<SampleSlot>,
    free: Vec<u32>,
    waiting: Vec<Path>,
    /// One accumulator per pixel of the tile (row-major), cleared by the caller.
    pub pixels: Vec<PixelAccumulator>,
    /// In a pass that learns the split counts: each pixel's learning samples (row-major,
    /// cleared by the caller) and the tile's rays by part.
    pub pixel_parts: Vec<PixelParts>,
    pub split_stats: SplitStats,
}

impl PacketBuffers {
    /// Buffers for tiles of `pixels` pixels.
    pub fn new(pixels: usize) -> Self {
        Self {
            slots: Vec::new(),
            free: Vec::new(),
            waiting: Vec::new(),
            pixels: (0..pixels)
                .map(|_| PixelAccumulator::new(1, false))
                .collect(),
            pixel_parts: vec![PixelParts::default(); pixels],
            split_stats: SplitStats::default(),
        }
    }
}

/// The BSDF of lanes that do not scatter (never read).
const NO_BSDF: Bsdf<'static> = Bsdf::Lambert(Lambert { albedo: Vec3::ZERO });

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

/// Shading points that the scalar code computed, lane by lane.
struct ScalarShading {
    p: [Vec3; LANES],
    ng: [Vec3; LANES],
    frame: [[Vec3; LANES]; 3],
}

impl ScalarShading {
    #[inline(always)]
    fn new() -> Self {
        Self {
            p: [Vec3::ZERO; LANES],
            ng: [Vec3::Z; LANES],
            frame: [[Vec3::X; LANES], [Vec3::Y; LANES], [Vec3::Z; LANES]],
        }
    }

    #[inline(always)]
    fn set(&mut self, lane: usize, it: &Interaction) {
        (self.p[lane], self.ng[lane]) = (it.p, it.ng);
        let [s, t, n] = &mut self.frame;
        (s[lane], t[lane], n[lane]) = (it.frame.s, it.frame.t, it.frame.n);
    }

    #[inline(always)]
    fn lanes(&self) -> ShadingLanes {
        let [s, t, n] = &self.frame;
        ShadingLanes {
            p: V3::from_lanes(&self.p),
            ng: V3::from_lanes(&self.ng),
            frame: [V3::from_lanes(s), V3::from_lanes(t), V3::from_lanes(n)],
        }
    }
}

/// A bounce's shading points: lanes the scalar code shaded, and triangle hits the lanes
/// shade. Reused from bounce to bounce, not cleared: only the lanes a bounce sets are read.
struct Shading {
    scalar: ScalarShading,
    triangles: TriangleHits,
    lane_shaded: u32,
}

impl Shading {
    #[inline(always)]
    fn new() -> Self {
        Self {
            scalar: ScalarShading::new(),
            triangles: TriangleHits::new(),
            lane_shaded: 0,
        }
    }

    /// The shading points of the lanes of `mask`, hit by rays of directions `dir`.
    #[inline(always)]
    fn lanes(&self, mask: u32, dir: V3) -> ShadingLanes {
        let lane_shaded = self.lane_shaded;
        if lane_shaded == 0 {
            return self.scalar.lanes();
        }
        let computed = self.triangles.shading(dir, lane_shaded);
        if lane_shaded == mask {
            return computed;
        }
        let (scalar, m) = (self.scalar.lanes(), M8::from_bits(lane_shaded));
        let [s, t, n] = computed.frame;
        ShadingLanes {
            p: V3::select(m, computed.p, scalar.p),
            ng: V3::select(m, computed.ng, scalar.ng),
            frame: [
                V3::select(m, s, scalar.frame[0]),
                V3::select(m, t, scalar.frame[1]),
                V3::select(m, n, scalar.frame[2]),
            ],
        }
    }
}

/// The lanes that scatter at a bounce: their shading points, BSDFs and random numbers.
struct Vertices<'b> {
    mask: u32,
    /// The scattering lanes at their path's first vertex (the one that splits).
    first: u32,
    /// Shading points, and the origins of the rays that leave them, in lanes.
    p: V3,
    origin: V3,
    ng: V3,
    frame: [V3; 3],
    wo: V3,
    bsdf: BsdfLanes<'b>,
    /// The lanes' random numbers (`VertexSample`'s), a dimension a vector: see [`Dim`].
    numbers: [F8; Dim::COUNT],
}

/// The dimensions of a vertex's random numbers in [`Vertices::numbers`]: the light
/// sample's point and choice, roulette, the BSDF sample's direction and lobe.
struct Dim;

impl Dim {
    const LIGHT_X: usize = 0;
    const LIGHT_Y: usize = 1;
    const LIGHT_SELECT: usize = 2;
    const RR: usize = 3;
    const BSDF_X: usize = 4;
    const BSDF_Y: usize = 5;
    const LOBE: usize = 6;
    const COUNT: usize = 7;

    /// Writes `vs` into lane `lane` of `numbers`.
    #[inline(always)]
    fn set(numbers: &mut [[f32; LANES]; Dim::COUNT], lane: usize, vs: &VertexSample) {
        let values = [
            vs.light.x,
            vs.light.y,
            vs.light_select,
            vs.rr,
            vs.bsdf.x,
            vs.bsdf.y,
            vs.lobe,
        ];
        for (dim, x) in numbers.iter_mut().zip(values) {
            dim[lane] = x;
        }
    }
}

impl Vertices<'_> {
    /// The lanes of `lanes` in round `j` of the first vertex's `count` samples: a deeper
    /// vertex takes one. Decided from masks, not lane by lane: the lanes' depths are
    /// unpredictable branches.
    #[inline(always)]
    fn round_lanes(&self, lanes: u32, j: u32, count: u32) -> u32 {
        let deeper = if j == 0 { lanes & !self.first } else { 0 };
        deeper | if j < count { lanes & self.first } else { 0 }
    }

    /// How many rounds the lanes of `lanes` take with `count` samples at the first vertex.
    #[inline(always)]
    fn rounds(&self, lanes: u32, count: u32) -> u32 {
        let deeper = u32::from(lanes & !self.first != 0);
        deeper.max(if lanes & self.first != 0 { count } else { 0 })
    }

    /// `count` in the first-vertex lanes, 1 in the others.
    #[inline(always)]
    fn counts(&self, count: u32) -> F8 {
        F8::select(M8::from_bits(self.first), F8::splat(count as f32), F8::ONE)
    }

    #[inline(always)]
    fn to_local(&self, v: V3) -> V3 {
        let [s, t, n] = self.frame;
        V3::new(v.dot(s), v.dot(t), v.dot(n))
    }

    #[inline(always)]
    fn to_world(&self, v: V3) -> V3 {
        let [s, t, n] = self.frame;
        s * v.x + t * v.y + n * v.z
    }
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
            sampler.start(w.x, w.y, index);
            if let Some((r, s)) = sampler.camera_sobol() {
                (rev[lane], seed[lane]) = (r, s);
            } else {
                let cs = sampler.camera();
                (u[0][lane], u[1][lane]) = (cs.film.x, cs.film.y);
                (u[2][lane], u[3][lane]) = (cs.lens.x, cs.lens.y);
            }
            (centre[0][lane], centre[1][lane]) = (w.x as f32 + 0.5, w.y as f32 + 0.5);
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
            state: LaneState::camera(rays[lane].origin),
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
        let p_light = path.light_density(self.world, self.settings, &e);
        let w = self
            .settings
            .mis
            .weight(Technique::Bsdf, path.prev_pdf, p_light);
        self.learn(slot, value * w, path.depth, false, path.branch);
        Self::contribute(slot, value * w);
    }

    /// Traces the active lanes' rays and takes their paths one bounce on: emitters found,
    /// light samples at the new vertices, and the continuations (into the same lane, or
    /// waiting for one when the first vertex splits).
    #[inline(always)]
    fn bounce(
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
            let it = world.interaction(&ray, &hit);
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
    fn vertices<'b>(
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
        let origin = offset_ray_origin_lanes(points.p, points.ng);
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

    /// Shadow rays towards the lights from every scattering lane (the first vertex's split
    /// count of them at depth 0, one deeper), each weighted by MIS against BSDF sampling.
    #[inline(always)]
    fn light_samples(
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
    fn split_points(
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
    fn select_lights(&self, v: &Vertices, round: u32, u_select: F8) -> (U8, F8, u32) {
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
    fn scalar_light_sample(
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
        out.shadow[lane] = match ls.target {
            Some(target) => Ray {
                origin,
                dir: target - origin,
                tmax: 1.0,
            },
            None => Ray::new(origin, ls.wi),
        };
        if ls.delta {
            out.delta |= 1 << lane;
        }
        out.sampled |= 1 << lane;
    }

    /// Samples the BSDF at every scattering lane for its continuations (the first vertex's
    /// split count at depth 0), with Russian roulette: the first continuation takes over its
    /// parent's lane (updated in place), the others wait for a lane; lanes whose paths end
    /// are freed.
    #[inline(always)]
    fn continue_paths(
        &self,
        lanes: &mut PathLanes,
        active: &mut u32,
        v: &Vertices,
        buffers: &mut PacketBuffers,
    ) {
        let counts = self.split.at(0);
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

/// Receives what a path handed to the scalar kernel brings back for its sample.
#[derive(Default)]
struct SlotRecorder {
    value: Vec3,
    discarded: u64,
    covered: bool,
}

impl Recorder for SlotRecorder {
    fn wants_single_technique(&self) -> bool {
        false
    }

    fn wants_lobes(&self) -> bool {
        false
    }

    fn contribution(&mut self, c: Contribution) {
        if c.value.is_finite() {
            self.value += c.value;
        } else {
            self.discarded += 1;
        }
    }

    fn first_hit(&mut self, _: Option<FirstHit>) {
        self.covered = true;
    }
}

/// Camera paths started together, waiting for lanes; taken in the order they started.
struct CameraPaths {
    paths: [Path; LANES],
    next: usize,
    len: usize,
}

impl CameraPaths {
    #[inline(always)]
    fn new() -> Self {
        Self {
            paths: [NO_PATH; LANES],
            next: 0,
            len: 0,
        }
    }

    #[inline(always)]
    fn is_empty(&self) -> bool {
        self.next == self.len
    }

    /// Replaces the (taken) paths with `count` new ones, `path(i)` the i-th.
    #[inline(always)]
    fn fill(&mut self, count: usize, path: impl Fn(usize) -> Path) {
        for (i, p) in self.paths.iter_mut().enumerate().take(count) {
            *p = path(i);
        }
        (self.next, self.len) = (0, count);
    }

    /// The next path in start order.
    #[inline(always)]
    fn pop(&mut self) -> Option<Path> {
        (self.next < self.len).then(|| {
            self.next += 1;
            self.paths[self.next - 1]
        })
    }
}

/// A round's light samples lane by lane: the scalar code's direction, radiance, density
/// (selection included) and delta lights; the shadow rays and sampling lanes of both the
/// scalar code's and the lanes' own samples.
struct ScalarLightSamples {
    wi: [Vec3; LANES],
    radiance: [Vec3; LANES],
    p_light: [f32; LANES],
    shadow: [Ray; LANES],
    sampled: u32,
    delta: u32,
}

impl ScalarLightSamples {
    #[inline(always)]
    fn new() -> Self {
        Self {
            wi: [Vec3::Z; LANES],
            radiance: [Vec3::ZERO; LANES],
            p_light: [1.0; LANES],
            shadow: [Ray::new(Vec3::ZERO, Vec3::Z); LANES],
            sampled: 0,
            delta: 0,
        }
    }
}

/// [`RussianRoulette::survival`] in lanes, with its operations: the probability that a
/// path of throughput luminance `luminance` goes on after `depth` scattering events.
#[inline(always)]
fn roulette_survival(rr: RussianRoulette, luminance: F8, depth: U8) -> F8 {
    match rr {
        RussianRoulette::Off | RussianRoulette::Efficiency(_) => F8::ONE,
        RussianRoulette::Fixed(p) => F8::splat(p),
        RussianRoulette::Throughput(threshold) => {
            let capped = depth.gt(U8::splat(ROULETTE_CAP_DEPTH));
            let cap = F8::select(capped, F8::splat(ROULETTE_CAP), F8::ONE);
            (luminance / F8::splat(threshold)).min(cap)
        }
    }
}

/// MIS weights of `technique` for the lanes of `lanes` (densities times sample counts):
/// the balance and default power heuristics in lanes, the others lane by lane.
#[inline(always)]
fn mis_weights(mis: Mis, technique: Technique, own: F8, other: F8, lanes: u32) -> F8 {
    let zero = F8::ZERO;
    let w = match mis {
        Mis::Balance => own / (own + other),
        Mis::Power(2.0) => {
            let q = other / own;
            F8::ONE / (F8::ONE + q * q)
        }
        _ => {
            let (o, t) = (own.to_array(), other.to_array());
            let mut w = [0.0; LANES];
            for lane in Lanes::new(lanes) {
                w[lane] = mis.weight(technique, o[lane], t[lane]);
            }
            return F8::from_array(w);
        }
    };
    let w = F8::select(other.gt(zero), w, F8::ONE);
    F8::select(own.gt(zero), w, zero)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lanes' survival probability is `RussianRoulette::survival`'s to the bit, for
    /// every kind of roulette, at depths on both sides of the cap and across it, and for
    /// zero, tiny, huge, infinite and NaN luminances.
    #[test]
    fn lane_roulette_is_the_scalar_roulette() {
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let luminances = [
            0.0,
            -0.0,
            1e-30,
            0.004,
            0.05,
            0.0999,
            0.1,
            0.35,
            0.95,
            1.0,
            7.5,
            1e30,
            f32::INFINITY,
            f32::NAN,
        ];
        let depths = [0, 1, 7, 8, 9, 10, 200, u32::MAX];
        let kinds = [
            RussianRoulette::Off,
            RussianRoulette::Fixed(0.3),
            RussianRoulette::Throughput(0.1),
            RussianRoulette::Throughput(0.01),
            RussianRoulette::Efficiency(1.0),
        ];
        for rr in kinds {
            for i in 0..luminances.len() {
                let n = luminances.len();
                let lum: [f32; LANES] = std::array::from_fn(|l| luminances[(i + l) % n]);
                let depth: [u32; LANES] = std::array::from_fn(|l| depths[(i + 3 * l) % 8]);
                let lanes = roulette_survival(rr, F8::from_array(lum), U8::from_array(depth));
                for l in 0..LANES {
                    let scalar = rr.survival(lum[l], depth[l]);
                    assert_eq!(
                        lanes.lane(l).to_bits(),
                        scalar.to_bits(),
                        "{rr:?}, luminance {} at depth {}",
                        lum[l],
                        depth[l]
                    );
                }
            }
        }
    }
}
