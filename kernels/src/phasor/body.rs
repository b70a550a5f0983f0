//! The phasor rows' portable body (the method and the error bound: [`crate::phasor`]): plain safe Rust on
//! chunks of [`LANES`] pixels in fixed-size arrays, branch-free (selects and sign-bit flips only), compiled as
//! it is (SSE2 on x86-64, NEON on aarch64) and inside `#[target_feature]` functions (AVX2, AVX-512F). Rust
//! never contracts `a·b + c` into an FMA and never reorders float arithmetic, so every copy computes
//! bit-identical values (tested).

use std::f32::consts::TAU;

use crate::quant::ROUND_MAGIC;

/// Pixels per chunk: one AVX-512 register of f32, two AVX2, four SSE2 / NEON.
pub(crate) const LANES: usize = 16;

/// Above this magnitude every f32 is an integer (a whole number of turns).
const WHOLE_TURNS: f32 = 8_388_608.0; // 2²³

/// `1.5·2²⁴`: `(t + EVEN_MAGIC) − EVEN_MAGIC` is `t` rounded to an even integer for `|t| < 2²³` (the sum lies
/// in `(2²⁴, 2²⁵)`, where f32 holds the even integers only). `ROUND_MAGIC` (`1.5·2²³`) would not round a
/// negative `t` below `−2²²`.
const EVEN_MAGIC: f32 = 25_165_824.0;

/// The Cephes `sinf` polynomial on `|x| ≤ π/4`, highest power first: `sin x ≈ x + x·z·((S0·z + S1)·z + S2)`,
/// `z = x²`.
const SIN_P: [f32; 3] = [-1.951_529_6e-4, 8.332_161e-3, -1.666_665_5e-1];

/// The Cephes `cosf` polynomial on `|x| ≤ π/4`, highest power first: `cos x ≈ 1 − z/2 + z²·((C0·z + C1)·z +
/// C2)`, `z = x²`.
const COS_P: [f32; 3] = [2.443_315_7e-5, -1.388_731_6e-3, 4.166_664_6e-2];

/// `(sin 2πt, cos 2πt)` for any f32 `t` (turns); NaN in, NaN out.
///
/// Method: the whole turns go exactly (`f = t − n ∈ [−1, 1]`, `n` the nearest even integer, by the
/// `1.5·2²⁴` rounding trick; `f = 0` where `|t| ≥ 2²³`, a whole number), then the quarter turns
/// (`q = round(4f)`, `r = f − q/4 ∈ [−1/8, 1/8]`, exact by
/// Sterbenz's lemma), so the only rounding before the polynomials is `x = r·2π ∈ [−π/4, π/4]`. The Cephes
/// polynomials give `sin x` and `cos x`; the quadrant `q mod 4` swaps them and flips signs.
#[inline(always)]
pub fn sincos_turns(t: f32) -> (f32, f32) {
    let n = (t + EVEN_MAGIC) - EVEN_MAGIC;
    // `f ∈ [−1, 1]`, exact (a multiple of t's ulp, no larger than 1). A NaN fails the test and stays NaN.
    let f = if t.abs() >= WHOLE_TURNS { 0.0 } else { t - n };
    let j = 4.0 * f + ROUND_MAGIC;
    let qf = j - ROUND_MAGIC;
    // The integer q sits in the low mantissa bits of j (offset by the magic's own bits).
    let q = (j.to_bits() as i32).wrapping_sub(ROUND_MAGIC.to_bits() as i32) as u32;
    let r = f - 0.25 * qf;
    let x = r * TAU;
    let z = x * x;
    let sin = ((SIN_P[0] * z + SIN_P[1]) * z + SIN_P[2]) * z * x + x;
    let cos = ((COS_P[0] * z + COS_P[1]) * z + COS_P[2]) * (z * z) - 0.5 * z + 1.0;
    // Quadrant q mod 4: 0 (sin, cos), 1 (cos, −sin), 2 (−sin, −cos), 3 (−cos, sin).
    let swap = q & 1 != 0;
    let (s, c) = if swap { (cos, sin) } else { (sin, cos) };
    let s = f32::from_bits(s.to_bits() ^ ((q & 2) << 30));
    let c = f32::from_bits(c.to_bits() ^ ((q.wrapping_add(1) & 2) << 30));
    (s, c)
}

/// One pixel of the hologram CNN's heads as a phasor: amplitude `a`, phase head `p` (turns, `[0, 1]` by the
/// model contract) → `(a·cos θ, a·sin θ)` with `θ = 2π·(p − 0.5)`.
#[inline(always)]
pub fn phasor(a: f32, p: f32) -> (f32, f32) {
    let (s, c) = sincos_turns(p - 0.5);
    (a * c, a * s)
}

