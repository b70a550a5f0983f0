//! What a session asks of its CNN plans and what it got: the request ([`PlanRequest`]: engine options from
//! `options.rs` and where the decisions come from, [`PlanSource`]) and the report ([`PlanReport`]).
//!
//! By default ([`PlanSource::Table`]) nothing is timed: the plans are a function of the build, the CPU's
//! features, the layer shapes, the size and the thread count (the plan table, `cnn/table.rs`), so that the
//! same command gives the same bits in every process, whatever else the machine is doing. Timing happens only
//! when asked ([`PlanSource::Tune`]): each engine times its own candidates on the machine, at the session's
//! resolution (`cnn/native/`: each f32 layer shape's kernel rows, then thread counts; `cnn/tract/`, cargo
//! feature `tract`: layouts × thread counts), and `cnn/select.rs` compares the engines. A tuning's result
//! can be saved ([`PlanReport::saved`], [`SavedPlans`]) and given to later sessions
//! ([`PlanSource::Saved`]), which then make the same plans without timing.
//!
//! This module also holds what every engine's timing shares: the candidates' resolution and thread counts,
//! and the timing rule ([`fastest_run`]).

use std::sync::Arc;

use super::options::{default_threads, CnnEngine, CnnLayout, CnnOptions, MAX_CNN_THREADS};
use super::saved::{SavedPlans, SavedRow, SavedSession};
use crate::error::Result;

/// Frames above this many pixels are timed on a full-width strip of about this many pixels (at least
/// [`TUNE_MIN_ROWS`] rows) instead of the whole frame: the convolutions' cost is linear in the rows, and the
/// layouts' relative speed depends on the row width, which the strip keeps. 1920×1080 is timed on
/// 1920×34, 384×384 on 384×170. A small strip also keeps the timing's memory small: a 384² CPU session
/// (`holo render --backend cpu`) peaked at 95 MiB with whole-frame timing runs, at 60 MiB with this strip
/// (53–55 MiB with the native engine alone, no timing).
pub(crate) const TUNE_PIXELS: usize = 64 * 1024;
/// The fewest rows of a timing strip ([`TUNE_PIXELS`]).
pub(crate) const TUNE_MIN_ROWS: usize = 32;
/// A candidate whose first run takes less than this (seconds) is run twice more and its fastest run kept.
const REPEAT_BELOW_S: f64 = 0.25;

/// How much slower than the best engine timed so far an engine's likeliest candidate may be before its
/// other candidates are left untimed ([`crate::cnn::CnnEngine::Auto`]). Tract's candidates differ from one
/// another by less than this (layouts by about 10 %, its thread counts: the likeliest is the most threads),
/// so a first candidate 1.5× slower than the native engine cannot plausibly win with another.
#[cfg(feature = "tract")]
pub(crate) const PLAUSIBLE_FACTOR: f64 = 1.5;

/// How a candidate left untimed starts its `skipped` reason: by tract's early stop ([`PLAUSIBLE_FACTOR`]), or
/// an engine [`crate::cnn::CnnEngine::Auto`] did not time at all (another outruns it on this CPU).
pub(crate) const NOT_TIMED: &str = "not timed";

/// Where a session's CNN plans come from ([`PlanRequest::source`]).
#[derive(Debug, Clone, PartialEq, Eq, Hash, Default)]
pub enum PlanSource {
    /// The plan table (the default): the engine, tract's layout, each f32 layer's kernel row and the threads
    /// follow from the build, the CPU's features, the shapes and the size (`cnn/table.rs`, made from
    /// benchmarks); nothing is timed, and every process gives the same bits.
    #[default]
    Table,
    /// Time the candidates on this machine now (the engines, tract's layouts, each f32 layer shape's kernel
    /// rows, 1, half and all cores) and keep the fastest. Where two candidates are close, or the machine is
    /// busy, two processes can choose differently, and their last bits differ; save the result
    /// ([`PlanReport::saved`]) to make later runs repeat it.
    Tune,
    /// The choices of a saved tuning ([`SavedPlans`]), the table's where it has none (the report says
    /// which); nothing is timed. Refused at session creation when made for another kernel ISA level.
    Saved(Arc<SavedPlans>),
}

