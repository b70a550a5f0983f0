//! Scene containers: [`RgbdFrame`] (one colour + depth view) and [`LayeredDepthImage`] (Shade et al.
//! 1998, the paper's Fig. 1 input), with their invariants checked at construction.

use ndarray::{Array2, Array3, Axis, Zip};

use crate::error::{invalid, HoloError, Result};

/// An RGB-D frame, the SDK's input (`docs/CONVENTIONS.md` §2, §4).
///
/// * `amplitude`: `[3, H, W]`, channels R, G, B; field amplitude = √(linear intensity) after sRGB decoding
///   (see [`crate::color::srgb8_to_amplitude`]), nominally in `[0, 1]`.
/// * `depth`: `[H, W]` normalised depth `d ∈ [0, 1]`, 0 = near (the viewer's side).
///
/// [`RgbdFrame::new`] guarantees both are non-empty, agree in shape and are finite, with amplitude ≥ 0
/// and depth in `[0, 1]`. The fields are public for zero-copy access; code that mutates them is
/// responsible for keeping those invariants.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbdFrame {
    /// `[3, H, W]` linear amplitude, R, G, B.
    pub amplitude: Array3<f32>,
    /// `[H, W]` normalised depth, 0 = near, 1 = far.
    pub depth: Array2<f32>,
}

/// Counts entries failing `ok`.
fn count_bad<'a, I: IntoIterator<Item = &'a f32>>(it: I, ok: impl Fn(f32) -> bool) -> usize {
    it.into_iter().filter(|&&v| !ok(v)).count()
}

/// Checks a `[3, H, W]` amplitude: 3 channels, non-empty, finite, ≥ 0. `what` names it in errors.
fn check_amplitude(amplitude: &Array3<f32>, what: &str) -> Result<()> {
    let (c, h, w) = amplitude.dim();
    if c != 3 {
        return Err(HoloError::ShapeMismatch {
            what: format!("{what} channels (R, G, B)"),
            expected: vec![3, h, w],
            got: vec![c, h, w],
        });
    }
    if h == 0 || w == 0 {
        return Err(HoloError::InvalidData(format!(
            "{what} is empty ({h}x{w} pixels)"
        )));
    }
    let non_finite = count_bad(amplitude, f32::is_finite);
    if non_finite > 0 {
        return Err(HoloError::InvalidData(format!(
            "{what} has {non_finite} non-finite values"
        )));
    }
    let negative = count_bad(amplitude, |v| v >= 0.0);
    if negative > 0 {
        return Err(HoloError::InvalidData(format!(
            "{what} has {negative} negative values (amplitude must be >= 0)"
        )));
    }
    Ok(())
}

impl RgbdFrame {
    /// Validated constructor.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if `amplitude` does not have 3 channels or its `[H, W]`
    /// differs from `depth` (`what` = `"depth map vs RGB image"`); [`HoloError::InvalidData`] if empty,
    /// non-finite or negative amplitude; [`HoloError::InvalidDepth`] with the number of bad pixels if depth
    /// is NaN/infinite or outside `[0, 1]`.
    pub fn new(amplitude: Array3<f32>, depth: Array2<f32>) -> Result<Self> {
        let (c, h, w) = amplitude.dim();
        if c != 3 {
            return Err(HoloError::ShapeMismatch {
                what: "RGB amplitude channels (R, G, B)".into(),
                expected: vec![3, h, w],
                got: vec![c, h, w],
            });
        }
        if depth.dim() != (h, w) {
            return Err(HoloError::ShapeMismatch {
                what: "depth map vs RGB image".into(),
                expected: vec![h, w],
                got: depth.shape().to_vec(),
            });
        }
        check_amplitude(&amplitude, "RGB amplitude")?;
        let non_finite = count_bad(&depth, f32::is_finite);
        if non_finite > 0 {
            return Err(HoloError::InvalidDepth(format!(
                "{non_finite} of {} depth pixels are NaN or infinite",
                depth.len()
            )));
        }
        let out_of_range = count_bad(&depth, |v| (0.0..=1.0).contains(&v));
        if out_of_range > 0 {
            return Err(HoloError::InvalidDepth(format!(
                "{out_of_range} of {} depth pixels are outside the normalised range [0, 1]",
                depth.len()
            )));
        }
        Ok(RgbdFrame { amplitude, depth })
    }

