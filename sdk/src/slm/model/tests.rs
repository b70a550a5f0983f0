//! The display model's file, its validation, and the refinement through it: the ideal model bit for bit, the
//! gradient through each part against finite differences, the projected step.

use std::ops::ControlFlow;

use ndarray::Array3;

use super::*;
use crate::refine::{loss_depths, FocalTarget, RefineOptions, Refiner};
use crate::slm::model_captures::{draw_display, response_curve, varying_response};
use crate::splitmix::SplitMix64;

const OFFSET_M: f64 = 2e-3;

fn target(h: usize, w: usize, seed: u64) -> FocalTarget {
    let mut rng = SplitMix64::new(seed);
    let mid = Array3::from_shape_simple_fn((3, h, w), || {
        Complex32::from_polar(
            0.2 + rng.next_f64() as f32,
            (rng.next_f64() * std::f64::consts::TAU) as f32,
        )
    });
    FocalTarget::from_midpoint(
        mid.view(),
        &OpticalSetup::default(),
        PropagationOptions::default(),
        &loss_depths(3).unwrap(),
    )
    .unwrap()
}

fn refiner(h: usize, w: usize, quantised: bool, model: Option<&DisplayModel>) -> Refiner {
    let options = RefineOptions {
        quantised,
        planes: 3,
        ..Default::default()
    };
    refiner_with(h, w, options, model)
}

fn refiner_with(
    h: usize,
    w: usize,
    options: RefineOptions,
    model: Option<&DisplayModel>,
) -> Refiner {
    Refiner::new(
        &OpticalSetup::default(),
        PropagationOptions::default(),
        OFFSET_M,
        target(h, w, 3),
        options,
        2,
    )
    .unwrap()
    .with_display_model(model)
    .unwrap()
}

/// A phase inside the drive's range, away from its ends (the projection's clamp has no gradient there).
fn drive_phase(h: usize, w: usize, seed: u64) -> Array3<f32> {
    let mut rng = SplitMix64::new(seed);
    Array3::from_shape_simple_fn((3, h, w), || {
        (0.2 + rng.next_f64() * (f64::from(255.0 * LINEAR_SLOPE) - 0.4)) as f32
    })
}

fn with_part(h: usize, w: usize, f: impl Fn(&mut ColourDisplay)) -> DisplayModel {
    let mut m = DisplayModel {
        slm_size: [h, w],
        ..Default::default()
    };
    for c in &mut m.colours {
        f(c);
    }
    m
}

#[test]
fn a_model_without_parts_refines_bit_for_bit_as_the_ideal_display() {
    let (h, w) = (16, 20);
    let start = drive_phase(h, w, 5);
    let run = |model: Option<&DisplayModel>| {
        let mut r = refiner(h, w, true, model);
        let mut p = start.clone();
        let report = r
            .refine(p.view_mut(), &mut |_| ControlFlow::Continue(()))
            .unwrap();
        (p, report.history)
    };
    let ideal = run(None);
    let empty = DisplayModel {
        slm_size: [h, w],
        ..Default::default()
    };
    let through = run(Some(&empty));
    assert!(ideal
        .0
        .iter()
        .zip(&through.0)
        .all(|(a, b)| a.to_bits() == b.to_bits()));
    assert_eq!(ideal.1, through.1);
    // And the file of such a model reads back as one without parts.
    let back = DisplayModel::from_json_str(&empty.to_json_string(), "t").unwrap();
    assert!(back.is_ideal());
}

