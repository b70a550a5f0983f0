//! The model I/O contract in one place (`docs/CONVENTIONS.md` §7; paper Fig. 3): how the
//! SDK packs a scene into a CNN input, what an invalid pixel becomes, how the hologram CNN's heads become a
//! complex field, and how the offset hologram enters the pre-filter CNN. The pipeline, the model loader and the
//! training-dataset writer all call these functions; nothing else packs a network input.
//!
//! | network | input | outputs |
//! |---|---|---|
//! | hologram CNN | `rgbd` `[4·L, H, W]`: per layer `k` (front to back) R, G, B amplitude in `[0, 1]` then depth `d ∈ [0, 1]` (0 = near) | `amplitude` `[3, H, W]` in `[0, √2]`, `phase` `[3, H, W]` in `[0, 1]` meaning `(p − 0.5)·2π` rad |
//! | pre-filter CNN (format 2) | `slm_field` `[6, H, W]`: `Re H` (R, G, B) then `Im H` (R, G, B) of the offset hologram, midpoint amplitude units | `real`, `imag` `[3, H, W]`: `H' = blur(H) + CNN(H)` |
//!
//! Invalid pixels (no scene point in an LDI layer) enter the hologram CNN as amplitude
//! [`INVALID_AMPLITUDE`] = 0 and depth [`INVALID_DEPTH`] = 1 (far): what the training data holds.

use ndarray::{s, Array3, ArrayView3, ArrayViewMut3, Axis, Zip};
use num_complex::Complex32;

use crate::error::{invalid, HoloError, Result};
use crate::scene::{LayeredDepthImage, RgbdFrame};

/// Amplitude an invalid LDI pixel takes in the hologram CNN's input (black).
pub const INVALID_AMPLITUDE: f32 = 0.0;
/// Normalised depth an invalid LDI pixel takes in the hologram CNN's input (1 = far, never near).
pub const INVALID_DEPTH: f32 = 1.0;

/// One pixel of [`heads_to_field`]: amplitude head `a` and phase head `p ∈ [0, 1]` (turns) →
/// `a·e^{i(p − 0.5)2π}`, as [`tensorholo_kernels::phasor::phasor`] computes it (the angle reduced in turns,
/// each component within 1.0e-7·|a| of the exact value; the vectorised rows give the same bits).
#[inline]
pub fn head_to_phasor(a: f32, p: f32) -> Complex32 {
    let (re, im) = tensorholo_kernels::phasor::phasor(a, p);
    Complex32::new(re, im)
}

/// Converts the hologram CNN's heads to the complex midpoint hologram: `A · exp(i·(p − 0.5)·2π)`
/// ([`head_to_phasor`] on every pixel, on the vectorised rows of [`tensorholo_kernels::phasor`]).
///
/// `amplitude` (in `[0, √2]`) and `phase` (in `[0, 1]`) are `[3, H, W]`; the result is `[3, H, W]`
/// (R, G, B), on this CPU's best rows ([`tensorholo_kernels::Isa::detect`]: every level computes the same
/// values). Errors: [`HoloError::ShapeMismatch`] if the two shapes differ.
pub fn heads_to_field(
    amplitude: ArrayView3<f32>,
    phase: ArrayView3<f32>,
) -> Result<Array3<Complex32>> {
    if amplitude.shape() != phase.shape() {
        return Err(HoloError::ShapeMismatch {
            what: "amplitude head vs phase head".into(),
            expected: amplitude.shape().to_vec(),
            got: phase.shape().to_vec(),
        });
    }
    let isa = tensorholo_kernels::Isa::detect();
    let (amplitude, phase) = (amplitude.as_standard_layout(), phase.as_standard_layout());
    let mut out = Array3::<Complex32>::zeros(amplitude.raw_dim());
    let (Some(a), Some(p), Some(o)) = (amplitude.as_slice(), phase.as_slice(), out.as_slice_mut())
    else {
        return Err(HoloError::Internal(
            "standard-layout heads without a slice".into(),
        ));
    };
    // The finiteness flag is not needed here: a non-finite head gives a non-finite value, as before.
    tensorholo_kernels::phasor::phasors(a, p, bytemuck::cast_slice_mut(o), isa)
        .map_err(|e| HoloError::Internal(format!("phasor rows: {e}")))?;
    Ok(out)
}

