//! What a session asks of its CNN plans and what it got: the engine ([`CnnEngine`]), tract's memory layout
//! ([`CnnLayout`]), the threads ([`ThreadCount`], at most [`MAX_CNN_THREADS`]), the request ([`PlanRequest`])
//! and the report ([`PlanReport`]). Imports nothing of `cnn/`: every engine reads it.
//!
//! Autotuned CNN plans: which tract plan is fastest depends on the CPU (channels-first won at large frames on
//! one 2-core Xeon, channels-last was 2.2× faster at 384×384 on another; a phone is yet another CPU), so the
//! candidates are timed on the machine, at the session's resolution, when a session is created
//! (`docs/BENCHMARKS.md`, "Autotuned plans").
//!
//! This module holds what every engine's tuning shares: the request ([`PlanRequest`], [`ThreadCount`]), the
//! report ([`PlanReport`], [`PlanTiming`]), the candidates' resolution and thread counts, and the timing rule
//! ([`fastest_run`]). Each engine times its own candidates (`cnn/native/`: thread counts; `cnn/tract/`, cargo
//! feature `tract`: layouts × thread counts, cached per model, resolution and request so that a second
//! session of the same size starts at once), and `cnn/select.rs` compares the engines.

use crate::error::{invalid, Result};

/// The most threads a CNN plan may use (tract's `ModelPlan::with_threads`, the native engine's thread
/// count): far above any phone or desktop core count, low enough that a typo cannot ask the OS for a hundred
/// thousand threads.
pub const MAX_CNN_THREADS: usize = 256;

/// The engine that runs a session's CNNs on the CPU
/// ([`PipelineConfig::cnn_engine`](crate::pipeline::PipelineConfig::cnn_engine)).
///
/// - [`CnnEngine::Native`]: our direct 3×3 convolution kernels (`tensorholo-kernels`: AVX-512, AVX2+FMA,
///   NEON or portable scalar rows, chosen at run time from the CPU's features), row bands on the plan's own
///   threads. f32 files (agree with tract to float rounding) and int8 QDQ files (u8 × s8 kernels, each layer's
///   convolution, ReLU, residual and requantisation fused; a mixed-precision file's f32 first and last layers
///   on the f32 kernels: within the models' int8 tolerance of tract's node-by-node execution;
///   `sdk/src/cnn/tests.rs`).
/// - [`CnnEngine::Tract`]: tract's optimised plans (any file that passes the contract, int8 included; cargo
///   feature `tract`, [`CnnEngine::cargo_feature`]).
/// - [`CnnEngine::Auto`] (the default): the engines of this build that can run the file are timed at session
///   creation on this machine (on the frame, or a full-width strip of a large one), the native engine first,
///   and the faster runs; int8 QOperator files run on tract. Where the native engine runs its x86-64 SIMD
///   rows, measured 2.3–20× tract's best on every such CPU tried, tract is not timed (0.3–0.4 s of a 1080p
///   setup); on the portable rows and on ARM it is. The choice, the timings and what was not timed (with
///   why) are in [`crate::cnn::PlanReport`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CnnEngine {
    /// Time the engines that can run the file; keep the fastest.
    #[default]
    Auto,
    /// Our direct-convolution kernels (an error at session creation for a file they cannot run).
    Native,
    /// tract.
    Tract,
}

impl CnnEngine {
    /// The engines (every variant but [`CnnEngine::Auto`]), whether or not this build has them.
    pub const ENGINES: [CnnEngine; 2] = [Self::Native, Self::Tract];

    /// Short name: `auto`, `native`, `tract`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Native => "native",
            Self::Tract => "tract",
        }
    }

    /// The cargo feature of `tensorholo` (and `tensorholo-ffi`) that compiles this engine in, `None` for one
    /// every build has (named by errors in a build without it).
    pub fn cargo_feature(self) -> Option<&'static str> {
        match self {
            Self::Tract => Some("tract"),
            Self::Auto | Self::Native => None,
        }
    }

    /// Parses [`CnnEngine::name`]. Errors: [`crate::HoloError::InvalidParameter`] (`engine`) naming the
    /// choices.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "auto" => Ok(Self::Auto),
            "native" => Ok(Self::Native),
            "tract" => Ok(Self::Tract),
            other => Err(invalid(
                "engine",
                format!("unknown CNN engine `{other}` (auto, native or tract)"),
            )),
        }
    }
}

impl std::fmt::Display for CnnEngine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The memory layout tract runs a CNN in. The ONNX files are always channels-first `[1, C, H, W]`
/// (`docs/CONVENTIONS.md` §7) and a plan takes and returns `[C, H, W]` arrays in every layout; only tract's
/// internal graph differs (`cnn::tract::TractModel::plan_with_layout`, feature `tract`). The native engine's
/// buffers are channel-major within each row: it reports [`CnnLayout::ChannelsFirst`].
///
/// Which layout is faster depends on the CPU and the frame size (`docs/BENCHMARKS.md`: on one 2-core Xeon
/// channels-first won at large frames, on another channels-last was 2.2× faster at 384×384), so the default
/// is [`CnnLayout::Auto`]: the candidates are timed on the machine at session creation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CnnLayout {
    /// Time both layouts on this machine at the real resolution and keep the faster; a plan never runs in
    /// `Auto` itself.
    #[default]
    Auto,
    /// Channels first (NCHW), as in the file. tract 0.23 runs the 3×3 convolutions as its direct spatial
    /// convolution (a filter along W, four output channels at a time) where the rows are ≥ 128 pixels wide.
    ChannelsFirst,
    /// Channels last (NHWC): the whole graph is moved by tract's axis-change propagation, and the
    /// convolutions run as a lazy im2col (one gather per output pixel of 3 contiguous runs of 3·C values)
    /// feeding tract's matrix-product kernels, after an explicit zero `Pad`. f32 and int8 QDQ files (float
    /// convolutions); tract 0.23 does not move a quantised `QLinearConv` nor the pre-filter graph, so those
    /// files in this layout are an error (and `Auto` skips it for them).
    ChannelsLast,
}

impl CnnLayout {
    /// The two concrete layouts, channels-first first.
    pub const ALL: [CnnLayout; 2] = [Self::ChannelsFirst, Self::ChannelsLast];

    /// Short name: `auto`, `nchw`, `nhwc`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::ChannelsFirst => "nchw",
            Self::ChannelsLast => "nhwc",
        }
    }
}

impl std::fmt::Display for CnnLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

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

/// How many threads a CNN plan uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ThreadCount {
    /// Time [`auto_thread_candidates`] and keep the fastest.
    #[default]
    Auto,
    /// Exactly this many threads (≥ 1) in the plan's own executor.
    Fixed(usize),
    /// tract's process-wide default executor (one thread), as plans made by `cnn::tract::TractModel::plan`
    /// use; the native engine runs such a request on 1 thread.
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

/// What a session's CNN plans may be chosen from: [`CnnLayout::Auto`] tries both of tract's layouts, a
/// concrete layout only itself; [`ThreadCount::Auto`] tries [`auto_thread_candidates`].
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

/// What a session's engine choice ([`crate::pipeline::PipelineConfig::cnn_engine`]) and the engine's own
/// timing (tract's layouts and threads, the native engine's threads) chose and why.
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
