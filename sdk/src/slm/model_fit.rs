//! Fitting a display model (`slm::model`) to camera captures by Levenberg–Marquardt least squares, with
//! the Jacobian made analytically (forward-mode: each parameter's derivative of the SLM field, propagated as
//! the field is), docs/CALIBRATION.md "The fit".
//!
//! Per colour the parameters are the colour's log-gain `ln g_c` (the set's one gain `g` times the colour's
//! source power: the two are one parameter to the captures of one colour, and are told apart afterwards,
//! the brightest colour's power being 1), the source's log-amplitude and phase polynomials
//! (5 terms each), the response's `(s, r₂, r₃)` (`model_captures::response_basis`), the crosstalk
//! kernel's neighbour weights (the centre is `1 − Σ`, so a flat drive stays flat: the response's scale holds
//! the rest), the zero order `(Re z, Im z)` and the aberration's five Zernike terms. The residual is
//! `g·|U|² − I` over every capture's unsaturated pixels, `U = F⁻¹{M·E·H·F{u}}` (`slm::model`).
//! `∂(g|U|²)/∂θ = 2g·Re(conj(U)·∂U/∂θ)` with `∂U/∂θ = F⁻¹{M·E·H·F{∂u/∂θ}}` for the field's parameters and
//! `F⁻¹{−i·Z_j·M·E·H·F{u}}` for an aberration term `a_j` (`E = circ·exp(−i·Σa_jZ_j)`).

use num_complex::Complex32;

use super::model::{
    capture_multiplier, normalised, source_terms, ColourDisplay, ColourRuntime, Crosstalk,
    DisplayModel, SourceField, COLOUR_KEYS,
};
use super::model_captures::{response_basis, response_curve, CaptureSet};
use crate::error::{invalid, HoloError, Result};
use crate::optics::propagation::SpectralPlan;
use crate::optics::zernike::pupil_multiplier;
use crate::optics::{OpticalSetup, Padding, PropagationOptions, ZernikeCoefficients};
use crate::slm::LutRepresentation;

/// How a fit runs.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// The display's wavelengths and pitch (the captures' distances are given).
    pub setup: OpticalSetup,
    /// Levenberg–Marquardt iterations at most, `1..=500`.
    pub iterations: usize,
    /// The crosstalk kernel's side: 1 (no crosstalk fitted), 3 or 5.
    pub kernel_side: usize,
    /// A simulation's hidden parameters: the report then gives the error of each fitted part against them.
    pub truth: Option<DisplayModel>,
    /// Per colour (R, G, B) a phase response the fit holds instead of fitting one: a calibration's look-up
    /// tables (`DisplayCalibration::luts`, Eq. 12–13), global or per pixel (of the captures' SLM size). The
    /// model keeps it as its response. `None`: the response is fitted (one curve for the panel).
    pub responses: [Option<LutRepresentation>; 3],
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            setup: OpticalSetup::default(),
            iterations: 40,
            kernel_side: 3,
            truth: None,
            responses: [None, None, None],
        }
    }
}

/// One capture's residual after the fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CaptureResidual {
    /// The capture file's name in the manifest.
    pub capture: String,
    /// RMS of `g·|U|² − I` over its used pixels, in units of full scale.
    pub rms: f64,
    /// That RMS before the fit (the ideal display at the best gain).
    pub ideal_rms: f64,
}

/// A fitted part's error against a simulation's hidden parameters.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PartError {
    /// `green.crosstalk`, …
    pub part: String,
    /// What is compared and the largest absolute error, in the part's units.
    pub measure: String,
    /// The error.
    pub error: f64,
}

/// What [`fit`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct FitReport {
    /// The fitted model (parts the captures do not determine kept ideal).
    pub model: DisplayModel,
    /// Per capture, in the manifest's order.
    pub residuals: Vec<CaptureResidual>,
    /// Parts the captures do not determine, each naming the colour, part and parameter.
    pub warnings: Vec<String>,
    /// The capture set's one gain `g` (captured intensity per unit of `|U|²`; `None`: no captures), with the
    /// brightest colour's source taken at power 1.
    pub gain: Option<f64>,
    /// Per colour the source's power relative to the brightest colour's (`None`: no captures of it): the
    /// constant of the source's log-amplitude, `ln(power)/2`, which the fit separates from the one gain. The
    /// model file does not store it: the refinement and the evaluation scale each colour by least squares.
    pub power: [Option<f64>; 3],
    /// Errors against [`FitOptions::truth`] where one was given.
    pub truth_errors: Vec<PartError>,
}

