//! Eight-lane values for the packet kernel (`integrator::packet`): `F8` (f32), `U8` (u32),
//! `M8` (a lane mask) and `V3` (three `F8`s, a vector per lane), on AVX2 and FMA.
//!
//! One concept in one file (1000 lines): the lane types and their operations, which must
//! all follow the invariant below; splitting them would spread that invariant over files.
//!
//! Invariant: these types are only used inside functions compiled with
//! `#[target_feature(enable = "avx2,fma")]`, which the render loop enters after
//! `is_x86_feature_detected!` found both (every x86-64 CPU since 2013-2015). Their methods
//! are `#[inline(always)]`, so the intrinsics inline into those functions and compile to
//! single AVX instructions; called anywhere else they would be undefined behaviour on a CPU
//! without AVX2, which is why the module is private to the crate.

use core::arch::x86_64::*;
use glam::Vec3;
use std::ops::{Add, AddAssign, BitAnd, BitOr, BitXor, Div, Mul, MulAssign, Neg, Not, Sub};

/// Number of lanes.
pub const LANES: usize = 8;

/// Eight f32 lanes.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct F8(__m256);

/// Eight u32 lanes.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct U8(__m256i);

/// A mask over the eight lanes: each lane all ones (set) or all zeros.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct M8(__m256);

// SAFETY (every `unsafe` block of this module): the intrinsics need AVX, AVX2 or FMA, which
// the module's invariant guarantees; the pointer arguments point into arrays of 8 lanes.

macro_rules! binary {
    ($trait:ident, $method:ident, $ty:ident, $intrinsic:ident) => {
        impl $trait for $ty {
            type Output = $ty;
            #[inline(always)]
            fn $method(self, o: $ty) -> $ty {
                unsafe { $ty($intrinsic(self.0, o.0)) }
            }
        }
    };
}

binary!(Add, add, F8, _mm256_add_ps);
binary!(Sub, sub, F8, _mm256_sub_ps);
binary!(Mul, mul, F8, _mm256_mul_ps);
binary!(Div, div, F8, _mm256_div_ps);
binary!(BitAnd, bitand, M8, _mm256_and_ps);
binary!(BitOr, bitor, M8, _mm256_or_ps);
binary!(BitXor, bitxor, M8, _mm256_xor_ps);
binary!(Add, add, U8, _mm256_add_epi32);
binary!(Sub, sub, U8, _mm256_sub_epi32);
binary!(BitAnd, bitand, U8, _mm256_and_si256);
binary!(BitOr, bitor, U8, _mm256_or_si256);
binary!(BitXor, bitxor, U8, _mm256_xor_si256);

impl Mul<f32> for F8 {
    type Output = F8;
    #[inline(always)]
    fn mul(self, o: f32) -> F8 {
        self * F8::splat(o)
    }
}

impl Add<f32> for F8 {
    type Output = F8;
    #[inline(always)]
    fn add(self, o: f32) -> F8 {
        self + F8::splat(o)
    }
}

impl Sub<f32> for F8 {
    type Output = F8;
    #[inline(always)]
    fn sub(self, o: f32) -> F8 {
        self - F8::splat(o)
    }
}

impl Neg for F8 {
    type Output = F8;
    #[inline(always)]
    fn neg(self) -> F8 {
        unsafe { F8(_mm256_xor_ps(self.0, _mm256_set1_ps(-0.0))) }
    }
}

impl AddAssign for F8 {
    #[inline(always)]
    fn add_assign(&mut self, o: F8) {
        *self = *self + o;
    }
}

impl MulAssign for F8 {
    #[inline(always)]
    fn mul_assign(&mut self, o: F8) {
        *self = *self * o;
    }
}

impl Not for M8 {
    type Output = M8;
    #[inline(always)]
    fn not(self) -> M8 {
        unsafe {
            M8(_mm256_xor_ps(
                self.0,
                _mm256_castsi256_ps(_mm256_set1_epi32(-1)),
            ))
        }
    }
}

/// One lane read or written where the vector lies, and lanes merged under a mask, for a
/// lane type (`F8`, `U8`) of element `$elem`.
macro_rules! lane_access {
    ($ty:ident, $elem:ty) => {
        impl $ty {
            /// Lane `lane` (taken modulo the lane count), read where the vector lies (no copy
            /// of the whole vector, as indexing `to_array()` may make).
            #[inline(always)]
            pub fn lane(&self, lane: usize) -> $elem {
                // SAFETY: the vector is eight elements of this type.
                let lanes = unsafe { &*(self as *const $ty).cast::<[$elem; LANES]>() };
                lanes[lane & (LANES - 1)]
            }

            /// Sets lane `lane` (taken modulo the lane count) to `x`.
            #[inline(always)]
            pub fn set_lane(&mut self, lane: usize, x: $elem) {
                // SAFETY: the vector is eight elements of this type, and any bits are one.
                let lanes = unsafe { &mut *(self as *mut $ty).cast::<[$elem; LANES]>() };
                lanes[lane & (LANES - 1)] = x;
            }

            /// The lanes of `m` take `new`'s values. Written back with a plain store: a
            /// select into a vector in memory otherwise compiles to a masked store
            /// (`vmaskmovps`), which AMD's cores execute as microcode, many times slower
            /// than a blend and a store.
            #[inline(always)]
            pub fn merge(&mut self, m: M8, new: $ty) {
                let merged = $ty::select(m, new, *self);
                // SAFETY: `self` is a valid, aligned vector.
                unsafe { std::ptr::write_volatile(self, merged) }
            }
        }
    };
}

