//! [`HologramGenerator`]: camera frames to SLM patterns, with [`GeneratorInfo`] (what it runs) and
//! [`BenchmarkReport`].

use std::sync::Arc;

use tensorholo::generator as core;
use tensorholo::scene;

use crate::config::{GeneratorConfig, Prescription};
use crate::error::{guard, invalid, Result, TensorholoError};
use crate::foveation::Gaze;
use crate::frames::{Preview, RgbdFrame, SlmPatterns, StageTimings};
use crate::refine::{RefineProgress, RefineSettings};
use crate::stream::{HologramStream, PatternsListener};

/// What a generator runs.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct GeneratorInfo {
    /// Library version.
    pub version: String,
    /// Hologram width in pixels.
    pub width: u32,
    /// Hologram height in pixels.
    pub height: u32,
    /// Hologram CNN depth.
    pub layers: u32,
    /// Weight format (`f32`, `int8-qdq`, …).
    pub precision: String,
    /// Hologram CNN (embedded file name).
    pub hologram_model: String,
    /// Pre-filter CNN, if one runs.
    pub prefilter_model: Option<String>,
    /// Why a pre-filter runs or not.
    pub prefilter_reason: String,
    /// SLM offset in millimetres.
    pub offset_mm: f64,
    /// CPU CNN engine that runs (`native` or `tract`).
    pub cnn_engine: String,
    /// Why that engine (e.g. "faster on this CPU (2.41× tract's best)").
    pub cnn_engine_reason: String,
    /// The native engine's kernel row (e.g. `conv3x3.f32.6x2.avx2`, `conv3x3.u8s8.4x1.avx2`), if it runs.
    pub cnn_kernel: Option<String>,
    /// Chosen CNN memory layout (`nchw` or `nhwc`).
    pub cnn_layout: String,
    /// Chosen CNN threads.
    pub cnn_threads: u32,
    /// Whether the plan was chosen by timing candidates on this device.
    pub autotuned: bool,
    /// Where the CNN plan came from: `table` (the plan table, nothing timed), `saved`
    /// ([`GeneratorConfig::saved_plans`]) or `tuned` ([`GeneratorConfig::tune`]).
    pub cnn_plan_source: String,
    /// The same in words (with saved plans: what they decided and what the table filled in).
    pub cnn_plan_detail: String,
    /// This generator's CNN plans as a `tensorholo.cnn-plans` JSON text: store it (after a `tune` run) and
    /// pass it as [`GeneratorConfig::saved_plans`] to repeat them.
    pub saved_plans: String,
    /// What computes the frames now: `cpu` or `gpu`.
    pub backend: String,
    /// Why (no GPU, the first frame's self-check, a GPU failure mid-stream, …).
    pub backend_reason: String,
    /// The GPU adapter, where one was used or tried.
    pub gpu_adapter: Option<String>,
    /// The display calibration applied ([`HologramGenerator::set_calibration`]), in words, e.g.
    /// `"1080×1920 SLM: red tiled (16×16 px), green global, blue linear; intensity map: none"`.
    pub calibration: Option<String>,
    /// How the hologram CNN's training display maps onto this display, in one line, e.g. "the 8-layer
    /// hologram CNN (trained at 8 µm, 6 mm volume) serves 4 µm with a 1.5 mm volume (σ = 0.250000); offset
    /// 1.5 mm ↔ 6 mm trained; wavelength mismatch 0.00 % (tolerance 0.50 %); non-paraxial residual 0.084 rad
    /// (bound 0.25 rad)" (`docs/DISPLAYS.md`).
    pub display_mapping: String,
    /// The viewer's aberration correction ([`HologramGenerator::set_prescription`]), in words: the distance
    /// whose coefficients apply and, for coefficients that change with distance, the residual left over the
    /// volume (radians RMS, R/G/B); `None` without one.
    pub aberration: Option<String>,
    /// Everything above and the autotuning timings, as JSON.
    pub json: String,
}

/// Median per-stage timings of [`HologramGenerator::benchmark`].
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct BenchmarkReport {
    /// Frames timed (after one warm-up frame).
    pub frames: u32,
    /// Median stage timings.
    pub median: StageTimings,
    /// Frames per second of the median frame (`1000 / (convert_ms + total_ms)`).
    pub fps: f64,
    /// The generator's [`GeneratorInfo`] (chosen plan, threads).
    pub info: GeneratorInfo,
}

