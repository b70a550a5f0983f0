//! [`HologramSession`]: one resolution's frames. It owns everything a frame reuses (the CNN plans, FFT plans,
//! transfer functions, double phase encoders, scratch buffers and three colour worker threads) and, where
//! the backend asks for one, an accelerator ([`super::executor`]) that runs whole frames instead, with the
//! CPU frame as its self-check and fallback.

use std::sync::Arc;
use std::time::Instant;

use ndarray::Array3;
use rayon::prelude::*;

use super::cnn_stage::CnnStage;
use super::colour::{ColourState, Task};
use super::config::Backend;
use super::correction::{AberrationReport, PupilCorrection};
use super::executor::Accelerator;
use super::frame::{FrameTimings, Heads, SlmFrame};
use super::models::check_calibration_wavelengths;
use super::pool::OpticsPool;
use super::report::BackendReport;
use super::workers::{lost_state, ColourWorkers};
use crate::cnn::{CnnPlan, PlanReport};
use crate::display::AberrationProfile;
use crate::encoding::{normaliser, ChannelStats, DoublePhaseMethod};
use crate::error::{HoloError, Result};
use crate::model::contract;
use crate::optics::OpticalSetup;
use crate::scene::{LayeredDepthImage, RgbdFrame};
use crate::slm::codes::calibrated_lut;
use crate::slm::DisplayCalibration;

/// A hologram session for one resolution (see the [module docs](crate::pipeline)). Not `Sync`: one frame at a time;
/// a failed frame (wrong size, NaN) leaves the session usable.
#[derive(Debug)]
pub struct HologramSession {
    pub(super) height: usize,
    pub(super) width: usize,
    pub(super) encoding: DoublePhaseMethod,
    pub(super) offset_m: f64,
    pub(super) cnn: CnnStage,
    pub(super) prefilter: Option<Box<dyn CnnPlan>>,
    pub(super) states: [Option<Box<ColourState>>; 3],
    pub(super) workers: ColourWorkers,
    /// The encoding stage's threads ([`OpticsPool`]).
    pub(super) optics: OpticsPool,
    pub(super) output: SlmFrame,
    pub(super) last_heads: Option<Arc<Heads>>,
    pub(super) plan_report: PlanReport,
    pub(super) backend: BackendReport,
    pub(super) full_outputs: bool,
    /// The display calibration applied (look-up tables, intensity scale maps), and the wavelengths it must
    /// match.
    pub(super) calibration: Option<Arc<DisplayCalibration>>,
    /// The display's optics (the calibration's wavelengths and the aberration file's display must match).
    pub(super) display: OpticalSetup,
    /// The viewer's aberration profile applied and its report ([`HologramSession::set_aberration`]), with
    /// the kernels the colour workers share.
    pub(super) aberration: Option<(Arc<AberrationProfile>, AberrationReport)>,
    pub(super) correction: Option<Arc<PupilCorrection>>,
    /// The accelerator (the GPU frame) while it runs the frames; `None`: the CPU frame does.
    /// Whether the hologram CNN corrects the aberrations itself (trained for them): no kernel is applied.
    pub(super) corrected_by_cnn: bool,
    pub(super) accelerator: Option<Accelerator>,
    /// The foveated frames' state ([`HologramSession::render_foveated`]); `None` without
    /// [`PipelineConfig::foveation`](crate::pipeline::PipelineConfig::foveation).
    pub(super) foveated: Option<Box<super::fovea_tiles::FoveatedState>>,
}

impl HologramSession {
    /// Replaces the display calibration of this session's next frames (`None`: an ideal SLM, linear look-up
    /// tables and no intensity scaling), e.g. after recalibrating the bench, without rebuilding the session.
    /// See [`HologramPipeline::with_calibration`](crate::pipeline::HologramPipeline::with_calibration).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if the calibration is for another SLM size;
    /// [`HoloError::InvalidParameter`] if its wavelengths differ from the display's by more than 1 nm. The
    /// session keeps its calibration on error.
    pub fn set_calibration(&mut self, calibration: Option<Arc<DisplayCalibration>>) -> Result<()> {
        if let Some(cal) = &calibration {
            cal.check_size(self.height, self.width)?;
            check_calibration_wavelengths(cal, &self.display.wavelengths_m)?;
        }
        self.cnn.calibration = calibration.clone();
        self.calibration = calibration;
        Ok(())
    }

