//! One colour channel's optics ([`ColourState`]): on its worker thread, heads → field, the offset propagation
//! (Eq. 6, carrier removed) and the pre-filter's planes (or, without a pre-filter, pass 1 of the double phase
//! encoding); the buffers the session's encoding stage then runs over its pool (pass 1 on the pre-filter's
//! output, pass 2 of Eq. 7 and the look-up table). Allocation-free after the first frame.

use std::sync::Arc;

use ndarray::Axis;
use num_complex::Complex32;
use tensorholo_kernels::phasor::{phasors, phasors_in_place};
use tensorholo_kernels::Isa;

use super::correction::PupilCorrection;
use super::frame::Heads;
use crate::encoding::{ChannelEncoder, ChannelStats, PassOneLayout};
use crate::error::{HoloError, Result};
use crate::optics::{EvenMultiplier, Scratch, SpectralPlan};

/// What a colour worker does next (see [`ColourState::run`]).
#[derive(Debug, Clone)]
pub(super) enum Task {
    /// Heads → field, offset propagation, then the pre-filter input or pass 1 of the encoding. The heads
    /// are read from `heads` (the session's `[3, H, W]` arrays, shared read-only with the other colours:
    /// no copy into the field's memory, 50 MB at 1080p) or, with `None`, from [`ColourState::planes`]
    /// (where the CNN wrote them).
    Midpoint {
        prefilter: bool,
        heads: Option<Arc<Heads>>,
    },
}

/// Two real `[H, W]` planes of one colour, read-only.
pub(super) type PlanePair<'a> = (&'a [f32], &'a [f32]);
/// Two real `[H, W]` planes of one colour, to write.
pub(super) type PlanePairMut<'a> = (&'a mut [f32], &'a mut [f32]);

/// Everything one colour channel reuses between frames.
#[derive(Debug)]
pub(super) struct ColourState {
    /// The complex field `[H, W]`. Its memory also holds two real planes (`[H, W]` each) while the session
    /// writes them: the midpoint amplitude head before [`Task::Midpoint`] in a session without full outputs
    /// (the phase head in `phase`, [`ColourState::planes`]); [`Task::Midpoint`] turns the heads into the field
    /// in place (no buffer of their own: 50 MB less at 1080p). With a pre-filter, [`Task::Midpoint`] leaves
    /// the pre-filter's input `Im H` in the second half (`Re H` in `phase`), the pre-filter writes its output
    /// `Re H'` into the first half ([`ColourState::prefilter_io`]), and with the plain method pass 1 leaves
    /// `Re H'` and `|H'|` here (`layout`) instead of interleaving them: no buffer of the pre-filter's own
    /// (its input and output were 50 + 50 MB at 1080p).
    pub(super) field: Vec<Complex32>,
    pub(super) plan: SpectralPlan,
    /// Offset transfer function with the carrier removed (Eq. 6), as its even quarter (a function of the
    /// frequency radius: a quarter of the memory, [`EvenMultiplier`]); `None` at 0 m.
    pub(super) transfer: Option<EvenMultiplier>,
    /// The viewer's aberration correction ([`PupilCorrection`], shared by the colours), multiplied onto the
    /// spectrum after `transfer`; `None`: no correction.
    pub(super) correction: Option<Arc<PupilCorrection>>,
    pub(super) scratch: Scratch,
    pub(super) encoder: ChannelEncoder,
    /// A real `[H, W]` plane: the midpoint phase head (a session without full outputs), then with a
    /// pre-filter its input `Re H`, without one `arg H` from pass 1 and the pattern of a session without full
    /// outputs.
    pub(super) phase: Vec<f32>,
    pub(super) stats: ChannelStats,
    /// Where pass 1 left each pixel's `|H|` for pass 2 (the interleaved field, or with a pre-filter and the
    /// plain method its own plane in the field's memory: [`ChannelEncoder::analyse_planes`]).
    pub(super) layout: PassOneLayout,
    /// This colour (0 = R) and the session's `(height, width)`.
    pub(super) colour: usize,
    pub(super) size: (usize, usize),
    /// The instruction set of the heads-to-phasor rows ([`tensorholo_kernels::phasor`]).
    pub(super) isa: Isa,
}

