//! `conv3x3.u8s8.4x1.avx2`: the int8 row for x86-64 without VNNI, on the generic loop
//! [`simd_u8::conv`](super::simd_u8::conv). `vpmaddubsw` would saturate (255·127·2 > 32767), so inputs are
//! zero-extended to i16 (`vpmovzxbw`, 4 pixels × 4 channels per ymm) and multiplied with i16 weights by
//! `vpmaddwd` (exact): lane `2p` accumulates channels 0–1 of pixel `p`, lane `2p+1` channels 2–3; the two are
//! added once per tile (`vphaddd` + `vpermq`). An 8-pixel unit is 2 ymm accumulators, so the tile is 4 output
//! channels × 8 pixels = 8 accumulators + 2 inputs + 1 weight (11 of 16 ymm).
//!
//! The f32 epilogue on `__m256` (macro `epilogue_256`) is shared with the AVX-VNNI row
//! ([`u8s8_avxvnni`](super::u8s8_avxvnni)), so that row (not testable on the machine the tests ran on) differs
//! from this tested one only in `load_x`/`load_w`/`dot`/`to_f32`. In test builds this file also runs the two
//! VNNI rows' tile geometries on AVX2 registers (`Wide16`, `conv_*_geometry`).

use super::job::{entry_points, U8Job, U8Out};
use super::simd_u8::{conv, SimdQ};
use std::arch::x86_64::*;

/// Lane masks of the 256-bit stores: `MASK[8 − valid..]` keeps the first `valid` lanes.
pub(super) static MASK: [i32; 16] = [-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0];

/// AVX2 widening accumulator: pixels 0–3 and 4–7, two i32 lanes (channel pairs) per pixel.
#[derive(Clone, Copy)]
pub(crate) struct Avx2Wide(__m256i, __m256i);