/// The parameter layout of one colour.
#[derive(Debug, Clone, Copy)]
struct Layout {
    /// Neighbour count of the kernel (`side² − 1`).
    kernel: usize,
    side: usize,
}

/// The parts' names in warnings (`green.source.phase_rad`), by index: [`GAIN`], [`AMPLITUDE`], [`PHASE`],
/// [`RESPONSE`], [`CROSSTALK`], [`ZERO_ORDER`], [`ABERRATION`].
const PARTS: [&str; 7] = [
    "gain",
    "source.log_amplitude",
    "source.phase_rad",
    "response",
    "crosstalk",
    "zero_order",
    "aberration",
];
const GAIN: usize = 0;
const AMPLITUDE: usize = 1;
const PHASE: usize = 2;
const RESPONSE: usize = 3;
const CROSSTALK: usize = 4;
const ZERO_ORDER: usize = 5;
const ABERRATION: usize = 6;

impl Layout {
    /// Each part's parameters: the gain (1), the source's log-amplitude (5) and phase (5), the response (3),
    /// the kernel's neighbours, the zero order (2) and the aberration (5).
    fn ranges(&self) -> [std::ops::Range<usize>; 7] {
        let k = 14 + self.kernel;
        [0..1, 1..6, 6..11, 11..14, 14..k, k..k + 2, k + 2..k + 7]
    }
    fn len(&self) -> usize {
        21 + self.kernel
    }
    /// The indices of the free parts' parameters (the gain always), in order.
    fn free_indices(&self, free: &[bool; 7]) -> Vec<usize> {
        let ranges = self.ranges();
        (0..PARTS.len())
            .filter(|&p| free[p] || p == GAIN)
            .flat_map(|p| ranges[p].clone())
            .collect()
    }
    /// Neighbour `n`'s kernel offset `(dy, dx)` and index in the row-major kernel.
    fn neighbour(&self, n: usize) -> (isize, isize, usize) {
        let centre = self.side * self.side / 2;
        let idx = if n < centre { n } else { n + 1 };
        let h = (self.side / 2) as isize;
        (
            (idx / self.side) as isize - h,
            (idx % self.side) as isize - h,
            idx,
        )
    }
    fn ideal(&self) -> Vec<f64> {
        let mut t = vec![0.0; self.len()];
        t[self.ranges()[RESPONSE].start] = 1.0;
        t
    }
    /// The colour's parts of `theta` (`free[part]`: fitted; others ideal). The response is not checked here.
    fn display(&self, theta: &[f64], free: &[bool; 7]) -> (ColourDisplay, Option<[f32; 256]>) {
        let r = self.ranges();
        let mut part = ColourDisplay::default();
        if free[AMPLITUDE] || free[PHASE] {
            let mut source = SourceField::default();
            if free[AMPLITUDE] {
                source
                    .log_amplitude
                    .copy_from_slice(&theta[r[AMPLITUDE].clone()]);
            }
            if free[PHASE] {
                source.phase_rad.copy_from_slice(&theta[r[PHASE].clone()]);
            }
            part.source = Some(source);
        }
        let response = &theta[r[RESPONSE].clone()];
        let table = free[RESPONSE].then(|| {
            std::array::from_fn(|k| {
                let b = response_basis(k);
                (response[0] * b[0] + response[1] * b[1] + response[2] * b[2]) as f32
            })
        });
        if free[CROSSTALK] && self.kernel > 0 {
            let mut weights = vec![0.0; self.side * self.side];
            let mut centre = 1.0;
            for n in 0..self.kernel {
                let (_, _, idx) = self.neighbour(n);
                weights[idx] = theta[r[CROSSTALK].start + n];
                centre -= theta[r[CROSSTALK].start + n];
            }
            weights[self.side * self.side / 2] = centre;
            part.crosstalk = Some(Crosstalk {
                size: [self.side, self.side],
                weights,
            });
        }
        if free[ZERO_ORDER] {
            let z = r[ZERO_ORDER].start;
            part.zero_order = Some([theta[z], theta[z + 1]]);
        }
        if free[ABERRATION] {
            let mut a = [0.0; 5];
            a.copy_from_slice(&theta[r[ABERRATION].clone()]);
            part.aberration = Some(ZernikeCoefficients::from_array(a));
        }
        (part, table)
    }
}

