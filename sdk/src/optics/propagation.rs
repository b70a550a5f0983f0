//! Angular spectrum method (paper Eq. 2), offset propagation with the carrier term (Eq. 6 and Eq. 10), and the
//! planned spectral machinery both share.

use std::f64::consts::PI;

use num_complex::Complex32;
use rustfft::FftPlanner;
use tensorholo_kernels::{spectral, Isa};

use super::fft::{on_kernels, signed_index, Fft2};
use crate::error::{invalid, HoloError, Result};

/// Options of the angular spectrum method that change its transfer function or grid.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct PropagationOptions {
    /// Zero-pad the field to `2H × 2W` (centred) before the FFT and crop afterwards, so that the circular
    /// convolution of the FFT becomes the linear convolution of free-space diffraction (no wrap-around).
    pub pad: bool,
    /// Apply the band limit of Matsushima & Shimobaba (Opt. Express 17, 2009):
    /// `|fx| ≤ 1 / (λ·√((2·Δfx·z)² + 1))` (likewise `fy`), with `Δf = 1/(N·p)` the spectral sampling of the
    /// computational grid, which removes the aliased high-frequency part of the sampled transfer function.
    pub band_limit: bool,
}

/// Scratch space of a [`SpectralPlan`], owned by the caller so that the hot path performs no allocation.
/// Make one with [`SpectralPlan::scratch`]; one scratch per thread.
#[derive(Debug, Clone)]
pub struct Scratch {
    work: Vec<Complex32>,
    spare: Vec<Complex32>,
    /// The column block of [`Fft2::filter`].
    block: Vec<Complex32>,
    /// One chunk of rows ([`super::fft::ROW_CHUNK`]) for [`SpectralPlan::apply_even_rows`] when
    /// the field's own memory need not hold the result (unpadded plans).
    rows: Vec<Complex32>,
    fft: Vec<Complex32>,
}

/// A spectral multiplier that is even in both frequencies, `M(−u, v) = M(u, −v) = M(u, v)` (a transfer
/// function of the frequency radius, as the offset propagation's, Eq. 6), stored as the quarter of the
/// spectrum with non-negative frequencies: `(rows/2 + 1) × (cols/2 + 1)` values instead of `rows × cols`
/// (at 1080p, 4.2 MB instead of 16.6 MB per colour). Made from the full multiplier by
/// [`EvenMultiplier::from_full`], which checks the symmetry; applied by [`SpectralPlan::apply_even`].
#[derive(Debug, Clone, PartialEq)]
pub struct EvenMultiplier {
    /// The full spectrum's rows and columns (the plan's transposed layout).
    rows: usize,
    cols: usize,
    /// `[rows/2 + 1][cols/2 + 1]`.
    values: Vec<Complex32>,
}

impl EvenMultiplier {
    /// The compact form of `full`, a multiplier in `plan`'s spectrum layout, or `None` if `full` is not
    /// exactly (bit for bit) even in both frequencies. Errors: [`HoloError::ShapeMismatch`] for a length
    /// other than [`SpectralPlan::spectrum_len`].
    pub fn from_full(plan: &SpectralPlan, full: &[Complex32]) -> Result<Option<Self>> {
        plan.check_multiplier(full.len())?;
        let (rows, cols) = plan.spectrum_layout();
        let at = |r: usize, c: usize| full[r * cols + c];
        for r in 0..rows {
            for c in 0..cols {
                let (mr, mc) = (r.min(rows - r), c.min(cols - c));
                let (a, b) = (at(r, c), at(mr, mc));
                if a.re.to_bits() != b.re.to_bits() || a.im.to_bits() != b.im.to_bits() {
                    return Ok(None);
                }
            }
        }
        let qc = cols / 2 + 1;
        let mut values = Vec::with_capacity((rows / 2 + 1) * qc);
        for r in 0..=rows / 2 {
            values.extend_from_slice(&full[r * cols..r * cols + qc]);
        }
        Ok(Some(Self { rows, cols, values }))
    }

