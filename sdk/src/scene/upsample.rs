//! Depth of a lower resolution than the colour (a phone's 256 × 192 LiDAR depth under its 1920 × 1440 image)
//! brought to the colour's resolution: by nearest neighbour, or edge-aware by the joint bilateral upsampling of
//! Kopf et al. ("Joint bilateral upsampling", SIGGRAPH 2007), guided by the colour so that a depth edge follows
//! the image's edge instead of the depth map's blocky one. No maintained Rust crate offers it (OpenCV's
//! `ximgproc::jointBilateralFilter` is C++), so it is written here.
//!
//! For an output pixel `p` at low-resolution position `p↓`, the depth is `Σ_q D(q)·f(‖q − p↓‖)·g(‖I(p) −
//! I(q↑)‖) / Σ_q f·g` over the valid low-resolution samples `q` of the 4 × 4 window around `p↓`, `f` a Gaussian
//! of [`SPATIAL_SIGMA`] low-resolution pixels, `g` a Gaussian of [`COLOUR_SIGMA`] in the colour's linear
//! amplitude (R, G, B), `I(q↑)` the colour at the sample's centre. No invalid sample contributes, and a pixel
//! is valid where the valid samples carry at least half of the window's weight `Σ f·g` (so a hole's edge, e.g.
//! an object's silhouette on an empty background, follows the colour's edge too); an invalid pixel is filled
//! later as every hole is, never read as near. Where no sample of the window resembles the pixel's colour,
//! nearest neighbour's value and validity stay.

use ndarray::{Array2, ArrayView3};
use rayon::prelude::*;

use super::depth::DecodedDepth;

/// How depth of another resolution is brought to the colour's ([`upsample_depth`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepthUpsampling {
    /// Nearest neighbour, values and validity alike: blocky edges at the depth's own resolution.
    Nearest,
    /// Joint bilateral upsampling guided by the colour (the default of files, [`crate::scene::LoadOptions`]:
    /// closer to the full-resolution hologram on frames with exact depth at 1/4 and 1/8 resolution,
    /// docs/VIDEO.md; the camera path's default stays nearest for its cost, [`crate::scene::FrameOptions`]).
    #[default]
    JointBilateral,
}

impl DepthUpsampling {
    /// The CLI's name (`nearest`, `joint-bilateral`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Nearest => "nearest",
            Self::JointBilateral => "joint-bilateral",
        }
    }
}

/// The spatial Gaussian's standard deviation, low-resolution pixels. With [`COLOUR_SIGMA`], the better of the
/// two pairs measured (0.75 and 0.08 the other; `tests/real_inputs.rs`, docs/VIDEO.md).
pub const SPATIAL_SIGMA: f32 = 0.5;
/// The colour Gaussian's standard deviation, linear amplitude (`[0, 1]` per channel).
pub const COLOUR_SIGMA: f32 = 0.05;
/// The window's side: samples `[p↓] − 1 ..= [p↓] + 1` (`[·]` rounding) in each direction, within 1.5
/// low-resolution pixels of `p↓` (the spatial weight beyond is below 1.2 %).
const TAPS: usize = 3;
/// The largest depth value summed (larger ones count as this): far beyond any scene, and 9 of them fit f32.
const MAX_SUMMED_DEPTH: f32 = 1e30;
/// Entries of the colour weight's table over `‖ΔI‖² ∈ [0, 9σ²]` (beyond: 0).
const TABLE: usize = 1024;

