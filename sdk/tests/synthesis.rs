//! Physics tests of the silhouette-mask layer-based method (paper Eq. 1–4, Fig. 9).

mod common;

use common::{gradient_energy, rel_error, Rng};
use ndarray::{s, Array2, Array3, Axis};
use num_complex::Complex32;
use tensorholo::optics::{focal_stack, Carrier, OpticalSetup, PropagationOptions, Propagator};
use tensorholo::synthesis::{SceneLayer, SmLbm};
use tensorholo::HoloError;

fn no_progress(_: u64, _: u64) {}

fn config(levels: usize) -> SmLbm {
    SmLbm {
        levels,
        ..SmLbm::default()
    }
}

#[test]
fn a_point_source_refocuses_to_a_spot_at_its_depth() {
    let (h, w) = (64, 64);
    let d_point = 0.2;
    let amplitude = Array3::from_elem((3, h, w), 1.0f32);
    let depth = Array2::from_elem((h, w), d_point as f32);
    let mut valid = Array2::from_elem((h, w), false);
    valid[[30, 40]] = true;
    let layer = SceneLayer {
        amplitude: amplitude.view(),
        depth: depth.view(),
        valid: Some(valid.view()),
    };
    let holo = config(251).synthesize(&[layer], &no_progress).unwrap();
    // The midpoint hologram of an out-of-plane point is spread out (a sub-hologram), not a spot.
    let spot_fraction = |a: &Array3<f32>, c: usize| -> f64 {
        let ch = a.index_axis(Axis(0), c);
        let total: f64 = ch.iter().map(|v| (v * v) as f64).sum();
        let spot: f64 = ch
            .slice(s![29..32, 39..42])
            .iter()
            .map(|v| (v * v) as f64)
            .sum();
        spot / total
    };
    let mid = holo.mapv(|v| v.norm());
    let depths = [0.0, d_point, 0.5, 0.8];
    let stack = focal_stack(
        holo.view(),
        &OpticalSetup::default(),
        0.0,
        &depths,
        Default::default(),
        false,
    )
    .unwrap();
    for c in 0..3 {
        assert!(
            spot_fraction(&mid, c) < 0.2,
            "midpoint plane must not be in focus"
        );
        let focused = spot_fraction(&stack[1], c);
        assert!(
            focused > 0.95,
            "colour {c}: energy in 3×3 spot at focus {focused}"
        );
        for k in [0, 2, 3] {
            let f = spot_fraction(&stack[k], c);
            assert!(
                f < 0.5 * focused,
                "colour {c}: depth {} has spot fraction {f}",
                depths[k]
            );
        }
        // The peak is at the point's pixel.
        let ch = stack[1].index_axis(Axis(0), c);
        let (mut best, mut at) = (0.0, (0, 0));
        for ((y, x), &v) in ch.indexed_iter() {
            if v > best {
                best = v;
                at = (y, x);
            }
        }
        assert_eq!(at, (30, 40));
    }
}

/// A planar textured scene (random speckle-free texture) at normalised depth `d`.
fn textured_plane(h: usize, w: usize, d: f32, seed: u64) -> (Array3<f32>, Array2<f32>) {
    let mut rng = Rng::new(seed);
    let cells: Vec<f32> = (0..(h / 4) * (w / 4)).map(|_| rng.next()).collect();
    let amp = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
        0.2 + 0.8 * cells[(y / 4) * (w / 4) + x / 4] * (0.7 + 0.1 * c as f32)
    });
    (amp, Array2::from_elem((h, w), d))
}

#[test]
fn a_textured_plane_is_sharpest_when_reconstructed_at_its_depth() {
    let (h, w) = (96, 96);
    for d in [0.15f32, 0.7] {
        let (amp, depth) = textured_plane(h, w, d, 4);
        let layer = SceneLayer {
            amplitude: amp.view(),
            depth: depth.view(),
            valid: None,
        };
        let holo = config(1024).synthesize(&[layer], &no_progress).unwrap();
        let depths: Vec<f64> = (0..=20).map(|k| k as f64 / 20.0).collect();
        let stack = focal_stack(
            holo.view(),
            &OpticalSetup::default(),
            0.0,
            &depths,
            Default::default(),
            false,
        )
        .unwrap();
        let sharpness: Vec<f64> = stack
            .iter()
            .map(|a| {
                (0..3)
                    .map(|c| gradient_energy(a.index_axis(Axis(0), c), None))
                    .sum()
            })
            .collect();
        let best = (0..depths.len())
            .max_by(|&i, &j| sharpness[i].total_cmp(&sharpness[j]))
            .unwrap();
        assert!(
            (depths[best] - d as f64).abs() < 0.051,
            "plane at {d}: sharpest at {}",
            depths[best]
        );
        // And the in-focus reconstruction reproduces the texture.
        let k = (d as f64 * 20.0).round() as usize;
        let err: f32 = (&stack[k] - &amp).mapv(|v| v * v).mean().unwrap().sqrt();
        assert!(err < 0.03, "in-focus RMS amplitude error {err}");
    }
}

