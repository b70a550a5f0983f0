//! The tiles of a session's foveated frames ([`crate::foveation`]): [`FoveatedState`], what a foveated session
//! keeps (the hologram CNN's plan for its tile and the tile's buffers, the periphery's tables, the pre-filter
//! on its own tile with its base filter elsewhere, the last frame's report). The frame that uses them is
//! `foveated` (`HologramSession::render_foveated`); this file imports nothing of the session.

use std::sync::Arc;

use ndarray::{s, Array3};
use rayon::prelude::*;
use tensorholo_kernels::{depthwise_rows, Isa};

use super::cnn_stage::CnnStage;
use super::colour::ColourState;
use super::models::HologramPipeline;
use crate::cnn::{CnnPlan, CnnPlans, PlanRequest};
use crate::error::{HoloError, Result};
use crate::foveation::{row_span, FoveaReport, FoveationOptions, Gaze, Periphery, TileGeometry};
use crate::model::contract;
use crate::model::graph::CnnOutput;

/// What a foveated session keeps between frames: the tile's CNN and buffers, the periphery's tables, the
/// last frame's report.
#[derive(Debug)]
pub(super) struct FoveatedState {
    pub(super) radius_deg: Option<f64>,
    /// The hologram CNN's plan for the tile (same engine and options as the frame's), with its input buffer.
    pub(super) cnn: CnnStage,
    /// The tile's heads: amplitude R, G, B then phase R, G, B, `T_h·T_w` values each.
    pub(super) heads: Vec<f32>,
    pub(super) periphery: Periphery,
    /// `κ·V·λ/(2p²)` per colour: the blur radius at a depth difference of 1, pixels.
    pub(super) blur_px: [f64; 3],
    /// The display's volume depth, metres.
    pub(super) volume_m: f64,
    /// The pre-filter CNN on its own tile (a session with a pre-filter whose graph the native reader knows),
    /// its base filter elsewhere; `None`: the pre-filter runs on the whole frame.
    pub(super) prefilter: Option<PrefilterTile>,
    pub(super) report: Option<FoveaReport>,
    /// Whether the session's accelerator runs the foveated frames (`FrameExecutor::plan_foveated`).
    pub(super) on_accelerator: bool,
    /// The frame's amplitude after a calibration's intensity maps, `[3, H, W]`, for the accelerator (sized by
    /// the first calibrated frame).
    pub(super) scaled: Vec<f32>,
}

/// The pre-filter CNN of a foveated frame (`H' = base(H) + CNN(H)`, DDPM): the CNN's residual where the fovea's
/// light lies at the SLM, its depthwise base filter (the AA-DPM blur) everywhere.
///
/// The light the viewer sees in the fovea (`r < R + B`) at any focal plane of the volume left the SLM within
/// `(|s| + V/2)·tan(asin(λ/2p))/p` pixels of it (the SLM lies `|s|` from the midpoint plane, the focal planes
/// up to `V/2` beyond; the band-limited angular spectrum's largest angle, the reddest colour): within
/// `R_p = R + B + spread` of the gaze the frame keeps the whole pre-filter, exactly the full frame's for the
/// same field; the residual then fades linearly to 0 over [`PREFILTER_RAMP_PX`]. The tile holds that disc and
/// the pre-filter's receptive radius.
#[derive(Debug)]
pub(super) struct PrefilterTile {
    plan: Box<dyn CnnPlan>,
    /// `radius_px`: `R_p`; `band_px`: the residual's ramp; `margin`: the pre-filter's receptive radius.
    geometry: TileGeometry,
    /// The tile's input and output, six planes `[Re R, Re G, Re B, Im R, Im G, Im B]` of `T_h·T_w` values.
    input: Vec<f32>,
    output: Vec<f32>,
    /// The base filter `[6][taps][taps]`.
    base: Vec<f32>,
    taps: usize,
    isa: Isa,
}

/// Width in pixels over which a foveated frame's pre-filter residual fades out beyond `R_p`: the blend band's
/// width. Against a 64-pixel fade on the foveation tests' frames the fovea's scores moved by at most 0.06 dB and
/// the periphery's displayed scores rose (0.1–1.8 dB), with a tile of 633² pixels instead of 729² at 1080p.
const PREFILTER_RAMP_PX: f64 = 16.0;