    /// Height `H` in pixels.
    pub fn height(&self) -> usize {
        self.depth.nrows()
    }

    /// Width `W` in pixels.
    pub fn width(&self) -> usize {
        self.depth.ncols()
    }

    /// Resamples to `height × width`.
    ///
    /// Amplitude: separable Catmull-Rom (support widened by the scale factor when shrinking, i.e.
    /// area-correct antialiasing) applied to linear intensity `amplitude²`, clamped to `[0, max]` of the
    /// channel's input intensity (the filter's overshoot at edges), then `√`.
    /// Depth: nearest neighbour, so no "flying pixels" with invented depths appear at occlusion edges.
    /// Error: [`HoloError::InvalidParameter`] if `height` or `width` is 0.
    pub fn resize(&self, height: usize, width: usize) -> Result<Self> {
        check_target_size(height, width)?;
        if (height, width) == (self.height(), self.width()) {
            return Ok(self.clone());
        }
        Ok(RgbdFrame {
            amplitude: resize_amplitude(&self.amplitude, height, width),
            depth: resize_nearest(&self.depth, height, width),
        })
    }
}

/// One layer of a layered depth image (Shade et al. 1998; paper Fig. 1).
///
/// * `amplitude`: `[3, H, W]` linear amplitude, R, G, B (as in [`RgbdFrame`]);
/// * `depth`: `[H, W]` normalised depth `d ∈ [0, 1]`, 0 = near (meaningful where `valid`);
/// * `valid`: `[H, W]`, `true` where this layer holds a scene point.
#[derive(Debug, Clone, PartialEq)]
pub struct LdiLayer {
    /// `[3, H, W]` linear amplitude, R, G, B.
    pub amplitude: Array3<f32>,
    /// `[H, W]` normalised depth, 0 = near.
    pub depth: Array2<f32>,
    /// `[H, W]` point present.
    pub valid: Array2<bool>,
}

/// A layered depth image: per pixel, up to `L` scene points sorted front to back (layer 0 = what an
/// RGB-D camera sees). The TensorHolo CNN takes `L = 5` for LDI input (`docs/CONVENTIONS.md` §7.1).
#[derive(Debug, Clone, PartialEq)]
pub struct LayeredDepthImage {
    layers: Vec<LdiLayer>,
}

