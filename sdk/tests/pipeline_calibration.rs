//! The display calibration in the real-time pipeline (`HologramPipeline::with_calibration`,
//! docs/CALIBRATION.md) on the random-init fixture CNNs: the codes are the calibrated look-up tables of the
//! double phase pattern and make the panel display that pattern (which the linear table does not), the laser
//! intensity map scales the CNN's target, and calibrations of another size or wavelength are refused.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use ndarray::{Array2, Array3, Axis};
use tensorholo::model::{HologramModel, ModelConfig, ModelKind};
use tensorholo::pipeline::{Backend, HologramPipeline, PipelineConfig, SlmFrame};
use tensorholo::scene::RgbdFrame;
use tensorholo::slm::{DisplayCalibration, LutRepresentation, PhaseCurve, PhaseLut, TiledCurves};
use tensorholo::HoloError;

const H: usize = 24;
const W: usize = 40;

fn load(name: &str, kind: ModelKind) -> Arc<HologramModel> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/models")
        .join(name);
    Arc::new(HologramModel::from_path(path, kind, &ModelConfig::default()).unwrap())
}

fn pipeline(prefilter: bool) -> HologramPipeline {
    let pre = prefilter.then(|| load("holo8_rgbd.prefilter.onnx", ModelKind::PreFilter));
    let config = PipelineConfig {
        offset_m: 6e-3,
        backend: Backend::Cpu,
        ..PipelineConfig::default()
    };
    HologramPipeline::new(load("holo8_rgbd.onnx", ModelKind::Hologram), pre, config).unwrap()
}

fn frame(seed: usize) -> RgbdFrame {
    let amp = Array3::from_shape_fn((3, H, W), |(c, y, x)| {
        (((x * 7 + y * 13 + c * 5 + seed * 3) % 17) as f32 / 16.0).sqrt()
    });
    let depth = Array2::from_shape_fn((H, W), |(y, x)| ((x + 2 * y + seed) % 11) as f32 / 10.0);
    RgbdFrame::new(amp, depth).unwrap()
}

/// A panel far from linear: red follows one gamma curve over 2.4π; green's response varies smoothly over the
/// panel, as a real one does, if faster (8×8 tiles, gamma 0.85–1.15 and range 2.2π–2.5π from corner to
/// corner of a 24×40 panel); blue is linear.
fn calibration() -> DisplayCalibration {
    let mut cal = DisplayCalibration::linear(H, W).unwrap();
    let pi = std::f32::consts::PI;
    cal.colours[0].lut = PhaseLut::new(LutRepresentation::Global(
        PhaseCurve::gamma(2.4 * pi, 1.4).unwrap(),
    ));
    let (rows, cols) = (H.div_ceil(8), W.div_ceil(8));
    let curves = (0..rows * cols)
        .map(|t| {
            let u = (t / cols) as f32 / (rows - 1) as f32;
            let v = (t % cols) as f32 / (cols - 1) as f32;
            PhaseCurve::gamma((2.2 + 0.3 * u) * pi, 0.85 + 0.3 * v).unwrap()
        })
        .collect();
    let tiles = TiledCurves::new(H, W, 8, 8, curves).unwrap();
    cal.colours[1].lut = PhaseLut::new(LutRepresentation::Tiled(tiles));
    cal
}

fn cyclic(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(std::f32::consts::TAU);
    d.min(std::f32::consts::TAU - d)
}

/// Over colour `c`'s pixels, the largest cyclic distance between the phase the panel displays for
/// `out.codes` (through `lut`) and the double phase pattern `out.phase`, and the largest excess of that
/// distance over the best any code could do at that pixel (the naive search over the pixel's 256 phases).
fn display_error(lut: &PhaseLut, out: &SlmFrame, c: usize) -> (f32, f32) {
    let (mut worst, mut excess) = (0.0f32, 0.0f32);
    for ((y, x), &code) in out.codes.index_axis(Axis(0), c).indexed_iter() {
        let target = out.phase[[c, y, x]];
        let err = cyclic(lut.displayed_phase(y, x, code).unwrap(), target);
        let best = (0..=255u8)
            .map(|k| cyclic(lut.displayed_phase(y, x, k).unwrap(), target))
            .fold(f32::INFINITY, f32::min);
        worst = worst.max(err);
        excess = excess.max(err - best);
    }
    (worst, excess)
}

#[test]
fn calibrated_codes_make_the_panel_display_the_double_phase_pattern() {
    let cal = Arc::new(calibration());
    for prefilter in [false, true] {
        let plain = pipeline(prefilter);
        let calibrated = pipeline(prefilter).with_calibration(cal.clone()).unwrap();
        let mut linear = plain.session(H, W).unwrap();
        let mut session = calibrated.session(H, W).unwrap();
        let f = frame(1);
        let want = linear.render(&f).unwrap().clone();
        let got = session.render(&f).unwrap().clone();
        // The LUT changes the codes only.
        assert_eq!(got.phase, want.phase);
        for (c, col) in cal.colours.iter().enumerate() {
            let lut = &col.lut;
            let (calibrated_err, excess) = display_error(lut, &got, c);
            let (linear_err, _) = display_error(lut, &want, c);
            println!(
                "pre-filter {prefilter}, colour {c}: displayed phase within {calibrated_err:.4} rad with \
                 the calibration ({excess:.4} rad above the best code at worst), {linear_err:.4} rad with \
                 the linear LUT"
            );
            // The tables' interpolation (256 phase bins, bilinear between tiles) costs at most ~1/3 of a
            // code step over the best code (here 0.028 rad at worst, in the border half-tile).
            assert!(
                excess <= 0.04,
                "colour {c}: {excess} rad above the best code"
            );
            assert!(calibrated_err <= 0.08, "colour {c}: {calibrated_err}");
            if c < 2 {
                assert!(
                    linear_err > 0.5,
                    "colour {c}: the linear LUT fits this panel"
                );
            } else {
                assert_eq!(
                    got.codes.index_axis(Axis(0), c),
                    want.codes.index_axis(Axis(0), c)
                );
            }
        }
        // Streaming applies the same tables.
        let frames = vec![Ok(frame(1)), Ok(frame(2))];
        let mut streamed = Vec::new();
        session
            .render_stream(frames, |_, out| {
                streamed.push(out.codes.clone());
                Ok(())
            })
            .unwrap();
        assert_eq!(streamed[0], got.codes);
    }
}