lane_access!(F8, f32);
lane_access!(U8, u32);

impl F8 {
    pub const ZERO: F8 = F8::from_array([0.0; 8]);
    pub const ONE: F8 = F8::from_array([1.0; 8]);

    /// The same value in every lane.
    #[inline(always)]
    pub fn splat(x: f32) -> F8 {
        unsafe { F8(_mm256_set1_ps(x)) }
    }

    /// Lanes from an array (lane i = `a[i]`).
    #[inline(always)]
    pub const fn from_array(a: [f32; 8]) -> F8 {
        // SAFETY: __m256 and [f32; 8] have the same size, and every bit pattern is valid.
        unsafe { std::mem::transmute::<[f32; 8], F8>(a) }
    }

    /// The lanes as an array.
    #[inline(always)]
    pub fn to_array(self) -> [f32; 8] {
        // SAFETY: as in `from_array`.
        unsafe { std::mem::transmute::<F8, [f32; 8]>(self) }
    }

    #[inline(always)]
    pub fn min(self, o: F8) -> F8 {
        unsafe { F8(_mm256_min_ps(self.0, o.0)) }
    }

    #[inline(always)]
    pub fn max(self, o: F8) -> F8 {
        unsafe { F8(_mm256_max_ps(self.0, o.0)) }
    }

    /// The least lane (a NaN lane may or may not be ignored).
    #[inline(always)]
    pub fn reduce_min(self) -> f32 {
        unsafe {
            let m = _mm_min_ps(
                _mm256_castps256_ps128(self.0),
                _mm256_extractf128_ps::<1>(self.0),
            );
            let m = _mm_min_ps(m, _mm_movehl_ps(m, m));
            _mm_cvtss_f32(_mm_min_ss(m, _mm_shuffle_ps::<1>(m, m)))
        }
    }

    /// Square root (correctly rounded, as f32::sqrt).
    #[inline(always)]
    pub fn sqrt(self) -> F8 {
        unsafe { F8(_mm256_sqrt_ps(self.0)) }
    }

