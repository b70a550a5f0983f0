//! Weight packing at plan time.
//!
//! Kernels keep a tile of `G` output channels in registers and, at each of the `9·C_in` reduction steps,
//! broadcast one weight per output channel. The packed order is therefore `[oc-group][ic][ky][kx][G]`: the
//! `G` weights of one step are adjacent, and a group's steps follow each other in the order the kernel reads
//! them. `C_out` is padded up to a multiple of `G` with zero weights and zero bias; the kernels compute those
//! channels and do not store them.

use crate::buffer::planar::MAX_DIM;
use crate::error::KernelError;

pub(crate) fn check_channels(c_in: usize, c_out: usize) -> Result<(), KernelError> {
    for (what, value) in [("C_in", c_in), ("C_out", c_out)] {
        if value == 0 || value > MAX_DIM {
            return Err(KernelError::Dimension { what, value });
        }
    }
    Ok(())
}

pub(crate) fn check_len(
    what: &'static str,
    got: usize,
    expected: usize,
) -> Result<(), KernelError> {
    if got != expected {
        return Err(KernelError::Length {
            what,
            expected,
            got,
        });
    }
    Ok(())
}

/// Checks an f32 layer's channel counts and that `weights` is `[C_out][C_in][3][3]` and `bias` `[C_out]`.
fn check_layer(
    weights: &[f32],
    bias: &[f32],
    c_in: usize,
    c_out: usize,
) -> Result<(), KernelError> {
    check_channels(c_in, c_out)?;
    check_len(
        "weights [C_out][C_in][3][3]",
        weights.len(),
        c_out * c_in * 9,
    )?;
    check_len("bias [C_out]", bias.len(), c_out)?;
    Ok(())
}

/// Packs OIHW `[C_out][C_in][3][3]` weights and `[C_out]` bias for a kernel with an output-channel tile `g`:
/// returns weights `[ceil(C_out/g)][C_in][3][3][g]` and bias `[ceil(C_out/g)·g]`, zero-padded.
pub(crate) fn pack_f32(
    weights: &[f32],
    bias: &[f32],
    c_in: usize,
    c_out: usize,
    g: usize,
) -> Result<(Vec<f32>, Vec<f32>), KernelError> {
    check_layer(weights, bias, c_in, c_out)?;
    let groups = c_out.div_ceil(g);
    let mut packed = vec![0.0; groups * c_in * 9 * g];
    for o in 0..c_out {
        let (grp, lane) = (o / g, o % g);
        for i in 0..c_in {
            for t in 0..9 {
                packed[((grp * c_in + i) * 9 + t) * g + lane] = weights[(o * c_in + i) * 9 + t];
            }
        }
    }
    let mut b = vec![0.0; groups * g];
    b[..c_out].copy_from_slice(bias);
    Ok((packed, b))
}

/// Packs OIHW `[C_out][C_in][3][3]` weights and `[C_out]` bias for a Winograd F(2×2, 3×3) kernel with an
/// output-channel tile `g`: each filter `g₃ₓ₃` becomes `U = G g Gᵀ` (4×4; `G` as in `wino2x2.rs`,
/// computed in f64 and rounded once), packed `[16][ceil(C_out/g)][C_in][g]` (position `k = 4i + j` of `U`
/// outermost: one product's weights are adjacent); bias `[ceil(C_out/g)·g]`, zero-padded.
pub(crate) fn pack_winograd_f32(
    weights: &[f32],
    bias: &[f32],
    c_in: usize,
    c_out: usize,
    g: usize,
) -> Result<(Vec<f32>, Vec<f32>), KernelError> {
    const GM: [[f64; 3]; 4] = [
        [1.0, 0.0, 0.0],
        [0.5, 0.5, 0.5],
        [0.5, -0.5, 0.5],
        [0.0, 0.0, 1.0],
    ];
    pack_winograd(weights, bias, c_in, c_out, g, &GM)
}

/// Packs OIHW `[C_out][C_in][3][3]` weights and `[C_out]` bias for a Winograd F(4×4, 3×3) kernel with an
/// output-channel tile `g`: each filter becomes `U = G g Gᵀ` (6×6; `G` as in `wino4x4.rs`, computed in
/// f64 and rounded once), packed `[36][ceil(C_out/g)][C_in][g]`; bias `[ceil(C_out/g)·g]`, zero-padded.
pub(crate) fn pack_winograd4_f32(
    weights: &[f32],
    bias: &[f32],
    c_in: usize,
    c_out: usize,
    g: usize,
) -> Result<(Vec<f32>, Vec<f32>), KernelError> {
    const GM: [[f64; 3]; 6] = [
        [1.0 / 4.0, 0.0, 0.0],
        [-1.0 / 6.0, -1.0 / 6.0, -1.0 / 6.0],
        [-1.0 / 6.0, 1.0 / 6.0, -1.0 / 6.0],
        [1.0 / 24.0, 1.0 / 12.0, 1.0 / 6.0],
        [1.0 / 24.0, -1.0 / 12.0, 1.0 / 6.0],
        [0.0, 0.0, 1.0],
    ];
    pack_winograd(weights, bias, c_in, c_out, g, &GM)
}

/// `U = G g Gᵀ` of every filter for the `n × 3` matrix `gm` (`n²` points), packed `[n²][groups][C_in][g]`.
fn pack_winograd(
    weights: &[f32],
    bias: &[f32],
    c_in: usize,
    c_out: usize,
    g: usize,
    gm: &[[f64; 3]],
) -> Result<(Vec<f32>, Vec<f32>), KernelError> {
    check_layer(weights, bias, c_in, c_out)?;
    let n = gm.len();
    let groups = c_out.div_ceil(g);
    let mut packed = vec![0.0; n * n * groups * c_in * g];
    for o in 0..c_out {
        let (grp, lane) = (o / g, o % g);
        for i in 0..c_in {
            let f = &weights[(o * c_in + i) * 9..][..9];
            for k in 0..n * n {
                let (u, v) = (k / n, k % n);
                let mut s = 0.0f64;
                for a in 0..3 {
                    for b in 0..3 {
                        s += gm[u][a] * f[a * 3 + b] as f64 * gm[v][b];
                    }
                }
                packed[((k * groups + grp) * c_in + i) * g + lane] = s as f32;
            }
        }
    }
    let mut b = vec![0.0; groups * g];
    b[..c_out].copy_from_slice(bias);
    Ok((packed, b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_order_and_padding() {
        let (c_in, c_out, g) = (2, 3, 2);
        let w: Vec<f32> = (0..c_out * c_in * 9).map(|i| i as f32 + 1.0).collect();
        let (p, b) = pack_f32(&w, &[1.0, 2.0, 3.0], c_in, c_out, g).unwrap();
        assert_eq!(p.len(), 2 * c_in * 9 * g);
        // group 0, ic 1, tap 4, lane 1 = o 1.
        assert_eq!(p[(9 + 4) * g + 1], w[(c_in + 1) * 9 + 4]);
        // group 1 lane 1 = o 3: padding.
        assert_eq!(p[(c_in * 9 + 5) * g + 1], 0.0);
        assert_eq!(b, vec![1.0, 2.0, 3.0, 0.0]);
        assert!(pack_f32(&w[1..], &[0.0; 3], c_in, c_out, g).is_err());
        assert!(pack_f32(&w, &[0.0; 2], c_in, c_out, g).is_err());
    }
}
