//! Double phase encoding (Eq. 7) followed by the Fourier filter (Eq. 8–9) must reproduce a smooth complex
//! field; pre-filtered variants trade sharpness for fidelity as documented.

mod common;

use common::Rng;
use ndarray::{Array2, Array3, Axis};
use num_complex::Complex32;
use tensorholo::encoding::{
    double_phase_encode, phase_to_codes, DoublePhase, DoublePhaseMethod, LinearLut,
};
use tensorholo::metrics::psnr;
use tensorholo::optics::{simulate_phase_only, Carrier, OpticalSetup, PropagationOptions};

/// A smooth random complex field `[3, H, W]`: amplitude in [0.2, 1], phase within ±2 rad, built from a few
/// low spatial frequencies (well inside the Fourier filter's aperture).
fn smooth_field(h: usize, w: usize, seed: u64) -> Array3<Complex32> {
    let mut rng = Rng::new(seed);
    let waves: Vec<(f32, f32, f32, f32)> = (0..12)
        .map(|_| {
            let fx = (rng.next() - 0.5) * 0.1;
            let fy = (rng.next() - 0.5) * 0.1;
            (fx, fy, rng.next() * std::f32::consts::TAU, rng.next())
        })
        .collect();
    let smooth = |y: usize, x: usize, k: usize| -> f32 {
        let (fx, fy, ph, a) = waves[k];
        a * (std::f32::consts::TAU * (fx * x as f32 + fy * y as f32) + ph).sin()
    };
    Array3::from_shape_fn((3, h, w), |(c, y, x)| {
        let amp = 0.6 + 0.2 * (smooth(y, x, c) + smooth(y, x, 3 + c));
        let phase = 1.0 * (smooth(y, x, 6 + c) + smooth(y, x, 9 - c));
        Complex32::from_polar(amp.clamp(0.2, 1.0), phase)
    })
}

/// Double phase encoding, then the display's Fourier filter at a 0 mm offset: (encoding, field at midpoint).
fn encode_and_simulate(
    field: &Array3<Complex32>,
    method: DoublePhaseMethod,
) -> (DoublePhase, Array3<Complex32>) {
    let dp = double_phase_encode(field.view(), &method).unwrap();
    let recon = simulate_phase_only(
        dp.phase.view(),
        &OpticalSetup::default(),
        0.0,
        Default::default(),
    )
    .unwrap();
    (dp, recon)
}

fn encode_and_reconstruct(
    field: &Array3<Complex32>,
    method: DoublePhaseMethod,
) -> (Array3<f32>, Array3<f32>) {
    let (dp, recon) = encode_and_simulate(field, method);
    let target = field.mapv(|v| v.norm() / dp.amplitude_scale);
    (recon.mapv(|v| v.norm()), target)
}

#[test]
fn double_phase_plus_fourier_filter_reproduces_a_smooth_field() {
    let field = smooth_field(128, 160, 1);
    let (dp, recon) = encode_and_simulate(&field, DoublePhaseMethod::Plain);
    let (_, h, w) = field.dim();
    // Compare the complex field (amplitude and phase, up to the removed per-channel mean phase), away from the
    // borders where the periodic FFT meets a non-periodic field.
    let crop = |a: &Array3<f32>| a.slice(ndarray::s![.., 8..h - 8, 8..w - 8]).to_owned();
    let mut re_t = Array3::zeros((3, h, w));
    let mut re_r = Array3::zeros((3, h, w));
    for c in 0..3 {
        let rot = Complex32::from_polar(1.0 / dp.amplitude_scale, -dp.mean_phase[c]);
        for y in 0..h {
            for x in 0..w {
                let t = field[[c, y, x]] * rot;
                re_t[[c, y, x]] = t.re;
                re_r[[c, y, x]] = recon[[c, y, x]].re;
            }
        }
    }
    let amp_psnr = psnr(
        crop(&field.mapv(|v| v.norm() / dp.amplitude_scale)).view(),
        crop(&recon.mapv(|v| v.norm())).view(),
        1.0,
    )
    .unwrap();
    let re_psnr = psnr(crop(&re_t).view(), crop(&re_r).view(), 2.0).unwrap();
    println!("DPM + Fourier filter on a smooth field: amplitude PSNR {amp_psnr:.1} dB, real part {re_psnr:.1} dB");
    assert!(amp_psnr > 40.0, "amplitude PSNR {amp_psnr} dB");
    assert!(re_psnr > 40.0, "real-part PSNR {re_psnr} dB");
}