impl LayeredDepthImage {
    /// Validated constructor.
    ///
    /// Requires at least one layer; every layer's amplitude `[3, H, W]`, depth `[H, W]` and valid `[H, W]`
    /// of one common `H × W` (non-empty); all values finite, amplitude ≥ 0; depth in `[0, 1]` where valid;
    /// and front-to-back order: wherever layers `k` and `k+1` are both valid,
    /// `depth[k+1] ≥ depth[k]`. (A layer may be valid where the one before it is not.)
    ///
    /// Errors: [`HoloError::InvalidParameter`] (no layer), [`HoloError::ShapeMismatch`],
    /// [`HoloError::InvalidData`] (amplitude), [`HoloError::InvalidDepth`] (depth values or order, with
    /// the layer index and number of offending pixels).
    pub fn new(layers: Vec<LdiLayer>) -> Result<Self> {
        let first = layers
            .first()
            .ok_or_else(|| invalid("layers", "a layered depth image needs at least one layer"))?;
        let (_, h, w) = first.amplitude.dim();
        for (k, layer) in layers.iter().enumerate() {
            if layer.amplitude.dim() != (3, h, w) {
                return Err(HoloError::ShapeMismatch {
                    what: format!("LDI layer {k} amplitude"),
                    expected: vec![3, h, w],
                    got: layer.amplitude.shape().to_vec(),
                });
            }
            if layer.depth.dim() != (h, w) {
                return Err(HoloError::ShapeMismatch {
                    what: format!("LDI layer {k} depth vs its RGB"),
                    expected: vec![h, w],
                    got: layer.depth.shape().to_vec(),
                });
            }
            if layer.valid.dim() != (h, w) {
                return Err(HoloError::ShapeMismatch {
                    what: format!("LDI layer {k} validity mask vs its RGB"),
                    expected: vec![h, w],
                    got: layer.valid.shape().to_vec(),
                });
            }
            check_amplitude(&layer.amplitude, &format!("LDI layer {k} amplitude"))?;
            let non_finite = count_bad(&layer.depth, f32::is_finite);
            if non_finite > 0 {
                return Err(HoloError::InvalidDepth(format!(
                    "LDI layer {k}: {non_finite} depth values are NaN or infinite"
                )));
            }
            let out = Zip::from(&layer.depth)
                .and(&layer.valid)
                .fold(0usize, |n, &d, &ok| {
                    n + usize::from(ok && !(0.0..=1.0).contains(&d))
                });
            if out > 0 {
                return Err(HoloError::InvalidDepth(format!(
                    "LDI layer {k}: {out} valid pixels have depth outside [0, 1]"
                )));
            }
            if k > 0 {
                let prev = &layers[k - 1];
                let in_front = Zip::from(&prev.depth)
                    .and(&prev.valid)
                    .and(&layer.depth)
                    .and(&layer.valid)
                    .fold(0usize, |n, &d0, &v0, &d1, &v1| {
                        n + usize::from(v0 && v1 && d1 < d0)
                    });
                if in_front > 0 {
                    return Err(HoloError::InvalidDepth(format!(
                        "LDI layer {k} lies in front of layer {} at {in_front} pixels; layers must be \
                         ordered front to back (depth[k+1] >= depth[k])",
                        k - 1
                    )));
                }
            }
        }
        Ok(LayeredDepthImage { layers })
    }

    /// The layers, front to back.
    pub fn layers(&self) -> &[LdiLayer] {
        &self.layers
    }

    /// Consumes the image, returning its layers front to back.
    pub fn into_layers(self) -> Vec<LdiLayer> {
        self.layers
    }

    /// Height `H` in pixels.
    pub fn height(&self) -> usize {
        self.layers[0].depth.nrows()
    }

    /// Width `W` in pixels.
    pub fn width(&self) -> usize {
        self.layers[0].depth.ncols()
    }

    /// Number of layers `L` (≥ 1).
    pub fn num_layers(&self) -> usize {
        self.layers.len()
    }

    /// Resamples every layer to `height × width`, as [`RgbdFrame::resize`]: amplitude by area-correct
    /// Catmull-Rom on intensity, depth and validity by nearest neighbour. Depth and validity of all layers
    /// come from the same source pixel, so the front-to-back order and the validity of the input hold in the
    /// output.
    ///
    /// Error: [`HoloError::InvalidParameter`] if `height` or `width` is 0.
    pub(crate) fn resize(&self, height: usize, width: usize) -> Result<Self> {
        check_target_size(height, width)?;
        if (height, width) == (self.height(), self.width()) {
            return Ok(self.clone());
        }
        let layers = self
            .layers
            .iter()
            .map(|l| LdiLayer {
                amplitude: resize_amplitude(&l.amplitude, height, width),
                depth: resize_nearest(&l.depth, height, width),
                valid: resize_nearest(&l.valid, height, width),
            })
            .collect();
        Ok(LayeredDepthImage { layers })
    }

    /// The first layer as an RGB-D frame (an RGB-D image is a one-layer LDI). Pixels where the first layer
    /// is invalid get amplitude 0 (black) and depth 1 (far).
    pub fn to_rgbd(&self) -> RgbdFrame {
        let l = &self.layers[0];
        let mut amplitude = l.amplitude.clone();
        for mut ch in amplitude.axis_iter_mut(Axis(0)) {
            Zip::from(&mut ch).and(&l.valid).for_each(|a, &ok| {
                if !ok {
                    *a = 0.0;
                }
            });
        }
        let depth = Zip::from(&l.depth)
            .and(&l.valid)
            .map_collect(|&d, &ok| if ok { d } else { 1.0 });
        RgbdFrame { amplitude, depth }
    }
}