impl ColourState {
    pub(super) fn run(&mut self, task: Task) -> Result<()> {
        match task {
            Task::Midpoint { prefilter, heads } => {
                let finite = if self.transfer.is_some() || self.correction.is_some() {
                    self.propagate(heads.as_deref(), prefilter)?
                } else {
                    let finite = match &heads {
                        Some(heads) => self.shared_heads_to_field(heads)?,
                        None => self.heads_to_field()?,
                    };
                    if prefilter {
                        // Pre-filter input (docs/CONVENTIONS.md §7.2, format 2): Re H and Im H, two planes.
                        split_in_place(&mut self.field, &mut self.phase);
                    }
                    finite
                };
                if !finite {
                    return Err(HoloError::InvalidData(
                        "midpoint heads hold NaN or infinite values".into(),
                    ));
                }
                if !prefilter {
                    self.stats = self.encoder.analyse(&mut self.field, &mut self.phase)?;
                    self.layout = PassOneLayout::Field;
                }
                Ok(())
            }
        }
    }

    /// The two real planes `(amplitude, phase)` of `H·W` values each the CNN writes a frame's heads into in
    /// a session without full outputs: the first half of the field's memory and `phase` (which
    /// [`Task::Midpoint`] reads in place: no plane copied aside).
    pub(super) fn planes(&mut self) -> PlanePairMut<'_> {
        let (amplitude, _) = field_planes(&mut self.field);
        (amplitude, &mut self.phase[..])
    }

    /// The pre-filter's input `(Re H, Im H)` where [`Task::Midpoint`] left it (`phase` and the second half of
    /// the field's memory), beside the plane the pre-filter writes its output `Re H'` into: the first half of
    /// the field's memory (so that the encoding's pass 1 reads it there; the session gives `Im H'` a plane of
    /// the frame's phase output, idle until pass 2 writes the pattern there).
    pub(super) fn prefilter_io(&mut self) -> (PlanePair<'_>, &mut [f32]) {
        let (re_out, im) = field_planes(&mut self.field);
        ((&self.phase[..], &*im), re_out)
    }

    /// Turns the midpoint heads of [`ColourState::planes`] (amplitude in the field's memory, phase in `phase`)
    /// into the field in place, on the vectorised rows ([`tensorholo_kernels::phasor::phasors_in_place`], the
    /// same values as [`crate::model::contract::head_to_phasor`]). Returns whether every head was finite.
    ///
    /// Errors: [`HoloError::Internal`] if the kernel refuses (lengths equal by construction, ISA checked).
    fn heads_to_field(&mut self) -> Result<bool> {
        let flat = bytemuck::cast_slice_mut::<Complex32, f32>(&mut self.field);
        phasors_in_place(flat, &self.phase, self.isa)
            .map_err(|e| HoloError::Internal(format!("phasor rows: {e}")))
    }

    /// Heads → field and the offset propagation (Eq. 6, carrier removed) with both ends fused into the row
    /// transforms ([`SpectralPlan::apply_even_rows`]): each chunk of rows is made from the heads just before
    /// its forward row transforms and, with `prefilter`, split into the pre-filter's input planes
    /// `(Re H, Im H)` (docs/CONVENTIONS.md §7.2, format 2) just after its inverse ones, while the rows are in
    /// cache: two passes over the field fewer, bit-identical to the passes apart (tested); with `prefilter`
    /// the last row transforms run on a copy of each chunk (`keep = false`), so the field is left with the
    /// column pass's values and not written a third time: `Re H` goes to `phase`, `Im H` to the second half of
    /// the field's memory, into rows already spent (the chunks run last first, and pixel `p`'s value lands at
    /// `n + p ≥ 2·p`, in row `≥` the chunk's first; a padded plan splits the whole field after). The heads are
    /// this colour's planes of `heads` (the session's `[3, H, W]` arrays, standard layout) or, with `None`,
    /// [`ColourState::planes`] ([`phasor_rows`] makes the chunks in place). Returns whether every head was
    /// finite.
    ///
    /// Errors: [`HoloError::Internal`] for shared heads that are not contiguous, without a transfer function
    /// or, with `prefilter`, without room for the pre-filter's input, or if the phasor kernel refuses.
    fn propagate(&mut self, heads: Option<&Heads>, prefilter: bool) -> Result<bool> {
        let shared = match heads {
            Some(heads) => Some(colour_planes(heads, self.colour)?),
            None => None,
        };
        let n = self.field.len();
        // `before` reads the phase head there (a lean session), `after` writes `Re H` there: never at once.
        let phase = std::cell::RefCell::new(&mut self.phase);
        let (width, isa) = (self.size.1, self.isa);
        let (mut finite, mut failure, mut split_after) = (true, None, false);
        let before = |field: &mut [Complex32], rows: std::ops::Range<usize>| {
            let made = match shared {
                Some((amplitude, phase)) => {
                    let px = rows.start * width..rows.end * width;
                    let out = bytemuck::cast_slice_mut::<Complex32, f32>(&mut field[px.clone()]);
                    phasors(&amplitude[px.clone()], &phase[px], out, isa)
                        .map_err(|e| HoloError::Internal(format!("phasor rows: {e}")))
                }
                None => phasor_rows(field, &phase.borrow(), rows, width, isa),
            };
            match made {
                Ok(f) => finite &= f,
                Err(e) => {
                    failure.get_or_insert(e);
                }
            }
        };
        let after = |chunk: &[Complex32], rows: std::ops::Range<usize>, spent: &mut [Complex32]| {
            if !prefilter {
                return;
            }
            let px = rows.start * width..rows.end * width;
            // `Im H` of pixel `p` at value `n + p` of the field's memory, `spent` starting at value `2·p0`.
            let at = n - px.start;
            let spent = bytemuck::cast_slice_mut::<Complex32, f32>(spent);
            match spent.get_mut(at..at + px.len()) {
                Some(im) => split_planes(chunk, &mut phase.borrow_mut()[px], im),
                None => split_after = true,
            }
        };
        // With the pre-filter the field is read only in `after` (the pre-filter's output replaces it).
        let keep = !prefilter;
        match (&self.correction, &self.transfer) {
            (Some(correction), transfer) => self.plan.apply_rows_then(
                &mut self.field,
                transfer.as_ref(),
                correction.kernel(self.colour),
                &mut self.scratch,
                before,
                keep,
                after,
            )?,
            (None, Some(transfer)) => self.plan.apply_even_rows(
                &mut self.field,
                transfer,
                &mut self.scratch,
                before,
                keep,
                after,
            )?,
            (None, None) => {
                return Err(HoloError::Internal(
                    "no transfer function or correction to apply".into(),
                ))
            }
        }
        if split_after {
            split_in_place(&mut self.field, &mut self.phase);
        }
        failure.map_or(Ok(finite), Err)
    }

    /// Turns this colour's planes of the session's heads (`[3, H, W]` each, standard layout) into the field,
    /// on the same rows as [`ColourState::heads_to_field`] (bit-identical: the same phasor per pixel).
    /// Returns whether every head was finite.
    ///
    /// Errors: [`HoloError::Internal`] if a plane is not contiguous or not `H·W` values (the session makes
    /// them so) or the kernel refuses.
    fn shared_heads_to_field(&mut self, heads: &Heads) -> Result<bool> {
        let (amplitude, phase) = colour_planes(heads, self.colour)?;
        let flat = bytemuck::cast_slice_mut::<Complex32, f32>(&mut self.field);
        phasors(amplitude, phase, flat, self.isa)
            .map_err(|e| HoloError::Internal(format!("phasor rows: {e}")))
    }
}

