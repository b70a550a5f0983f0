//! Double phase encoding (paper Eq. 7) with optional pre-filtering (AA-DPM, BL-DPM).

use std::f32::consts::TAU;

use ndarray::{Array3, ArrayView3, CowArray, Ix3};
use num_complex::Complex32;
use rayon::prelude::*;
use tensorholo_kernels::{double_phase as kernel, Isa};

use crate::error::{invalid, HoloError, Result};
use crate::optics::{check_colour_stack, check_finite_field, par_channels, Scratch, SpectralPlan};

/// Which low-pass pre-filter, if any, to apply to the complex hologram before double phase encoding.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(tag = "method", rename_all = "kebab-case")]
pub enum DoublePhaseMethod {
    /// Plain double phase encoding, Eq. 7 (what DDPM uses after its pre-filter CNN).
    Plain,
    /// Anti-aliasing DPM (TensorHolo V1): Gaussian blur of the real and imaginary parts with standard
    /// deviation `sigma_px` (pixels) and an odd `kernel_size` (pixels), edges clamped, before encoding.
    AntiAliased {
        /// Gaussian standard deviation in pixels (> 0).
        sigma_px: f32,
        /// Kernel width in pixels (odd, ≥ 1).
        kernel_size: usize,
    },
    /// Band-limiting DPM (Sui et al. 2021): the hologram's spectrum is multiplied by a diamond-shaped mask
    /// `|fx|/f_Nx + |fy|/f_Ny ≤ k` (`f_N` the Nyquist frequency `1/(2p)` of each axis), `0 < k ≤ 1`. The
    /// diamond is the Nyquist cell of the checkerboard (quincunx) lattice on which each of the two double-phase
    /// sub-holograms is sampled, so frequencies outside it alias when the two are interleaved; smaller `k`
    /// trades sharpness for less speckle.
    BandLimited {
        /// Cut-off as a fraction of the diamond Nyquist cell, `0 < k ≤ 1`.
        k: f32,
    },
}

impl Default for DoublePhaseMethod {
    fn default() -> Self {
        Self::AntiAliased {
            sigma_px: 0.7,
            kernel_size: 5,
        }
    }
}

impl DoublePhaseMethod {
    fn validate(&self) -> Result<()> {
        match *self {
            Self::Plain => Ok(()),
            Self::AntiAliased {
                sigma_px,
                kernel_size,
            } => {
                if !(sigma_px.is_finite() && sigma_px > 0.0) {
                    return Err(invalid("sigma_px", format!("must be > 0, got {sigma_px}")));
                }
                if kernel_size == 0 || kernel_size % 2 == 0 {
                    return Err(invalid(
                        "kernel_size",
                        format!("must be odd and ≥ 1, got {kernel_size}"),
                    ));
                }
                Ok(())
            }
            Self::BandLimited { k } => {
                if !(k.is_finite() && k > 0.0 && k <= 1.0) {
                    return Err(invalid("k", format!("must lie in (0, 1], got {k}")));
                }
                Ok(())
            }
        }
    }
}

/// A double-phase-encoded hologram.
#[derive(Debug, Clone)]
pub struct DoublePhase {
    /// Phase-only pattern `[3, H, W]` (R, G, B) in radians, wrapped to `[0, 2π)`.
    pub phase: Array3<f32>,
    /// The global amplitude normaliser `a` (max amplitude over all colours after pre-filtering): the pattern
    /// reconstructs (after the Fourier filter) to about `H / a` up to a per-channel constant phase.
    pub amplitude_scale: f32,
    /// Per-channel mean phase (radians) removed before encoding.
    pub mean_phase: [f32; 3],
}

/// Double phase encoding of a complex hologram `field` `[3, H, W]` (R, G, B), paper Eq. 7
/// (`docs/CONVENTIONS.md` §5.3):
///
/// 1. optional pre-filter (`method`);
/// 2. amplitude normalised by one global maximum `a` over all colours: `Ã = A / a ∈ [0, 1]`;
/// 3. phase `φ = arg H` de-meaned per channel;
/// 4. `P = φ − acos Ã` where `x + y` is odd, `φ + acos Ã` where it is even (`x` column, `y` row);
/// 5. `P` wrapped to `[0, 2π)`.
///
/// The scale `0.5·a` of Eq. 7 cannot be shown by a phase-only SLM; it is returned as `amplitude_scale`.
///
/// The per-pixel arithmetic runs in the vectorised row kernels of `tensorholo-kernels`
/// ([`tensorholo_kernels::double_phase`]: polynomial `atan2` and `acos`, within 1.2·10⁻⁶ rad of libm's
/// `atan2f`/`acosf`, so an 8-bit code equals libm's or, within that distance of a rounding boundary, differs
/// by one step), on bands of rows on rayon's threads.
///
/// Errors: a field that is not `[3, H, W]` ([`HoloError::ShapeMismatch`]), non-finite values or an all-zero
/// field ([`HoloError::InvalidData`]), invalid method parameters ([`HoloError::InvalidParameter`]).
pub fn double_phase_encode(
    field: ArrayView3<Complex32>,
    method: &DoublePhaseMethod,
) -> Result<DoublePhase> {
    let (h, w) = check_colour_stack("hologram", &field)?;
    check_finite_field("hologram", &field)?;
    method.validate()?;
    let isa = Isa::detect();
    let filtered: CowArray<Complex32, Ix3> = match *method {
        DoublePhaseMethod::Plain => field.as_standard_layout(),
        _ => {
            let mut owned = field.as_standard_layout().into_owned();
            let band = match *method {
                DoublePhaseMethod::BandLimited { k } => Some(BandLimit::new(h, w, k)?),
                _ => None,
            };
            let kernel = method.kernel();
            par_channels(&mut owned, |_, slice| {
                let mut tmp = Vec::new();
                match &band {
                    Some(b) => b.apply(slice, &mut b.plan.scratch()),
                    None => {
                        blur_separable(slice, h, w, &kernel, &mut tmp);
                        Ok(())
                    }
                }
            })?;
            owned.into()
        }
    };
    // Pass 1 (bands of rows in parallel): phase φ = arg H into the output, per-row max |H|² and Σφ.
    let mut phase = Array3::<f32>::zeros((3, h, w));
    let src = filtered.as_slice().expect("standard layout");
    let band = band_rows(w);
    let rows: Vec<ChannelStats> = phase
        .as_slice_mut()
        .expect("fresh array")
        .par_chunks_mut(w)
        .zip(src.par_chunks(w))
        .with_min_len(band)
        .map(|(out, row)| analyse_row(row, out, isa))
        .collect::<Result<_>>()?;
    let stats: Vec<ChannelStats> = rows
        .chunks(h)
        .map(|c| c.iter().fold(ChannelStats::default(), |a, b| a.merge(*b)))
        .collect();
    let (a, mean_phase) = normaliser(&stats, h * w)?;
    // Pass 2 (bands of rows in parallel): P = φ − mean ∓ acos(Ã), checkerboard by x + y parity (Eq. 7).
    let inv_a = 1.0 / a;
    phase
        .as_slice_mut()
        .expect("fresh array")
        .par_chunks_mut(w)
        .zip(src.par_chunks(w))
        .enumerate()
        .with_min_len(band)
        .try_for_each(|(r, (out, row))| {
            let row = bytemuck::cast_slice(row);
            let (layout, mean) = (PassOneLayout::Field, mean_phase[r / h]);
            encode_row(row, layout, out, None, r % h, mean, inv_a, isa)
        })?;
    debug_assert!(phase.iter().all(|p| (0.0..TAU).contains(p)));
    Ok(DoublePhase {
        phase,
        amplitude_scale: a,
        mean_phase,
    })
}

