//! `--aberration FILE` of `holo reference` and `holo dataset`: loading the profile and the cost guard of the
//! aberration-corrected SM-LBM (paper Eq. 5, `docs/ABERRATION.md`).

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde_json::{json, Value};
use tensorholo::display::AberrationProfile;
use tensorholo::synthesis::AberrationCorrectedSmLbm;

/// Most propagations per colour a run may need before it is refused (the corrected SM-LBM needs
/// `G·(G + 1)/2` for `G` non-empty planes).
pub const MAX_PROPAGATIONS_PER_COLOUR: usize = 5_000_000;

/// Loads an aberration profile file; `what` names where the file was given (`--aberration`, or `the --display
/// profile's aberration`), so that an error blames what the user wrote.
pub fn load(what: &str, path: &Path) -> Result<AberrationProfile> {
    AberrationProfile::load(path).with_context(|| format!("cannot use {what} {}", path.display()))
}

/// Refuses a run of `propagations` per colour above [`MAX_PROPAGATIONS_PER_COLOUR`] (`what` says whether the
/// count is the scene's or the worst case of `levels`).
pub fn check_cost(propagations: usize, levels: usize, what: &str) -> Result<()> {
    if propagations > MAX_PROPAGATIONS_PER_COLOUR {
        // Largest G with G(G+1)/2 ≤ the limit.
        let g = (((8.0 * MAX_PROPAGATIONS_PER_COLOUR as f64 + 1.0).sqrt() - 1.0) / 2.0).floor();
        bail!(
            "the aberration-corrected SM-LBM would need {propagations} propagations per colour ({what}, \
             G(G+1)/2 for G non-empty planes of --levels {levels}); the limit is \
             {MAX_PROPAGATIONS_PER_COLOUR}: reduce --levels (up to {g} non-empty planes stay under it; \
             --levels 512 needs at most 131328)"
        );
    }
    Ok(())
}

/// The report/manifest entry of a correction: the file, the offset, the coefficients.
pub fn report(path: &Path, synthesis: &AberrationCorrectedSmLbm, propagations: usize) -> Value {
    json!({
        "file": crate::output::path_text(path),
        "slm_offset_m": synthesis.correction.slm_offset_m,
        "profile": synthesis.correction.profile,
        "propagations_per_colour": propagations,
        "method": "aberration-corrected SM-LBM (paper Eq. 5), kernel circ(rho <= 1) exp(i sum Z_j) per plane at d = z_N - s",
    })
}
