//! The heads' and the output grid's paths (the method: [`crate::heads`]): one portable body each, compiled as
//! it is and inside `#[target_feature]` functions. The heads' [`PATHS`](super::PATHS) list
//! which serves each ISA level.

use crate::quant::{quantize_f32, QuantU8, ROUND_MAGIC};

/// `exp(t)` for `t ∈ [−87, 88]` (the caller clamps), ≈ 1 ulp.
#[inline(always)]
pub(crate) fn exp_reduced(t: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 = C1 + C2, C1 exact in 9 bits so that n·C1 is exact for |n| ≤ 2⁷.
    const C1: f32 = 0.693_359_4;
    const C2: f32 = -2.121_944_4e-4;
    let j = t * LOG2E + ROUND_MAGIC;
    let n = j - ROUND_MAGIC;
    // The integer n sits in the low mantissa bits of j (offset by the magic's own bits).
    let ni = (j.to_bits() as i32).wrapping_sub(ROUND_MAGIC.to_bits() as i32);
    let r = (t - n * C1) - n * C2;
    let mut p = 1.987_569_1e-4f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 0.166_666_65;
    p = p * r + 0.5;
    let e = p * (r * r) + r + 1.0;
    // 2ⁿ for n ∈ [−126, 127] from its exponent bits.
    let two_n = f32::from_bits((ni.wrapping_add(127) as u32) << 23);
    e * two_n
}

/// `(tanh(v) + 1)·scale` as `2·scale / (1 + exp(−2v))`; NaN stays NaN.
#[inline(always)]
fn head(v: f32, two_scale: f32) -> f32 {
    let t = -2.0 * v;
    // `clamp`, not `min`/`max`: a NaN passes through to the result.
    let t = t.clamp(-87.0, 88.0);
    two_scale / (1.0 + exp_reduced(t))
}

/// ONNX `QuantizeLinear` then `DequantizeLinear`: `(clamp(round_ties_even(v / s) + zp, 0, 255) − zp)·s`.
#[inline(always)]
fn grid_round(v: f32, scale: f32, zp: f32) -> f32 {
    (quantize_f32(v / scale, zp) - zp) * scale
}

#[inline(always)]
pub(crate) fn heads_body(raw: &[f32], out: &mut [f32], scale: f32, grid: Option<QuantU8>) {
    let two = 2.0 * scale;
    match grid {
        None => out
            .iter_mut()
            .zip(raw)
            .for_each(|(o, &v)| *o = head(v, two)),
        Some(g) => {
            let (s, zp) = (g.scale, g.zero_point as f32);
            out.iter_mut()
                .zip(raw)
                .for_each(|(o, &v)| *o = head(grid_round(v, s, zp), two))
        }
    }
}

#[inline(always)]
pub(crate) fn grid_body(values: &mut [f32], grid: QuantU8) {
    let (s, zp) = (grid.scale, grid.zero_point as f32);
    values.iter_mut().for_each(|v| *v = grid_round(*v, s, zp));
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod x86 {
    use super::{grid_body, heads_body};
    use crate::quant::QuantU8;

    /// # Safety
    /// The CPU has AVX2.
    #[target_feature(enable = "avx2")]
    pub(crate) unsafe fn heads_avx2(raw: &[f32], out: &mut [f32], s: f32, g: Option<QuantU8>) {
        heads_body(raw, out, s, g)
    }
    /// # Safety
    /// The CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn heads_avx512(raw: &[f32], out: &mut [f32], s: f32, g: Option<QuantU8>) {
        heads_body(raw, out, s, g)
    }
    /// # Safety
    /// The CPU has AVX2.
    #[target_feature(enable = "avx2")]
    pub(crate) unsafe fn grid_avx2(values: &mut [f32], g: QuantU8) {
        grid_body(values, g)
    }
    /// # Safety
    /// The CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn grid_avx512(values: &mut [f32], g: QuantU8) {
        grid_body(values, g)
    }
}