#[test]
fn a_uniform_plane_gives_a_flat_zero_phase_midpoint_hologram() {
    // Maimone et al.'s initial phase (Eq. 1) cancels the propagation carrier: smooth, zero-mean phase.
    let (h, w) = (16, 16);
    let amp = Array3::from_elem((3, h, w), 0.6f32);
    let depth = Array2::from_elem((h, w), 0.9f32);
    let layer = SceneLayer {
        amplitude: amp.view(),
        depth: depth.view(),
        valid: None,
    };
    let holo = config(100).synthesize(&[layer], &no_progress).unwrap();
    for v in holo.iter() {
        assert!((v - Complex32::new(0.6, 0.0)).norm() < 1e-3, "{v}");
    }
}

/// The two-bar occlusion scene of paper Fig. 9 as a 2-layer LDI: a near bar hides the right half of a far bar.
struct BarScene {
    front_amp: Array3<f32>,
    front_depth: Array2<f32>,
    front_valid: Array2<bool>,
    rear_amp: Array3<f32>,
    rear_depth: Array2<f32>,
    rear_valid: Array2<bool>,
    front_region: Array2<bool>,
}

fn bar_scene() -> BarScene {
    let (h, w) = (96, 96);
    let (d_front, d_rear) = (0.1f32, 0.9f32);
    let front_region = Array2::from_shape_fn((h, w), |(y, x)| {
        (40..56).contains(&y) && (44..80).contains(&x)
    });
    let rear_bar = Array2::from_shape_fn((h, w), |(y, x)| {
        (36..60).contains(&y) && (16..76).contains(&x)
    });
    let mut front_amp = Array3::zeros((3, h, w));
    let mut front_depth = Array2::from_elem((h, w), d_rear);
    let mut front_valid = Array2::from_elem((h, w), false);
    let mut rear_amp = Array3::zeros((3, h, w));
    let rear_depth = Array2::from_elem((h, w), d_rear);
    let mut rear_valid = Array2::from_elem((h, w), false);
    for y in 0..h {
        for x in 0..w {
            if front_region[[y, x]] {
                front_valid[[y, x]] = true;
                front_depth[[y, x]] = d_front;
                for c in 0..3 {
                    front_amp[[c, y, x]] = 0.5;
                }
                if rear_bar[[y, x]] {
                    // Hidden part of the rear bar goes to the second LDI layer.
                    rear_valid[[y, x]] = true;
                    for c in 0..3 {
                        rear_amp[[c, y, x]] = 1.0;
                    }
                }
            } else if rear_bar[[y, x]] {
                front_valid[[y, x]] = true;
                for c in 0..3 {
                    front_amp[[c, y, x]] = 1.0;
                }
            }
        }
    }
    BarScene {
        front_amp,
        front_depth,
        front_valid,
        rear_amp,
        rear_depth,
        rear_valid,
        front_region,
    }
}

#[test]
fn fig9_occluded_half_of_the_rear_bar_does_not_leak_into_the_front_focus() {
    let scene = bar_scene();
    let front = SceneLayer {
        amplitude: scene.front_amp.view(),
        depth: scene.front_depth.view(),
        valid: Some(scene.front_valid.view()),
    };
    let rear = SceneLayer {
        amplitude: scene.rear_amp.view(),
        depth: scene.rear_depth.view(),
        valid: Some(scene.rear_valid.view()),
    };
    let setup = OpticalSetup::default();
    let front_focus = |layers: &[SceneLayer], masks: bool| -> Array3<f32> {
        let cfg = SmLbm {
            silhouette_masks: masks,
            ..config(251)
        };
        let holo = cfg.synthesize(layers, &no_progress).unwrap();
        focal_stack(holo.view(), &setup, 0.0, &[0.1], Default::default(), false)
            .unwrap()
            .remove(0)
    };
    let inside = |a: &Array3<f32>| -> Vec<f32> {
        let mut v = Vec::new();
        for c in 0..3 {
            for ((y, x), &m) in scene.front_region.indexed_iter() {
                if m {
                    v.push(a[[c, y, x]]);
                }
            }
        }
        v
    };
    // With silhouette masks, the front bar at front focus is exactly its own amplitude: the hidden half of the
    // rear bar (2nd LDI layer) leaves no trace on it (no type-1/type-2 leakage, Fig. 9).
    let ldi = front_focus(&[front, rear], true);
    let max_dev = inside(&ldi)
        .iter()
        .map(|v| (v - 0.5).abs())
        .fold(0.0f32, f32::max);
    assert!(
        max_dev < 1e-3,
        "front bar deviates by {max_dev} from its amplitude 0.5"
    );
    // Without masks the rear bar's wavefront leaks through the front bar.
    let leaky = front_focus(&[front, rear], false);
    let leak = inside(&leaky)
        .iter()
        .map(|v| (v - 0.5).abs())
        .fold(0.0f32, f32::max);
    assert!(
        leak > 0.1,
        "without silhouette masks the leak is only {leak}"
    );
    // The hidden half still contributes to the rear focus: the LDI differs there from the RGB-D (layer 1) scene.
    let holo_ldi = config(251)
        .synthesize(&[front, rear], &no_progress)
        .unwrap();
    let holo_rgbd = config(251).synthesize(&[front], &no_progress).unwrap();
    let rear_ldi = focal_stack(
        holo_ldi.view(),
        &setup,
        0.0,
        &[0.9],
        Default::default(),
        false,
    )
    .unwrap();
    let rear_rgbd = focal_stack(
        holo_rgbd.view(),
        &setup,
        0.0,
        &[0.9],
        Default::default(),
        false,
    )
    .unwrap();
    // Next to the front bar's left edge, on the visible rear bar, RGB-D loses amplitude (type-3 artifact).
    let region = s![.., 40..56, 40..48];
    let mean = |a: &Array3<f32>| a.slice(region).mean().unwrap();
    assert!(
        mean(&rear_ldi[0]) > mean(&rear_rgbd[0]) + 0.02,
        "LDI {} vs RGB-D {}",
        mean(&rear_ldi[0]),
        mean(&rear_rgbd[0])
    );
}

