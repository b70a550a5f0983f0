//! What a display shows of a `holo render` output's SLM codes, through a display model (docs/REFINE.md
//! "Through a display model"; the figure there): the codes (`phase_{r,g,b}.png`) and their amplitude scale
//! (report.json) shown by the model's forward simulation at the midpoint plane
//! (`DisplayModel::shown_midpoint`), refocused at the normalised depth `DEPTH`, written as an sRGB PNG
//! normalised to its own 99.5th percentile. The paper's optics (8 µm, 638/520/450 nm, 6 mm volume) and a
//! 6 mm offset, as `holo render`'s defaults.
//!
//! `cargo run --release -p tensorholo --example display_model_view -- MODEL RENDER_DIR DEPTH OUT.png`

use std::path::{Path, PathBuf};

use ndarray::Array3;
use tensorholo::io::save_amplitude_png;
use tensorholo::optics::{focal_stack, OpticalSetup, PropagationOptions};
use tensorholo::slm::model::DisplayModel;
use tensorholo::{HoloError, Result};

/// The codes `[3, H, W]` of a render folder's `phase_{r,g,b}.png`.
fn codes(dir: &Path) -> Result<Array3<u8>> {
    let planes = ["r", "g", "b"]
        .iter()
        .map(|c| {
            let path = dir.join(format!("phase_{c}.png"));
            image::open(&path)
                .map(|i| i.to_luma8())
                .map_err(|source| HoloError::Image { path, source })
        })
        .collect::<Result<Vec<_>>>()?;
    let (w, h) = planes[0].dimensions();
    Array3::from_shape_vec(
        (3, h as usize, w as usize),
        planes
            .iter()
            .flat_map(|p| p.as_raw().iter().copied())
            .collect(),
    )
    .map_err(|e| HoloError::InvalidData(format!("{}: {e}", dir.display())))
}

/// The amplitude scale of the codes: the refinement's where it ran, else the double phase encoding's.
fn amplitude_scale(dir: &Path) -> Result<f32> {
    let path = dir.join("report.json");
    let text = std::fs::read_to_string(&path).map_err(|source| HoloError::Io {
        path: path.clone(),
        source,
    })?;
    let report: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| HoloError::InvalidData(format!("{}: {e}", path.display())))?;
    report["refine"]["amplitude_scale"]
        .as_f64()
        .or_else(|| report["statistics"]["double_phase_amplitude_scale"].as_f64())
        .map(|a| a as f32)
        .ok_or_else(|| HoloError::InvalidData(format!("{}: no amplitude scale", path.display())))
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [model, dir, depth, out] = args.as_slice() else {
        eprintln!("usage: display_model_view MODEL RENDER_DIR DEPTH OUT.png");
        std::process::exit(2);
    };
    let depth: f64 = depth
        .parse()
        .map_err(|_| HoloError::InvalidData(format!("DEPTH `{depth}` is not a number")))?;
    let model = DisplayModel::load(Path::new(model))?;
    let dir = PathBuf::from(dir);
    let (setup, options) = (OpticalSetup::default(), PropagationOptions::default());
    let shown = model.shown_midpoint(
        codes(&dir)?.view(),
        amplitude_scale(&dir)?,
        &setup,
        6e-3,
        options,
    )?;
    let image = focal_stack(shown.view(), &setup, 0.0, &[depth], options, false)?.remove(0);
    let mut sorted: Vec<f32> = image.iter().copied().collect();
    sorted.sort_by(f32::total_cmp);
    let top = sorted[(sorted.len() as f64 * 0.995) as usize].max(f32::MIN_POSITIVE);
    save_amplitude_png(Path::new(out), image.view(), 1.0 / top)
}
