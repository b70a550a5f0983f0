//! The periphery of a foveated frame and its blend with the fovea: the gaze's depth ([`gaze_depth`]), the
//! colour image blurred per pixel by the defocus at its depth, turned to the band's phase and blended into
//! the CNN's field ([`Periphery::compose`]).
//!
//! The blur of a pixel is the mean of the colour's amplitude over a square of the area of a disc of radius
//! `r = κ·|d − d_g|·ρ` pixels (`ρ = V·λ/(2p²)`): side `L = r·√π`, half-width `h = (L − 1)/2`, the mean of
//! the squares of half-widths `⌊h⌋` and `⌊h⌋ + 1` weighted by the fraction of `h` (so the blur grows
//! continuously with the depth difference), each clipped to the frame. The sums come from a summed-area table
//! of each band of rows (f64: exact to far below an f32's rounding), built by the band's task: one pass over
//! the frame, no table of the whole frame.

use std::f64::consts::{PI, TAU};
use std::sync::Mutex;

use rayon::prelude::*;
use tensorholo_kernels::box_blur::{box_means, Defocus, SatRow};
use tensorholo_kernels::Isa;

use super::gaze::{Gaze, GAZE_DEPTH_WINDOW_PX};
use super::geometry::TileGeometry;
use crate::error::{HoloError, Result};

/// The scene's normalised depth at `gaze`: the median (the upper middle) of `depth` (`[H, W]`) over the
/// `(2·GAZE_DEPTH_WINDOW_PX + 1)²` window around the gaze's nearest pixel, clipped to the frame. `window`
/// holds the values (its capacity is kept: no allocation after the first frame).
pub(crate) fn gaze_depth(
    depth: &[f32],
    (height, width): (usize, usize),
    gaze: &Gaze,
    window: &mut Vec<f32>,
) -> f32 {
    let k = GAZE_DEPTH_WINDOW_PX;
    let centre = |g: f64, n: usize| (g.round().max(0.0) as usize).min(n - 1);
    let (cy, cx) = (centre(gaze.y, height), centre(gaze.x, width));
    window.clear();
    for y in cy.saturating_sub(k)..=(cy + k).min(height - 1) {
        let row = &depth[y * width..(y + 1) * width];
        window.extend_from_slice(&row[cx.saturating_sub(k)..=(cx + k).min(width - 1)]);
    }
    let mid = window.len() / 2;
    let (_, m, _) = window.select_nth_unstable_by(mid, f32::total_cmp);
    *m
}

/// One colour's inputs to [`Periphery::compose`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct ColourInputs<'a> {
    /// The frame's amplitude of this colour, `[H, W]`.
    pub(crate) amplitude: &'a [f32],
    /// A calibration's intensity scale map of this colour (`[H, W]`, multiplying the amplitude), if any.
    pub(crate) scale: Option<&'a [f32]>,
    /// The CNN's heads of this colour on the tile, `[T_h, T_w]` each: amplitude and phase.
    pub(crate) tile_heads: (&'a [f32], &'a [f32]),
    /// Blur radius per unit of normalised depth difference, pixels: `κ·V·λ/(2p²)`.
    pub(crate) blur_px: f64,
}

/// What every colour of one frame shares in [`Periphery::compose`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct FrameInputs<'a> {
    /// The frame's normalised depth, `[H, W]`.
    pub(crate) depth: &'a [f32],
    /// The gaze point `(x, y)`, pixels.
    pub(crate) gaze: (f64, f64),
    /// The gaze's normalised depth.
    pub(crate) gaze_depth: f32,
    /// The tile's top-left pixel `(y, x)`.
    pub(crate) origin: (usize, usize),
}

/// The buffers of a session's foveated frames: a summed-area table per thread of the pool that runs
/// [`Periphery::compose`], and the gaze window's values.
#[derive(Debug)]
pub(crate) struct Periphery {
    geometry: TileGeometry,
    /// Rows of the output per task.
    band_rows: usize,
    /// The largest box half-width any pixel can ask for (`⌊h⌋ + 1` at the largest depth difference).
    reach: usize,
    tables: Vec<Mutex<Vec<f64>>>,
    /// `1/(2k + 1)²` for `k ≤ reach`: the area of a box the frame does not clip.
    inv_area: Vec<f64>,
    /// The gaze window's depths ([`gaze_depth`]).
    pub(crate) window: Vec<f32>,
    /// The kernels' level for the unclipped boxes.
    isa: Isa,
}