    /// The display calibration this session applies, if any.
    pub fn calibration(&self) -> Option<&Arc<DisplayCalibration>> {
        self.calibration.as_ref()
    }

    /// Which backend runs this session's frames, and why ([`Backend`]).
    pub fn backend_report(&self) -> &BackendReport {
        &self.backend
    }

    /// Whether GPU frames also download the double phase pattern ([`SlmFrame::phase`]) and the CNN heads
    /// ([`HologramSession::last_heads`]); on by default. Off, a GPU frame downloads only the codes and the
    /// normaliser (what an SLM needs): `phase` and `last_heads` then keep older values. On the CPU, off, the
    /// heads are not kept after a frame (`last_heads` is `None`; two `[3, H, W]` f32 arrays, 50 MB at 1080p);
    /// `phase` is filled only in a session with a pre-filter (whose pass 1 works in those planes), elsewhere
    /// it keeps older values (zeros in a new session, whose pages then never become resident: 25 MB at
    /// 1080p).
    pub fn set_full_outputs(&mut self, full: bool) {
        self.full_outputs = full;
    }

    /// How the hologram CNN's plan was chosen: the engine and why, layout, threads, and the autotuning
    /// timings (the session's engine choice, as [`crate::cnn::cnn_plan`] makes it). The pre-filter CNN runs on the same engine with the same threads.
    pub fn plan_report(&self) -> &PlanReport {
        &self.plan_report
    }

    /// `(height, width)` of this session's frames.
    pub fn size(&self) -> (usize, usize) {
        (self.height, self.width)
    }

    /// The SLM offset `s` in metres.
    pub fn offset_m(&self) -> f64 {
        self.offset_m
    }

    /// The double phase method (plain after a pre-filter CNN).
    pub fn encoding(&self) -> DoublePhaseMethod {
        self.encoding
    }

    /// Whether a pre-filter CNN runs between offset propagation and double phase encoding (DDPM).
    pub fn has_prefilter(&self) -> bool {
        self.prefilter.is_some()
    }

    /// The output of the last successful frame (codes all zero before the first).
    pub fn output(&self) -> &SlmFrame {
        &self.output
    }

    /// The hologram CNN heads of the last successful frame (the midpoint hologram; [`Heads::to_field`]);
    /// `None` before the first frame and after a CPU frame that failed (two frames' heads are never held at
    /// once: with full outputs a frame's CNN writes into the last frame's arrays, without them none are kept).
    pub fn last_heads(&self) -> Option<&Heads> {
        self.last_heads.as_deref()
    }

    /// Ends the session and keeps the last frame: its output and the hologram CNN heads (`None` before the
    /// first frame). Every other buffer (CNN windows, the colour workers' fields, transfer functions) is freed
    /// first, so that work on the frame afterwards (previews, reconstructions, evaluation) does not stack on
    /// top of the session's memory: at 1080p the session holds about 0.35 GB (docs/BENCHMARKS.md, "Memory").
    pub fn into_last_frame(self) -> (SlmFrame, Option<Heads>) {
        let Self {
            output, last_heads, ..
        } = self;
        // The colour workers let go of the heads before a frame ends: the session's handle is the only one.
        let heads = last_heads.map(|h| Arc::try_unwrap(h).unwrap_or_else(|h| (*h).clone()));
        (output, heads)
    }

