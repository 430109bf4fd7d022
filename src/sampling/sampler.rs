//! Samplers: where a path's random numbers come from. Every number a sample uses is a pure
//! function of (pixel, sample index, seed), so an image is identical whatever the thread
//! count or tile order.

use super::pcg::{Pcg32, hash_u32, mix_u64};
use glam::Vec2;

/// Which sequence feeds the paths.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplerKind {
    /// Independent uniform numbers (PCG32 per pixel sample).
    Independent,
    /// Owen-scrambled Sobol (Burley 2020), padded in 4D sets decorrelated by seed, for the
    /// camera and every vertex.
    Sobol,
}

impl SamplerKind {
    /// Name as used on the command line and in EXR metadata.
    pub fn name(self) -> &'static str {
        match self {
            Self::Independent => "independent",
            Self::Sobol => "sobol",
        }
    }

    /// Parses a command-line name.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "independent" => Some(Self::Independent),
            "sobol" => Some(Self::Sobol),
            _ => None,
        }
    }
}

/// Random numbers for one camera ray: position in the pixel filter and on the lens.
#[derive(Clone, Copy, Debug)]
pub struct CameraSample {
    pub film: Vec2,
    pub lens: Vec2,
}

/// Random numbers one path vertex consumes: light selection and position, Russian roulette,
/// BSDF lobe and direction.
#[derive(Clone, Copy, Debug)]
pub struct VertexSample {
    pub light: Vec2,
    pub light_select: f32,
    pub rr: f32,
    pub bsdf: Vec2,
    pub lobe: f32,
    /// The free flight through a medium on the way to the vertex (`crate::medium`).
    pub medium: f32,
}

/// The random numbers of one pixel sample. Dimensions come in 4D sets: set 0 is the camera,
/// sets 1 + 2k and 2 + 2k are vertex k's on the main path; paths branched off by splitting
/// get their own sets. Each set's (x, y) pair is the best-stratified 2D projection, so the
/// 2D samples go there.
#[derive(Clone, Debug)]
pub struct Sampler {
    kind: SamplerKind,
    /// The image seed, mixed once: every pixel's key starts from it.
    seed_key: u64,
    /// This pixel's key (image seed and pixel): seeds the sequences of the first vertex's
    /// split samples, which run over all of the pixel's samples.
    pixel_key: u64,
    /// The pixel (x, y) of the sample.
    pixel: (u32, u32),
    /// The sample's index in the pixel.
    index: u32,
    pixel_seed: u32,
    /// The sample's index within its Sobol seed, bit-reversed (as the scramble takes it).
    index_rev: u32,
    /// A key of this pixel sample, seeding the points of split samples.
    sample_key: u32,
    rng: Pcg32,
}

/// Which split samples a [`Sampler::split_point`] is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SplitKind {
    /// Shadow rays: light position (x, y), light selection, unused.
    Light = 0x6c,
    /// BSDF samples: direction (x, y), lobe, Russian roulette.
    Bsdf = 0xb5,
}

impl Sampler {
    /// A sampler of `kind` for image seed `seed`.
    pub fn new(kind: SamplerKind, seed: u32) -> Self {
        Self {
            kind,
            seed_key: mix_u64(seed as u64 ^ 0x5851f42d4c957f2d),
            pixel_key: 0,
            pixel: (0, 0),
            index: 0,
            pixel_seed: 0,
            index_rev: 0,
            sample_key: 0,
            rng: Pcg32::new(0, 0),
        }
    }

    /// Starts sample `index` of pixel (`x`, `y`).
    #[inline]
    pub fn start(&mut self, x: u32, y: u32, index: u32) {
        let pixel = ((y as u64) << 32) | x as u64;
        let key = mix_u64(pixel ^ self.seed_key);
        self.pixel_key = key;
        self.pixel = (x, y);
        self.index = index;
        self.sample_key = mix_u64(key ^ ((index as u64) << 20)) as u32;
        match self.kind {
            SamplerKind::Independent => {
                self.rng = Pcg32::new(mix_u64(key ^ index as u64), key);
            }
            SamplerKind::Sobol => {
                (self.pixel_seed, self.index_rev) = sobol_position(key, index as u64);
            }
        }
    }

