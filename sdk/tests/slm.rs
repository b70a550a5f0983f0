//! Display calibration on a simulated SLM (paper Methods, Eq. 12–13, Fig. 11): per-pixel curves recovered from
//! the 256 double-phase captures, the deep-black test, and every kind of bad capture refused clearly.

use std::f32::consts::PI;
use std::path::Path;

use ndarray::Array2;
use tensorholo::slm::calibrate::{calibrate, CalibrationOptions};
use tensorholo::slm::captures::{capture_name, PngCaptureDir};
use tensorholo::slm::simulate::{write_grey_png, SimulatedSlm};
use tensorholo::slm::{
    black_test_codes, filtered_intensity, LutRepresentation, PhaseCurve, PhaseLut, TiledCurves,
};

fn quiet(_: u64, _: u64) {}

/// RMS difference (radians) between the calibrated per-pixel curves and the simulator's truth, over every
/// pixel and code.
fn rms_error(tiles: &TiledCurves, sim: &SimulatedSlm, colour: usize) -> f32 {
    let (mut sum, mut n) = (0f64, 0usize);
    for y in 0..sim.height {
        for x in 0..sim.width {
            let got = tiles.pixel_curve(y, x).unwrap();
            let truth = sim.true_curve(colour, y, x).unwrap();
            for (a, b) in got.iter().zip(truth.phases().iter()) {
                sum += ((a - b) as f64).powi(2);
                n += 1;
            }
        }
    }
    (sum / n as f64).sqrt() as f32
}

#[test]
fn recovered_curves_match_the_simulated_panel_and_deepen_black() {
    // 64×64 SLM (captures 128×128, noise, dust, a Gaussian beam); ranges 2π, 2.45π, 2.8π with ±8 % range and
    // ±15 % gamma variation across the panel.
    let sim = SimulatedSlm::new(64, 64, 7);
    // The default tile for 64 px is 4 (auto_tile); the simulator's fields vary over the panel's width.
    let options = CalibrationOptions::default();
    let mut luts = Vec::new();
    let mut globals = Vec::new();
    for colour in 0..3 {
        let (tiles, report) = calibrate(&sim.stack(colour), &options, &quiet).unwrap();
        let rms = rms_error(&tiles, &sim, colour);
        // The best global table of this panel (its mean curve) is far from many pixels' truth.
        let global = TiledCurves::new(64, 64, 64, 64, vec![tiles.mean_curve()]).unwrap();
        let rms_global = rms_error(&global, &sim, colour);
        eprintln!(
            "colour {colour}: per-pixel RMS {rms:.4} rad, global {rms_global:.4} rad, ranges {:?}, unusable {:.3}, filled {}",
            report.range_rad, report.unusable_fraction, report.filled_tiles
        );
        assert!(
            rms < 0.05,
            "colour {colour}: recovered curves {rms} rad RMS from the truth"
        );
        assert!(
            rms < 0.5 * rms_global,
            "colour {colour}: per-pixel {rms} vs global {rms_global}"
        );
        let nominal = sim.response[colour].range_rad as f32;
        assert!(
            report.range_rad[0] < nominal && report.range_rad[1] > nominal,
            "{:?}",
            report.range_rad
        );
        luts.push(PhaseLut::new(LutRepresentation::Tiled(tiles.clone())));
        globals.push(PhaseLut::new(LutRepresentation::Global(tiles.mean_curve())));
    }
    // Fig. 11: the π-offset checkerboard (double phase of black) through each LUT, displayed by the simulated
    // panel, after the Fourier filter.
    let linear = PhaseLut::linear();
    let black = |l: [&PhaseLut; 3]| {
        let codes = black_test_codes(l, 64, 64).unwrap();
        filtered_intensity(sim.display(codes.view()).unwrap().view()).unwrap()
    };
    let b_linear = black([&linear, &linear, &linear]);
    let b_global = black([&globals[0], &globals[1], &globals[2]]);
    let b_pixel = black([&luts[0], &luts[1], &luts[2]]);
    for c in 0..3 {
        eprintln!(
            "colour {c}: black level linear {:.2e}, global {:.2e}, per-pixel {:.2e}; contrast global {:.0}:1, per-pixel {:.0}:1",
            b_linear[c],
            b_global[c],
            b_pixel[c],
            1.0 / b_global[c],
            1.0 / b_pixel[c]
        );
        assert!(
            b_pixel[c] < b_global[c],
            "colour {c}: per-pixel black {} vs global {}",
            b_pixel[c],
            b_global[c]
        );
        assert!(b_global[c] < b_linear[c]);
        assert!(
            1.0 / b_pixel[c] > 100.0,
            "colour {c}: contrast {}",
            1.0 / b_pixel[c]
        );
    }
}