/// One distance's fixed multiplier `M·H` (full spectrum layout) and its grid.
struct Plane {
    distance_m: f64,
    mh: Vec<Complex32>,
}

/// What one evaluation of the least-squares problem gives.
struct Normal {
    cost: f64,
    jtj: Vec<f64>,
    jtr: Vec<f64>,
    rms: Vec<f64>,
}

/// One colour's problem.
struct Problem<'a> {
    set: &'a CaptureSet,
    captures: Vec<usize>,
    layout: Layout,
    plan: SpectralPlan,
    planes: Vec<Plane>,
    /// The Zernike terms `Z_j` on the spectrum layout (real).
    zernike: Vec<Vec<f32>>,
    /// The source's polynomial terms per pixel.
    terms: Vec<[f64; 5]>,
    /// The response held ([`FitOptions::responses`]), `None`: fitted.
    held_response: Option<LutRepresentation>,
}

impl<'a> Problem<'a> {
    fn new(set: &'a CaptureSet, colour: usize, options: &FitOptions) -> Result<Self> {
        let (h, w) = set.size;
        let captures: Vec<usize> = (0..set.captures.len())
            .filter(|&i| set.captures[i].colour == colour)
            .collect();
        let mut planes: Vec<Plane> = Vec::new();
        for &i in &captures {
            let d = set.captures[i].distance_m;
            if planes.iter().any(|p| p.distance_m == d) {
                continue;
            }
            let (prop, m) = capture_multiplier(
                &options.setup,
                PropagationOptions::default(),
                colour,
                (h, w),
                d,
                None,
            )?;
            let (rows, cols) = (
                prop.plan().computational_shape().1,
                prop.plan().computational_shape().0,
            );
            planes.push(Plane {
                distance_m: d,
                mh: m.full(rows, cols, prop.plan().fft().isa()),
            });
        }
        let plan = SpectralPlan::new(h, w, Padding::None)?;
        let (ch, cw) = plan.computational_shape();
        let zernike = (0..5)
            .map(|j| {
                let mut a = [0.0; 5];
                a[j] = 1.0;
                let z = ZernikeCoefficients::from_array(a);
                plan.build_multiplier(|kx, ky| {
                    let (rx, ry) = (2.0 * kx as f64 / cw as f64, 2.0 * ky as f64 / ch as f64);
                    Complex32::new(z.phase_xy(rx, ry) as f32, 0.0)
                })
                .into_iter()
                .map(|v| v.re)
                .collect()
            })
            .collect();
        let terms = (0..h)
            .flat_map(|i| (0..w).map(move |j| source_terms(normalised(j, w), normalised(i, h))))
            .collect();
        let side = options.kernel_side;
        Ok(Self {
            set,
            captures,
            layout: Layout {
                kernel: side * side - 1,
                side,
            },
            plan,
            planes,
            zernike,
            terms,
            held_response: options.responses[colour].clone(),
        })
    }