    #[inline]
    fn set(&mut self, set: u32) -> [f32; 4] {
        match self.kind {
            SamplerKind::Independent => std::array::from_fn(|_| self.rng.next_f32()),
            SamplerKind::Sobol => sobol_4d(self.index_rev, self.set_seed(set)),
        }
    }

    /// The scramble seed of dimension set `set` in this pixel (Sobol sampler).
    #[inline]
    fn set_seed(&self, set: u32) -> u32 {
        self.pixel_seed ^ set_key(set)
    }

    /// Numbers for the camera ray.
    #[inline]
    pub fn camera(&mut self) -> CameraSample {
        let s = self.set(0);
        CameraSample {
            film: Vec2::new(s[0], s[1]),
            lens: Vec2::new(s[2], s[3]),
        }
    }

    /// The camera ray's time in the shutter, in [0, 1): the first dimension of a set of its
    /// own, so that the pixel's samples spread evenly over the shutter, and drawn only in
    /// scenes that move (those that do not keep their numbers to the bit).
    #[inline]
    pub fn time(&mut self) -> f32 {
        self.set(TIME_SET)[0]
    }

    /// What the camera's Sobol set starts from: the sample's bit-reversed index and the
    /// set's seed, so that [`sobol_4d_lanes`] computes eight samples' camera numbers at once
    /// ([`Sampler::camera`]'s to the bit); `None` for the independent sampler.
    #[inline]
    pub(crate) fn camera_sobol(&self) -> Option<(u32, u32)> {
        (self.kind == SamplerKind::Sobol).then(|| (self.index_rev, self.set_seed(0)))
    }

    /// Numbers for path vertex `depth` (0 = the first hit from the camera) of branch
    /// `branch` (0: the main path).
    #[inline]
    pub fn vertex(&mut self, depth: u32, branch: u32) -> VertexSample {
        let [a, b] = vertex_sets(depth, branch);
        VertexSample::from_sets(self.set(a), self.set(b))
    }

    /// What the sample's Sobol sets start from: its bit-reversed index and its pixel's
    /// seed, so that the packet kernel computes eight paths' vertex sets at once
    /// ([`vertex_seeds_lanes`], then [`sobol_4d_lanes`]); `None` for the independent
    /// sampler.
    #[inline]
    pub(crate) fn sobol_key(&self) -> Option<(u32, u32)> {
        (self.kind == SamplerKind::Sobol).then_some((self.index_rev, self.pixel_seed))
    }
}

/// The seeds of the two Sobol sets of vertex `depth` of branch `branch`, lane by lane, for
/// samples of pixel seeds `pixel_seed` ([`Sampler::sobol_key`]): `vertex_sets` and
/// `set_key` in lanes. [`sobol_4d_lanes`] of them and of the samples' indices gives
/// [`Sampler::vertex`]'s sets to the bit. Only for code compiled with AVX2.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn vertex_seeds_lanes(
    pixel_seed: crate::simd::U8,
    depth: crate::simd::U8,
    branch: crate::simd::U8,
) -> [crate::simd::U8; 2] {
    use crate::simd::U8;
    let branched =
        U8::splat(0x4000_0000) ^ lanes::hash_u32(branch).wrapping_mul(U8::splat(0x10000));
    let base = U8::select(branch.eq(U8::splat(0)), U8::splat(1), branched);
    let first = base + depth + depth;
    let second = first + U8::splat(1);
    [
        pixel_seed ^ lanes::set_key(first),
        pixel_seed ^ lanes::set_key(second),
    ]
}

impl VertexSample {
    /// A vertex's numbers from its two sets: light position, light selection and roulette
    /// from the first; BSDF direction, lobe and the free flight that reaches the vertex from
    /// the second.
    #[inline(always)]
    pub(crate) fn from_sets(a: [f32; 4], b: [f32; 4]) -> Self {
        Self {
            light: Vec2::new(a[0], a[1]),
            light_select: a[2],
            rr: a[3],
            bsdf: Vec2::new(b[0], b[1]),
            lobe: b[2],
            medium: b[3],
        }
    }
}