/// Writes the hologram CNN input of an RGB-D frame into `out` `[4, H, W]`: the frame's linear amplitude
/// (R, G, B) then its normalised depth (0 = near). Every pixel of an [`RgbdFrame`] is valid (holes were
/// filled when it was built).
///
/// Errors: [`HoloError::ShapeMismatch`] if `out` is not `[4, H, W]` of the frame's size.
pub fn pack_rgbd(frame: &RgbdFrame, mut out: ArrayViewMut3<f32>) -> Result<()> {
    let want = [4, frame.height(), frame.width()];
    if out.shape() != want {
        return Err(HoloError::ShapeMismatch {
            what: "RGB-D frame vs the CNN input [4, H, W]".into(),
            expected: out.shape().to_vec(),
            got: want.to_vec(),
        });
    }
    out.slice_mut(s![..3, .., ..]).assign(&frame.amplitude);
    out.slice_mut(s![3, .., ..]).assign(&frame.depth);
    Ok(())
}

/// Writes the hologram CNN input of a layered depth image into `out` `[4·L', H, W]` for a CNN of `L' ≥ L`
/// input layers: per layer `k` (front to back), channels `4k..4k+3` = R, G, B amplitude then depth; where
/// layer `k` holds no point, and in the `L' − L` empty layers that pad an LDI of fewer layers than the CNN
/// takes, amplitude [`INVALID_AMPLITUDE`] and depth [`INVALID_DEPTH`] (what the training data holds where a
/// pixel has fewer points than layers).
///
/// Errors: [`HoloError::InvalidParameter`] (`ldi`) if the LDI has more layers than `out` holds;
/// [`HoloError::ShapeMismatch`] if `out` is not `[4·L', H, W]` of the LDI's size.
pub fn pack_ldi(ldi: &LayeredDepthImage, mut out: ArrayViewMut3<f32>) -> Result<()> {
    let (c, h, w) = out.dim();
    let layers = c / 4;
    if c % 4 != 0 || (h, w) != (ldi.height(), ldi.width()) {
        return Err(HoloError::ShapeMismatch {
            what: "layered depth image vs the CNN input [4·L, H, W]".into(),
            expected: out.shape().to_vec(),
            got: vec![4 * ldi.num_layers(), ldi.height(), ldi.width()],
        });
    }
    if ldi.num_layers() > layers {
        return Err(invalid(
            "ldi",
            format!(
                "the layered depth image has {} layers, the hologram CNN takes at most {layers}",
                ldi.num_layers()
            ),
        ));
    }
    for (k, layer) in ldi.layers().iter().enumerate() {
        for c in 0..3 {
            Zip::from(out.index_axis_mut(Axis(0), 4 * k + c))
                .and(layer.amplitude.index_axis(Axis(0), c))
                .and(&layer.valid)
                .for_each(|o, &a, &v| *o = if v { a } else { INVALID_AMPLITUDE });
        }
        Zip::from(out.index_axis_mut(Axis(0), 4 * k + 3))
            .and(&layer.depth)
            .and(&layer.valid)
            .for_each(|o, &d, &v| *o = if v { d } else { INVALID_DEPTH });
    }
    fill_empty_layers(out, ldi.num_layers(), layers);
    Ok(())
}

/// Writes empty LDI layers `from..to` (no point anywhere: amplitude [`INVALID_AMPLITUDE`], depth
/// [`INVALID_DEPTH`]) into the CNN input `out` `[4·L, H, W]`, `to ≤ L`: the padding of an LDI (or an RGB-D
/// frame, `from = 1`) with fewer layers than the CNN takes. The caller checks `from ≤ to ≤ L` (a slice
/// beyond `out` panics).
pub(crate) fn fill_empty_layers(mut out: ArrayViewMut3<f32>, from: usize, to: usize) {
    for k in from..to {
        out.slice_mut(s![4 * k..4 * k + 3, .., ..])
            .fill(INVALID_AMPLITUDE);
        out.index_axis_mut(Axis(0), 4 * k + 3).fill(INVALID_DEPTH);
    }
}