#[test]
fn the_intensity_map_scales_the_target_amplitude() {
    let mut cal = DisplayCalibration::linear(H, W).unwrap();
    let scale = Array2::from_shape_fn((H, W), |(y, x)| 0.4 + 0.6 * ((x + 3 * y) % 10) as f32 / 9.0);
    cal.colours[1].intensity_scale = Some(scale.clone());
    let calibrated = pipeline(false).with_calibration(Arc::new(cal)).unwrap();
    let f = frame(3);
    let got = calibrated
        .session(H, W)
        .unwrap()
        .render(&f)
        .unwrap()
        .clone();
    // The same frame with its green amplitude scaled by hand, on an ideal display.
    let mut amp = f.amplitude.clone();
    amp.index_axis_mut(Axis(0), 1)
        .zip_mut_with(&scale, |a, &s| *a *= s);
    let scaled = RgbdFrame::new(amp, f.depth.clone()).unwrap();
    let want = pipeline(false)
        .session(H, W)
        .unwrap()
        .render(&scaled)
        .unwrap()
        .clone();
    assert_eq!(got.codes, want.codes);
    assert_eq!(got.phase, want.phase);
    let unscaled = pipeline(false)
        .session(H, W)
        .unwrap()
        .render(&f)
        .unwrap()
        .clone();
    assert_ne!(
        got.codes, unscaled.codes,
        "the map must change the hologram"
    );
}

fn temp_file(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("tensorholo-pipeline-cal-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn a_holocal_file_gives_the_same_frames_and_can_be_swapped_in_a_session() {
    let cal = calibration();
    let path = temp_file("panel.holocal");
    cal.write(&path).unwrap();
    let from_file = Arc::new(DisplayCalibration::read(&path).unwrap());
    let calibrated = pipeline(false).with_calibration(from_file.clone()).unwrap();
    let f = frame(4);
    let want = calibrated
        .session(H, W)
        .unwrap()
        .render(&f)
        .unwrap()
        .clone();
    // The file stores the curves in 16 bits (1/4096 rad): at most a rounding tie away from the originals.
    let in_memory = pipeline(false).with_calibration(Arc::new(cal)).unwrap();
    let exact = in_memory.session(H, W).unwrap().render(&f).unwrap().clone();
    let max_diff = exact
        .codes
        .iter()
        .zip(want.codes.iter())
        .map(|(&a, &b)| {
            (a as i32 - b as i32)
                .unsigned_abs()
                .min(256 - (a as i32 - b as i32).unsigned_abs())
        })
        .max()
        .unwrap();
    assert!(max_diff <= 1, "{max_diff}");

    let plain = pipeline(false);
    let mut session = plain.session(H, W).unwrap();
    let linear = session.render(&f).unwrap().clone();
    session.set_calibration(Some(from_file.clone())).unwrap();
    assert_eq!(session.render(&f).unwrap().codes, want.codes);
    // A calibration of another size is refused and the session keeps the one it has.
    let other = Arc::new(DisplayCalibration::linear(H, W + 2).unwrap());
    assert!(matches!(
        session.set_calibration(Some(other)),
        Err(HoloError::ShapeMismatch { .. })
    ));
    assert_eq!(session.render(&f).unwrap().codes, want.codes);
    session.set_calibration(None).unwrap();
    assert_eq!(session.render(&f).unwrap().codes, linear.codes);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn calibrations_of_another_size_or_wavelength_are_refused() {
    let small = pipeline(false)
        .with_calibration(Arc::new(DisplayCalibration::linear(H / 2, W).unwrap()))
        .unwrap();
    let err = small.session(H, W).unwrap_err();
    assert!(matches!(err, HoloError::ShapeMismatch { .. }), "{err}");
    assert!(err.to_string().contains(&format!("{}×{W}", H / 2)), "{err}");

    let mut cal = DisplayCalibration::linear(H, W).unwrap();
    cal.colours[2].wavelength_m = 473e-9;
    let err = pipeline(false)
        .with_calibration(Arc::new(cal.clone()))
        .unwrap_err();
    assert!(matches!(err, HoloError::InvalidParameter { .. }), "{err}");
    assert!(err.to_string().contains("473.0 nm"), "{err}");
    let mut session = pipeline(false).session(H, W).unwrap();
    assert!(session
        .set_calibration(Some(Arc::new(cal.clone())))
        .is_err());
    // Within 1 nm is the same laser.
    cal.colours[2].wavelength_m = 450.5e-9;
    pipeline(false).with_calibration(Arc::new(cal)).unwrap();
}
