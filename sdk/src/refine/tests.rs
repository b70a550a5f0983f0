//! The refinement's model, gradient, optimiser and refusals.

use std::f32::consts::TAU;
use std::ops::ControlFlow;

use ndarray::Array3;
use num_complex::Complex32;

use super::*;
use crate::display::AberrationProfile;
use crate::error::HoloError;
use crate::optics::{focal_stack, OpticalSetup, PropagationOptions};
use crate::refine::engine::held_out_psnr;
use crate::slm::codes::displayed_phase;
use crate::splitmix::SplitMix64;

const OFFSET_M: f64 = 2e-3;

/// The continuous phase's loss (a quantised loss is piecewise constant: no finite differences).
const CONTINUOUS: RefineOptions = RefineOptions {
    iterations: 10,
    step_rad: 0.04,
    beta1: 0.9,
    beta2: 0.999,
    epsilon: 1e-8,
    planes: 7,
    quantised: false,
};

fn setup() -> OpticalSetup {
    OpticalSetup::default()
}

/// A smooth random-ish complex midpoint hologram `[3, h, w]` (a scene-like target).
fn midpoint(h: usize, w: usize, seed: u64) -> Array3<Complex32> {
    let mut rng = SplitMix64::new(seed);
    let blobs: Vec<[f64; 4]> = (0..6)
        .map(|_| {
            [
                rng.next_f64() * h as f64,
                rng.next_f64() * w as f64,
                2.0 + 4.0 * rng.next_f64(),
                0.3 + 0.7 * rng.next_f64(),
            ]
        })
        .collect();
    Array3::from_shape_fn((3, h, w), |(c, y, x)| {
        let a: f64 = blobs
            .iter()
            .map(|&[by, bx, r, v]| {
                let d2 = (y as f64 - by).powi(2) + (x as f64 - bx).powi(2);
                v * (-d2 / (2.0 * r * r)).exp() * (1.0 + 0.2 * c as f64)
            })
            .sum();
        Complex32::from_polar(a as f32, ((x * 7 + y * 3 + c) % 11) as f32 * 0.3)
    })
}

fn target(h: usize, w: usize, depths: &[f64]) -> FocalTarget {
    FocalTarget::from_midpoint(
        midpoint(h, w, 5).view(),
        &setup(),
        Default::default(),
        depths,
    )
    .unwrap()
}

fn random_phase(h: usize, w: usize, seed: u64) -> Array3<f32> {
    initial_phase(RefineStart::Random { seed }, h, w).unwrap()
}

fn refiner(target: FocalTarget, options: RefineOptions, threads: usize) -> Refiner {
    Refiner::new(
        &setup(),
        Default::default(),
        OFFSET_M,
        target,
        options,
        threads,
    )
    .unwrap()
}

/// The display of the tests' frame refiners: the default optics at [`OFFSET_M`], no calibration, no viewer.
fn ideal_display() -> RefineDisplay {
    RefineDisplay {
        optics: setup(),
        propagation: Default::default(),
        offset_m: OFFSET_M,
        encoding: Default::default(),
        calibration: None,
        viewer: None,
        viewer_corrected_by_cnn: false,
    }
}

fn never_stop(_: &IterationRecord) -> ControlFlow<()> {
    ControlFlow::Continue(())
}