/// The phasors of rows `rows` of a `[H, width]` field whose memory holds the amplitude head in its first
/// half (pixel `i` at value `i`, as [`ColourState::planes`] gives it to the CNN) and whose phase head is in
/// `phase`, for the chunks of [`SpectralPlan::apply_even_rows`] (last first, each starting at a multiple of
/// its row count): a chunk from row `y0 > 0` reads values up to `y1·width ≤ 2·y0·width`, below the values
/// `2·y0·width..` it writes, so the out-of-place rows apply; the first chunk runs in place. The same values
/// as [`ColourState::heads_to_field`] on the whole field. Returns whether every head was finite.
///
/// Errors: [`HoloError::Internal`] for a chunk that breaks that order, or if the kernel refuses.
fn phasor_rows(
    field: &mut [Complex32],
    phase: &[f32],
    rows: std::ops::Range<usize>,
    width: usize,
    isa: Isa,
) -> Result<bool> {
    let flat = bytemuck::cast_slice_mut::<Complex32, f32>(field);
    let (p0, p1) = (rows.start * width, rows.end * width);
    let run = if p0 == 0 {
        phasors_in_place(&mut flat[..2 * p1], &phase[..p1], isa)
    } else if p1 <= 2 * p0 {
        let (amplitude, out) = flat.split_at_mut(2 * p0);
        phasors(
            &amplitude[p0..p1],
            &phase[p0..p1],
            &mut out[..2 * (p1 - p0)],
            isa,
        )
    } else {
        return Err(HoloError::Internal(format!(
            "phasor rows {rows:?} would overwrite amplitudes still to be read"
        )));
    };
    run.map_err(|e| HoloError::Internal(format!("phasor rows: {e}")))
}