/// The f32 epilogue operations on `__m256` shared by the 256-bit rows.
macro_rules! epilogue_256 {
    () => {
        type F = __m256;
        #[inline(always)]
        unsafe fn splat(v: f32) -> __m256 {
            // SAFETY: the caller guarantees AVX2.
            unsafe { _mm256_set1_ps(v) }
        }
        #[inline(always)]
        unsafe fn mul(a: __m256, b: __m256) -> __m256 {
            // SAFETY: the caller guarantees AVX2.
            unsafe { _mm256_mul_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn add(a: __m256, b: __m256) -> __m256 {
            // SAFETY: the caller guarantees AVX2.
            unsafe { _mm256_add_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn sub(a: __m256, b: __m256) -> __m256 {
            // SAFETY: the caller guarantees AVX2.
            unsafe { _mm256_sub_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn relu(v: __m256) -> __m256 {
            // SAFETY: the caller guarantees AVX2. `maxps(v, 0)` = `v > 0 ? v : 0` (NaN and ±0 give 0).
            unsafe { _mm256_max_ps(v, _mm256_setzero_ps()) }
        }
        #[inline(always)]
        unsafe fn load_byte(p: *const u8, lane: usize) -> __m256 {
            // SAFETY: the caller guarantees AVX2 and 32 readable bytes at `p`.
            unsafe {
                let w = _mm256_loadu_si256(p.cast());
                let s = _mm256_srl_epi32(w, _mm_cvtsi32_si128(8 * lane as i32));
                _mm256_cvtepi32_ps(_mm256_and_si256(s, _mm256_set1_epi32(0xFF)))
            }
        }
        #[inline(always)]
        unsafe fn quant(v: __m256, inv: __m256, zp: __m256) -> __m256 {
            // SAFETY: the caller guarantees AVX2. Round to nearest even, then `max(·, 0)`, `min(·, 255)` with
            // the constant second, as the scalar `quantize`.
            unsafe {
                let r = _mm256_round_ps::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(
                    _mm256_mul_ps(v, inv),
                );
                let y = _mm256_max_ps(_mm256_add_ps(r, zp), _mm256_setzero_ps());
                _mm256_min_ps(y, _mm256_set1_ps(255.0))
            }
        }
        #[inline(always)]
        unsafe fn store_u8x4(p: *mut u8, q: [__m256; 4], valid: usize, border: u8) {
            // SAFETY: the caller guarantees AVX2 and 32 writable bytes at `p`; `8 − valid ∈ 0..=8` keeps the
            // mask read inside MASK.
            unsafe {
                let mut word = _mm256_cvttps_epi32(q[0]);
                word = _mm256_or_si256(word, _mm256_slli_epi32::<8>(_mm256_cvttps_epi32(q[1])));
                word = _mm256_or_si256(word, _mm256_slli_epi32::<16>(_mm256_cvttps_epi32(q[2])));
                word = _mm256_or_si256(word, _mm256_slli_epi32::<24>(_mm256_cvttps_epi32(q[3])));
                if valid < 8 {
                    let m = _mm256_loadu_si256(MASK.as_ptr().add(8 - valid).cast());
                    let b = _mm256_set1_epi32(i32::from_ne_bytes([border; 4]));
                    word = _mm256_blendv_epi8(b, word, m);
                }
                _mm256_storeu_si256(p.cast(), word)
            }
        }
        #[inline(always)]
        unsafe fn store_f32(p: *mut f32, v: __m256, valid: usize) {
            // SAFETY: the caller guarantees AVX2 and `valid` writable values at `p`; `vmaskmovps` writes only
            // the lanes whose mask is set (the first `valid`).
            unsafe {
                if valid == 8 {
                    _mm256_storeu_ps(p, v)
                } else {
                    let m = _mm256_loadu_si256(MASK.as_ptr().add(8 - valid).cast());
                    _mm256_maskstore_ps(p, m, v)
                }
            }
        }
    };
}
pub(super) use epilogue_256;

impl SimdQ for Avx2Wide {
    const PX: usize = 8;
    const WB: usize = 8;
    type X = (__m256i, __m256i);
    type W = __m256i;
    epilogue_256!();
    #[inline(always)]
    unsafe fn init(v: i32) -> Self {
        // SAFETY: the caller guarantees AVX2. Only lane 0 of each pixel's pair starts at `v`.
        unsafe {
            let s = _mm256_setr_epi32(v, 0, v, 0, v, 0, v, 0);
            Avx2Wide(s, s)
        }
    }
    #[inline(always)]
    unsafe fn load_x(p: *const u8) -> Self::X {
        // SAFETY: the caller guarantees AVX2 and 32 readable bytes at `p`.
        unsafe {
            (
                _mm256_cvtepu8_epi16(_mm_loadu_si128(p.cast())),
                _mm256_cvtepu8_epi16(_mm_loadu_si128(p.add(16).cast())),
            )
        }
    }
    #[inline(always)]
    unsafe fn load_w(p: *const u8) -> Self::W {
        // SAFETY: the caller guarantees AVX2 and 8 readable bytes at `p` (4 × i16, little-endian).
        unsafe { _mm256_set1_epi64x(p.cast::<i64>().read_unaligned()) }
    }
    #[inline(always)]
    unsafe fn dot(self, x: Self::X, w: Self::W) -> Self {
        // SAFETY: the caller guarantees AVX2. `vpmaddwd` of u8 (as i16) × s8 (as i16) pairs is exact.
        unsafe {
            Avx2Wide(
                _mm256_add_epi32(self.0, _mm256_madd_epi16(x.0, w)),
                _mm256_add_epi32(self.1, _mm256_madd_epi16(x.1, w)),
            )
        }
    }
    #[inline(always)]
    unsafe fn to_f32(self) -> __m256 {
        // SAFETY: the caller guarantees AVX2. hadd gives pixels [0 1 4 5 | 2 3 6 7]; vpermq puts them in order.
        unsafe {
            let s = _mm256_hadd_epi32(self.0, self.1);
            _mm256_cvtepi32_ps(_mm256_permute4x64_epi64::<0b11_01_10_00>(s))
        }
    }
}

entry_points! {
    "avx2,fma", U8Job, U8Out;
    /// `conv3x3.u8s8.4x1.avx2`.
    ///
    /// # Safety
    /// The CPU has AVX2; the job was checked by the safe API and packed with
    /// [`PackKind::I16`](crate::registry::PackKind).
    fn conv_avx2 = conv::<Avx2Wide, 4, 1>;
    /// Tests only: the AVX-VNNI row's tile geometry (4 × 2 units of 8 pixels) with the AVX2 widening dot.
    ///
    /// # Safety
    /// As [`conv_avx2`].
    #[cfg(test)]
    fn conv_avxvnni_geometry = conv::<Avx2Wide, 4, 2>;
    /// Tests only: the AVX-512 VNNI row's tile geometry (8 × 3 units of 16 pixels) with the AVX2 widening
    /// dot.
    ///
    /// # Safety
    /// As [`conv_avx2`].
    #[cfg(test)]
    fn conv_avx512vnni_geometry = conv::<Wide16, 8, 3>;
}

/// `vpmaddwd` + `vpaddd` peak: 12 chains; ops = `iters · 12 · 16 · 2`.
///
/// # Safety
/// The CPU has AVX2.
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn peak_avx2(iters: u64) -> i32 {
    let mut acc = [_mm256_set1_epi32(1); 12];
    let w = _mm256_set1_epi16(-2);
    for _ in 0..iters {
        for a in acc.iter_mut() {
            // The product depends on the accumulator, so it cannot be hoisted out of the loop.
            *a = _mm256_add_epi32(*a, _mm256_madd_epi16(*a, w));
        }
    }
    let mut s = _mm256_setzero_si256();
    for a in acc {
        s = _mm256_add_epi32(s, a);
    }
    _mm256_extract_epi32::<0>(s)
}

/// Tests only: two AVX2 widening units acting as one 16-pixel unit, so that the generic loop runs the
/// AVX-512 VNNI row's tile geometry (8 output channels × 3 units of 16 pixels, 16-lane masks) on a CPU
/// without AVX-512; the epilogue operations are the 256-bit ones applied to each half.
#[cfg(test)]
#[derive(Clone, Copy)]
pub(crate) struct Wide16(Avx2Wide, Avx2Wide);

#[cfg(test)]
impl SimdQ for Wide16 {
    const PX: usize = 16;
    const WB: usize = 8;
    type X = ((__m256i, __m256i), (__m256i, __m256i));
    type W = __m256i;
    type F = (__m256, __m256);
    #[inline(always)]
    unsafe fn init(v: i32) -> Self {
        // SAFETY: the caller guarantees AVX2.
        unsafe { Wide16(Avx2Wide::init(v), Avx2Wide::init(v)) }
    }
    #[inline(always)]
    unsafe fn load_x(p: *const u8) -> Self::X {
        // SAFETY: the caller guarantees 64 readable bytes at `p`.
        unsafe { (Avx2Wide::load_x(p), Avx2Wide::load_x(p.add(32))) }
    }
    #[inline(always)]
    unsafe fn load_w(p: *const u8) -> Self::W {
        // SAFETY: the caller guarantees 8 readable bytes at `p`.
        unsafe { Avx2Wide::load_w(p) }
    }
    #[inline(always)]
    unsafe fn dot(self, x: Self::X, w: Self::W) -> Self {
        // SAFETY: the caller guarantees AVX2.
        unsafe { Wide16(self.0.dot(x.0, w), self.1.dot(x.1, w)) }
    }
    #[inline(always)]
    unsafe fn to_f32(self) -> Self::F {
        // SAFETY: the caller guarantees AVX2.
        unsafe { (self.0.to_f32(), self.1.to_f32()) }
    }
    #[inline(always)]
    unsafe fn splat(v: f32) -> Self::F {
        // SAFETY: the caller guarantees AVX2.
        unsafe { (Avx2Wide::splat(v), Avx2Wide::splat(v)) }
    }
    #[inline(always)]
    unsafe fn mul(a: Self::F, b: Self::F) -> Self::F {
        // SAFETY: the caller guarantees AVX2.
        unsafe { (Avx2Wide::mul(a.0, b.0), Avx2Wide::mul(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn add(a: Self::F, b: Self::F) -> Self::F {
        // SAFETY: the caller guarantees AVX2.
        unsafe { (Avx2Wide::add(a.0, b.0), Avx2Wide::add(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn sub(a: Self::F, b: Self::F) -> Self::F {
        // SAFETY: the caller guarantees AVX2.
        unsafe { (Avx2Wide::sub(a.0, b.0), Avx2Wide::sub(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn relu(v: Self::F) -> Self::F {
        // SAFETY: the caller guarantees AVX2.
        unsafe { (Avx2Wide::relu(v.0), Avx2Wide::relu(v.1)) }
    }
    #[inline(always)]
    unsafe fn load_byte(p: *const u8, lane: usize) -> Self::F {
        // SAFETY: the caller guarantees 64 readable bytes at `p`.
        unsafe {
            (
                Avx2Wide::load_byte(p, lane),
                Avx2Wide::load_byte(p.add(32), lane),
            )
        }
    }
    #[inline(always)]
    unsafe fn quant(v: Self::F, inv: Self::F, zp: Self::F) -> Self::F {
        // SAFETY: the caller guarantees AVX2.
        unsafe {
            (
                Avx2Wide::quant(v.0, inv.0, zp.0),
                Avx2Wide::quant(v.1, inv.1, zp.1),
            )
        }
    }
    #[inline(always)]
    unsafe fn store_u8x4(p: *mut u8, q: [Self::F; 4], valid: usize, border: u8) {
        // SAFETY: the caller guarantees 64 writable bytes at `p`; each half gets its own valid count.
        unsafe {
            Avx2Wide::store_u8x4(p, q.map(|f| f.0), valid.min(8), border);
            Avx2Wide::store_u8x4(p.add(32), q.map(|f| f.1), valid.saturating_sub(8), border);
        }
    }
    #[inline(always)]
    unsafe fn store_f32(p: *mut f32, v: Self::F, valid: usize) {
        // SAFETY: the caller guarantees `valid` writable values at `p`.
        unsafe {
            Avx2Wide::store_f32(p, v.0, valid.min(8));
            if valid > 8 {
                Avx2Wide::store_f32(p.add(8), v.1, valid - 8);
            }
        }
    }
}