    #[inline(always)]
    pub fn abs(self) -> F8 {
        unsafe { F8(_mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0)) }
    }

    /// Nearest integer, ties to even.
    #[inline(always)]
    pub fn round(self) -> F8 {
        unsafe {
            F8(_mm256_round_ps::<
                { _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC },
            >(self.0))
        }
    }

    /// Lanes of `a` where `m` is set, of `b` elsewhere.
    #[inline(always)]
    pub fn select(m: M8, a: F8, b: F8) -> F8 {
        unsafe { F8(_mm256_blendv_ps(b.0, a.0, m.0)) }
    }

    #[inline(always)]
    pub fn lt(self, o: F8) -> M8 {
        unsafe { M8(_mm256_cmp_ps::<_CMP_LT_OQ>(self.0, o.0)) }
    }

    #[inline(always)]
    pub fn le(self, o: F8) -> M8 {
        unsafe { M8(_mm256_cmp_ps::<_CMP_LE_OQ>(self.0, o.0)) }
    }

    #[inline(always)]
    pub fn gt(self, o: F8) -> M8 {
        unsafe { M8(_mm256_cmp_ps::<_CMP_GT_OQ>(self.0, o.0)) }
    }

    #[inline(always)]
    pub fn eq(self, o: F8) -> M8 {
        unsafe { M8(_mm256_cmp_ps::<_CMP_EQ_OQ>(self.0, o.0)) }
    }

    /// Not equal, or either is NaN (as `!=` on f32).
    #[inline(always)]
    pub fn ne(self, o: F8) -> M8 {
        unsafe { M8(_mm256_cmp_ps::<_CMP_NEQ_UQ>(self.0, o.0)) }
    }

    /// The lanes' bits as integers.
    #[inline(always)]
    pub fn to_bits(self) -> U8 {
        unsafe { U8(_mm256_castps_si256(self.0)) }
    }

    /// Floats with the lanes' bits.
    #[inline(always)]
    pub fn from_bits(bits: U8) -> F8 {
        unsafe { F8(_mm256_castsi256_ps(bits.0)) }
    }

    /// Rows into columns: lane j of the i-th result is lane i of row j (the 8×8
    /// transpose of unpacks, shuffles and 128-bit permutes).
    #[inline(always)]
    pub fn transpose(rows: [F8; 8]) -> [F8; 8] {
        let mut r = [unsafe { _mm256_setzero_ps() }; 8];
        for (r, row) in r.iter_mut().zip(rows) {
            *r = row.0;
        }
        unsafe {
            let t0 = _mm256_unpacklo_ps(r[0], r[1]);
            let t1 = _mm256_unpackhi_ps(r[0], r[1]);
            let t2 = _mm256_unpacklo_ps(r[2], r[3]);
            let t3 = _mm256_unpackhi_ps(r[2], r[3]);
            let t4 = _mm256_unpacklo_ps(r[4], r[5]);
            let t5 = _mm256_unpackhi_ps(r[4], r[5]);
            let t6 = _mm256_unpacklo_ps(r[6], r[7]);
            let t7 = _mm256_unpackhi_ps(r[6], r[7]);
            let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
            let u1 = _mm256_shuffle_ps::<0xee>(t0, t2);
            let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
            let u3 = _mm256_shuffle_ps::<0xee>(t1, t3);
            let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
            let u5 = _mm256_shuffle_ps::<0xee>(t4, t6);
            let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
            let u7 = _mm256_shuffle_ps::<0xee>(t5, t7);
            [
                F8(_mm256_permute2f128_ps::<0x20>(u0, u4)),
                F8(_mm256_permute2f128_ps::<0x20>(u1, u5)),
                F8(_mm256_permute2f128_ps::<0x20>(u2, u6)),
                F8(_mm256_permute2f128_ps::<0x20>(u3, u7)),
                F8(_mm256_permute2f128_ps::<0x31>(u0, u4)),
                F8(_mm256_permute2f128_ps::<0x31>(u1, u5)),
                F8(_mm256_permute2f128_ps::<0x31>(u2, u6)),
                F8(_mm256_permute2f128_ps::<0x31>(u3, u7)),
            ]
        }
    }

    /// Lanes of eight consecutive floats of `floats`, from `at` (unaligned).
    #[inline(always)]
    pub fn load(floats: &[f32], at: usize) -> F8 {
        assert!(at + LANES <= floats.len());
        // SAFETY: the eight floats are in the slice (checked above).
        unsafe { F8(_mm256_loadu_ps(floats.as_ptr().add(at))) }
    }

    /// Row `index[i]` of `table` in each lane, transposed (as [`U8::gather_rows`]).
    #[inline(always)]
    pub fn gather_rows(table: &[[f32; 4]], index: U8) -> [F8; 4] {
        // SAFETY: [f32; 4] and [u32; 4] have the same size and alignment, and every bit
        // pattern is valid for both.
        let bits =
            unsafe { std::slice::from_raw_parts(table.as_ptr().cast::<[u32; 4]>(), table.len()) };
        index.gather_rows(bits).map(F8::from_bits)
    }

    /// `table[index[i]]` in each lane; an index past the end reads the last entry.
    /// `table` must not be empty.
    #[inline(always)]
    pub fn gather(table: &[f32], index: U8) -> F8 {
        assert!(!table.is_empty() && table.len() <= i32::MAX as usize);
        let last = U8::splat(table.len() as u32 - 1);
        // SAFETY: every index is clamped into `table`.
        unsafe {
            let index = _mm256_min_epu32(index.0, last.0);
            F8(_mm256_i32gather_ps::<4>(table.as_ptr(), index))
        }
    }

    /// For lanes in [0, 1): the bin `(u as f64 * n as f64) as usize` (at most `n - 1`) and
    /// the fraction past it, `(x - bin as f64) as f32`, computed in f64 as the scalar alias
    /// table's `sample` computes them, so that both choose the same outcome.
    #[inline(always)]
    pub fn bin_and_fraction(self, n: u32) -> (U8, F8) {
        #[inline(always)]
        fn fraction(x: __m256d, bin: __m128i) -> __m128 {
            // SAFETY: as for the module's other intrinsics.
            unsafe { _mm256_cvtpd_ps(_mm256_sub_pd(x, _mm256_cvtepi32_pd(bin))) }
        }
        // SAFETY: as for the module's other intrinsics.
        unsafe {
            let count = _mm256_set1_pd(n as f64);
            let low = _mm256_mul_pd(_mm256_cvtps_pd(_mm256_castps256_ps128(self.0)), count);
            let high = _mm256_mul_pd(_mm256_cvtps_pd(_mm256_extractf128_ps::<1>(self.0)), count);
            let bins = _mm256_set_m128i(_mm256_cvttpd_epi32(high), _mm256_cvttpd_epi32(low));
            let bins = _mm256_min_epu32(bins, _mm256_set1_epi32(n as i32 - 1));
            let low = fraction(low, _mm256_castsi256_si128(bins));
            let high = fraction(high, _mm256_extracti128_si256::<1>(bins));
            (U8(bins), F8(_mm256_set_m128(high, low)))
        }
    }

    /// 1.0 with the sign of each lane (as `1.0f32.copysign(x)`).
    #[inline(always)]
    pub fn sign_of(x: F8) -> F8 {
        let sign = x.to_bits() & U8::splat(0x8000_0000);
        F8::from_bits(sign | F8::ONE.to_bits())
    }

    /// Truncates towards zero into signed integers (lanes out of range become i32::MIN).
    #[inline(always)]
    pub fn to_i32(self) -> U8 {
        unsafe { U8(_mm256_cvttps_epi32(self.0)) }
    }

    /// Sine and cosine of each lane: `sampling::warp::sin_cos`'s operations lane by lane,
    /// so the result is the scalar function's to the bit (the two kernels then sample the
    /// same directions).
    #[inline(always)]
    pub fn sin_cos(self) -> (F8, F8) {
        use crate::sampling::warp::sin_cos_constants::*;
        let q = (self * std::f32::consts::FRAC_2_PI).round();
        let r = ((self - q * PI_2_HIGH) - q * PI_2_MID) - q * PI_2_LOW;
        let r2 = r * r;
        let sin_poly = ((r2 * SIN[0] + SIN[1]) * r2 + SIN[2]) * (r2 * r) + r;
        let cos_poly = ((r2 * COS[0] + COS[1]) * r2 + COS[2]) * (r2 * r2) + (F8::ONE - r2 * 0.5);
        // Quadrant q mod 4: (sin, cos) of x = q π/2 + r.
        let quadrant = q.to_i32();
        let swap = (quadrant & U8::splat(1)).eq(U8::splat(1));
        let sin_negative = (quadrant & U8::splat(2)).eq(U8::splat(2));
        let cos_negative = ((quadrant + U8::splat(1)) & U8::splat(2)).eq(U8::splat(2));
        let s = F8::select(swap, cos_poly, sin_poly);
        let c = F8::select(swap, sin_poly, cos_poly);
        (
            F8::select(sin_negative, -s, s),
            F8::select(cos_negative, -c, c),
        )
    }
}

