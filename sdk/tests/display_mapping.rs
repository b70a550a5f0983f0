//! Fresnel-equivalent displays (`docs/DISPLAYS.md`): the shipped 8 µm models serve a 4 µm or 3.74 µm SLM at
//! the paper's lasers with the volume and offset scaled by `σ = (p'/p)²`, and give the same SLM codes.
#![cfg(feature = "embedded-models")]

use tensorholo::model::MAX_NONPARAXIAL_RESIDUAL_RAD;
use tensorholo::optics::OpticalSetup;
use tensorholo::pipeline::{Backend, HologramPipeline, ModelSelection, PipelineConfig};
use tensorholo::scene::procedural::default_scene;
use tensorholo::HoloError;

const PAPER: [f64; 3] = [638e-9, 520e-9, 450e-9];
const SIZE: (usize, usize) = (64, 96);

fn config(pitch: f64, volume: f64, offset: f64) -> PipelineConfig {
    PipelineConfig {
        optics: OpticalSetup {
            wavelengths_m: PAPER,
            pixel_pitch_m: pitch,
            volume_depth_m: volume,
        },
        offset_m: offset,
        backend: Backend::Cpu,
        ..PipelineConfig::default()
    }
}

fn codes(pipeline: &HologramPipeline) -> ndarray::Array3<u8> {
    let frame = default_scene(SIZE.0, SIZE.1).unwrap();
    let mut session = pipeline.session(SIZE.0, SIZE.1).unwrap();
    session.render(&frame).unwrap().codes.clone()
}

/// Share of codes within one step (circularly: 255 and 0 are one step apart).
fn within_one_step(a: &ndarray::Array3<u8>, b: &ndarray::Array3<u8>) -> f64 {
    let near = a
        .iter()
        .zip(b)
        .filter(|(&x, &y)| {
            let d = u16::from(x.abs_diff(y));
            d.min(256 - d) <= 1
        })
        .count();
    near as f64 / a.len() as f64
}

#[test]
fn equivalent_displays_give_the_paper_display_codes() {
    let sel = ModelSelection::default();
    let paper = HologramPipeline::embedded(&sel, config(8e-6, 6e-3, 6e-3)).unwrap();
    assert!(
        paper.prefilter_model().is_some(),
        "{}",
        paper.prefilter_reason()
    );
    assert_eq!(paper.display_mapping().scale, 1.0);
    let reference = codes(&paper);
    for pitch in [4e-6, 3.74e-6] {
        let s = (pitch / 8e-6f64).powi(2);
        let p = HologramPipeline::embedded(&sel, config(pitch, 6e-3 * s, 6e-3 * s)).unwrap();
        // The 6 mm pre-filter is paired by the mapped offset.
        assert!(p.prefilter_model().is_some(), "{}", p.prefilter_reason());
        assert!(
            p.prefilter_reason().contains("6 mm pre-filter"),
            "{}",
            p.prefilter_reason()
        );
        let m = p.display_mapping();
        assert!((m.scale - s).abs() < 1e-12);
        assert!(m.residual_rad < MAX_NONPARAXIAL_RESIDUAL_RAD);
        let share = within_one_step(&reference, &codes(&p));
        println!(
            "{} µm: {:.2} % of codes within one step of the 8 µm run; {}",
            pitch * 1e6,
            share * 100.0,
            p.display_mapping_description()
        );
        assert!(share >= 0.99, "{pitch}: {share}");
    }
}

#[test]
fn a_display_outside_the_tolerance_is_refused_naming_the_colour() {
    let sel = ModelSelection::default();
    let mut cfg = config(4e-6, 1.5e-3, 1.5e-3);
    cfg.optics.wavelengths_m[1] = 532e-9;
    let e = HologramPipeline::embedded(&sel, cfg).unwrap_err();
    assert!(
        matches!(&e, HoloError::ModelMetadata { key, .. } if key == "tensorholo.wavelengths_m"),
        "{e}"
    );
    assert!(e.to_string().contains("green"), "{e}");
    // Widened, with the volume and offset of the common scale, it is served and reported as widened.
    cfg.wavelength_ratio_tolerance = 0.02;
    let m = tensorholo::model::DisplayMapping::compute(
        &OpticalSetup::default(),
        &cfg.optics,
        0.0,
        cfg.wavelength_ratio_tolerance,
    )
    .unwrap();
    cfg.optics.volume_depth_m = m.served_volume_depth_m();
    cfg.offset_m = 6e-3 * m.scale;
    let p = HologramPipeline::embedded(&sel, cfg).unwrap();
    assert!(p.display_mapping().widened);
    assert!(p.display_mapping_description().contains("widened"));
    println!("{}", p.display_mapping_description());
}