/// What pass 1 of the double phase encoding learns about a channel (or a row of it): the maximum `|H|²` and
/// the sum of `arg H` (radians) over its pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ChannelStats {
    /// Maximum squared amplitude.
    pub max_amplitude_sq: f32,
    /// Sum of the phases `arg H` (radians), in f64 to keep the mean exact over millions of pixels.
    pub phase_sum: f64,
}

impl ChannelStats {
    fn merge(self, o: Self) -> Self {
        Self {
            max_amplitude_sq: self.max_amplitude_sq.max(o.max_amplitude_sq),
            phase_sum: self.phase_sum + o.phase_sum,
        }
    }
}

/// The global normaliser `a = max |H|` over all colours and the per-channel mean phases (Eq. 7) from the
/// pass-1 statistics of the three channels of `pixels` pixels each.
///
/// Errors: [`HoloError::InvalidData`] if the hologram is zero everywhere (or not finite).
pub fn normaliser(stats: &[ChannelStats], pixels: usize) -> Result<(f32, [f32; 3])> {
    let a = stats
        .iter()
        .map(|s| s.max_amplitude_sq)
        .fold(0.0f32, f32::max)
        .sqrt();
    if !(a > 0.0 && a.is_finite()) {
        return Err(HoloError::InvalidData(
            "hologram amplitude is zero everywhere: nothing to encode".into(),
        ));
    }
    let mut mean = [0.0f32; 3];
    for (m, s) in mean.iter_mut().zip(stats) {
        *m = (s.phase_sum / pixels as f64) as f32;
    }
    Ok((a, mean))
}

/// Rows per band of [`double_phase_encode`]'s passes on rayon's threads: about 64k pixels, enough to
/// amortise a task, few enough to balance `3·H` rows over the threads.
fn band_rows(width: usize) -> usize {
    (65_536 / width.max(1)).max(1)
}

/// A row kernel's error: the lengths are equal by construction and the ISA was checked, so never.
fn kernel_err(e: tensorholo_kernels::KernelError) -> HoloError {
    HoloError::Internal(format!("double phase row kernel: {e}"))
}

/// Pass 1 on one row: `out ← arg H`, returns the row's statistics.
fn analyse_row(row: &[Complex32], out: &mut [f32], isa: Isa) -> Result<ChannelStats> {
    let (max_amplitude_sq, phase_sum) =
        kernel::analyse_row(bytemuck::cast_slice(row), out, isa).map_err(kernel_err)?;
    Ok(ChannelStats {
        max_amplitude_sq,
        phase_sum,
    })
}

/// Pass 2 on row `y`: `out` holds `arg H` from pass 1 and becomes the wrapped double phase
/// `φ − mean ± acos(|H|/a)` (Eq. 7, `+` where `x + y` is even); `codes`, if given, receives the 8-bit codes of
/// the [`LinearLut`](super::LinearLut).
///
/// `row` holds the row's `(Re H, Im H)` pairs with `layout` [`PassOneLayout::Field`] (`2·W` values), its
/// magnitudes `|H|` with [`PassOneLayout::Magnitudes`] (`W` values): the same values either way.
#[allow(clippy::too_many_arguments)]
fn encode_row(
    row: &[f32],
    layout: PassOneLayout,
    out: &mut [f32],
    codes: Option<&mut [u8]>,
    y: usize,
    mean: f32,
    inv_a: f32,
    isa: Isa,
) -> Result<()> {
    let odd = y % 2 == 1;
    match layout {
        PassOneLayout::Field => kernel::encode_row(row, out, codes, odd, mean, inv_a, isa),
        PassOneLayout::Magnitudes => kernel::encode_abs_row(row, out, codes, odd, mean, inv_a, isa),
    }
    .map_err(kernel_err)
}

