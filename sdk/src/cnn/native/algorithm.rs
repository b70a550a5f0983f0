//! Direct or Winograd, and which kernel row, per f32 layer shape: decided once per session, before any plan is
//! built ([`Rows`], [`decide`]), from the plan table (`cnn/table.rs`, the default), a saved tuning, or a
//! timing on this machine ([`PlanSource::Tune`]).
//!
//! The f32 kernels compute a 3×3 convolution directly (`9·C_in` multiply-adds per output value) or with
//! Winograd's minimal filtering, F(2×2, 3×3) (`4·C_in` plus the tile transforms) or F(4×4, 3×3) (`2.25·C_in`,
//! larger transforms; neither bit-identical with direct, within the bounds the kernels crate states). Which
//! is fastest depends on the layer's channels and the CPU: the transforms cost relatively more where `C_in`
//! or `C_out` is small. So does the row: under AVX-512, a 6-channel layer may run on the 6-channel AVX-512
//! tile, the 8-channel one (a quarter of it wasted) or the 6-channel AVX2 tile.
//!
//! A layer shape is `(C_in, C_out, the algorithms chosen among)`: every algorithm, or one (a pinned
//! [`ConvAlgorithm`], or direct alone for the float layers of an int8 file, whose strips are one row apart).
//! With [`PlanSource::Tune`] every candidate row ([`tensorholo_kernels::registry::f32_rows_of`]) is timed on a
//! sample band ([`SAMPLE_ROWS`] × [`SAMPLE_WIDTH`], one thread, best of [`ROUNDS`] alternating runs), once per
//! shape and session, and the rules of [`pick`] keep:
//! - direct, unless the best Winograd row beats the best direct row by [`MARGIN`];
//! - among Winograd, F(4×4, 3×3) where it beats F(2×2, 3×3) by [`MARGIN_F4`];
//! - within the algorithm, the first row unless another beats it by [`MARGIN`].
//!
//! The plan table's rows are what these rules chose in most of 30–35 processes per shape on a quiet machine.

use std::collections::BTreeMap;
use std::time::Instant;

use tensorholo_kernels::{registry, Algorithm, Conv3x3F32, Inputs, Isa, RowPlanar};

use crate::cnn::options::ConvAlgorithm;
use crate::cnn::saved::SavedRow;
use crate::cnn::table;
use crate::cnn::tuning::PlanSource;
use crate::error::{HoloError, Result};
use crate::model::graph::ConvLayer;
use crate::model::CnnWeights;

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

/// A layer shape: `(C_in, C_out, what its row is chosen among)`.
pub(crate) type RowKey = (usize, usize, ConvAlgorithm);

/// The kernel row of each f32 layer shape of a session's networks, and where each came from.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Rows {
    rows: BTreeMap<RowKey, &'static str>,
    /// How many rows came from a saved tuning and how many from the table.
    pub(crate) saved: usize,
    pub(crate) table: usize,
}

/// No decided rows: every layer on the plan table's row (tests that plan without a session).
#[cfg(test)]
pub(crate) static TABLE_ROWS: Rows = Rows {
    rows: BTreeMap::new(),
    saved: 0,
    table: 0,
};

impl Rows {
    /// The row decided for `key`, if any.
    fn get(&self, key: RowKey) -> Option<&'static str> {
        self.rows.get(&key).copied()
    }

    /// The rows of a list (a session's decisions, [`Rows::saved_rows`]), each where `isa` may run it.
    pub(crate) fn from_saved(isa: Isa, list: &[SavedRow]) -> Self {
        let mut rows = Self::default();
        for r in list {
            let key = (r.c_in, r.c_out, r.algorithms);
            if let Some(name) = known(isa, key, &r.row) {
                rows.rows.insert(key, name);
            }
        }
        rows
    }

    /// Rows for `graph` whose layer shapes cycle through direct, F(2×2, 3×3) and F(4×4, 3×3), each on its
    /// first row (tests: layers of different tile widths in one network).
    #[cfg(test)]
    pub(crate) fn mixed(graph: &CnnWeights, isa: Isa) -> Self {
        let algorithms = [
            Algorithm::Direct,
            Algorithm::Winograd2x2,
            Algorithm::Winograd4x4,
        ];
        let mut rows = Self::default();
        for (i, (key, _)) in shapes(graph, ConvAlgorithm::Auto).into_iter().enumerate() {
            let alg = algorithms[i % algorithms.len()];
            if let Some(k) = registry::f32_rows_of(isa, key.1, alg).next() {
                rows.rows.entry(key).or_insert(k.name);
            }
        }
        rows
    }

    /// The rows as a saved tuning lists them.
    pub(crate) fn saved_rows(&self) -> Vec<SavedRow> {
        self.rows
            .iter()
            .map(|(&(c_in, c_out, algorithms), &row)| SavedRow {
                c_in,
                c_out,
                algorithms,
                row: row.into(),
            })
            .collect()
    }
}

