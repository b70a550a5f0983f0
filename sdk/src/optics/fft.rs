//! Planned 2D FFT on row-major `[height, width]` complex buffers (rustfft), with the spectrum kept in
//! **transposed** layout `[width, height]` so that a spectral operation costs two transposes instead of four,
//! and a cache-blocked filter (`Fft2::filter`) that never writes the whole spectrum: three passes over the
//! field instead of seven.

use std::sync::Arc;

use num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use tensorholo_kernels::{spectral, Isa, KernelError};

/// Columns per block of `Fft2::filter`: 16 complex values of each row (128 bytes, two cache lines), so that
/// a block (`16 × height` values: 138 KB at 1080 rows, 276 KB at 2160) stays in a core's L2 from its
/// gather through its column transforms, the multiplier and back, and every cache line read from the field is
/// used whole.
pub const BLOCK_COLUMNS: usize = 16;

/// A 2D discrete Fourier transform of one size, planned once and applied many times.
///
/// - `Fft2::forward` transforms a row-major `[height, width]` buffer and writes its unnormalised spectrum to
///   a row-major `[width, height]` buffer (the transpose of the usual layout: element `[kx, ky]`).
/// - `Fft2::inverse` takes such a transposed spectrum back to a `[height, width]` buffer, **unnormalised**
///   (the caller folds the `1/(height·width)` factor into its spectral multiplier).
///
/// The caller owns the scratch space (`Fft2::scratch_len` complex values), so the hot path allocates nothing.
#[derive(Clone)]
pub(crate) struct Fft2 {
    height: usize,
    width: usize,
    row_forward: Arc<dyn Fft<f32>>,
    row_inverse: Arc<dyn Fft<f32>>,
    col_forward: Arc<dyn Fft<f32>>,
    col_inverse: Arc<dyn Fft<f32>>,
    scratch_len: usize,
    /// The vector level of the column moves ([`tensorholo_kernels::spectral`]): the process's.
    isa: Isa,
}

impl std::fmt::Debug for Fft2 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fft2")
            .field("height", &self.height)
            .field("width", &self.width)
            .finish()
    }
}

impl Fft2 {
    /// Plans the four 1D transforms of a `[height, width]` 2D FFT. Both sizes must be ≥ 1 (checked by callers).
    pub(crate) fn new(planner: &mut FftPlanner<f32>, height: usize, width: usize) -> Self {
        let row_forward = planner.plan_fft_forward(width);
        let row_inverse = planner.plan_fft_inverse(width);
        let col_forward = planner.plan_fft_forward(height);
        let col_inverse = planner.plan_fft_inverse(height);
        let scratch_len = [
            row_forward.get_inplace_scratch_len(),
            row_inverse.get_inplace_scratch_len(),
            col_forward.get_inplace_scratch_len(),
            col_inverse.get_inplace_scratch_len(),
        ]
        .into_iter()
        .max()
        .unwrap_or(0);
        Self {
            height,
            width,
            row_forward,
            row_inverse,
            col_forward,
            col_inverse,
            scratch_len,
            isa: Isa::detect(),
        }
    }

    /// The vector level of the column pass's moves (this CPU's best, [`Isa::detect`], read once at planning), for the spectral
    /// multiply of the same filter.
    pub(crate) fn isa(&self) -> Isa {
        self.isa
    }

    /// Rows of the spatial buffer.
    pub(crate) fn height(&self) -> usize {
        self.height
    }

    /// Columns of the spatial buffer.
    pub(crate) fn width(&self) -> usize {
        self.width
    }

    /// Number of complex values of the column block [`Fft2::filter`] needs.
    pub(crate) fn block_len(&self) -> usize {
        BLOCK_COLUMNS.min(self.width) * self.height
    }

    /// Number of complex values of scratch that [`Fft2::forward`] and [`Fft2::inverse`] need.
    pub(crate) fn scratch_len(&self) -> usize {
        self.scratch_len
    }

    /// Forward DFT: `data` `[height, width]` (overwritten with intermediate row transforms) → `spectrum`
    /// `[width, height]` (transposed). Both slices must hold `height·width` values.
    pub(crate) fn forward(
        &self,
        data: &mut [Complex32],
        spectrum: &mut [Complex32],
        scratch: &mut [Complex32],
    ) {
        debug_assert_eq!(data.len(), self.height * self.width);
        debug_assert_eq!(spectrum.len(), self.height * self.width);
        let scratch = &mut scratch[..self.scratch_len];
        self.row_forward.process_with_scratch(data, scratch);
        transpose::transpose(data, spectrum, self.width, self.height);
        self.col_forward.process_with_scratch(spectrum, scratch);
    }