fn write_stack(sim: &SimulatedSlm, dir: &Path) {
    sim.write_captures(1, dir, &quiet).unwrap();
}

fn bytes_of(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path();
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn png_captures_calibrate_like_the_in_memory_stack() {
    let dir = tempdir("png");
    let sim = SimulatedSlm {
        bit_depth: 16,
        ..SimulatedSlm::new(16, 24, 3)
    };
    write_stack(&sim, &dir);
    let before = bytes_of(&dir);
    let options = CalibrationOptions {
        tile: 8,
        ..CalibrationOptions::default()
    };
    let stack = PngCaptureDir::open(&dir, (16, 24), None).unwrap();
    let (from_png, _) = calibrate(&stack, &options, &quiet).unwrap();
    let (in_memory, _) = calibrate(&sim.stack(1), &options, &quiet).unwrap();
    for (a, b) in from_png.curves().iter().zip(in_memory.curves()) {
        for (p, q) in a.phases().iter().zip(b.phases().iter()) {
            assert!((p - q).abs() < 2e-3, "{p} vs {q}");
        }
    }
    assert_eq!(
        bytes_of(&dir),
        before,
        "calibration must not touch its captures"
    );
    // A crop: the same captures padded by a black border read with --crop give the same tables.
    let padded = tempdir("crop");
    for k in 0..256 {
        let img = sim.capture(1, k).unwrap();
        let mut big = Array2::<f32>::zeros((32 + 7, 48 + 5));
        big.slice_mut(ndarray::s![3..35, 2..50]).assign(&img);
        write_grey_png(&padded.join(capture_name(k)), big.view(), 16).unwrap();
    }
    let crop = "2,3,48,32".parse().unwrap();
    let (cropped, _) = calibrate(
        &PngCaptureDir::open(&padded, (16, 24), Some(crop)).unwrap(),
        &options,
        &quiet,
    )
    .unwrap();
    assert_eq!(cropped, from_png);
    std::fs::remove_dir_all(&dir).ok();
    std::fs::remove_dir_all(&padded).ok();
}

fn tempdir(tag: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("tensorholo-slm-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn bad_captures_are_refused_naming_the_capture_or_region() {
    let options = CalibrationOptions {
        tile: 8,
        ..CalibrationOptions::default()
    };
    let sim = SimulatedSlm::new(16, 16, 5);
    let dir = tempdir("bad");
    write_stack(&sim, &dir);

    // A missing frame.
    let gone = dir.join(capture_name(137));
    let saved = std::fs::read(&gone).unwrap();
    std::fs::remove_file(&gone).unwrap();
    let e = PngCaptureDir::open(&dir, (16, 16), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("capture_137.png") && e.contains("lacks 1 of the 256"),
        "{e}"
    );
    std::fs::write(&gone, &saved).unwrap();

    // Mixed sizes.
    let odd = dir.join(capture_name(50));
    let saved = std::fs::read(&odd).unwrap();
    write_grey_png(&odd, Array2::<f32>::zeros((30, 32)).view(), 16).unwrap();
    let e = PngCaptureDir::open(&dir, (16, 16), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("capture_050.png") && e.contains("32×30") && e.contains("32×32"),
        "{e}"
    );
    std::fs::write(&odd, &saved).unwrap();

    // A truncated file is an error naming it, not a grey frame.
    let cut = dir.join(capture_name(9));
    let saved = std::fs::read(&cut).unwrap();
    std::fs::write(&cut, &saved[..saved.len() / 2]).unwrap();
    let stack = PngCaptureDir::open(&dir, (16, 16), None).unwrap();
    let e = calibrate(&stack, &options, &quiet).unwrap_err().to_string();
    assert!(e.contains("capture_009.png"), "{e}");
    std::fs::write(&cut, &saved).unwrap();

    // An SLM larger than the captures.
    let e = PngCaptureDir::open(&dir, (64, 64), None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("smaller than the 64×64 SLM"), "{e}");
    std::fs::remove_dir_all(&dir).ok();

    // Saturated: 2.5× the exposure clips the beam's centre.
    let over = Overexposed(&sim, 2.5);
    let e = calibrate(&over, &options, &quiet).unwrap_err().to_string();
    assert!(
        e.contains("saturated")
            && e.contains("simulated capture")
            && e.contains("% of the SLM's pixels"),
        "{e}"
    );

    // Dark.
    let dark = SimulatedSlm {
        peak: 0.004,
        noise: 0.0005,
        ..sim.clone()
    };
    let e = calibrate(&dark.stack(0), &options, &quiet)
        .unwrap_err()
        .to_string();
    assert!(e.contains("dark") && e.contains("rows 0–15"), "{e}");

    // A phase range below π: no minimum to find.
    let mut shallow = sim.clone();
    shallow.response[2].range_rad = 0.8 * std::f64::consts::PI;
    let e = calibrate(&shallow.stack(2), &options, &quiet)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("never reaches a minimum") && e.contains("below π") && e.contains("rows 0–15"),
        "{e}"
    );
}

/// A simulated stack captured with `gain` times the exposure (clipped at full scale).
struct Overexposed<'a>(&'a SimulatedSlm, f32);