/// RGB-D camera frames → SLM patterns with the shipped CNNs. Any thread may call it; calls run one at a time.
#[derive(Debug, uniffi::Object)]
pub struct HologramGenerator {
    inner: core::HologramGenerator,
}

#[uniffi::export]
impl HologramGenerator {
    /// Loads the shipped CNNs and prepares everything for `config.width × config.height` frames (the CNN
    /// plans from the plan table, or timed on the device with `config.tune`: up to a few seconds).
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for a bad configuration (sizes, NaN or negative numbers,
    /// layers other than 8/15/30, a required pre-filter that is not shipped for the offset);
    /// [`TensorholoError::InvalidModel`] if an embedded model fails its checks.
    /// [`TensorholoError::Unsupported`] in a library built without the shipped CNNs (cargo feature
    /// `embedded-models` off): use [`HologramGenerator::with_models`].
    #[uniffi::constructor]
    pub fn new(config: GeneratorConfig) -> Result<Arc<Self>> {
        guard(|| {
            let config = config.to_core()?;
            #[cfg(feature = "embedded-models")]
            let inner = core::HologramGenerator::new(config)?;
            #[cfg(not(feature = "embedded-models"))]
            let inner: core::HologramGenerator = {
                let _ = config;
                Err(TensorholoError::Unsupported {
                    message: "this library was built without the shipped CNNs (cargo feature \
                              `embedded-models`); pass ONNX files to HologramGenerator.withModels"
                        .into(),
                })?
            };
            Ok(Arc::new(Self { inner }))
        })
    }

    /// As [`HologramGenerator::new`] with ONNX files instead of the embedded CNNs: the app's own trained
    /// weights, or the shipped `models/` files downloaded at run time by an app that leaves them out of its
    /// binary. `hologram_onnx`: an RGB-D hologram CNN (e.g. `holo8_rgbd.onnx`); `prefilter_onnx`: a DDPM
    /// pre-filter CNN for `config.offset_mm` (e.g. `prefilter_6mm.onnx`), or none for AA-DPM encoding.
    /// `config.layers`, `precision` and `prefilter` are ignored: the files say what they are.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for a bad configuration; [`TensorholoError::InvalidModel`]
    /// for bytes that are not such a model, or a model trained for another display (wavelengths, pixel
    /// pitch, volume depth) or, for the pre-filter, another offset (the message names the key and both
    /// values).
    #[uniffi::constructor]
    pub fn with_models(
        config: GeneratorConfig,
        hologram_onnx: Vec<u8>,
        prefilter_onnx: Option<Vec<u8>>,
    ) -> Result<Arc<Self>> {
        guard(|| {
            let inner = core::HologramGenerator::from_onnx(
                config.to_core()?,
                &hologram_onnx,
                prefilter_onnx.as_deref(),
            )?;
            Ok(Arc::new(Self { inner }))
        })
    }

    /// Renders one camera frame into SLM patterns.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for buffers that do not match their sizes, strides and
    /// formats, or a depth map without one valid pixel; the generator stays usable.
    pub fn render(&self, frame: RgbdFrame) -> Result<SlmPatterns> {
        guard(|| {
            let frame = frame.into_core();
            Ok(self.inner.render(&frame.view())?.into())
        })
    }

    /// Renders one camera frame foveated on `gaze` (`docs/FOVEATION.md`): the 3D CNN where the viewer looks,
    /// the paper's 2D hologram with synthetic blur (in focus at the gaze's depth) elsewhere; at 1080p with a 5°
    /// fovea 0.41–0.45 of [`HologramGenerator::render`]'s time (int8, two Zen 4 cores, docs/BENCHMARKS.md). Needs a generator made with
    /// [`GeneratorConfig::foveation`](crate::GeneratorConfig::foveation); pass this frame's gaze (an eye
    /// tracker's, ARKit face tracking's, or a touch point) in hologram pixels.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for a generator made without foveation, a gaze outside the
    /// hologram or not finite (naming it), and as [`HologramGenerator::render`]; the generator stays usable.
    pub fn render_foveated(&self, frame: RgbdFrame, gaze: Gaze) -> Result<SlmPatterns> {
        guard(|| {
            let frame = frame.into_core();
            Ok(self
                .inner
                .render_foveated(&frame.view(), &gaze.into())?
                .into())
        })
    }

    /// The photo mode ("best quality"): renders `frame` as [`HologramGenerator::render`], then refines its
    /// SLM patterns with `settings` (focal-stack refinement warm-started from the CNN's codes,
    /// docs/REFINE.md: about +4 dB at 10 iterations on real photos). `progress` hears of every iteration and
    /// may cancel. Takes seconds on a phone: call it off the main thread.
    ///
    /// Errors: as [`HologramGenerator::render`]; [`TensorholoError::InvalidInput`] for settings out of range
    /// (naming them) or a generator correcting a viewer's aberration; [`TensorholoError::Cancelled`] when
    /// `progress` returned `false`. The generator stays usable.
    pub fn render_refined(
        &self,
        frame: RgbdFrame,
        settings: RefineSettings,
        progress: Option<Arc<dyn RefineProgress>>,
    ) -> Result<SlmPatterns> {
        guard(|| {
            let frame = frame.into_core();
            let mut progress = crate::refine::progress_of(progress, settings.iterations);
            Ok(self
                .inner
                .render_refined(&frame.view(), &settings.to_core(), &mut progress)?
                .into())
        })
    }

    /// Renders a layered depth image into SLM patterns: one [`RgbdFrame`] per layer, front to back (what a
    /// renderer's depth-peeling pass gives), each with the buffer rules of [`HologramGenerator::render`]. In
    /// the layers behind the first, a depth sample of 0 (or NaN, or confidence 0 %) means "no point here"; a
    /// point may appear only where the layer in front holds one, no nearer than it. All layers share one
    /// depth range (`z_near_m`/`z_far_m`, or the 1st/99th percentiles of every layer's depths). Needs a
    /// generator made with `input` = [`SceneInput::Ldi`](crate::SceneInput::Ldi); fewer layers than its CNN takes (5) are padded with
    /// empty ones.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for no layer, more layers than the CNN takes (with an RGB-D
    /// generator: more than one), layers whose colour sizes differ, a back layer nearer than the one in front
    /// of it, and as [`HologramGenerator::render`]; the generator stays usable.
    pub fn render_ldi(&self, layers: Vec<RgbdFrame>) -> Result<SlmPatterns> {
        guard(|| {
            let buffers: Vec<scene::CameraFrameBuf> =
                layers.into_iter().map(RgbdFrame::into_core).collect();
            let views: Vec<scene::CameraFrame<&[u8]>> =
                buffers.iter().map(scene::CameraFrameBuf::view).collect();
            Ok(self.inner.render_ldi(&views)?.into())
        })
    }

    /// Renders `frame` and returns what a viewer sees focused at normalised depth `focus` ∈ [0, 1]
    /// (0 = near), for the phone's screen.
    ///
    /// Errors: as [`HologramGenerator::render`], and for a focus outside [0, 1].
    pub fn preview(&self, frame: RgbdFrame, focus: f32) -> Result<Preview> {
        guard(|| {
            let frame = frame.into_core();
            let p = self.inner.preview(&frame.view(), focus)?;
            Ok(Preview {
                width: p.width as u32,
                height: p.height as u32,
                rgba: p.rgba,
            })
        })
    }

    /// Applies a display calibration file (the bytes of a `.holocal` made by `holo calibrate`, e.g. bundled
    /// with the app or downloaded per device) to the frames rendered from now on and to streams started
    /// later; `None` returns to an ideal SLM (linear look-up tables, no intensity map). Its per-colour
    /// look-up tables turn the double phase pattern into the codes this SLM needs, and its laser intensity
    /// map evens out the illumination (`docs/CALIBRATION.md`).
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for bytes that are not a valid `.holocal` file (truncated,
    /// corrupt, another version: the message says which), a calibration for another SLM size than this
    /// generator's, or one measured at other wavelengths; the generator keeps its calibration.
    pub fn set_calibration(&self, calibration: Option<Vec<u8>>) -> Result<()> {
        guard(|| {
            let calibration = calibration
                .map(|bytes| {
                    tensorholo::slm::DisplayCalibration::from_bytes(
                        &bytes,
                        "calibration (.holocal)",
                    )
                })
                .transpose()?
                .map(Arc::new);
            Ok(self.inner.set_calibration(calibration)?)
        })
    }

    /// Replaces the viewer's prescription of the frames rendered from now on and of streams started later
    /// (`None`: none), without a new generator: a prescription slider. Make the generator with a
    /// prescription in its configuration (a zero one will do) so that it encodes with AA-DPM.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] naming the field (`sphere_d` beyond ±20 D, a cylinder
    /// without `axis_deg`, an axis outside 0–180°, …), or on a generator whose frames run on the GPU; the
    /// generator keeps its correction.
    pub fn set_prescription(&self, prescription: Option<Prescription>) -> Result<()> {
        guard(|| Ok(self.inner.set_prescription(prescription.map(Into::into))?))
    }

    /// [`HologramGenerator::set_prescription`] with measured aberrations: the JSON text of a
    /// `tensorholo.aberration` file, or `None` for none.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for text that is not such a file (the message says what),
    /// one calibrated for another pitch or other lasers, or on a generator whose frames run on the GPU.
    pub fn set_aberration(&self, aberration: Option<String>) -> Result<()> {
        guard(|| {
            let profile = aberration
                .map(|json| {
                    tensorholo::display::AberrationProfile::from_json_str(&json, "aberration")
                })
                .transpose()?
                .map(Arc::new);
            Ok(self.inner.set_aberration(profile)?)
        })
    }

    /// The models, precision, pre-filter and CNN plan this generator runs.
    pub fn info(&self) -> Result<GeneratorInfo> {
        guard(|| info(&self.inner))
    }

    /// Renders the built-in test scene `frames` times (after one warm-up) at this generator's resolution and
    /// returns the median stage timings, so an app can show what its device does.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for 0 frames.
    pub fn benchmark(&self, frames: u32) -> Result<BenchmarkReport> {
        guard(|| {
            if frames == 0 {
                return Err(invalid("benchmark needs at least 1 frame"));
            }
            let b = self.inner.benchmark(frames as usize)?;
            Ok(BenchmarkReport {
                frames,
                fps: b.fps,
                median: b.median.into(),
                info: info(&self.inner)?,
            })
        })
    }

    /// Starts a video stream: [`HologramStream::push`] frames, results reach `listener` in frame order on a
    /// background thread. The queue holds 2 frames and drops the oldest when full.
    ///
    /// Errors: [`TensorholoError::Internal`] if the worker thread cannot start.
    pub fn stream(&self, listener: Arc<dyn PatternsListener>) -> Result<Arc<HologramStream>> {
        guard(|| Ok(Arc::new(HologramStream::start(&self.inner, listener)?)))
    }
}

fn info(g: &core::HologramGenerator) -> Result<GeneratorInfo> {
    let i = g.info()?;
    let json = serde_json::to_string(&i).map_err(|e| TensorholoError::Internal {
        message: format!("cannot serialise the generator info: {e}"),
    })?;
    Ok(GeneratorInfo {
        version: i.version,
        width: i.width as u32,
        height: i.height as u32,
        layers: i.layers as u32,
        precision: i.precision.to_string(),
        hologram_model: i.hologram_model,
        prefilter_model: i.prefilter_model,
        prefilter_reason: i.prefilter_reason,
        offset_mm: i.offset_m * 1e3,
        cnn_engine: i.plan.engine.to_string(),
        cnn_engine_reason: i.plan.engine_reason.clone(),
        cnn_kernel: i.plan.kernel.clone(),
        cnn_layout: i.plan.layout.to_string(),
        cnn_threads: i.plan.threads.unwrap_or(1) as u32,
        autotuned: i.plan.autotuned,
        cnn_plan_source: i.plan.source.name().to_string(),
        cnn_plan_detail: i.plan.source_detail.clone(),
        saved_plans: i.plan.saved().to_json(),
        backend: i.backend.active.to_string(),
        backend_reason: i.backend.reason,
        gpu_adapter: i.backend.adapter,
        calibration: i.calibration,
        display_mapping: i.display_mapping,
        aberration: i.aberration.as_ref().map(ToString::to_string),
        json,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::tests::config;
    #[cfg(feature = "embedded-models")]
    use crate::display::tests::PROFILE_4UM;
    #[cfg(feature = "embedded-models")]
    use crate::display::{display_profile_from_json, generator_config_for_display};
    use crate::enums::CnnEngine;
    use crate::frames::tests::frame;

    /// A generator for the 4 µm profile renders and reports σ = 0.25.
    #[cfg(feature = "embedded-models")]
    #[test]
    fn a_generator_for_a_4um_display_reports_its_mapping() {
        let p = display_profile_from_json(PROFILE_4UM.into()).unwrap();
        let c = GeneratorConfig {
            threads: 1,
            engine: Some(CnnEngine::Native),
            ..generator_config_for_display(p).unwrap()
        };
        let g = HologramGenerator::new(c).unwrap();
        assert_eq!(g.render(frame()).unwrap().red.len(), 32 * 24);
        let info = g.info().unwrap();
        assert!(info.display_mapping.contains("σ = 0.25"), "{info:?}");
        assert!(info.json.contains("display_mapping"), "{}", info.json);
    }

    /// A tuned generator's plans, stored as text and given to a new generator, give the same codes without
    /// timing; the plan table's give the same codes in every generator; bad or conflicting plans are refused.
    #[cfg(feature = "embedded-models")]
    #[test]
    fn saved_plans_repeat_a_tuned_generator() {
        let tuned = HologramGenerator::new(GeneratorConfig {
            tune: true,
            threads: 0,
            ..config(48, 32)
        })
        .unwrap();
        let info = tuned.info().unwrap();
        assert_eq!(info.cnn_plan_source, "tuned");
        let again = HologramGenerator::new(GeneratorConfig {
            saved_plans: Some(info.saved_plans.clone()),
            threads: 0,
            ..config(48, 32)
        })
        .unwrap();
        let again_info = again.info().unwrap();
        assert_eq!(again_info.cnn_plan_source, "saved");
        assert_eq!(again_info.cnn_kernel, info.cnn_kernel);
        assert_eq!(again_info.cnn_threads, info.cnn_threads);
        let codes = |g: &HologramGenerator| {
            let p = g.render(frame()).unwrap();
            [p.red, p.green, p.blue]
        };
        assert_eq!(codes(&again), codes(&tuned));
        let table = || codes(&HologramGenerator::new(config(48, 32)).unwrap());
        assert_eq!(table(), table());
        for (plans, tune) in [
            (Some("{}".to_string()), false),
            (Some(info.saved_plans), true),
        ] {
            let e = HologramGenerator::new(GeneratorConfig {
                saved_plans: plans,
                tune,
                ..config(48, 32)
            })
            .unwrap_err();
            assert!(matches!(e, TensorholoError::InvalidInput { .. }), "{e:?}");
        }
    }

    /// A prescription slider: a generator made with a zero prescription encodes with AA-DPM and takes
    /// prescriptions between frames; each frame equals a generator made with that prescription; a bad one is
    /// `InvalidInput` naming the field and changes nothing; measured aberrations as text work alike.
    #[cfg(feature = "embedded-models")]
    #[test]
    fn a_prescription_slider_changes_the_patterns_without_a_new_generator() {
        let rx = |sphere_d: f64, cylinder_d: f64, axis_deg: Option<f64>| Prescription {
            sphere_d,
            cylinder_d,
            axis_deg,
            eyepiece_focal_m: 0.021,
        };
        let made = |p: Prescription| {
            HologramGenerator::new(GeneratorConfig {
                prescription: Some(p),
                ..config(48, 32)
            })
            .unwrap()
        };
        let codes = |g: &HologramGenerator| {
            let p = g.render(frame()).unwrap();
            [p.red, p.green, p.blue]
        };
        let g = made(rx(0.0, 0.0, None));
        let info = g.info().unwrap();
        assert!(info.prefilter_model.is_none(), "{info:?}");
        assert!(info.aberration.unwrap().contains("exact"));
        let plain = codes(&g);
        for p in [rx(-2.0, 0.0, None), rx(-1.0, -1.5, Some(30.0))] {
            g.set_prescription(Some(p)).unwrap();
            let now = codes(&g);
            assert_ne!(now, plain, "{p:?}");
            assert_eq!(now, codes(&made(p)), "{p:?}");
        }
        let before = codes(&g);
        for (bad, field) in [
            (rx(-25.0, 0.0, None), "sphere_d"),
            (rx(-1.0, -1.0, None), "axis_deg"),
            (rx(-1.0, -1.0, Some(200.0)), "axis_deg"),
        ] {
            match g.set_prescription(Some(bad)) {
                Err(TensorholoError::InvalidInput { message }) => {
                    assert!(message.contains(field), "{message}")
                }
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(codes(&g), before, "a refused prescription changes nothing");
        g.set_aberration(Some(
            r#"{"format": "tensorholo.aberration", "version": 1,
                "samples": [{"distance_m": 0, "coefficients": {"astigmatism_oblique": 2}}]}"#
                .into(),
        ))
        .unwrap();
        assert_ne!(codes(&g), before);
        assert!(matches!(
            g.set_aberration(Some("{}".into())),
            Err(TensorholoError::InvalidInput { .. })
        ));
        g.set_prescription(None).unwrap();
        assert!(g.info().unwrap().aberration.is_none());
    }

    fn model_file(name: &str) -> Vec<u8> {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/").to_string() + name;
        std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
    }

    /// The shipped files passed as bytes give the embedded generator's patterns exactly; a pre-filter of
    /// another offset and bytes that are no model are `InvalidModel`.
    #[cfg(feature = "embedded-models")]
    #[test]
    fn with_models_equals_the_embedded_models_and_checks_the_files() {
        let embedded = HologramGenerator::new(config(32, 24)).unwrap();
        let from_files = HologramGenerator::with_models(
            config(32, 24),
            model_file("holo8_rgbd.onnx"),
            Some(model_file("prefilter_6mm.onnx")),
        )
        .unwrap();
        let (a, b) = (
            embedded.render(frame()).unwrap(),
            from_files.render(frame()).unwrap(),
        );
        assert_eq!((a.red, a.green, a.blue), (b.red, b.green, b.blue));

        let wrong_offset = HologramGenerator::with_models(
            config(32, 24),
            model_file("holo8_rgbd.onnx"),
            Some(model_file("prefilter_12mm.onnx")),
        );
        assert!(
            matches!(&wrong_offset, Err(TensorholoError::InvalidModel { message }) if message.contains("offset")),
            "{wrong_offset:?}"
        );
        let garbage = HologramGenerator::with_models(config(32, 24), vec![7; 100], None);
        assert!(
            matches!(garbage, Err(TensorholoError::InvalidModel { .. })),
            "{garbage:?}"
        );
    }

    /// `engine` reaches the session: each engine runs when asked, the info names it (and the native kernel
    /// row), and both give nearly the same pattern (they agree to float rounding, not bit for bit).
    #[test]
    fn the_engine_choice_reaches_the_session() {
        let mut patterns = Vec::new();
        for (engine, name) in [(CnnEngine::Native, "native"), (CnnEngine::Tract, "tract")] {
            let g = HologramGenerator::new(GeneratorConfig {
                engine: Some(engine),
                ..config(32, 24)
            })
            .unwrap();
            let info = g.info().unwrap();
            assert_eq!(info.cnn_engine, name, "{info:?}");
            assert_eq!(
                info.cnn_kernel.is_some(),
                engine == CnnEngine::Native,
                "{info:?}"
            );
            assert!(info.json.contains("\"engine\""), "{}", info.json);
            patterns.push(g.render(frame()).unwrap().red);
        }
        let differ = patterns[0]
            .iter()
            .zip(&patterns[1])
            .filter(|(a, b)| a.abs_diff(**b) > 1)
            .count();
        assert!(
            differ * 100 <= patterns[0].len(),
            "{differ} codes differ by more than 1"
        );
    }

    /// Without a pre-filter file the generator encodes with AA-DPM, unlike the default embedded one.
    #[test]
    fn with_models_without_prefilter_runs_none() {
        let g = HologramGenerator::with_models(config(32, 24), model_file("holo8_rgbd.onnx"), None)
            .unwrap();
        let info = g.info().unwrap();
        assert_eq!(info.prefilter_model, None, "{info:?}");
        assert_eq!(info.layers, 8);
        let p = g.render(frame()).unwrap();
        assert_eq!(p.red.len(), 32 * 24);
        assert!(p.red.iter().any(|&c| c != p.red[0]), "constant pattern");
    }

    /// A library without the shipped CNNs says so instead of failing later.
    #[cfg(not(feature = "embedded-models"))]
    #[test]
    fn new_without_embedded_models_is_unsupported() {
        let e = HologramGenerator::new(config(32, 24)).unwrap_err();
        assert!(
            matches!(&e, TensorholoError::Unsupported { message } if message.contains("withModels")),
            "{e:?}"
        );
    }
}
