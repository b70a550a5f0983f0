//! The fit of the five Zernike coefficients (paper Eq. 14–18) per distance from spot captures (phase
//! diversity), and of the whole plan into a `tensorholo.aberration` file.

use std::cell::RefCell;
use std::path::Path;

use argmin::core::{CostFunction, Error as ArgminError, Executor, State};
use argmin::solver::neldermead::NelderMead;
use rayon::prelude::*;

use super::model::{ModelScratch, SpotModel};
use super::windows::{initial_offset, load_windows, CaptureWindow};
use super::{wavelength_scaled, SpotPlan, COLOURS};
use crate::display::{AberrationProfile, AberrationSample};
use crate::error::{HoloError, Result};
use crate::optics::ZernikeCoefficients;

/// Largest `|coefficient|` (radians) and spot offset (fraction of the window) the fit explores.
const MAX_COEFFICIENT_RAD: f64 = 8.0;

/// Options of [`fit_captures`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Nelder–Mead iterations per run (each distance makes up to four runs).
    pub max_iters: u64,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self { max_iters: 1500 }
    }
}

/// The fit at one distance of one colour.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceFit {
    /// The distance `d` in metres.
    pub distance_m: f64,
    /// The fitted coefficients `a3 … a7` (radians at `ρ = 1`).
    pub coefficients: ZernikeCoefficients,
    /// The spot's fitted centre in the captures, `(x, y)` camera pixels.
    pub spot_px: (f64, f64),
    /// The relative RMS residual: `√(Σ residual² / Σ (capture − its mean)²)` over the usable pixels.
    pub residual: f64,
    /// Cost evaluations used.
    pub evaluations: u64,
}

/// The fit of one colour.
#[derive(Debug, Clone, PartialEq)]
pub struct ColourFit {
    /// Fitted from its own captures; else derived by `super::wavelength_scaled`.
    pub fitted: bool,
    /// For a derived colour, the colour index (0–2) it was derived from.
    pub derived_from: Option<usize>,
    /// One entry per plan distance (increasing).
    pub distances: Vec<DistanceFit>,
}

/// What [`fit_captures`] found: per colour (R, G, B) the fits, and the profile to save.
#[derive(Debug, Clone)]
pub struct FitReport {
    /// R, G, B.
    pub colours: Vec<ColourFit>,
    /// One sample per distance, with the plan's display ([`AberrationProfile::with_display`]).
    pub profile: AberrationProfile,
}

/// The least-squares cost of one distance: Σ over captures of the residual of `a_k·I_k + b_k` (closed form)
/// over the usable pixels, divided by the captures' total variance.
struct SpotCost<'a> {
    model: &'a SpotModel,
    diversities: &'a [ZernikeCoefficients],
    windows: &'a [CaptureWindow],
    total_variance: f64,
    scratch: RefCell<(ModelScratch, Vec<f64>)>,
    evaluations: RefCell<u64>,
}

impl SpotCost<'_> {
    fn value(&self, x: &[f64]) -> f64 {
        *self.evaluations.borrow_mut() += 1;
        let half = self.model.window_px() as f64 / 2.0;
        let excess = x[..5]
            .iter()
            .map(|a| (a.abs() - MAX_COEFFICIENT_RAD).max(0.0))
            .chain(x[5..7].iter().map(|t| (t.abs() - half).max(0.0)))
            .sum::<f64>();
        if !x.iter().all(|v| v.is_finite()) || excess > 0.0 {
            return 1.0 + excess.min(1e6);
        }
        let mut guard = self.scratch.borrow_mut();
        let (scratch, image) = &mut *guard;
        let mut sse = 0.0;
        for (d, win) in self.diversities.iter().zip(self.windows) {
            let z =
                ZernikeCoefficients::from_array(std::array::from_fn(|j| x[j] + d.to_array()[j]));
            if self
                .model
                .intensity(&z, (x[5], x[6]), scratch, image)
                .is_err()
            {
                return 1.0;
            }
            sse += linear_residual(image, win);
        }
        sse / self.total_variance
    }
}