    /// The compact form of the multiplier `f(kx, ky)` of signed DFT bin indices in `plan`'s layout (as
    /// [`SpectralPlan::build_multiplier`] takes), for an `f` that is even in both by construction: only its
    /// quarter of non-negative indices is evaluated.
    pub(crate) fn from_fn(plan: &SpectralPlan, f: impl Fn(i64, i64) -> Complex32) -> Self {
        let (rows, cols) = plan.spectrum_layout();
        let qc = cols / 2 + 1;
        let mut values = Vec::with_capacity((rows / 2 + 1) * qc);
        for r in 0..=rows / 2 {
            let sr = signed_index(r, rows);
            values.extend((0..qc).map(|c| f(sr, signed_index(c, cols))));
        }
        Self { rows, cols, values }
    }

    fn quarter_cols(&self) -> usize {
        self.cols / 2 + 1
    }

    /// Multiplies row `r` of a spectrum (`cols` values, the plan's layout) by this multiplier's row `r`,
    /// read from the quarter: row `r` mirrors row `rows − r`, column `c ≥ cols/2 + 1` column `cols − c`.
    /// On the kernels' vector path for `isa` ([`tensorholo_kernels::spectral::multiply`]: `Complex32`'s own
    /// product, bit for bit).
    pub(crate) fn multiply_row(&self, r: usize, row: &mut [Complex32], isa: Isa) {
        let (rows, cols, qc) = (self.rows, self.cols, self.quarter_cols());
        let q = &self.values[r.min(rows - r) * qc..][..qc];
        let (low, high) = row.split_at_mut(qc);
        // Column c ≥ qc mirrors column cols − c, from cols − qc down to 1.
        let parts: [(&mut [Complex32], &[Complex32], bool); 2] =
            [(low, q, false), (high, &q[1..=cols - qc], true)];
        for (values, by, mirrored) in parts {
            let v = bytemuck::cast_slice_mut::<Complex32, f32>(values);
            let m = bytemuck::cast_slice::<Complex32, f32>(by);
            on_kernels(isa, |isa| spectral::multiply(v, m, mirrored, isa));
        }
    }

    /// Row `r`'s values in the quarter (`cols/2 + 1` of them): those of row `min(r, rows − r)`.
    pub(crate) fn quarter_row(&self, r: usize) -> &[Complex32] {
        let qc = self.quarter_cols();
        &self.values[r.min(self.rows - r) * qc..][..qc]
    }

    /// Bytes of the stored values.
    pub fn bytes(&self) -> usize {
        self.values.len() * std::mem::size_of::<Complex32>()
    }
}

/// A planned spectral (Fourier-domain) operation for fields of one size `[height, width]`, optionally with 2×
/// zero padding: `u ↦ F⁻¹{F{u} · M}` for a multiplier `M` given in the plan's spectrum layout
/// (transposed: `[comp_width, comp_height]`, FFT bin order, with the `1/(comp_height·comp_width)` inverse-FFT
/// normalisation folded in). Used by the [`Propagator`] and the Fourier filter.
#[derive(Debug, Clone)]
pub struct SpectralPlan {
    height: usize,
    width: usize,
    pad: bool,
    fft: Fft2,
}

/// Whether a [`SpectralPlan`] works on the field as it is (circular convolution) or zero-padded to
/// `2H × 2W` (linear convolution; 4× the work).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Padding {
    /// FFTs of the field's own size.
    #[default]
    None,
    /// FFTs of twice the field's height and width.
    Double,
}

impl Padding {
    /// `Double` when `pad`, as [`PropagationOptions::pad`] says.
    pub(crate) fn from_pad(pad: bool) -> Self {
        if pad {
            Self::Double
        } else {
            Self::None
        }
    }
}

impl SpectralPlan {
    /// Plans the FFTs for `[height, width]` fields, zero-padded as `padding` says.
    ///
    /// Errors: [`HoloError::InvalidParameter`] if either size is zero.
    pub(crate) fn new(height: usize, width: usize, padding: Padding) -> Result<Self> {
        let pad = padding == Padding::Double;
        if height == 0 || width == 0 {
            return Err(invalid(
                "field size",
                format!("height and width must be ≥ 1, got {height}×{width}"),
            ));
        }
        let factor = if pad { 2 } else { 1 };
        let mut planner = FftPlanner::new();
        let fft = Fft2::new(&mut planner, height * factor, width * factor);
        Ok(Self {
            height,
            width,
            pad,
            fft,
        })
    }

    /// Field rows.
    pub(crate) fn height(&self) -> usize {
        self.height
    }

    /// Field columns.
    pub(crate) fn width(&self) -> usize {
        self.width
    }