/// Where pass 2 finds each pixel's `|H|` once pass 1 has run on a channel: what
/// [`ChannelEncoder::analyse_planes`] returns (the session keeps it beside the field until pass 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum PassOneLayout {
    /// The field memory holds `H`, interleaved complex `[H, W]` ([`ChannelEncoder::analyse`], or
    /// `analyse_planes` with a filtering method).
    Field,
    /// The field memory holds two real planes `[H, W]`: `Re H`, then `|H|` (`analyse_planes` with the plain
    /// method: no interleaved copy of the field is written, and pass 2 reads `|H|` and `arg H` only).
    Magnitudes,
}

impl PassOneLayout {
    /// Values per pixel of the plane pass 2 reads.
    fn values_per_pixel(self) -> usize {
        match self {
            Self::Field => 2,
            Self::Magnitudes => 1,
        }
    }

    /// The values pass 2 reads in a field's memory (`2·H·W` values): all of it, or its second half.
    fn source(self, field: &[Complex32]) -> &[f32] {
        let flat: &[f32] = bytemuck::cast_slice(field);
        match self {
            Self::Field => flat,
            Self::Magnitudes => &flat[field.len()..],
        }
    }
}

/// Rows per task of [`ChannelEncoder::analyse_planes`] and [`ChannelEncoder::encode_on`] on a pool: 8 rows of
/// 1920 pixels are 61 KB of each plane, a few hundred tasks per 1080p colour for the pool's threads to share.
const ANALYSE_ROWS: usize = 8;

/// Pixels per block of [`interleave_in_place`].
const INTERLEAVE_BLOCK: usize = 16;

/// `buf[2i], buf[2i + 1] ← buf[i], second[i]` for the pixels `i` in `pixels` (`buf` holds `2n` values, the
/// first plane in its first half, `n = second.len()`), where the pixels from `pixels.end` on are already
/// interleaved and those below `pixels.start` not yet (so a whole field goes as one range or as ranges from
/// the last to the first). Blocks of [`INTERLEAVE_BLOCK`] pixels run from last to first, each read whole
/// before it is written, so that writing block `[i, i + B)` (values `2i..2i + 2B`) never overwrites a
/// first-plane value still to be read (those are below `i ≤ 2i`); the pixels after the range's last whole
/// block go first, one by one from the last. The fixed-size blocks compile to vector shuffles (a
/// pixel-by-pixel loop does not vectorise).
pub(crate) fn interleave_in_place(buf: &mut [f32], second: &[f32], pixels: std::ops::Range<usize>) {
    const B: usize = INTERLEAVE_BLOCK;
    debug_assert_eq!(buf.len(), 2 * second.len());
    let (p0, p1) = (pixels.start, pixels.end);
    let whole = p0 + (p1 - p0) / B * B;
    for i in (whole..p1).rev() {
        buf[2 * i] = buf[i];
        buf[2 * i + 1] = second[i];
    }
    for i in (p0..whole).step_by(B).rev() {
        let mut first = [0.0f32; B];
        first.copy_from_slice(&buf[i..i + B]);
        let mut pairs = [0.0f32; 2 * B];
        for ((pair, re), im) in pairs.chunks_exact_mut(2).zip(first).zip(&second[i..i + B]) {
            pair[0] = re;
            pair[1] = *im;
        }
        buf[2 * i..2 * (i + B)].copy_from_slice(&pairs);
    }
}

/// The diamond band limit of BL-DPM for one field size: plan, mask (with the inverse-FFT normalisation).
#[derive(Debug, Clone)]
struct BandLimit {
    plan: SpectralPlan,
    mask: Vec<Complex32>,
}

impl BandLimit {
    fn new(h: usize, w: usize, k: f32) -> Result<Self> {
        let plan = SpectralPlan::new(h, w, crate::optics::Padding::None)?;
        let norm = 1.0 / plan.spectrum_len() as f32;
        let (hh, hw) = ((h as f64 / 2.0).max(0.5), (w as f64 / 2.0).max(0.5));
        let mask = plan.build_multiplier(|kx, ky| {
            let r = kx.unsigned_abs() as f64 / hw + ky.unsigned_abs() as f64 / hh;
            Complex32::new(if r <= k as f64 { norm } else { 0.0 }, 0.0)
        });
        Ok(Self { plan, mask })
    }

    fn apply(&self, field: &mut [Complex32], scratch: &mut Scratch) -> Result<()> {
        self.plan.apply(field, &self.mask, scratch)
    }
}

/// Allocation-free double phase encoding of one colour channel `[H, W]` for real-time sessions: everything
/// it needs (blur buffer, BL-DPM plan, mask and scratch) is allocated once in [`ChannelEncoder::new`].
///
/// Encoding is two passes around the global normaliser, which couples the colours (Eq. 7,
/// `docs/CONVENTIONS.md` §5.3): [`ChannelEncoder::analyse`] on each channel, [`normaliser`] over the three
/// [`ChannelStats`], then [`ChannelEncoder::encode`] on each channel. The result equals
/// [`double_phase_encode`]'s (same row kernels).
#[derive(Debug)]
pub struct ChannelEncoder {
    height: usize,
    width: usize,
    method: DoublePhaseMethod,
    kernel: Vec<f32>,
    tmp: Vec<Complex32>,
    band: Option<(BandLimit, Scratch)>,
    /// Each row's statistics of [`ChannelEncoder::analyse_planes`] (`H` entries), merged in row order.
    row_stats: Vec<ChannelStats>,
    /// The row kernels' instruction set.
    isa: Isa,
}