    /// The cost, and with `free` the normal equations of the free parameters' Jacobian, at `theta`.
    fn evaluate(&self, theta: &[f64], free: &[bool; 7], with_jacobian: bool) -> Normal {
        let (h, w) = self.set.size;
        let n = h * w;
        let fft = self.plan.fft();
        let zero = Complex32::new(0.0, 0.0);
        let ranges = self.layout.ranges();
        // The free parameters' indices.
        let index = self.layout.free_indices(free);
        let np = index.len();
        let (mut part, table) = self.layout.display(theta, free);
        part.response.clone_from(&self.held_response);
        let mut runtime = ColourRuntime::new(&part, h, w);
        if let Some(t) = table {
            runtime.set_response(t);
        }
        let e = free[ABERRATION].then(|| {
            pupil_multiplier(
                &self.plan,
                part.aberration.as_ref().expect("made when free"),
            )
        });
        let gain = theta[0].exp();
        let mut scratch = vec![zero; fft.scratch_len()];
        let mut unit = vec![zero; n];
        let mut jtj = vec![0.0f64; np * np];
        let mut jtr = vec![0.0f64; np];
        let mut cost = 0.0;
        let mut rms = Vec::new();
        let cols = fft.height();
        let mut last_pattern = usize::MAX;
        let mut spectra: Vec<Vec<Complex32>> = Vec::new();
        for &ci in &self.captures {
            let cap = &self.set.captures[ci];
            if cap.pattern != last_pattern {
                last_pattern = cap.pattern;
                let drive: Vec<f32> = self.set.patterns[cap.pattern]
                    .iter()
                    .map(|&c| f32::from(c))
                    .collect();
                runtime.forward(&drive, &mut unit);
                // The field's derivatives (index order), then their spectra; the field's own first.
                let mut fields = vec![unit.clone()];
                if with_jacobian {
                    for &k in &index {
                        if let Some(d) = self.field_derivative(k, &runtime, &unit, &drive, theta) {
                            fields.push(d);
                        }
                    }
                }
                spectra = fields
                    .into_iter()
                    .map(|mut f| {
                        let mut s = vec![zero; n];
                        fft.forward(&mut f, &mut s, &mut scratch);
                        s
                    })
                    .collect();
            }
            let plane = self
                .planes
                .iter()
                .find(|p| p.distance_m == cap.distance_m)
                .expect("a plane per distance");
            let mut m = plane.mh.clone();
            if let Some(e) = &e {
                for (m, e) in m.iter_mut().zip(e) {
                    *m *= e.conj();
                }
            }
            let apply = |s: &[Complex32], extra: Option<&[f32]>, scratch: &mut [Complex32]| {
                let mut y: Vec<Complex32> = s.iter().zip(&m).map(|(a, b)| a * b).collect();
                if let Some(z) = extra {
                    for (y, &z) in y.iter_mut().zip(z) {
                        *y *= Complex32::new(0.0, -z);
                    }
                }
                let mut out = vec![zero; n];
                fft.inverse(&mut y, &mut out, scratch);
                out
            };
            debug_assert_eq!(cols * (n / cols), n);
            let field = apply(&spectra[0], None, &mut scratch);
            // Jacobian columns, index order.
            let mut columns: Vec<Vec<f32>> = Vec::new();
            if with_jacobian {
                let mut next = 1;
                for &k in &index {
                    let du = if k == 0 {
                        None
                    } else if ranges[ABERRATION].contains(&k) {
                        Some(apply(
                            &spectra[0],
                            Some(&self.zernike[k - ranges[ABERRATION].start]),
                            &mut scratch,
                        ))
                    } else {
                        next += 1;
                        Some(apply(&spectra[next - 1], None, &mut scratch))
                    };
                    columns.push(match du {
                        None => field.iter().map(|u| gain as f32 * u.norm_sqr()).collect(),
                        Some(d) => field
                            .iter()
                            .zip(&d)
                            .map(|(u, d)| 2.0 * gain as f32 * (u.conj() * d).re)
                            .collect(),
                    });
                }
            }
            let (mut sum, mut count) = (0.0f64, 0usize);
            for q in 0..n {
                if !cap.valid[q] {
                    continue;
                }
                let r = gain * f64::from(field[q].norm_sqr()) - f64::from(cap.intensity[q]);
                sum += r * r;
                count += 1;
                if with_jacobian {
                    for a in 0..np {
                        let ja = f64::from(columns[a][q]);
                        jtr[a] += ja * r;
                        for b in a..np {
                            jtj[a * np + b] += ja * f64::from(columns[b][q]);
                        }
                    }
                }
            }
            cost += sum;
            rms.push((sum / count.max(1) as f64).sqrt());
        }
        for a in 0..np {
            for b in 0..a {
                jtj[a * np + b] = jtj[b * np + a];
            }
        }
        Normal {
            cost,
            jtj,
            jtr,
            rms,
        }
    }

