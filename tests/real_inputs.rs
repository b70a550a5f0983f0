//! End-to-end on real RGB-D photos: `ReferencePipeline` (SM-LBM → double phase → simulated reconstruction)
//! and the real-time `HologramSession` with the shipped CNNs (hologram CNN → offset → pre-filter CNN → double
//! phase → simulated reconstruction).
//! A near-focused reconstruction must be sharper on the near object than a far-focused one, and the reverse on
//! the background, where "sharper" means a smaller gradient-domain error against the input
//! ([`detail_error`]).

use std::path::Path;

use ndarray::{Array2, Array3};
use tensorholo::optics::{focal_stack, post_encoding_midpoint};
use tensorholo::pipeline::{HologramPipeline, ModelSelection, PipelineConfig, PrefilterMode};
use tensorholo::reference::ReferencePipeline;
use tensorholo::scene::{load_rgbd, DepthEncoding, LoadOptions, RgbdFrame};
use tensorholo::synthesis::{SceneLayer, SmLbm};
use tensorholo_integration_tests::{detail_error, shared_data};

/// Phase-only reconstructions of a frame at normalised depths `[near, far]`.
type Reconstruct = fn(&RgbdFrame, &[f64]) -> Vec<Array3<f32>>;

fn reference(frame: &RgbdFrame, depths: &[f64]) -> Vec<Array3<f32>> {
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
    pipeline
        .reconstruct_phase_only(&hologram, depths)
        .expect("reconstruction")
}

/// The shipped 8-layer CNN with the 6 mm pre-filter (DDPM), what `holo render` runs by default.
fn shipped_cnn(frame: &RgbdFrame, depths: &[f64]) -> Vec<Array3<f32>> {
    let config = PipelineConfig {
        offset_m: 6e-3,
        ..PipelineConfig::default()
    };
    let selection = ModelSelection {
        prefilter: PrefilterMode::Required,
        ..ModelSelection::default()
    };
    let pipeline = HologramPipeline::embedded(&selection, config).expect("models");
    let mut session = pipeline
        .session(frame.height(), frame.width())
        .expect("session");
    let out = session.render(frame).expect("frame");
    let shown = post_encoding_midpoint(
        out.phase.view(),
        out.amplitude_scale,
        &config.optics,
        config.offset_m,
        config.options,
    )
    .expect("simulation");
    focal_stack(
        shown.view(),
        &config.optics,
        0.0,
        depths,
        config.options,
        false,
    )
    .expect("stack")
}

fn check_near_far_focus(
    rgb: &Path,
    depth: &Path,
    encoding: DepthEncoding,
    size: (usize, usize),
    reconstruct: Reconstruct,
) {
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
    let recon = reconstruct(&frame, &[near_d as f64, far_d as f64]);
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
        reference,
    );
}

#[test]
fn redwood_frame_near_focus_sharpens_the_foreground_far_focus_the_background() {
    check_near_far_focus(
        &shared_data("redwood_livingroom_seq/color/00000.jpg"),
        &shared_data("redwood_livingroom_seq/depth/00000.png"),
        DepthEncoding::Millimetres16,
        (240, 320),
        reference,
    );
}

#[test]
fn shipped_cnn_near_focus_sharpens_the_vase_far_focus_the_background() {
    check_near_far_focus(
        &shared_data("iphone_portrait_vase/derived_rgb_576x768.png"),
        &shared_data("iphone_portrait_vase/disparity_aux_576x768.jpg"),
        DepthEncoding::IphoneDisparity,
        (256, 192),
        shipped_cnn,
    );
}

#[test]
fn shipped_cnn_near_focus_sharpens_the_redwood_foreground_far_focus_the_background() {
    check_near_far_focus(
        &shared_data("redwood_livingroom_seq/color/00000.jpg"),
        &shared_data("redwood_livingroom_seq/depth/00000.png"),
        DepthEncoding::Millimetres16,
        (240, 320),
        shipped_cnn,
    );
}
