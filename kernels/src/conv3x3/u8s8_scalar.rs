//! `conv3x3.u8s8.8x8.scalar`: the portable int8 fallback, safe code. Tile: 8 output channels × 8 pixels of
//! i32 accumulators; each step reads 4 interleaved input channels of one tap. The epilogue is the shared
//! arithmetic of [`simd_u8`](super::simd_u8) written with scalars.

use super::job::{U8Job, U8Out};
use crate::quant::quantize;

/// Output-channel tile.
pub(crate) const G: usize = 8;
/// Pixel tile.
pub(crate) const P: usize = 8;

/// The epilogue value before quantisation: `(acc as f32)·mult + bias`, ReLU, residual.
pub(crate) fn epilogue_value(
    acc: i32,
    mult: f32,
    bias: f32,
    relu: bool,
    res: Option<(u8, f32, f32)>,
) -> f32 {
    let mut v = (acc as f32) * mult + bias;
    if relu {
        v = if v > 0.0 { v } else { 0.0 };
    }
    if let Some((r, zp, scale)) = res {
        v += (r as f32 - zp) * scale;
    }
    v
}

pub(crate) fn conv(job: &U8Job<'_>, out: &mut U8Out<'_>) {
    let (w, wp, cout) = (job.w, job.wp, job.cout);
    let cg = job.ga + job.gb;
    let groups = cout.div_ceil(G);
    let c4 = cout.div_ceil(4);
    for y in job.y0..job.y1 {
        for grp in 0..groups {
            let mut x0 = 0;
            while x0 < w {
                let mut acc = [[0i32; P]; G];
                for (g, a) in acc.iter_mut().enumerate() {
                    *a = [job.init[grp * G + g]; P];
                }
                let mut step = grp * cg * 9;
                for (src, gs) in [(job.a, job.ga), (job.b, job.gb)] {
                    for j in 0..gs {
                        for ky in 0..3 {
                            let row = (((y + ky) * gs + j) * wp + x0) * 4;
                            for kx in 0..3 {
                                let xs = &src[row + kx * 4..row + (kx + P) * 4];
                                let ws = &job.weights[step * G * 4..(step + 1) * G * 4];
                                for (g, a) in acc.iter_mut().enumerate() {
                                    let wg = &ws[g * 4..g * 4 + 4];
                                    for (p, a) in a.iter_mut().enumerate() {
                                        for l in 0..4 {
                                            *a += xs[p * 4 + l] as i32 * wg[l] as i8 as i32;
                                        }
                                    }
                                }
                                step += 1;
                            }
                        }
                    }
                }
                let valid = P.min(w - x0);
                // A copy for the epilogue keeps `acc` at constant indices (registers).
                let tile_acc = acc;
                for (g, a) in tile_acc.iter().enumerate() {
                    let o = grp * G + g;
                    if o >= c4 * 4 {
                        break;
                    }
                    let at = (((y + 1) * c4 + o / 4) * wp + 1 + x0) * 4 + o % 4;
                    for p in 0..P {
                        let i = at + p * 4;
                        if o >= cout || p >= valid {
                            if let U8Out::Rows { data, base } = out {
                                data[i - *base] = job.out_zp_u8;
                            }
                            continue;
                        }
                        let res = job.residual.map(|(r, zp, s)| (r[i], zp, s));
                        let v = epilogue_value(a[p], job.mult[o], job.bias[o], job.relu, res);
                        match out {
                            U8Out::Rows { data, base } => {
                                data[i - *base] = quantize(v * job.out_inv, job.out_zp_u8)
                            }
                            U8Out::F32 {
                                data,
                                c_stride,
                                y_stride,
                                base,
                            } => {
                                data[U8Out::f32_index(*c_stride, *y_stride, *base, o, y, x0 + p)] =
                                    v
                            }
                        }
                    }
                }
                x0 += P;
            }
        }
    }
}

/// The portable int8 peak loop: 16 independent i32 multiply-add chains; ops = `iters · 16 · 2`.
pub(crate) fn peak(iters: u64) -> i32 {
    let mut acc = [1i32; 16];
    let a = std::hint::black_box(3i32);
    let b = std::hint::black_box(-5i32);
    for _ in 0..iters {
        for x in acc.iter_mut() {
            *x = x.wrapping_mul(a).wrapping_add(b);
        }
    }
    acc.iter().fold(0, |s, &x| s.wrapping_add(x))
}