/// The layer shapes of `graph` (an f32 network's every layer under `conv`; an int8 file's float layers,
/// direct only), with the layers.
fn shapes(graph: &CnnWeights, conv: ConvAlgorithm) -> Vec<(RowKey, &ConvLayer)> {
    fn key(l: &ConvLayer, set: ConvAlgorithm) -> (RowKey, &ConvLayer) {
        ((l.c_in, l.c_out, set), l)
    }
    match graph.quant {
        None => graph.layers.iter().map(|l| key(l, conv)).collect(),
        Some(_) => graph
            .float_layers_of_int8()
            .map(|l| key(l, ConvAlgorithm::Direct))
            .collect(),
    }
}

/// The rows of every f32 layer shape of `graphs` under `isa`, as `source` says: the plan table's; a saved
/// tuning's, the table's where it lists none (after checking it was made for `isa`); or timed now.
///
/// Errors: [`HoloError::InvalidParameter`] (`tuning`) for saved plans of another ISA level; the kernels'
/// plan errors while timing.
pub(crate) fn decide(
    graphs: &[&CnnWeights],
    isa: Isa,
    conv: ConvAlgorithm,
    source: &PlanSource,
) -> Result<Rows> {
    if let PlanSource::Saved(p) = source {
        p.check_isa(isa)?;
    }
    let mut rows = Rows::default();
    for graph in graphs {
        for ((c_in, c_out, set), layer) in shapes(graph, conv) {
            let key = (c_in, c_out, set);
            if rows.rows.contains_key(&key) {
                continue;
            }
            let name = match source {
                PlanSource::Table => {
                    rows.table += 1;
                    table::row(isa, c_in, c_out, set).0
                }
                PlanSource::Saved(p) => {
                    match p.row(c_in, c_out, set).and_then(|n| known(isa, key, n)) {
                        Some(name) => {
                            rows.saved += 1;
                            name
                        }
                        None => {
                            rows.table += 1;
                            table::row(isa, c_in, c_out, set).0
                        }
                    }
                }
                PlanSource::Tune => timed_row(layer, isa, set)?,
            };
            rows.rows.insert(key, name);
        }
    }
    Ok(rows)
}

/// The compiled row `name` where `isa` may run it for `key` (a saved row's name as the registry's
/// `&'static str`).
fn known(isa: Isa, (_, c_out, set): RowKey, name: &str) -> Option<&'static str> {
    set.algorithms()
        .iter()
        .flat_map(|&alg| registry::f32_rows_of(isa, c_out, alg))
        .map(|k| k.name)
        .find(|&k| k == name)
}

/// How a layer's row is picked ([`plan_layer`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Choice<'a> {
    /// The row `rows` holds for the layer's shape among these algorithms (the table's where it holds none).
    Rows(&'a Rows, ConvAlgorithm),
    /// This algorithm on its first row (tests that compare algorithms).
    #[cfg(test)]
    Exact(Algorithm),
}

#[cfg(test)]
impl Choice<'static> {
    /// `conv`'s first row in every layer, or the plan table's row among every algorithm for `None` (tests).
    pub(crate) fn table_or(conv: Option<Algorithm>) -> Self {
        conv.map_or(
            Choice::Rows(&TABLE_ROWS, ConvAlgorithm::Auto),
            Choice::Exact,
        )
    }
}

/// The planned f32 convolution of `layer` (`relu` after the bias) for `isa`, on the row `choice` gives.
/// Errors: the kernels' (as [`Conv3x3F32::new`]).
pub(crate) fn plan_layer(
    layer: &ConvLayer,
    relu: bool,
    isa: Isa,
    choice: Choice<'_>,
) -> Result<Conv3x3F32> {
    let name = match choice {
        #[cfg(test)]
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
            .map_err(HoloError::from)
        }
        Choice::Rows(rows, set) => rows
            .get((layer.c_in, layer.c_out, set))
            .unwrap_or_else(|| table::row(isa, layer.c_in, layer.c_out, set).0),
    };
    Conv3x3F32::with_kernel(
        &layer.weights,
        &layer.bias,
        layer.c_in,
        layer.c_out,
        relu,
        name,
    )
    .map_err(HoloError::from)
}