impl PlanSource {
    /// Short name: `table`, `tune`, `saved`.
    pub(crate) fn name(&self) -> &'static str {
        match self {
            Self::Table => "table",
            Self::Tune => "tune",
            Self::Saved(_) => "saved",
        }
    }

    /// Whether candidates are timed.
    pub fn tunes(&self) -> bool {
        matches!(self, Self::Tune)
    }

    /// The saved plans, if any.
    pub fn saved(&self) -> Option<&SavedPlans> {
        match self {
            Self::Saved(p) => Some(p),
            _ => None,
        }
    }
}

impl serde::Serialize for PlanSource {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// What a session's CNN plans are made from: each option's `Auto` is decided by `source` (the plan table by
/// default, a timing, or a saved tuning); a concrete value is used as given.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Default, serde::Serialize)]
pub struct PlanRequest {
    /// The caller's options, whole ([`CnnOptions`]: engine, layout, threads, algorithm, strips, slabs,
    /// instruction set; `tune` is read into `source`). Flat in reports: `request.strip_rows`, `request.isa`, ….
    #[serde(flatten)]
    pub cnn: CnnOptions,
    /// Where the decisions come from.
    pub source: PlanSource,
}

/// How a session's plans were decided ([`PlanReport::source`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PlanOrigin {
    /// The plan table, nothing timed.
    Table,
    /// A saved tuning ([`PlanSource::Saved`]), the table for what it lacks.
    Saved,
    /// Timed in this session ([`PlanSource::Tune`]).
    Tuned,
}

impl PlanOrigin {
    /// Short name: `table`, `saved`, `tuned`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Table => "table",
            Self::Saved => "saved",
            Self::Tuned => "tuned",
        }
    }
}

/// One candidate's timing.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PlanTiming {
    /// The engine that ran it ([`CnnEngine::Tract`] or [`CnnEngine::Native`]).
    pub engine: CnnEngine,
    /// Its layout.
    pub layout: CnnLayout,
    /// Its threads (`None`: tract's process-wide executor).
    pub threads: Option<usize>,
    /// Fastest wall-clock seconds of one run at the timed resolution; `None` if the candidate cannot run
    /// (see `skipped`).
    pub seconds: Option<f64>,
    /// Why the candidate was not timed (e.g. tract cannot move this graph channels-last).
    pub skipped: Option<String>,
}

/// What a session's engine choice ([`CnnOptions::engine`](crate::cnn::CnnOptions::engine)) and the engine's own
/// choices (tract's layout and threads, the native engine's rows and threads) were, why, and where they came
/// from ([`PlanReport::source`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PlanReport {
    /// `[height, width]` the plan runs at.
    pub resolution: [usize; 2],
    /// What was asked for.
    pub request: PlanRequest,
    /// The engine that runs the CNNs on the CPU ([`CnnEngine::Tract`] or [`CnnEngine::Native`]).
    pub engine: CnnEngine,
    /// Why that engine (e.g. "faster on this CPU", "requested", or why the native engine cannot run the
    /// file).
    pub engine_reason: String,
    /// The native engine's kernel row and the CPU features it uses (e.g. `conv3x3.f32.6x2.avx2`); `None`
    /// for tract.
    pub kernel: Option<String>,
    /// The chosen tract layout (concrete); the native engine reports [`CnnLayout::ChannelsFirst`] (its
    /// buffers are channel-major within each row).
    pub layout: CnnLayout,
    /// The chosen thread count (`None`: tract's process-wide executor).
    pub threads: Option<usize>,
    /// Whether more than one candidate was timed.
    pub autotuned: bool,
    /// `[height, width]` the candidates were timed at (the resolution, or a full-width strip of it).
    pub timed_resolution: [usize; 2],
    /// Every candidate, in the order timed (empty when only one candidate existed).
    pub candidates: Vec<PlanTiming>,
    /// Wall-clock seconds the tuning took (plans and timed runs), 0 when nothing was timed or the result came
    /// from the model's cache.
    pub tuning_s: f64,
    /// Where the decisions came from: the plan table, a saved tuning or a timing in this session.
    pub source: PlanOrigin,
    /// The same in words: with a saved tuning, what it decided and what the table filled in.
    pub source_detail: String,
    /// The hologram CNN as saved plans name it (`network_key`).
    pub network: String,
    /// The kernel ISA level of the native engine on this CPU (`avx512vnni`, `neondot`, …), what a saved tuning
    /// is made for.
    pub isa: String,
    /// The kernel row of each f32 layer shape of the native engine's plans (empty for tract).
    pub rows: Vec<SavedRow>,
}