    /// `∂u/∂θ_k` of the last forward pass of `runtime` (`None` for parameters outside the field: the gain and
    /// the aberration).
    fn field_derivative(
        &self,
        k: usize,
        runtime: &ColourRuntime,
        unit: &[Complex32],
        drive: &[f32],
        theta: &[f64],
    ) -> Option<Vec<Complex32>> {
        let r = self.layout.ranges();
        let (h, w) = self.set.size;
        let src = |p: usize| {
            runtime
                .source
                .as_ref()
                .map_or(Complex32::new(1.0, 0.0), |s| s[p])
        };
        let i_dphi = |p: usize, dphi: f32| runtime.modulated[p] * Complex32::new(0.0, dphi);
        if r[AMPLITUDE].contains(&k) {
            let t = k - r[AMPLITUDE].start;
            return Some(
                unit.iter()
                    .zip(&self.terms)
                    .map(|(u, b)| u * b[t] as f32)
                    .collect(),
            );
        }
        if r[PHASE].contains(&k) {
            // ∂u/∂φ_t = i·b_t·u: the source multiplies the modulated light and the zero order alike.
            let t = k - r[PHASE].start;
            return Some(
                unit.iter()
                    .zip(&self.terms)
                    .map(|(u, b)| u * Complex32::new(0.0, b[t] as f32))
                    .collect(),
            );
        }
        if r[RESPONSE].contains(&k) {
            let j = k - r[RESPONSE].start;
            return Some(
                (0..h * w)
                    .map(|p| {
                        let v = runtime.crossed[p];
                        let i = (v.floor() as isize).clamp(0, 254) as usize;
                        let (b0, b1) = (response_basis(i)[j], response_basis(i + 1)[j]);
                        i_dphi(p, (b0 + (f64::from(v) - i as f64) * (b1 - b0)) as f32)
                    })
                    .collect(),
            );
        }
        if r[CROSSTALK].contains(&k) {
            let (dy, dx, _) = self.layout.neighbour(k - r[CROSSTALK].start);
            return Some(
                (0..h * w)
                    .map(|p| {
                        let (i, j) = ((p / w) as isize, (p % w) as isize);
                        let q = ((i + dy).clamp(0, h as isize - 1) * w as isize
                            + (j + dx).clamp(0, w as isize - 1))
                            as usize;
                        let slope = runtime.respond(p, runtime.crossed[p]).1;
                        i_dphi(p, slope * (drive[q] - drive[p]))
                    })
                    .collect(),
            );
        }
        if r[ZERO_ORDER].contains(&k) {
            let c = if k == r[ZERO_ORDER].start {
                Complex32::new(1.0, 0.0)
            } else {
                Complex32::new(0.0, 1.0)
            };
            return Some((0..h * w).map(|p| src(p) * c).collect());
        }
        let _ = theta;
        None
    }
}

/// Solves `a·x = b` (`n × n`, symmetric positive definite after damping) by Gaussian elimination with
/// partial pivoting; `None` when singular.
fn solve(mut a: Vec<f64>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i * n + c].abs().total_cmp(&a[j * n + c].abs()))?;
        if a[p * n + c].abs() < 1e-300 {
            return None;
        }
        for k in 0..n {
            a.swap(c * n + k, p * n + k);
        }
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r * n + c] / a[c * n + c];
            for k in c..n {
                a[r * n + k] -= f * a[c * n + k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| a[r * n + k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r * n + r];
    }
    Some(x)
}

