//! Fixed depthwise `k × k` filter with edge replication (the pre-filter's skip branch).

use crate::buffer::check_dims;
use crate::KernelError;

/// Depthwise `k × k` filter (`k` odd) of a planar `[C][H][W]` f32 image, edges replicated (clamp-to-edge):
/// `out[c][y][x] (+)= Σ_{ky,kx} kernel[c][ky][kx] · in[c][clamp(y+ky−r)][clamp(x+kx−r)]`, `r = k/2`.
///
/// `kernel` is `[C][k][k]`. With `accumulate` the result is added to `out` (e.g. to the last layer's output),
/// otherwise `out` is overwritten. `scratch` holds two rows (`2·w + k − 1` values); it grows on the first call
/// and is reused after, so a caller that keeps it allocates nothing per frame. Portable code written so that
/// the inner loop over `x` auto-vectorises.
/// Errors: `k` even or zero ([`KernelError::Parameter`]), a zero dimension, wrong slice lengths
/// ([`KernelError::Length`]).
#[allow(clippy::too_many_arguments)]
pub fn depthwise(
    input: &[f32],
    c: usize,
    h: usize,
    w: usize,
    kernel: &[f32],
    k: usize,
    out: &mut [f32],
    accumulate: bool,
    scratch: &mut Vec<f32>,
) -> Result<(), KernelError> {
    check_dims(c, h, w)?;
    if k.is_multiple_of(2) || k > 63 {
        return Err(KernelError::Parameter {
            what: format!("depthwise kernel size {k} must be odd and ≤ 63"),
        });
    }
    let n = c * h * w;
    crate::pack::check_len("depthwise input [C][H][W]", input.len(), n)?;
    crate::pack::check_len("depthwise output [C][H][W]", out.len(), n)?;
    crate::pack::check_len("depthwise kernel [C][k][k]", kernel.len(), c * k * k)?;
    let r = k / 2;
    // One edge-replicated row: `r` copies of the first pixel, the row, `r` copies of the last.
    scratch.resize(2 * w + 2 * r, 0.0);
    let (padded, acc) = scratch.split_at_mut(w + 2 * r);
    for ch in 0..c {
        let plane = &input[ch * h * w..(ch + 1) * h * w];
        let taps = &kernel[ch * k * k..(ch + 1) * k * k];
        for y in 0..h {
            acc.iter_mut().for_each(|a| *a = 0.0);
            for ky in 0..k {
                let sy = (y + ky).saturating_sub(r).min(h - 1);
                let row = &plane[sy * w..(sy + 1) * w];
                padded[..r].fill(row[0]);
                padded[r..r + w].copy_from_slice(row);
                padded[r + w..].fill(row[w - 1]);
                accumulate_taps(acc, padded, &taps[ky * k..(ky + 1) * k]);
            }
            let o = &mut out[(ch * h + y) * w..(ch * h + y + 1) * w];
            if accumulate {
                o.iter_mut().zip(acc.iter()).for_each(|(o, a)| *o += a);
            } else {
                o.copy_from_slice(acc);
            }
        }
    }
    Ok(())
}

/// `acc[x] += Σ_kx taps[kx] · padded[x + kx]`: one kernel row over one padded image row. A function of its
/// own so that `acc` and `padded` (two parts of one scratch buffer) are known not to alias and the loop over
/// `x` vectorises without run-time checks.
fn accumulate_taps(acc: &mut [f32], padded: &[f32], taps: &[f32]) {
    let w = acc.len();
    for (kx, &t) in taps.iter().enumerate() {
        for (a, &p) in acc.iter_mut().zip(&padded[kx..kx + w]) {
            *a += t * p;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conv3x3::tests::Rng;

    fn reference(
        input: &[f32],
        c: usize,
        h: usize,
        w: usize,
        kernel: &[f32],
        k: usize,
    ) -> Vec<f64> {
        let r = k as isize / 2;
        let mut out = vec![0.0; c * h * w];
        for ch in 0..c {
            for y in 0..h as isize {
                for x in 0..w as isize {
                    let mut s = 0.0f64;
                    for ky in 0..k as isize {
                        for kx in 0..k as isize {
                            let sy = (y + ky - r).clamp(0, h as isize - 1) as usize;
                            let sx = (x + kx - r).clamp(0, w as isize - 1) as usize;
                            s += kernel[ch * k * k + (ky * k as isize + kx) as usize] as f64
                                * input[(ch * h + sy) * w + sx] as f64;
                        }
                    }
                    out[(ch * h + y as usize) * w + x as usize] = s;
                }
            }
        }
        out
    }

    #[test]
    fn matches_reference_with_edge_replication() {
        let mut rng = Rng::new(3);
        for &(c, h, w, k) in &[
            (6, 1, 1, 5),
            (6, 7, 9, 5),
            (3, 2, 13, 3),
            (2, 5, 4, 7),
            (1, 3, 3, 1),
        ] {
            let input = rng.vec(c * h * w);
            let kernel = rng.vec(c * k * k);
            let want = reference(&input, c, h, w, &kernel, k);
            let mut out = vec![f32::NAN; c * h * w];
            depthwise(
                &input,
                c,
                h,
                w,
                &kernel,
                k,
                &mut out,
                false,
                &mut Vec::new(),
            )
            .unwrap();
            let base = rng.vec(c * h * w);
            let mut acc = base.clone();
            depthwise(&input, c, h, w, &kernel, k, &mut acc, true, &mut Vec::new()).unwrap();
            for i in 0..c * h * w {
                assert!(
                    (out[i] as f64 - want[i]).abs() < 1e-5,
                    "{c} {h} {w} {k} at {i}"
                );
                assert!((acc[i] as f64 - base[i] as f64 - want[i]).abs() < 1e-5);
            }
        }
        // A constant image stays constant under a normalised kernel (edges replicated, not zero).
        let input = vec![2.0f32; 2 * 4 * 6];
        let kernel = vec![1.0 / 25.0; 2 * 25];
        let mut out = vec![0.0; 2 * 4 * 6];
        depthwise(
            &input,
            2,
            4,
            6,
            &kernel,
            5,
            &mut out,
            false,
            &mut Vec::new(),
        )
        .unwrap();
        assert!(out.iter().all(|&v| (v - 2.0).abs() < 1e-5));
    }

    #[test]
    fn bad_input_is_an_error() {
        let mut out = vec![0.0; 12];
        // A 1×3×4 image: (input, kernel, k, output) with one thing wrong each.
        let refused = |input: &[f32], kernel: &[f32], k: usize, out: &mut [f32]| {
            depthwise(input, 1, 3, 4, kernel, k, out, false, &mut Vec::new()).is_err()
        };
        assert!(refused(&[0.0; 12], &[0.0; 16], 4, &mut out), "even k");
        assert!(refused(&[0.0; 11], &[0.0; 9], 3, &mut out), "short input");
        assert!(refused(&[0.0; 12], &[0.0; 8], 3, &mut out), "short kernel");
        assert!(
            refused(&[0.0; 12], &[0.0; 9], 3, &mut out.clone()[1..]),
            "short output"
        );
        assert!(!refused(&[0.0; 12], &[0.0; 9], 3, &mut out), "a good call");
    }
}
