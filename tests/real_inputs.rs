//! End-to-end: `ReferencePipeline` (SM-LBM → double phase → simulated reconstruction) on real RGB-D photos.
//! A near-focused reconstruction must be sharper on the near object than a far-focused one, and the reverse on
//! the background, where "sharper" means a smaller gradient-domain error against the input
//! ([`detail_error`]).

use std::path::Path;

use ndarray::{Array2, Array3};
use tensorholo::reference::ReferencePipeline;
use tensorholo::scene::{load_rgbd, DepthEncoding, LoadOptions};
use tensorholo::synthesis::{SceneLayer, SmLbm};
use tensorholo_integration_tests::{detail_error, shared_data};

fn check_near_far_focus(rgb: &Path, depth: &Path, encoding: DepthEncoding, size: (usize, usize)) {
    let options = LoadOptions {
        size: Some(size),
        ..LoadOptions::default()
    };
    let (frame, _) = load_rgbd(rgb, depth, encoding, &options).expect("loads");
    let mut sorted: Vec<f32> = frame.depth.iter().copied().collect();
    sorted.sort_by(f32::total_cmp);
    let q = |p: f64| sorted[((sorted.len() - 1) as f64 * p) as usize];
    let (near_d, far_d) = (q(0.1), q(0.9));
    let (near_cut, far_cut) = (q(0.3), q(0.7));
    assert!(
        far_d - near_d > 0.2,
        "scene must span the volume: {near_d}..{far_d}"
    );
    let near_region: Array2<bool> = frame.depth.mapv(|d| d <= near_cut);
    let far_region: Array2<bool> = frame.depth.mapv(|d| d >= far_cut);
    let pipeline = ReferencePipeline {
        synthesis: SmLbm {
            levels: 256,
            ..SmLbm::default()
        },
        ..ReferencePipeline::default()
    };
    let layer = SceneLayer {
        amplitude: frame.amplitude.view(),
        depth: frame.depth.view(),
        valid: None,
    };
    let hologram = pipeline.run(&[layer], &|_, _| {}).expect("synthesis");
    let recon = pipeline
        .reconstruct_phase_only(&hologram, &[near_d as f64, far_d as f64])
        .expect("reconstruction");
    // "Sharper" = reproduces the scene's own detail there: the gradient-domain error against the input
    // amplitude. (Raw gradient energy is not usable: defocused smooth-phase content rings rather than blurs.)
    let err = |a: &Array3<f32>, r: &Array2<bool>| detail_error(a, &frame.amplitude, r);
    let near_obj = (err(&recon[0], &near_region), err(&recon[1], &near_region));
    let background = (err(&recon[0], &far_region), err(&recon[1], &far_region));
    println!(
        "{}: detail error (near focus / far focus): near object {:.3e} / {:.3e}, background {:.3e} / {:.3e}",
        rgb.display(),
        near_obj.0,
        near_obj.1,
        background.0,
        background.1
    );
    assert!(near_obj.1 > 1.25 * near_obj.0, "near object: {near_obj:?}");
    assert!(
        background.0 > 1.05 * background.1,
        "background: {background:?}"
    );
}

#[test]
fn iphone_portrait_near_focus_sharpens_the_vase_far_focus_the_background() {
    check_near_far_focus(
        &shared_data("iphone_portrait_vase/derived_rgb_576x768.png"),
        &shared_data("iphone_portrait_vase/disparity_aux_576x768.jpg"),
        DepthEncoding::IphoneDisparity,
        (256, 192),
    );
}

#[test]
fn redwood_frame_near_focus_sharpens_the_foreground_far_focus_the_background() {
    check_near_far_focus(
        &shared_data("redwood_livingroom_seq/color/00000.jpg"),
        &shared_data("redwood_livingroom_seq/depth/00000.png"),
        DepthEncoding::Millimetres16,
        (240, 320),
    );
}
