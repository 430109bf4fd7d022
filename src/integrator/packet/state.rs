//! The packet kernel's state: the paths in the eight lanes (a field a vector), paths waiting
//! for a lane, camera samples in flight and what their paths bring back, and the buffers a
//! thread reuses from tile to tile.

use super::super::estimator::PathState;
use super::super::media::Media;
use super::super::split::{PixelParts, SampleParts, SamplePoints, SplitStats};
use crate::film::PixelAccumulator;
use crate::film::record::{Contribution, FirstHit, Recorder};
use crate::geometry::cone::RayCone;
use crate::geometry::ray::{Ray, RayLanes};
use crate::sampling::sampler::Sampler;
use crate::simd::{F8, LANES, U8, V3};
use glam::Vec3;

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
pub(super) struct Path {
    pub(super) ray: Ray,
    pub(super) state: LaneState,
    pub(super) sample: u32,
}

/// The part of the scalar kernel's `PathState` that a path in a lane has: paths in lanes
/// record no lobe shares (the packet kernel renders the beauty alone) and meet no
/// transmissive surface, so they are in no volume and cross no filter.
#[derive(Clone, Copy, Debug)]
pub(super) struct LaneState {
    pub(super) beta: Vec3,
    pub(super) depth: u32,
    pub(super) branch: u32,
    pub(super) prev_p: Vec3,
    pub(super) prev_n: Vec3,
    pub(super) prev_pdf: f32,
    pub(super) prev_delta: bool,
    pub(super) prev_nee_count: u32,
    pub(super) cone: RayCone,
}

impl LaneState {
    /// The state of a camera path whose ray starts at `origin` with cone `cone`
    /// (`PathState::camera`'s).
    #[inline(always)]
    pub(super) fn camera(origin: Vec3, cone: RayCone) -> Self {
        let s = PathState::camera(origin, cone);
        Self {
            beta: s.beta,
            depth: s.depth,
            branch: s.branch,
            prev_p: s.prev_p,
            prev_n: s.prev_n,
            prev_pdf: s.prev_pdf,
            prev_delta: s.prev_delta,
            prev_nee_count: s.prev_nee_count,
            cone: s.cone,
        }
    }
}

/// What idle lanes hold (never read).
pub(super) const NO_PATH: Path = Path {
    ray: Ray {
        origin: Vec3::ZERO,
        dir: Vec3::Z,
        tmax: 0.0,
        time: 0.0,
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
        cone: RayCone::POINT,
    },
    sample: 0,
};

/// The paths in the eight lanes, a field a vector (or an array of eight): what a bounce
/// reads in lanes (rays, throughputs, the previous vertices) is not gathered from eight
/// records, and a path continues in its lane by selects. Lanes are filled from [`Path`]
/// records (camera samples, split branches); the scalar code gets a lane's state back
/// ([`PathLanes::state`]). The packet kernel renders the beauty alone, so no lane records
/// lobe shares (`PathState::lobes` stays zero).
pub(super) struct PathLanes {
    pub(super) ray: RayLanes,
    pub(super) beta: V3,
    pub(super) prev_p: V3,
    pub(super) prev_n: V3,
    pub(super) prev_pdf: F8,
    /// Lanes whose previous vertex sampled a delta lobe.
    pub(super) prev_delta: u32,
    pub(super) depth: U8,
    pub(super) branch: [u32; LANES],
    pub(super) prev_nee_count: U8,
    /// Each lane's ray cone (`world::footprint`): its width where the ray starts and its
    /// spread.
    pub(super) cone_width: F8,
    pub(super) cone_spread: F8,
    /// The distance to each lane's hit of this bounce (render space).
    pub(super) arrived: F8,
    /// Sample slot of each lane's path.
    pub(super) sample: [u32; LANES],
    /// Each lane's sample's Sobol key ([`Sampler::sobol_key`]): its bit-reversed index and
    /// its pixel's seed (zero with the independent sampler).
    pub(super) sobol_rev: U8,
    pub(super) sobol_seed: U8,
    /// What each lane's path has brought back by light sampling, the rays it traced and
    /// the non-finite contributions it dropped, since it took its lane: added to its sample
    /// when it ends ([`PacketTracer::end_path`]) instead of lane by lane at every bounce.
    pub(super) value: V3,
    pub(super) rays: U8,
    pub(super) discarded: U8,
}