    /// Renders one RGB-D frame (`[3, H, W]` amplitude and `[H, W]` normalised depth at the session's size)
    /// into SLM patterns. An LDI CNN takes the frame as a one-layer LDI (its back layers empty).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a frame of another size; [`HoloError::InvalidData`] for
    /// non-finite values or a black frame (every amplitude ≤
    /// [`BLACK_FRAME_AMPLITUDE`](crate::pipeline::BLACK_FRAME_AMPLITUDE): the CNN would only show its bias);
    /// the CNN engine's run errors ([`HoloError::ModelRun`]); [`HoloError::Gpu`] never (a GPU failure
    /// re-renders the frame on the CPU). The session stays usable after an error.
    pub fn render(&mut self, frame: &RgbdFrame) -> Result<&SlmFrame> {
        if self.accelerator.is_some() {
            let t = Instant::now();
            // An RGB-D frame goes up from its own planes (no `[4, H, W]` copy: 33 MB at 1080p).
            if let Some(planes) = self.cnn.frame_planes(frame, true)? {
                return self.render_on_accelerator(Some(planes), t);
            }
            self.cnn.pack_frame(frame)?;
            return self.render_on_accelerator(None, t);
        }
        // The previous frame's heads are this frame's arrays (or go before this frame's arrive: at 1080p,
        // 50 MB less at the peak).
        let previous = self.last_heads.take();
        if self.full_outputs {
            // The CNN writes its heads into the arrays the session keeps, and the colour workers read them
            // there (no copy: 50 MB at 1080p). The previous frame's arrays are reused (no allocation; written
            // pages: fresh arrays cost the CNN 5–10 % at 1080p in page faults).
            let mut shared = Heads::reuse_or_new(previous, self.height, self.width);
            let Some(planes) = Arc::get_mut(&mut shared).and_then(Heads::planes_mut) else {
                return Err(HoloError::Internal(
                    "the kept heads are not writable".into(),
                ));
            };
            let cnn_s = self.cnn.run_frame_into(frame, planes)?;
            return self.encode_shared(shared, cnn_s);
        }
        drop(previous);
        // The CNN writes its heads straight into the colour workers' planes (no per-frame output arrays).
        let [(a0, p0), (a1, p1), (a2, p2)] =
            colour_states(&mut self.states)?.map(ColourState::planes);
        let heads = [a0, a1, a2, p0, p1, p2];
        let cnn_s = self.cnn.run_frame_into(frame, heads)?;
        self.encode_loaded(cnn_s)
    }

    /// Renders a layered depth image (the LDI-input CNN of the paper, Fig. 1; layers `[r, g, b, d]` each,
    /// front to back). An LDI of fewer layers than the CNN takes is padded with empty layers (no point
    /// anywhere, [`crate::model::contract::pack_ldi`]); a one-layer LDI is an RGB-D frame.
    ///
    /// Errors: as [`HologramSession::render`], and [`HoloError::InvalidParameter`] (`ldi`) if the LDI has
    /// more layers than the CNN takes.
    pub fn render_ldi(&mut self, ldi: &LayeredDepthImage) -> Result<&SlmFrame> {
        if self.accelerator.is_some() {
            let t = Instant::now();
            self.cnn.pack_ldi(ldi)?;
            return self.render_on_accelerator(None, t);
        }
        self.last_heads = None;
        let (heads, cnn_s) = self.cnn.run_ldi(ldi)?;
        self.encode_heads(heads, cnn_s)
    }

    /// Runs the stages after the hologram CNN on `heads` (midpoint hologram): offset propagation, pre-filter
    /// CNN, double phase encoding and LUT. `cnn_s` is recorded as the CNN time of this frame.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for heads of another size; [`HoloError::InvalidData`] for
    /// non-finite heads or a hologram that is zero everywhere.
    pub(crate) fn encode_heads(&mut self, heads: Heads, cnn_s: f64) -> Result<&SlmFrame> {
        let standard = |a: Array3<f32>| {
            if a.is_standard_layout() {
                a
            } else {
                a.as_standard_layout().into_owned()
            }
        };
        let heads = Heads {
            amplitude: standard(heads.amplitude),
            phase: standard(heads.phase),
        };
        self.encode_shared(Arc::new(heads), cnn_s)
    }