impl M8 {
    /// No lane set.
    #[inline(always)]
    pub fn none() -> M8 {
        unsafe { M8(_mm256_setzero_ps()) }
    }

    /// Every lane set.
    #[inline(always)]
    pub fn all() -> M8 {
        !M8::none()
    }

    /// The mask whose lane i is bit i of `bits`.
    #[inline(always)]
    pub fn from_bits(bits: u32) -> M8 {
        let lanes = U8::from_array([1, 2, 4, 8, 16, 32, 64, 128]);
        (U8::splat(bits) & lanes).eq(lanes)
    }

    /// Bit i set where lane i is set.
    #[inline(always)]
    pub fn bits(self) -> u32 {
        unsafe { _mm256_movemask_ps(self.0) as u32 }
    }

    #[inline(always)]
    pub fn any(self) -> bool {
        self.bits() != 0
    }

    /// The mask's lanes as integers (all ones or zero).
    #[inline(always)]
    pub fn as_u8(self) -> U8 {
        unsafe { U8(_mm256_castps_si256(self.0)) }
    }

    /// Set lanes of `self` that are not set in `o`.
    #[inline(always)]
    pub fn and_not(self, o: M8) -> M8 {
        unsafe { M8(_mm256_andnot_ps(o.0, self.0)) }
    }
}

impl U8 {
    /// The same value in every lane.
    #[inline(always)]
    pub fn splat(x: u32) -> U8 {
        unsafe { U8(_mm256_set1_epi32(x as i32)) }
    }

    /// Lanes from an array.
    #[inline(always)]
    pub const fn from_array(a: [u32; 8]) -> U8 {
        // SAFETY: __m256i and [u32; 8] have the same size, and every bit pattern is valid.
        unsafe { std::mem::transmute::<[u32; 8], U8>(a) }
    }

    #[inline(always)]
    pub fn eq(self, o: U8) -> M8 {
        unsafe { M8(_mm256_castsi256_ps(_mm256_cmpeq_epi32(self.0, o.0))) }
    }

    /// Lanes where `self` is above `o`, compared as unsigned integers.
    #[inline(always)]
    pub fn gt(self, o: U8) -> M8 {
        let most = unsafe { U8(_mm256_max_epu32(self.0, o.0)) };
        !most.eq(o)
    }

    /// The lanes as an array.
    #[inline(always)]
    pub fn to_array(self) -> [u32; 8] {
        // SAFETY: as in `from_array`.
        unsafe { std::mem::transmute::<U8, [u32; 8]>(self) }
    }

    /// Lanes of `a` where `m` is set, of `b` elsewhere.
    #[inline(always)]
    pub fn select(m: M8, a: U8, b: U8) -> U8 {
        F8::select(m, F8::from_bits(a), F8::from_bits(b)).to_bits()
    }

    /// Lane-wise wrapping product (the low 32 bits, as `u32::wrapping_mul`).
    #[inline(always)]
    pub fn wrapping_mul(self, o: U8) -> U8 {
        unsafe { U8(_mm256_mullo_epi32(self.0, o.0)) }
    }

    /// Logical shift right by `N` bits.
    #[inline(always)]
    pub fn shr<const N: i32>(self) -> U8 {
        unsafe { U8(_mm256_srli_epi32::<N>(self.0)) }
    }

    /// Shift left by `N` bits.
    #[inline(always)]
    pub fn shl<const N: i32>(self) -> U8 {
        unsafe { U8(_mm256_slli_epi32::<N>(self.0)) }
    }

    /// Each lane's bits in reverse order (as `u32::reverse_bits`).
    #[inline(always)]
    pub fn reverse_bits(self) -> U8 {
        // Each byte's nibbles reversed through two 16-entry tables and swapped, then the
        // bytes of each lane swapped: three byte shuffles instead of five mask-and-shift
        // steps.
        unsafe {
            #[rustfmt::skip]
            let reversed = _mm256_setr_epi8(
                0x0, 0x8, 0x4, 0xc, 0x2, 0xa, 0x6, 0xe, 0x1, 0x9, 0x5, 0xd, 0x3, 0xb, 0x7, 0xf,
                0x0, 0x8, 0x4, 0xc, 0x2, 0xa, 0x6, 0xe, 0x1, 0x9, 0x5, 0xd, 0x3, 0xb, 0x7, 0xf,
            );
            let high = _mm256_slli_epi16::<4>(reversed);
            let nibble = _mm256_set1_epi8(0x0f);
            let low_nibbles = _mm256_and_si256(self.0, nibble);
            let high_nibbles = _mm256_and_si256(_mm256_srli_epi16::<4>(self.0), nibble);
            let bytes = _mm256_or_si256(
                _mm256_shuffle_epi8(high, low_nibbles),
                _mm256_shuffle_epi8(reversed, high_nibbles),
            );
            #[rustfmt::skip]
            let swap = _mm256_setr_epi8(
                3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12,
                3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12,
            );
            U8(_mm256_shuffle_epi8(bytes, swap))
        }
    }