impl Periphery {
    /// The buffers for frames of `geometry` whose largest blur radius (a depth difference of 1) is
    /// `max_blur_px` pixels, composed on `threads` threads with the kernels of level `isa`.
    pub(crate) fn new(geometry: TileGeometry, max_blur_px: f64, threads: usize, isa: Isa) -> Self {
        let (height, width) = geometry.frame;
        let reach = (half_width(max_blur_px).floor() as usize + 1).min(height.max(width));
        let band_rows = 64.max(2 * reach).min(height);
        let rows = (band_rows + 2 * reach).min(height) + 1;
        let tables = (0..threads.max(1))
            .map(|_| Mutex::new(vec![0.0; rows * (width + 1)]))
            .collect();
        let side = 2 * GAZE_DEPTH_WINDOW_PX + 1;
        Self {
            geometry,
            band_rows,
            reach,
            tables,
            inv_area: (0..=reach)
                .map(|k| 1.0 / ((2 * k + 1) * (2 * k + 1)) as f64)
                .collect(),
            window: Vec::with_capacity(side * side),
            isa,
        }
    }

    /// The geometry this periphery composes.
    pub(crate) fn geometry(&self) -> &TileGeometry {
        &self.geometry
    }

    /// Writes the foveated midpoint hologram's heads into `out` (amplitude R, G, B then phase R, G, B,
    /// `[H, W]` each, the heads' convention: `A·e^{i(p − 0.5)2π}`): the tile's CNN heads within `R` of the gaze,
    /// the blurred amplitude at the band's phase beyond `R + B`, their linear blend between. Returns each
    /// colour's periphery phase (radians). Runs its parallel iterators on the caller's pool.
    ///
    /// Errors: [`HoloError::Internal`] for planes of the wrong length (the session sizes them).
    pub(crate) fn compose(
        &self,
        frame: FrameInputs<'_>,
        colours: [ColourInputs<'_>; 3],
        out: [&mut [f32]; 6],
    ) -> Result<[f32; 3]> {
        let (h, w) = self.geometry.frame;
        let (th, tw) = self.geometry.tile;
        let n = h * w;
        let bad = out.iter().any(|p| p.len() != n)
            || frame.depth.len() != n
            || colours.iter().any(|c| {
                c.amplitude.len() != n
                    || c.scale.is_some_and(|s| s.len() != n)
                    || c.tile_heads.0.len() != th * tw
                    || c.tile_heads.1.len() != th * tw
            });
        if bad {
            return Err(HoloError::Internal(
                "foveated frame: planes of the wrong size".into(),
            ));
        }
        let mut phases = [0.0f64; 3];
        phases
            .par_iter_mut()
            .zip(colours)
            .for_each(|(t, c)| *t = self.band_phase(&frame, &c));
        let [a0, a1, a2, p0, p1, p2] = out;
        let work = [(a0, p0), (a1, p1), (a2, p2)];
        work.into_par_iter().zip(colours).zip(phases).try_for_each(
            |(((amp, phase), colour), theta)| {
                let rows = self.band_rows * w;
                amp.par_chunks_mut(rows)
                    .zip(phase.par_chunks_mut(rows))
                    .enumerate()
                    .try_for_each(|(band, (amp, phase))| {
                        let y0 = band * self.band_rows;
                        self.compose_band(&frame, &colour, theta, y0, amp, phase)
                    })
            },
        )?;
        Ok(phases.map(|t| t as f32))
    }

    /// The periphery's phase of one colour: `arg Σ_band U_cnn·A` over the band's pixels, `A` the colour's
    /// amplitude (the periphery's field before its blur: the phase that best aligns the two fields, at one
    /// multiply-add a pixel), summed in row order; 0 where the sum vanishes.
    fn band_phase(&self, frame: &FrameInputs<'_>, colour: &ColourInputs<'_>) -> f64 {
        let g = &self.geometry;
        let (h, w) = g.frame;
        let (gx, gy) = frame.gaze;
        let (r_in2, r_out) = (g.radius_px * g.radius_px, g.radius_px + g.band_px);
        let r_out2 = r_out * r_out;
        let (mut re, mut im) = (0.0f64, 0.0f64);
        for y in row_span(gy, r_out, h) {
            let dy = y as f64 - gy;
            let outer = row_span(gx, (r_out2 - dy * dy).max(0.0).sqrt(), w);
            // The fovea's chord, one pixel short at each end (surely inside `R`), is skipped whole.
            let inner = if dy * dy < r_in2 {
                let s = row_span(gx, (r_in2 - dy * dy).sqrt() - 1.0, w);
                s.start.max(outer.start)..s.end.min(outer.end)
            } else {
                outer.start..outer.start
            };
            let inner = inner.start..inner.end.max(inner.start);
            for x in (outer.start..inner.start).chain(inner.end..outer.end) {
                let dx = x as f64 - gx;
                let r2 = dx * dx + dy * dy;
                if r2 <= r_in2 || r2 >= r_out2 {
                    continue;
                }
                let (a, p) = tile_head(g, frame.origin, colour.tile_heads, y, x);
                let amplitude = f64::from(a) * f64::from(amplitude_at(colour, y * w + x));
                let phi = (f64::from(p) - 0.5) * TAU;
                re += amplitude * phi.cos();
                im += amplitude * phi.sin();
            }
        }
        if re == 0.0 && im == 0.0 {
            0.0
        } else {
            im.atan2(re)
        }
    }

    /// Rows `y0..` of one colour's heads (`amp`, `phase`: whole rows).
    fn compose_band(
        &self,
        frame: &FrameInputs<'_>,
        colour: &ColourInputs<'_>,
        theta: f64,
        y0: usize,
        amp: &mut [f32],
        phase: &mut [f32],
    ) -> Result<()> {
        let g = &self.geometry;
        let (h, w) = g.frame;
        let y1 = y0 + amp.len() / w;
        let (ys, ye) = (y0.saturating_sub(self.reach), (y1 + self.reach).min(h));
        let slot = rayon::current_thread_index().unwrap_or(0) % self.tables.len();
        let mut table = self.tables[slot]
            .lock()
            .map_err(|_| HoloError::Internal("a periphery table was poisoned".into()))?;
        let stride = w + 1;
        let table = &mut table[..(ye - ys + 1) * stride];
        summed_area(colour, w, ys..ye, table);
        let (gx, gy) = frame.gaze;
        let (r_in, r_out) = (g.radius_px, g.radius_px + g.band_px);
        let (cos_t, sin_t) = (theta.cos(), theta.sin());
        let periphery_p = (theta / TAU + 0.5) as f32;
        let inv_area = &self.inv_area;
        // The half-width, at most `reach − 1` (the table's rows; a depth outside [0, 1] is clamped there).
        let max_hw = (self.reach - 1) as f64;
        let box_mean = |y: usize, x: usize, k: usize| {
            let (r0, r1) = (y.saturating_sub(k), (y + k).min(h - 1));
            let (c0, c1) = (x.saturating_sub(k), (x + k).min(w - 1));
            let (t0, t1) = ((r0 - ys) * stride, (r1 + 1 - ys) * stride);
            let sum = table[t1 + c1 + 1] - table[t0 + c1 + 1] - table[t1 + c0] + table[t0 + c0];
            let n = (r1 - r0 + 1) * (c1 - c0 + 1);
            match inv_area.get(k) {
                Some(&inv) if n == (2 * k + 1) * (2 * k + 1) => sum * inv,
                _ => sum / n as f64,
            }
        };
        let blurred = |y: usize, x: usize, d: f32| {
            let hw = half_width(blur_radius(colour.blur_px, d, frame.gaze_depth)).min(max_hw);
            let k = hw.floor();
            let t = hw - k;
            let k = k as usize;
            let m = box_mean(y, x, k);
            if t > 0.0 {
                m + t * (box_mean(y, x, k + 1) - m)
            } else {
                m
            }
        };
        let (r_in2, r_out2) = (r_in * r_in, r_out * r_out);
        // `h = |d − d_g|·scale − 1/2` ([`half_width`] of [`blur_radius`]).
        let scale = colour.blur_px * PI.sqrt() / 2.0;
        for (i, (arow, prow)) in amp
            .chunks_exact_mut(w)
            .zip(phase.chunks_exact_mut(w))
            .enumerate()
        {
            let y = y0 + i;
            let dy = y as f64 - gy;
            let drow = &frame.depth[y * w..(y + 1) * w];
            // The columns within R + B of the gaze on this row (none beyond it): the rest is periphery.
            let near = row_span(gx, (r_out2 - dy * dy).max(0.0).sqrt(), w);
            let near = if dy * dy < r_out2 { near } else { 0..0 };
            // Rows whose every box stays inside the frame: the boxes' corners without clipping, on the columns
            // `fast` (a box of half-width `reach` fits); elsewhere the clipped means.
            let fast = if y >= self.reach && y + self.reach < h {
                self.reach.min(w)..w.saturating_sub(self.reach)
            } else {
                0..0
            };
            for seg in [0..near.start, near.end..w] {
                prow[seg.clone()].fill(periphery_p);
                let a = seg.start.max(fast.start).min(seg.end);
                let b = seg.end.min(fast.end).max(a);
                for x in (seg.start..a).chain(b..seg.end) {
                    arow[x] = blurred(y, x, drow[x]) as f32;
                }
                // The unclipped boxes, vectorised ([`tensorholo_kernels::box_blur`]).
                box_means(
                    SatRow {
                        table,
                        stride,
                        row: y - ys,
                        x0: a,
                    },
                    &drow[a..b],
                    Defocus {
                        gaze_depth: frame.gaze_depth,
                        scale,
                        max_half: max_hw,
                    },
                    &mut arow[a..b],
                    self.isa,
                )?;
            }
            for x in near {
                let dx = x as f64 - gx;
                let r2 = dx * dx + dy * dy;
                if r2 <= r_in2 {
                    (arow[x], prow[x]) = tile_head(g, frame.origin, colour.tile_heads, y, x);
                    continue;
                }
                let m = blurred(y, x, drow[x]);
                if r2 >= r_out2 {
                    arow[x] = m as f32;
                    prow[x] = periphery_p;
                    continue;
                }
                let wgt = (r_out - r2.sqrt()) / g.band_px;
                let (ta, tp) = tile_head(g, frame.origin, colour.tile_heads, y, x);
                let phi = (f64::from(tp) - 0.5) * TAU;
                let re = wgt * f64::from(ta) * phi.cos() + (1.0 - wgt) * m * cos_t;
                let im = wgt * f64::from(ta) * phi.sin() + (1.0 - wgt) * m * sin_t;
                arow[x] = (re * re + im * im).sqrt() as f32;
                prow[x] = (im.atan2(re) / TAU + 0.5) as f32;
            }
        }
        Ok(())
    }
}

/// The blur's disc radius in pixels at normalised depth `d` for a gaze at `d_g`: `blur_px·|d − d_g|`.
fn blur_radius(blur_px: f64, d: f32, d_g: f32) -> f64 {
    blur_px * f64::from((d - d_g).abs())
}

/// The continuous half-width `h = (r·√π − 1)/2 ≥ 0` of the square of a disc's area (`r` its radius).
pub(crate) fn half_width(radius: f64) -> f64 {
    ((radius * PI.sqrt() - 1.0) / 2.0).max(0.0)
}

/// The pixels of a row (or column) within `reach` of `g` on a line of `n`.
pub(crate) fn row_span(g: f64, reach: f64, n: usize) -> std::ops::Range<usize> {
    let lo = (g - reach).ceil().max(0.0) as usize;
    let hi = ((g + reach).floor().max(-1.0) + 1.0).min(n as f64) as usize;
    lo.min(n)..hi.max(lo.min(n))
}

/// The tile's heads `(A, p)` of one colour at frame pixel `(y, x)` (inside the tile by the geometry).
fn tile_head(
    g: &TileGeometry,
    (oy, ox): (usize, usize),
    (amp, phase): (&[f32], &[f32]),
    y: usize,
    x: usize,
) -> (f32, f32) {
    let i = (y - oy) * g.tile.1 + (x - ox);
    (amp[i], phase[i])
}

/// The colour's amplitude at pixel `i`, times its intensity scale map.
fn amplitude_at(colour: &ColourInputs<'_>, i: usize) -> f32 {
    match colour.scale {
        Some(s) => colour.amplitude[i] * s[i],
        None => colour.amplitude[i],
    }
}

/// Rows of the table built together: each row's running sum is a chain of additions as slow as their
/// latency, and [`SAT_GROUP`] independent chains keep the adder busy.
const SAT_GROUP: usize = 4;

/// The summed-area table of the colour's amplitude (times its scale map, where it has one) over the frame
/// rows `rows` (all `w` columns) into `table` (`(rows + 1) × (w + 1)`, row 0 and column 0 zero):
/// `table[i + 1][x + 1]` is the sum over the first `i + 1` rows and the first `x + 1` columns, each row's
/// running sum (f64, left to right) added to the table's row above. Rows without a scale map are built
/// [`SAT_GROUP`] at a time, in one pass over their columns.
fn summed_area(
    colour: &ColourInputs<'_>,
    w: usize,
    rows: std::ops::Range<usize>,
    table: &mut [f64],
) {
    let (amplitude, scale) = (colour.amplitude, colour.scale);
    let stride = w + 1;
    table[..stride].fill(0.0);
    let value = |y: usize, x: usize| match scale {
        Some(s) => f64::from(amplitude[y * w + x] * s[y * w + x]),
        None => f64::from(amplitude[y * w + x]),
    };
    let mut y = rows.start;
    let mut i = 0;
    while y < rows.end {
        // Table rows `i ..= i + g`: row `i` done, rows `i + 1 ..= i + g` written here.
        let g = (rows.end - y).min(SAT_GROUP);
        let group = &mut table[i * stride..(i + g + 1) * stride];
        if g == SAT_GROUP && scale.is_none() {
            let (above, below) = group.split_at_mut(stride);
            let (t1, below) = below.split_at_mut(stride);
            let (t2, below) = below.split_at_mut(stride);
            let (t3, t4) = below.split_at_mut(stride);
            let (above, t1, t2, t3, t4) = (
                &above[1..=w],
                &mut t1[1..=w],
                &mut t2[1..=w],
                &mut t3[1..=w],
                &mut t4[1..=w],
            );
            let (a0, a1, a2, a3) = (
                &amplitude[y * w..][..w],
                &amplitude[(y + 1) * w..][..w],
                &amplitude[(y + 2) * w..][..w],
                &amplitude[(y + 3) * w..][..w],
            );
            let (mut c0, mut c1, mut c2, mut c3) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for x in 0..w {
                c0 += f64::from(a0[x]);
                c1 += f64::from(a1[x]);
                c2 += f64::from(a2[x]);
                c3 += f64::from(a3[x]);
                t1[x] = above[x] + c0;
                t2[x] = t1[x] + c1;
                t3[x] = t2[x] + c2;
                t4[x] = t3[x] + c3;
            }
        } else {
            for r in 0..g {
                let mut acc = 0.0f64;
                for x in 0..w {
                    acc += value(y + r, x);
                    group[(r + 1) * stride + x + 1] = group[r * stride + x + 1] + acc;
                }
            }
        }
        for r in 1..=g {
            group[r * stride] = 0.0;
        }
        y += g;
        i += g;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gaze(x: f64, y: f64) -> Gaze {
        Gaze {
            x,
            y,
            depth_m: None,
        }
    }

    /// One pixel's blurred amplitude by direct sums: the naive reference of the tables' means.
    fn direct_blur(
        frame: &FrameInputs<'_>,
        colour: &ColourInputs<'_>,
        (h, w): (usize, usize),
        y: usize,
        x: usize,
    ) -> f64 {
        let hw = half_width(blur_radius(
            colour.blur_px,
            frame.depth[y * w + x],
            frame.gaze_depth,
        ));
        let k = hw.floor();
        let t = hw - k;
        let mean = |k: usize| {
            let (mut sum, mut count) = (0.0f64, 0usize);
            for yy in y.saturating_sub(k)..=(y + k).min(h - 1) {
                for xx in x.saturating_sub(k)..=(x + k).min(w - 1) {
                    sum += f64::from(amplitude_at(colour, yy * w + xx));
                    count += 1;
                }
            }
            sum / count as f64
        };
        let m = mean(k as usize);
        if t > 0.0 {
            m + t * (mean(k as usize + 1) - m)
        } else {
            m
        }
    }

    #[test]
    fn the_gaze_depth_is_the_window_median_clipped_to_the_frame() {
        let (h, w) = (30, 40);
        // Depth = column / 100: the median of a window is its centre column's, also near an edge.
        let depth: Vec<f32> = (0..h * w).map(|i| (i % w) as f32 / 100.0).collect();
        let mut window = Vec::new();
        assert_eq!(
            gaze_depth(&depth, (h, w), &gaze(20.2, 10.0), &mut window),
            0.20
        );
        // At the left edge the window holds columns 0..=8: its median is column 4.
        assert_eq!(
            gaze_depth(&depth, (h, w), &gaze(-0.5, 29.5), &mut window),
            0.04
        );
        // A few outliers (an edge under the gaze) do not move the median.
        let mut spiky = vec![0.5f32; h * w];
        for x in 10..30 {
            spiky[15 * w + x] = 0.0;
        }
        assert_eq!(
            gaze_depth(&spiky, (h, w), &gaze(20.0, 15.0), &mut window),
            0.5
        );
    }

    /// The tables' blur equals the direct sums; the fovea holds the tile's heads bit for bit; the periphery
    /// is the blurred amplitude at the band's phase; the band blends linearly.
    #[test]
    fn compose_matches_a_naive_reference() {
        let (h, w) = (70, 90);
        let geometry = TileGeometry::new(12.0, 6.0, 3, h, w);
        let periphery = Periphery::new(geometry, 9.0, 3, Isa::detect());
        let amplitude: Vec<Vec<f32>> = (0..3)
            .map(|c| {
                (0..h * w)
                    .map(|i| ((i * (7 + c) + i / w * 13) % 29) as f32 / 29.0)
                    .collect()
            })
            .collect();
        let depth: Vec<f32> = (0..h * w)
            .map(|i| ((i * 5 + i / w) % 23) as f32 / 22.0)
            .collect();
        let g = gaze(40.3, 33.7);
        let origin = geometry.origin(&g);
        let (th, tw) = geometry.tile;
        let tile: Vec<Vec<f32>> = (0..6)
            .map(|c| {
                (0..th * tw)
                    .map(|i| ((i * 3 + c) % 11) as f32 / 10.0)
                    .collect()
            })
            .collect();
        let frame = FrameInputs {
            depth: &depth,
            gaze: (g.x, g.y),
            gaze_depth: 0.4,
            origin,
        };
        let colours = [0, 1, 2].map(|c| ColourInputs {
            amplitude: &amplitude[c],
            scale: None,
            tile_heads: (&tile[c], &tile[3 + c]),
            blur_px: 3.0 + 3.0 * c as f64,
        });
        let mut out = vec![vec![0.0f32; h * w]; 6];
        let [o0, o1, o2, o3, o4, o5] = &mut out[..] else {
            unreachable!()
        };
        let phases = periphery
            .compose(frame, colours, [o0, o1, o2, o3, o4, o5])
            .unwrap();
        let mut checked = [0usize; 3];
        for c in 0..3 {
            let theta = f64::from(phases[c]);
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    let (a, p) = (out[c][i], out[3 + c][i]);
                    let r = (x as f64 - g.x).hypot(y as f64 - g.y);
                    let head = || tile_head(&geometry, origin, colours[c].tile_heads, y, x);
                    if r <= 12.0 {
                        let (ta, tp) = head();
                        assert_eq!((a.to_bits(), p.to_bits()), (ta.to_bits(), tp.to_bits()));
                        checked[0] += 1;
                        continue;
                    }
                    let m = direct_blur(&frame, &colours[c], (h, w), y, x);
                    let u2 = num_complex::Complex64::from_polar(m, theta);
                    let want = if r >= 18.0 {
                        checked[2] += 1;
                        u2
                    } else {
                        checked[1] += 1;
                        let wgt = (18.0 - r) / 6.0;
                        let (ta, tp) = head();
                        let cnn = num_complex::Complex64::from_polar(
                            f64::from(ta),
                            (f64::from(tp) - 0.5) * TAU,
                        );
                        cnn * wgt + u2 * (1.0 - wgt)
                    };
                    let got = num_complex::Complex64::from_polar(
                        f64::from(a),
                        (f64::from(p) - 0.5) * TAU,
                    );
                    assert!(
                        (got - want).norm() < 1e-5,
                        "colour {c} pixel ({y}, {x}): {got} vs {want}"
                    );
                }
            }
        }
        assert!(checked.iter().all(|&n| n > 100), "{checked:?}");
        // A blur that grows with the depth difference: at the gaze's depth the periphery is the image.
        let flat = vec![0.4f32; h * w];
        let frame = FrameInputs {
            depth: &flat,
            ..frame
        };
        let mut out = vec![vec![0.0f32; h * w]; 6];
        let [o0, o1, o2, o3, o4, o5] = &mut out[..] else {
            unreachable!()
        };
        periphery
            .compose(frame, colours, [o0, o1, o2, o3, o4, o5])
            .unwrap();
        assert_eq!(out[1][0], amplitude[1][0]);
        assert_eq!(out[2][h * w - 1], amplitude[2][h * w - 1]);
        // Depths outside [0, 1] blur no further than the largest difference the tables hold.
        let wild = vec![40.0f32; h * w];
        let frame = FrameInputs {
            depth: &wild,
            ..frame
        };
        let [o0, o1, o2, o3, o4, o5] = &mut out[..] else {
            unreachable!()
        };
        periphery
            .compose(frame, colours, [o0, o1, o2, o3, o4, o5])
            .unwrap();
        assert!(out[0].iter().all(|v| v.is_finite()));
    }
}