/// The parameters the normal matrix `jtj` (`np × np`) does not determine: a zero diagonal against the gain's,
/// or a variance inflation (the diagonal of the inverse correlation matrix) above 10⁸.
fn undetermined(jtj: &[f64], np: usize) -> Vec<usize> {
    let d: Vec<f64> = (0..np).map(|i| jtj[i * np + i]).collect();
    let floor = 1e-9 * d[0].max(f64::MIN_POSITIVE);
    let live: Vec<usize> = (0..np).filter(|&i| d[i] > floor).collect();
    let mut out: Vec<usize> = (0..np).filter(|&i| d[i] <= floor).collect();
    let m = live.len();
    let corr: Vec<f64> = live
        .iter()
        .flat_map(|&i| {
            let d = &d;
            live.iter()
                .map(move |&j| jtj[i * np + j] / (d[i] * d[j]).sqrt())
        })
        .collect();
    for (a, &i) in live.iter().enumerate() {
        let mut e = vec![0.0; m];
        e[a] = 1.0;
        let vif = solve(corr.clone(), e).map_or(f64::INFINITY, |x| x[a]);
        if vif.is_nan() || vif.abs() >= 1e8 {
            out.push(i);
        }
    }
    out
}

/// Fits a display model to the captures of the manifest `manifest` (`tensorholo.captures`,
/// docs/CALIBRATION.md; every file checked before the fit): per colour with captures, Levenberg–Marquardt
/// from the ideal display (module docs). A part the captures do not determine (a parameter with no effect on
/// them, or one they cannot tell from others) is named in [`FitReport::warnings`] and kept ideal; colours
/// without captures stay ideal. Nothing is written: the caller writes [`FitReport::model`].
///
/// Errors: [`HoloError::Io`] for an unreadable manifest; [`HoloError::InvalidData`] for one that is not a
/// capture manifest, and for each bad entry, naming it (`captures[3]`) and its file: a missing or unreadable
/// file, a capture of another size than its pattern, patterns of different sizes, a duplicate entry, a
/// non-finite distance, a saturated capture; [`HoloError::InvalidParameter`] for
/// `iterations` outside `1..=500` or a `kernel_side` other than 1, 3 or 5; [`HoloError::ShapeMismatch`] for a
/// truth model or a held per-pixel response of another SLM size; those of the propagation.
pub fn fit(manifest: &std::path::Path, options: &FitOptions) -> Result<FitReport> {
    fit_set(&CaptureSet::read(manifest)?, options)
}