#[test]
fn without_the_fourier_filter_the_double_phase_pattern_is_not_the_field() {
    // The unfiltered phase-only field has unit amplitude everywhere: the filter is what removes the
    // checkerboard term. Guards against a filter that passes everything.
    let field = smooth_field(64, 64, 2);
    let dp = double_phase_encode(field.view(), &DoublePhaseMethod::Plain).unwrap();
    let raw = dp.phase.mapv(|p| 1.0f32 + 0.0 * p);
    let target = field.mapv(|v| v.norm() / dp.amplitude_scale);
    assert!(psnr(target.view(), raw.view(), 1.0).unwrap() < 15.0);
}

#[test]
fn offset_encoding_reconstructs_at_the_midpoint() {
    // Encode at an SLM plane 6 mm from the midpoint (Eq. 6), simulate back (Eq. 10): the midpoint amplitude
    // returns.
    let setup = OpticalSetup::default();
    let field = smooth_field(96, 96, 3);
    let mut slm = field.clone();
    tensorholo::optics::propagate_colour(
        &mut slm,
        &setup,
        6e-3,
        Carrier::Remove,
        PropagationOptions::default(),
    )
    .unwrap();
    let dp = double_phase_encode(slm.view(), &DoublePhaseMethod::Plain).unwrap();
    let recon =
        simulate_phase_only(dp.phase.view(), &setup, 6e-3, PropagationOptions::default()).unwrap();
    let a = recon.mapv(|v| v.norm() * dp.amplitude_scale);
    let t = field.mapv(|v| v.norm());
    let p = psnr(t.view(), a.view(), 1.0).unwrap();
    println!("6 mm offset round trip: amplitude PSNR {p:.1} dB");
    assert!(p > 30.0, "{p}");
}

#[test]
fn pre_filters_trade_detail_for_smoothness() {
    // A field with fine detail (random amplitude per pixel): AA-DPM and BL-DPM blur it, so the encoded
    // reconstruction loses high-frequency energy relative to plain DPM.
    let mut rng = Rng::new(4);
    let field = Array3::from_shape_fn((3, 64, 64), |_| {
        Complex32::from_polar(0.2 + 0.8 * rng.next(), 0.0)
    });
    let hf = |a: &Array3<f32>| -> f64 {
        let mut e = 0.0;
        for ch in a.axis_iter(Axis(0)) {
            let g: Array2<f32> =
                Array2::from_shape_fn((63, 63), |(y, x)| ch[[y, x + 1]] - ch[[y, x]]);
            e += g.mapv(|v| (v * v) as f64).sum();
        }
        e
    };
    let (plain, _) = encode_and_reconstruct(&field, DoublePhaseMethod::Plain);
    let (aa, _) = encode_and_reconstruct(
        &field,
        DoublePhaseMethod::AntiAliased {
            sigma_px: 1.0,
            kernel_size: 7,
        },
    );
    let (bl, _) = encode_and_reconstruct(&field, DoublePhaseMethod::BandLimited { k: 0.5 });
    assert!(
        hf(&aa) < 0.7 * hf(&plain),
        "AA {} vs plain {}",
        hf(&aa),
        hf(&plain)
    );
    assert!(
        hf(&bl) < 0.7 * hf(&plain),
        "BL {} vs plain {}",
        hf(&bl),
        hf(&plain)
    );
}

#[test]
fn slm_codes_follow_the_linear_lut() {
    let field = smooth_field(16, 16, 5);
    let dp = double_phase_encode(field.view(), &DoublePhaseMethod::Plain).unwrap();
    let codes = phase_to_codes(dp.phase.view());
    for (p, c) in dp.phase.iter().zip(codes.iter()) {
        let back = LinearLut.phase(*c);
        let d = (back - p).abs();
        assert!(d.min(std::f32::consts::TAU - d) <= std::f32::consts::PI / 256.0 + 1e-5);
    }
}
