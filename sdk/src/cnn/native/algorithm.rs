//! Direct or Winograd, and which kernel row, per layer shape and CPU, chosen by measurement.
//!
//! The f32 kernels compute a 3×3 convolution directly (`9·C_in` multiply-adds per output value) or with
//! Winograd's minimal filtering, F(2×2, 3×3) (`4·C_in` plus the tile transforms) or F(4×4, 3×3) (`2.25·C_in`,
//! larger transforms; neither bit-identical with direct, within the bounds the kernels crate states). Which
//! is fastest depends on the layer's channels and the CPU: the transforms cost relatively more where `C_in`
//! or `C_out` is small. So does the row: under AVX-512, a 6-channel layer may run on the 6-channel AVX-512
//! tile, the 8-channel one (a quarter of it wasted) or the 6-channel AVX2 tile, and which wins can differ
//! between CPUs (of the last two, the AVX2 tile on Zen 4, the AVX-512 one on Zen 5: docs/BENCHMARKS.md).
//!
//! The first plan of a layer shape `(ISA, C_in, C_out)` in a process times every candidate row
//! ([`tensorholo_kernels::registry::f32_rows_of`]: each algorithm's rows under the ISA) on a sample band
//! ([`SAMPLE_ROWS`] × [`SAMPLE_WIDTH`], one thread, best of [`ROUNDS`] alternating runs) and keeps:
//! - direct, unless the best Winograd row beats the best direct row by [`MARGIN`] (a near tie stays direct,
//!   the reference path, so that the choice does not flip between processes on noise);
//! - among Winograd, F(4×4, 3×3) where it beats F(2×2, 3×3) by [`MARGIN_F4`] (it rounds more, and a plan with
//!   an F(4×4, 3×3) layer puts every layer 4 rows behind the one before: [`super::strips::Strips`]);
//! - within the algorithm, the first row unless another beats it by [`MARGIN`].
//!
//! Later plans of that shape, whatever their size or thread count, reuse the choice, so every plan of a
//! process computes a shape the same way.
//!
//! `TENSORHOLO_CONV=direct|winograd2x2|winograd4x4` pins the algorithm for every f32 layer (`winograd` is
//! F(2×2, 3×3); `auto`, or unset: measure); the row within it is still timed.

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};
use std::time::Instant;

use tensorholo_kernels::{registry, Algorithm, Conv3x3F32, Inputs, Isa, RowPlanar};

use super::kernel_err;
use crate::error::{invalid, HoloError, Result};
use crate::model::graph::ConvLayer;

/// Rows of the sample band (8 Winograd row pairs; the strips of a plan have up to 16 rows).
const SAMPLE_ROWS: usize = 16;
/// Width of the sample band: the default frame's.
const SAMPLE_WIDTH: usize = 384;
/// Alternating timing rounds; the best of each algorithm counts.
const ROUNDS: usize = 5;
/// How much faster a Winograd row must run than the best direct row to be chosen, and another row of an
/// algorithm than its first.
const MARGIN: f64 = 1.15;
/// How much faster F(4×4, 3×3) must run than F(2×2, 3×3) to be chosen.
const MARGIN_F4: f64 = 1.1;

/// The environment variable that pins the algorithm.
pub(crate) const ENV: &str = "TENSORHOLO_CONV";

/// A layer shape and the algorithms its timing chose among.
type Key = (Isa, usize, usize, Vec<Algorithm>);

