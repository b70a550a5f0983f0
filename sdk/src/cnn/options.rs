//! What a caller may ask of a session's CNN plans, as one value that travels whole from the request
//! ([`crate::pipeline::PipelineConfig::cnn`], [`crate::generator::GeneratorConfig::cnn`], the bindings) to the
//! plans and the kernels: [`CnnOptions`], made of the engine ([`CnnEngine`]), tract's memory layout
//! ([`CnnLayout`]), the threads ([`ThreadCount`], at most [`MAX_CNN_THREADS`]), the f32 convolution algorithm
//! ([`ConvAlgorithm`]), whether to time the candidates, the native engine's strips and slabs, and the kernels'
//! instruction set ([`Isa`]). Their `Auto` values are decided by the plan table (`cnn/table.rs`), or timed on
//! the machine when tuning is asked for ([`crate::cnn::PlanSource::Tune`]). Imports nothing of `cnn/`: every
//! other file of it reads this one.

use tensorholo_kernels::{Algorithm, Isa};

use crate::error::{invalid, Result};

/// How a session's CNNs run: one value from the request to the kernels. `Default` is every decision the plan
/// table's (the same bits in every process), on the cores the CPU reports and this CPU's best instruction set.
///
/// The engine's plans read it whole ([`crate::cnn::PlanRequest::cnn`]); nothing in the SDK reads the
/// environment for it (`holo` maps `TENSORHOLO_ISA`, `TENSORHOLO_CONV`, `TENSORHOLO_STRIP_ROWS` and
/// `TENSORHOLO_SLABS` onto it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
pub struct CnnOptions {
    /// The engine of the CPU CNNs ([`CnnEngine::Auto`], the default: the plan table's, the native engine
    /// wherever it runs the files; the native engine runs the f32 and the int8 QDQ files, tract every file,
    /// int8 QOperator included; with `tune` the engines are timed and the fastest runs).
    pub engine: CnnEngine,
    /// Memory layout tract runs the hologram CNN in ([`CnnLayout`]; results agree to float rounding);
    /// [`CnnLayout::Auto`] (the default) is the plan table's (both timed with `tune`). The pre-filter CNN
    /// always runs channels-first: with its 8 filters the channels-last matrix product has only 8 rows, and it
    /// measured 2.1× slower (`holo bench --skip-cnn --layout nchw,nhwc`, 384², 1 thread: 89 ms against
    /// 42 ms); tract 0.23 cannot move its graph channels-last anyway.
    pub layout: CnnLayout,
    /// Threads of the CNNs ([`ThreadCount::Auto`], the default: the cores the CPU reports; with `tune`, the
    /// fastest of 1, half and all cores, timed). The optics run on their own threads (the offset propagation
    /// one thread per colour, the encoding on a pool of all the cores).
    pub threads: ThreadCount,
    /// The native engine's f32 convolution algorithm ([`ConvAlgorithm::Auto`], the default: each layer
    /// shape's row from the plan table, a saved tuning or the timing); a pinned algorithm still takes its row
    /// from there.
    pub algorithm: ConvAlgorithm,
    /// Time the CNN candidates when a session is created ([`crate::cnn::PlanSource::Tune`]: engines, layouts,
    /// each layer shape's kernel row, thread counts) instead of taking the plan table's (the default,
    /// `false`: the same bits in every process). Two tuned processes can differ in their last bits where two
    /// candidates are close; save a session's choice ([`crate::cnn::PlanReport::saved`]) and give it to later
    /// pipelines ([`HologramPipeline::with_saved_plans`](crate::pipeline::HologramPipeline::with_saved_plans))
    /// to repeat it.
    pub tune: bool,
    /// The native engine's strip height in frame rows (`None`, the default: the rule of
    /// `cnn/native/strips.rs`, the most rows whose activation windows fit a cache budget), rounded up to a
    /// whole number of its layers' row groups; more rows than the frame's make one strip. A benchmark setting
    /// (`holo` reads `TENSORHOLO_STRIP_ROWS`); the same value gives the same bits.
    pub strip_rows: Option<usize>,
    /// The native f32 engine's column slab count (`None`, the default: the rule of `cnn/native/slabs.rs`);
    /// the int8 engine runs whole rows. More slabs than the frame can hold (each starts at its own multiple of
    /// 4 columns: at most `⌈W/4⌉`) run the whole frame. A benchmark setting (`holo` reads `TENSORHOLO_SLABS`).
    pub slabs: Option<usize>,
    /// The highest instruction-set level the kernels may use (`None`, the default: this CPU's best,
    /// [`Isa::detect`]); a lower level runs the same plans on that level's kernel rows (the portable ones with
    /// [`Isa::Scalar`]), to compare or to reproduce another machine's bits. Resolved once per session
    /// ([`CnnOptions::kernel_isa`]). `holo` maps `TENSORHOLO_ISA` onto it.
    #[serde(serialize_with = "isa_name")]
    pub isa: Option<Isa>,
}