/// `min over a, b of Σ (a·m + b − y)²` over the window's usable pixels.
fn linear_residual(model: &[f64], win: &CaptureWindow) -> f64 {
    let (mut n, mut sm, mut sy, mut smm, mut smy, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for ((&m, &y), &ok) in model.iter().zip(&win.values).zip(&win.valid) {
        if ok {
            n += 1.0;
            sm += m;
            sy += y;
            smm += m * m;
            smy += m * y;
            syy += y * y;
        }
    }
    let (cmm, cmy, cyy) = (smm - sm * sm / n, smy - sm * sy / n, syy - sy * sy / n);
    if cmm <= 0.0 {
        return cyy.max(0.0);
    }
    (cyy - cmy * cmy / cmm).max(0.0)
}

/// The captures' total variance about each capture's mean (usable pixels).
fn total_variance(windows: &[CaptureWindow]) -> f64 {
    windows
        .iter()
        .map(|w| {
            let ok: Vec<f64> = w
                .values
                .iter()
                .zip(&w.valid)
                .filter(|(_, &b)| b)
                .map(|(&v, _)| v)
                .collect();
            let mean = ok.iter().sum::<f64>() / ok.len().max(1) as f64;
            ok.iter().map(|v| (v - mean).powi(2)).sum::<f64>()
        })
        .sum()
}

/// One Nelder–Mead run from `start` with simplex steps `step` (radians for the coefficients, pixels for the
/// position). Returns the best point and its cost.
fn nelder_mead(
    cost: &SpotCost,
    start: &[f64],
    step: [f64; 2],
    iters: u64,
) -> Result<(Vec<f64>, f64)> {
    let mut simplex = vec![start.to_vec()];
    for j in 0..start.len() {
        let mut v = start.to_vec();
        v[j] += if j < 5 { step[0] } else { step[1] };
        simplex.push(v);
    }
    let internal = |e: ArgminError| HoloError::Internal(format!("Nelder–Mead: {e}"));
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-12)
        .map_err(internal)?;
    let result = Executor::new(CostRef(cost), solver)
        .configure(|s| s.max_iters(iters))
        .run()
        .map_err(internal)?;
    let best = result
        .state()
        .get_best_param()
        .cloned()
        .unwrap_or_else(|| start.to_vec());
    let c = cost.value(&best);
    Ok((best, c))
}

/// The cost as argmin's problem, borrowed (the executor takes its problem by value).
struct CostRef<'a>(&'a SpotCost<'a>);

impl CostFunction for CostRef<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Self::Param) -> std::result::Result<f64, ArgminError> {
        Ok(self.0.value(x))
    }
}

/// Fits the coefficients and the spot's position at one distance from its capture windows (one per
/// diversity of `diversities`, same order). `start_px` is the initial spot offset from the window's centre.
/// Deterministic: the starts are zero and the best of a 3×3×3 scan of focus and astigmatism (±1 rad), each
/// refined by Nelder–Mead, the best of them refined twice more with smaller simplices.
///
/// Returns `(coefficients, offset (tx, ty), relative RMS residual, evaluations)`.
///
/// Errors: [`HoloError::InvalidData`] for windows of another count or size, or captures without contrast;
/// [`HoloError::Internal`] if the optimiser fails.
pub(crate) fn fit_distance(
    model: &SpotModel,
    diversities: &[ZernikeCoefficients],
    windows: &[CaptureWindow],
    start_px: (f64, f64),
    options: &FitOptions,
) -> Result<(ZernikeCoefficients, (f64, f64), f64, u64)> {
    let len = model.window_px() * model.window_px();
    if windows.len() != diversities.len()
        || windows
            .iter()
            .any(|w| w.values.len() != len || w.valid.len() != len)
    {
        return Err(HoloError::InvalidData(format!(
            "{} capture windows of {len} pixels expected, one per diversity",
            diversities.len()
        )));
    }
    let total = total_variance(windows);
    if !(total.is_finite() && total > 0.0) {
        return Err(HoloError::InvalidData(
            "the captures have no contrast in the spot's window".into(),
        ));
    }
    let cost = SpotCost {
        model,
        diversities,
        windows,
        total_variance: total,
        scratch: RefCell::new((model.scratch(), vec![0.0; len])),
        evaluations: RefCell::new(0),
    };
    let zero = vec![0.0, 0.0, 0.0, 0.0, 0.0, start_px.0, start_px.1];
    let mut scan = (zero.clone(), cost.value(&zero));
    for f in [-1.0, 0.0, 1.0] {
        for a in [-1.0, 0.0, 1.0] {
            for b in [-1.0, 0.0, 1.0] {
                let x = vec![f, a, b, 0.0, 0.0, start_px.0, start_px.1];
                let c = cost.value(&x);
                if c < scan.1 {
                    scan = (x, c);
                }
            }
        }
    }
    let mut best = nelder_mead(&cost, &zero, [0.5, 1.0], options.max_iters)?;
    if scan.0 != zero {
        let other = nelder_mead(&cost, &scan.0, [0.5, 1.0], options.max_iters)?;
        if other.1 < best.1 {
            best = other;
        }
    }
    for step in [[0.15, 0.3], [0.05, 0.1]] {
        let refined = nelder_mead(&cost, &best.0, step, options.max_iters)?;
        if refined.1 <= best.1 {
            best = refined;
        }
    }
    let (x, c) = best;
    let z = ZernikeCoefficients::from_array([x[0], x[1], x[2], x[3], x[4]]);
    let evaluations = *cost.evaluations.borrow();
    Ok((z, (x[5], x[6]), c.max(0.0).sqrt(), evaluations))
}