impl From<RgbdFrame> for LayeredDepthImage {
    /// A one-layer LDI, valid everywhere.
    fn from(frame: RgbdFrame) -> Self {
        let valid = Array2::from_elem(frame.depth.raw_dim(), true);
        LayeredDepthImage {
            layers: vec![LdiLayer {
                amplitude: frame.amplitude,
                depth: frame.depth,
                valid,
            }],
        }
    }
}

/// Refuses a resize target of zero height or width. Error: [`HoloError::InvalidParameter`] (`size`).
pub(crate) fn check_target_size(height: usize, width: usize) -> Result<()> {
    if height == 0 || width == 0 {
        return Err(invalid(
            "size",
            format!("target size must be non-zero, got {height}x{width}"),
        ));
    }
    Ok(())
}

/// Catmull-Rom cubic (a = −0.5), support 2.
fn catmull_rom(x: f32) -> f32 {
    let x = x.abs();
    if x < 1.0 {
        (1.5 * x - 2.5) * x * x + 1.0
    } else if x < 2.0 {
        ((-0.5 * x + 2.5) * x - 4.0) * x + 2.0
    } else {
        0.0
    }
}

/// Per output sample: first input index and normalised weights (edge samples replicated).
fn resample_weights(n_in: usize, n_out: usize) -> Vec<(Vec<usize>, Vec<f32>)> {
    let scale = n_in as f32 / n_out as f32;
    let fscale = scale.max(1.0);
    let support = 2.0 * fscale;
    (0..n_out)
        .map(|o| {
            let center = (o as f32 + 0.5) * scale - 0.5;
            let lo = (center - support).floor() as isize;
            let hi = (center + support).ceil() as isize;
            let mut idx = Vec::new();
            let mut wts = Vec::new();
            for j in lo..=hi {
                let wgt = catmull_rom((j as f32 - center) / fscale);
                if wgt != 0.0 {
                    idx.push(j.clamp(0, n_in as isize - 1) as usize);
                    wts.push(wgt);
                }
            }
            let sum: f32 = wts.iter().sum();
            wts.iter_mut().for_each(|w| *w /= sum);
            (idx, wts)
        })
        .collect()
}

/// Separable Catmull-Rom resampling of one `[H_in, W_in]` plane whose rows `fill(y, row)` writes (so that a
/// plane computed from another, e.g. intensities from 8-bit codes, is never held whole): rows first, then
/// columns, each output the sum of its taps' products in tap order from `−0.0` (as `Iterator::sum`). The
/// rows' pass takes [`RESAMPLE_ROWS`] rows at a time through a transposed block (`block[j][r]`: column `j` of
/// row `r`), each tap one contiguous multiply-add over the rows; the columns' pass accumulates a whole output
/// row per tap.
fn resample_rows(
    h_in: usize,
    w_in: usize,
    mut fill: impl FnMut(usize, &mut [f32]),
    wy: &[(Vec<usize>, Vec<f32>)],
    wx: &[(Vec<usize>, Vec<f32>)],
) -> Array2<f32> {
    const R: usize = RESAMPLE_ROWS;
    let w_out = wx.len();
    let mut tmp = vec![0.0f32; h_in * w_out];
    let mut rows = vec![0.0f32; w_in * R];
    let mut block = vec![0.0f32; w_in * R];
    for (b, rows_out) in tmp.chunks_mut(R * w_out).enumerate() {
        let n = rows_out.len() / w_out.max(1);
        for (r, row) in rows.chunks_exact_mut(w_in).take(n).enumerate() {
            fill(b * R + r, row);
        }
        if n == R {
            for (r, row) in rows.chunks_exact(w_in).enumerate() {
                for (col, &v) in block.chunks_exact_mut(R).zip(row) {
                    col[r] = v;
                }
            }
            for (x, (idx, wts)) in wx.iter().enumerate() {
                let mut acc = [-0.0f32; R];
                for (&j, &w) in idx.iter().zip(wts) {
                    let col = &block[j * R..(j + 1) * R];
                    for (a, &v) in acc.iter_mut().zip(col) {
                        *a += v * w;
                    }
                }
                for (r, &a) in acc.iter().enumerate() {
                    rows_out[r * w_out + x] = a;
                }
            }
            continue;
        }
        for (row_out, row_in) in rows_out
            .chunks_exact_mut(w_out)
            .zip(rows.chunks_exact(w_in))
        {
            for (o, (idx, wts)) in row_out.iter_mut().zip(wx) {
                *o = idx
                    .iter()
                    .zip(wts)
                    .map(|(&j, &w)| row_in[j] * w)
                    .sum::<f32>();
            }
        }
    }
    let mut out = vec![-0.0f32; wy.len() * w_out];
    for (row_out, (idx, wts)) in out.chunks_exact_mut(w_out).zip(wy) {
        for (&j, &w) in idx.iter().zip(wts) {
            let row = &tmp[j * w_out..(j + 1) * w_out];
            for (o, &t) in row_out.iter_mut().zip(row) {
                *o += t * w;
            }
        }
    }
    Array2::from_shape_vec((wy.len(), w_out), out).unwrap_or_default()
}