    /// Inverse DFT (unnormalised): transposed `spectrum` `[width, height]` (overwritten) → `data`
    /// `[height, width]`.
    pub(crate) fn inverse(
        &self,
        spectrum: &mut [Complex32],
        data: &mut [Complex32],
        scratch: &mut [Complex32],
    ) {
        debug_assert_eq!(data.len(), self.height * self.width);
        debug_assert_eq!(spectrum.len(), self.height * self.width);
        let scratch = &mut scratch[..self.scratch_len];
        self.col_inverse.process_with_scratch(spectrum, scratch);
        transpose::transpose(spectrum, data, self.height, self.width);
        self.row_inverse.process_with_scratch(data, scratch);
    }

    /// `data ← F⁻¹{M · F{data}}` in place (unnormalised, as [`Fft2::inverse`]): `data` is `[height, width]`,
    /// and `multiply(kx, spectrum_row)` applies `M` to row `kx` of the transposed spectrum (`height` values,
    /// `ky` in FFT order), as it would to the spectrum [`Fft2::forward`] writes.
    ///
    /// Cache-blocked: the row transforms of the whole field, then per block of [`BLOCK_COLUMNS`] columns the
    /// gather (a transpose of the block into `block`, [`Fft2::block_len`] values), its column transforms,
    /// `multiply`, the inverse column transforms and the scatter back; then the inverse row transforms. The
    /// field is read and written three times (the forward–multiply–inverse sequence: seven, with a
    /// whole-field spectrum). Bit-identical to that sequence: the same 1D transforms on the same values, and
    /// the transposes only copy (tested).
    ///
    /// `data` must hold `height·width` values and `block` at least [`Fft2::block_len`] (as for the other
    /// methods, the callers' plans size them; a shorter `block` panics).
    pub(crate) fn filter(
        &self,
        data: &mut [Complex32],
        block: &mut [Complex32],
        scratch: &mut [Complex32],
        multiply: impl FnMut(usize, &mut [Complex32]),
    ) {
        self.filter_rows(
            data,
            block,
            scratch,
            |_, _| {},
            multiply,
            None,
            |_, _, _| {},
        );
    }