    /// [`HologramSession::encode_heads`] for heads in standard layout, shared with the colour workers (no
    /// copy); they become [`HologramSession::last_heads`] with full outputs.
    fn encode_shared(&mut self, heads: Arc<Heads>, cnn_s: f64) -> Result<&SlmFrame> {
        self.last_heads = None;
        let t0 = Instant::now();
        self.propagate_to_slm(&heads)?;
        // Without full outputs nobody reads the heads again: they go before the pre-filter's outputs arrive
        // (50 MB less at the 1080p peak).
        let heads = self.full_outputs.then_some(heads);
        self.encode_from_midpoint(t0, cnn_s, heads)
    }

    /// [`HologramSession::encode_heads`] for heads the CNN wrote into the colour planes
    /// ([`CnnStage::run_frame_into`]) of a session without full outputs: runs the rest of the frame (the
    /// colour workers check the heads are finite as they turn them into fields); no heads are kept.
    ///
    /// Errors: [`HoloError::InvalidData`] for non-finite heads; as [`HologramSession::encode_heads`].
    fn encode_loaded(&mut self, cnn_s: f64) -> Result<&SlmFrame> {
        self.last_heads = None;
        let t0 = Instant::now();
        let prefilter = self.prefilter.is_some();
        self.workers.run(&mut self.states, |_| Task::Midpoint {
            prefilter,
            heads: None,
        })?;
        self.encode_from_midpoint(t0, cnn_s, None)
    }

    /// The rest of a frame once the colour workers propagated the midpoint hologram (started at `t0`): the
    /// pre-filter, the encoding, the timings; `heads` becomes [`HologramSession::last_heads`].
    fn encode_from_midpoint(
        &mut self,
        t0: Instant,
        cnn_s: f64,
        heads: Option<Arc<Heads>>,
    ) -> Result<&SlmFrame> {
        let offset_s = t0.elapsed().as_secs_f64();
        let t = Instant::now();
        let filtered = self.run_prefilter_cnn()?;
        let prefilter_s = if filtered {
            t.elapsed().as_secs_f64()
        } else {
            0.0
        };
        let t = Instant::now();
        if filtered {
            self.filtered()?;
        }
        self.encode(filtered, None)?;
        let encoding_s = t.elapsed().as_secs_f64();
        self.output.timings = FrameTimings {
            cnn_s,
            offset_s,
            prefilter_s,
            encoding_s,
            gpu_s: 0.0,
            periphery_s: 0.0,
            total_s: cnn_s + t0.elapsed().as_secs_f64(),
        };
        self.output.backend = Backend::Cpu;
        self.last_heads = heads;
        Ok(&self.output)
    }

    /// Stage 2 on its own: the colour workers read the midpoint `heads` (`[3, H, W]` each, standard layout)
    /// where they are (shared read-only: no copy), turn them into fields, propagate them to the SLM (Eq. 6,
    /// carrier removed) and either prepare the pre-filter input or run pass 1 of the double phase encoding.
    /// Follow with [`HologramSession::run_prefilter_cnn`] (then pass 1 on its output) and
    /// [`HologramSession::encode`] ([`HologramSession::encode_heads`] does all three). No heap allocation.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for heads of another size; [`HoloError::InvalidData`] for
    /// non-finite values (found by the workers as they read them).
    pub(crate) fn propagate_to_slm(&mut self, heads: &Arc<Heads>) -> Result<()> {
        let want = [3, self.height, self.width];
        for head in [&heads.amplitude, &heads.phase] {
            if head.shape() != want {
                return Err(HoloError::ShapeMismatch {
                    what: "midpoint heads vs the session's [3, H, W]".into(),
                    expected: want.to_vec(),
                    got: head.shape().to_vec(),
                });
            }
        }
        let prefilter = self.prefilter.is_some();
        self.workers.run(&mut self.states, |_| Task::Midpoint {
            prefilter,
            heads: Some(heads.clone()),
        })
    }