    /// Row `self[i]` of `table` in each lane, transposed: element `d` of the lanes' rows in
    /// vector `d`. One 16-byte load a lane and a 4×4 transpose instead of four gathers; an
    /// index past the end reads the last row. `table` must not be empty.
    #[inline(always)]
    pub fn gather_rows(self, table: &[[u32; 4]]) -> [U8; 4] {
        assert!(!table.is_empty() && table.len() <= i32::MAX as usize);
        let last = U8::splat(table.len() as u32 - 1);
        // SAFETY: every index is clamped into `table`, whose rows are 16 bytes.
        unsafe {
            let rows = U8(_mm256_min_epu32(self.0, last.0)).to_array();
            let base = table.as_ptr() as *const __m128i;
            let row = |lane: usize| _mm_loadu_si128(base.add(rows[lane] as usize));
            // Lanes l and l + 4 in the two halves, so that the transposes within halves
            // leave the lanes in order.
            let pair =
                |l: usize| _mm256_inserti128_si256::<1>(_mm256_castsi128_si256(row(l)), row(l + 4));
            let (a, b, c, d) = (pair(0), pair(1), pair(2), pair(3));
            let (ab_low, cd_low) = (_mm256_unpacklo_epi32(a, b), _mm256_unpacklo_epi32(c, d));
            let (ab_high, cd_high) = (_mm256_unpackhi_epi32(a, b), _mm256_unpackhi_epi32(c, d));
            [
                U8(_mm256_unpacklo_epi64(ab_low, cd_low)),
                U8(_mm256_unpackhi_epi64(ab_low, cd_low)),
                U8(_mm256_unpacklo_epi64(ab_high, cd_high)),
                U8(_mm256_unpackhi_epi64(ab_high, cd_high)),
            ]
        }
    }

    /// `table[self[i]]` in each lane; an index past the end reads the last entry (so that
    /// no index can read outside the table). `table` must not be empty.
    #[inline(always)]
    pub fn gather(self, table: &[u32]) -> U8 {
        assert!(!table.is_empty() && table.len() <= i32::MAX as usize);
        let last = U8::splat(table.len() as u32 - 1);
        // SAFETY: every index is clamped into `table`.
        unsafe {
            let index = _mm256_min_epu32(self.0, last.0);
            U8(_mm256_i32gather_epi32::<4>(
                table.as_ptr() as *const i32,
                index,
            ))
        }
    }

    /// The top 23 bits as a float in [0, 1) (sobol_burley's `to_f32_norm`).
    #[inline(always)]
    pub fn to_f32_norm(self) -> F8 {
        unsafe {
            let bits = _mm256_or_si256(
                _mm256_srli_epi32::<9>(self.0),
                _mm256_set1_epi32(0x3f80_0000),
            );
            F8(_mm256_castsi256_ps(bits)) - F8::ONE
        }
    }
}

/// A vector per lane.
#[derive(Clone, Copy, Debug)]
pub struct V3 {
    pub x: F8,
    pub y: F8,
    pub z: F8,
}

impl V3 {
    pub const ZERO: V3 = V3 {
        x: F8::ZERO,
        y: F8::ZERO,
        z: F8::ZERO,
    };

    #[inline(always)]
    pub fn new(x: F8, y: F8, z: F8) -> V3 {
        V3 { x, y, z }
    }

    /// The vector `v` in every lane.
    #[inline(always)]
    pub fn splat(v: Vec3) -> V3 {
        V3::new(F8::splat(v.x), F8::splat(v.y), F8::splat(v.z))
    }

    /// The same value in every component.
    #[inline(always)]
    pub fn broadcast(x: F8) -> V3 {
        V3::new(x, x, x)
    }

    /// Lanes from eight vectors: six loads of the 24 floats and five shuffles (Intel's
    /// three-way deinterleave), where copying component by component would cost 24 scalar
    /// stores and three vector loads that wait for them.
    #[inline(always)]
    pub fn from_lanes(v: &[Vec3; 8]) -> V3 {
        // glam's Vec3 is three f32s (repr(C), 12 bytes): the array is x0 y0 z0 x1 … z7.
        const { assert!(std::mem::size_of::<[Vec3; 8]>() == 96) };
        // Floats `at` to `at + 3` and `at + 12` to `at + 15` of `p` (a function, not a closure,
        // so that it compiles in the caller's AVX2 context).
        #[inline(always)]
        unsafe fn halves(p: *const f32, at: usize) -> __m256 {
            unsafe {
                _mm256_insertf128_ps::<1>(
                    _mm256_castps128_ps256(_mm_loadu_ps(p.add(at))),
                    _mm_loadu_ps(p.add(at + 12)),
                )
            }
        }
        let p = v.as_ptr().cast::<f32>();
        unsafe {
            // x0 y0 z0 x1 | x4 y4 z4 x5;  y1 z1 x2 y2 | y5 z5 x6 y6;  z2 x3 y3 z3 | z6 x7 y7 z7.
            let (m03, m14, m25) = (halves(p, 0), halves(p, 4), halves(p, 8));
            // x2 y2 x3 y3 | x6 y6 x7 y7;  y0 z0 y1 z1 | y4 z4 y5 z5.
            let xy = _mm256_shuffle_ps::<0b10_01_11_10>(m14, m25);
            let yz = _mm256_shuffle_ps::<0b01_00_10_01>(m03, m14);
            V3::new(
                F8(_mm256_shuffle_ps::<0b10_00_11_00>(m03, xy)),
                F8(_mm256_shuffle_ps::<0b11_01_10_00>(yz, xy)),
                F8(_mm256_shuffle_ps::<0b11_00_11_01>(yz, m25)),
            )
        }
    }