/// [`CnnOptions::isa`] in reports: its name, or null.
fn isa_name<S: serde::Serializer>(isa: &Option<Isa>, s: S) -> std::result::Result<S::Ok, S::Error> {
    match isa {
        Some(i) => s.serialize_some(i.name()),
        None => s.serialize_none(),
    }
}

impl CnnOptions {
    /// Checks the values: a fixed thread count in 1..=[`MAX_CNN_THREADS`], strip rows and slabs ≥ 1 where
    /// given, and an instruction set this CPU has.
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] naming the field (`threads`, `strip_rows`, `slabs`,
    /// `isa`).
    pub(crate) fn validate(&self) -> Result<()> {
        if let ThreadCount::Fixed(n) = self.threads {
            if n == 0 || n > MAX_CNN_THREADS {
                return Err(invalid(
                    "threads",
                    format!("0 (automatic) to {MAX_CNN_THREADS} threads, got {n}"),
                ));
            }
        }
        for (name, v) in [("strip_rows", self.strip_rows), ("slabs", self.slabs)] {
            if v == Some(0) {
                return Err(invalid(
                    name,
                    "must be at least 1 (or unset for the engine's rule)",
                ));
            }
        }
        self.kernel_isa().map(drop)
    }

    /// The instruction-set level the kernels run at: [`CnnOptions::isa`], else this CPU's best
    /// ([`Isa::detect`]).
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] (`isa`) for a level this CPU does not have.
    pub fn kernel_isa(&self) -> Result<Isa> {
        self.isa.map_or(Ok(Isa::detect()), available)
    }
}

/// `isa` where this CPU has it: the one check of an instruction set a caller names (the options, an encoder's
/// [`crate::encoding::ChannelEncoder::with_isa`], the peak loops).
///
/// Errors: [`crate::HoloError::InvalidParameter`] (`isa`) naming the levels this CPU has.
pub(crate) fn available(isa: Isa) -> Result<Isa> {
    if isa.is_available() {
        return Ok(isa);
    }
    let has: Vec<&str> = Isa::available().iter().map(|i| i.name()).collect();
    Err(invalid(
        "isa",
        format!(
            "`{}` is not available on this CPU (it has: {})",
            isa.name(),
            has.join(", ")
        ),
    ))
}

/// The most threads a CNN plan may use (tract's `ModelPlan::with_threads`, the native engine's thread
/// count): far above any phone or desktop core count, low enough that a typo cannot ask the OS for a hundred
/// thousand threads.
pub const MAX_CNN_THREADS: usize = 256;