    /// Stage 3 on its own: the pre-filter CNN, if the session has one, on `[Re H, Im H]` of the offset
    /// hologram (`docs/CONVENTIONS.md` §7.2, format 2), its outputs `(Re H', Im H')` written into the colour
    /// workers' field memory (`Re H'`) and the frame's phase planes (`Im H'`: idle until pass 2 writes the
    /// pattern there); returns whether it ran. Pass 1 of the encoding then turns them into the filtered field
    /// on the optics pool (timed as encoding: without a pre-filter, pass 1 runs in [`Task::Midpoint`]).
    ///
    /// Errors: the engine's run errors ([`HoloError::ModelRun`]); call after
    /// [`HologramSession::propagate_to_slm`].
    pub(crate) fn run_prefilter_cnn(&mut self) -> Result<bool> {
        let Some(plan) = &mut self.prefilter else {
            return Ok(false);
        };
        let [r, g, b] = colour_states(&mut self.states)?;
        // The input: each colour's (Re H, Im H) where Task::Midpoint left them, read in place (no [6, H, W]
        // copy, 50 MB at 1080p). The output: Re H' in each colour's field memory, Im H' in the frame's phase
        // planes (no output arrays, 50 MB).
        let [(ri, ro), (gi, go), (bi, bo)] = [r.prefilter_io(), g.prefilter_io(), b.prefilter_io()];
        let [rp, gp, bp] = phase_planes(&mut self.output)?;
        plan.run_planes_into(
            &contract::prefilter_planes([ri, gi, bi]),
            [ro, go, bo, rp, gp, bp],
        )?;
        Ok(true)
    }

    /// Stage 4 on its own (no heap allocation after the first frame): the global normaliser, pass 2 of the
    /// double phase encoding (Eq. 7) and the LUT, each colour's rows over the optics pool's threads
    /// ([`crate::encoding::ChannelEncoder::encode_on`], bit-identical to one thread per colour), writing
    /// the codes straight into [`HologramSession::output`], and the phase too: in place where pass 1 left
    /// `arg H'` in the frame's planes (`filtered`: after the pre-filter, [`HologramSession::filtered`]), else
    /// with full outputs (each row copied from pass 1's plane as it is encoded, instead of a pass over the
    /// planes afterwards). Timings are not updated. `fixed`: the global normaliser `a` where it does not
    /// come from the field (a foveated frame's, [`crate::foveation::FOVEATED_NORMALISER_GAIN`]); `None`: the
    /// field's largest `|H|`.
    ///
    /// Errors: [`HoloError::InvalidData`] if the hologram is zero everywhere.
    pub(crate) fn encode(&mut self, filtered: bool, fixed: Option<f32>) -> Result<&SlmFrame> {
        let mut stats = [ChannelStats::default(); 3];
        for (s, slot) in stats.iter_mut().zip(&self.states) {
            *s = slot.as_ref().ok_or_else(lost_state)?.stats;
        }
        let (h, w) = (self.height, self.width);
        let (a, mean) = normaliser(&stats, h * w)?;
        let a = fixed.unwrap_or(a);
        let (full, calibration, optics) = (self.full_outputs, &self.calibration, &self.optics);
        let states = colour_states(&mut self.states)?;
        let (Some(phase_out), Some(codes_out)) = (
            self.output.phase.as_slice_mut(),
            self.output.codes.as_slice_mut(),
        ) else {
            return Err(HoloError::Internal("SLM frame not contiguous".into()));
        };
        // Pass 2 on each colour's rows over the optics pool's threads, the colours side by side.
        let colours = states
            .into_par_iter()
            .zip(phase_out.par_chunks_mut(h * w))
            .zip(codes_out.par_chunks_mut(h * w))
            .enumerate();
        optics.run(|| {
            colours.try_for_each(|(c, ((st, phase_out), codes_out))| -> Result<()> {
                let ColourState {
                    field,
                    layout,
                    encoder,
                    phase: own,
                    ..
                } = &mut *st;
                // The pattern: in place in the frame's phase plane where pass 1 left `arg H'` there (after
                // the pre-filter); else with full outputs into that plane, each row copied there from pass
                // 1's plane just before it is encoded; else in place in pass 1's plane. The codes straight
                // into the frame.
                let (arg, phase): (Option<&[f32]>, &mut [f32]) = match (filtered, full) {
                    (true, _) => (None, phase_out),
                    (false, true) => (Some(&own[..]), phase_out),
                    (false, false) => (None, &mut own[..]),
                };
                let io = (arg, &mut *phase);
                encoder.encode_on(field, *layout, io, codes_out, (mean[c], a), true)?;
                let phase = &*phase;
                if let Some(lut) = calibrated_lut(calibration.as_deref(), c) {
                    lut.apply(h, w, phase, codes_out)?;
                }
                Ok(())
            })
        })?;
        self.output.amplitude_scale = a;
        self.output.mean_phase = mean;
        Ok(&self.output)
    }
}