/// Rows of [`resample_rows`]'s first pass taken together.
const RESAMPLE_ROWS: usize = 8;

/// Resizes `[3, H, W]` amplitude in the intensity domain (see [`RgbdFrame::resize`]).
pub(crate) fn resize_amplitude(
    amplitude: &Array3<f32>,
    height: usize,
    width: usize,
) -> Array3<f32> {
    let (c, h, w) = amplitude.dim();
    let amplitude = amplitude.as_standard_layout();
    let src = amplitude.as_slice().unwrap_or_default();
    let plane = |ch: usize| &src[ch * h * w..(ch + 1) * h * w];
    resize_intensity_rows(
        c,
        (h, w),
        (height, width),
        |ch| plane(ch).iter().map(|&a| a * a).fold(0.0f32, f32::max),
        |ch, y, row| {
            for (i, &a) in row.iter_mut().zip(&plane(ch)[y * w..(y + 1) * w]) {
                *i = a * a;
            }
        },
    )
}

/// The resize of [`resize_amplitude`] from planes given row by row: `channels` planes of `h × w`
/// intensities (`fill(channel, y, row)` writes row `y`'s, the amplitude squared), resampled to
/// `height × width` (Catmull-Rom, [`resample_rows`]), each clamped to `[0, top(channel)]` (the plane's own
/// largest intensity: Catmull-Rom over- and undershoots at edges, and an image in `[0, 1]` stays there, the
/// CNN's training range, with no negative intensity) and returned as amplitude `[channels, height, width]`.
pub(crate) fn resize_intensity_rows(
    channels: usize,
    (h, w): (usize, usize),
    (height, width): (usize, usize),
    mut top: impl FnMut(usize) -> f32,
    mut fill: impl FnMut(usize, usize, &mut [f32]),
) -> Array3<f32> {
    let wy = resample_weights(h, height);
    let wx = resample_weights(w, width);
    let mut out = Array3::<f32>::zeros((channels, height, width));
    for (ch, mut plane) in out.outer_iter_mut().enumerate() {
        let top = top(ch);
        let resampled = resample_rows(h, w, |y, row| fill(ch, y, row), &wy, &wx);
        Zip::from(&mut plane)
            .and(&resampled)
            .for_each(|o, &i| *o = i.clamp(0.0, top).sqrt());
    }
    out
}

/// The input index output index `o` of `n_out` reads in a nearest-neighbour resize from `n_in` (pixel centres
/// aligned): `⌊(o + ½)·n_in/n_out⌋`.
pub(crate) fn nearest_index(o: usize, n_in: usize, n_out: usize) -> usize {
    (((o as f64 + 0.5) * n_in as f64 / n_out as f64).floor() as usize).min(n_in - 1)
}