impl ChannelEncoder {
    /// This encoder on the row kernels of `isa`: the same codes at every level (one portable body compiled
    /// per level), a lower one to compare their speeds or to run what a session's
    /// [`crate::cnn::CnnOptions::isa`] allows.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`isa`) for a level this CPU does not have.
    pub fn with_isa(mut self, isa: Isa) -> Result<Self> {
        self.isa = crate::cnn::available(isa)?;
        Ok(self)
    }

    /// Prepares the encoder for `[height, width]` channels, on this CPU's best row kernels ([`Isa::detect`];
    /// [`ChannelEncoder::with_isa`] lowers them).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for invalid method parameters or an empty size.
    pub fn new(height: usize, width: usize, method: DoublePhaseMethod) -> Result<Self> {
        method.validate()?;
        let isa = Isa::detect();
        if height == 0 || width == 0 {
            return Err(invalid(
                "channel size",
                format!("height and width must be ≥ 1, got {height}×{width}"),
            ));
        }
        let band = match method {
            DoublePhaseMethod::BandLimited { k } => {
                let b = BandLimit::new(height, width, k)?;
                let s = b.plan.scratch();
                Some((b, s))
            }
            _ => None,
        };
        let tmp = match method {
            DoublePhaseMethod::AntiAliased { .. } => vec![Complex32::default(); height * width],
            _ => Vec::new(),
        };
        Ok(Self {
            height,
            width,
            method,
            kernel: method.kernel(),
            tmp,
            band,
            row_stats: vec![ChannelStats::default(); height],
            isa,
        })
    }

    /// The encoding method.
    pub fn method(&self) -> DoublePhaseMethod {
        self.method
    }

    fn check(&self, what: &str, len: usize) -> Result<()> {
        if len != self.height * self.width {
            return Err(HoloError::ShapeMismatch {
                what: format!("{what} vs the encoder's [H, W]"),
                expected: vec![self.height, self.width],
                got: vec![len],
            });
        }
        Ok(())
    }

    /// Pass 1: applies the method's pre-filter to `field` (row-major `[H, W]`) in place and writes
    /// `arg H` (radians) into `phase`; returns the channel's statistics for [`normaliser`].
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for wrong lengths.
    pub fn analyse(&mut self, field: &mut [Complex32], phase: &mut [f32]) -> Result<ChannelStats> {
        self.check("field", field.len())?;
        self.check("phase", phase.len())?;
        match (&self.method, &mut self.band) {
            (DoublePhaseMethod::AntiAliased { .. }, _) => {
                blur_separable(field, self.height, self.width, &self.kernel, &mut self.tmp)
            }
            (DoublePhaseMethod::BandLimited { .. }, Some((b, scratch))) => {
                b.apply(field, scratch)?
            }
            _ => {}
        }
        let w = self.width;
        let mut stats = ChannelStats::default();
        for (row, out) in field.chunks_exact(w).zip(phase.chunks_exact_mut(w)) {
            stats = stats.merge(analyse_row(row, out, self.isa)?);
        }
        Ok(stats)
    }