/// The row [`pick`] keeps among every row of `set`'s algorithms for `layer`, timed on the sample band.
fn timed_row(layer: &ConvLayer, isa: Isa, set: ConvAlgorithm) -> Result<&'static str> {
    let mut candidates = Vec::new();
    for &alg in set.algorithms() {
        for info in registry::f32_rows_of(isa, layer.c_out, alg) {
            candidates.push(
                Conv3x3F32::with_kernel(
                    &layer.weights,
                    &layer.bias,
                    layer.c_in,
                    layer.c_out,
                    true,
                    info.name,
                )
                .map_err(HoloError::from)?,
            );
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
    Ok(candidates[best].kernel().name)
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
    let a = RowPlanar::from_planar(&values, c_in, h, w, None).map_err(HoloError::from)?;
    let mut out = RowPlanar::new(c_out, h, w).map_err(HoloError::from)?;
    // One untimed run each: the scratch and the packed weights in cache.
    for p in plans {
        p.run(Inputs::new(&a), &mut out, 0..h)
            .map_err(HoloError::from)?;
    }
    let mut best = vec![f64::INFINITY; plans.len()];
    for _ in 0..ROUNDS {
        for (b, p) in best.iter_mut().zip(plans) {
            let t = Instant::now();
            p.run(Inputs::new(&a), &mut out, 0..h)
                .map_err(HoloError::from)?;
            *b = b.min(t.elapsed().as_secs_f64());
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::cnn::saved::SavedPlans;

    fn graph(shapes: &[(usize, usize)]) -> CnnWeights {
        CnnWeights {
            in_channels: shapes[0].0,
            layers: shapes
                .iter()
                .map(|&(c_in, c_out)| ConvLayer {
                    c_in,
                    c_out,
                    weights: vec![0.25; c_out * c_in * 9],
                    bias: vec![0.5; c_out],
                })
                .collect(),
            input_offset: 0.0,
            output: crate::model::graph::CnnOutput::Heads {
                amplitude_scale: 1.0,
                phase_scale: 0.5,
            },
            quant: None,
        }
    }

    #[test]
    fn the_table_decides_each_shape_once_and_the_same_every_time() {
        let isa = Isa::detect();
        let g = graph(&[(4, 24), (24, 24), (24, 24), (28, 6)]);
        let a = decide(&[&g], isa, ConvAlgorithm::Auto, &PlanSource::Table).unwrap();
        let b = decide(&[&g], isa, ConvAlgorithm::Auto, &PlanSource::Table).unwrap();
        assert_eq!(a, b);
        assert_eq!((a.table, a.saved), (3, 0));
        for (key, row) in &a.rows {
            assert_eq!(*row, table::row(isa, key.0, key.1, key.2).0);
        }
        // A pinned algorithm: every row of it.
        let d = decide(&[&g], isa, ConvAlgorithm::Direct, &PlanSource::Table).unwrap();
        for row in d.saved_rows() {
            let k = registry::f32_kernels().find(|k| k.name == row.row).unwrap();
            assert_eq!(k.algorithm, Algorithm::Direct, "{}", row.row);
            assert_eq!(row.algorithms, ConvAlgorithm::Direct);
        }
    }

    #[test]
    fn saved_rows_are_used_and_the_table_fills_the_rest() {
        let isa = Isa::detect();
        let g = graph(&[(4, 24), (24, 24), (28, 6)]);
        // Save a row the table would not choose for 24→24: the direct one.
        let direct = registry::f32_rows_of(isa, 24, Algorithm::Direct)
            .next()
            .unwrap();
        let mut p = SavedPlans::new(isa.name(), "test");
        p.rows.push(SavedRow {
            c_in: 24,
            c_out: 24,
            algorithms: ConvAlgorithm::Auto,
            row: direct.name.into(),
        });
        let source = PlanSource::Saved(Arc::new(p.clone()));
        let rows = decide(&[&g], isa, ConvAlgorithm::Auto, &source).unwrap();
        assert_eq!(rows.get((24, 24, ConvAlgorithm::Auto)), Some(direct.name));
        assert_eq!((rows.saved, rows.table), (1, 2));
        let plan = plan_layer(
            &g.layers[1],
            true,
            isa,
            Choice::Rows(&rows, ConvAlgorithm::Auto),
        )
        .unwrap();
        assert_eq!(plan.kernel().name, direct.name);
        // Made for another ISA level: refused, naming both.
        let other = if isa == Isa::Scalar { "avx2" } else { "scalar" };
        p.isa = other.into();
        let e = decide(
            &[&g],
            isa,
            ConvAlgorithm::Auto,
            &PlanSource::Saved(Arc::new(p)),
        )
        .unwrap_err();
        assert!(
            e.to_string().contains(other) && e.to_string().contains(isa.name()),
            "{e}"
        );
    }

    #[test]
    fn tuning_times_the_rows_of_the_shape_and_keeps_one_of_them() {
        let isa = Isa::detect();
        let g = graph(&[(5, 7), (7, 7)]);
        let rows = decide(&[&g], isa, ConvAlgorithm::Winograd4x4, &PlanSource::Tune).unwrap();
        for row in rows.saved_rows() {
            assert!(
                registry::f32_rows_of(isa, row.c_out, Algorithm::Winograd4x4)
                    .any(|k| k.name == row.row),
                "{}",
                row.row
            );
        }
        assert_eq!(rows.saved_rows().len(), 2);
    }

    #[test]
    fn the_margins_decide_between_algorithms_and_rows() {
        // Rows of a 6-channel layer under the active ISA: direct, F(2×2, 3×3) and F(4×4, 3×3), with made-up
        // times, so the rules are checked whatever this CPU measures.
        let isa = Isa::detect();
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