/// The loss's model is the display's: the focal stack of the pattern itself (through the Fourier filter,
/// from the SLM plane, `optics::focal_stack` with its aperture) as target gives a loss of ~0, and two
/// different patterns' stacks do not.
#[test]
fn a_patterns_own_focal_stack_is_its_loss_minimum() {
    let (h, w) = (24, 32);
    let depths = loss_depths(3).unwrap();
    let phase = random_phase(h, w, 1);
    let field = phase.mapv(|p| Complex32::from_polar(1.0, p));
    let own = focal_stack(
        field.view(),
        &setup(),
        OFFSET_M,
        &depths,
        Default::default(),
        true,
    )
    .unwrap();
    // Scaled by 0.3: the least-squares scale absorbs it.
    let own = own.into_iter().map(|a| a * 0.3).collect();
    let mut r = refiner(
        FocalTarget::from_stack(depths.clone(), own).unwrap(),
        CONTINUOUS,
        2,
    );
    let same = r.score(phase.view()).unwrap();
    assert!(same.psnr_db > 80.0, "{same:?}");
    let other = r.score(random_phase(h, w, 2).view()).unwrap();
    assert!(other.psnr_db < 40.0, "{other:?}");
    let (_, grad) = r.loss_and_gradient(phase.view());
    let (_, grad_other) = r.loss_and_gradient(random_phase(h, w, 2).view());
    let max = |g: &Array3<f32>| g.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(
        max(&grad) < 1e-3 * max(&grad_other),
        "{} vs {}",
        max(&grad),
        max(&grad_other)
    );
}

/// The analytic gradient against central finite differences of the loss, at pixels of every colour.
#[test]
fn the_analytic_gradient_matches_finite_differences() {
    let (h, w) = (16, 20);
    let t = target(h, w, &loss_depths(3).unwrap());
    let mut r = refiner(t, CONTINUOUS, 1);
    let phase = random_phase(h, w, 3);
    let (_, grad) = r.loss_and_gradient(phase.view());
    let scale = grad.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let mut rng = SplitMix64::new(9);
    let step = 2e-3f32;
    let mut checked = 0;
    for _ in 0..12 {
        let c = rng.below(0, 3);
        let y = rng.below(0, h);
        let x = rng.below(0, w);
        let mut plus = phase.clone();
        plus[[c, y, x]] += step;
        let mut minus = phase.clone();
        minus[[c, y, x]] -= step;
        let lp = r.score(plus.view()).unwrap().loss;
        let lm = r.score(minus.view()).unwrap().loss;
        let fd = (lp - lm) / (2.0 * f64::from(step));
        let an = f64::from(grad[[c, y, x]]);
        assert!(
            (fd - an).abs() <= 0.03 * f64::from(scale),
            "pixel ({c}, {y}, {x}): finite difference {fd}, analytic {an} (largest |gradient| {scale})"
        );
        checked += 1;
    }
    assert_eq!(checked, 12);
    // Not a gradient of zeros: the check above compares something.
    assert!(scale > 0.0);
}

/// The loss and the analytic gradient against PyTorch autograd through `training/`'s optics (its
/// `focal_stack` with the Fourier filter, from the SLM plane): the fixture `sdk/tests/fixtures/refine_gradient`
/// written by `training/make_refine_fixture.py` (random phase, a noisy focal stack of another pattern as the
/// target, 3 planes, 2 mm offset; `training/tests/test_refine_fixture.py` checks that it is autograd's today).
#[test]
fn the_loss_and_gradient_are_pytorch_autograds() {
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/refine_gradient");
    let read3 = |name: &str| -> Array3<f32> {
        ndarray_npy::read_npy(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("meta.json")).unwrap()).unwrap();
    let depths: Vec<f64> = meta["depths"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d.as_f64().unwrap())
        .collect();
    assert_eq!(depths, loss_depths(3).unwrap());
    assert_eq!(meta["offset_m"].as_f64(), Some(OFFSET_M));
    let stack: ndarray::Array4<f32> = ndarray_npy::read_npy(dir.join("target.npy")).unwrap();
    let target = FocalTarget::from_stack(
        depths.clone(),
        stack.outer_iter().map(|p| p.to_owned()).collect(),
    )
    .unwrap();
    let phase = read3("phase.npy");
    let want = read3("gradient.npy");
    let mut r = refiner(target, CONTINUOUS, 2);
    let (loss, grad) = r.loss_and_gradient(phase.view());
    let want_loss = meta["loss"].as_f64().unwrap();
    let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let err = grad
        .iter()
        .zip(&want)
        .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    println!(
        "loss {loss:.6e} (autograd {want_loss:.6e}); gradient max |Δ| {err:.2e} of max |∂L/∂φ| {scale:.2e}"
    );
    assert!(
        (loss - want_loss).abs() <= 1e-4 * want_loss,
        "{loss} vs {want_loss}"
    );
    assert!(scale > 0.0);
    assert!(err <= 1e-3 * scale, "{err} vs {scale}");
}