/// `decoded` (`[h, w]` depths in metres, or relative, with their validity) at the size of `guide` (`[3, H, W]`,
/// the colour's linear amplitude at the output resolution) by `method`: nearest neighbour, or the joint
/// bilateral upsampling of Kopf et al. 2007 as the module docs give it. The same map where the size is already
/// the guide's. No errors: every size is accepted (a depth larger than the guide is resampled down the same way).
pub fn upsample_depth(
    decoded: DecodedDepth,
    guide: ArrayView3<f32>,
    method: DepthUpsampling,
) -> DecodedDepth {
    let (_, h, w) = guide.dim();
    let (hd, wd) = decoded.values.dim();
    if (hd, wd) == (h, w) || method == DepthUpsampling::Nearest || hd == 0 || wd == 0 {
        return decoded.into_resolution(h, w);
    }
    let metric = decoded.metric;
    let low = LowRes::new(&decoded.values, &decoded.valid, &guide, (h, w));
    // The guide's planes as contiguous slices (a copy only for another layout).
    let guide = guide.as_standard_layout();
    let planes = guide.as_slice().expect("standard layout");
    let (g0, rest) = planes.split_at(h * w);
    let (g1, g2) = rest.split_at(h * w);
    // The last entry, and every distance beyond 9σ², weighs 0.
    let table: Vec<f32> = (0..TABLE)
        .map(|k| {
            let d2 = k as f32 / (TABLE - 1) as f32 * 9.0 * COLOUR_SIGMA * COLOUR_SIGMA;
            if k + 1 == TABLE {
                0.0
            } else {
                (-d2 / (2.0 * COLOUR_SIGMA * COLOUR_SIGMA)).exp()
            }
        })
        .collect();
    let scale = (TABLE - 1) as f32 / (9.0 * COLOUR_SIGMA * COLOUR_SIGMA);
    // Per output row and column: the window's first sample, its taps' spatial weights (0 past the map's
    // edge) and the nearest sample.
    let axis = |n_out: usize, n_in: usize| -> Vec<(usize, [f32; TAPS], usize)> {
        (0..n_out)
            .map(|o| {
                let pos = (o as f32 + 0.5) * n_in as f32 / n_out as f32 - 0.5;
                let first = (pos.round() as isize - 1).clamp(0, n_in.saturating_sub(TAPS) as isize)
                    as usize;
                let weights = std::array::from_fn(|t| {
                    let d = (first + t) as f32 - pos;
                    if first + t < n_in {
                        (-d * d / (2.0 * SPATIAL_SIGMA * SPATIAL_SIGMA)).exp()
                    } else {
                        0.0
                    }
                });
                (first, weights, super::frame::nearest_index(o, n_in, n_out))
            })
            .collect()
    };
    let (rows, cols) = (axis(h, hd), axis(w, wd));
    let mut out = vec![0f32; h * w];
    let mut valid = vec![false; h * w];
    out.par_chunks_mut(w)
        .zip(valid.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (row, valid_row))| {
            let (fy, wy, ny) = rows[y];
            let line = y * w;
            for (x, (o, v)) in row.iter_mut().zip(valid_row.iter_mut()).enumerate() {
                let (fx, wx, nx) = cols[x];
                let c = [g0[line + x], g1[line + x], g2[line + x]];
                // Over valid samples: the depth's weighted sum; over all: the weight, for the validity.
                let (mut num, mut den, mut all) = (0.0f32, 0.0f32, 0.0f32);
                // The span of the valid samples met: the mean is clamped into it, so that samples of one depth
                // give exactly that depth (a rounding off it would widen a one-depth frame's range).
                let (mut lo, mut hi) = (f32::MAX, f32::MIN);
                for (ty, &sy) in wy.iter().enumerate() {
                    if sy == 0.0 {
                        continue;
                    }
                    let start = (fy + ty) * wd + fx;
                    let end = (start + TAPS).min((fy + ty + 1) * wd);
                    for (q, &sx) in low.samples[start..end].iter().zip(&wx) {
                        let d2 = (c[0] - q[0]) * (c[0] - q[0])
                            + (c[1] - q[1]) * (c[1] - q[1])
                            + (c[2] - q[2]) * (c[2] - q[2]);
                        let k = ((d2 * scale) as usize).min(TABLE - 1);
                        let wgt = sy * sx * table[k];
                        all += wgt;
                        num += wgt * q[3];
                        den += wgt * q[4];
                        if q[4] > 0.0 && wgt > 0.0 {
                            lo = lo.min(q[3]);
                            hi = hi.max(q[3]);
                        }
                    }
                }
                // Valid where the valid samples carry at least half the weight: a hole's edge follows the
                // colour's edge as the depth's does. Where no sample resembles the pixel, nearest's answer.
                if all > 0.0 {
                    *v = den > 0.0 && den >= 0.5 * all;
                    *o = if *v { (num / den).clamp(lo, hi) } else { 0.0 };
                } else {
                    let q = low.samples[ny * wd + nx];
                    *v = q[4] > 0.0;
                    *o = q[3];
                }
            }
        });
    let values = Array2::from_shape_vec((h, w), out).expect("h·w values");
    let valid = Array2::from_shape_vec((h, w), valid).expect("h·w flags");
    // A map whose few valid samples all lost the vote (a tiny map): nearest's, never none where some exist.
    if !valid.iter().any(|&v| v) && low.samples.iter().any(|q| q[4] > 0.0) {
        return DecodedDepth {
            metric,
            ..low.nearest((hd, wd), (h, w))
        };
    }
    DecodedDepth {
        values,
        valid,
        metric,
    }
}

/// The low-resolution samples flattened, each `[R, G, B, depth, valid]`: the colour at the sample's centre,
/// its depth (0 where invalid, bounded by [`MAX_SUMMED_DEPTH`]) and 1 or 0.
struct LowRes {
    samples: Vec<[f32; 5]>,
}