#[test]
fn the_gradient_through_each_part_matches_finite_differences() {
    let (h, w) = (12, 14);
    let drawn = draw_display([h, w], 1, 4).colours[1].clone();
    let parts: Vec<(&str, DisplayModel)> = vec![
        ("source", with_part(h, w, |c| c.source = drawn.source)),
        (
            "response",
            with_part(h, w, |c| {
                c.response = Some(LutRepresentation::Global(
                    response_curve(1.05, 0.2, -0.1).unwrap(),
                ))
            }),
        ),
        (
            "crosstalk",
            with_part(h, w, |c| {
                c.crosstalk = Some(Crosstalk {
                    size: [3, 3],
                    weights: vec![0.0, 0.08, 0.01, 0.12, 0.7, 0.05, 0.02, 0.02, 0.0],
                })
            }),
        ),
        (
            "per-pixel response",
            with_part(h, w, |c| c.response = Some(varying_response(h, w, 4))),
        ),
        (
            "zero_order",
            with_part(h, w, |c| c.zero_order = Some([0.2, -0.1])),
        ),
        (
            "aberration",
            with_part(h, w, |c| c.aberration = drawn.aberration),
        ),
        ("all", with_part(h, w, |c| *c = drawn.clone())),
    ];
    for (name, model) in parts {
        let mut r = refiner(h, w, false, Some(&model));
        let phase = drive_phase(h, w, 8);
        let (_, grad) = r.loss_and_gradient(phase.view());
        let scale = grad.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(scale > 0.0, "{name}");
        let mut rng = SplitMix64::new(9);
        let step = 2e-3f32;
        for _ in 0..10 {
            let (c, y, x) = (
                (rng.next_f64() * 3.0) as usize,
                (rng.next_f64() * h as f64) as usize,
                (rng.next_f64() * w as f64) as usize,
            );
            let mut plus = phase.clone();
            plus[[c, y, x]] += step;
            let mut minus = phase.clone();
            minus[[c, y, x]] -= step;
            let fd = (r.score(plus.view()).unwrap().loss - r.score(minus.view()).unwrap().loss)
                / (2.0 * f64::from(step));
            let an = f64::from(grad[[c, y, x]]);
            assert!(
                (fd - an).abs() <= 0.03 * f64::from(scale),
                "{name}: pixel ({c}, {y}, {x}): finite difference {fd}, analytic {an} (largest {scale})"
            );
        }
    }
}

#[test]
fn refinement_through_a_model_keeps_the_codes_in_range_and_lowers_its_loss() {
    let (h, w) = (16, 16);
    let model = draw_display([h, w], 1, 2);
    let mut model3 = model.clone();
    model3.colours = [
        model.colours[1].clone(),
        model.colours[1].clone(),
        model.colours[1].clone(),
    ];
    let mut r = refiner(h, w, true, Some(&model3));
    // A start that wraps: values beyond 2π and below 0 are projected into the drive's range.
    let mut p = drive_phase(h, w, 1).mapv(|v| v * 1.3 - 0.5);
    let report = r
        .refine(p.view_mut(), &mut |_| ControlFlow::Continue(()))
        .unwrap();
    assert!(p.iter().all(|&v| (0.0..=255.0 * LINEAR_SLOPE).contains(&v)));
    let (first, last) = (report.history[0].loss, report.history.last().unwrap().loss);
    assert!(last < 0.9 * first, "loss {first} → {last}");
}