    /// Pass 1 on a field still held as two real planes (the pre-filter's output): `Re H` in the first half of
    /// `field`'s memory (`H·W` values) and `Im H` in `phase`. Writes `arg H` into `phase` and returns the
    /// statistics of [`interleave_in_place`] on the whole field then [`ChannelEncoder::analyse`], bit for bit,
    /// with the layout pass 2 must read:
    /// - the plain method: [`PassOneLayout::Magnitudes`]. Each row's `|H|` goes to the second half of the
    ///   field's memory ([`kernel::analyse_planes_row`]) and `Re H` stays: no interleaved field is written
    ///   (at 1080p 16.6 MB less per colour, written here and read back by pass 2). Chunks of
    ///   [`ANALYSE_ROWS`] rows on the current rayon pool's threads with `pool` (the pipeline's optics pool),
    ///   else one after the other; each row's statistics are kept and merged in row order afterwards, as
    ///   `analyse` merges them;
    /// - a filtering method: [`PassOneLayout::Field`] (the field is interleaved and filtered, as `analyse`).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for wrong lengths.
    pub(crate) fn analyse_planes(
        &mut self,
        field: &mut [Complex32],
        phase: &mut [f32],
        pool: bool,
    ) -> Result<(ChannelStats, PassOneLayout)> {
        self.check("field", field.len())?;
        self.check("phase", phase.len())?;
        let (h, w, isa) = (self.height, self.width, self.isa);
        if !matches!(self.method, DoublePhaseMethod::Plain) {
            interleave_in_place(bytemuck::cast_slice_mut(field), phase, 0..h * w);
            return Ok((self.analyse(field, phase)?, PassOneLayout::Field));
        }
        let (re, abs) = bytemuck::cast_slice_mut::<Complex32, f32>(field).split_at_mut(h * w);
        let chunk = ANALYSE_ROWS * w;
        type Chunk<'a> = (
            ((&'a [f32], &'a mut [f32]), &'a mut [f32]),
            &'a mut [ChannelStats],
        );
        let rows = |(((re, phase), abs), stats): Chunk<'_>| -> Result<()> {
            let rows = re
                .chunks_exact(w)
                .zip(phase.chunks_exact_mut(w))
                .zip(abs.chunks_exact_mut(w));
            for (((re, arg), abs), s) in rows.zip(stats) {
                let (max_amplitude_sq, phase_sum) =
                    kernel::analyse_planes_row(re, arg, abs, isa).map_err(kernel_err)?;
                *s = ChannelStats {
                    max_amplitude_sq,
                    phase_sum,
                };
            }
            Ok(())
        };
        let stats = &mut self.row_stats[..];
        if pool {
            re.par_chunks(chunk)
                .zip(phase.par_chunks_mut(chunk))
                .zip(abs.par_chunks_mut(chunk))
                .zip(stats.par_chunks_mut(ANALYSE_ROWS))
                .try_for_each(rows)?;
        } else {
            re.chunks(chunk)
                .zip(phase.chunks_mut(chunk))
                .zip(abs.chunks_mut(chunk))
                .zip(stats.chunks_mut(ANALYSE_ROWS))
                .try_for_each(rows)?;
        }
        let merged = self
            .row_stats
            .iter()
            .fold(ChannelStats::default(), |s, r| s.merge(*r));
        Ok((merged, PassOneLayout::Magnitudes))
    }

    /// Pass 2: turns `phase` (from [`ChannelEncoder::analyse`] on the same `field`) into the wrapped double
    /// phase pattern in `[0, 2π)` (Eq. 7) with the channel's `mean_phase` and the global `amplitude_scale`
    /// from [`normaliser`], and writes the 8-bit codes of the linear look-up table into `codes`.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for wrong lengths; [`HoloError::InvalidParameter`] for a
    /// non-positive scale.
    pub fn encode(
        &self,
        field: &[Complex32],
        phase: &mut [f32],
        codes: &mut [u8],
        mean_phase: f32,
        amplitude_scale: f32,
    ) -> Result<()> {
        let params = (mean_phase, amplitude_scale);
        let layout = PassOneLayout::Field;
        self.encode_on(field, layout, (None, phase), codes, params, false)
    }

    /// [`ChannelEncoder::encode`] with `(mean_phase, amplitude_scale)`, its chunks of rows on the current
    /// rayon pool's threads with `pool` (the pipeline's optics pool), else one after the other: bit for bit
    /// the same (each row's values depend on the row alone). `layout` says where pass 1 left each pixel's
    /// `|H|` in `field`'s memory ([`ChannelEncoder::analyse_planes`]; [`PassOneLayout::Field`] after
    /// `analyse`): the same values either way. With `(Some(arg), phase)`, pass 1's `arg H` is read from
    /// `arg` (left as it is) and the pattern written into `phase`: each row copied there just before it is
    /// encoded, while it is in cache (a frame's output plane, instead of a copy of the encoded plane
    /// afterwards); with `(None, phase)`, `phase` holds `arg H` and is encoded in place.
    ///
    /// Errors: as `encode` (`arg` checked as `phase`).
    pub(crate) fn encode_on(
        &self,
        field: &[Complex32],
        layout: PassOneLayout,
        (arg, phase): (Option<&[f32]>, &mut [f32]),
        codes: &mut [u8],
        (mean_phase, amplitude_scale): (f32, f32),
        pool: bool,
    ) -> Result<()> {
        self.check("field", field.len())?;
        self.check("phase", phase.len())?;
        self.check("codes", codes.len())?;
        if let Some(arg) = arg {
            self.check("arg", arg.len())?;
        }
        if !(amplitude_scale > 0.0 && amplitude_scale.is_finite()) {
            return Err(invalid(
                "amplitude_scale",
                format!("must be > 0, got {amplitude_scale}"),
            ));
        }
        let (w, inv_a, isa) = (self.width, 1.0 / amplitude_scale, self.isa);
        let (source, k) = (layout.source(field), layout.values_per_pixel());
        let chunk = ANALYSE_ROWS * w;
        type Chunk<'a> = (usize, ((&'a [f32], &'a mut [f32]), &'a mut [u8]));
        let rows = |(i, ((source, phase), codes)): Chunk<'_>| -> Result<()> {
            let rows = source
                .chunks_exact(k * w)
                .zip(phase.chunks_exact_mut(w))
                .zip(codes.chunks_exact_mut(w));
            for (j, ((row, out), c)) in rows.enumerate() {
                let y = i * ANALYSE_ROWS + j;
                if let Some(arg) = arg {
                    out.copy_from_slice(&arg[y * w..(y + 1) * w]);
                }
                encode_row(row, layout, out, Some(c), y, mean_phase, inv_a, isa)?;
            }
            Ok(())
        };
        if pool {
            source
                .par_chunks(k * chunk)
                .zip(phase.par_chunks_mut(chunk))
                .zip(codes.par_chunks_mut(chunk))
                .enumerate()
                .try_for_each(rows)
        } else {
            source
                .chunks(k * chunk)
                .zip(phase.chunks_mut(chunk))
                .zip(codes.chunks_mut(chunk))
                .enumerate()
                .try_for_each(rows)
        }
    }
}

impl DoublePhaseMethod {
    /// The Gaussian kernel of AA-DPM (empty for the other methods).
    pub(crate) fn kernel(&self) -> Vec<f32> {
        match *self {
            Self::AntiAliased {
                sigma_px,
                kernel_size,
            } => gaussian_kernel(sigma_px, kernel_size),
            _ => Vec::new(),
        }
    }
}

/// Normalised 1D Gaussian kernel of odd length `size` and standard deviation `sigma` (pixels).
fn gaussian_kernel(sigma: f32, size: usize) -> Vec<f32> {
    let r = (size / 2) as i64;
    let k: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f32 = k.iter().sum();
    k.into_iter().map(|v| v / s).collect()
}