/// [`fit`] on a capture set already read.
pub(crate) fn fit_set(set: &CaptureSet, options: &FitOptions) -> Result<FitReport> {
    if !(1..=500).contains(&options.iterations) {
        return Err(invalid(
            "iterations",
            format!("{}; give 1 to 500", options.iterations),
        ));
    }
    if ![1, 3, 5].contains(&options.kernel_side) {
        return Err(invalid(
            "kernel_side",
            format!("{}; give 1, 3 or 5", options.kernel_side),
        ));
    }
    options.setup.validate()?;
    let (h, w) = set.size;
    if let Some(t) = &options.truth {
        t.check_size(h, w)?;
    }
    for r in options.responses.iter().flatten() {
        if let LutRepresentation::Tiled(t) = r {
            if t.size() != (h, w) {
                return Err(HoloError::ShapeMismatch {
                    what: "the held per-pixel response vs the captures' SLM size".into(),
                    expected: vec![h, w],
                    got: vec![t.size().0, t.size().1],
                });
            }
        }
    }
    let mut report = FitReport {
        model: DisplayModel {
            slm_size: [h, w],
            ..Default::default()
        },
        residuals: Vec::new(),
        warnings: Vec::new(),
        gain: None,
        power: [None; 3],
        truth_errors: Vec::new(),
    };
    let mut residuals = vec![None; set.captures.len()];
    for (colour, key) in COLOUR_KEYS.iter().enumerate() {
        let problem = Problem::new(set, colour, options)?;
        if problem.captures.is_empty() {
            continue;
        }
        let layout = problem.layout;
        let ranges = layout.ranges();
        let held = problem.held_response.is_some();
        let mut free = [true, true, true, !held, layout.kernel > 0, true, true];
        let mut theta = layout.ideal();
        // The gain at the ideal display in closed form, g = Σ I·|U|² / Σ |U|⁴ (at g = 1 the gain's column is
        // |U|², so Σ J·r = Σ|U|⁴ − Σ I·|U|²).
        let only_gain = [true, false, false, false, false, false, false];
        let ideal = problem.evaluate(&theta, &only_gain, true);
        let g = (ideal.jtj[0] - ideal.jtr[0]) / ideal.jtj[0].max(f64::MIN_POSITIVE);
        theta[0] = g.max(1e-12).ln();
        let ideal_rms = problem.evaluate(&theta, &only_gain, false).rms;
        // Which parts do the captures determine? Judged at the ideal display.
        let start = problem.evaluate(&theta, &free, true);
        let idx = layout.free_indices(&free);
        for i in undetermined(&start.jtj, idx.len()) {
            let k = idx[i];
            let p = (0..PARTS.len())
                .find(|&p| ranges[p].contains(&k))
                .expect("in a part");
            if p == GAIN || !free[p] {
                continue;
            }
            free[p] = false;
            report.warnings.push(format!(
                "{}.{}: parameter {} is not determined by the captures; the part is kept ideal",
                key,
                PARTS[p],
                k - ranges[p].start
            ));
        }
        for (p, r) in ranges.iter().enumerate() {
            if !free[p] && p != GAIN {
                for k in r.clone() {
                    theta[k] = layout.ideal()[k];
                }
            }
        }
        let idx = layout.free_indices(&free);
        let mut current = problem.evaluate(&theta, &free, true);
        let mut lambda = 1e-3;
        for _ in 0..options.iterations {
            let np = idx.len();
            let mut a = current.jtj.clone();
            for i in 0..np {
                a[i * np + i] *= 1.0 + lambda;
                a[i * np + i] += 1e-30;
            }
            let b: Vec<f64> = current.jtr.iter().map(|v| -v).collect();
            let Some(step) = solve(a, b) else { break };
            let mut trial = theta.clone();
            for (s, &k) in step.iter().zip(&idx) {
                trial[k] += s;
            }
            let next = problem.evaluate(&trial, &free, true);
            if next.cost.is_finite() && next.cost < current.cost {
                let gain = (current.cost - next.cost) / current.cost.max(f64::MIN_POSITIVE);
                theta = trial;
                current = next;
                lambda = (lambda / 3.0).max(1e-12);
                if gain < 1e-9 {
                    break;
                }
            } else {
                lambda *= 4.0;
                if lambda > 1e12 {
                    break;
                }
            }
        }
        for (k, &ci) in problem.captures.iter().enumerate() {
            residuals[ci] = Some(CaptureResidual {
                capture: set.captures[ci].name.clone(),
                rms: current.rms[k],
                ideal_rms: ideal_rms[k],
            });
        }
        // A gain per colour is the set's gain times that colour's source power (the source's constant).
        report.power[colour] = Some(theta[GAIN].exp());
        let (mut part, _) = layout.display(&theta, &free);
        part.response.clone_from(&problem.held_response);
        if free[RESPONSE] {
            let r = &theta[ranges[RESPONSE].clone()];
            match response_curve(r[0], r[1], r[2]) {
                Ok(c) => part.response = Some(LutRepresentation::Global(c)),
                Err(e) => report.warnings.push(format!(
                    "{}.response: the fitted curve is not a look-up table ({e}); kept ideal",
                    key
                )),
            }
        }
        if let Some([re, im]) = part.zero_order {
            if re.hypot(im) >= 1.0 {
                report
                    .warnings
                    .push(format!("{}.zero_order: fitted |z| ≥ 1; kept ideal", key));
                part.zero_order = None;
            }
        }
        if let Some(truth) = &options.truth {
            report
                .truth_errors
                .extend(part_errors(colour, &part, &truth.colours[colour], (h, w)));
        }
        report.model.colours[colour] = part;
    }
    let brightest = report
        .power
        .iter()
        .flatten()
        .fold(0.0, |a: f64, &b| a.max(b));
    if brightest > 0.0 {
        report.gain = Some(brightest);
        for p in report.power.iter_mut().flatten() {
            *p /= brightest;
        }
    }
    report.residuals = residuals.into_iter().flatten().collect();
    report.model.validate().map_err(|e| {
        HoloError::Internal(format!("the fitted display model does not validate: {e}"))
    })?;
    Ok(report)
}