    /// [`Fft2::filter`] with a pass of the caller's fused into each end, on rows still in cache:
    /// - `before(data, rows)` fills or changes `data`'s rows `rows` just before their forward row transforms.
    ///   It sees the whole buffer and is called on chunks of [`ROW_CHUNK`] rows from the **last** chunk to the
    ///   first, each chunk starting at a multiple of [`ROW_CHUNK`]: rows `≥ rows.end` are already transformed,
    ///   rows `< rows.start` untouched. (So a field can be made in place from values packed in the first half
    ///   of its own memory: chunk `[y0, y1)` with `y0 > 0` writes values `2·y0·width..` and reads at most up to
    ///   `y1·width ≤ 2·y0·width`.)
    /// - `after(chunk, rows, spent)` reads the chunk's rows `rows` (`chunk`: those rows alone, row-major) just
    ///   after their inverse row transforms, again from the **last** chunk to the first.
    ///
    /// With `rows_out` (at least `ROW_CHUNK·width` values) the inverse row transforms run there, on a copy of
    /// each chunk's rows, instead of in `data`: only `after` sees the result, and `data` is left holding the
    /// column pass's values, but it is not written a third time (a field whose result is read once by
    /// `after` then spares 16.6 MB of writes at 1080p). `spent` is then `data` from the chunk's first row to
    /// the end (`data[rows.start·width..]`): rows whose values nothing reads any more (this chunk's were
    /// copied, the later ones are done), which `after` may overwrite, e.g. to keep a plane of the result in
    /// the field's own memory. Without `rows_out`, `spent` is empty.
    ///
    /// Without the hooks' own work it is [`Fft2::filter`], bit for bit (the row transforms are independent).
    /// Each fused pass saves a read and a write of the whole field from memory: at 1080p a field is 16.6 MB,
    /// far more than a core's L2.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn filter_rows(
        &self,
        data: &mut [Complex32],
        block: &mut [Complex32],
        scratch: &mut [Complex32],
        mut before: impl FnMut(&mut [Complex32], std::ops::Range<usize>),
        mut multiply: impl FnMut(usize, &mut [Complex32]),
        mut rows_out: Option<&mut [Complex32]>,
        mut after: impl FnMut(&[Complex32], std::ops::Range<usize>, &mut [Complex32]),
    ) {
        let (h, w) = (self.height, self.width);
        debug_assert_eq!(data.len(), h * w);
        let scratch = &mut scratch[..self.scratch_len];
        for y0 in (0..h).step_by(ROW_CHUNK).rev() {
            let rows = y0..(y0 + ROW_CHUNK).min(h);
            before(data, rows.clone());
            self.row_forward
                .process_with_scratch(&mut data[rows.start * w..rows.end * w], scratch);
        }
        for x0 in (0..w).step_by(BLOCK_COLUMNS) {
            let bw = BLOCK_COLUMNS.min(w - x0);
            let block = &mut block[..bw * h];
            gather(data, w, x0, block, h, self.isa);
            self.col_forward.process_with_scratch(block, scratch);
            for (b, column) in block.chunks_exact_mut(h).enumerate() {
                multiply(x0 + b, column);
            }
            self.col_inverse.process_with_scratch(block, scratch);
            scatter(block, h, data, w, x0, self.isa);
        }
        for y0 in (0..h).step_by(ROW_CHUNK).rev() {
            let rows = y0..(y0 + ROW_CHUNK).min(h);
            let len = rows.len() * w;
            match rows_out.as_deref_mut() {
                Some(out) => {
                    let (out, spent) = (&mut out[..len], &mut data[rows.start * w..]);
                    out.copy_from_slice(&spent[..len]);
                    self.row_inverse.process_with_scratch(out, scratch);
                    after(out, rows, spent);
                }
                None => {
                    let chunk = &mut data[rows.start * w..rows.end * w];
                    self.row_inverse.process_with_scratch(chunk, scratch);
                    after(chunk, rows, &mut []);
                }
            }
        }
    }
}

/// Rows per chunk of `Fft2::filter_rows`' hooks: 8 rows of 1920 complex values are 123 KB, well inside a
/// core's L2 between the hook and the row transforms.
pub const ROW_CHUNK: usize = 8;

/// `block[b·h + y] = data[y·w + x0 + b]` for `b < block.len() / h`, `y < h`: the columns `x0..` of the
/// row-major `[h, w]` field, transposed into `block` ([`tensorholo_kernels::spectral::gather_columns`]: 8 × 8
/// tiles transposed in registers under AVX-512, tiles of 8 rows on the portable path).
fn gather(data: &[Complex32], w: usize, x0: usize, block: &mut [Complex32], h: usize, isa: Isa) {
    let bw = block.len() / h;
    let field = bytemuck::cast_slice::<Complex32, f32>(data);
    let out = bytemuck::cast_slice_mut::<Complex32, f32>(block);
    on_kernels(isa, |isa| {
        spectral::gather_columns(field, [h, w], x0, out, bw, isa)
    });
}

/// The inverse of [`gather`]: `data[y·w + x0 + b] = block[b·h + y]`.
fn scatter(block: &[Complex32], h: usize, data: &mut [Complex32], w: usize, x0: usize, isa: Isa) {
    let bw = block.len() / h;
    let src = bytemuck::cast_slice::<Complex32, f32>(block);
    let field = bytemuck::cast_slice_mut::<Complex32, f32>(data);
    on_kernels(isa, |isa| {
        spectral::scatter_columns(src, bw, field, [h, w], x0, isa)
    });
}

/// Runs one [`tensorholo_kernels::spectral`] call at `isa`. Its callers pass lengths that hold by
/// construction and a level [`Isa::detect`] found (one this CPU has), so the call does not fail; were it to,
/// it runs again on the portable level, which serves every CPU.
pub(crate) fn on_kernels(isa: Isa, mut call: impl FnMut(Isa) -> Result<(), KernelError>) {
    if call(isa).is_err() {
        let _ = call(Isa::Scalar);
    }
}