    /// Whether the computational grid is 2× zero padded.
    pub fn padded(&self) -> bool {
        self.pad
    }

    /// Computational grid `(rows, columns)`: the field size, doubled when padded.
    pub(crate) fn computational_shape(&self) -> (usize, usize) {
        (self.fft.height(), self.fft.width())
    }

    /// Number of values of a spectral multiplier or spectrum (`comp_height · comp_width`).
    pub fn spectrum_len(&self) -> usize {
        self.fft.height() * self.fft.width()
    }

    /// Allocates the scratch space this plan needs.
    pub fn scratch(&self) -> Scratch {
        let n = self.spectrum_len();
        let zero = Complex32::new(0.0, 0.0);
        Scratch {
            work: if self.pad { vec![zero; n] } else { Vec::new() },
            spare: Vec::new(),
            block: vec![zero; self.fft.block_len()],
            rows: if self.pad {
                Vec::new()
            } else {
                vec![zero; super::fft::ROW_CHUNK.min(self.height) * self.width]
            },
            fft: vec![zero; self.fft.scratch_len()],
        }
    }

    fn check_field(&self, len: usize) -> Result<()> {
        if len != self.height * self.width {
            return Err(HoloError::ShapeMismatch {
                what: "field vs planned propagation size".into(),
                expected: vec![self.height, self.width],
                got: vec![len],
            });
        }
        Ok(())
    }

    fn check_multiplier(&self, len: usize) -> Result<()> {
        if len != self.spectrum_len() {
            let (h, w) = self.computational_shape();
            return Err(HoloError::ShapeMismatch {
                what: "spectral multiplier vs planned computational grid".into(),
                expected: vec![w, h],
                got: vec![len],
            });
        }
        Ok(())
    }

    /// Copies a `[height, width]` field into the centre of the zeroed padded work buffer.
    fn embed(&self, field: &[Complex32], work: &mut [Complex32]) {
        let (ch, cw) = self.computational_shape();
        let (oy, ox) = ((ch - self.height) / 2, (cw - self.width) / 2);
        work.fill(Complex32::new(0.0, 0.0));
        for (y, row) in field.chunks_exact(self.width).enumerate() {
            let start = (y + oy) * cw + ox;
            work[start..start + self.width].copy_from_slice(row);
        }
    }

    /// Copies the centre `[height, width]` of the padded work buffer into `field`.
    fn crop(&self, work: &[Complex32], field: &mut [Complex32]) {
        let (ch, cw) = self.computational_shape();
        let (oy, ox) = ((ch - self.height) / 2, (cw - self.width) / 2);
        for (y, row) in field.chunks_exact_mut(self.width).enumerate() {
            let start = (y + oy) * cw + ox;
            row.copy_from_slice(&work[start..start + self.width]);
        }
    }

    /// `field ← F⁻¹{F{field} · multiplier}` in place (`field`: row-major `[height, width]`).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if `field` or `multiplier` has the wrong length.
    pub fn apply(
        &self,
        field: &mut [Complex32],
        multiplier: &[Complex32],
        scratch: &mut Scratch,
    ) -> Result<()> {
        self.check_field(field.len())?;
        self.check_multiplier(multiplier.len())?;
        let cols = self.spectrum_layout().1;
        self.filter_with(field, scratch, |r, row| {
            for (s, m) in row.iter_mut().zip(&multiplier[r * cols..(r + 1) * cols]) {
                *s *= m;
            }
        });
        Ok(())
    }

    /// `field ← F⁻¹{multiply(F{field})}` in place, padded as planned (lengths checked by the caller), on the
    /// cache-blocked [`Fft2::filter`]: `multiply(r, row)` gets row `r` of the spectrum (this plan's layout).
    fn filter_with(
        &self,
        field: &mut [Complex32],
        scratch: &mut Scratch,
        multiply: impl FnMut(usize, &mut [Complex32]),
    ) {
        let Scratch {
            work, block, fft, ..
        } = scratch;
        let spatial: &mut [Complex32] = if self.pad {
            self.embed(field, work);
            work
        } else {
            field
        };
        self.fft.filter(spatial, block, fft, multiply);
        if self.pad {
            self.crop(work, field);
        }
    }

