//! Fixed depthwise `k × k` filter with edge replication (the pre-filter's skip branch).
//!
//! Direct, register-tiled: a tile is `L` consecutive output pixels of one row, whose `L` sums stay in
//! registers through all `k²` taps (the tap's weight broadcast, `L` input values loaded at the tap's offset),
//! and are written once. `L` is four vector registers of the path (AVX-512: 64 pixels, AVX2: 32, portable:
//! 16 on SSE2's 16 registers and 32 on NEON's 32), so four independent sum chains share each broadcast.
//! The middle of a row is read in place, in tiles of `L`, then of 8 pixels; pixels within `r = k/2` of
//! either end, and the few the tiles leave over, are summed one at a time with clamped reads. Rows are
//! clamped by choosing the source row. The filter needs no scratch from the caller, and any band of rows
//! can run on its own thread. (Tried and dropped: the ends as 8-pixel tiles over an edge-replicated copy,
//! 15–30 % slower at 384² than these single pixels.)
//!
//! Every pixel's sum runs in the same order (`ky` outer, `kx` inner, from 0.0) on every path, and Rust
//! never contracts `a·b + c` into an FMA on its own, so every path is bit-identical (tested).

use std::ops::Range;

pub(crate) mod body;

use crate::buffer::planar::check_dims;
use crate::dispatch::{self, Path};
use crate::error::KernelError;
use crate::isa::Isa;
use body::Job;

pub use body::MAX_TAPS;

/// The depthwise filter on output rows `rows` of one checked plane (`accumulate`: add to `out`).
pub(crate) type DepthwiseFn = unsafe fn(&Job<'_>, Range<usize>, &mut [f32], bool);

/// The filter's paths, best first: the portable body's `#[target_feature]` copies, then the body itself
/// (SSE2 / NEON).
pub(crate) static PATHS: &[Path<DepthwiseFn>] = &[
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx512,
        run: body::x86::rows_avx512,
    },
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx2Fma,
        run: body::x86::rows_avx2,
    },
    Path {
        isa: Isa::Scalar,
        run: body::rows::<body::Portable<{ body::PORTABLE_TILE }>>,
    },
];

/// Depthwise `k × k` filter (`k` odd, ≤ [`MAX_TAPS`]) of a planar `[C][H][W]` f32 image, edges replicated
/// (clamp-to-edge): `out[c][y][x] (+)= Σ_{ky,kx} kernel[c][ky][kx] · in[c][clamp(y+ky−r)][clamp(x+kx−r)]`,
/// `r = k/2`.
///
/// `kernel` is `[C][k][k]`. With `accumulate` the result is added to `out` (e.g. to the last layer's output),
/// otherwise `out` is overwritten. Runs [`depthwise_rows`] on every channel's whole plane (the module docs
/// give the method); bit-identical on every path `isa` allows.
/// Errors: `k` even, zero or above [`MAX_TAPS`] ([`KernelError::Parameter`]), a zero dimension, wrong slice
/// lengths ([`KernelError::Length`]), `isa` not available on this CPU ([`KernelError::Isa`]).
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
    isa: Isa,
) -> Result<(), KernelError> {
    check_dims(c, h, w)?;
    check_taps(k)?;
    let n = c * h * w;
    crate::pack::check_len("depthwise input [C][H][W]", input.len(), n)?;
    crate::pack::check_len("depthwise output [C][H][W]", out.len(), n)?;
    crate::pack::check_len("depthwise kernel [C][k][k]", kernel.len(), c * k * k)?;
    for ((plane, taps), o) in input
        .chunks_exact(h * w)
        .zip(kernel.chunks_exact(k * k))
        .zip(out.chunks_exact_mut(h * w))
    {
        depthwise_rows(plane, h, w, taps, k, 0..h, o, accumulate, isa)?;
    }
    Ok(())
}

/// Rows `rows` of [`depthwise`] on one channel: `plane` is the whole input plane `[H][W]`, `taps` its
/// `[k][k]` kernel, and `out` holds exactly the output rows `rows` (`rows.len()·W` values), so that bands of
/// rows can run on different threads. Bit-identical to the same rows of a whole-plane call.
/// Errors: as [`depthwise`]; rows outside `0..H` ([`KernelError::Length`]).
#[allow(clippy::too_many_arguments)]
pub fn depthwise_rows(
    plane: &[f32],
    h: usize,
    w: usize,
    taps: &[f32],
    k: usize,
    rows: Range<usize>,
    out: &mut [f32],
    accumulate: bool,
    isa: Isa,
) -> Result<(), KernelError> {
    check_dims(1, h, w)?;
    check_taps(k)?;
    crate::pack::check_len("depthwise input plane [H][W]", plane.len(), h * w)?;
    crate::pack::check_len("depthwise kernel [k][k]", taps.len(), k * k)?;
    if rows.end > h {
        return Err(KernelError::Length {
            what: "depthwise output rows (end past H)",
            expected: h,
            got: rows.end,
        });
    }
    if rows.start > rows.end {
        return Err(KernelError::Parameter {
            what: format!("depthwise output rows {rows:?} start after they end"),
        });
    }
    crate::pack::check_len("depthwise output rows [rows][W]", out.len(), rows.len() * w)?;
    let job = Job {
        plane,
        h,
        w,
        taps,
        k,
    };
    let run = dispatch::pick(PATHS, isa)?;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the plane, the kernel and the rows are checked above.
    unsafe { run(&job, rows, out, accumulate) };
    Ok(())
}

