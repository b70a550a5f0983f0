//! The spot fit's memory does not grow with the camera's resolution (issue 67, cause 3): five 36-megapixel
//! captures of one distance (a simulated spot pasted into a large black frame) are fitted within a stated
//! bound, where keeping each capture whole took ~50 bytes per camera pixel (1.7 GB here). Alone in its test
//! binary, so that the process's peak resident memory is this test's.

use std::path::Path;

use tensorholo::optics::OpticalSetup;
use tensorholo::slm::spots::simulate::{simulate_captures, SimulateOptions};
use tensorholo::slm::spots::{fit_captures, FitOptions, SpotPlan};

/// The side of the large captures: 6000² = 36 MP.
const SIDE: usize = 6000;
/// Where the small capture's top-left corner goes in the large one.
const AT: (usize, usize) = (3217, 1402);
/// The bound on the fit's peak resident memory above what the process held before it, MiB: the spot grid
/// (blocks of 6 pixels: 1000² cells, with the blur's copies 24 MiB), a row of the decoder, the windows and
/// the model. Measured (Intel Xeon VM, debug build): 23 MiB; keeping every capture whole took 1,682.
const FIT_LIMIT_MIB: f64 = 64.0;

fn status_mib(key: &str) -> Option<f64> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// Pastes the 8-bit grey PNG at `small` into a `SIDE × SIDE` frame of its own darkest value at `AT`.
fn paste_large(small: &Path, large: &Path) {
    let img = image::open(small).unwrap().to_luma8();
    let black = *img.as_raw().iter().min().unwrap();
    let mut big = image::GrayImage::from_pixel(SIDE as u32, SIDE as u32, image::Luma([black]));
    image::imageops::replace(&mut big, &img, AT.0 as i64, AT.1 as i64);
    big.save(large).unwrap();
}

#[test]
fn the_spot_fit_of_36_megapixel_captures_stays_within_its_memory_bound() {
    let dir = tempfile::tempdir().unwrap();
    let (patterns, small, large) = (
        dir.path().join("patterns"),
        dir.path().join("small"),
        dir.path().join("large"),
    );
    let plan = SpotPlan::new(
        [64, 64],
        &OpticalSetup::default(),
        &[1],
        vec![4e-3],
        2.0,
        32,
    )
    .unwrap();
    plan.write_patterns(&patterns, &|_, _| {}).unwrap();
    let options = SimulateOptions {
        seed: 11,
        ..SimulateOptions::default()
    };
    let hidden = simulate_captures(&plan, &patterns, &small, &options, &|_, _| {}).unwrap();
    let reference = fit_captures(&plan, &small, &FitOptions::default(), &|_| {}).unwrap();
    std::fs::create_dir_all(&large).unwrap();
    for k in 0..plan.diversities.len() {
        let name = SpotPlan::capture_name(1, 0, k);
        paste_large(&small.join(&name), &large.join(&name));
    }
    // The peak from here on (Linux: 5 to clear_refs resets VmHWM); without it, the process's whole peak,
    // which the pasting keeps near 100 MiB.
    let reset = std::fs::write("/proc/self/clear_refs", "5").is_ok();
    let before = status_mib("VmRSS:").expect("/proc/self/status (Linux)");
    let report = fit_captures(&plan, &large, &FitOptions::default(), &|_| {}).unwrap();
    let peak = status_mib("VmHWM:").unwrap();
    eprintln!(
        "fit of 5 captures of {SIDE}²: peak {peak:.0} MiB, {:.0} above the {before:.0} before (reset: {reset})",
        peak - before
    );
    assert!(
        peak - before <= FIT_LIMIT_MIB,
        "the fit took {:.0} MiB above its start (limit {FIT_LIMIT_MIB})",
        peak - before
    );
    // The same spot, found in blocks of 6 pixels and cut at full resolution: the fit places it where the small
    // captures' fit did, shifted by the paste, and recovers the hidden coefficients as well.
    let (a, b) = (
        reference.colours[1].distances[0].spot_px,
        report.colours[1].distances[0].spot_px,
    );
    let shifted = (a.0 + AT.0 as f64, a.1 + AT.1 as f64);
    assert!(
        (b.0 - shifted.0).abs() < 0.5 && (b.1 - shifted.1).abs() < 0.5,
        "spot at {b:?}, expected {shifted:?}"
    );
    let want = hidden.samples()[0].coefficients[1].to_array();
    let got = report.profile.samples()[0].coefficients[1].to_array();
    let err = got
        .iter()
        .zip(want)
        .map(|(g, w)| (g - w).abs())
        .fold(0.0, f64::max);
    assert!(
        err < 0.1,
        "fitted {got:.3?}, hidden {want:.3?}: error {err} rad"
    );
}
