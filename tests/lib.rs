//! Helpers of the workspace-level integration tests: where the shared third-party data lives, and an image
//! sharpness measure.

use std::path::PathBuf;

use ndarray::{Array2, Array3, Axis};

/// Path of a file under `../shared/data` (beside the repository), failing with a clear message if absent.
pub fn shared_data(relative: &str) -> PathBuf {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data")
        .join(relative);
    assert!(
        path.exists(),
        "shared test data {} is missing: the tests expect ../shared/data beside the repository",
        path.display()
    );
    path
}

/// Mean squared difference of the forward-difference gradients of `img` and `reference` (`[3, H, W]`) over
/// `region`: small where `img` reproduces the reference's detail (in focus), large where it is blurred or
/// shows artifacts.
pub fn detail_error(img: &Array3<f32>, reference: &Array3<f32>, region: &Array2<bool>) -> f64 {
    let (_, h, w) = img.dim();
    let (mut acc, mut n) = (0.0f64, 0usize);
    for (a, b) in img.axis_iter(Axis(0)).zip(reference.axis_iter(Axis(0))) {
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                if region[[y, x]] && region[[y + 1, x]] && region[[y, x + 1]] {
                    let gx = (a[[y, x + 1]] - a[[y, x]] - b[[y, x + 1]] + b[[y, x]]) as f64;
                    let gy = (a[[y + 1, x]] - a[[y, x]] - b[[y + 1, x]] + b[[y, x]]) as f64;
                    acc += gx * gx + gy * gy;
                    n += 1;
                }
            }
        }
    }
    acc / n.max(1) as f64
}

/// What the SLM displays for one session frame, focused at each normalised depth: the phase-only simulation of
/// `out`'s double phase pattern brought back to the midpoint plane (Eq. 8–10), then its focal stack.
///
/// Panics on an invalid configuration (tests only).
pub fn displayed_focal_stack(
    out: &tensorholo::pipeline::SlmFrame,
    config: &tensorholo::pipeline::PipelineConfig,
    depths: &[f64],
) -> Vec<ndarray::Array3<f32>> {
    let shown = tensorholo::optics::post_encoding_midpoint(
        out.phase.view(),
        out.amplitude_scale,
        &config.optics,
        config.offset_m,
        config.options,
    )
    .expect("simulation");
    tensorholo::optics::focal_stack(
        shown.view(),
        &config.optics,
        0.0,
        depths,
        config.options,
        false,
    )
    .expect("focal stack")
}