impl PathLanes {
    /// Lanes holding [`NO_PATH`].
    #[inline(always)]
    pub(super) fn new() -> Self {
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
            cone_width: F8::ZERO,
            cone_spread: F8::ZERO,
            arrived: F8::ZERO,
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
    pub(super) fn set(&mut self, lane: usize, path: &Path, (rev, seed): (u32, u32)) {
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
        self.cone_width.set_lane(lane, state.cone.width);
        self.cone_spread.set_lane(lane, state.cone.spread);
        self.sample[lane] = path.sample;
        self.sobol_rev.set_lane(lane, rev);
        self.sobol_seed.set_lane(lane, seed);
        self.value.set_lane(lane, Vec3::ZERO);
        self.rays.set_lane(lane, 0);
        self.discarded.set_lane(lane, 0);
    }

    /// Lane `lane`'s path state, as the scalar code takes it.
    #[inline(always)]
    pub(super) fn state(&self, lane: usize) -> PathState {
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
            cone: RayCone {
                width: self.cone_width.lane(lane),
                spread: self.cone_spread.lane(lane),
            },
            // Lanes record their first hits; a path handed over at the camera's first
            // surface has not yet.
            first_hit_recorded: self.depth.lane(lane) > 0,
            // The packet kernel renders only scenes that do not move.
            time: 0.0,
        }
    }
}

/// A camera sample in flight: its pixel, its random numbers and what its paths have
/// brought back so far.
#[derive(Clone, Debug)]
pub(super) struct SampleSlot {
    /// Index in the tile.
    pub(super) pixel: usize,
    pub(super) sampler: Sampler,
    pub(super) value: Vec3,
    pub(super) covered: bool,
    /// Paths of the sample still running or waiting.
    pub(super) paths: u32,
    pub(super) rays: u64,
    pub(super) discarded: u64,
    /// In a pass that learns the split counts: what the sample's parts brought back, and
    /// the rays of its camera ray, of its first vertex's light samples and of the rest.
    pub(super) parts: SampleParts,
    pub(super) part_rays: [u64; 3],
    /// Where its first vertex's split points lie.
    pub(super) split_points: SamplePoints,
}

/// What a thread reuses from tile to tile: samples in flight, waiting paths, and the
/// tile's pixel accumulators.
pub struct PacketBuffers {
    pub(super) slots: Vec<SampleSlot>,
    pub(super) free: Vec<u32>,
    pub(super) waiting: Vec<Path>,
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

/// Receives what a path handed to the scalar kernel brings back for its sample.
#[derive(Default)]
pub(super) struct SlotRecorder {
    pub(super) value: Vec3,
    pub(super) discarded: u64,
    pub(super) covered: bool,
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
pub(super) struct CameraPaths {
    pub(super) paths: [Path; LANES],
    pub(super) next: usize,
    pub(super) len: usize,
}

impl CameraPaths {
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            paths: [NO_PATH; LANES],
            next: 0,
            len: 0,
        }
    }

    #[inline(always)]
    pub(super) fn is_empty(&self) -> bool {
        self.next == self.len
    }

    /// Replaces the (taken) paths with `count` new ones, `path(i)` the i-th.
    #[inline(always)]
    pub(super) fn fill(&mut self, count: usize, path: impl Fn(usize) -> Path) {
        for (i, p) in self.paths.iter_mut().enumerate().take(count) {
            *p = path(i);
        }
        (self.next, self.len) = (0, count);
    }

    /// The next path in start order.
    #[inline(always)]
    pub(super) fn pop(&mut self) -> Option<Path> {
        (self.next < self.len).then(|| {
            self.next += 1;
            self.paths[self.next - 1]
        })
    }
}
