//! The display's one map between 8-bit SLM codes and the phase they show (`docs/CONVENTIONS.md` §5.6): the
//! look-up tables of a [`DisplayCalibration`] where one is given, the linear table of an ideal SLM
//! (`2π·code/256`) otherwise. Codes → displayed phase ([`displayed_phase`]) and phase → codes
//! ([`codes_of`], and in place for a frame's calibrated colours) are written here once; the refinement, the
//! pipeline and the generator call them.

use std::sync::LazyLock;

use ndarray::{Array3, ArrayView3, ArrayViewMut3, Axis};

use super::file::DisplayCalibration;
use super::lut::{LutRepresentation, PhaseLut};
use crate::error::{HoloError, Result};

/// The linear table of an ideal SLM, made once.
static LINEAR: LazyLock<PhaseLut> = LazyLock::new(PhaseLut::linear);

/// Colour `c`'s look-up table (0 = R, 1 = G, 2 = B): `calibration`'s, or the linear one without a calibration.
pub(crate) fn colour_lut(calibration: Option<&DisplayCalibration>, c: usize) -> &PhaseLut {
    calibration
        .and_then(|cal| cal.colours.get(c))
        .map_or(&*LINEAR, |col| &col.lut)
}

/// Colour `c`'s look-up table in `calibration`, or `None` where it is the linear one (whose codes the double
/// phase encoder already writes).
pub(crate) fn calibrated_lut(
    calibration: Option<&DisplayCalibration>,
    c: usize,
) -> Option<&PhaseLut> {
    let lut = &calibration?.colours.get(c)?.lut;
    (!matches!(lut.representation(), LutRepresentation::Linear)).then_some(lut)
}

/// The phase in radians `[3, H, W]` (relative to code 0, not wrapped) each 8-bit code of `codes` `[3, H, W]`
/// displays on the SLM: through `calibration`'s look-up tables where one is given
/// ([`PhaseLut`] per colour, per-pixel tables included), the linear table's `2π·code/256` otherwise. What a
/// viewer of the display sees, quantisation included: the start of a refinement warm-started from an SLM
/// frame, the preview of a calibrated panel.
///
/// Errors: [`HoloError::ShapeMismatch`] for codes that are not `[3, H, W]` or a per-pixel calibration of
/// another SLM size.
pub fn displayed_phase(
    codes: ArrayView3<u8>,
    calibration: Option<&DisplayCalibration>,
) -> Result<Array3<f32>> {
    per_colour(codes, "SLM codes", calibration, |lut, h, w, k, o| {
        lut.displayed_phases(h, w, k, o)
    })
}

/// The 8-bit codes `[3, H, W]` of a phase pattern `phase` `[3, H, W]` (radians, any values: wrapped first),
/// through `calibration`'s look-up tables where one is given ([`PhaseLut::apply`]), the linear table
/// otherwise (the nearest code, `docs/CONVENTIONS.md` §5.6): what the SLM is sent.
///
/// Errors: [`HoloError::ShapeMismatch`] as [`displayed_phase`]; [`HoloError::InvalidData`] for a non-finite
/// phase.
pub fn codes_of(
    phase: ArrayView3<f32>,
    calibration: Option<&DisplayCalibration>,
) -> Result<Array3<u8>> {
    if phase.iter().any(|v| !v.is_finite()) {
        return Err(HoloError::InvalidData(
            "the SLM phase pattern holds NaN or infinite values".into(),
        ));
    }
    per_colour(
        phase,
        "SLM phase pattern",
        calibration,
        |lut, h, w, p, o| lut.apply(h, w, p, o),
    )
}

/// Rewrites `codes` `[3, H, W]` from `phase` `[3, H, W]` (radians) through `calibration`'s look-up table for
/// each colour whose table is not the linear one; the other colours keep their codes (the double phase
/// encoder's, already linear). Allocation-free.
///
/// Errors: [`HoloError::ShapeMismatch`] for a per-pixel table of another size; [`HoloError::Internal`] for
/// planes that are not contiguous.
pub(crate) fn recode_calibrated(
    calibration: Option<&DisplayCalibration>,
    phase: ArrayView3<f32>,
    mut codes: ArrayViewMut3<u8>,
) -> Result<()> {
    let (_, h, w) = codes.dim();
    for c in 0..3 {
        let Some(lut) = calibrated_lut(calibration, c) else {
            continue;
        };
        let phase = phase.index_axis(Axis(0), c);
        let mut codes = codes.index_axis_mut(Axis(0), c);
        match (phase.as_slice(), codes.as_slice_mut()) {
            (Some(p), Some(k)) => lut.apply(h, w, p, k)?,
            _ => return Err(HoloError::Internal("SLM frame not contiguous".into())),
        }
    }
    Ok(())
}

/// `f(lut, H, W, input plane, output plane)` for each colour of a `[3, H, W]` input (`what` in a shape
/// error) with that colour's look-up table ([`colour_lut`]), into a new `[3, H, W]` array.
fn per_colour<A: Copy, B: Copy + Default>(
    input: ArrayView3<A>,
    what: &str,
    calibration: Option<&DisplayCalibration>,
    f: impl Fn(&PhaseLut, usize, usize, &[A], &mut [B]) -> Result<()>,
) -> Result<Array3<B>> {
    let (h, w) = crate::optics::check_colour_stack(what, &input)?;
    let input = input.as_standard_layout();
    let mut out = Array3::<B>::from_elem((3, h, w), B::default());
    let n = h * w;
    let not_contiguous = || HoloError::Internal("standard-layout array not contiguous".into());
    let all = out.as_slice_mut().ok_or_else(not_contiguous)?;
    let src = input.as_slice().ok_or_else(not_contiguous)?;
    for (c, (o, i)) in all.chunks_exact_mut(n).zip(src.chunks_exact(n)).enumerate() {
        f(colour_lut(calibration, c), h, w, i, o)?;
    }
    Ok(out)
}