/// The dimension set of the shutter time ([`Sampler::time`]): apart from the camera's (0),
/// the main path's (1 + 2k) and the branches' (from 0x4000_0000).
const TIME_SET: u32 = 0x2000_0000;

/// The dimension sets of vertex `depth` of branch `branch`: the main path's follow the
/// camera's; a split branch's start at a key of their own.
#[inline]
fn vertex_sets(depth: u32, branch: u32) -> [u32; 2] {
    let base = if branch == 0 {
        1
    } else {
        0x4000_0000 ^ hash_u32(branch).wrapping_mul(0x10000)
    };
    [
        base.wrapping_add(2 * depth),
        base.wrapping_add(2 * depth + 1),
    ]
}

impl Sampler {
    /// Point `j` of the split samples of `kind` at the vertex with key `vertex`, where the
    /// number of splits varies from sample to sample (efficiency-aware splitting; key 0 at
    /// the first vertex): the j-th point of an Owen-scrambled Sobol sequence seeded per pixel
    /// sample and vertex, so every point is uniform and the points of one vertex together
    /// are stratified (a (0, 2)-sequence in the first two numbers).
    #[inline]
    pub fn split_point(&self, kind: SplitKind, vertex: u32, j: u32) -> [f32; 4] {
        sobol_4d(
            (j & 0xffff).reverse_bits(),
            self.sample_key ^ split_key(kind, vertex),
        )
    }

    /// Point `point` of the pixel's sequence `stream` of split samples of `kind` at the first
    /// vertex, where sample `index`'s j-th split takes point `index × count + j` of stream 0
    /// (see `integrator::split::FirstSplit`). With the Sobol sampler each sequence is one
    /// Owen-scrambled Sobol sequence per pixel, so the points of all the pixel's samples
    /// together are stratified as the unsplit sets are across its samples; points drawn per
    /// sample (as [`Sampler::split_point`] does) would be stratified only within a sample and
    /// random from one sample to the next, which on the MIS plates doubled the relMSE at
    /// equal samples with two shadow rays. The independent sampler draws them per sample.
    #[inline]
    pub fn first_split_point(&self, kind: SplitKind, (stream, point): (u32, u64)) -> [f32; 4] {
        match self.kind {
            SamplerKind::Independent => self.split_point(kind, stream, point as u32),
            SamplerKind::Sobol => {
                let (seed, rev) = sobol_position(self.pixel_key, point);
                sobol_4d(rev, seed ^ split_key(kind, stream))
            }
        }
    }

    /// The pixel's key, which [`Sampler::first_split_point`]'s Sobol sequences start from,
    /// so that [`first_split_sobol_lanes`] takes eight lanes' points at once; `None` for
    /// the independent sampler.
    #[inline]
    pub(crate) fn split_pixel_key(&self) -> Option<u64> {
        (self.kind == SamplerKind::Sobol).then_some(self.pixel_key)
    }

    /// The index of the current sample in its pixel.
    #[inline]
    pub fn sample_index(&self) -> u32 {
        self.index
    }

    /// The pixel (x, y) of the current sample.
    #[inline]
    pub fn pixel(&self) -> (u32, u32) {
        self.pixel
    }
}

/// The key split samples of `kind` add to their seed at the vertex (or in the stream) `n`.
#[inline]
fn split_key(kind: SplitKind, n: u32) -> u32 {
    hash_u32(kind as u32 ^ n.wrapping_mul(0x2c1b3c6d))
}

/// Where point `index` of a pixel's Sobol sequence lies: the pixel's seed for that point
/// (Sobol supports 2^16 points per seed; later points continue with a new seed) and the
/// point's index within it, bit-reversed.
#[inline]
fn sobol_position(pixel_key: u64, index: u64) -> (u32, u32) {
    let seed = (pixel_key as u32) ^ hash_u32((pixel_key >> 32) as u32 ^ (index >> 16) as u32);
    (seed, ((index & 0xffff) as u32).reverse_bits())
}

