//! Direct or Winograd, per layer shape and CPU, chosen by measurement.
//!
//! The f32 kernels compute a 3×3 convolution directly (`9·C_in` multiply-adds per output value) or with
//! Winograd's minimal filtering, F(2×2, 3×3) (`4·C_in` plus the tile transforms) or F(4×4, 3×3) (`2.25·C_in`,
//! larger transforms; not bit-identical with direct, within the bounds the kernels crate states). Which is
//! fastest depends on the layer's channels and the CPU: the transforms cost relatively more where `C_in` or
//! `C_out` is small. The first plan of a layer shape `(ISA, C_in, C_out)` in a process times direct and
//! F(2×2, 3×3) on a sample band ([`SAMPLE_ROWS`] × [`SAMPLE_WIDTH`], one thread, best of [`ROUNDS`]
//! alternating runs) and keeps the faster; later plans of that shape, whatever their size or thread count,
//! reuse the choice, so every plan of a process computes a shape the same way. Winograd must beat direct by
//! [`MARGIN`]: a near tie stays direct (the reference path), so that the choice does not flip between
//! processes on noise.
//!
//! F(4×4, 3×3) runs only where pinned: one layer on its own runs 1.19–1.37× faster than F(2×2, 3×3), but its
//! 4-row tiles put every layer of the plan 4 rows behind the one before (strips a tile apart,
//! [`super::strips::Strips`]), and the larger windows cost the 30-layer network more than the kernels save
//! (docs/BENCHMARKS.md, "Winograd F(4×4, 3×3)"): the choice is a whole plan's, which a per-shape timing does
//! not see.
//!
//! `TENSORHOLO_CONV=direct|winograd2x2|winograd4x4` pins the algorithm for every f32 layer (`winograd` is
//! F(2×2, 3×3); `auto`, or unset: measure).

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};
use std::time::Instant;

use tensorholo_kernels::{Algorithm, Conv3x3F32, Inputs, Isa, RowPlanar};

use super::kernel_err;
use crate::error::{invalid, HoloError, Result};
use crate::model::graph::ConvLayer;

/// Rows of the sample band (8 Winograd row pairs; the strips of a plan have up to 16 rows).
const SAMPLE_ROWS: usize = 16;
/// Width of the sample band: the default frame's.
const SAMPLE_WIDTH: usize = 384;
/// Alternating timing rounds; the best of each algorithm counts.
const ROUNDS: usize = 5;
/// How much faster Winograd must run to be chosen (its best time × `MARGIN` < direct's best time).
const MARGIN: f64 = 1.15;

/// The environment variable that pins the algorithm.
pub(crate) const ENV: &str = "TENSORHOLO_CONV";

type Key = (Isa, usize, usize);

fn chosen() -> &'static Mutex<HashMap<Key, Algorithm>> {
    static CHOSEN: OnceLock<Mutex<HashMap<Key, Algorithm>>> = OnceLock::new();
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

/// The planned f32 convolution of `layer` (`relu` after the bias) for `isa`, with the algorithm `conv` or,
/// `None`, the one [`TENSORHOLO_CONV`](ENV) pins or, unset, the one measured faster for its shape (once per
/// process and shape). Errors: the kernels' (as [`Conv3x3F32::new`]), a bad `TENSORHOLO_CONV`.
pub(crate) fn plan_layer(
    layer: &ConvLayer,
    relu: bool,
    isa: Isa,
    conv: Option<Algorithm>,
) -> Result<Conv3x3F32> {
    let plan = |alg| {
        Conv3x3F32::with_algorithm(
            &layer.weights,
            &layer.bias,
            layer.c_in,
            layer.c_out,
            relu,
            isa,
            alg,
        )
        .map_err(kernel_err)
    };
    if let Some(alg) = conv.or(pinned()?) {
        return plan(alg);
    }
    let key = (isa, layer.c_in, layer.c_out);
    let known = chosen().lock().ok().and_then(|m| m.get(&key).copied());
    if let Some(alg) = known {
        return plan(alg);
    }
    let candidates = [plan(Algorithm::Direct)?, plan(Algorithm::Winograd2x2)?];
    let times = best_times(&candidates)?;
    // (A CPU without a vector Winograd row runs the portable one: timed all the same.)
    let chosen_index = usize::from(times[1] * MARGIN < times[0]);
    let alg = candidates[chosen_index].kernel().algorithm;
    log::debug!(
        "conv {}→{} on {}: direct {:.3} ms, winograd2x2 {:.3} ms: {}",
        layer.c_in,
        layer.c_out,
        isa.name(),
        times[0] * 1e3,
        times[1] * 1e3,
        alg.name()
    );
    if let Ok(mut m) = chosen().lock() {
        m.insert(key, alg);
    }
    candidates
        .into_iter()
        .nth(chosen_index)
        .ok_or_else(|| HoloError::Internal("the chosen convolution plan is missing".into()))
}

/// The best of [`ROUNDS`] alternating timings (seconds) of each plan on the sample band (all see the same
/// cache and clock state).
fn best_times<const N: usize>(plans: &[Conv3x3F32; N]) -> Result<[f64; N]> {
    let (c_in, c_out) = (plans[0].c_in(), plans[0].c_out());
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
    let mut best = [f64::INFINITY; N];
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
        let first = plan_layer(&layer, true, isa, None)
            .unwrap()
            .kernel()
            .algorithm;
        let known = chosen().lock().unwrap().get(&(isa, 5, 7)).copied();
        assert_eq!(known, Some(first));
        let again = plan_layer(&layer, true, isa, None)
            .unwrap()
            .kernel()
            .algorithm;
        assert_eq!(again, first);
        // An explicit algorithm overrides the measured one.
        let other = match first {
            Algorithm::Direct => Algorithm::Winograd2x2,
            _ => Algorithm::Direct,
        };
        let pinned = plan_layer(&layer, true, isa, Some(other)).unwrap();
        assert_eq!(pinned.kernel().algorithm, other);
    }
}