    /// [`apply`](Self::apply) with a multiplier stored in its compact even form ([`EvenMultiplier`]: a
    /// quarter of the values). Bit-identical to `apply` with the full multiplier it was made from.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if `field` has the wrong length or the multiplier was made for
    /// another computational grid.
    pub fn apply_even(
        &self,
        field: &mut [Complex32],
        multiplier: &EvenMultiplier,
        scratch: &mut Scratch,
    ) -> Result<()> {
        self.apply_even_rows(field, multiplier, scratch, |_, _| {}, true, |_, _, _| {})
    }

    /// [`apply_even`](Self::apply_even) (the angular spectrum method's spectral multiply, Eq. 2; the offset
    /// propagation, Eq. 6, with its transfer function) on `field`, row-major `[height, width]`, with a pass of
    /// the caller's fused into each end (`Fft2::filter_rows`): `before(field, rows)` makes or changes the field's rows `rows` just before they are transformed (chunks
    /// of [`super::fft::ROW_CHUNK`] rows, last chunk first, each starting at a multiple of it; the
    /// whole field is passed, rows `≥ rows.end` already transformed), and `after(chunk, rows, spent)` reads
    /// rows `rows` of the result (`chunk`: those rows alone; last chunk first). With `keep` the field holds the
    /// result afterwards; without, an unpadded plan transforms each chunk's last pass in the scratch's own rows
    /// and leaves intermediate values in the field (not writing it a third time: 16.6 MB at 1080p, for a
    /// caller that reads the result only in `after`), and `spent` is the field from row `rows.start` to the
    /// end, values nothing reads any more that `after` may overwrite (`super::fft::Fft2::filter_rows`);
    /// otherwise `spent` is empty. With padding the hooks run on the whole field, before the embedding and
    /// after the crop (the field always holds the result; `spent` empty). Bit-identical to `before` on the
    /// whole field, `apply_even`, then `after`.
    ///
    /// Errors: as [`apply_even`](Self::apply_even).
    pub fn apply_even_rows(
        &self,
        field: &mut [Complex32],
        multiplier: &EvenMultiplier,
        scratch: &mut Scratch,
        before: impl FnMut(&mut [Complex32], std::ops::Range<usize>),
        keep: bool,
        after: impl FnMut(&[Complex32], std::ops::Range<usize>, &mut [Complex32]),
    ) -> Result<()> {
        self.check_field(field.len())?;
        self.check_even(multiplier)?;
        let isa = self.fft.isa();
        let multiply = |r: usize, row: &mut [Complex32]| multiplier.multiply_row(r, row, isa);
        self.filter_rows_with(field, scratch, before, keep, after, multiply);
        Ok(())
    }