/// Adam lowers the loss at every iteration on a small scene, from a random and from a zero start, and the
/// history has the start and every iteration.
#[test]
fn the_loss_falls() {
    let (h, w) = (32, 32);
    let t = target(h, w, &loss_depths(5).unwrap());
    let options = RefineOptions {
        iterations: 20,
        planes: 5,
        step_rad: 0.1,
        ..Default::default()
    };
    let mut r = refiner(t, options, 2);
    for mut phase in [random_phase(h, w, 4), Array3::zeros((3, h, w))] {
        let report = r.refine(phase.view_mut(), &mut never_stop).unwrap();
        assert_eq!(report.history.len(), 21);
        let first = report.history[0].loss;
        let last = report.history[20].loss;
        assert!(last < 0.7 * first, "{first} → {last}");
        assert!(phase.iter().all(|p| (0.0..TAU).contains(p)));
    }
}

/// The same bits on 1 and 3 threads (every sum in a fixed order), and run after run.
#[test]
fn the_same_bits_whatever_the_threads() {
    let (h, w) = (20, 28);
    let depths = loss_depths(4).unwrap();
    let options = RefineOptions {
        iterations: 3,
        planes: 4,
        ..Default::default()
    };
    let start = random_phase(h, w, 6);
    let run = |threads| {
        let mut r = refiner(target(h, w, &depths), options, threads);
        let mut p = start.clone();
        let report = r.refine(p.view_mut(), &mut never_stop).unwrap();
        (p, report.history)
    };
    let (a, ha) = run(1);
    let (b, hb) = run(3);
    let (c, hc) = run(3);
    assert_eq!(a, b);
    assert_eq!(b, c);
    assert_eq!(ha, hb);
    assert_eq!(hb, hc);
    assert_ne!(a, start.mapv(|p| p.rem_euclid(TAU)));
}

#[test]
fn bad_settings_are_refused_naming_them() {
    let t = || target(8, 8, &loss_depths(2).unwrap());
    let bad = [
        (
            RefineOptions {
                iterations: 0,
                ..Default::default()
            },
            "iterations",
        ),
        (
            RefineOptions {
                iterations: MAX_ITERATIONS + 1,
                ..Default::default()
            },
            "iterations",
        ),
        (
            RefineOptions {
                step_rad: f32::NAN,
                ..Default::default()
            },
            "step_rad",
        ),
        (
            RefineOptions {
                step_rad: -0.1,
                ..Default::default()
            },
            "step_rad",
        ),
        (
            RefineOptions {
                step_rad: f32::INFINITY,
                ..Default::default()
            },
            "step_rad",
        ),
        (
            RefineOptions {
                beta2: 1.0,
                ..Default::default()
            },
            "beta2",
        ),
        (
            RefineOptions {
                planes: 0,
                ..Default::default()
            },
            "planes",
        ),
    ];
    for (options, name) in bad {
        let e = Refiner::new(&setup(), Default::default(), OFFSET_M, t(), options, 1).unwrap_err();
        assert!(
            matches!(&e, HoloError::InvalidParameter { name: n, .. } if *n == name),
            "{name}: {e}"
        );
    }
    let padded = PropagationOptions {
        pad: true,
        ..Default::default()
    };
    let e = Refiner::new(&setup(), padded, OFFSET_M, t(), Default::default(), 1).unwrap_err();
    assert!(e.to_string().contains("pad"), "{e}");
    let e = Refiner::new(
        &setup(),
        Default::default(),
        OFFSET_M,
        t(),
        Default::default(),
        0,
    )
    .unwrap_err();
    assert!(e.to_string().contains("threads"), "{e}");
}