fn chosen() -> &'static Mutex<HashMap<Key, &'static str>> {
    static CHOSEN: OnceLock<Mutex<HashMap<Key, &'static str>>> = OnceLock::new();
    CHOSEN.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The algorithm `TENSORHOLO_CONV` pins (`None`: unset or `auto`). Errors: [`HoloError::InvalidParameter`]
/// (crate::error::HoloError) for another value.
pub(crate) fn pinned() -> Result<Option<Algorithm>> {
    parse(std::env::var(ENV).ok().as_deref())
}

/// A `TENSORHOLO_CONV` value (`None`: unset). Errors: as [`pinned`].
fn parse(value: Option<&str>) -> Result<Option<Algorithm>> {
    match value.map(str::trim) {
        None | Some("") | Some("auto") => Ok(None),
        Some("direct") => Ok(Some(Algorithm::Direct)),
        Some("winograd") | Some("winograd2x2") => Ok(Some(Algorithm::Winograd2x2)),
        Some("winograd4x4") => Ok(Some(Algorithm::Winograd4x4)),
        Some(other) => Err(invalid(
            "TENSORHOLO_CONV",
            format!("`{other}` is not one of direct, winograd2x2 (or winograd), winograd4x4, auto"),
        )),
    }
}

/// How a layer's algorithm is picked ([`plan_layer`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Choice<'a> {
    /// The one [`TENSORHOLO_CONV`](ENV) pins or, unset, the fastest of every algorithm (measured).
    Measure,
    /// The fastest of these algorithms (measured; `TENSORHOLO_CONV` ignored): e.g. direct alone for the
    /// float layers of the int8 plan, whose strips are one row apart.
    Among(&'a [Algorithm]),
    /// This algorithm on its first row, not timed (tests that compare algorithms).
    Exact(Algorithm),
}

/// The planned f32 convolution of `layer` (`relu` after the bias) for `isa`, its algorithm and row picked as
/// `choice` says (measured once per process, shape and set of algorithms). Errors: the kernels' (as
/// [`Conv3x3F32::new`]), a bad `TENSORHOLO_CONV`.
pub(crate) fn plan_layer(
    layer: &ConvLayer,
    relu: bool,
    isa: Isa,
    choice: Choice<'_>,
) -> Result<Conv3x3F32> {
    let row = |name: &str| {
        Conv3x3F32::with_kernel(
            &layer.weights,
            &layer.bias,
            layer.c_in,
            layer.c_out,
            relu,
            name,
        )
        .map_err(kernel_err)
    };
    let all = [
        Algorithm::Direct,
        Algorithm::Winograd2x2,
        Algorithm::Winograd4x4,
    ];
    let pin;
    let algorithms: &[Algorithm] = match choice {
        Choice::Exact(alg) => {
            return Conv3x3F32::with_algorithm(
                &layer.weights,
                &layer.bias,
                layer.c_in,
                layer.c_out,
                relu,
                isa,
                alg,
            )
            .map_err(kernel_err)
        }
        Choice::Among(algs) => algs,
        Choice::Measure => match pinned()? {
            Some(alg) => {
                pin = [alg];
                &pin
            }
            None => &all,
        },
    };
    let key = (isa, layer.c_in, layer.c_out, algorithms.to_vec());
    let known = chosen().lock().ok().and_then(|m| m.get(&key).copied());
    if let Some(name) = known {
        return row(name);
    }
    let mut candidates = Vec::new();
    for &alg in algorithms {
        for info in registry::f32_rows_of(isa, layer.c_out, alg) {
            candidates.push(row(info.name)?);
        }
    }
    let times = best_times(&candidates)?;
    let best = pick(&candidates, &times)
        .ok_or_else(|| HoloError::Internal("no convolution row to choose from".into()))?;
    log::debug!(
        "conv {}→{} on {}: {}: {}",
        layer.c_in,
        layer.c_out,
        isa.name(),
        candidates
            .iter()
            .zip(&times)
            .map(|(c, t)| format!("{} {:.3} ms", c.kernel().name, t * 1e3))
            .collect::<Vec<_>>()
            .join(", "),
        candidates[best].kernel().name
    );
    let name = candidates[best].kernel().name;
    if let Ok(mut m) = chosen().lock() {
        m.insert(key, name);
    }
    candidates
        .into_iter()
        .nth(best)
        .ok_or_else(|| HoloError::Internal("the chosen convolution plan is missing".into()))
}

/// The index of the row to keep among `plans` timed `times` (seconds; the rules in the module docs), `None`
/// for no plans.
fn pick(plans: &[Conv3x3F32], times: &[f64]) -> Option<usize> {
    // Per algorithm: its first row, unless another is MARGIN faster.
    let best_of = |alg: Algorithm| -> Option<(usize, f64)> {
        let mut rows = plans
            .iter()
            .zip(times)
            .enumerate()
            .filter(|(_, (p, _))| p.kernel().algorithm == alg)
            .map(|(i, (_, &t))| (i, t));
        let first = rows.next()?;
        Some(rows.fold(
            first,
            |keep, (i, t)| {
                if t * MARGIN < keep.1 {
                    (i, t)
                } else {
                    keep
                }
            },
        ))
    };
    let direct = best_of(Algorithm::Direct);
    let winograd = match (
        best_of(Algorithm::Winograd2x2),
        best_of(Algorithm::Winograd4x4),
    ) {
        (Some(f2), Some(f4)) => Some(if f4.1 * MARGIN_F4 < f2.1 { f4 } else { f2 }),
        (f2, f4) => f2.or(f4),
    };
    match (direct, winograd) {
        (Some(d), Some(w)) => Some(if w.1 * MARGIN < d.1 { w.0 } else { d.0 }),
        (d, w) => d.or(w).map(|(i, _)| i),
    }
}

/// The best of [`ROUNDS`] alternating timings (seconds) of each plan on the sample band (all see the same
/// cache and clock state).
fn best_times(plans: &[Conv3x3F32]) -> Result<Vec<f64>> {
    let Some(first) = plans.first() else {
        return Ok(Vec::new());
    };
    let (c_in, c_out) = (first.c_in(), first.c_out());
    let (h, w) = (SAMPLE_ROWS, SAMPLE_WIDTH);
    // Deterministic values in [−0.5, 0.5): the timing does not depend on them, only the work.
    let values: Vec<f32> = (0..c_in * h * w)
        .map(|i| ((i * 7919) % 1000) as f32 / 1000.0 - 0.5)
        .collect();
    let a = RowPlanar::from_planar(&values, c_in, h, w, None).map_err(kernel_err)?;
    let mut out = RowPlanar::new(c_out, h, w).map_err(kernel_err)?;
    // One untimed run each: the scratch and the packed weights in cache.
    for p in plans {
        p.run(Inputs::new(&a), &mut out, 0..h).map_err(kernel_err)?;
    }
    let mut best = vec![f64::INFINITY; plans.len()];
    for _ in 0..ROUNDS {
        for (b, p) in best.iter_mut().zip(plans) {
            let t = Instant::now();
            p.run(Inputs::new(&a), &mut out, 0..h).map_err(kernel_err)?;
            *b = b.min(t.elapsed().as_secs_f64());
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pin_names_an_algorithm_or_is_refused() {
        assert_eq!(parse(None).unwrap(), None);
        assert_eq!(parse(Some(" auto")).unwrap(), None);
        assert_eq!(parse(Some("direct")).unwrap(), Some(Algorithm::Direct));
        assert_eq!(
            parse(Some("winograd")).unwrap(),
            Some(Algorithm::Winograd2x2)
        );
        assert_eq!(
            parse(Some("winograd2x2")).unwrap(),
            Some(Algorithm::Winograd2x2)
        );
        assert_eq!(
            parse(Some("winograd4x4")).unwrap(),
            Some(Algorithm::Winograd4x4)
        );
        let e = parse(Some("fft")).unwrap_err();
        assert!(matches!(
            e,
            HoloError::InvalidParameter {
                name: "TENSORHOLO_CONV",
                ..
            }
        ));
        assert!(e.to_string().contains("`fft`"), "{e}");
    }

    #[test]
    fn a_measured_choice_is_kept_for_the_shape() {
        // The second plan of a shape reuses the first one's choice (no second measurement), whatever it was.
        if pinned().unwrap().is_some() {
            println!("SKIPPED: TENSORHOLO_CONV pins the algorithm");
            return;
        }
        let layer = ConvLayer {
            c_in: 5,
            c_out: 7,
            weights: vec![0.25; 7 * 5 * 9],
            bias: vec![0.5; 7],
        };
        let isa = Isa::active().unwrap();
        let first = plan_layer(&layer, true, isa, Choice::Measure)
            .unwrap()
            .kernel()
            .name;
        let all = vec![
            Algorithm::Direct,
            Algorithm::Winograd2x2,
            Algorithm::Winograd4x4,
        ];
        let known = chosen().lock().unwrap().get(&(isa, 5, 7, all)).copied();
        assert_eq!(known, Some(first));
        let again = plan_layer(&layer, true, isa, Choice::Measure)
            .unwrap()
            .kernel()
            .name;
        assert_eq!(again, first);
        // A choice among direct rows only stays direct; an exact algorithm overrides the measured one.
        let direct = plan_layer(&layer, true, isa, Choice::Among(&[Algorithm::Direct])).unwrap();
        assert_eq!(direct.kernel().algorithm, Algorithm::Direct);
        for alg in [Algorithm::Direct, Algorithm::Winograd4x4] {
            let exact = plan_layer(&layer, true, isa, Choice::Exact(alg)).unwrap();
            assert_eq!(exact.kernel().algorithm, alg);
        }
    }

    #[test]
    fn the_margins_decide_between_algorithms_and_rows() {
        // Rows of a 6-channel layer under the active ISA: direct, F(2×2, 3×3) and F(4×4, 3×3), with made-up
        // times, so the rules are checked whatever this CPU measures.
        let isa = Isa::active().unwrap();
        let plan = |alg| {
            Conv3x3F32::with_algorithm(&[0.5; 6 * 4 * 9], &[0.0; 6], 4, 6, true, isa, alg).unwrap()
        };
        let plans = [
            plan(Algorithm::Direct),
            plan(Algorithm::Winograd2x2),
            plan(Algorithm::Winograd4x4),
            plan(Algorithm::Direct),
        ];
        let at = |t: [f64; 4]| pick(&plans, &t).unwrap();
        // Winograd 1.1× faster than direct: direct stays (MARGIN 1.15).
        assert_eq!(at([1.1, 1.0, 1.0, 2.0]), 0);
        // 1.2×: F(2×2, 3×3), since F(4×4, 3×3) is not MARGIN_F4 faster than it.
        assert_eq!(at([1.2, 1.0, 0.95, 2.0]), 1);
        // F(4×4, 3×3) 1.2× faster than F(2×2, 3×3): F(4×4, 3×3).
        assert_eq!(at([1.2, 1.0, 0.8, 2.0]), 2);
        // Direct's second row: only where MARGIN faster than its first.
        assert_eq!(at([1.0, 5.0, 5.0, 0.9]), 0);
        assert_eq!(at([1.0, 5.0, 5.0, 0.8]), 3);
        // The margins compare against the best direct row (the second here).
        assert_eq!(at([2.0, 1.0, 1.0, 0.8]), 3);
        assert_eq!(pick(&[], &[]), None);
    }
}