    /// [`apply_even_rows`](Self::apply_even_rows) with a second multiplier `full`, in this plan's spectrum
    /// layout ([`SpectralPlan::spectrum_len`] values, as [`apply`](Self::apply) takes), applied after
    /// `even` (or alone with `None`): `field ← F⁻¹{F{field}·even·full}`. The session's aberration correction
    /// (`e^{iΣZ}` inside the pupil, which is not even in the frequencies) joins the offset propagation's
    /// transfer function this way, in the same pass; with `None` the normalisation of the inverse transform
    /// must be folded into `full`.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if `field` has the wrong length or a multiplier was made for
    /// another computational grid.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn apply_rows_then(
        &self,
        field: &mut [Complex32],
        even: Option<&EvenMultiplier>,
        full: &[Complex32],
        scratch: &mut Scratch,
        before: impl FnMut(&mut [Complex32], std::ops::Range<usize>),
        keep: bool,
        after: impl FnMut(&[Complex32], std::ops::Range<usize>, &mut [Complex32]),
    ) -> Result<()> {
        self.check_field(field.len())?;
        self.check_multiplier(full.len())?;
        if let Some(even) = even {
            self.check_even(even)?;
        }
        let isa = self.fft.isa();
        let cols = self.spectrum_layout().1;
        let multiply = |r: usize, row: &mut [Complex32]| {
            if let Some(even) = even {
                even.multiply_row(r, row, isa);
            }
            let v = bytemuck::cast_slice_mut::<Complex32, f32>(row);
            let m = bytemuck::cast_slice::<Complex32, f32>(&full[r * cols..(r + 1) * cols]);
            on_kernels(isa, |isa| spectral::multiply(v, m, false, isa));
        };
        self.filter_rows_with(field, scratch, before, keep, after, multiply);
        Ok(())
    }

    /// The row-fused filter of [`apply_even_rows`](Self::apply_even_rows) with any row multiply (lengths
    /// checked by the caller).
    fn filter_rows_with(
        &self,
        field: &mut [Complex32],
        scratch: &mut Scratch,
        mut before: impl FnMut(&mut [Complex32], std::ops::Range<usize>),
        keep: bool,
        mut after: impl FnMut(&[Complex32], std::ops::Range<usize>, &mut [Complex32]),
        multiply: impl FnMut(usize, &mut [Complex32]),
    ) {
        if self.pad {
            before(field, 0..self.height);
            self.filter_with(field, scratch, multiply);
            after(field, 0..self.height, &mut []);
        } else {
            let Scratch {
                block, fft, rows, ..
            } = scratch;
            let rows_out = (!keep).then_some(&mut rows[..]);
            self.fft
                .filter_rows(field, block, fft, before, multiply, rows_out, after);
        }
    }

    /// Errors: [`HoloError::ShapeMismatch`] if `multiplier` was made for another computational grid.
    fn check_even(&self, multiplier: &EvenMultiplier) -> Result<()> {
        let (rows, cols) = self.spectrum_layout();
        if (multiplier.rows, multiplier.cols) != (rows, cols) {
            return Err(HoloError::ShapeMismatch {
                what: "even spectral multiplier (spectrum rows, columns)".into(),
                expected: vec![rows, cols],
                got: vec![multiplier.rows, multiplier.cols],
            });
        }
        Ok(())
    }

    /// The spectrum layout `(rows, columns)`: transposed, `(comp_width, comp_height)`.
    fn spectrum_layout(&self) -> (usize, usize) {
        (self.fft.width(), self.fft.height())
    }

    /// The planned 2D FFT of the computational grid (for callers that keep their own spectra, such as the
    /// focal-stack refinement, `crate::refine`).
    pub(crate) fn fft(&self) -> &Fft2 {
        &self.fft
    }

    /// Forward transform of a `[height, width]` field into `spectrum` (this plan's layout, unnormalised),
    /// for applying several multipliers to one spectrum with [`SpectralPlan::inverse`].
    ///
    /// Errors: [`HoloError::ShapeMismatch`] on wrong lengths.
    pub fn forward(
        &self,
        field: &[Complex32],
        spectrum: &mut [Complex32],
        scratch: &mut Scratch,
    ) -> Result<()> {
        self.check_field(field.len())?;
        self.check_multiplier(spectrum.len())?;
        let Scratch { work, fft, .. } = scratch;
        if self.pad {
            self.embed(field, work);
        } else {
            work.clear();
            work.extend_from_slice(field);
        }
        self.fft.forward(work, spectrum, fft);
        Ok(())
    }

    /// `field ← F⁻¹{spectrum · multiplier}` (cropped when padded); `spectrum` is left unchanged.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] on wrong lengths.
    pub fn inverse(
        &self,
        spectrum: &[Complex32],
        multiplier: &[Complex32],
        field: &mut [Complex32],
        scratch: &mut Scratch,
    ) -> Result<()> {
        self.check_field(field.len())?;
        self.check_multiplier(spectrum.len())?;
        self.check_multiplier(multiplier.len())?;
        let spare = &mut scratch.spare;
        spare.clear();
        spare.extend(spectrum.iter().zip(multiplier).map(|(s, m)| s * m));
        self.inverse_of_spare(field, scratch);
        Ok(())
    }

    /// `field ← F⁻¹{scratch.spare}` (cropped when padded; `spare` is overwritten).
    fn inverse_of_spare(&self, field: &mut [Complex32], scratch: &mut Scratch) {
        let Scratch {
            work, spare, fft, ..
        } = scratch;
        if self.pad {
            self.fft.inverse(spare, work, fft);
            self.crop(work, field);
        } else {
            self.fft.inverse(spare, field, fft);
        }
    }

    /// [`inverse`](Self::inverse) with a multiplier in its compact even form ([`EvenMultiplier`]):
    /// bit-identical to `inverse` with the full multiplier it stands for.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] on wrong lengths or a multiplier of another grid.
    pub fn inverse_even(
        &self,
        spectrum: &[Complex32],
        multiplier: &EvenMultiplier,
        field: &mut [Complex32],
        scratch: &mut Scratch,
    ) -> Result<()> {
        self.check_field(field.len())?;
        self.check_multiplier(spectrum.len())?;
        self.check_even(multiplier)?;
        let spare = &mut scratch.spare;
        spare.clear();
        spare.extend_from_slice(spectrum);
        let cols = self.spectrum_layout().1;
        for (r, row) in spare.chunks_exact_mut(cols).enumerate() {
            multiplier.multiply_row(r, row, self.fft.isa());
        }
        self.inverse_of_spare(field, scratch);
        Ok(())
    }

    /// [`build_multiplier`](Self::build_multiplier) into the caller's buffer (resized to
    /// [`SpectralPlan::spectrum_len`]: no allocation when it already has that capacity).
    pub(crate) fn fill_multiplier(
        &self,
        out: &mut Vec<Complex32>,
        mut f: impl FnMut(i64, i64) -> Complex32,
    ) {
        let (ch, cw) = self.computational_shape();
        out.clear();
        for kx in 0..cw {
            let sx = signed_index(kx, cw);
            out.extend((0..ch).map(|ky| f(sx, signed_index(ky, ch))));
        }
    }

    /// Calls `f(fx_index, fy_index, value)` to fill a multiplier in this plan's layout, where the indices are
    /// signed DFT bin indices of the computational grid (see [`signed_index`]).
    pub(crate) fn build_multiplier(&self, f: impl FnMut(i64, i64) -> Complex32) -> Vec<Complex32> {
        let mut out = Vec::with_capacity(self.spectrum_len());
        self.fill_multiplier(&mut out, f);
        out
    }
}

