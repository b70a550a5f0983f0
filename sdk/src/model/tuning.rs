//! Autotuned CNN plans: which tract plan is fastest depends on the CPU (channels-first won at large frames on
//! one 2-core Xeon, channels-last was 2.2× faster at 384×384 on another; a phone is yet another CPU), so the
//! candidates are timed on the machine, at the session's resolution, when a session is created
//! (`docs/BENCHMARKS.md`, "Autotuned plans").
//!
//! This module holds what every engine's tuning shares: the request ([`PlanRequest`], [`ThreadCount`]), the
//! report ([`PlanReport`], [`PlanTiming`]), the candidates' resolution and thread counts, and the timing rule.
//! With the `tract` feature, `HologramModel::tuned_plan` (`model/tract.rs`) times every tract candidate
//! (layout × thread count) of a [`PlanRequest`], keeps the fastest, and caches the report in the model per
//! resolution and request, so a second session of the same size starts at once; the native engine's thread
//! count is timed in `cnn/select.rs`.

use super::{CnnEngine, CnnLayout, MAX_CNN_THREADS};
use crate::error::Result;

/// Frames above this many pixels are timed on a full-width strip of about this many pixels (at least
/// [`TUNE_MIN_ROWS`] rows) instead of the whole frame: the convolutions' cost is linear in the rows, and the
/// layouts' relative speed depends on the row width, which the strip keeps. 1920×1080 is timed on
/// 1920×34, 384×384 on 384×170. A small strip also keeps the timing's memory small: a 384² CPU session
/// (`holo render --backend cpu`) peaked at 95 MiB with whole-frame timing runs, at 60 MiB with this strip
/// (53–55 MiB with the native engine alone, no timing).
pub const TUNE_PIXELS: usize = 64 * 1024;
/// The fewest rows of a timing strip ([`TUNE_PIXELS`]).
pub const TUNE_MIN_ROWS: usize = 32;
/// A candidate whose first run takes less than this (seconds) is run twice more and its fastest run kept.
const REPEAT_BELOW_S: f64 = 0.25;

/// How many threads a CNN plan uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ThreadCount {
    /// Time [`auto_thread_candidates`] and keep the fastest.
    #[default]
    Auto,
    /// Exactly this many threads (≥ 1) in the plan's own executor.
    Fixed(usize),
    /// tract's process-wide executor (`set_cnn_threads`), as plans made by
    /// `HologramModel::plan` use.
    ProcessDefault,
}

impl ThreadCount {
    /// `0` → [`ThreadCount::Auto`], `n` → [`ThreadCount::Fixed`]`(n)`: the `threads` convention of the
    /// CLI and the bindings.
    pub fn from_count(threads: usize) -> Self {
        match threads {
            0 => Self::Auto,
            n => Self::Fixed(n),
        }
    }
}

/// What `HologramModel::tuned_plan` may choose from: [`CnnLayout::Auto`] tries both layouts, a concrete
/// layout only itself; [`ThreadCount::Auto`] tries [`auto_thread_candidates`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
pub struct PlanRequest {
    /// Memory layout, or [`CnnLayout::Auto`].
    pub layout: CnnLayout,
    /// Thread count, or [`ThreadCount::Auto`].
    pub threads: ThreadCount,
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

/// What `HologramModel::tuned_plan` (tract's layouts and threads) and a session's engine choice
/// ([`crate::pipeline::PipelineConfig::cnn_engine`]) chose and why.
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
}

/// The thread counts [`ThreadCount::Auto`] times on this machine: 1, half the available cores and all of
/// them (deduplicated; `std::thread::available_parallelism`, at most [`MAX_CNN_THREADS`]).
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
pub fn timing_resolution(height: usize, width: usize) -> [usize; 2] {
    if height.saturating_mul(width) <= TUNE_PIXELS {
        return [height, width];
    }
    let rows = (TUNE_PIXELS / width.max(1)).max(TUNE_MIN_ROWS).min(height);
    [rows, width]
}

/// The timing rule of every autotuner (tract's layouts and threads here, the native engine's in
/// `cnn::select`): one run of `run` (which returns its seconds), or the fastest of three when the first is
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