/// A start of another size or holding NaN is refused, and a cancelled run leaves the pattern as it was.
#[test]
fn bad_starts_and_cancellation_leave_the_pattern_unchanged() {
    let mut r = refiner(
        target(8, 10, &loss_depths(2).unwrap()),
        RefineOptions::default(),
        1,
    );
    let mut wrong = Array3::<f32>::zeros((3, 8, 11));
    let e = r.refine(wrong.view_mut(), &mut never_stop).unwrap_err();
    assert!(
        matches!(e, HoloError::ShapeMismatch { .. }) && e.to_string().contains("target"),
        "{e}"
    );
    let mut nan = Array3::<f32>::zeros((3, 8, 10));
    nan[[2, 1, 1]] = f32::NAN;
    let e = r.refine(nan.view_mut(), &mut never_stop).unwrap_err();
    assert!(e.to_string().contains("NaN"), "{e}");
    let start = random_phase(8, 10, 8);
    let mut phase = start.clone();
    let mut seen = Vec::new();
    let e = r
        .refine(phase.view_mut(), &mut |rec| {
            seen.push(rec.iteration);
            if rec.iteration == 2 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        })
        .unwrap_err();
    assert!(matches!(e, HoloError::Cancelled(_)), "{e}");
    assert!(e.to_string().contains("after 2 of 10"), "{e}");
    assert_eq!(seen, vec![0, 1, 2]);
    assert_eq!(phase, start);
}

#[test]
fn starts_made_here() {
    let z = initial_phase(RefineStart::Zero, 2, 3).unwrap();
    assert!(z.iter().all(|&p| p == 0.0));
    let a = initial_phase(RefineStart::Random { seed: 1 }, 4, 5).unwrap();
    let b = initial_phase(RefineStart::Random { seed: 1 }, 4, 5).unwrap();
    let c = initial_phase(RefineStart::Random { seed: 2 }, 4, 5).unwrap();
    assert_eq!(a, b);
    assert_ne!(a, c);
    assert!(a.iter().all(|p| (0.0..TAU).contains(p)));
    let spread = a.iter().fold(0.0f32, |m, &p| m.max(p)) - a.iter().fold(TAU, |m, &p| m.min(p));
    assert!(spread > 4.0, "{spread}");
    assert!(initial_phase(RefineStart::Cnn, 2, 2).is_err());
    assert!(initial_phase(RefineStart::Zero, 0, 2).is_err());
}

/// The CNN's midpoint hologram is refused as the target for a viewer whose aberration the CNN corrects itself
/// (its midpoint is the corrected hologram), when the frame refiner is made, naming `target`; SM-LBM is taken,
/// and so is the CNN target where the kernel, not the CNN, corrects.
#[test]
fn the_cnn_target_is_refused_where_the_cnn_corrects_the_viewer() {
    use crate::optics::ZernikeCoefficients;
    use std::sync::Arc;

    let display = |by_cnn: bool| RefineDisplay {
        viewer: Some(Arc::new(AberrationProfile::uniform(ZernikeCoefficients {
            focus: 2.0,
            ..ZernikeCoefficients::ZERO
        }))),
        viewer_corrected_by_cnn: by_cnn,
        ..ideal_display()
    };
    let request = |target| FrameRefinement {
        target,
        ..FrameRefinement::default()
    };
    let e = FrameRefiner::new(request(RefineTarget::CnnMidpoint), display(true), 1).unwrap_err();
    assert!(
        matches!(&e, HoloError::InvalidParameter { name, .. } if *name == "target"),
        "{e:?}"
    );
    assert!(FrameRefiner::new(request(RefineTarget::default()), display(true), 1).is_ok());
    assert!(FrameRefiner::new(request(RefineTarget::CnnMidpoint), display(false), 1).is_ok());
}