/// The pre-filter input channels (format 2) of colour `c` (0 = R, 1 = G, 2 = B): `Re H` in channel `c`,
/// `Im H` in channel `3 + c`. The one place that says so.
const fn prefilter_channels(c: usize) -> [usize; 2] {
    [c, 3 + c]
}

/// The pre-filter input (format 2) as six channel planes, without copying them: `[Re H_R, Re H_G, Re H_B,
/// Im H_R, Im H_G, Im H_B]` from the three colours' `(Re, Im)` planes (`H·W` values each, row-major), the
/// channel order [`pack_prefilter_colour`] writes.
pub(crate) fn prefilter_planes<'a>(colours: [(&'a [f32], &'a [f32]); 3]) -> [&'a [f32]; 6] {
    let mut planes: [&[f32]; 6] = [&[]; 6];
    for (c, (re, im)) in colours.into_iter().enumerate() {
        let [a, b] = prefilter_channels(c);
        (planes[a], planes[b]) = (re, im);
    }
    planes
}

/// Writes colour `c` (0 = R, 1 = G, 2 = B) of the offset hologram `H` into the pre-filter input `out`
/// `[6, H, W]` (format 2): `re` (`H·W` values, row-major) into channel `c`, `im` into channel `3 + c`.
///
/// Errors: [`HoloError::InvalidParameter`] for `c > 2`; [`HoloError::ShapeMismatch`] if `out` is not
/// `[6, H, W]` with `H·W` = `re.len()` = `im.len()`. The layout's reference for the tests (the sessions write
/// the planes in place).
#[cfg(test)]
pub(crate) fn pack_prefilter_colour(
    c: usize,
    re: &[f32],
    im: &[f32],
    mut out: ArrayViewMut3<f32>,
) -> Result<()> {
    if c > 2 {
        return Err(invalid(
            "colour",
            format!("is 0, 1 or 2 (R, G, B), got {c}"),
        ));
    }
    let (ch, h, w) = out.dim();
    if ch != 6 || re.len() != h * w || im.len() != h * w {
        return Err(HoloError::ShapeMismatch {
            what: "offset hologram planes vs the pre-filter input [6, H, W]".into(),
            expected: vec![6, h, w],
            got: vec![ch, re.len(), im.len()],
        });
    }
    let [a, b] = prefilter_channels(c);
    for (plane, src) in [(a, re), (b, im)] {
        let mut lane = out.index_axis_mut(Axis(0), plane);
        match lane.as_slice_mut() {
            Some(dst) => dst.copy_from_slice(src),
            None => lane.iter_mut().zip(src).for_each(|(o, v)| *o = *v),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::LdiLayer;
    use ndarray::{array, Array2};

    #[test]
    fn phasor_maps_half_to_zero_phase_and_ends_to_pi() {
        let z = head_to_phasor(0.8, 0.5);
        assert!((z.re - 0.8).abs() < 1e-6 && z.im.abs() < 1e-6);
        for p in [0.0, 1.0] {
            let z = head_to_phasor(1.0, p);
            assert!((z.re + 1.0).abs() < 1e-6 && z.im.abs() < 1e-5, "{z}");
        }
        let z = head_to_phasor(2.0, 0.75);
        assert!(z.re.abs() < 1e-5 && (z.im - 2.0).abs() < 1e-5, "{z}");
    }

    #[test]
    fn ldi_invalid_pixels_are_black_and_far() {
        let layer = LdiLayer {
            amplitude: Array3::from_elem((3, 1, 2), 0.4),
            depth: array![[0.2, 0.3]],
            valid: array![[true, false]],
        };
        let ldi = LayeredDepthImage::new(vec![layer]).unwrap();
        let mut out = Array3::<f32>::from_elem((4, 1, 2), -7.0);
        pack_ldi(&ldi, out.view_mut()).unwrap();
        assert_eq!(out.slice(s![.., 0, 0]).to_vec(), vec![0.4, 0.4, 0.4, 0.2]);
        assert_eq!(
            out.slice(s![.., 0, 1]).to_vec(),
            vec![
                INVALID_AMPLITUDE,
                INVALID_AMPLITUDE,
                INVALID_AMPLITUDE,
                INVALID_DEPTH
            ]
        );
        // A one-layer LDI of an RGB-D frame packs exactly as the frame does.
        let f = RgbdFrame::new(
            Array3::from_shape_fn((3, 2, 3), |(c, y, x)| (c + y + x) as f32 / 8.0),
            Array2::from_shape_fn((2, 3), |(y, x)| (y * 3 + x) as f32 / 6.0),
        )
        .unwrap();
        let (mut a, mut b) = (Array3::zeros((4, 2, 3)), Array3::zeros((4, 2, 3)));
        pack_rgbd(&f, a.view_mut()).unwrap();
        pack_ldi(&LayeredDepthImage::from(f), b.view_mut()).unwrap();
        assert_eq!(a, b);
        assert!(pack_rgbd(&ldi.to_rgbd(), Array3::zeros((4, 2, 2)).view_mut()).is_err());
    }

    #[test]
    fn fewer_ldi_layers_pad_with_empty_layers_and_more_are_refused() {
        let layer = |v: f32, d: f32| LdiLayer {
            amplitude: Array3::from_elem((3, 2, 2), v),
            depth: Array2::from_elem((2, 2), d),
            valid: Array2::from_elem((2, 2), true),
        };
        let ldi = LayeredDepthImage::new(vec![layer(0.5, 0.1), layer(0.25, 0.6)]).unwrap();
        let mut out = Array3::<f32>::from_elem((20, 2, 2), -7.0);
        pack_ldi(&ldi, out.view_mut()).unwrap();
        let at = |c: usize| out[[c, 1, 0]];
        assert_eq!((at(0), at(3), at(4), at(7)), (0.5, 0.1, 0.25, 0.6));
        for k in 2..5 {
            for c in 0..3 {
                assert_eq!(at(4 * k + c), INVALID_AMPLITUDE, "layer {k} channel {c}");
            }
            assert_eq!(at(4 * k + 3), INVALID_DEPTH, "layer {k} depth");
        }
        // Two layers into a one-layer (RGB-D) CNN input: refused, nothing dropped silently.
        let err = pack_ldi(&ldi, Array3::zeros((4, 2, 2)).view_mut()).unwrap_err();
        assert!(err.to_string().contains("at most 1"), "{err}");
        // An input whose channels are not whole layers, or of another size.
        assert!(pack_ldi(&ldi, Array3::zeros((10, 2, 2)).view_mut()).is_err());
        assert!(pack_ldi(&ldi, Array3::zeros((20, 2, 3)).view_mut()).is_err());
    }

    #[test]
    fn prefilter_colour_goes_to_c_and_3_plus_c() {
        let mut out = Array3::<f32>::zeros((6, 1, 2));
        pack_prefilter_colour(1, &[1.0, 2.0], &[3.0, 4.0], out.view_mut()).unwrap();
        assert_eq!(out.slice(s![1, 0, ..]).to_vec(), vec![1.0, 2.0]);
        assert_eq!(out.slice(s![4, 0, ..]).to_vec(), vec![3.0, 4.0]);
        assert_eq!(out.iter().filter(|v| **v != 0.0).count(), 4);
        assert!(pack_prefilter_colour(3, &[0.0; 2], &[0.0; 2], out.view_mut()).is_err());
        assert!(pack_prefilter_colour(0, &[0.0; 3], &[0.0; 2], out.view_mut()).is_err());
        // The planes in place follow the same order as the packed array.
        let (re, im): (Vec<Vec<f32>>, Vec<Vec<f32>>) = (0..3)
            .map(|c| (vec![c as f32; 2], vec![10.0 + c as f32; 2]))
            .unzip();
        let mut packed = Array3::<f32>::zeros((6, 1, 2));
        for c in 0..3 {
            pack_prefilter_colour(c, &re[c], &im[c], packed.view_mut()).unwrap();
        }
        let planes = prefilter_planes([0, 1, 2].map(|c| (&re[c][..], &im[c][..])));
        for (ch, plane) in planes.iter().enumerate() {
            assert_eq!(
                packed.slice(s![ch, 0, ..]).to_vec(),
                plane.to_vec(),
                "channel {ch}"
            );
        }
    }
}