    /// `color::luminance` of each lane, with its operations in its order.
    #[inline(always)]
    pub fn luminance(self) -> F8 {
        self.x * 0.2126 + self.y * 0.7152 + self.z * 0.0722
    }

    /// The lanes of `m` take `new`'s values ([`F8::merge`]).
    #[inline(always)]
    pub fn merge(&mut self, m: M8, new: V3) {
        self.x.merge(m, new.x);
        self.y.merge(m, new.y);
        self.z.merge(m, new.z);
    }

    /// Sets lane `lane` to `v`.
    #[inline(always)]
    pub fn set_lane(&mut self, lane: usize, v: Vec3) {
        self.x.set_lane(lane, v.x);
        self.y.set_lane(lane, v.y);
        self.z.set_lane(lane, v.z);
    }

    /// Lane `lane` as a vector.
    #[inline(always)]
    pub fn lane(&self, lane: usize) -> Vec3 {
        Vec3::new(self.x.lane(lane), self.y.lane(lane), self.z.lane(lane))
    }

    /// The dot product, in glam's order of operations (so that it rounds as the scalar
    /// kernel's does).
    #[inline(always)]
    pub fn dot(self, o: V3) -> F8 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    #[inline(always)]
    pub fn length_squared(self) -> F8 {
        self.dot(self)
    }

    /// The unit vector (NaN lanes where the length is 0).
    #[inline(always)]
    pub fn normalize(self) -> V3 {
        self * (F8::ONE / self.length_squared().sqrt())
    }

    /// The lanes as eight vectors: [`V3::from_lanes`]'s shuffles backwards, and six stores.
    #[inline(always)]
    pub fn to_lanes(self) -> [Vec3; 8] {
        const { assert!(std::mem::size_of::<[Vec3; 8]>() == 96) };
        let (x, y, z) = (self.x.0, self.y.0, self.z.0);
        let mut out = [Vec3::ZERO; 8];
        let p = out.as_mut_ptr().cast::<f32>();
        unsafe {
            // x0 x2 y0 y2;  y1 y3 z1 z3;  z0 z2 x1 x3 (and lanes 4 to 7 in the high halves).
            let xy = _mm256_shuffle_ps::<0b10_00_10_00>(x, y);
            let yz = _mm256_shuffle_ps::<0b11_01_11_01>(y, z);
            let zx = _mm256_shuffle_ps::<0b11_01_10_00>(z, x);
            // x0 y0 z0 x1;  y1 z1 x2 y2;  z2 x3 y3 z3.
            let m03 = _mm256_shuffle_ps::<0b10_00_10_00>(xy, zx);
            let m14 = _mm256_shuffle_ps::<0b11_01_10_00>(yz, xy);
            let m25 = _mm256_shuffle_ps::<0b11_01_11_01>(zx, yz);
            for (i, m) in [m03, m14, m25].into_iter().enumerate() {
                _mm_storeu_ps(p.add(4 * i), _mm256_castps256_ps128(m));
                _mm_storeu_ps(p.add(12 + 4 * i), _mm256_extractf128_ps::<1>(m));
            }
        }
        out
    }

    /// The unit vector where glam's `normalize_or` gives one (a finite, positive inverse
    /// length), `fallback` elsewhere; also says in which lanes it gave one.
    #[inline(always)]
    pub fn normalize_or(self, fallback: V3) -> (V3, M8) {
        let rcp = F8::ONE / self.length_squared().sqrt();
        let ok = rcp.gt(F8::ZERO) & rcp.lt(F8::splat(f32::INFINITY));
        (V3::select(ok, self * rcp, fallback), ok)
    }