/// Whether a transfer function keeps the on-axis phase `exp(i·2π·z/λ)` of a plane wave travelling `z`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Carrier {
    /// Plain angular spectrum method, Eq. 2.
    Keep,
    /// Multiply by `exp(−i·2π·z/λ)`: the offset propagation of Eq. 6 (`z = s`) and of Eq. 10 (`z = −s`), which
    /// keeps the propagated phase centred near 0 (paper: "exponential phase correction term").
    Remove,
}

/// A transfer function `exp(i·2π·z·√(λ⁻² − fx² − fy²))` sampled on a [`Propagator`]'s grid (paper Eq. 2), with
/// evanescent components zeroed and optionally band-limited; built once per (size, λ, z) and reused.
#[derive(Debug, Clone)]
pub struct TransferFunction {
    distance_m: f64,
    values: Vec<Complex32>,
}

impl TransferFunction {
    /// Propagation distance `z` in metres (positive along the light).
    pub fn distance_m(&self) -> f64 {
        self.distance_m
    }

    /// The multiplier in [`SpectralPlan`] layout (transposed, FFT order, normalisation folded in).
    pub fn values(&self) -> &[Complex32] {
        &self.values
    }

    /// Multiplies the transfer function by another multiplier of the same plan in place (e.g. a Fourier filter
    /// mask, to filter and propagate with one FFT pair).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if the lengths differ.
    pub fn multiply(&mut self, other: &[Complex32]) -> Result<()> {
        if other.len() != self.values.len() {
            return Err(HoloError::ShapeMismatch {
                what: "multiplier vs transfer function".into(),
                expected: vec![self.values.len()],
                got: vec![other.len()],
            });
        }
        for (v, o) in self.values.iter_mut().zip(other) {
            *v *= o;
        }
        Ok(())
    }
}

/// An angular spectrum propagator (paper Eq. 2) for one field size, pixel pitch and wavelength, planned once.
///
/// `ASM(u, z) = F⁻¹{F{u} · exp(i·2π·z·√(λ⁻² − fx² − fy²))}` with `fx = kx / (N·p)` the spatial frequency in
/// cycles per metre; positive `z` travels with the light (`docs/CONVENTIONS.md` §5.1). Fields are
/// `[height, width]` row-major `Complex32`; distances in metres.
#[derive(Debug, Clone)]
pub struct Propagator {
    plan: SpectralPlan,
    pixel_pitch_m: f64,
    wavelength_m: f64,
    options: PropagationOptions,
}

/// Checks that a physical scalar is finite and strictly positive.
pub(crate) fn check_positive(name: &'static str, value: f64) -> Result<()> {
    if !(value.is_finite() && value > 0.0) {
        return Err(invalid(
            name,
            format!("must be a finite positive number, got {value}"),
        ));
    }
    Ok(())
}

