//! A session's foveated frames ([`HologramSession::render_foveated`]; [`crate::foveation`]): the hologram CNN
//! on a tile around the gaze, the periphery's 2D hologram with synthetic blur, their blend, then the rest of
//! the CPU frame (offset propagation, pre-filter, encoding) on the composed midpoint hologram, with a
//! normaliser that does not follow the gaze.

use std::sync::Arc;
use std::time::Instant;

use ndarray::{s, Array3};

use rayon::prelude::*;
use tensorholo_kernels::{depthwise_rows, Isa};

use super::cnn_stage::CnnStage;
use super::colour::{ColourState, Task};
use super::frame::{check_not_black, max_and_finite, FrameTimings, Heads, SlmFrame};
use super::models::HologramPipeline;
use super::session::{colour_states, phase_planes, HologramSession};
use crate::cnn::{CnnPlan, CnnPlans, PlanRequest};
use crate::error::{invalid, HoloError, Result};
use crate::foveation::{
    gaze_depth, ColourInputs, FoveaReport, FoveationOptions, FrameInputs, Gaze, GazeDepthSource,
    Periphery, TileGeometry, FOVEATED_NORMALISER_GAIN,
};
use crate::model::contract;
use crate::model::graph::CnnOutput;
use crate::scene::RgbdFrame;