impl LowRes {
    fn new(
        values: &Array2<f32>,
        valid: &Array2<bool>,
        guide: &ArrayView3<f32>,
        (h, w): (usize, usize),
    ) -> Self {
        let (hd, wd) = values.dim();
        // The output pixel at each sample's centre.
        let centre =
            |q: usize, n_in: usize, n_out: usize| super::frame::nearest_index(q, n_out, n_in);
        let mut samples = Vec::with_capacity(hd * wd);
        for qy in 0..hd {
            for qx in 0..wd {
                let (y, x) = (centre(qy, hd, h), centre(qx, wd, w));
                let ok = valid[[qy, qx]];
                samples.push([
                    guide[[0, y, x]],
                    guide[[1, y, x]],
                    guide[[2, y, x]],
                    // Bounded so that a weighted sum of 9 cannot overflow f32: a sensor's extreme depths
                    // (1/disparity of a tiny disparity: 4e37 m) lie beyond any display's range anyway.
                    if ok {
                        values[[qy, qx]].min(MAX_SUMMED_DEPTH)
                    } else {
                        0.0
                    },
                    f32::from(u8::from(ok)),
                ]);
            }
        }
        Self { samples }
    }

    /// Nearest neighbour's map of these samples at `h × w`.
    fn nearest(&self, (hd, wd): (usize, usize), (h, w): (usize, usize)) -> DecodedDepth {
        let values = Array2::from_shape_fn((hd, wd), |(y, x)| self.samples[y * wd + x][3]);
        let valid = Array2::from_shape_fn((hd, wd), |(y, x)| self.samples[y * wd + x][4] > 0.0);
        DecodedDepth {
            values: super::frame::resize_nearest(&values, h, w),
            valid: super::frame::resize_nearest(&valid, h, w),
            metric: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    fn decoded(h: usize, w: usize, f: impl Fn(usize, usize) -> Option<f32>) -> DecodedDepth {
        DecodedDepth {
            values: Array2::from_shape_fn((h, w), |(y, x)| f(y, x).unwrap_or(0.0)),
            valid: Array2::from_shape_fn((h, w), |(y, x)| f(y, x).is_some()),
            metric: true,
        }
    }

    #[test]
    fn a_map_of_any_size_keeps_its_valid_samples() {
        let guide = Array3::from_shape_fn((3, 4, 3), |(c, y, x)| {
            ((c * 5 + y * 3 + x * 7) % 11) as f32 / 10.0
        });
        for (hd, wd) in [(5, 1), (1, 5), (2, 2), (8, 6), (1, 1)] {
            let d = upsample_depth(
                decoded(hd, wd, |_, _| Some(1.5)),
                guide.view(),
                DepthUpsampling::JointBilateral,
            );
            assert_eq!(d.values.dim(), (4, 3));
            assert!(d.valid.iter().any(|&v| v), "{hd}x{wd}: {:?}", d.valid);
            for (v, ok) in d.values.iter().zip(&d.valid) {
                if *ok {
                    assert!((v - 1.5).abs() < 1e-6, "{hd}x{wd}: {v}");
                }
            }
        }
    }

    #[test]
    fn a_half_valid_row_keeps_a_valid_pixel() {
        let guide = Array3::from_shape_fn((3, 1, 8), |(c, _, x)| ((x * 3 + c) % 5) as f32 / 4.0);
        let d = upsample_depth(
            decoded(1, 2, |_, x| (x == 0).then_some(2.0)),
            guide.view(),
            DepthUpsampling::JointBilateral,
        );
        assert!(d.valid.iter().any(|&v| v), "{:?} {:?}", d.valid, d.values);
    }

    /// An edge in the colour that the depth map's blocks cross: the joint bilateral result follows the colour
    /// (left half near, right half far), where nearest neighbour follows the blocks.
    #[test]
    fn the_depth_edge_follows_the_colour_edge() {
        let (h, w) = (16, 16);
        // The colour's edge at column 6; the depth at 1/4 puts its block edge at column 8.
        let guide = Array3::from_shape_fn((3, h, w), |(_, _, x)| if x < 6 { 0.2 } else { 0.8 });
        let low = decoded(4, 4, |_, x| Some(if 4 * x + 2 < 6 { 1.0 } else { 3.0 }));
        let jbu = upsample_depth(low.clone(), guide.view(), DepthUpsampling::JointBilateral);
        let nearest = upsample_depth(low, guide.view(), DepthUpsampling::Nearest);
        for y in 0..h {
            for x in 0..w {
                let want = if x < 6 { 1.0 } else { 3.0 };
                assert!(
                    (jbu.values[[y, x]] - want).abs() < 0.05,
                    "({y}, {x}): {}",
                    jbu.values[[y, x]]
                );
            }
        }
        // Nearest keeps the block's edge: columns 4 and 5 read the far sample.
        assert!(
            (nearest.values[[0, 4]] - 3.0).abs() < 1e-6,
            "{}",
            nearest.values[[0, 4]]
        );
    }
}