impl Propagator {
    /// Plans a propagator for `[height, width]` fields sampled at `pixel_pitch_m` with light of `wavelength_m`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a zero size or a non-positive / non-finite pitch or
    /// wavelength.
    pub fn new(
        height: usize,
        width: usize,
        pixel_pitch_m: f64,
        wavelength_m: f64,
        options: PropagationOptions,
    ) -> Result<Self> {
        check_positive("pixel_pitch_m", pixel_pitch_m)?;
        check_positive("wavelength_m", wavelength_m)?;
        Ok(Self {
            plan: SpectralPlan::new(height, width, Padding::from_pad(options.pad))?,
            pixel_pitch_m,
            wavelength_m,
            options,
        })
    }

    /// The planned FFT machinery (field size, padding, scratch, forward/inverse).
    pub fn plan(&self) -> &SpectralPlan {
        &self.plan
    }

    /// Wavelength in metres.
    pub fn wavelength_m(&self) -> f64 {
        self.wavelength_m
    }

    /// Pixel pitch in metres.
    pub fn pixel_pitch_m(&self) -> f64 {
        self.pixel_pitch_m
    }

    /// Padding and band-limit options.
    pub fn options(&self) -> PropagationOptions {
        self.options
    }

    /// Builds the transfer function for distance `distance_m` (metres, any sign).
    ///
    /// Phases are computed in f64 (at 3 mm and 450 nm the carrier alone is ~4·10⁴ rad) before rounding to f32.
    ///
    /// Errors: [`HoloError::InvalidParameter`] if `distance_m` is not finite.
    pub fn transfer_function(&self, distance_m: f64, carrier: Carrier) -> Result<TransferFunction> {
        let value = self.transfer_value(distance_m, carrier)?;
        let values = self.plan.build_multiplier(value);
        Ok(TransferFunction { distance_m, values })
    }

    /// [`Propagator::transfer_function`] in its compact even form ([`EvenMultiplier`]): the transfer function
    /// depends on `fx²`, `fy²`, `|fx|` and `|fy|` only, so only the quarter of non-negative frequencies is
    /// computed (a quarter of the work and memory; a session's setup at 1080p computes three). Bit-identical
    /// to [`EvenMultiplier::from_full`] of the full transfer function (tested).
    ///
    /// Errors: as [`Propagator::transfer_function`].
    pub fn even_transfer_function(
        &self,
        distance_m: f64,
        carrier: Carrier,
    ) -> Result<EvenMultiplier> {
        let value = self.transfer_value(distance_m, carrier)?;
        Ok(EvenMultiplier::from_fn(&self.plan, value))
    }

    /// [`Propagator::even_transfer_function`] times a real multiplier `mask(kx, ky)` of signed DFT bin
    /// indices that is even in both (the Fourier filter's aperture, Eq. 9): filter and propagation as one
    /// spectral multiplier. Errors: as [`Propagator::transfer_function`].
    pub(crate) fn even_transfer_function_masked(
        &self,
        distance_m: f64,
        carrier: Carrier,
        mask: impl Fn(i64, i64) -> f32,
    ) -> Result<EvenMultiplier> {
        let value = self.transfer_value(distance_m, carrier)?;
        Ok(EvenMultiplier::from_fn(&self.plan, |kx, ky| {
            value(kx, ky) * mask(kx, ky)
        }))
    }

    /// The transfer function's value at signed DFT bin `(kx, ky)` of the computational grid (Eq. 2, with the
    /// carrier removed for Eq. 6 / Eq. 10; evanescent and band-limited bins zero; the inverse-FFT
    /// normalisation folded in). Errors: as [`Propagator::transfer_function`].
    fn transfer_value(
        &self,
        distance_m: f64,
        carrier: Carrier,
    ) -> Result<impl Fn(i64, i64) -> Complex32> {
        if !distance_m.is_finite() {
            return Err(invalid(
                "distance_m",
                format!("must be finite, got {distance_m}"),
            ));
        }
        let (ch, cw) = self.plan.computational_shape();
        let p = self.pixel_pitch_m;
        let wavelength_m = self.wavelength_m;
        let inv_lambda = 1.0 / wavelength_m;
        let inv_lambda2 = inv_lambda * inv_lambda;
        let norm = 1.0 / (ch * cw) as f32;
        let (dfx, dfy) = (1.0 / (cw as f64 * p), 1.0 / (ch as f64 * p));
        let band_limit = self.options.band_limit;
        let limit = |df: f64| {
            if band_limit {
                1.0 / (wavelength_m * ((2.0 * df * distance_m).powi(2) + 1.0).sqrt())
            } else {
                f64::INFINITY
            }
        };
        let (fx_limit, fy_limit) = (limit(dfx), limit(dfy));
        Ok(move |kx: i64, ky: i64| {
            let fx = kx as f64 * dfx;
            let fy = ky as f64 * dfy;
            let f2 = fx * fx + fy * fy;
            if fx.abs() > fx_limit || fy.abs() > fy_limit {
                return Complex32::new(0.0, 0.0);
            }
            let Some(phase) = transfer_phase_rad(inv_lambda, inv_lambda2, distance_m, f2, carrier)
            else {
                return Complex32::new(0.0, 0.0);
            };
            let (s, c) = phase.sin_cos();
            Complex32::new(c as f32 * norm, s as f32 * norm)
        })
    }