impl tensorholo::slm::calibrate::CaptureStack for Overexposed<'_> {
    fn slm_size(&self) -> (usize, usize) {
        (self.0.height, self.0.width)
    }
    fn name(&self, k: usize) -> String {
        format!("simulated capture {k}")
    }
    fn read(&self, k: usize, out: &mut [f32], clipped: &mut [bool]) -> tensorholo::Result<()> {
        let img = self.0.capture(0, k)?.mapv(|v| (v * self.1).min(1.0));
        tensorholo::slm::captures::downsample(img.view(), self.slm_size(), out, clipped)
    }
}

#[test]
fn global_curves_from_csv_and_models_apply_as_luts() {
    // A 3π panel: code 255 displays 3π; the LUT must send 2π to the code that displays 2π, not to 255.
    let curve = PhaseCurve::gamma(3.0 * PI, 1.0).unwrap();
    let lut = PhaseLut::new(LutRepresentation::Global(curve.clone()));
    let phase = [0.0, PI, 2.0 * PI - 1e-3, 0.5];
    let mut codes = [0u8; 4];
    lut.apply(1, 4, &phase, &mut codes).unwrap();
    assert_eq!(codes[0], 0);
    assert!(
        (curve.phases()[codes[1] as usize] - PI).abs() < 0.02,
        "{codes:?}"
    );
    assert!(
        (curve.phases()[codes[2] as usize] - 2.0 * PI).abs() < 0.02,
        "{codes:?}"
    );
    assert!(
        codes[2] < 200,
        "2π lies at code 170 of a 3π panel, got {}",
        codes[2]
    );
}

#[test]
fn tile_size_trades_memory_for_accuracy() {
    // The green panel of a 128×128 simulated SLM calibrated with tiles of 4 to 32 px: RMS from the truth and
    // the stored size, scaled to a 1080p panel's three colours (docs/CALIBRATION.md's table).
    let sim = SimulatedSlm::new(128, 128, 3);
    let stack = sim.stack(1);
    let mut rms = Vec::new();
    for tile in [4usize, 8, 16, 32] {
        let options = CalibrationOptions {
            tile,
            ..CalibrationOptions::default()
        };
        let (tiles, _) = calibrate(&stack, &options, &quiet).unwrap();
        let e = rms_error(&tiles, &sim, 1);
        let mb_1080p = 3 * 1080usize.div_ceil(tile) * 1920usize.div_ceil(tile) * 512;
        eprintln!(
            "tile {tile:>2} px: RMS {e:.4} rad, {} B here, {:.1} MB for 1080p × 3 colours",
            tiles.stored_bytes(),
            mb_1080p as f64 / 1e6
        );
        assert_eq!(tiles.stored_bytes(), 128usize.div_ceil(tile).pow(2) * 512);
        rms.push(e);
    }
    let global = {
        let (tiles, _) = calibrate(&stack, &CalibrationOptions::default(), &quiet).unwrap();
        let g = TiledCurves::new(128, 128, 128, 128, vec![tiles.mean_curve()]).unwrap();
        rms_error(&g, &sim, 1)
    };
    eprintln!("global: RMS {global:.4} rad, 512 B");
    // Tiles too coarse for the panel's variation lose accuracy; every tiling beats the global table.
    assert!(rms[3] > rms[1], "{rms:?}");
    assert!(rms.iter().all(|&e| e < 0.5 * global), "{rms:?} vs {global}");
}