impl HologramSession {
    /// Pass 1 of the encoding on the pre-filter's output (the colours' planes: `Re H'` in the field's memory,
    /// `Im H'` in the frame's phase plane, which receives `arg H'`), each colour's rows over the optics pool's
    /// threads ([`crate::encoding::ChannelEncoder::analyse_planes`] on the pool), the colours side by side.
    ///
    /// Errors: [`HoloError::Internal`] if a colour's state is lost or a thread panicked.
    pub(super) fn filtered(&mut self) -> Result<()> {
        let states = colour_states(&mut self.states)?;
        let planes = phase_planes(&mut self.output)?;
        self.optics.run(|| {
            states
                .into_par_iter()
                .zip(planes)
                .try_for_each(|(st, arg)| {
                    (st.stats, st.layout) = st.encoder.analyse_planes(&mut st.field, arg, true)?;
                    Ok(())
                })
        })
    }
}

/// The frame's three phase planes (`[H, W]` each), each borrowed on its own.
///
/// Errors: [`HoloError::Internal`] if the frame's phase is not contiguous (the session makes it so).
pub(super) fn phase_planes(output: &mut SlmFrame) -> Result<[&mut [f32]; 3]> {
    let (_, h, w) = output.phase.dim();
    let not_contiguous = || HoloError::Internal("SLM frame not contiguous".into());
    let all = output.phase.as_slice_mut().ok_or_else(not_contiguous)?;
    let (r, gb) = all.split_at_mut(h * w);
    let (g, b) = gb.split_at_mut(h * w);
    Ok([r, g, b])
}

/// The three colour states, each borrowed on its own. Errors: as [`lost_state`] if a worker kept one.
pub(super) fn colour_states(
    states: &mut [Option<Box<ColourState>>; 3],
) -> Result<[&mut ColourState; 3]> {
    let [r, g, b] = states;
    match (r.as_deref_mut(), g.as_deref_mut(), b.as_deref_mut()) {
        (Some(r), Some(g), Some(b)) => Ok([r, g, b]),
        _ => Err(lost_state()),
    }
}

#[cfg(test)]
mod tests {
    //! The stage methods on bad heads (they are crate-private; the public path, `render`, is tested in
    //! `sdk/tests/pipeline.rs`).

    use std::path::Path;
    use std::sync::Arc;

    use ndarray::{Array3, Axis};

    use crate::cnn::{CnnEngine, CnnOptions};
    use crate::error::HoloError;
    use crate::model::{HologramModel, ModelConfig, ModelKind};
    use crate::pipeline::{Backend, Heads, HologramPipeline, PipelineConfig};

    fn pipeline(prefilter: bool) -> HologramPipeline {
        pipeline_padded(prefilter, false)
    }

    /// [`pipeline`] whose propagation zero-pads the field (`PropagationOptions::pad`) or not.
    fn pipeline_padded(prefilter: bool, pad: bool) -> HologramPipeline {
        let load = |name: &str, kind| {
            let path = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/fixtures/models")
                .join(name);
            Arc::new(HologramModel::from_path(path, kind, &ModelConfig::default()).unwrap())
        };
        let pre = prefilter.then(|| load("holo8_rgbd.prefilter.onnx", ModelKind::PreFilter));
        let config = PipelineConfig {
            // The fixtures are trained for a 6 mm offset.
            offset_m: 6e-3,
            backend: Backend::Cpu,
            options: crate::optics::PropagationOptions {
                pad,
                ..Default::default()
            },
            cnn: CnnOptions {
                engine: CnnEngine::Native,
                ..CnnOptions::default()
            },
            ..PipelineConfig::default()
        };
        HologramPipeline::new(load("holo8_rgbd.onnx", ModelKind::Hologram), pre, config).unwrap()
    }