/// Errors: `k` even (0 included) or above [`MAX_TAPS`] ([`KernelError::Parameter`]).
fn check_taps(k: usize) -> Result<(), KernelError> {
    if k.is_multiple_of(2) || k > MAX_TAPS {
        return Err(KernelError::Parameter {
            what: format!("depthwise kernel size {k} must be odd and ≤ {MAX_TAPS}"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::Rng;

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
            depthwise(&input, c, h, w, &kernel, k, &mut out, false, Isa::Scalar).unwrap();
            let base = rng.vec(c * h * w);
            let mut acc = base.clone();
            depthwise(&input, c, h, w, &kernel, k, &mut acc, true, Isa::Scalar).unwrap();
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
        depthwise(&input, 2, 4, 6, &kernel, 5, &mut out, false, Isa::Scalar).unwrap();
        assert!(out.iter().all(|&v| (v - 2.0).abs() < 1e-5));
    }

    /// The same sum in f32, pixel by pixel in the documented order (`ky` outer, `kx` inner, from 0.0).
    fn same_order_f32(plane: &[f32], h: usize, w: usize, taps: &[f32], k: usize) -> Vec<f32> {
        let r = k / 2;
        let mut out = vec![0.0f32; h * w];
        for y in 0..h {
            for x in 0..w {
                let mut a = 0.0f32;
                for ky in 0..k {
                    for kx in 0..k {
                        let sy = (y + ky).saturating_sub(r).min(h - 1);
                        let sx = (x + kx).saturating_sub(r).min(w - 1);
                        a += taps[ky * k + kx] * plane[sy * w + sx];
                    }
                }
                out[y * w + x] = a;
            }
        }
        out
    }

    #[test]
    fn every_path_and_band_is_bit_identical_to_the_pixel_loop() {
        let mut rng = Rng::new(11);
        // Widths under one tile, at the tile edges (16, 32, 64 pixels plus 2r), odd and wide.
        let widths = [
            1, 2, 3, 4, 5, 7, 9, 13, 20, 21, 35, 36, 68, 69, 77, 131, 389,
        ];
        for &k in &[1usize, 3, 5, 7] {
            for &w in &widths {
                let h = 1 + (w % 5);
                let plane = rng.vec(h * w);
                let taps = rng.vec(k * k);
                let want = same_order_f32(&plane, h, w, &taps, k);
                let base = rng.vec(h * w);
                for (name, isa) in crate::dispatch::available_paths("depthwise", PATHS) {
                    let mut out = vec![f32::NAN; h * w];
                    depthwise(&plane, 1, h, w, &taps, k, &mut out, false, isa).unwrap();
                    for (i, (a, b)) in out.iter().zip(&want).enumerate() {
                        assert_eq!(a.to_bits(), b.to_bits(), "{name} k {k} w {w} h {h} at {i}");
                    }
                    // Bands of one row each, accumulated onto a base.
                    let mut acc = base.clone();
                    for (y, band) in acc.chunks_exact_mut(w).enumerate() {
                        depthwise_rows(&plane, h, w, &taps, k, y..y + 1, band, true, isa).unwrap();
                    }
                    for i in 0..h * w {
                        assert_eq!(
                            acc[i].to_bits(),
                            (base[i] + want[i]).to_bits(),
                            "{name} band"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn rows_outside_the_plane_are_refused() {
        let plane = [0.0f32; 12];
        let taps = [0.0f32; 9];
        let mut out = vec![0.0f32; 8];
        let rows = |r: std::ops::Range<usize>, out: &mut [f32]| {
            depthwise_rows(&plane, 3, 4, &taps, 3, r, out, false, Isa::Scalar).is_err()
        };
        assert!(rows(2..4, &mut out), "past H");
        assert!(rows(0..2, &mut out[..7]), "short output");
        assert!(!rows(1..3, &mut out), "a good call");
        let reversed = std::ops::Range { start: 2, end: 1 };
        assert!(rows(reversed, &mut out[..0]), "start after end");
        assert!(
            depthwise_rows(
                &plane,
                3,
                4,
                &[0.0; 65 * 65],
                65,
                0..1,
                &mut out[..4],
                false,
                Isa::Scalar
            )
            .is_err(),
            "k above MAX_TAPS"
        );
    }

    #[test]
    fn bad_input_is_an_error() {
        let mut out = vec![0.0; 12];
        // A 1×3×4 image: (input, kernel, k, output) with one thing wrong each.
        let refused = |input: &[f32], kernel: &[f32], k: usize, out: &mut [f32]| {
            depthwise(input, 1, 3, 4, kernel, k, out, false, Isa::Scalar).is_err()
        };
        assert!(refused(&[0.0; 12], &[0.0; 16], 4, &mut out), "even k");
        assert!(
            refused(&[0.0; 12], &[], 0, &mut out),
            "k = 0 (before any chunking)"
        );
        assert!(refused(&[0.0; 11], &[0.0; 9], 3, &mut out), "short input");
        assert!(refused(&[0.0; 12], &[0.0; 8], 3, &mut out), "short kernel");
        assert!(
            refused(&[0.0; 12], &[0.0; 9], 3, &mut out.clone()[1..]),
            "short output"
        );
        assert!(!refused(&[0.0; 12], &[0.0; 9], 3, &mut out), "a good call");
    }
}