/// A complex field's memory as two real planes of `field.len()` values each.
fn field_planes(field: &mut [Complex32]) -> PlanePairMut<'_> {
    let n = field.len();
    bytemuck::cast_slice_mut::<Complex32, f32>(field).split_at_mut(n)
}

/// Colour `c`'s amplitude and phase planes of `heads` (`H·W` values each).
///
/// Errors: [`HoloError::Internal`] if either is not contiguous (the session keeps them in standard layout).
fn colour_planes(heads: &Heads, c: usize) -> Result<PlanePair<'_>> {
    match (
        heads.amplitude.index_axis(Axis(0), c).to_slice(),
        heads.phase.index_axis(Axis(0), c).to_slice(),
    ) {
        (Some(amplitude), Some(phase)) => Ok((amplitude, phase)),
        _ => Err(HoloError::Internal("shared heads not contiguous".into())),
    }
}

/// `re[i], im[i] ← field[i]`.
fn split_planes(field: &[Complex32], re: &mut [f32], im: &mut [f32]) {
    for ((r, i), v) in re.iter_mut().zip(im.iter_mut()).zip(field) {
        *r = v.re;
        *i = v.im;
    }
}

/// The pre-filter's input planes of a whole field in place: `re[i] ← Re field[i]`, and `Im field[i]` to
/// value `n + i` of the field's memory (its second half), last pixel first (value `n + i ≥ 2·i + 1` belongs
/// to a pixel already read).
fn split_in_place(field: &mut [Complex32], re: &mut [f32]) {
    let n = field.len();
    let flat = bytemuck::cast_slice_mut::<Complex32, f32>(field);
    for (i, r) in re.iter_mut().enumerate().rev() {
        let (a, b) = (flat[2 * i], flat[2 * i + 1]);
        *r = a;
        flat[n + i] = b;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Phasors made chunk by chunk in the order of the offset propagation's row hooks (last chunk first,
    /// starts at multiples of 8) are the whole-field in-place phasors, bit for bit, on every ISA; a chunk
    /// order that would read overwritten amplitudes is refused, not computed.
    #[test]
    fn phasor_rows_in_chunk_order_equal_the_whole_field() {
        let (h, w) = (37usize, 6usize);
        let n = h * w;
        let amplitude: Vec<f32> = (0..n)
            .map(|i| 0.1 + (i as f32 * 0.31).sin().abs())
            .collect();
        let phase: Vec<f32> = (0..n).map(|i| (i as f32 * 0.077).fract()).collect();
        for isa in Isa::available() {
            let mut whole = vec![0.0f32; 2 * n];
            whole[..n].copy_from_slice(&amplitude);
            assert!(phasors_in_place(&mut whole, &phase, isa).unwrap());

            let mut field = vec![Complex32::default(); n];
            bytemuck::cast_slice_mut::<Complex32, f32>(&mut field)[..n].copy_from_slice(&amplitude);
            for y0 in (0..h).step_by(crate::optics::fft::ROW_CHUNK).rev() {
                let rows = y0..(y0 + crate::optics::fft::ROW_CHUNK).min(h);
                assert!(phasor_rows(&mut field, &phase, rows, w, isa).unwrap());
            }
            let got = bytemuck::cast_slice::<Complex32, f32>(&field);
            assert!(
                got.iter()
                    .zip(&whole)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{isa:?}"
            );
            // Rows 1..9 before row 0 (y1 = 9 > 2·y0 = 2) would read amplitudes the chunk overwrites.
            assert!(phasor_rows(&mut field, &phase, 1..9, w, isa).is_err());
        }
    }
}