/// What a foveated session keeps between frames: the tile's CNN and buffers, the periphery's tables, the
/// last frame's report.
#[derive(Debug)]
pub(super) struct FoveatedState {
    radius_deg: Option<f64>,
    /// The hologram CNN's plan for the tile (same engine and options as the frame's), with its input buffer.
    cnn: CnnStage,
    /// The tile's heads: amplitude R, G, B then phase R, G, B, `T_h·T_w` values each.
    heads: Vec<f32>,
    periphery: Periphery,
    /// `κ·V·λ/(2p²)` per colour: the blur radius at a depth difference of 1, pixels.
    blur_px: [f64; 3],
    /// The display's volume depth, metres.
    volume_m: f64,
    /// The pre-filter CNN on its own tile (a session with a pre-filter whose graph the native reader knows),
    /// its base filter elsewhere; `None`: the pre-filter runs on the whole frame.
    prefilter: Option<PrefilterTile>,
    pub(super) report: Option<FoveaReport>,
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
struct PrefilterTile {
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

/// Width in pixels over which a foveated frame's pre-filter residual fades out beyond `R_p`.
const PREFILTER_RAMP_PX: f64 = 64.0;

/// The most input planes of a tile's hologram CNN passed without a list on the heap (an LDI CNN of 8 layers).
const MAX_TILE_PLANES: usize = 32;

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
            periphery: Periphery::new(geometry, max_blur, threads),
            blur_px,
            volume_m: optics.volume_depth_m,
            prefilter,
            report: None,
        })
    }

    /// Packs the tile at `origin` of the frame's planes (amplitude R, G, B, depth) into the tile CNN's input,
    /// as [`CnnStage::pack_frame`] packs a frame: the calibration's intensity maps on the amplitudes, the
    /// display's depth fraction on the depth, empty back layers for an LDI CNN.
    fn pack_tile(&mut self, planes: [&[f32]; 4], width: usize, (oy, ox): (usize, usize)) {
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
    fn run(
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
                    for (tx, (o, &t)) in row.iter_mut().zip(trow).enumerate() {
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

impl HologramSession {
    /// Renders one RGB-D frame foveated on `gaze` (`docs/FOVEATION.md`; [`crate::foveation`]): the hologram
    /// CNN runs on a tile around the gaze (the fovea, its blend band and the CNN's receptive radius), the rest
    /// of the midpoint hologram is the paper's 2D hologram with synthetic blur, in focus at the gaze's depth;
    /// offset propagation, pre-filter and encoding then run on the whole frame. Inside the fovea the field
    /// is the full frame's CNN field; the double phase normaliser is
    /// [`FOVEATED_NORMALISER_GAIN`]` · max A`, the same for every gaze. A fovea that covers the frame, or a
    /// session whose tile is the whole frame (a small frame, a wide fovea: no CNN work to save), renders the
    /// frame as [`HologramSession::render`] does, bit for bit. The tile has one size for every gaze (one
    /// plan, made with the session) and nothing is allocated per frame once the first has run.
    /// [`HologramSession::fovea_report`] says what the frame did. Runs on the CPU (a session on the GPU runs
    /// its foveated frames on its CPU frame).
    ///
    /// Errors: [`HoloError::InvalidParameter`] naming `foveation` (a session made without
    /// [`PipelineConfig::foveation`](crate::pipeline::PipelineConfig::foveation)), `gaze` or `gaze_depth_m`
    /// ([`Gaze`]); otherwise as [`HologramSession::render`]. The session stays usable after an error.
    pub fn render_foveated(&mut self, frame: &RgbdFrame, gaze: &Gaze) -> Result<&SlmFrame> {
        let t = Instant::now();
        let Some(mut fov) = self.foveated.take() else {
            return Err(invalid(
                "foveation",
                "this session was made without foveation options (PipelineConfig::foveation)",
            ));
        };
        let result = self.foveated_frame(&mut fov, frame, gaze, t);
        self.foveated = Some(fov);
        result?;
        Ok(&self.output)
    }

    /// Renders a stream of foveated frames, each on its own gaze (an eye tracker's, frame by frame), handing
    /// each result to `sink` with its tag as [`HologramSession::render_stream_each`] does: a frame's error
    /// goes to `sink` and the stream goes on unless `sink` returns it; `sink`'s own error stops the stream.
    /// The frames run one after another ([`HologramSession::render_foveated`]: the tile's CNN is short, there
    /// is little to overlap); each output's `timings.total_s` is the frame period (from the previous
    /// frame's end). Returns the number of frames taken from `frames`.
    ///
    /// Errors: the first error `sink` returns.
    pub fn render_foveated_stream_each<T, I, F>(&mut self, frames: I, mut sink: F) -> Result<usize>
    where
        I: IntoIterator<Item = (T, Result<(RgbdFrame, Gaze)>)>,
        F: FnMut(T, Result<&SlmFrame>) -> Result<()>,
    {
        let mut count = 0;
        let mut last = Instant::now();
        for (tag, frame) in frames {
            count += 1;
            match frame.and_then(|(f, gaze)| self.render_foveated(&f, &gaze).map(drop)) {
                Ok(()) => {
                    let now = Instant::now();
                    self.output.timings.total_s = (now - last).as_secs_f64();
                    last = now;
                    sink(tag, Ok(&self.output))?;
                }
                Err(e) => sink(tag, Err(e))?,
            }
        }
        Ok(count)
    }

    /// What the last foveated frame did (gaze, its depth, the fovea, the tile, the share of the frame the
    /// CNN ran on); `None` before the first or after a frame that failed.
    pub fn fovea_report(&self) -> Option<&FoveaReport> {
        self.foveated.as_ref().and_then(|f| f.report.as_ref())
    }

    fn foveated_frame(
        &mut self,
        fov: &mut FoveatedState,
        frame: &RgbdFrame,
        gaze: &Gaze,
        t: Instant,
    ) -> Result<()> {
        fov.report = None;
        let (h, w) = (self.height, self.width);
        gaze.check(h, w)?;
        if frame.amplitude.dim() != (3, h, w) || frame.depth.dim() != (h, w) {
            return Err(HoloError::ShapeMismatch {
                what: "RGB-D frame vs the session's [H, W]".into(),
                expected: vec![h, w],
                got: vec![frame.height(), frame.width()],
            });
        }
        let geometry = *fov.periphery.geometry();
        let (radius_px, band_px) = (geometry.radius_px, geometry.band_px);
        let mut report = FoveaReport {
            gaze: *gaze,
            gaze_depth: 0.0,
            gaze_depth_source: GazeDepthSource::Scene,
            radius_px,
            radius_deg: fov.radius_deg,
            band_px,
            cnn_margin_px: geometry.margin,
            tile: [0, 0, h, w],
            cnn_share: 1.0,
            covers_frame: true,
            periphery_phase_rad: [0.0; 3],
        };
        // The fovea holds the whole frame, or the CNN's tile does (no CNN work to save): the full frame.
        if geometry.covers_frame(gaze) || geometry.tile == geometry.frame {
            self.render(frame)?;
            fov.report = Some(report);
            return Ok(());
        }
        let amplitude = frame.amplitude.as_standard_layout();
        let depth = frame.depth.as_standard_layout();
        let (Some(amplitude), Some(depth)) = (amplitude.as_slice(), depth.as_slice()) else {
            return Err(HoloError::Internal("standard layout is contiguous".into()));
        };
        let (r, gb) = amplitude.split_at(h * w);
        let (g, b) = gb.split_at(h * w);
        let planes = [r, g, b, depth];
        // The frame's checks (as the CNN stage's): finite values, not black; the normaliser's `max A` after
        // the intensity maps, which the periphery shows.
        let scales = [0, 1, 2].map(|c| {
            self.calibration
                .as_ref()
                .and_then(|cal| cal.colours[c].intensity_scale.as_ref())
                .and_then(|m| m.as_slice())
        });
        let mut brightest = 0.0f32;
        for (plane, scale) in planes[..3].iter().zip(scales) {
            let (m, finite) = max_and_finite(plane);
            if !finite {
                return Err(HoloError::InvalidData(
                    "the RGB-D frame holds NaN or infinite values".into(),
                ));
            }
            let m = match scale {
                Some(s) => plane.iter().zip(s).fold(0.0f32, |m, (&a, &s)| m.max(a * s)),
                None => m,
            };
            brightest = brightest.max(m);
        }
        if !max_and_finite(depth).1 {
            return Err(HoloError::InvalidData(
                "the RGB-D frame's depth holds NaN or infinite values".into(),
            ));
        }
        check_not_black(brightest)?;

        let t_periphery = Instant::now();
        let d_g = match gaze.depth_m {
            Some(z) => {
                report.gaze_depth_source = GazeDepthSource::Given;
                (0.5 - z / fov.volume_m).clamp(0.0, 1.0) as f32
            }
            None => gaze_depth(depth, (h, w), gaze, &mut fov.periphery.window),
        };
        let mut periphery_s = t_periphery.elapsed().as_secs_f64();
        let origin = geometry.origin(gaze);

        // The tile's CNN.
        let t_cnn = Instant::now();
        fov.pack_tile(planes, w, origin);
        let (th, tw) = geometry.tile;
        {
            let [a0, a1, a2, p0, p1, p2] = tile_planes(&mut fov.heads, th * tw);
            // The input's planes without a list on the heap (an RGB-D CNN's 4, an LDI CNN's up to 32).
            let mut planes: [&[f32]; MAX_TILE_PLANES] = [&[]; MAX_TILE_PLANES];
            let input = fov.cnn.input.as_slice().unwrap_or_default();
            let c = fov.cnn.input.dim().0;
            for (p, plane) in planes.iter_mut().zip(input.chunks_exact(th * tw)) {
                *p = plane;
            }
            let out = [a0, a1, a2, p0, p1, p2];
            if c <= MAX_TILE_PLANES {
                fov.cnn.plan.run_planes_into(&planes[..c], out)?;
            } else {
                let input = CnnStage::planes_of(&fov.cnn.input);
                fov.cnn.plan.run_planes_into(&input, out)?;
            }
        }
        let cnn_s = t_cnn.elapsed().as_secs_f64();

        // The composed midpoint hologram, written where the colour workers read heads.
        let t_compose = Instant::now();
        let n = th * tw;
        let tile_heads = |c: usize| {
            (
                &fov.heads[c * n..(c + 1) * n],
                &fov.heads[(3 + c) * n..(4 + c) * n],
            )
        };
        let colours = [0, 1, 2].map(|c| ColourInputs {
            amplitude: planes[c],
            scale: scales[c],
            tile_heads: tile_heads(c),
            blur_px: fov.blur_px[c],
        });
        let inputs = FrameInputs {
            depth,
            gaze: (gaze.x, gaze.y),
            gaze_depth: d_g,
            origin,
        };
        let periphery = &fov.periphery;
        let previous = self.last_heads.take();
        let shared = if self.full_outputs {
            let mut shared = Heads::reuse_or_new(previous, h, w);
            let Some(out) = Arc::get_mut(&mut shared).and_then(Heads::planes_mut) else {
                return Err(HoloError::Internal(
                    "the kept heads are not writable".into(),
                ));
            };
            report.periphery_phase_rad = self
                .optics
                .run(|| periphery.compose(inputs, colours, out))?;
            Some(shared)
        } else {
            drop(previous);
            let [(a0, p0), (a1, p1), (a2, p2)] =
                colour_states(&mut self.states)?.map(ColourState::planes);
            let out = [a0, a1, a2, p0, p1, p2];
            report.periphery_phase_rad = self
                .optics
                .run(|| periphery.compose(inputs, colours, out))?;
            None
        };
        periphery_s += t_compose.elapsed().as_secs_f64();

        // The rest of the frame: offset propagation, the pre-filter (on its tile where it can), the encoding
        // with the gaze-independent normaliser.
        self.last_heads = None;
        let t_offset = Instant::now();
        let prefilter = self.prefilter.is_some();
        self.workers.run(&mut self.states, |_| Task::Midpoint {
            prefilter,
            heads: shared.clone(),
        })?;
        let offset_s = t_offset.elapsed().as_secs_f64();
        let t_prefilter = Instant::now();
        let filtered = match (&mut fov.prefilter, prefilter) {
            (Some(tile), true) => {
                let states = colour_states(&mut self.states)?;
                let planes = phase_planes(&mut self.output)?;
                self.optics.run(|| tile.run(states, planes, gaze, (h, w)))?;
                true
            }
            _ => self.run_prefilter_cnn()?,
        };
        let prefilter_s = t_prefilter.elapsed().as_secs_f64();
        let t_encoding = Instant::now();
        if filtered {
            self.filtered()?;
        }
        self.fixed_normaliser = Some(FOVEATED_NORMALISER_GAIN * brightest);
        let encoded = self.encode(filtered).map(|_| ());
        self.fixed_normaliser = None;
        encoded?;
        self.output.timings = FrameTimings {
            cnn_s,
            offset_s,
            prefilter_s: if filtered { prefilter_s } else { 0.0 },
            encoding_s: t_encoding.elapsed().as_secs_f64(),
            gpu_s: 0.0,
            periphery_s,
            total_s: t.elapsed().as_secs_f64(),
        };
        self.output.backend = super::config::Backend::Cpu;
        self.last_heads = shared;
        report.gaze_depth = f64::from(d_g);
        report.tile = [origin.0, origin.1, th, tw];
        report.cnn_share = geometry.share();
        report.covers_frame = false;
        fov.report = Some(report);
        Ok(())
    }
}

/// The six `n`-value planes of the tile's heads buffer.
fn tile_planes(buf: &mut [f32], n: usize) -> [&mut [f32]; 6] {
    let (a0, rest) = buf.split_at_mut(n);
    let (a1, rest) = rest.split_at_mut(n);
    let (a2, rest) = rest.split_at_mut(n);
    let (p0, rest) = rest.split_at_mut(n);
    let (p1, p2) = rest.split_at_mut(n);
    [a0, a1, a2, p0, p1, p2]
}
