//! A bounce's shading points and scattering vertices in lanes: the lanes the scalar code
//! shaded and the triangle hits the lanes shade, the vertices' BSDFs, frames and random
//! numbers; and the light samples the scalar code takes for lanes.

use crate::geometry::ray::Ray;
use crate::material::Bsdf;
use crate::material::lambert::Lambert;
use crate::material::lanes::BsdfLanes;
use crate::sampling::sampler::VertexSample;
use crate::simd::{F8, LANES, M8, V3};
use crate::world::Interaction;
use crate::world::lanes::{ShadingLanes, TriangleHits};
use glam::Vec3;

/// The BSDF of lanes that do not scatter (never read).
pub(super) const NO_BSDF: Bsdf<'static> = Bsdf::Lambert(Lambert { albedo: Vec3::ZERO });

/// Shading points that the scalar code computed, lane by lane.
pub(super) struct ScalarShading {
    pub(super) p: [Vec3; LANES],
    pub(super) magnitude: [f32; LANES],
    pub(super) ng: [Vec3; LANES],
    pub(super) frame: [[Vec3; LANES]; 3],
}

impl ScalarShading {
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            p: [Vec3::ZERO; LANES],
            magnitude: [1.0; LANES],
            ng: [Vec3::Z; LANES],
            frame: [[Vec3::X; LANES], [Vec3::Y; LANES], [Vec3::Z; LANES]],
        }
    }

    #[inline(always)]
    pub(super) fn set(&mut self, lane: usize, it: &Interaction) {
        (self.p[lane], self.ng[lane]) = (it.p, it.ng);
        self.magnitude[lane] = it.magnitude;
        let [s, t, n] = &mut self.frame;
        (s[lane], t[lane], n[lane]) = (it.frame.s, it.frame.t, it.frame.n);
    }

    #[inline(always)]
    pub(super) fn lanes(&self) -> ShadingLanes {
        let [s, t, n] = &self.frame;
        ShadingLanes {
            p: V3::from_lanes(&self.p),
            magnitude: F8::from_array(self.magnitude),
            ng: V3::from_lanes(&self.ng),
            frame: [V3::from_lanes(s), V3::from_lanes(t), V3::from_lanes(n)],
        }
    }
}

/// A bounce's shading points: lanes the scalar code shaded, and triangle hits the lanes
/// shade. Reused from bounce to bounce, not cleared: only the lanes a bounce sets are read.
pub(super) struct Shading {
    pub(super) scalar: ScalarShading,
    pub(super) triangles: TriangleHits,
    pub(super) lane_shaded: u32,
}

impl Shading {
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            scalar: ScalarShading::new(),
            triangles: TriangleHits::new(),
            lane_shaded: 0,
        }
    }

    /// The shading points of the lanes of `mask`, hit by rays of directions `dir`.
    #[inline(always)]
    pub(super) fn lanes(&self, mask: u32, dir: V3) -> ShadingLanes {
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
            magnitude: F8::select(m, computed.magnitude, scalar.magnitude),
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
pub(super) struct Vertices<'b> {
    pub(super) mask: u32,
    /// The scattering lanes at their path's first vertex (the one that splits).
    pub(super) first: u32,
    /// Shading points, and the origins of the rays that leave them, in lanes.
    pub(super) p: V3,
    pub(super) origin: V3,
    pub(super) ng: V3,
    pub(super) frame: [V3; 3],
    pub(super) wo: V3,
    pub(super) bsdf: BsdfLanes<'b>,
    /// The lanes' random numbers (`VertexSample`'s), a dimension a vector: see [`Dim`].
    pub(super) numbers: [F8; Dim::COUNT],
}

/// The dimensions of a vertex's random numbers in [`Vertices::numbers`]: the light
/// sample's point and choice, roulette, the BSDF sample's direction and lobe.
pub(super) struct Dim;

impl Dim {
    pub(super) const LIGHT_X: usize = 0;
    pub(super) const LIGHT_Y: usize = 1;
    pub(super) const LIGHT_SELECT: usize = 2;
    pub(super) const RR: usize = 3;
    pub(super) const BSDF_X: usize = 4;
    pub(super) const BSDF_Y: usize = 5;
    pub(super) const LOBE: usize = 6;
    pub(super) const COUNT: usize = 7;

    /// Writes `vs` into lane `lane` of `numbers`.
    #[inline(always)]
    pub(super) fn set(numbers: &mut [[f32; LANES]; Dim::COUNT], lane: usize, vs: &VertexSample) {
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
    pub(super) fn round_lanes(&self, lanes: u32, j: u32, count: u32) -> u32 {
        let deeper = if j == 0 { lanes & !self.first } else { 0 };
        deeper | if j < count { lanes & self.first } else { 0 }
    }

    /// How many rounds the lanes of `lanes` take with `count` samples at the first vertex.
    #[inline(always)]
    pub(super) fn rounds(&self, lanes: u32, count: u32) -> u32 {
        let deeper = u32::from(lanes & !self.first != 0);
        deeper.max(if lanes & self.first != 0 { count } else { 0 })
    }

    /// `count` in the first-vertex lanes, 1 in the others.
    #[inline(always)]
    pub(super) fn counts(&self, count: u32) -> F8 {
        F8::select(M8::from_bits(self.first), F8::splat(count as f32), F8::ONE)
    }

    #[inline(always)]
    pub(super) fn to_local(&self, v: V3) -> V3 {
        let [s, t, n] = self.frame;
        V3::new(v.dot(s), v.dot(t), v.dot(n))
    }

    #[inline(always)]
    pub(super) fn to_world(&self, v: V3) -> V3 {
        let [s, t, n] = self.frame;
        s * v.x + t * v.y + n * v.z
    }
}

/// A round's light samples lane by lane: the scalar code's direction, radiance, density
/// (selection included) and delta lights; the shadow rays and sampling lanes of both the
/// scalar code's and the lanes' own samples.
pub(super) struct ScalarLightSamples {
    pub(super) wi: [Vec3; LANES],
    pub(super) radiance: [Vec3; LANES],
    pub(super) p_light: [f32; LANES],
    pub(super) shadow: [Ray; LANES],
    pub(super) sampled: u32,
    pub(super) delta: u32,
}

impl ScalarLightSamples {
    #[inline(always)]
    pub(super) fn new() -> Self {
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