/// `RefineStart::Previous` in a video: the first frame starts from the CNN's codes; a frame like the last one
/// starts from the last refined pattern (its loss is lower than the CNN's); a new view, which the CNN's codes
/// show exactly, starts from them, so a moving camera never starts worse than the CNN.
#[test]
fn the_previous_start_falls_back_to_the_cnn_where_the_view_changed() {
    let (h, w) = (16, 20);
    let display = ideal_display();
    let request = FrameRefinement {
        target: RefineTarget::CnnMidpoint,
        start: RefineStart::Previous,
        options: RefineOptions {
            iterations: 5,
            ..RefineOptions::default()
        },
    };
    let mut refiner = FrameRefiner::new(request, display.clone(), 1).unwrap();
    let scene = midpoint(h, w, 5);
    let codes = |seed| {
        let mut rng = SplitMix64::new(seed);
        Array3::from_shape_fn((3, h, w), |_| (rng.next_f64() * 256.0) as u8)
    };
    let cnn = codes(1);
    let mut run = |target: &Array3<Complex32>, cnn: &Array3<u8>| {
        refiner
            .refine(&[], Some(target.view()), cnn.view(), &mut |_| {
                ControlFlow::Continue(())
            })
            .unwrap()
    };
    let first = run(&scene, &cnn);
    assert_eq!(first.start, RefineStart::Cnn);
    let second = run(&scene, &cnn);
    assert_eq!(second.start, RefineStart::Previous);
    assert!(second.report.history[0].loss < first.report.history[0].loss);
    // A new view: the midpoint field that the new CNN codes show.
    let new_codes = codes(2);
    let shown = displayed_phase(new_codes.view(), None).unwrap();
    let view =
        crate::optics::simulate_phase_only(shown.view(), &setup(), OFFSET_M, Default::default())
            .unwrap();
    let third = run(&view, &new_codes);
    assert_eq!(third.start, RefineStart::Cnn);
    let held = &third.held_out;
    assert_eq!(Some(held.start_psnr_db), held.cnn_codes_psnr_db);
}