    /// Propagates `field` (`[height, width]` row-major) in place by the transfer function `tf`.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if `field` or `tf` does not belong to this plan.
    pub fn propagate(
        &self,
        field: &mut [Complex32],
        tf: &TransferFunction,
        scratch: &mut Scratch,
    ) -> Result<()> {
        self.plan.apply(field, &tf.values, scratch)
    }

    /// Convenience (allocating) form: propagates `field` by `distance_m` with the given carrier handling.
    ///
    /// Errors: as [`Propagator::transfer_function`] and [`Propagator::propagate`];
    /// [`HoloError::InvalidData`] if `field` holds NaN or infinite values (the FFT would spread them over
    /// the whole field), naming how many and the first.
    pub fn propagate_by(
        &self,
        field: &mut [Complex32],
        distance_m: f64,
        carrier: Carrier,
    ) -> Result<()> {
        let bad = field.iter().filter(|v| !v.is_finite()).count();
        if bad > 0 {
            let first = field.iter().position(|v| !v.is_finite()).unwrap_or(0);
            return Err(HoloError::InvalidData(format!(
                "the field holds {bad} NaN or infinite value(s) (the first at element {first}, row {}, column \
                 {}); propagation would spread them over the whole field",
                first / self.plan.width().max(1),
                first % self.plan.width().max(1)
            )));
        }
        let tf = self.transfer_function(distance_m, carrier)?;
        let mut scratch = self.plan.scratch();
        self.propagate(field, &tf, &mut scratch)
    }
}
/// The angular spectrum transfer function's phase in radians (paper Eq. 2, `docs/CONVENTIONS.md` §5.2) at
/// squared radial frequency `f2` (cycles² per m²) over `distance_m` metres, for `inv_lambda = 1/λ` and
/// `inv_lambda2 = 1/λ²`: `2π·z·√(1/λ² − f²)`, or with the carrier removed (Eq. 6, Eq. 10)
/// `2π·z·(√(1/λ² − f²) − 1/λ)`, computed as `−2π·z·f²/(√(1/λ² − f²) + 1/λ)` (no cancellation for small `f`).
/// `None` for an evanescent `f² ≥ 1/λ²`. The one transfer phase of the SDK: the propagator's transfer
/// functions and the display mapping's residual (`crate::display`) both use it.
#[inline]
pub(crate) fn transfer_phase_rad(
    inv_lambda: f64,
    inv_lambda2: f64,
    distance_m: f64,
    f2: f64,
    carrier: Carrier,
) -> Option<f64> {
    let arg = inv_lambda2 - f2;
    if arg <= 0.0 {
        return None;
    }
    let kz = arg.sqrt();
    Some(match carrier {
        Carrier::Keep => 2.0 * PI * distance_m * kz,
        Carrier::Remove => -2.0 * PI * distance_m * f2 / (kz + inv_lambda),
    })
}

/// The carrier-free transfer phase (the propagator's, with [`Carrier::Remove`]) at wavelength
/// `wavelength_m` and squared radial frequency `f2` (cycles² per m²) over `distance_m` metres, radians;
/// `None` for an evanescent frequency.
pub(crate) fn carrier_free_phase_rad(wavelength_m: f64, distance_m: f64, f2: f64) -> Option<f64> {
    let inv = 1.0 / wavelength_m;
    transfer_phase_rad(inv, inv * inv, distance_m, f2, Carrier::Remove)
}