/// The first four Sobol dimensions (bit-reversed, as sobol_burley computes them) of each
/// byte of a bit-reversed 16-bit index: `high[b]` for the index's top byte, `low[b]` for
/// the next. Sobol points are linear in the index bits over GF(2), so a point is the XOR
/// of its two bytes' entries.
struct SobolBytes {
    high: [[u32; 4]; 256],
    low: [[u32; 4]; 256],
}

static SOBOL_BYTES: std::sync::LazyLock<SobolBytes> = std::sync::LazyLock::new(|| {
    use sobol_burley::parts::sobol_rev;
    let entry = |rev_index: u32| std::array::from_fn(|d| sobol_rev(rev_index, d as u32));
    SobolBytes {
        high: std::array::from_fn(|b| entry((b as u32) << 24)),
        low: std::array::from_fn(|b| entry((b as u32) << 16)),
    }
});

/// The key set `set` adds to a pixel's Sobol seed; the camera's and the main path's sets
/// (the first [`SET_KEYS`]) are read from a table.
#[inline]
fn set_key(set: u32) -> u32 {
    const fn key(set: u32) -> u32 {
        hash_u32(set.wrapping_mul(0x9e3779b9) ^ 0x68bc21eb)
    }
    const SET_KEYS: [u32; 8] = {
        let mut keys = [0; 8];
        let mut set = 0;
        while set < keys.len() {
            keys[set] = key(set as u32);
            set += 1;
        }
        keys
    };
    SET_KEYS
        .get(set as usize)
        .copied()
        .unwrap_or_else(|| key(set))
}

/// The per-dimension scramble constants of sobol_burley, for dimension set 0.
const SCRAMBLE_LANES: [u32; 4] = [0x912f69ba, 0x174f18ab, 0x691e72ca, 0xb40cc1b8];

/// `sobol_burley::sample_4d(index, 0, seed)` (Burley 2020: Owen-scrambled, shuffled Sobol)
/// of the index given bit-reversed (`index_rev`, so a sample reverses it once for all its
/// sets), with the Sobol matrix product read from two byte tables instead of a loop over
/// the index's bits, whose data-dependent branches cost about a tenth of a render's time.
#[inline]
fn sobol_4d(index_rev: u32, seed: u32) -> [f32; 4] {
    use sobol_burley::parts::{Int4, hash, hash_int4, owen_scramble_int4_rev, owen_scramble_rev};
    let rev = owen_scramble_rev(index_rev, hash(seed ^ 0x79c68e4a));
    let bytes = &*SOBOL_BYTES;
    let high = bytes.high[(rev >> 24) as usize];
    let low = bytes.low[((rev >> 16) & 0xff) as usize];
    let sobol = Int4::from(high) ^ Int4::from(low);
    let scramble = Int4::from([seed.wrapping_mul(0x9c8f2d3b); 4]) ^ Int4::from(SCRAMBLE_LANES);
    owen_scramble_int4_rev(sobol, hash_int4(scramble))
        .reverse_bits()
        .to_f32_norm()
}

/// [`sobol_4d`] in eight lanes: lane i is `sobol_4d(index_rev[i], seed[i])` to the bit
/// (the same integer operations), for the packet kernel, which takes eight vertices' sets
/// at once. Only for code compiled with AVX2 (see `crate::simd`). Written with loops and
/// functions, not closures handed to library code, which would compile outside AVX2.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn sobol_4d_lanes(
    index_rev: crate::simd::U8,
    seed: crate::simd::U8,
) -> [crate::simd::F8; 4] {
    use crate::simd::{F8, U8};
    let rev = lanes::owen_scramble(index_rev, lanes::hash(seed ^ U8::splat(0x79c6_8e4a)));
    let bytes = &*SOBOL_BYTES;
    let high = rev.shr::<24>().gather_rows(&bytes.high);
    let low = (rev.shr::<16>() & U8::splat(0xff)).gather_rows(&bytes.low);
    let seed_mix = seed.wrapping_mul(U8::splat(0x9c8f_2d3b));
    let mut out = [F8::ZERO; 4];
    for (d, out) in out.iter_mut().enumerate() {
        let sobol = high[d] ^ low[d];
        let scramble = seed_mix ^ U8::splat(SCRAMBLE_LANES[d]);
        *out = lanes::owen_scramble(sobol, lanes::hash(scramble))
            .reverse_bits()
            .to_f32_norm();
    }
    out
}