/// The errors of `fitted` against `truth` for one colour: the source's relative amplitude (largest over the
/// SLM, after both are scaled to mean 1) and phase (largest over the SLM, radians, both means removed), the
/// response (largest phase difference over the codes, radians),
/// the crosstalk (largest weight difference), the zero order (`|Δz|`) and the aberration (largest
/// coefficient difference, radians).
fn part_errors(
    colour: usize,
    fitted: &ColourDisplay,
    truth: &ColourDisplay,
    (h, w): (usize, usize),
) -> Vec<PartError> {
    let name = |p: &str| format!("{}.{p}", COLOUR_KEYS[colour]);
    let mut out = Vec::new();
    let (fr, tr) = (
        ColourRuntime::new(fitted, h, w),
        ColourRuntime::new(truth, h, w),
    );
    let amp = |r: &ColourRuntime| -> Vec<f64> {
        let a: Vec<f64> = (0..h * w)
            .map(|p| r.source.as_ref().map_or(1.0, |s| f64::from(s[p].norm())))
            .collect();
        let mean = a.iter().sum::<f64>() / a.len() as f64;
        a.into_iter().map(|v| v / mean).collect()
    };
    let (fa, ta) = (amp(&fr), amp(&tr));
    out.push(PartError {
        part: name("source.log_amplitude"),
        measure: "largest relative amplitude difference".into(),
        error: fa
            .iter()
            .zip(&ta)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max),
    });
    // The phase's constant is invisible: compare with each map's mean removed.
    let phase = |c: &ColourDisplay| -> Vec<f64> {
        let k = c.source.map_or([0.0; 5], |s| s.phase_rad);
        let p: Vec<f64> = (0..h * w)
            .map(|p| {
                let t = source_terms(normalised(p % w, w), normalised(p / w, h));
                k.iter().zip(&t).map(|(a, b)| a * b).sum()
            })
            .collect();
        let mean = p.iter().sum::<f64>() / p.len() as f64;
        p.into_iter().map(|v| v - mean).collect()
    };
    out.push(PartError {
        part: name("source.phase_rad"),
        measure: "largest phase difference over the SLM (means removed), rad".into(),
        error: phase(fitted)
            .iter()
            .zip(&phase(truth))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max),
    });
    // Every pixel's curve (a per-pixel response), compared code by code without storing them.
    out.push(PartError {
        part: name("response"),
        measure: "largest phase difference over the codes and pixels, rad".into(),
        error: (0..h * w)
            .flat_map(|p| (0..256).map(move |k| (p, k as f32)))
            .map(|(p, v)| f64::from((fr.respond(p, v).0 - tr.respond(p, v).0).abs()))
            .fold(0.0, f64::max),
    });
    let kernel = |c: &ColourDisplay, side: usize| -> Vec<f64> {
        let mut k = vec![0.0; side * side];
        match &c.crosstalk {
            None => k[side * side / 2] = 1.0,
            Some(x) => {
                let (kr, kc) = (x.size[0], x.size[1]);
                for a in 0..kr {
                    for b in 0..kc {
                        let (i, j) = (a + (side - kr) / 2, b + (side - kc) / 2);
                        if i < side && j < side {
                            k[i * side + j] = x.weights[a * kc + b];
                        }
                    }
                }
            }
        }
        k
    };
    let side = [fitted, truth]
        .iter()
        .filter_map(|c| c.crosstalk.as_ref().map(|x| x.size[0].max(x.size[1])))
        .max()
        .unwrap_or(1);
    out.push(PartError {
        part: name("crosstalk"),
        measure: "largest kernel weight difference".into(),
        error: kernel(fitted, side)
            .iter()
            .zip(&kernel(truth, side))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max),
    });
    let z = |c: &ColourDisplay| c.zero_order.unwrap_or([0.0; 2]);
    let (fz, tz) = (z(fitted), z(truth));
    out.push(PartError {
        part: name("zero_order"),
        measure: "|Δz|".into(),
        error: (fz[0] - tz[0]).hypot(fz[1] - tz[1]),
    });
    let a = |c: &ColourDisplay| c.aberration.unwrap_or_default().to_array();
    out.push(PartError {
        part: name("aberration"),
        measure: "largest Zernike coefficient difference, rad".into(),
        error: a(fitted)
            .iter()
            .zip(&a(truth))
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max),
    });
    out
}

#[cfg(test)]
mod tests;