/// What a fitted display shows of codes at the midpoint plane (`DisplayModel::shown_midpoint`, the evaluation's
/// "displayed"), refocused at a plane, is that display's direct simulation there (the captures' forward model,
/// `M·E·H(z_d − s)` in one multiplier); with a strong crosstalk it is far from the ideal display's, and a model
/// without parts is the ideal display of the codes.
#[test]
fn what_a_model_shows_is_its_direct_simulation_and_not_the_ideal_display() {
    let (h, w) = (24, 32);
    let setup = OpticalSetup::default();
    let options = PropagationOptions::default();
    let mut rng = SplitMix64::new(21);
    let codes = Array3::from_shape_simple_fn((3, h, w), || (rng.next_f64() * 256.0) as u8);
    let phase = codes.mapv(|c| f32::from(c) * LINEAR_SLOPE);
    let drawn = draw_display([h, w], 1, 6).colours[1].clone();
    let model = with_part(h, w, |c| {
        *c = drawn.clone();
        c.crosstalk = Some(Crosstalk {
            size: [3, 3],
            weights: vec![0.03, 0.1, 0.03, 0.14, 0.4, 0.14, 0.03, 0.1, 0.03],
        });
    });
    let scale = 0.7f32;
    let shown = model
        .shown_midpoint(codes.view(), scale, &setup, OFFSET_M, options)
        .unwrap();
    let ideal =
        crate::optics::post_encoding_midpoint(phase.view(), scale, &setup, OFFSET_M, options)
            .unwrap();
    let depths = [0.15, 0.6, 0.95];
    let stack =
        crate::optics::focal_stack(shown.view(), &setup, 0.0, &depths, options, false).unwrap();
    let ideal_stack =
        crate::optics::focal_stack(ideal.view(), &setup, 0.0, &depths, options, false).unwrap();
    for (k, &d) in depths.iter().enumerate() {
        let planes: Vec<_> = (0..3)
            .map(|c| (c, c, setup.depth_to_z(d) - OFFSET_M))
            .collect();
        let patterns: Vec<_> = codes.outer_iter().map(|p| p.to_owned()).collect();
        let (direct, gain) = crate::slm::model_captures::simulate_captures(
            &model, &setup, &patterns, &planes, 0.0, 1,
        )
        .unwrap();
        for (c, captured) in direct.iter().enumerate() {
            let want = captured.mapv(|v| v / gain as f32 * scale * scale);
            let got = stack[k].index_axis(ndarray::Axis(0), c).mapv(|a| a * a);
            let peak = want.iter().fold(0.0f32, |m, &v| m.max(v));
            let err = got
                .iter()
                .zip(&want)
                .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
            assert!(err < 1e-4 * peak, "depth {d}, colour {c}: {err} of {peak}");
            let ideal_i = ideal_stack[k]
                .index_axis(ndarray::Axis(0), c)
                .mapv(|a| a * a);
            let off = ideal_i
                .iter()
                .zip(&want)
                .map(|(a, b)| (a - b).abs())
                .sum::<f32>()
                / want.iter().sum::<f32>();
            assert!(
                off > 0.2,
                "depth {d}, colour {c}: the ideal display within {off} of the model's"
            );
        }
    }
    let none = DisplayModel {
        slm_size: [h, w],
        ..Default::default()
    }
    .shown_midpoint(codes.view(), scale, &setup, OFFSET_M, options)
    .unwrap();
    let err = none
        .iter()
        .zip(&ideal)
        .fold(0.0f32, |m, (a, b)| m.max((a - b).norm()));
    assert!(
        err < 1e-4,
        "a model without parts: {err} from the ideal display"
    );
    // Codes of another size than the model's, and a padded propagation: refused.
    assert!(model
        .shown_midpoint(
            codes.slice(ndarray::s![.., ..20, ..]),
            scale,
            &setup,
            OFFSET_M,
            options
        )
        .is_err());
    let padded = PropagationOptions {
        pad: true,
        ..options
    };
    assert!(model
        .shown_midpoint(codes.view(), scale, &setup, OFFSET_M, padded)
        .is_err());
}