/// The engine that runs a session's CNNs on the CPU
/// ([`CnnOptions::engine`]).
///
/// - [`CnnEngine::Native`]: our direct 3×3 convolution kernels (`tensorholo-kernels`: AVX-512, AVX2+FMA,
///   NEON or portable scalar rows, chosen at run time from the CPU's features), row bands on the plan's own
///   threads. f32 files (agree with tract to float rounding) and int8 QDQ files (u8 × s8 kernels, each layer's
///   convolution, ReLU, residual and requantisation fused; a mixed-precision file's f32 first and last layers
///   on the f32 kernels: within the models' int8 tolerance of tract's node-by-node execution;
///   `sdk/src/cnn/tests.rs`).
/// - [`CnnEngine::Tract`]: tract's optimised plans (any file that passes the contract, int8 included; cargo
///   feature `tract`, `CnnEngine::cargo_feature`).
/// - [`CnnEngine::Auto`] (the default): the plan table's engine, a function of the CPU's features and the
///   files (`cnn/table.rs`): the native engine wherever it runs them (2.3–20× tract's best on x86-64, 2.3×
///   fewer instructions on ARM), tract for int8 QOperator files and for int8 files on the portable rows
///   (tract 4.3× the native portable int8 rows there). With [`crate::cnn::PlanSource::Tune`] the engines of
///   this build that can run the files are timed instead and the fastest runs. The choice and why are in
///   [`crate::cnn::PlanReport`].
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum CnnEngine {
    /// The plan table's engine for this CPU and these files (timed with [`crate::cnn::PlanSource::Tune`]).
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
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Native => "native",
            Self::Tract => "tract",
        }
    }

    /// The cargo feature of `tensorholo` (and `tensorholo-ffi`) that compiles this engine in, `None` for one
    /// every build has (named by errors in a build without it).
    pub(crate) fn cargo_feature(self) -> Option<&'static str> {
        match self {
            Self::Tract => Some("tract"),
            Self::Auto | Self::Native => None,
        }
    }

    /// Parses `CnnEngine::name`. Errors: [`crate::HoloError::InvalidParameter`] (`engine`) naming the
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
/// Which layout is faster depends on the CPU (`docs/BENCHMARKS.md`): the default, [`CnnLayout::Auto`], is the
/// plan table's (`cnn/table.rs`: channels-first on x86-64, channels-last on aarch64 where tract can move the
/// graph), or the faster of the two timed on the machine with [`crate::cnn::PlanSource::Tune`].
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum CnnLayout {
    /// The plan table's layout (both timed with [`crate::cnn::PlanSource::Tune`]); a plan never runs in
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
    pub(crate) fn name(self) -> &'static str {
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

/// How many threads a CNN plan uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ThreadCount {
    /// The cores this CPU reports ([`default_threads`]); with [`crate::cnn::PlanSource::Tune`], the fastest
    /// of [`crate::cnn::auto_thread_candidates`], timed.
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

/// The threads [`ThreadCount::Auto`] runs on without tuning: the cores this CPU reports
/// (`std::thread::available_parallelism`, 1 where it cannot tell), at most [`MAX_CNN_THREADS`]. On the
/// 2-core Zen 4 of docs/BENCHMARKS.md two threads ran the 384² frame in 40–42 ms against 73–81 ms on one
/// (`holo render --threads 1|2 --repeat 9`), where the timed choice had picked one thread in some processes.
pub fn default_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, MAX_CNN_THREADS)
}

/// The algorithm of the native engine's f32 3×3 convolutions: what a caller pins ([`CnnOptions::algorithm`])
/// and what a saved layer row was chosen among ([`crate::cnn::SavedRow::algorithms`]); the one enum for the
/// choice (the kernels' concrete [`Algorithm`] is what a row runs).
///
/// Direct convolution computes `9·C_in` multiply-adds per output value; Winograd's minimal filtering
/// F(2×2, 3×3) `4·C_in` and F(4×4, 3×3) `2.25·C_in` plus the tile transforms (Lavin & Gray 2016). The
/// Winograd forms round differently from direct, within the bounds `tensorholo-kernels` states. int8 layers
/// are always direct.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    Default,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum ConvAlgorithm {
    /// Each layer shape's row from the plan table (or a tuning), among every algorithm. Saved-plans files of
    /// version 1 wrote it `any`, which still reads.
    #[default]
    #[serde(alias = "any")]
    Auto,
    /// Direct convolution in every f32 layer.
    Direct,
    /// Winograd F(2×2, 3×3) in every f32 layer.
    Winograd2x2,
    /// Winograd F(4×4, 3×3) in every f32 layer.
    Winograd4x4,
}