    /// Copies `heads` into the colour workers' planes, as the CNN writes them there in a session without
    /// full outputs.
    fn load_planes(session: &mut super::HologramSession, heads: &Heads) {
        for (c, slot) in session.states.iter_mut().enumerate() {
            let (a, p) = slot.as_deref_mut().unwrap().planes();
            let plane =
                |x: &Array3<f32>| x.index_axis(Axis(0), c).iter().copied().collect::<Vec<_>>();
            a.copy_from_slice(&plane(&heads.amplitude));
            p.copy_from_slice(&plane(&heads.phase));
        }
    }

    fn heads(h: usize, w: usize, amplitude: f32) -> Heads {
        Heads {
            amplitude: Array3::from_elem((3, h, w), amplitude),
            phase: Array3::from_elem((3, h, w), 0.5),
        }
    }

    /// A 16×20 session with the pre-filter and the codes of `heads(16, 20, 0.5)` through `encode_heads`.
    fn session_and_good_codes() -> (super::HologramSession, Array3<u8>) {
        let mut session = pipeline(true).session(16, 20).unwrap();
        let good = session
            .encode_heads(heads(16, 20, 0.5), 0.0)
            .unwrap()
            .codes
            .clone();
        (session, good)
    }

    #[test]
    fn bad_heads_are_refused_and_the_session_stays_usable() {
        let (mut session, good) = session_and_good_codes();

        let mut nan = heads(16, 20, 0.5);
        nan.phase[[1, 2, 3]] = f32::NAN;
        let e = session.encode_heads(nan, 0.0).unwrap_err();
        assert!(matches!(e, HoloError::InvalidData(_)), "{e}");
        let e = session.encode_heads(heads(8, 20, 0.0), 0.0).unwrap_err();
        assert!(matches!(e, HoloError::ShapeMismatch { .. }), "{e}");
        // A zero hologram cannot be encoded (without pre-filter: the pre-filter may make it non-zero).
        let mut plain = pipeline(false).session(16, 20).unwrap();
        let e = plain.encode_heads(heads(16, 20, 0.0), 0.0).unwrap_err();
        assert!(matches!(e, HoloError::InvalidData(_)), "{e}");

        // After the refusals the same heads give the same codes.
        let again = session.encode_heads(heads(16, 20, 0.5), 0.0).unwrap();
        assert_eq!(again.codes, good);
    }

    #[test]
    fn non_finite_heads_written_in_place_are_refused_by_the_workers() {
        // The render path: the CNN writes its heads into the colour workers' field memory and the workers
        // check them as they turn them into fields.
        let (mut session, good) = session_and_good_codes();
        let mut bad = heads(16, 20, 0.5);
        bad.phase[[1, 2, 3]] = f32::INFINITY;
        session.set_full_outputs(false);
        load_planes(&mut session, &bad);
        let e = session.encode_loaded(0.0).unwrap_err();
        assert!(matches!(e, HoloError::InvalidData(_)), "{e}");
        assert!(session.last_heads().is_none());
        // The same heads, finite, through the same path: the codes of `encode_heads`.
        let fine = heads(16, 20, 0.5);
        load_planes(&mut session, &fine);
        assert_eq!(session.encode_loaded(0.0).unwrap().codes, good);
    }