impl PlanReport {
    /// These plans as a record to save ([`SavedPlans::to_json`]) and give to later sessions
    /// ([`PlanSource::Saved`]): this session's engine, layout and threads, and its layers' rows.
    pub fn saved(&self) -> SavedPlans {
        let origin = format!(
            "{} by tensorholo {} ({} threads available)",
            match self.source {
                PlanOrigin::Table => "the plan table",
                PlanOrigin::Saved => "saved plans",
                PlanOrigin::Tuned => "tuned",
            },
            env!("CARGO_PKG_VERSION"),
            default_threads()
        );
        let mut plans = SavedPlans::new(&self.isa, &origin);
        plans.sessions.push(SavedSession {
            network: self.network.clone(),
            resolution: self.resolution,
            engine: self.engine,
            layout: self.layout,
            threads: self.threads,
        });
        plans.rows = self.rows.clone();
        plans
    }
}

/// The thread counts [`ThreadCount::Auto`](crate::cnn::ThreadCount::Auto) times with [`PlanSource::Tune`]: 1, half the available cores and
/// all of them (deduplicated; `std::thread::available_parallelism`, at most [`MAX_CNN_THREADS`]).
pub fn auto_thread_candidates() -> Vec<usize> {
    let n = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .min(MAX_CNN_THREADS);
    let mut v = vec![1, n / 2, n];
    v.retain(|&t| t >= 1);
    v.sort_unstable();
    v.dedup();
    v
}

/// The `[height, width]` candidates are timed at for a `height × width` session ([`TUNE_PIXELS`]).
pub(crate) fn timing_resolution(height: usize, width: usize) -> [usize; 2] {
    if height.saturating_mul(width) <= TUNE_PIXELS {
        return [height, width];
    }
    let rows = (TUNE_PIXELS / width.max(1)).max(TUNE_MIN_ROWS).min(height);
    [rows, width]
}

/// The timing rule of every autotuner (tract's layouts and threads, the native engine's threads): one run of `run` (which returns its seconds), or the fastest of three when the first is
/// under [`REPEAT_BELOW_S`].
pub(crate) fn fastest_run(mut run: impl FnMut() -> Result<f64>) -> Result<f64> {
    let mut best = run()?;
    if best < REPEAT_BELOW_S {
        for _ in 0..2 {
            best = best.min(run()?);
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cnn::ThreadCount;

    #[test]
    fn strips_keep_the_width_and_the_pixel_budget() {
        assert_eq!(timing_resolution(256, 256), [256, 256]);
        assert_eq!(timing_resolution(384, 384), [170, 384]);
        assert_eq!(timing_resolution(1080, 1920), [34, 1920]);
        // Very wide frames keep at least TUNE_MIN_ROWS rows, never more than the frame has.
        assert_eq!(timing_resolution(100, 100_000), [32, 100_000]);
        assert_eq!(timing_resolution(20, 100_000), [20, 100_000]);
        let [h, w] = timing_resolution(4000, 1000);
        assert_eq!(w, 1000);
        assert!(h * w <= TUNE_PIXELS && h * w > TUNE_PIXELS - 1000);
    }

    #[test]
    fn thread_candidates_start_at_one_and_are_unique() {
        let v = auto_thread_candidates();
        assert_eq!(v[0], 1);
        assert!(v.windows(2).all(|w| w[0] < w[1]));
        assert!(v.iter().all(|&t| t <= MAX_CNN_THREADS));
        assert_eq!(ThreadCount::from_count(0), ThreadCount::Auto);
        assert_eq!(ThreadCount::from_count(3), ThreadCount::Fixed(3));
    }
}