/// What [`Sampler::first_split_point`]'s Sobol points start from, lane by lane: with each
/// lane's pixel key ([`Sampler::split_pixel_key`]), stream and point as (low, high) 32-bit
/// halves, the points' bit-reversed indices and seeds (`sobol_position` and `split_key` in
/// lanes), of which [`sobol_4d_lanes`] gives the points to the bit. Only for code compiled
/// with AVX2.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn first_split_sobol_lanes(
    kind: SplitKind,
    pixel_key: [crate::simd::U8; 2],
    stream: crate::simd::U8,
    point: [crate::simd::U8; 2],
) -> (crate::simd::U8, crate::simd::U8) {
    use crate::simd::U8;
    let [key_low, key_high] = pixel_key;
    let [point_low, point_high] = point;
    // (point >> 16) as u32: bits 16-47 of the point.
    let point_seed = point_high.shl::<16>() | point_low.shr::<16>();
    let seed = key_low ^ lanes::hash_u32(key_high ^ point_seed);
    let rev = (point_low & U8::splat(0xffff)).reverse_bits();
    let split_key =
        lanes::hash_u32(U8::splat(kind as u32) ^ stream.wrapping_mul(U8::splat(0x2c1b_3c6d)));
    (rev, seed ^ split_key)
}

/// sobol_burley's hash and Owen scramble, and the sets' keys, lane by lane.
#[cfg(target_arch = "x86_64")]
mod lanes {
    use crate::simd::U8;

    /// `sobol_burley::parts::hash` in each lane.
    #[inline(always)]
    pub(super) fn hash(n: U8) -> U8 {
        hash_u32(n ^ U8::splat(0xe6fe_3beb))
    }

    /// [`super::hash_u32`] in each lane.
    #[inline(always)]
    pub(super) fn hash_u32(n: U8) -> U8 {
        let n = n ^ n.shr::<16>();
        let n = n.wrapping_mul(U8::splat(0x7feb_352d));
        let n = n ^ n.shr::<15>();
        let n = n.wrapping_mul(U8::splat(0x846c_a68b));
        n ^ n.shr::<16>()
    }

    /// `sobol_burley::parts::owen_scramble_rev` in each lane.
    #[inline(always)]
    pub(super) fn owen_scramble(n: U8, scramble: U8) -> U8 {
        let n = n ^ n.wrapping_mul(U8::splat(0x3d20_adea));
        let n = n + scramble;
        let n = n.wrapping_mul(scramble.shr::<16>() | U8::splat(1));
        let n = n ^ n.wrapping_mul(U8::splat(0x0552_6c56));
        n ^ n.wrapping_mul(U8::splat(0x53a2_2864))
    }