/// Nearest-neighbour resize of an `[H, W]` map (pixel centres aligned, [`nearest_index`]; the column indices
/// computed once, rows copied from them).
pub(crate) fn resize_nearest<T: Copy + Default>(
    map: &Array2<T>,
    height: usize,
    width: usize,
) -> Array2<T> {
    let (h, w) = map.dim();
    let cols: Vec<usize> = (0..width).map(|x| nearest_index(x, w, width)).collect();
    let mut out = Array2::from_elem((height, width), T::default());
    for (y, mut row) in out.outer_iter_mut().enumerate() {
        let src = map.row(nearest_index(y, h, height));
        for (o, &x) in row.iter_mut().zip(&cols) {
            *o = src[x];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    fn frame(h: usize, w: usize) -> RgbdFrame {
        let amp = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            ((c + y * 3 + x * 7) % 11) as f32 / 10.0
        });
        let depth =
            Array2::from_shape_fn(
                (h, w),
                |(y, x)| if x < w / 2 { 0.1 } else { 0.9 + 0.0 * y as f32 },
            );
        RgbdFrame::new(amp, depth).unwrap()
    }

    #[test]
    fn new_validates_shapes_and_values() {
        let f = frame(4, 6);
        assert_eq!((f.height(), f.width()), (4, 6));
        let err = RgbdFrame::new(f.amplitude.clone(), Array2::zeros((4, 5))).unwrap_err();
        match err {
            HoloError::ShapeMismatch {
                what,
                expected,
                got,
            } => {
                assert_eq!(what, "depth map vs RGB image");
                assert_eq!(expected, vec![4, 6]);
                assert_eq!(got, vec![4, 5]);
            }
            e => panic!("unexpected {e}"),
        }
        assert!(matches!(
            RgbdFrame::new(Array3::zeros((4, 4, 6)), f.depth.clone()),
            Err(HoloError::ShapeMismatch { .. })
        ));
        let mut d = f.depth.clone();
        d[[1, 1]] = f32::NAN;
        d[[2, 2]] = f32::NAN;
        match RgbdFrame::new(f.amplitude.clone(), d).unwrap_err() {
            HoloError::InvalidDepth(msg) => assert!(msg.starts_with("2 of 24"), "{msg}"),
            e => panic!("unexpected {e}"),
        }
        let mut d = f.depth.clone();
        d[[0, 0]] = 1.5;
        assert!(matches!(
            RgbdFrame::new(f.amplitude.clone(), d),
            Err(HoloError::InvalidDepth(_))
        ));
        let mut a = f.amplitude.clone();
        a[[2, 0, 0]] = -0.1;
        assert!(matches!(
            RgbdFrame::new(a, f.depth.clone()),
            Err(HoloError::InvalidData(_))
        ));
        let mut a = f.amplitude.clone();
        a[[0, 0, 0]] = f32::INFINITY;
        assert!(matches!(
            RgbdFrame::new(a, f.depth.clone()),
            Err(HoloError::InvalidData(_))
        ));
        assert!(matches!(
            RgbdFrame::new(Array3::zeros((3, 0, 0)), Array2::zeros((0, 0))),
            Err(HoloError::InvalidData(_))
        ));
    }

    #[test]
    fn resize_keeps_depth_values_and_constant_amplitude() {
        let f = frame(30, 40);
        for (h, w) in [(15, 20), (61, 83), (7, 100)] {
            let r = f.resize(h, w).unwrap();
            assert_eq!(r.amplitude.dim(), (3, h, w));
            // Nearest: only existing depth values, no flying pixels between 0.1 and 0.9.
            assert!(r.depth.iter().all(|&d| d == 0.1 || d == 0.9));
            assert!(r.amplitude.iter().all(|a| a.is_finite() && *a >= 0.0));
        }
        let flat =
            RgbdFrame::new(Array3::from_elem((3, 9, 9), 0.6), Array2::zeros((9, 9))).unwrap();
        let r = flat.resize(20, 5).unwrap();
        assert!(r.amplitude.iter().all(|a| (a - 0.6).abs() < 1e-5));
        assert!(f.resize(0, 5).is_err() && f.resize(5, 0).is_err());
        assert_eq!(f.resize(30, 40).unwrap(), f);
    }

    #[test]
    fn downscale_by_two_averages_intensity() {
        // Checker of amplitudes 0 and 1 -> intensity average 0.5 -> amplitude sqrt(0.5).
        let amp = Array3::from_shape_fn((3, 64, 64), |(_, y, x)| ((x + y) % 2) as f32);
        let f = RgbdFrame::new(amp, Array2::zeros((64, 64))).unwrap();
        let r = f.resize(32, 32).unwrap();
        for ((_, y, x), a) in r.amplitude.indexed_iter() {
            if (4..28).contains(&y) && (4..28).contains(&x) {
                assert!((a - 0.5f32.sqrt()).abs() < 0.02, "({y}, {x}): {a}");
            }
        }
    }

    fn layer(depth: Array2<f32>, valid: Array2<bool>) -> LdiLayer {
        let (h, w) = depth.dim();
        LdiLayer {
            amplitude: Array3::from_elem((3, h, w), 0.5),
            depth,
            valid,
        }
    }

    #[test]
    fn ldi_checks_order_and_converts() {
        let l0 = layer(
            array![[0.2, 0.5], [0.0, 0.3]],
            array![[true, true], [false, true]],
        );
        let l1 = layer(
            array![[0.8, 0.5], [0.1, 0.9]],
            array![[true, true], [true, false]],
        );
        let ldi = LayeredDepthImage::new(vec![l0.clone(), l1.clone()]).unwrap();
        assert_eq!((ldi.num_layers(), ldi.height(), ldi.width()), (2, 2, 2));
        let rgbd = ldi.to_rgbd();
        assert_eq!(rgbd.depth, array![[0.2, 0.5], [1.0, 0.3]]);
        assert_eq!(rgbd.amplitude[[1, 1, 0]], 0.0);
        assert_eq!(rgbd.amplitude[[1, 0, 0]], 0.5);
        // Layer 1 in front of layer 0 where both valid -> error.
        let bad = layer(
            array![[0.1, 0.5], [0.1, 0.9]],
            array![[true, true], [true, true]],
        );
        assert!(matches!(
            LayeredDepthImage::new(vec![l0.clone(), bad]),
            Err(HoloError::InvalidDepth(_))
        ));
        // NaN depth, out-of-range depth where valid, shape mismatch, empty.
        let nan = layer(array![[f32::NAN, 0.5], [0.0, 0.3]], l0.valid.clone());
        assert!(LayeredDepthImage::new(vec![nan]).is_err());
        let mut oob = l0.clone();
        oob.depth[[0, 0]] = 1.2;
        assert!(matches!(
            LayeredDepthImage::new(vec![oob]),
            Err(HoloError::InvalidDepth(_))
        ));
        let mut ok_oob = l0.clone();
        ok_oob.depth[[1, 0]] = 7.0; // invalid pixel: value not checked against [0, 1]
        assert!(LayeredDepthImage::new(vec![ok_oob]).is_ok());
        let small = layer(array![[0.1]], array![[true]]);
        assert!(matches!(
            LayeredDepthImage::new(vec![l0, small]),
            Err(HoloError::ShapeMismatch { .. })
        ));
        assert!(LayeredDepthImage::new(vec![]).is_err());
        // RGB-D -> 1-layer LDI -> RGB-D round trip.
        let f = RgbdFrame::new(
            Array3::from_elem((3, 2, 3), 0.25),
            Array2::from_elem((2, 3), 0.4),
        )
        .unwrap();
        let ldi = LayeredDepthImage::from(f.clone());
        assert_eq!(ldi.num_layers(), 1);
        assert!(ldi.layers()[0].valid.iter().all(|&v| v));
        assert_eq!(ldi.to_rgbd(), f);
    }
}