    /// Stage 2 leaves the pre-filter's input where the pre-filter reads it, `Re H` in each colour's `phase`
    /// and `Im H` in the second half of its field's memory, equal bit for bit to the offset propagation of the
    /// heads' phasors: written chunk by chunk into the rows the inverse row pass has spent (an unpadded plan)
    /// or split in place after it (a padded plan, whose hooks see the whole field).
    #[test]
    fn stage_two_leaves_the_propagated_field_as_the_prefilter_input() {
        let (h, w) = (16, 20);
        let n = h * w;
        let varied = Heads {
            amplitude: Array3::from_shape_fn((3, h, w), |(c, y, x)| {
                ((x * 7 + y * 3 + c) % 13) as f32 / 9.0
            }),
            phase: Array3::from_shape_fn((3, h, w), |(c, y, x)| {
                ((x * 5 + y * 11 + 2 * c) % 17) as f32 / 16.0
            }),
        };
        let isa = tensorholo_kernels::Isa::detect();
        for pad in [false, true] {
            let mut session = pipeline_padded(true, pad).session(h, w).unwrap();
            session.propagate_to_slm(&Arc::new(varied.clone())).unwrap();
            for (c, slot) in session.states.iter().enumerate() {
                let st = slot.as_deref().unwrap();
                let plane =
                    |x: &Array3<f32>| x.index_axis(Axis(0), c).iter().copied().collect::<Vec<_>>();
                let mut want = vec![num_complex::Complex32::default(); n];
                let flat = bytemuck::cast_slice_mut::<_, f32>(&mut want);
                tensorholo_kernels::phasor::phasors(
                    &plane(&varied.amplitude),
                    &plane(&varied.phase),
                    flat,
                    isa,
                )
                .unwrap();
                let transfer = st.transfer.as_ref().unwrap();
                st.plan
                    .apply_even(&mut want, transfer, &mut st.plan.scratch())
                    .unwrap();
                let im = &bytemuck::cast_slice::<_, f32>(&st.field)[n..];
                let re_bits = want
                    .iter()
                    .zip(&st.phase)
                    .all(|(v, r)| v.re.to_bits() == r.to_bits());
                let im_bits = want
                    .iter()
                    .zip(im)
                    .all(|(v, i)| v.im.to_bits() == i.to_bits());
                assert!(
                    re_bits && im_bits,
                    "pad {pad}, colour {c}: Re {re_bits}, Im {im_bits}"
                );
                assert!(want.iter().any(|v| v.im != 0.0), "pad {pad}, colour {c}");
            }
        }
    }

    #[test]
    fn shared_heads_and_heads_in_the_planes_give_the_same_prefilter_input() {
        // Shared heads (full outputs): phasors made from the session's arrays in the forward row transforms'
        // chunks. Heads in the workers' planes (a lean session): the same chunks made in place. The
        // pre-filter's inputs must agree bit for bit (the fused passes against the passes apart: the FFT's
        // and `phasor_rows`' own tests).
        let (h, w) = (16, 20);
        let varied = Heads {
            amplitude: Array3::from_shape_fn((3, h, w), |(c, y, x)| {
                ((x * 7 + y * 3 + c) % 13) as f32 / 9.0
            }),
            phase: Array3::from_shape_fn((3, h, w), |(c, y, x)| {
                ((x * 5 + y * 11 + 2 * c) % 17) as f32 / 16.0
            }),
        };
        let mut shared = pipeline(true).session(h, w).unwrap();
        let shared_codes = shared
            .encode_heads(varied.clone(), 0.0)
            .unwrap()
            .codes
            .clone();
        let mut in_planes = pipeline(true).session(h, w).unwrap();
        in_planes.set_full_outputs(false);
        load_planes(&mut in_planes, &varied);
        assert_eq!(in_planes.encode_loaded(0.0).unwrap().codes, shared_codes);
        // The pre-filter's input `Re H` stays in each colour's `phase` (its `Im H` is overwritten by pass 1),
        // and the pattern fills the frame's phase in both sessions.
        for (a, b) in shared.states.iter().zip(&in_planes.states) {
            let bits = |s: &Option<Box<super::ColourState>>| {
                let re = &s.as_ref().unwrap().phase;
                assert_eq!(re.len(), h * w);
                assert!(re.iter().any(|&v| v != 0.0));
                re.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            };
            assert_eq!(bits(a), bits(b));
        }
        let bits = |a: &Array3<f32>| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&shared.output.phase), bits(&in_planes.output.phase));
        assert!(shared.output.phase.iter().any(|&v| v != 0.0));
    }
}