    /// [`super::set_key`] in each lane.
    #[inline(always)]
    pub(super) fn set_key(set: U8) -> U8 {
        hash_u32(set.wrapping_mul(U8::splat(0x9e37_79b9)) ^ U8::splat(0x68bc_21eb))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_are_deterministic_and_distinct_per_pixel() {
        for kind in [SamplerKind::Independent, SamplerKind::Sobol] {
            let mut a = Sampler::new(kind, 9);
            let mut b = Sampler::new(kind, 9);
            a.start(3, 4, 17);
            b.start(3, 4, 17);
            assert_eq!(a.vertex(2, 0).bsdf, b.vertex(2, 0).bsdf);
            b.start(4, 3, 17);
            a.start(3, 4, 17);
            assert_ne!(a.camera().film, b.camera().film);
        }
    }

    #[test]
    fn split_points_are_stratified_and_differ_between_samples() {
        let mut s = Sampler::new(SamplerKind::Independent, 3);
        s.start(1, 2, 0);
        let mut cells = [false; 64];
        for j in 0..64 {
            let p = s.split_point(SplitKind::Light, 0, j);
            let c = (p[0] * 8.0) as usize + 8 * (p[1] * 8.0) as usize;
            assert!(!cells[c], "cell {c} twice");
            cells[c] = true;
        }
        let first = s.split_point(SplitKind::Light, 0, 0);
        s.start(1, 2, 1);
        assert_ne!(first, s.split_point(SplitKind::Light, 0, 0));
        assert_ne!(
            s.split_point(SplitKind::Light, 0, 0),
            s.split_point(SplitKind::Bsdf, 0, 0)
        );
        assert_ne!(
            s.split_point(SplitKind::Bsdf, 0, 0),
            s.split_point(SplitKind::Bsdf, 1, 0)
        );
    }

    /// The first vertex's split points, over all the samples of a pixel, are one stratified
    /// sequence: 64 points fill every cell of an 8 × 8 grid (and of 64 × 1 and 1 × 64), as
    /// Owen-scrambled Sobol's first 64 points do, whatever the split count.
    #[test]
    fn first_split_points_are_stratified_across_a_pixels_samples() {
        let mut s = Sampler::new(SamplerKind::Sobol, 3);
        for kind in [SplitKind::Light, SplitKind::Bsdf] {
            for count in [1, 2, 4, 8, 64] {
                let mut grids = [[false; 64]; 3];
                for index in 0..64 / count {
                    s.start(5, 7, index);
                    for j in 0..count {
                        let p = s.first_split_point(kind, (0, (index * count + j) as u64));
                        let cells = [
                            (p[0] * 8.0) as usize + 8 * (p[1] * 8.0) as usize,
                            (p[0] * 64.0) as usize,
                            (p[1] * 64.0) as usize,
                        ];
                        for (grid, c) in grids.iter_mut().zip(cells) {
                            assert!(!grid[c], "{kind:?}, {count} splits: cell {c} twice");
                            grid[c] = true;
                        }
                    }
                }
            }
        }
        s.start(5, 7, 0);
        let light = s.first_split_point(SplitKind::Light, (0, 0));
        assert_ne!(light, s.first_split_point(SplitKind::Bsdf, (0, 0)));
        assert_ne!(light, s.first_split_point(SplitKind::Light, (1, 0)));
        s.start(6, 7, 0);
        assert_ne!(light, s.first_split_point(SplitKind::Light, (0, 0)));
    }

    #[test]
    fn byte_tables_give_sobol_burleys_points() {
        let mut rng = Pcg32::new(5, 1);
        for index in (0u32..1 << 16).step_by(7).chain([0, 1, 0xffff]) {
            let seed = rng.next_u32();
            assert_eq!(
                sobol_4d(index.reverse_bits(), seed),
                sobol_burley::sample_4d(index, 0, seed),
                "index {index}, seed {seed}"
            );
        }
    }

    /// Eight lanes' Sobol sets are the scalar sets to the bit, over the index range and
    /// random seeds, and eight vertices' sets from their samples' keys are
    /// [`Sampler::vertex`]'s numbers.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn sobol_lanes_are_the_scalar_sets() {
        use crate::simd::U8;
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let mut rng = Pcg32::new(11, 3);
        for base in (0u32..1 << 16).step_by(8 * 5).chain([0xfff8]) {
            let index: [u32; 8] = std::array::from_fn(|l| (base + l as u32 * 5) & 0xffff);
            let seed: [u32; 8] = std::array::from_fn(|_| rng.next_u32());
            let rev = index.map(u32::reverse_bits);
            let lanes = sobol_4d_lanes(U8::from_array(rev), U8::from_array(seed));
            for l in 0..8 {
                let scalar = sobol_4d(rev[l], seed[l]);
                for d in 0..4 {
                    assert_eq!(lanes[d].to_array()[l].to_bits(), scalar[d].to_bits());
                }
            }
        }
        // Eight paths' vertices at once: samples of different pixels and indices (one past
        // a seed's 2^16 points), depths from the first to deep ones, the main path and
        // split branches.
        let mut s = Sampler::new(SamplerKind::Sobol, 7);
        for round in 0..64u32 {
            let (mut rev, mut seed) = ([0; 8], [0; 8]);
            let (mut depth, mut branch) = ([0; 8], [0; 8]);
            let mut expected = Vec::new();
            for l in 0..8 {
                let index = [0, 9, 70_000, rng.next_u32() % 5000][l % 4];
                s.start(round + l as u32, 2, index);
                (rev[l], seed[l]) = s.sobol_key().expect("a Sobol sample");
                depth[l] = [0, 1, 2, 3, 7, 40, rng.next_u32() % 100, 0][l];
                branch[l] = if rng.next_u32().is_multiple_of(2) {
                    0
                } else {
                    1 + rng.next_u32() % 4
                };
                expected.push(s.vertex(depth[l], branch[l]));
            }
            let [seed_a, seed_b] = vertex_seeds_lanes(
                U8::from_array(seed),
                U8::from_array(depth),
                U8::from_array(branch),
            );
            let rev = U8::from_array(rev);
            let (a, b) = (sobol_4d_lanes(rev, seed_a), sobol_4d_lanes(rev, seed_b));
            for (l, expected) in expected.iter().enumerate() {
                let a = std::array::from_fn(|d| a[d].to_array()[l]);
                let b = std::array::from_fn(|d| b[d].to_array()[l]);
                let got = VertexSample::from_sets(a, b);
                assert_eq!(
                    format!("{got:?}"),
                    format!("{expected:?}"),
                    "round {round}, lane {l}"
                );
            }
        }
        assert!(
            Sampler::new(SamplerKind::Independent, 7)
                .sobol_key()
                .is_none()
        );
    }