/// The most input planes of a tile's hologram CNN passed without a list on the heap (an LDI CNN of 8 layers).
pub(super) const MAX_TILE_PLANES: usize = 32;

/// Rows per task of the base filter over the whole frame.
const BASE_ROWS: usize = 32;

impl FoveatedState {
    /// The foveated state of `pipeline`'s sessions at `height × width`: the tile's geometry from the options
    /// and the hologram CNN's receptive radius, its plan (made as the frame's, [`crate::cnn::select`]), the
    /// periphery's buffers for `threads` threads.
    ///
    /// Errors: the options' ([`FoveationOptions`]); the CNN engine's plan errors.
    pub(super) fn new(
        pipeline: &HologramPipeline,
        options: FoveationOptions,
        request: &PlanRequest,
        (height, width): (usize, usize),
        threads: usize,
    ) -> Result<Self> {
        let optics = pipeline.config().optics;
        let (radius_px, radius_deg) = options.radius_px(optics.pixel_pitch_m)?;
        let model = pipeline.hologram_model();
        // A 3 × 3 convolution reaches one pixel further: the receptive radius is the number of convolutions
        // (the graph's where the native reader knows it, else the file's declared layers).
        let margin = model
            .cnn_graph()
            .map_or(model.metadata().layers, |g| g.layers.len());
        let geometry = TileGeometry::new(radius_px, options.band_px, margin, height, width);
        let (th, tw) = geometry.tile;
        let CnnPlans { hologram, .. } = crate::cnn::select(model, None, th, tw, request)?;
        let p = optics.pixel_pitch_m;
        let blur_px = optics
            .wavelengths_m
            .map(|l| options.blur_scale * optics.volume_depth_m * l / (2.0 * p * p));
        let max_blur = blur_px.iter().copied().fold(0.0, f64::max);
        let (c, _, _) = hologram.input_dim();
        let spread = optics
            .wavelengths_m
            .iter()
            .map(|&l| {
                let reach_m = pipeline.config().offset_m.abs() + optics.volume_depth_m / 2.0;
                reach_m * (l / (2.0 * p)).asin().tan() / p
            })
            .fold(0.0, f64::max);
        let prefilter = match pipeline.prefilter_model() {
            Some(model) => PrefilterTile::new(
                model,
                radius_px + options.band_px + spread,
                request,
                (height, width),
            )?,
            None => None,
        };
        Ok(Self {
            radius_deg,
            cnn: CnnStage {
                plan: hologram,
                input: Array3::zeros((c, th, tw)),
                calibration: pipeline.calibration().cloned(),
                depth_fraction: pipeline.display_mapping().depth_fraction() as f32,
            },
            heads: vec![0.0; 6 * th * tw],
            periphery: Periphery::new(geometry, max_blur, threads, request.cnn.kernel_isa()?),
            blur_px,
            volume_m: optics.volume_depth_m,
            prefilter,
            report: None,
            on_accelerator: false,
            scaled: Vec::new(),
        })
    }

    /// Packs the tile at `origin` of the frame's planes (amplitude R, G, B, depth) into the tile CNN's input,
    /// as [`CnnStage::pack_frame`] packs a frame: the calibration's intensity maps on the amplitudes, the
    /// display's depth fraction on the depth, empty back layers for an LDI CNN.
    pub(super) fn pack_tile(
        &mut self,
        planes: [&[f32]; 4],
        width: usize,
        (oy, ox): (usize, usize),
    ) {
        let (c, th, tw) = self.cnn.input.dim();
        let k = self.cnn.depth_fraction;
        for (i, src) in planes.iter().enumerate() {
            let scale = (i < 3)
                .then(|| {
                    self.cnn
                        .calibration
                        .as_ref()
                        .and_then(|cal| cal.colours[i].intensity_scale.as_ref())
                        .and_then(|m| m.as_slice())
                })
                .flatten();
            let mut dst = self.cnn.input.slice_mut(s![i, .., ..]);
            for (ty, mut row) in dst.outer_iter_mut().enumerate() {
                let start = (oy + ty) * width + ox;
                let src = &src[start..start + tw];
                match (i, scale) {
                    (3, _) if k != 1.0 => {
                        row.iter_mut()
                            .zip(src)
                            .for_each(|(o, &d)| *o = 0.5 + (d - 0.5) * k);
                    }
                    (_, Some(scale)) => {
                        let scale = &scale[start..start + tw];
                        row.iter_mut()
                            .zip(src.iter().zip(scale))
                            .for_each(|(o, (&a, &s))| *o = a * s);
                    }
                    _ => row.iter_mut().zip(src).for_each(|(o, &v)| *o = v),
                }
            }
        }
        contract::fill_empty_layers(self.cnn.input.view_mut(), 1, c / 4);
        debug_assert_eq!(self.cnn.input.dim(), (c, th, tw));
    }

