//! Box means of a per-pixel size from a summed-area table: the synthetic defocus blur of a foveated frame's
//! periphery (the SDK's `foveation::periphery`; the paper's Discussion, "a 2D hologram with synthetic blur").
//!
//! A pixel `x` of an output row wants the mean of its image over a square of continuous half-width `h ≥ 0`:
//! the mean of the squares of half-widths `k = ⌊h⌋` and `k + 1` (sides `2k + 1`, `2k + 3`) weighted by
//! `t = h − k`, so that the blur grows continuously with `h`. With `S` the summed-area table (`S[r][c]` the
//! sum of the image over the rows before `r` and the columns before `c`, f64), the square of half-width `j`
//! around row `y`, column `x` sums to `S[y+j+1][x+j+1] − S[y−j][x+j+1] − S[y+j+1][x−j] + S[y−j][x−j]`.
//!
//! One pixel at a time that is eight reads scattered over four rows of the table (a gather). Here the mean is
//! written as the sum over the sizes `j` of the hat weight `max(0, 1 − |h − j|)` times the square's mean
//! (the weights are `1 − t` at `j = k`, `t` at `k + 1`, 0 elsewhere): for one size `j` and a run of
//! pixels, the four corners are four *contiguous* runs of the table, so the loop over a chunk of
//! [`CHUNK`] pixels is plain vector code, and a chunk visits only the sizes its pixels need (a scene's
//! depth, hence `h`, varies slowly along a row: two or three sizes per chunk).
//!
//! The half-width of a pixel comes from its depth, as the defocus of a 2D hologram focused at the gaze's
//! depth: `h = clamp(|d − d_g|·scale − 1/2, 0, max_half)` ([`Defocus`]).
//!
//! One portable body (`body.rs`) in plain safe Rust, compiled as it is (SSE2 / NEON: 2 f64 lanes) and inside
//! `#[target_feature]` functions (AVX2: 4 lanes, AVX-512F: 8). Rust neither contracts `a·b + c` into an FMA
//! nor reorders float arithmetic: every path gives the same bits (tested), and the mean is within a few
//! ulps of the direct sum (tested against a naive reference on random images).
//!
//! Speed, one 1080×1920 plane (AMD EPYC Zen 4, one thread; `cargo bench -p tensorholo-kernels --bench
//! conv3x3 -- box_means`): see the crate's README.

pub(crate) mod body;

use crate::dispatch::{self, Path};
use crate::error::KernelError;
use crate::isa::Isa;

/// Pixels per chunk of the body: the sizes a chunk visits are those its pixels need.
pub const CHUNK: usize = 64;

/// One output row's place in a summed-area table.
#[derive(Debug, Clone, Copy)]
pub struct SatRow<'a> {
    /// The table, `stride` values a row: `table[r·stride + c]` is the sum of the image over its rows before
    /// `r` and its columns before `c` (so row 0 and column 0 are zero), f64.
    pub table: &'a [f64],
    /// Values per table row: the image's width + 1.
    pub stride: usize,
    /// The output row `y` as a table row: the table's row `y` sums the image rows before `y`.
    pub row: usize,
    /// The image column of the first output pixel.
    pub x0: usize,
}

/// The half-width of each pixel's square from its depth: `h = clamp(|d − gaze_depth|·scale − 1/2, 0,
/// max_half)`, the square of a disc's area (`r·√π` wide) for a blur radius `r` proportional to `|d − d_g|`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Defocus {
    /// The depth in focus (normalised, the depth planes' unit).
    pub gaze_depth: f32,
    /// Half-width per unit of depth difference, pixels (`√π/2` times the blur radius per unit).
    pub scale: f64,
    /// The largest half-width; a pixel reads squares up to `⌊max_half⌋ + 1`.
    pub max_half: f64,
}

/// One level's copy of the body.
pub(crate) type MeansFn = unsafe fn(SatRow<'_>, &[f32], Defocus, &mut [f32]);

/// The box means' paths, best first: the portable body's `#[target_feature]` copies, then the body itself.
pub(crate) static PATHS: &[Path<MeansFn>] = &[
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx512,
        run: body::x86::means_avx512,
    },
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx2Fma,
        run: body::x86::means_avx2,
    },
    Path {
        isa: Isa::Scalar,
        run: body::means_body,
    },
];

/// `out[i]` ← the blurred image at row `sat.row`, column `sat.x0 + i`: the mean of the squares of half-widths
/// `⌊h⌋` and `⌊h⌋ + 1` around it weighted by the fraction of `h` (module docs), `h` from `depth[i]` by
/// `defocus`. `depth` and `out` hold one value per pixel (any number, e.g. a run of one image row).
///
/// Every square read must lie inside the image the table sums (the caller clips elsewhere): with
/// `K = ⌊max_half⌋ + 1`, `row ≥ K`, `x0 ≥ K`, `x0 + n + K < stride` and `(row + K + 2)·stride` within the
/// table. Errors: those bounds ([`KernelError::Shape`]), `out`'s length ([`KernelError::Length`]), a
/// `max_half` or `scale` that is negative or not finite ([`KernelError::Parameter`]), `isa` not available
/// ([`KernelError::Isa`]).
pub fn box_means(
    sat: SatRow<'_>,
    depth: &[f32],
    defocus: Defocus,
    out: &mut [f32],
    isa: Isa,
) -> Result<(), KernelError> {
    crate::pack::check_len("box means", out.len(), depth.len())?;
    let usable = |v: f64| v.is_finite() && v >= 0.0;
    if !(usable(defocus.max_half) && usable(defocus.scale)) {
        return Err(KernelError::Parameter {
            what: format!(
                "box means: scale {} and max_half {} must be finite and ≥ 0",
                defocus.scale, defocus.max_half
            ),
        });
    }
    let n = depth.len();
    if n > 0 {
        // `max_half` is below the table's size here (else a bound below fails first).
        let k = (defocus.max_half.min(1e9) as usize) + 1;
        let rows_fit = sat.row >= k
            && (sat.row + k + 2)
                .checked_mul(sat.stride)
                .is_some_and(|end| end <= sat.table.len());
        let columns_fit = sat.x0 >= k && sat.x0 + n + k < sat.stride;
        if !(rows_fit && columns_fit) {
            return Err(KernelError::Shape {
                what: format!(
                    "box means: squares of half-width up to {k} around row {} and columns {}..{} do not fit \
                     a table of {} values, {} a row",
                    sat.row,
                    sat.x0,
                    sat.x0 + n,
                    sat.table.len(),
                    sat.stride
                ),
            });
        }
    }
    let run = dispatch::pick(PATHS, isa)?;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned; the
    // body indexes with checks (the bounds above make them pass).
    unsafe { run(sat, depth, defocus, out) };
    Ok(())
}

#[cfg(test)]
mod tests;