/// Separable convolution of a `[h, w]` complex image with `kernel` along both axes, edges clamped; `tmp` is
/// resized to `h·w` (no allocation once it has that capacity).
fn blur_separable(
    data: &mut [Complex32],
    h: usize,
    w: usize,
    kernel: &[f32],
    tmp: &mut Vec<Complex32>,
) {
    let r = (kernel.len() / 2) as i64;
    tmp.resize(h * w, Complex32::default());
    for y in 0..h {
        for x in 0..w {
            let mut acc = Complex32::default();
            for (j, &kv) in kernel.iter().enumerate() {
                let xx = (x as i64 + j as i64 - r).clamp(0, w as i64 - 1) as usize;
                acc += data[y * w + xx] * kv;
            }
            tmp[y * w + x] = acc;
        }
    }
    for y in 0..h {
        for x in 0..w {
            let mut acc = Complex32::default();
            for (j, &kv) in kernel.iter().enumerate() {
                let yy = (y as i64 + j as i64 - r).clamp(0, h as i64 - 1) as usize;
                acc += tmp[yy * w + x] * kv;
            }
            data[y * w + x] = acc;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encoding::LinearLut;

    #[test]
    fn checkerboard_pairs_sum_to_the_encoded_complex_value() {
        // For each pixel pair the two phasors average to Ã·e^{i(φ − mean)} exactly (the double phase identity).
        let field = Array3::from_shape_fn((3, 4, 6), |(c, y, x)| {
            Complex32::from_polar(
                0.2 + 0.1 * (x + y + c) as f32,
                0.3 * x as f32 - 0.2 * y as f32,
            )
        });
        let dp = double_phase_encode(field.view(), &DoublePhaseMethod::Plain).unwrap();
        for c in 0..3 {
            for y in 0..4 {
                for x in 0..6 {
                    let v = field[[c, y, x]];
                    let theta = (v.norm() / dp.amplitude_scale).acos();
                    let phi = v.arg() - dp.mean_phase[c];
                    let plus = Complex32::from_polar(1.0, phi + theta);
                    let minus = Complex32::from_polar(1.0, phi - theta);
                    let got = Complex32::from_polar(1.0, dp.phase[[c, y, x]]);
                    let expected = if (x + y) % 2 == 0 { plus } else { minus };
                    assert!((got - expected).norm() < 1e-4);
                    let avg = (plus + minus) * 0.5;
                    let target = Complex32::from_polar(v.norm() / dp.amplitude_scale, phi);
                    assert!((avg - target).norm() < 1e-5);
                }
            }
        }
    }

    #[test]
    fn global_normaliser_is_the_max_over_all_colours() {
        let mut field = Array3::from_elem((3, 4, 4), Complex32::new(0.5, 0.0));
        field[[2, 1, 1]] = Complex32::new(0.0, 2.0);
        let dp = double_phase_encode(field.view(), &DoublePhaseMethod::Plain).unwrap();
        assert!((dp.amplitude_scale - 2.0).abs() < 1e-6);
    }

    #[test]
    fn bad_inputs_are_rejected() {
        let zero = Array3::<Complex32>::zeros((3, 4, 4));
        assert!(matches!(
            double_phase_encode(zero.view(), &DoublePhaseMethod::Plain),
            Err(HoloError::InvalidData(_))
        ));
        let two = Array3::from_elem((2, 4, 4), Complex32::new(1.0, 0.0));
        assert!(matches!(
            double_phase_encode(two.view(), &DoublePhaseMethod::Plain),
            Err(HoloError::ShapeMismatch { .. })
        ));
        let mut nan = Array3::from_elem((3, 4, 4), Complex32::new(1.0, 0.0));
        nan[[0, 0, 0]] = Complex32::new(f32::NAN, 0.0);
        assert!(double_phase_encode(nan.view(), &DoublePhaseMethod::Plain).is_err());
        let ones = Array3::from_elem((3, 4, 4), Complex32::new(1.0, 0.0));
        for m in [
            DoublePhaseMethod::AntiAliased {
                sigma_px: 0.0,
                kernel_size: 5,
            },
            DoublePhaseMethod::AntiAliased {
                sigma_px: 1.0,
                kernel_size: 4,
            },
            DoublePhaseMethod::BandLimited { k: 1.5 },
        ] {
            assert!(matches!(
                double_phase_encode(ones.view(), &m),
                Err(HoloError::InvalidParameter { .. })
            ));
        }
    }

    #[test]
    fn channel_encoder_matches_double_phase_encode_for_every_method() {
        let (h, w) = (12, 10);
        let field = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            let t = (c * 131 + y * 17 + x * 7) as f32;
            Complex32::from_polar(0.1 + (t * 0.37).sin().abs(), (t * 0.11).cos() * 3.0)
        });
        let methods = [
            DoublePhaseMethod::Plain,
            DoublePhaseMethod::default(),
            DoublePhaseMethod::BandLimited { k: 0.6 },
        ];
        for method in methods {
            let reference = double_phase_encode(field.view(), &method).unwrap();
            let mut encoders: Vec<_> = (0..3)
                .map(|_| ChannelEncoder::new(h, w, method).unwrap())
                .collect();
            let mut fields: Vec<Vec<Complex32>> = (0..3)
                .map(|c| {
                    field
                        .index_axis(ndarray::Axis(0), c)
                        .iter()
                        .copied()
                        .collect()
                })
                .collect();
            let mut phase = vec![vec![0.0f32; h * w]; 3];
            let mut codes = vec![vec![0u8; h * w]; 3];
            let stats: Vec<_> = (0..3)
                .map(|c| encoders[c].analyse(&mut fields[c], &mut phase[c]).unwrap())
                .collect();
            let (a, mean) = normaliser(&stats, h * w).unwrap();
            assert!(
                (a - reference.amplitude_scale).abs() <= 1e-6 * a,
                "{method:?}"
            );
            for c in 0..3 {
                assert!((mean[c] - reference.mean_phase[c]).abs() < 1e-6);
                encoders[c]
                    .encode(&fields[c], &mut phase[c], &mut codes[c], mean[c], a)
                    .unwrap();
                let want = reference.phase.index_axis(ndarray::Axis(0), c);
                for (i, (got, want)) in phase[c].iter().zip(want.iter()).enumerate() {
                    assert!((got - want).abs() < 1e-5, "{method:?} c{c} pixel {i}");
                    assert_eq!(codes[c][i], crate::encoding::LinearLut.code(*got));
                }
            }
        }
    }

    /// Pass 2 as the SDK computed it before the row kernels (libm `atan2f` and `acosf`, the scalar wrap).
    fn libm_phase(v: Complex32, y: usize, x: usize, mean: f32, inv_a: f32) -> f32 {
        let theta = (v.norm_sqr().sqrt() * inv_a).min(1.0).acos();
        let p = v.im.atan2(v.re) - mean;
        super::super::wrap_phase(if (x + y) % 2 == 1 {
            p - theta
        } else {
            p + theta
        })
    }

    #[test]
    fn the_row_kernels_match_libm_within_their_bound_and_one_code_step() {
        // A speckle-like field (uniform phase, amplitude in [0, 1)), odd width so that rows end in a tail.
        let (h, w) = (96, 203);
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let field = Array3::from_shape_simple_fn((3, h, w), || {
            let a = next();
            Complex32::from_polar(a, (next() - 0.5) * TAU)
        });
        let dp = double_phase_encode(field.view(), &DoublePhaseMethod::Plain).unwrap();
        let inv_a = 1.0 / dp.amplitude_scale;
        let (mut worst, mut differ, mut pixels) = (0.0f32, 0usize, 0usize);
        for c in 0..3 {
            let libm_mean = field
                .index_axis(ndarray::Axis(0), c)
                .iter()
                .map(|v| v.im.atan2(v.re) as f64)
                .sum::<f64>()
                / (h * w) as f64;
            assert!(
                (dp.mean_phase[c] as f64 - libm_mean).abs() < 1e-6,
                "mean {c}"
            );
            for y in 0..h {
                for x in 0..w {
                    let want = libm_phase(field[[c, y, x]], y, x, dp.mean_phase[c], inv_a);
                    let got = dp.phase[[c, y, x]];
                    let d = (got - want).abs();
                    let d = d.min(TAU - d);
                    worst = worst.max(d);
                    assert!(
                        d <= kernel::PHASE_MAX_ERROR,
                        "c{c} y{y} x{x}: {got} vs {want}"
                    );
                    let (a, b) = (LinearLut.code(got), LinearLut.code(want));
                    let step = a.wrapping_sub(b).min(b.wrapping_sub(a));
                    assert!(step <= 1, "c{c} y{y} x{x}: code {a} vs {b}");
                    differ += (step != 0) as usize;
                    pixels += 1;
                }
            }
        }
        println!(
            "row kernels vs libm: worst phase {worst:e} rad, codes differing {differ} of {pixels}"
        );
        // 2·1.2e-6 rad of the 0.0245 rad step: about 1e-4 of the pixels could differ; allow 1e-3.
        assert!(
            differ * 1000 <= pixels,
            "{differ} of {pixels} codes differ by one step"
        );
    }

    #[test]
    fn gaussian_kernel_is_normalised_and_symmetric() {
        let k = gaussian_kernel(1.0, 7);
        assert!((k.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert!((k[0] - k[6]).abs() < 1e-9 && k[3] > k[2]);
    }

    /// The in-place interleave against the definition, as one range and as ranges from the last to the
    /// first (chunks of rows), on sizes under one block, whole blocks and partial ones, with distinct values
    /// everywhere (a value read after it was overwritten shows).
    #[test]
    fn interleave_in_place_equals_the_definition() {
        for n in (0..=40).chain([63, 64, 65, 1920 * 3 + 7]) {
            let first: Vec<f32> = (0..n).map(|i| i as f32 + 0.25).collect();
            let second: Vec<f32> = (0..n).map(|i| -(i as f32) - 0.5).collect();
            let want: Vec<f32> = first
                .iter()
                .zip(&second)
                .flat_map(|(a, b)| [*a, *b])
                .collect();
            for chunk in [n.max(1), 5, 16, 17, 1920] {
                let mut buf = vec![f32::NAN; 2 * n];
                buf[..n].copy_from_slice(&first);
                let starts: Vec<usize> = (0..n).step_by(chunk).collect();
                for &p0 in starts.iter().rev() {
                    interleave_in_place(&mut buf, &second, p0..(p0 + chunk).min(n));
                }
                assert_eq!(buf, want, "n {n}, chunks of {chunk}");
            }
        }
    }

    /// Pass 1 on the two planes gives the phases and statistics of the interleave then `analyse`, bit for bit,
    /// for every method, on sizes with a partial last chunk: the plain method leaves `Re H` and `|H|` (no
    /// interleaved field), the filtering methods the filtered field; pass 2 from either layout gives the same
    /// pattern and codes.
    #[test]
    fn analyse_planes_equals_interleave_then_analyse() {
        let methods = [
            DoublePhaseMethod::Plain,
            DoublePhaseMethod::AntiAliased {
                sigma_px: 0.8,
                kernel_size: 3,
            },
            DoublePhaseMethod::BandLimited { k: 0.7 },
        ];
        for (h, w) in [(1, 1), (7, 5), (19, 33), (64, 40)] {
            let n = h * w;
            let re: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin()).collect();
            let im: Vec<f32> = (0..n).map(|i| (i as f32 * 0.11).cos() - 0.3).collect();
            for method in methods {
                let mut enc = ChannelEncoder::new(h, w, method).unwrap();
                let mut want_field: Vec<Complex32> = re
                    .iter()
                    .zip(&im)
                    .map(|(&a, &b)| Complex32::new(a, b))
                    .collect();
                let mut want_phase = vec![0.0f32; n];
                let want = enc.analyse(&mut want_field, &mut want_phase).unwrap();

                // Serial, then in parallel on pools of 1 to 3 threads.
                for threads in [0, 1, 2, 3] {
                    let mut field = vec![Complex32::new(f32::NAN, f32::NAN); n];
                    bytemuck::cast_slice_mut::<Complex32, f32>(&mut field)[..n]
                        .copy_from_slice(&re);
                    let mut phase = im.clone();
                    let (got, layout) = match threads {
                        0 => enc.analyse_planes(&mut field, &mut phase, false).unwrap(),
                        t => rayon::ThreadPoolBuilder::new()
                            .num_threads(t)
                            .build()
                            .unwrap()
                            .install(|| enc.analyse_planes(&mut field, &mut phase, true))
                            .unwrap(),
                    };
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    let what = format!("{h}×{w} {method:?} ×{threads}");
                    assert_eq!(
                        got.max_amplitude_sq.to_bits(),
                        want.max_amplitude_sq.to_bits(),
                        "{what}"
                    );
                    assert_eq!(got.phase_sum.to_bits(), want.phase_sum.to_bits(), "{what}");
                    assert_eq!(bits(&phase), bits(&want_phase), "{what}");
                    let flat: &[f32] = bytemuck::cast_slice(&field);
                    if method == DoublePhaseMethod::Plain {
                        // Re H kept, |H| beside it: no interleaved field.
                        assert_eq!(layout, PassOneLayout::Magnitudes, "{what}");
                        assert_eq!(bits(&flat[..n]), bits(&re), "{what}");
                        let mag: Vec<f32> = re
                            .iter()
                            .zip(&im)
                            .map(|(r, i)| (r * r + i * i).sqrt())
                            .collect();
                        assert_eq!(bits(&flat[n..]), bits(&mag), "{what}");
                    } else {
                        assert_eq!(layout, PassOneLayout::Field, "{what}");
                        assert_eq!(
                            bits(flat),
                            bits(bytemuck::cast_slice(&want_field)),
                            "{what}"
                        );
                    }
                    // Pass 2 from either layout: the same pattern and codes.
                    let (a, mean) = normaliser(&[got; 3], n).unwrap();
                    let (mut p1, mut c1) = (want_phase.clone(), vec![0u8; n]);
                    let io = (None, &mut p1[..]);
                    let field_layout = PassOneLayout::Field;
                    enc.encode_on(&want_field, field_layout, io, &mut c1, (mean[0], a), false)
                        .unwrap();
                    let (mut p2, mut c2) = (phase.clone(), vec![1u8; n]);
                    let io = (None, &mut p2[..]);
                    enc.encode_on(&field, layout, io, &mut c2, (mean[0], a), false)
                        .unwrap();
                    assert_eq!(bits(&p1), bits(&p2), "{what}: pass 2");
                    assert_eq!(c1, c2, "{what}: pass 2 codes");
                }
            }
        }
    }

    /// Pass 2 with its rows on a pool's threads is pass 2, bit for bit (phase and codes), in place and out of
    /// place (pass 1's phase read from its own plane), on odd sizes and pools of 1 to 3 threads; a bad scale
    /// and a short `arg` are refused.
    #[test]
    fn encode_on_the_pool_equals_encode() {
        for (h, w) in [(1, 1), (9, 7), (37, 20), (64, 33)] {
            let n = h * w;
            let field: Vec<Complex32> = (0..n)
                .map(|i| Complex32::from_polar(0.2 + (i as f32 * 0.07).sin().abs(), i as f32 * 0.3))
                .collect();
            let mut enc = ChannelEncoder::new(h, w, DoublePhaseMethod::Plain).unwrap();
            let (mut f, mut arg) = (field.clone(), vec![0.0f32; n]);
            let stats = enc.analyse(&mut f, &mut arg).unwrap();
            let (a, mean) = normaliser(&[stats; 3], n).unwrap();
            let (mut want_phase, mut want_codes) = (arg.clone(), vec![0u8; n]);
            enc.encode(&f, &mut want_phase, &mut want_codes, mean[0], a)
                .unwrap();
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let (mut phase, mut codes) = (arg.clone(), vec![0u8; n]);
                let io = (None, &mut phase[..]);
                pool.install(|| {
                    enc.encode_on(&f, PassOneLayout::Field, io, &mut codes, (mean[0], a), true)
                })
                .unwrap();
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&phase), bits(&want_phase), "{h}×{w} ×{threads}");
                assert_eq!(codes, want_codes, "{h}×{w} ×{threads}");
                // Out of place: `arg` kept, every row of the output written.
                let (mut out, mut codes) = (vec![f32::NAN; n], vec![0u8; n]);
                let io = (Some(&arg[..]), &mut out[..]);
                pool.install(|| {
                    enc.encode_on(&f, PassOneLayout::Field, io, &mut codes, (mean[0], a), true)
                })
                .unwrap();
                assert_eq!(
                    bits(&out),
                    bits(&want_phase),
                    "{h}×{w} ×{threads} out of place"
                );
                assert_eq!(codes, want_codes, "{h}×{w} ×{threads} out of place");
                let io = (None, &mut phase[..]);
                assert!(enc
                    .encode_on(
                        &f,
                        PassOneLayout::Field,
                        io,
                        &mut codes,
                        (mean[0], 0.0),
                        true
                    )
                    .is_err());
                let io = (Some(&arg[..n - 1]), &mut out[..]);
                assert!(enc
                    .encode_on(&f, PassOneLayout::Field, io, &mut codes, (mean[0], a), true)
                    .is_err());
            }
            assert!(
                n == 1 || want_codes.iter().any(|&c| c != want_codes[0]),
                "{h}×{w}"
            );
        }
    }
}