#[test]
fn without_masks_the_hologram_is_the_superposition_of_each_plane_propagated() {
    // Checks plane merging, distances and the initial phase against a direct computation.
    let (h, w) = (32, 40);
    let setup = OpticalSetup::default();
    let mut rng = Rng::new(21);
    let amp = Array3::from_shape_fn((3, h, w), |_| rng.next());
    let levels = 11;
    let depth = Array2::from_shape_fn((h, w), |(y, _)| {
        if y < 10 {
            0.2
        } else if y < 20 {
            0.6
        } else {
            1.0
        }
    });
    let layer = SceneLayer {
        amplitude: amp.view(),
        depth: depth.view(),
        valid: None,
    };
    let cfg = SmLbm {
        silhouette_masks: false,
        ..config(levels)
    };
    let holo = cfg.synthesize(&[layer], &no_progress).unwrap();
    for c in 0..3 {
        let lambda = setup.wavelengths_m[c];
        let prop = Propagator::new(
            h,
            w,
            setup.pixel_pitch_m,
            lambda,
            PropagationOptions::default(),
        )
        .unwrap();
        let mut total = vec![Complex32::default(); h * w];
        for d in [0.2f64, 0.6, 1.0] {
            let z = setup.depth_to_z(d);
            let phase = 2.0 * std::f64::consts::PI * (z / lambda).fract();
            let mut plane: Vec<Complex32> = (0..h * w)
                .map(|i| {
                    if (depth[[i / w, i % w]] as f64 - d).abs() < 1e-6 {
                        Complex32::from_polar(amp[[c, i / w, i % w]], phase as f32)
                    } else {
                        Complex32::default()
                    }
                })
                .collect();
            prop.propagate_by(&mut plane, -z, Carrier::Keep).unwrap();
            for (t, p) in total.iter_mut().zip(&plane) {
                *t += p;
            }
        }
        let got = holo.index_axis(Axis(0), c).to_owned();
        let err = rel_error(got.as_slice().unwrap(), &total);
        assert!(err < 1e-3, "colour {c}: relative error {err}");
    }
}

#[test]
fn bad_scenes_are_clear_errors() {
    let amp = Array3::from_elem((3, 8, 8), 0.5f32);
    let depth = Array2::from_elem((8, 8), 0.5f32);
    let ok = SceneLayer {
        amplitude: amp.view(),
        depth: depth.view(),
        valid: None,
    };
    let err = SmLbm {
        levels: 0,
        ..SmLbm::default()
    }
    .synthesize(&[ok], &no_progress)
    .unwrap_err();
    assert!(
        matches!(err, HoloError::InvalidParameter { name: "levels", .. }),
        "{err}"
    );
    let mut nan_depth = depth.clone();
    nan_depth[[2, 3]] = f32::NAN;
    let bad = SceneLayer {
        depth: nan_depth.view(),
        ..ok
    };
    let err = config(16).synthesize(&[bad], &no_progress).unwrap_err();
    assert!(
        matches!(err, HoloError::InvalidDepth(_)) && err.to_string().contains("row 2, column 3"),
        "{err}"
    );
    let small = Array2::from_elem((8, 7), 0.5f32);
    let err = config(16)
        .synthesize(
            &[SceneLayer {
                depth: small.view(),
                ..ok
            }],
            &no_progress,
        )
        .unwrap_err();
    assert!(matches!(err, HoloError::ShapeMismatch { .. }), "{err}");
    let none = Array2::from_elem((8, 8), false);
    let err = config(16)
        .synthesize(
            &[SceneLayer {
                valid: Some(none.view()),
                ..ok
            }],
            &no_progress,
        )
        .unwrap_err();
    assert!(err.to_string().contains("no valid point"), "{err}");
    let mut neg = amp.clone();
    neg[[1, 0, 0]] = -0.1;
    let err = config(16)
        .synthesize(
            &[SceneLayer {
                amplitude: neg.view(),
                ..ok
            }],
            &no_progress,
        )
        .unwrap_err();
    assert!(matches!(err, HoloError::InvalidData(_)), "{err}");
    assert!(config(16).synthesize(&[], &no_progress).is_err());
}