    /// Packs the tile at `origin` of the frame's planes ([`FoveatedState::pack_tile`]) and runs the hologram
    /// CNN on it, its heads into [`FoveatedState::heads`] (no allocation: the input planes listed on the
    /// stack for up to [`MAX_TILE_PLANES`] channels).
    ///
    /// Errors: the engine's run errors.
    pub(super) fn run_tile_cnn(
        &mut self,
        planes: [&[f32]; 4],
        width: usize,
        origin: (usize, usize),
    ) -> Result<()> {
        self.pack_tile(planes, width, origin);
        let (c, th, tw) = self.cnn.input.dim();
        let [a0, a1, a2, p0, p1, p2] = tile_planes(&mut self.heads, th * tw);
        let mut list: [&[f32]; MAX_TILE_PLANES] = [&[]; MAX_TILE_PLANES];
        let input = self.cnn.input.as_slice().unwrap_or_default();
        for (p, plane) in list.iter_mut().zip(input.chunks_exact(th * tw)) {
            *p = plane;
        }
        let out = [a0, a1, a2, p0, p1, p2];
        if c <= MAX_TILE_PLANES {
            self.cnn.plan.run_planes_into(&list[..c], out)
        } else {
            let input = CnnStage::planes_of(&self.cnn.input);
            self.cnn.plan.run_planes_into(&input, out)
        }
    }
}

impl PrefilterTile {
    /// The pre-filter's tile for a disc of radius `zone_px` (plus the ramp) on `height × width` frames;
    /// `None` where the native reader does not know the file's graph (its base filter): the whole frame's
    /// pre-filter runs then.
    ///
    /// Errors: the CNN engine's plan errors.
    fn new(
        model: &Arc<crate::model::HologramModel>,
        zone_px: f64,
        request: &PlanRequest,
        (height, width): (usize, usize),
    ) -> Result<Option<Self>> {
        let Ok(graph) = model.cnn_graph() else {
            return Ok(None);
        };
        let CnnOutput::Prefilter { taps, base } = &graph.output else {
            return Ok(None);
        };
        if graph.in_channels != 6
            || graph
                .quant
                .as_ref()
                .is_some_and(|q| q.base_reads_rounded_input)
        {
            return Ok(None);
        }
        let margin = graph.layers.len().max(taps / 2);
        let geometry = TileGeometry::new(zone_px, PREFILTER_RAMP_PX, margin, height, width);
        let (th, tw) = geometry.tile;
        let CnnPlans { hologram: plan, .. } = crate::cnn::select(model, None, th, tw, request)?;
        Ok(Some(Self {
            plan,
            geometry,
            input: vec![0.0; 6 * th * tw],
            output: vec![0.0; 6 * th * tw],
            base: base.clone(),
            taps: *taps,
            isa: request.cnn.kernel_isa()?,
        }))
    }