    /// Eight lanes' first-vertex split points are [`Sampler::first_split_point`]'s to the
    /// bit: both kinds, streams 0 to 3, points within a seed's 2^16, past it and past 2^32.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn split_point_lanes_are_the_scalar_points() {
        use crate::simd::U8;
        if !crate::simd::avx2_or_skip() {
            return;
        }
        let mut rng = Pcg32::new(17, 5);
        let mut s = Sampler::new(SamplerKind::Sobol, 4);
        for round in 0..64u32 {
            let kind = [SplitKind::Light, SplitKind::Bsdf][round as usize % 2];
            let (mut key, mut stream, mut point) = ([[0; 8]; 2], [0; 8], [[0; 8]; 2]);
            let mut expected = Vec::new();
            for l in 0..8 {
                s.start(round, l as u32, 3);
                let pixel_key = s.split_pixel_key().expect("a Sobol sample");
                let p = match l % 4 {
                    0 => u64::from(rng.next_u32() % 0x1_0000),
                    1 => u64::from(rng.next_u32()),
                    2 => (1u64 << 32) + u64::from(rng.next_u32()),
                    _ => (u64::from(rng.next_u32()) << 16) | 0xfffe,
                };
                let k = rng.next_u32() % 4;
                (key[0][l], key[1][l]) = (pixel_key as u32, (pixel_key >> 32) as u32);
                (point[0][l], point[1][l]) = (p as u32, (p >> 32) as u32);
                stream[l] = k;
                expected.push(s.first_split_point(kind, (k, p)));
            }
            let (rev, seed) = first_split_sobol_lanes(
                kind,
                key.map(U8::from_array),
                U8::from_array(stream),
                point.map(U8::from_array),
            );
            let got = sobol_4d_lanes(rev, seed);
            for (l, expected) in expected.iter().enumerate() {
                let got: [f32; 4] = std::array::from_fn(|d| got[d].to_array()[l]);
                assert_eq!(
                    got.map(f32::to_bits),
                    expected.map(f32::to_bits),
                    "round {round}, lane {l}"
                );
            }
        }
        assert!(
            Sampler::new(SamplerKind::Independent, 4)
                .split_pixel_key()
                .is_none()
        );
    }

    #[test]
    fn sobol_camera_samples_are_stratified() {
        // The first 16 samples of a pixel fall one in each cell of a 4x4 grid.
        let mut s = Sampler::new(SamplerKind::Sobol, 1);
        let mut cells = [false; 16];
        for i in 0..16 {
            s.start(10, 20, i);
            let f = s.camera().film;
            let c = (f.x * 4.0) as usize + 4 * (f.y * 4.0) as usize;
            assert!(!cells[c], "cell {c} twice");
            cells[c] = true;
        }
    }
}