impl ConvAlgorithm {
    /// The kernels' algorithms a layer chooses among: all three for [`ConvAlgorithm::Auto`], else the one.
    pub(crate) fn algorithms(self) -> &'static [Algorithm] {
        match self {
            Self::Auto => &[
                Algorithm::Direct,
                Algorithm::Winograd2x2,
                Algorithm::Winograd4x4,
            ],
            Self::Direct => &[Algorithm::Direct],
            Self::Winograd2x2 => &[Algorithm::Winograd2x2],
            Self::Winograd4x4 => &[Algorithm::Winograd4x4],
        }
    }

    /// Short name: `auto`, `direct`, `winograd2x2`, `winograd4x4`.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Direct => "direct",
            Self::Winograd2x2 => "winograd2x2",
            Self::Winograd4x4 => "winograd4x4",
        }
    }

    /// Parses `ConvAlgorithm::name` (also `winograd` for F(2×2, 3×3); surrounding spaces ignored).
    /// Errors: [`crate::HoloError::InvalidParameter`] (`conv`) naming the choices.
    pub fn parse(name: &str) -> Result<Self> {
        match name.trim() {
            "auto" => Ok(Self::Auto),
            "direct" => Ok(Self::Direct),
            "winograd" | "winograd2x2" => Ok(Self::Winograd2x2),
            "winograd4x4" => Ok(Self::Winograd4x4),
            other => Err(invalid(
                "conv",
                format!(
                    "`{other}` is not one of direct, winograd2x2 (or winograd), winograd4x4, auto"
                ),
            )),
        }
    }
}

impl std::fmt::Display for ConvAlgorithm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_algorithm_names_parse_back_and_others_are_refused() {
        for a in [
            ConvAlgorithm::Auto,
            ConvAlgorithm::Direct,
            ConvAlgorithm::Winograd2x2,
            ConvAlgorithm::Winograd4x4,
        ] {
            assert_eq!(ConvAlgorithm::parse(a.name()).unwrap(), a);
        }
        assert_eq!(
            ConvAlgorithm::parse(" winograd").unwrap(),
            ConvAlgorithm::Winograd2x2
        );
        let e = ConvAlgorithm::parse("fft").unwrap_err();
        assert!(
            matches!(e, crate::HoloError::InvalidParameter { name: "conv", .. }),
            "{e}"
        );
        assert!(e.to_string().contains("`fft`"), "{e}");
    }

    /// The options' instruction set is this CPU's best by default, a level it has as given, and a level it
    /// lacks (or a zero strip count, or too many threads) is refused naming the field.
    #[test]
    fn the_options_resolve_the_isa_and_refuse_what_cannot_run() {
        let name = |o: CnnOptions| match o.validate().unwrap_err() {
            crate::HoloError::InvalidParameter { name, .. } => name,
            e => panic!("unexpected {e}"),
        };
        assert_eq!(CnnOptions::default().kernel_isa().unwrap(), Isa::detect());
        let scalar = CnnOptions {
            isa: Some(Isa::Scalar),
            ..CnnOptions::default()
        };
        assert_eq!(scalar.kernel_isa().unwrap(), Isa::Scalar);
        let lacking = Isa::ALL.into_iter().find(|i| !i.is_available()).unwrap();
        let e = CnnOptions {
            isa: Some(lacking),
            ..CnnOptions::default()
        }
        .kernel_isa()
        .unwrap_err();
        assert!(e.to_string().contains(lacking.name()), "{e}");
        for (o, field) in [
            (
                CnnOptions {
                    isa: Some(lacking),
                    ..CnnOptions::default()
                },
                "isa",
            ),
            (
                CnnOptions {
                    strip_rows: Some(0),
                    ..CnnOptions::default()
                },
                "strip_rows",
            ),
            (
                CnnOptions {
                    threads: ThreadCount::Fixed(MAX_CNN_THREADS + 1),
                    ..CnnOptions::default()
                },
                "threads",
            ),
        ] {
            assert_eq!(name(o), field);
        }
    }

    #[test]
    fn the_default_thread_count_is_the_cores_reported() {
        let n = default_threads();
        assert!((1..=MAX_CNN_THREADS).contains(&n));
        let reported = std::thread::available_parallelism().map_or(1, |n| n.get());
        assert_eq!(n, reported.min(MAX_CNN_THREADS));
    }
}