/// Fits every colour of `plan` that has captures in `dir` (all of its captures; a colour of the plan with
/// none is derived, see below), at every distance, and returns the report and the aberration profile
/// (one sample per distance, R, G, B, with the plan's wavelengths and pitch). Colours without captures take
/// the fitted colour of nearest wavelength through `super::wavelength_scaled`. `progress` gets one line
/// per fitted distance. Distances and colours run in parallel (rayon); each fit is serial and
/// deterministic, so the result does not depend on the thread count.
///
/// Errors: as `super::windows::load_windows` (a missing capture names the file; when no colour has captures, the first
/// capture of the plan) and `fit_distance`; [`HoloError::InvalidData`] for a non-finite fitted value.
pub fn fit_captures(
    plan: &SpotPlan,
    dir: &Path,
    options: &FitOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<FitReport> {
    plan.validate()?;
    let planned = plan.colour_indices()?;
    let has_any = |c: usize| {
        (0..plan.distances_m.len()).any(|i| {
            (0..plan.diversities.len()).any(|k| dir.join(SpotPlan::capture_name(c, i, k)).exists())
        })
    };
    let mut captured: Vec<usize> = planned.iter().copied().filter(|&c| has_any(c)).collect();
    if captured.is_empty() {
        // Report the first capture the plan expects.
        captured.push(planned[0]);
    }
    let model = SpotModel::new(plan.window_px, plan.camera_scale)?;
    let jobs: Vec<(usize, usize)> = captured
        .iter()
        .flat_map(|&c| (0..plan.distances_m.len()).map(move |i| (c, i)))
        .collect();
    let fits: Vec<DistanceFit> = jobs
        .par_iter()
        .map(|&(c, i)| {
            let (windows, (x0, y0)) = load_windows(plan, dir, c, i)?;
            let start = initial_offset(&windows, plan.window_px);
            let (z, (tx, ty), residual, evaluations) =
                fit_distance(&model, &plan.diversities, &windows, start, options)?;
            if !(z.to_array().iter().all(|v| v.is_finite()) && residual.is_finite()) {
                return Err(HoloError::InvalidData(format!(
                    "the fit of the {} captures at {:+.3} mm gave a non-finite value",
                    COLOURS[c],
                    plan.distances_m[i] * 1e3
                )));
            }
            let half = plan.window_px as f64 / 2.0;
            let fit = DistanceFit {
                distance_m: plan.distances_m[i],
                coefficients: z,
                spot_px: (x0 as f64 + half + tx, y0 as f64 + half + ty),
                residual,
                evaluations,
            };
            progress(&format!(
                "{} {:+.3} mm: residual {:.4}, {} evaluations",
                COLOURS[c],
                fit.distance_m * 1e3,
                fit.residual,
                fit.evaluations
            ));
            Ok(fit)
        })
        .collect::<Result<_>>()?;
    let per_colour = |c: usize| -> Vec<DistanceFit> {
        jobs.iter()
            .zip(&fits)
            .filter(|((jc, _), _)| *jc == c)
            .map(|(_, f)| f.clone())
            .collect()
    };
    let colours: Vec<ColourFit> = (0..3)
        .map(|c| {
            if captured.contains(&c) {
                return ColourFit {
                    fitted: true,
                    derived_from: None,
                    distances: per_colour(c),
                };
            }
            let from = *captured
                .iter()
                .min_by(|&&a, &&b| {
                    let d = |x: usize| (plan.wavelengths_m[x] - plan.wavelengths_m[c]).abs();
                    d(a).total_cmp(&d(b))
                })
                .unwrap_or(&captured[0]);
            let distances = per_colour(from)
                .into_iter()
                .map(|f| DistanceFit {
                    coefficients: wavelength_scaled(
                        &f.coefficients,
                        plan.wavelengths_m[from],
                        plan.wavelengths_m[c],
                    ),
                    ..f
                })
                .collect();
            ColourFit {
                fitted: false,
                derived_from: Some(from),
                distances,
            }
        })
        .collect();
    let samples = (0..plan.distances_m.len())
        .map(|i| AberrationSample {
            distance_m: plan.distances_m[i],
            coefficients: std::array::from_fn(|c| colours[c].distances[i].coefficients),
        })
        .collect();
    let profile =
        AberrationProfile::new(samples)?.with_display(plan.wavelengths_m, plan.pixel_pitch_m);
    Ok(FitReport { colours, profile })
}
