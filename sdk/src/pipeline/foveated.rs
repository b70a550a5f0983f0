//! A session's foveated frames ([`HologramSession::render_foveated`]; [`crate::foveation`]): the hologram CNN
//! on a tile around the gaze, the periphery's 2D hologram with synthetic blur, their blend, then the rest of
//! the CPU frame (offset propagation, pre-filter, encoding) on the composed midpoint hologram, with a
//! normaliser that does not follow the gaze.

use std::sync::Arc;
use std::time::Instant;

use super::colour::{ColourState, Task};
use super::config::Backend;
use super::executor::FoveatedInput;
use super::fovea_tiles::{FoveatedState, MAX_TILE_PLANES};
use super::frame::{check_not_black, max_and_finite, FrameTimings, Heads, SlmFrame};
use super::session::{colour_states, phase_planes, HologramSession};
use crate::error::{invalid, HoloError, Result};
use crate::foveation::{
    gaze_depth, ColourInputs, FoveaReport, FrameInputs, Gaze, GazeDepthSource,
    FOVEATED_NORMALISER_GAIN,
};
use crate::scene::RgbdFrame;
use crate::slm::codes::recode_calibrated;

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
    /// [`HologramSession::fovea_report`] says what the frame did. A session whose frames run on the GPU runs
    /// its foveated frames there (the tile's CNN, the periphery's blur and blend in WGSL, then the GPU
    /// frame's stages with the pre-filter over the whole frame; `SlmFrame::backend` says which ran). Where
    /// [`Backend::Auto`]'s first-frame self-check has yet to run, the first foveated frame renders the full
    /// frame first for it (once per session); a GPU failure re-renders the frame on the CPU and stays there.
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
    pub fn render_foveated_stream_each<T, I, F>(&mut self, frames: I, sink: F) -> Result<usize>
    where
        I: IntoIterator<Item = (T, Result<(RgbdFrame, Gaze)>)>,
        F: FnMut(T, Result<&SlmFrame>) -> Result<()>,
    {
        self.deliver_each(
            frames,
            |s, (f, gaze)| s.render_foveated(&f, &gaze).map(drop),
            sink,
        )
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
        // The session's handle on the calibration (a reference count, no copy), so that the frame may run
        // on the session's accelerator while the maps are borrowed.
        let calibration = self.calibration.clone();
        let scales = [0, 1, 2].map(|c| {
            calibration
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
        report.gaze_depth = f64::from(d_g);
        report.tile = [origin.0, origin.1, geometry.tile.0, geometry.tile.1];
        report.cnn_share = geometry.share();
        report.covers_frame = false;

        // On the accelerator where it runs them. Backend::Auto's first-frame self-check compares a full frame
        // with the CPU's (a foveated pattern is not the CPU's foveated pattern bit for bit: its pre-filter runs
        // over the whole frame): once per session, before the first foveated frame.
        if fov.on_accelerator && self.accelerator.as_ref().is_some_and(|a| a.pending_check) {
            self.render(frame)?;
        }
        if fov.on_accelerator && self.accelerator.is_some() {
            let normaliser = FOVEATED_NORMALISER_GAIN * brightest;
            let frame = AcceleratedFoveated {
                planes,
                scales,
                gaze,
                gaze_depth: d_g,
                origin,
                normaliser,
            };
            match self.foveated_on_accelerator(fov, frame, t, periphery_s) {
                Ok(theta) => {
                    report.periphery_phase_rad = theta;
                    fov.report = Some(report);
                    return Ok(());
                }
                Err(HoloError::Gpu(e)) => {
                    log::warn!(
                        "GPU foveated frame failed ({e}); this frame and the next run on the CPU"
                    );
                    self.accelerator = None;
                    self.backend.active = Backend::Cpu;
                    self.backend.gpu_precision = None;
                    self.backend.reason = format!("GPU failed mid-stream, CPU since: {e}");
                }
                Err(e) => return Err(e),
            }
        }

        // The tile's CNN.
        let t_cnn = Instant::now();
        fov.run_tile_cnn(planes, w, origin)?;
        let (th, tw) = geometry.tile;
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
        self.encode(filtered, Some(FOVEATED_NORMALISER_GAIN * brightest))?;
        self.output.timings = FrameTimings {
            cnn_s,
            offset_s,
            prefilter_s: if filtered { prefilter_s } else { 0.0 },
            encoding_s: t_encoding.elapsed().as_secs_f64(),
            gpu_s: 0.0,
            periphery_s,
            total_s: t.elapsed().as_secs_f64(),
        };
        self.output.backend = Backend::Cpu;
        self.last_heads = shared;
        fov.report = Some(report);
        Ok(())
    }

    /// The foveated frame `frame` on the session's accelerator: the tile packed here (the CPU's packing, its
    /// time the frame's `cnn_s`), the amplitude after the intensity maps where a calibration has them, then
    /// [`super::executor::FrameExecutor::run_foveated`]; a calibrated look-up table on the downloaded
    /// pattern. Returns the periphery's phase per colour. `periphery_s`: the gaze depth's time so far.
    ///
    /// Errors: as [`super::executor::FrameExecutor::run_foveated`] ([`HoloError::Gpu`]: the caller falls back
    /// to the CPU).
    fn foveated_on_accelerator(
        &mut self,
        fov: &mut FoveatedState,
        frame: AcceleratedFoveated<'_>,
        t: Instant,
        periphery_s: f64,
    ) -> Result<[f32; 3]> {
        let AcceleratedFoveated { planes, scales, .. } = frame;
        let (h, w) = (self.height, self.width);
        let n = h * w;
        let t_cnn = Instant::now();
        fov.pack_tile(planes, w, frame.origin);
        let cnn_s = t_cnn.elapsed().as_secs_f64();
        let t_scale = Instant::now();
        let maps = scales.iter().any(Option::is_some);
        if maps {
            fov.scaled.resize(3 * n, 0.0);
            for ((dst, src), scale) in fov.scaled.chunks_exact_mut(n).zip(planes).zip(scales) {
                match scale {
                    Some(s) => dst
                        .iter_mut()
                        .zip(src.iter().zip(s))
                        .for_each(|(o, (&a, &s))| *o = a * s),
                    None => dst.copy_from_slice(src),
                }
            }
        }
        let periphery_s = periphery_s + t_scale.elapsed().as_secs_f64();
        let amplitude: [&[f32]; 3] = if maps {
            let (r, gb) = fov.scaled.split_at(n);
            let (g, b) = gb.split_at(n);
            [r, g, b]
        } else {
            [planes[0], planes[1], planes[2]]
        };
        let (c, th, tw) = fov.cnn.input.dim();
        let Some(input) = fov.cnn.input.as_slice() else {
            return Err(HoloError::Internal("the tile's input is contiguous".into()));
        };
        let mut list: [&[f32]; MAX_TILE_PLANES] = [&[]; MAX_TILE_PLANES];
        let many: Vec<&[f32]>;
        let tile: &[&[f32]] = if c <= MAX_TILE_PLANES {
            for (p, plane) in list.iter_mut().zip(input.chunks_exact(th * tw)) {
                *p = plane;
            }
            &list[..c]
        } else {
            many = input.chunks_exact(th * tw).collect();
            &many
        };
        let calibrated = self
            .calibration
            .as_ref()
            .is_some_and(|c| c.has_calibrated_lut());
        let full = self.full_outputs || calibrated;
        let Some(acc) = self.accelerator.as_mut() else {
            return Err(HoloError::Internal("no accelerator".into()));
        };
        let t_gpu = Instant::now();
        let input = FoveatedInput {
            tile,
            amplitude,
            depth: planes[3],
            gaze: (frame.gaze.x, frame.gaze.y),
            gaze_depth: frame.gaze_depth,
            origin: frame.origin,
            normaliser: frame.normaliser,
        };
        let (heads, theta) = acc.executor.run_foveated(&input, &mut self.output, full)?;
        let backend = acc.executor.backend();
        if calibrated {
            recode_calibrated(
                self.calibration.as_deref(),
                self.output.phase.view(),
                self.output.codes.view_mut(),
            )?;
        }
        self.output.backend = backend;
        self.output.timings = FrameTimings {
            cnn_s,
            periphery_s,
            gpu_s: t_gpu.elapsed().as_secs_f64(),
            total_s: t.elapsed().as_secs_f64(),
            ..FrameTimings::default()
        };
        self.last_heads = heads.map(Arc::new);
        Ok(theta)
    }
}

/// What [`HologramSession::foveated_on_accelerator`] takes of a checked foveated frame.
#[derive(Clone, Copy)]
struct AcceleratedFoveated<'a> {
    /// The frame's amplitude R, G, B and depth, `H·W` values each.
    planes: [&'a [f32]; 4],
    /// A calibration's intensity scale maps, per colour.
    scales: [Option<&'a [f32]>; 3],
    gaze: &'a Gaze,
    gaze_depth: f32,
    origin: (usize, usize),
    /// [`FOVEATED_NORMALISER_GAIN`]` · max A`.
    normaliser: f32,
}