/// The other beam case: a display whose only flaw is its beam, calibrated the paper's way (a diffuser
/// capture of the beam → the laser intensity map, `slm::intensity`). The codes made with the map (the target
/// scaled by it, as the CNN's is) gain over the codes made without; refining them with the calibration must
/// keep that gain (the refinement aims at the same scaled target), never scoring below the unrefined codes as
/// the beam shows them, at the planes the loss never saw, against the unscaled scene.
#[test]
fn with_an_intensity_map_refinement_never_scores_below_the_unrefined_codes() {
    use crate::encoding::DoublePhaseMethod;
    use crate::reference::ReferencePipeline;
    use crate::slm::intensity::{intensity_scale_map, IntensityFloor};
    use crate::slm::model::DisplayModel;
    use crate::slm::model_captures::draw_display;
    use crate::slm::{codes::codes_of, DisplayCalibration};
    use crate::synthesis::{SceneLayer, SmLbm};
    use std::sync::Arc;

    let (h, w) = (64, 64);
    let frame = crate::scene::shared_tum_frame(h, w);
    let (setup, prop, offset) = (setup(), PropagationOptions::default(), 6e-3);
    // The beam: a Gaussian drawn from the simulated displays' ranges, the same for the three colours.
    let source = draw_display([h, w], 1, 21).colours[1].source;
    let mut beam = DisplayModel {
        slm_size: [h, w],
        ..Default::default()
    };
    for c in &mut beam.colours {
        c.source = source;
    }
    // Its diffuser capture (the beam's intensity, the peak at 0.8 of full scale) and the map made from it.
    let mut unit = vec![Complex32::new(0.0, 0.0); h * w];
    crate::slm::model::ColourRuntime::new(&beam.colours[1], h, w)
        .forward(&vec![0.0; h * w], &mut unit);
    let intensity =
        ndarray::Array2::from_shape_vec((h, w), unit.iter().map(|u| u.norm_sqr()).collect())
            .unwrap();
    let peak = intensity.iter().fold(0.0f32, |m, &v| m.max(v));
    let (map, _) = intensity_scale_map(
        intensity.mapv(|v| 0.8 * v / peak).view(),
        IntensityFloor::default(),
    )
    .unwrap();
    let mut calibration = DisplayCalibration::linear(h, w).unwrap();
    for c in &mut calibration.colours {
        c.intensity_scale = Some(map.clone());
    }
    // The codes made from the scene, and from the scene scaled by the map (what the pipeline does with it).
    let smlbm = |amplitude: &Array3<f32>| {
        ReferencePipeline {
            synthesis: SmLbm {
                levels: 64,
                setup,
                options: prop,
                silhouette_masks: true,
            },
            offset_m: offset,
            encoding: DoublePhaseMethod::default(),
        }
        .run(
            &[SceneLayer {
                amplitude: amplitude.view(),
                depth: frame.depth.view(),
                valid: None,
            }],
            &|_, _| {},
        )
        .unwrap()
    };
    let plain = smlbm(&frame.amplitude);
    let mut scaled_amplitude = frame.amplitude.clone();
    for mut plane in scaled_amplitude.outer_iter_mut() {
        plane *= &map;
    }
    let scaled = smlbm(&scaled_amplitude);
    let codes = |phase: &Array3<f32>| codes_of(phase.view(), None).unwrap();
    // Scored as the beam shows them at the held-out planes, against the unscaled scene's focal stack.
    let score = |codes: &Array3<u8>| {
        let shown = displayed_phase(codes.view(), None).unwrap();
        held_out_psnr(
            (&setup, prop, offset),
            plain.midpoint.view(),
            7,
            &beam,
            shown.view(),
        )
    };
    let without_map = score(&codes(&plain.double_phase.phase));
    let with_map_codes = codes(&scaled.double_phase.phase);
    let with_map = score(&with_map_codes);
    let display = RefineDisplay {
        optics: setup,
        propagation: prop,
        offset_m: offset,
        encoding: DoublePhaseMethod::default(),
        calibration: Some(Arc::new(calibration)),
        viewer: None,
        viewer_corrected_by_cnn: false,
    };
    let request = FrameRefinement {
        options: RefineOptions::default(),
        target: RefineTarget::SmLbm { levels: 64 },
        start: RefineStart::Cnn,
    };
    let refined = FrameRefiner::new(request, display, 2)
        .unwrap()
        .refine(
            &[SceneLayer::from(&frame)],
            None,
            with_map_codes.view(),
            &mut never_stop,
        )
        .unwrap();
    let refined = score(&refined.codes);
    eprintln!(
        "through the beam: the codes without the map {without_map:.2} dB, with it {with_map:.2} dB, refined with \
         it {refined:.2} dB"
    );
    assert!(
        with_map > without_map + 0.5,
        "{with_map:.2} vs {without_map:.2}"
    );
    assert!(refined >= with_map, "{refined:.2} < {with_map:.2}");
}