    /// The cross product computed in f64 from the f32 lanes and rounded back to f32: glam's
    /// `DVec3::cross` of `as_dvec3()`s and `as_vec3()`, to the bit
    /// (`geometry::triangle::geometric_normal`).
    #[inline(always)]
    pub fn cross_in_f64(self, o: V3) -> V3 {
        #[inline(always)]
        fn half<const HIGH: i32>(v: F8) -> __m256d {
            // SAFETY: as for the module's other intrinsics.
            unsafe { _mm256_cvtps_pd(_mm256_extractf128_ps::<HIGH>(v.0)) }
        }
        #[inline(always)]
        fn diff(a: __m256d, b: __m256d, c: __m256d, d: __m256d) -> __m128 {
            // SAFETY: as for the module's other intrinsics.
            unsafe { _mm256_cvtpd_ps(_mm256_sub_pd(_mm256_mul_pd(a, b), _mm256_mul_pd(c, d))) }
        }
        #[inline(always)]
        fn cross_half<const HIGH: i32>(a: V3, b: V3) -> [__m128; 3] {
            let (ax, ay, az) = (half::<HIGH>(a.x), half::<HIGH>(a.y), half::<HIGH>(a.z));
            let (bx, by, bz) = (half::<HIGH>(b.x), half::<HIGH>(b.y), half::<HIGH>(b.z));
            [
                diff(ay, bz, by, az),
                diff(az, bx, bz, ax),
                diff(ax, by, bx, ay),
            ]
        }
        #[inline(always)]
        fn join(low: __m128, high: __m128) -> F8 {
            // SAFETY: as for the module's other intrinsics.
            unsafe { F8(_mm256_set_m128(high, low)) }
        }
        let ([lx, ly, lz], [hx, hy, hz]) = (cross_half::<0>(self, o), cross_half::<1>(self, o));
        V3::new(join(lx, hx), join(ly, hy), join(lz, hz))
    }

    /// Lanes of `a` where `m` is set, of `b` elsewhere.
    #[inline(always)]
    pub fn select(m: M8, a: V3, b: V3) -> V3 {
        V3::new(
            F8::select(m, a.x, b.x),
            F8::select(m, a.y, b.y),
            F8::select(m, a.z, b.z),
        )
    }
}