/// One chunk: interleaved phasors of `a` and `p` into `out`; returns whether every input was finite.
#[inline(always)]
fn chunk(a: &[f32; LANES], p: &[f32; LANES], out: &mut [f32; 2 * LANES]) -> bool {
    let mut re = [0.0f32; LANES];
    let mut im = [0.0f32; LANES];
    let mut bad = 0u32;
    for k in 0..LANES {
        (re[k], im[k]) = phasor(a[k], p[k]);
        bad |= u32::from(!a[k].is_finite()) | u32::from(!p[k].is_finite());
    }
    for k in 0..LANES {
        out[2 * k] = re[k];
        out[2 * k + 1] = im[k];
    }
    bad == 0
}

/// The last, partial chunk of `n` pixels starting at pixel `start`: the inputs padded with zeros.
#[inline(always)]
fn tail(a: &[f32], p: &[f32], out: &mut [f32]) -> bool {
    let (mut ca, mut cp) = ([0.0f32; LANES], [0.0f32; LANES]);
    ca[..a.len()].copy_from_slice(a);
    cp[..p.len()].copy_from_slice(p);
    let mut co = [0.0f32; 2 * LANES];
    let finite = chunk(&ca, &cp, &mut co);
    out.copy_from_slice(&co[..out.len()]);
    finite
}

/// `out` (`2n`, interleaved) ← the phasors of `amplitude` and `phase` (`n` each; lengths checked by the
/// caller). Returns whether every input was finite.
#[inline(always)]
pub(crate) fn polar_body(amplitude: &[f32], phase: &[f32], out: &mut [f32]) -> bool {
    let full = phase.len() / LANES * LANES;
    let mut finite = true;
    for ((a, p), o) in amplitude[..full]
        .chunks_exact(LANES)
        .zip(phase[..full].chunks_exact(LANES))
        .zip(out[..2 * full].chunks_exact_mut(2 * LANES))
    {
        let (a, p) = (a.try_into().unwrap(), p.try_into().unwrap());
        finite &= chunk(a, p, o.try_into().unwrap());
    }
    if full < phase.len() {
        finite &= tail(&amplitude[full..], &phase[full..], &mut out[2 * full..]);
    }
    finite
}

/// [`polar_body`] in place: `buf` (`2n`) holds the amplitudes in its first `n` values and receives the
/// interleaved phasors. Chunks run from the last to the first: chunk `c` writes values `[2cL, 2cL + 2L)`,
/// which only hold amplitudes of chunks `≥ c` (already read; chunk `c` reads its own before it writes).
#[inline(always)]
pub(crate) fn polar_in_place_body(buf: &mut [f32], phase: &[f32]) -> bool {
    let n = phase.len();
    let full = n / LANES * LANES;
    let mut finite = true;
    if full < n {
        let mut a = [0.0f32; LANES];
        a[..n - full].copy_from_slice(&buf[full..n]);
        finite &= tail(&a[..n - full], &phase[full..], &mut buf[2 * full..2 * n]);
    }
    for start in (0..full).step_by(LANES).rev() {
        let a: [f32; LANES] = buf[start..start + LANES].try_into().unwrap();
        let p = phase[start..start + LANES].try_into().unwrap();
        finite &= chunk(
            &a,
            p,
            (&mut buf[2 * start..2 * start + 2 * LANES])
                .try_into()
                .unwrap(),
        );
    }
    finite
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod x86 {
    use super::{polar_body, polar_in_place_body};

    /// # Safety
    /// The CPU has AVX2.
    #[target_feature(enable = "avx2")]
    pub(crate) unsafe fn polar_avx2(a: &[f32], p: &[f32], out: &mut [f32]) -> bool {
        polar_body(a, p, out)
    }
    /// # Safety
    /// The CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn polar_avx512(a: &[f32], p: &[f32], out: &mut [f32]) -> bool {
        polar_body(a, p, out)
    }
    /// # Safety
    /// The CPU has AVX2.
    #[target_feature(enable = "avx2")]
    pub(crate) unsafe fn polar_in_place_avx2(buf: &mut [f32], p: &[f32]) -> bool {
        polar_in_place_body(buf, p)
    }
    /// # Safety
    /// The CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn polar_in_place_avx512(buf: &mut [f32], p: &[f32]) -> bool {
        polar_in_place_body(buf, p)
    }
}