/// Signed DFT frequency index of bin `k` of an `n`-point transform: `0, 1, …, ⌈n/2⌉−1, −⌊n/2⌋, …, −1`
/// (the order of `numpy.fft.fftfreq(n) · n`).
pub fn signed_index(k: usize, n: usize) -> i64 {
    if k < n.div_ceil(2) {
        k as i64
    } else {
        k as i64 - n as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive_dft2(data: &[Complex32], h: usize, w: usize) -> Vec<Complex32> {
        let mut out = vec![Complex32::new(0.0, 0.0); h * w];
        for ky in 0..h {
            for kx in 0..w {
                let mut acc = num_complex::Complex64::new(0.0, 0.0);
                for y in 0..h {
                    for x in 0..w {
                        let ang = -2.0
                            * std::f64::consts::PI
                            * ((ky * y) as f64 / h as f64 + (kx * x) as f64 / w as f64);
                        let v = data[y * w + x];
                        acc += num_complex::Complex64::new(v.re as f64, v.im as f64)
                            * num_complex::Complex64::from_polar(1.0, ang);
                    }
                }
                out[ky * w + kx] = Complex32::new(acc.re as f32, acc.im as f32);
            }
        }
        out
    }

    #[test]
    fn forward_matches_naive_dft_in_transposed_layout_and_inverse_undoes_it() {
        let (h, w) = (6, 10);
        let data: Vec<Complex32> = (0..h * w)
            .map(|i| Complex32::new((i as f32 * 0.37).sin(), (i as f32 * 0.11).cos() - 0.3))
            .collect();
        let mut planner = FftPlanner::new();
        let fft = Fft2::new(&mut planner, h, w);
        let mut scratch = vec![Complex32::default(); fft.scratch_len()];
        let mut work = data.clone();
        let mut spectrum = vec![Complex32::default(); h * w];
        fft.forward(&mut work, &mut spectrum, &mut scratch);
        let reference = naive_dft2(&data, h, w);
        for ky in 0..h {
            for kx in 0..w {
                let d = spectrum[kx * h + ky] - reference[ky * w + kx];
                assert!(d.norm() < 1e-4, "bin ({ky},{kx}) differs by {}", d.norm());
            }
        }
        let mut back = vec![Complex32::default(); h * w];
        fft.inverse(&mut spectrum, &mut back, &mut scratch);
        for (b, d) in back.iter().zip(&data) {
            assert!((b / (h * w) as f32 - d).norm() < 1e-5);
        }
    }

    /// The blocked filter against rustfft's plain row/column form (forward, multiply, inverse) on random
    /// fields of odd and even sizes, under one block, several and a partial last one, and at 1080×1920:
    /// bit for bit, with a multiplier that depends on both frequencies (so a misplaced column shows).
    #[test]
    fn blocked_filter_is_bit_identical_to_forward_multiply_inverse() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let mut planner = FftPlanner::new();
        for (h, w) in [
            (1, 1),
            (5, 3),
            (7, 16),
            (6, 17),
            (33, 50),
            (64, 48),
            (1080, 1920),
        ] {
            let fft = Fft2::new(&mut planner, h, w);
            let data: Vec<Complex32> = (0..h * w).map(|_| Complex32::new(next(), next())).collect();
            let m: Vec<Complex32> = (0..h * w).map(|_| Complex32::new(next(), next())).collect();
            let mut scratch = vec![Complex32::default(); fft.scratch_len()];
            let (mut work, mut spectrum) = (data.clone(), vec![Complex32::default(); h * w]);
            fft.forward(&mut work, &mut spectrum, &mut scratch);
            spectrum.iter_mut().zip(&m).for_each(|(s, m)| *s *= m);
            let mut want = vec![Complex32::default(); h * w];
            fft.inverse(&mut spectrum, &mut want, &mut scratch);
            let mut got = data.clone();
            let mut block = vec![Complex32::default(); fft.block_len()];
            fft.filter(&mut got, &mut block, &mut scratch, |kx, row| {
                row.iter_mut()
                    .zip(&m[kx * h..(kx + 1) * h])
                    .for_each(|(s, m)| *s *= m)
            });
            let same = got
                .iter()
                .zip(&want)
                .all(|(a, b)| a.re.to_bits() == b.re.to_bits() && a.im.to_bits() == b.im.to_bits());
            assert!(same, "{h}×{w}");
            // And the filter is not the identity: the multiplier changed the field.
            assert!(
                got.iter().zip(&data).any(|(a, b)| (a - b).norm() > 1e-3),
                "{h}×{w}"
            );
        }
    }

    /// The hooks of `filter_rows`: `before` makes each chunk's rows (here from a function of the pixel) just
    /// before their transforms, last chunk first, on chunk starts that are multiples of `ROW_CHUNK`, with the
    /// rows after it already transformed and those before it untouched; `after` sees each chunk's final rows.
    /// The result is `filter` on the field made whole first, bit for bit, in the buffer or, with rows out,
    /// seen by `after` alone.
    #[test]
    fn row_hooks_run_in_chunk_order_and_keep_the_filter_bit_identical() {
        let value =
            |i: usize| Complex32::new((i as f32 * 0.37).sin(), (i as f32 * 0.013).cos() - 0.2);
        let mut planner = FftPlanner::new();
        for (h, w) in [(1, 4), (7, 5), (8, 3), (37, 20), (64, 33)] {
            let fft = Fft2::new(&mut planner, h, w);
            let mut scratch = vec![Complex32::default(); fft.scratch_len()];
            let mut block = vec![Complex32::default(); fft.block_len()];
            let multiply = |kx: usize, row: &mut [Complex32]| {
                for (ky, v) in row.iter_mut().enumerate() {
                    *v *= Complex32::new(1.0 + kx as f32 * 0.01, ky as f32 * 0.02);
                }
            };
            let mut want: Vec<Complex32> = (0..h * w).map(value).collect();
            fft.filter(&mut want, &mut block, &mut scratch, multiply);

            let mut rows_out = vec![Complex32::default(); ROW_CHUNK * w];
            for mut out in [None, Some(&mut rows_out[..])] {
                // Poisoned until `before` makes each row.
                let mut got = vec![Complex32::new(f32::NAN, f32::NAN); h * w];
                let (mut chunks, mut seen) = (Vec::new(), vec![Complex32::default(); h * w]);
                let (mut after_chunks, has_out) = (Vec::new(), out.is_some());
                fft.filter_rows(
                    &mut got,
                    &mut block,
                    &mut scratch,
                    |data, rows| {
                        assert_eq!(rows.start % ROW_CHUNK, 0, "{h}×{w}: chunk {rows:?}");
                        // Rows before the chunk are untouched (still poisoned).
                        assert!(data[..rows.start * w].iter().all(|v| v.re.is_nan()));
                        for (i, v) in data[rows.start * w..rows.end * w].iter_mut().enumerate() {
                            *v = value(rows.start * w + i);
                        }
                        chunks.push(rows);
                    },
                    multiply,
                    out.as_deref_mut(),
                    |chunk, rows, spent| {
                        seen[rows.start * w..rows.end * w].copy_from_slice(chunk);
                        // With rows out, the rows from this chunk on are spent: poisoned here, they must
                        // change no later chunk's result.
                        let spent_len = if has_out { (h - rows.start) * w } else { 0 };
                        assert_eq!(spent.len(), spent_len, "{h}×{w}: spent of {rows:?}");
                        spent.fill(Complex32::new(f32::NAN, f32::INFINITY));
                        after_chunks.push(rows);
                    },
                );
                assert_eq!(after_chunks, chunks, "{h}×{w}: after in before's order");
                let starts: Vec<usize> = chunks.iter().map(|r| r.start).collect();
                let mut descending = starts.clone();
                descending.sort_by(|a, b| b.cmp(a));
                assert_eq!(starts, descending, "{h}×{w}: last chunk first");
                assert_eq!(chunks.iter().map(|r| r.len()).sum::<usize>(), h, "{h}×{w}");
                let bits = |v: &[Complex32]| {
                    v.iter()
                        .flat_map(|c| [c.re.to_bits(), c.im.to_bits()])
                        .collect::<Vec<_>>()
                };
                // In place the buffer holds the result; with rows out, `after` alone sees it.
                assert_eq!(bits(&got) == bits(&want), out.is_none(), "{h}×{w}");
                assert_eq!(
                    bits(&seen),
                    bits(&want),
                    "{h}×{w}: after saw the final rows"
                );
            }
        }
    }

    #[test]
    fn signed_index_follows_fftfreq_order() {
        let even: Vec<i64> = (0..4).map(|k| signed_index(k, 4)).collect();
        assert_eq!(even, vec![0, 1, -2, -1]);
        let odd: Vec<i64> = (0..5).map(|k| signed_index(k, 5)).collect();
        assert_eq!(odd, vec![0, 1, 2, -2, -1]);
    }
}