    /// The pre-filter of a foveated frame on the offset hologram the colour workers left (`Re H` in each
    /// colour's `phase`, `Im H` in the second half of its field), written where the whole frame's pre-filter
    /// writes (`Re H'` in the field's first half, `Im H'` in the frame's phase planes): the base filter on the
    /// whole frame (bands of rows on the pool's threads), the CNN on the tile, its residual blended in.
    ///
    /// Errors: the kernels' and the engine's run errors.
    pub(super) fn run(
        &mut self,
        states: [&mut ColourState; 3],
        phase: [&mut [f32]; 3],
        gaze: &Gaze,
        (height, width): (usize, usize),
    ) -> Result<()> {
        let n = height * width;
        let [r, g, b] = states;
        let [(ri, ro), (gi, go), (bi, bo)] = [r.prefilter_io(), g.prefilter_io(), b.prefilter_io()];
        let [rp, gp, bp] = phase;
        let inputs = contract::prefilter_planes([ri, gi, bi]);
        let mut outputs: [&mut [f32]; 6] = [ro, go, bo, rp, gp, bp];
        let (taps, isa, base) = (self.taps, self.isa, &self.base);
        // The base filter on every plane, bands of rows.
        outputs
            .par_iter_mut()
            .zip(inputs.par_iter())
            .enumerate()
            .try_for_each(|(ch, (out, input))| {
                let kernel = &base[ch * taps * taps..(ch + 1) * taps * taps];
                out[..n]
                    .par_chunks_mut(BASE_ROWS * width)
                    .enumerate()
                    .try_for_each(|(band, rows)| {
                        let y0 = band * BASE_ROWS;
                        let y1 = y0 + rows.len() / width;
                        depthwise_rows(input, height, width, kernel, taps, y0..y1, rows, false, isa)
                            .map_err(HoloError::from)
                    })
            })?;
        // The CNN on the tile.
        let (oy, ox) = self.geometry.origin(gaze);
        let (th, tw) = self.geometry.tile;
        let m = th * tw;
        for (ch, input) in inputs.iter().enumerate() {
            let tile = &mut self.input[ch * m..(ch + 1) * m];
            for (ty, row) in tile.chunks_exact_mut(tw).enumerate() {
                let start = (oy + ty) * width + ox;
                row.copy_from_slice(&input[start..start + tw]);
            }
        }
        {
            let mut planes: [&[f32]; 6] = [&[]; 6];
            for (p, plane) in planes.iter_mut().zip(self.input.chunks_exact(m)) {
                *p = plane;
            }
            let [a, b, c, d, e, f] = tile_planes(&mut self.output, m);
            self.plan.run_planes_into(&planes, [a, b, c, d, e, f])?;
        }
        // Its residual, blended in: weight 1 within R_p, fading to 0 over the ramp.
        let g = &self.geometry;
        let (r_in, r_out) = (g.radius_px, g.radius_px + g.band_px);
        let (r_in2, r_out2) = (r_in * r_in, r_out * r_out);
        outputs
            .par_iter_mut()
            .zip(self.output.par_chunks_exact(m))
            .for_each(|(out, tile)| {
                for (ty, trow) in tile.chunks_exact(tw).enumerate() {
                    let y = oy + ty;
                    let dy = y as f64 - gaze.y;
                    let row = &mut out[y * width + ox..y * width + ox + tw];
                    // Only the columns within `r_out` of the gaze (one more each side: the test below
                    // decides); the chord a pixel inside `r_in` (one short at each end) copied whole.
                    let local = |reach: f64| {
                        let r = row_span(gaze.x - ox as f64, reach, tw);
                        r.start..r.end
                    };
                    if dy * dy >= r_out2 {
                        continue;
                    }
                    let outer = local((r_out2 - dy * dy).max(0.0).sqrt() + 1.0);
                    let inner = if dy * dy < r_in2 {
                        let s = local((r_in2 - dy * dy).sqrt() - 1.0);
                        s.start.max(outer.start)..s.end.min(outer.end).max(s.start.max(outer.start))
                    } else {
                        outer.start..outer.start
                    };
                    row[inner.clone()].copy_from_slice(&trow[inner.clone()]);
                    for tx in (outer.start..inner.start).chain(inner.end..outer.end) {
                        let (o, t) = (&mut row[tx], trow[tx]);
                        let dx = (ox + tx) as f64 - gaze.x;
                        let r2 = dx * dx + dy * dy;
                        if r2 <= r_in2 {
                            *o = t;
                        } else if r2 < r_out2 {
                            let wgt = ((r_out - r2.sqrt()) / g.band_px) as f32;
                            *o += wgt * (t - *o);
                        }
                    }
                }
            });
        Ok(())
    }
}

/// The six `n`-value planes of the tile's heads buffer.
pub(super) fn tile_planes(buf: &mut [f32], n: usize) -> [&mut [f32]; 6] {
    let (a0, rest) = buf.split_at_mut(n);
    let (a1, rest) = rest.split_at_mut(n);
    let (a2, rest) = rest.split_at_mut(n);
    let (p0, rest) = rest.split_at_mut(n);
    let (p1, p2) = rest.split_at_mut(n);
    [a0, a1, a2, p0, p1, p2]
}