impl Add for V3 {
    type Output = V3;
    #[inline(always)]
    fn add(self, o: V3) -> V3 {
        V3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl Sub for V3 {
    type Output = V3;
    #[inline(always)]
    fn sub(self, o: V3) -> V3 {
        V3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl Neg for V3 {
    type Output = V3;
    #[inline(always)]
    fn neg(self) -> V3 {
        V3::new(-self.x, -self.y, -self.z)
    }
}

impl Mul for V3 {
    type Output = V3;
    #[inline(always)]
    fn mul(self, o: V3) -> V3 {
        V3::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
}

impl Mul<F8> for V3 {
    type Output = V3;
    #[inline(always)]
    fn mul(self, s: F8) -> V3 {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
}

impl Div<F8> for V3 {
    type Output = V3;
    #[inline(always)]
    fn div(self, s: F8) -> V3 {
        V3::new(self.x / s, self.y / s, self.z / s)
    }
}

impl AddAssign for V3 {
    #[inline(always)]
    fn add_assign(&mut self, o: V3) {
        *self = *self + o;
    }
}

/// Whether this CPU has AVX2 and FMA, which every use of these types needs.
pub fn available() -> bool {
    is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
}

/// For the lane tests across the crate: whether the CPU has AVX2 and FMA (the module's
/// invariant); where it has not, says the test is skipped.
#[cfg(test)]
pub(crate) fn avx2_or_skip() -> bool {
    let available = available();
    if !available {
        eprintln!("no AVX2 and FMA here: skipped");
    }
    available
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `f` where the CPU has AVX2 and FMA (the module's invariant); skips elsewhere.
    fn with_avx2(f: impl FnOnce()) {
        if avx2_or_skip() {
            f();
        }
    }

    /// The lanes' sine and cosine are the scalar `warp::sin_cos`'s to the bit.
    #[test]
    fn sin_cos_is_the_scalar_functions() {
        with_avx2(|| {
            for i in 0..20_000 {
                let base = -40.0 + i as f32 * (80.0 / 20_000.0);
                let x = F8::from_array(std::array::from_fn(|l| base + l as f32 * 5e-4));
                let (s, c) = x.sin_cos();
                for l in 0..8 {
                    let (es, ec) = crate::sampling::warp::sin_cos(x.to_array()[l]);
                    assert_eq!(s.to_array()[l].to_bits(), es.to_bits());
                    assert_eq!(c.to_array()[l].to_bits(), ec.to_bits());
                }
            }
        });
    }

    /// Lanes read and written one at a time, merged under a mask and shifted down, and
    /// unsigned comparisons (above 2^31 too).
    #[test]
    fn lane_access_merges() {
        with_avx2(|| {
            let mut x = F8::from_array(std::array::from_fn(|l| l as f32));
            x.set_lane(3, -7.5);
            assert_eq!(x.lane(3), -7.5);
            assert_eq!(x.lane(4), 4.0);
            let m = M8::from_bits(0b1010_0101);
            x.merge(m, F8::splat(100.0));
            assert_eq!(
                x.to_array(),
                [100.0, 1.0, 100.0, -7.5, 4.0, 100.0, 6.0, 100.0]
            );
            let big = [0, 1, 8, 9, u32::MAX, 1 << 31, 7, 3];
            let mut u = U8::from_array(big);
            assert_eq!(u.gt(U8::splat(8)).bits(), 0b0011_1000);
            u.set_lane(0, 42);
            u.merge(M8::from_bits(0b1000_0000), U8::splat(5));
            assert_eq!(u.lane(0), 42);
            assert_eq!(u.to_array(), [42, 1, 8, 9, u32::MAX, 1 << 31, 7, 5]);
        });
    }

    /// The transpose takes lane j of row i to lane i of row j.
    #[test]
    fn transpose_swaps_rows_and_columns() {
        with_avx2(|| {
            let rows: [F8; 8] = std::array::from_fn(|i| {
                F8::from_array(std::array::from_fn(|j| (8 * i + j) as f32))
            });
            let columns = F8::transpose(rows);
            for (i, column) in columns.iter().enumerate() {
                let expected: [f32; 8] = std::array::from_fn(|j| (8 * j + i) as f32);
                assert_eq!(column.to_array(), expected, "column {i}");
            }
        });
    }

    /// Eight vectors go into lanes and back as they are, bit for bit (NaNs and signed zeros
    /// included), lane i the i-th vector.
    #[test]
    fn lanes_of_vectors_round_trip() {
        with_avx2(|| {
            let special = [f32::NAN, -0.0, f32::INFINITY, f32::MIN_POSITIVE / 4.0];
            let v: [Vec3; 8] = std::array::from_fn(|i| {
                let c = |k: usize| (i * 3 + k) as f32 + 0.25;
                Vec3::new(c(0), -c(1), if i < 4 { special[i] } else { c(2) })
            });
            let lanes = V3::from_lanes(&v);
            let bits = |f: f32| f.to_bits();
            for (i, u) in v.iter().enumerate() {
                let got = [lanes.x, lanes.y, lanes.z].map(|c| c.to_array()[i]);
                assert_eq!(got.map(bits), u.to_array().map(bits), "lane {i}");
            }
            let back = lanes.to_lanes();
            for (u, w) in v.iter().zip(&back) {
                assert_eq!(w.to_array().map(bits), u.to_array().map(bits));
            }
        });
    }

    /// The integer lanes agree with u32's operations, and gathers clamp into the table.
    #[test]
    fn integer_lanes_are_u32_operations() {
        with_avx2(|| {
            let mut rng = crate::sampling::pcg::Pcg32::new(1, 2);
            for _ in 0..10_000 {
                let a: [u32; 8] = std::array::from_fn(|_| rng.next_u32());
                let b: [u32; 8] = std::array::from_fn(|_| rng.next_u32());
                let (x, y) = (U8::from_array(a), U8::from_array(b));
                let each = |f: fn(u32, u32) -> u32| std::array::from_fn(|l| f(a[l], b[l]));
                assert_eq!(x.wrapping_mul(y).to_array(), each(u32::wrapping_mul));
                assert_eq!((x + y).to_array(), each(u32::wrapping_add));
                assert_eq!(x.reverse_bits().to_array(), a.map(u32::reverse_bits));
                assert_eq!(x.shr::<7>().to_array(), a.map(|v| v >> 7));
                assert_eq!(x.shl::<9>().to_array(), a.map(|v| v << 9));
                let f = x.to_f32_norm().to_array();
                let expected = a.map(|v| f32::from_bits((v >> 9) | 0x3f80_0000) - 1.0);
                assert_eq!(f.map(f32::to_bits), expected.map(f32::to_bits));
            }
            let table: Vec<u32> = (0..10).map(|i| i * 100).collect();
            let index = U8::from_array([0, 9, 3, 10, u32::MAX, 1, 2, 5]);
            assert_eq!(
                index.gather(&table).to_array(),
                [0, 900, 300, 900, 900, 100, 200, 500]
            );
            let rows: Vec<[u32; 4]> = (0..10)
                .map(|i| std::array::from_fn(|d| i * 100 + d as u32))
                .collect();
            let by_dim = index.gather_rows(&rows).map(U8::to_array);
            for (d, lanes) in by_dim.iter().enumerate() {
                let row = |i: u32| 100 * i + d as u32;
                let expected = [0, 9, 3, 9, 9, 1, 2, 5].map(row);
                assert_eq!(*lanes, expected, "element {d}");
            }
            let float_rows: Vec<[f32; 4]> =
                rows.iter().map(|r| r.map(|v| v as f32 + 0.5)).collect();
            let floats = F8::gather_rows(&float_rows, index).map(F8::to_array);
            for (d, lanes) in floats.iter().enumerate() {
                let row = |i: u32| (100 * i + d as u32) as f32 + 0.5;
                assert_eq!(*lanes, [0, 9, 3, 9, 9, 1, 2, 5].map(row), "element {d}");
            }
        });
    }

    #[test]
    fn masks_and_selects() {
        with_avx2(|| {
            let a = F8::from_array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, f32::NAN]);
            let m = a.lt(F8::splat(3.0));
            assert_eq!(m.bits(), 0b0000_0111);
            assert_eq!((!m).bits(), 0b1111_1000);
            assert_eq!(a.ne(a).bits(), 0b1000_0000);
            assert_eq!(M8::from_bits(0b1010_0101).bits(), 0b1010_0101);
            let s = F8::select(m, F8::ONE, F8::ZERO).to_array();
            assert_eq!(s, [1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
            let u = U8::from_array([1, 2, 3, 4, 5, 6, 7, 0xffff_ffff]);
            assert_eq!(u.eq(U8::splat(3)).bits(), 0b0000_0100);
            assert_eq!(
                F8::from_array([-1.5, 2.7, 0.5, -0.5, 3.0, 0.0, 9.9, -7.2])
                    .round()
                    .to_i32()
                    .eq(U8::from_array([
                        u32::MAX - 1,
                        3,
                        0,
                        0,
                        3,
                        0,
                        10,
                        u32::MAX - 6
                    ]))
                    .bits(),
                0xff
            );
        });
    }
}