/// `FrameRefiner::with_scoring_model`: the refinement is the same (the loss sees its own display), and the
/// held-out scores are what the scoring model's display shows of each pattern, as a refiner through that
/// model scores them directly; they differ from the ideal display's.
#[test]
fn held_out_scores_through_a_scoring_model_are_what_that_display_shows() {
    use crate::slm::codes::codes_of;
    use crate::slm::model::DisplayModel;
    use crate::slm::model_captures::draw_display;
    use std::sync::Arc;

    let (h, w) = (24, 32);
    let mid = midpoint(h, w, 5);
    let start = random_phase(h, w, 3);
    let mut hidden = DisplayModel {
        slm_size: [h, w],
        ..Default::default()
    };
    for c in 0..3 {
        hidden.colours[c] = draw_display([h, w], c, 40 + c as u64).colours[c].clone();
    }
    let options = RefineOptions {
        iterations: 3,
        ..RefineOptions::default()
    };
    let display = ideal_display();
    let request = FrameRefinement {
        options,
        ..FrameRefinement::default()
    };
    let run = |scoring: Option<Arc<DisplayModel>>| {
        FrameRefiner::new(request, display.clone(), 2)
            .unwrap()
            .with_scoring_model(scoring)
            .unwrap()
            .refine_against(mid.view(), start.view(), None, &mut never_stop)
            .unwrap()
    };
    let (own, scored) = (run(None), run(Some(Arc::new(hidden.clone()))));
    assert_eq!(own.codes, scored.codes);
    let score = |p: &Array3<f32>| {
        held_out_psnr(
            (&setup(), Default::default(), OFFSET_M),
            mid.view(),
            options.planes,
            &hidden,
            p.view(),
        )
    };
    let shown = displayed_phase(codes_of(scored.phase.view(), None).unwrap().view(), None).unwrap();
    let s = &scored.held_out;
    assert_eq!(s.start_psnr_db, score(&start));
    assert_eq!(s.refined_psnr_db, score(&scored.phase));
    assert_eq!(s.refined_codes_psnr_db, score(&shown));
    assert!(
        (s.refined_codes_psnr_db - own.held_out.refined_codes_psnr_db).abs() > 0.1,
        "{s:?} vs {:?}",
        own.held_out
    );
    // A scoring model of another SLM size: refused at the frame.
    let e = FrameRefiner::new(request, display, 2)
        .unwrap()
        .with_scoring_model(Some(Arc::new(DisplayModel {
            slm_size: [h, w + 8],
            ..hidden
        })))
        .unwrap()
        .refine_against(mid.view(), start.view(), None, &mut never_stop)
        .unwrap_err();
    assert!(matches!(e, HoloError::ShapeMismatch { .. }), "{e}");
}

/// A display model with an aberration and a viewer's aberration at once: refused, naming `display_model`,
/// whether the loss sees the model or the held-out planes are scored through it; a model without one is
/// taken beside the viewer.
#[test]
fn a_model_aberration_beside_a_viewers_is_refused() {
    use crate::optics::ZernikeCoefficients;
    use crate::slm::model::DisplayModel;
    use std::sync::Arc;

    let (h, w) = (8, 8);
    let viewer = Arc::new(AberrationProfile::uniform(ZernikeCoefficients {
        focus: 1.0,
        ..ZernikeCoefficients::ZERO
    }));
    let mut model = DisplayModel {
        slm_size: [h, w],
        ..Default::default()
    };
    model.colours[1].zero_order = Some([0.05, 0.0]);
    let display = RefineDisplay {
        viewer: Some(viewer.clone()),
        ..ideal_display()
    };
    let frame = || FrameRefiner::new(FrameRefinement::default(), display.clone(), 1).unwrap();
    assert!(frame()
        .with_display_model(Some(Arc::new(model.clone())))
        .is_ok());
    model.colours[1].aberration = Some(ZernikeCoefficients {
        focus: 0.3,
        ..ZernikeCoefficients::ZERO
    });
    let named = |e: HoloError| {
        matches!(
            e,
            HoloError::InvalidParameter {
                name: "display_model",
                ..
            }
        )
    };
    let m = Arc::new(model.clone());
    assert!(named(
        frame().with_display_model(Some(m.clone())).unwrap_err()
    ));
    assert!(named(frame().with_scoring_model(Some(m)).unwrap_err()));
    let e = refiner(target(h, w, &[0.5]), CONTINUOUS, 1)
        .with_viewer(Some(&viewer))
        .unwrap()
        .with_display_model(Some(&model))
        .unwrap_err();
    assert!(named(e));
}