#[test]
fn bad_model_files_are_refused_naming_the_entry() {
    let base = r#"{"format": "tensorholo.display-model", "version": 1, "slm_size": [8, 8], "green": PART}"#;
    let cases = [
        (r#"{"bogus": {}}"#, "bogus"),
        (
            r#"{"crosstalk": {"size": [2, 3], "weights": [0, 0, 0, 0, 1, 0]}}"#,
            "green.crosstalk",
        ),
        (r#"{"zero_order": [0.8, 0.7]}"#, "green.zero_order"),
        (r#"{"zero_order": [1.0, 0.0]}"#, "green.zero_order"),
        (
            r#"{"source": {"log_amplitude": [1e999, 0, 0, 0, 0]}}"#,
            "source",
        ),
    ];
    for (part, named) in cases {
        let text = base.replace("PART", part);
        let e = DisplayModel::from_json_str(&text, "m.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains(named) && e.contains("m.json"), "{part}: {e}");
    }
    let mut m = with_part(8, 8, |c| {
        c.crosstalk = Some(Crosstalk {
            size: [3, 3],
            weights: vec![0.0, 0.0, 0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0],
        })
    });
    assert!(m
        .validate()
        .unwrap_err()
        .to_string()
        .contains("red.crosstalk"));
    m.colours = Default::default();
    m.colours[2].aberration = Some(ZernikeCoefficients {
        focus: f64::INFINITY,
        ..Default::default()
    });
    assert!(m
        .validate()
        .unwrap_err()
        .to_string()
        .contains("blue.aberration"));
    // Another SLM size than the frame's.
    let model = with_part(8, 8, |c| c.zero_order = Some([0.1, 0.0]));
    let e = Refiner::new(
        &OpticalSetup::default(),
        PropagationOptions::default(),
        OFFSET_M,
        target(16, 16, 1),
        RefineOptions::default(),
        1,
    )
    .unwrap()
    .with_display_model(Some(&model))
    .unwrap_err();
    assert!(matches!(e, HoloError::ShapeMismatch { .. }), "{e}");
    // A model reads back as written, a per-pixel response too.
    let mut drawn = draw_display([8, 8], 0, 3);
    let back = DisplayModel::from_json_str(&drawn.to_json_string(), "t").unwrap();
    assert_eq!(back, drawn);
    drawn.colours[0].response = Some(varying_response(8, 8, 4));
    let text = drawn.to_json_string();
    assert!(text.contains("per_pixel"));
    assert_eq!(DisplayModel::from_json_str(&text, "t").unwrap(), drawn);
    // Per-pixel tables of another SLM size than the model's, or both forms at once: refused, naming the entry.
    drawn.colours[0].response = Some(varying_response(8, 12, 4));
    let e = DisplayModel::from_json_str(&drawn.to_json_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("red.response") && e.contains("8×12"), "{e}");
    let both = base.replace(
        "PART",
        r#"{"response": {"phases_rad": [], "per_pixel": {"slm_size": [8, 8], "tile": [8, 8], "tiles_rad": []}}}"#,
    );
    let e = DisplayModel::from_json_str(&both, "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("either"), "{e}");
}

/// The GPU's refinement through a display model (`refine.wgsl`'s `model_` kernels) follows the CPU's: a
/// non-square frame, every part drawn (red's response per pixel; a 3×5 kernel on green, not symmetric, for
/// the gathered adjoint at the clamped edges), quantised and not: each iteration's loss-plane PSNR within 0.02 dB and the refined drive
/// within 1e-3 rad of the CPU's everywhere (measured: 6e-6; an adjoint that misses the clamped edges is off
/// by 0.04), inside the codes' range. Skips without an adapter (lavapipe in CI).
#[cfg(feature = "gpu")]
#[test]
fn the_gpu_refines_through_a_model_as_the_cpu_does() {
    let Some(ctx) = crate::gpu::test_support::context() else {
        return;
    };
    let (h, w) = (24, 40);
    let mut model = DisplayModel {
        slm_size: [h, w],
        ..Default::default()
    };
    for c in 0..3 {
        model.colours[c] = draw_display([h, w], c, 30 + c as u64).colours[c].clone();
    }
    // Red's response per pixel (tiles of 8 pixels), for the blend of the tiles' curves.
    model.colours[0].response = Some(varying_response(h, w, 8));
    model.colours[1].crosstalk = Some(Crosstalk {
        size: [3, 5],
        weights: vec![
            0.0, 0.01, 0.03, 0.0, 0.0, 0.005, 0.04, 0.83, 0.02, 0.01, 0.0, 0.0, 0.03, 0.02, 0.005,
        ],
    });
    for quantised in [false, true] {
        let options = RefineOptions {
            quantised,
            planes: 3,
            iterations: 6,
            ..Default::default()
        };
        let make = || refiner_with(h, w, options, Some(&model));
        let start = drive_phase(h, w, 12);
        let mut cpu = start.clone();
        let cpu_report = make()
            .refine(cpu.view_mut(), &mut |_| ControlFlow::Continue(()))
            .unwrap();
        let mut gpu = start.clone();
        let gpu_report = make()
            .on_gpu(&ctx)
            .unwrap()
            .refine(gpu.view_mut(), &mut |_| ControlFlow::Continue(()))
            .unwrap();
        for (a, b) in cpu_report.history.iter().zip(&gpu_report.history) {
            assert!(
                (a.psnr_db - b.psnr_db).abs() < 0.02,
                "quantised {quantised}, iteration {}: CPU {:.4} dB, GPU {:.4} dB",
                a.iteration,
                a.psnr_db,
                b.psnr_db
            );
        }
        let first = &cpu_report.history[0];
        let last = cpu_report.history.last().unwrap();
        assert!(last.loss < 0.95 * first.loss, "{first:?} → {last:?}");
        let worst = cpu
            .iter()
            .zip(&gpu)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        eprintln!("quantised {quantised}: the GPU's drive within {worst:.1e} rad of the CPU's");
        assert!(
            worst < 1e-3,
            "quantised {quantised}: drives differ by {worst} rad"
        );
        assert!(gpu.iter().all(|p| (0.0..=255.0 * LINEAR_SLOPE).contains(p)));
    }
}
