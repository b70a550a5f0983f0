//! `holo`: command-line front end of the tensorholo SDK (Tensor Holography V2).
//!
//! Every subcommand is a thin layer over the `tensorholo` public API: argument parsing, progress output and
//! files. The physics lives in the SDK.

mod aberration;
mod args;
mod baselines;
mod bench;
mod calibrate;
mod calibrate_aberration;
mod calibrate_model;
mod compare;
mod dataset;
mod display;
mod encode;
mod fovea;
mod memory;
mod model_args;
mod output;
mod propagate;
mod reference;
mod refine;
mod render;
mod video;

use clap::{Parser, Subcommand};

/// Turn RGB-D images into 3D phase-only holograms for a spatial light modulator (SLM).
///
/// Units are SI on every flag whose name ends in `-m` (metres); `--offset-mm` is in millimetres as in the
/// paper. Colour order is always R, G, B (638, 520, 450 nm by default).
#[derive(Debug, Parser)]
#[command(name = "holo", version, about, long_about = None, propagate_version = true, after_help = ENVIRONMENT)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Largest input image decoded, in pixels (read from the file's header before decoding; a larger one is
    /// refused naming the limit). The default covers a 48 MP phone photo.
    #[arg(long, global = true, default_value_t = tensorholo::io::InputLimits::default().max_image_pixels)]
    max_image_pixels: u64,
    /// Largest input file read, in bytes (images, depth maps, .npy, models).
    #[arg(long, global = true, default_value_t = tensorholo::io::InputLimits::default().max_file_bytes)]
    max_file_bytes: u64,
}

/// The environment variables `holo` reads (the library reads none of its own).
const ENVIRONMENT: &str = "\
Environment:
  TENSORHOLO_CONV=direct|winograd2x2|winograd4x4|auto
                      pin the f32 convolution algorithm of the native engine's layers (render, video, bench);
                      auto or unset: each layer's row from the plan table (or --tune, --tuning)
  TENSORHOLO_STRIP_ROWS=N
                      the native engine's strip height in frame rows (render, video, bench; report.json's
                      cnn_plan.request.strip_rows): for benchmarks of the layout; unset: the engine's rule;
                      more rows than the frame's (plus the network's lag): one strip
  TENSORHOLO_SLABS=N  the native f32 engine's column slab count (render, video, bench; request.slabs);
                      unset: the engine's rule; more than ⌈width/4⌉: the whole frame
  TENSORHOLO_ISA=scalar|avx2|avxvnni|avx512|avx512vnni|neon|neondot|neoni8mm
                      lower the kernels' instruction set (the plan table's rows follow it)
  RUST_LOG=debug      more log lines (e.g. each layer's timed rows with --tune)";

#[derive(Debug, Subcommand)]
enum Command {
    /// Turn an RGB-D frame into SLM phase patterns with the hologram CNN (the SDK's main job): CNN → offset
    /// propagation (Eq. 6) → pre-filter CNN → double phase (Eq. 7) → 8-bit codes, with previews, timings and
    /// optional quality scores (--evaluate).
    ///
    /// Without --rgb/--depth it runs the shipped 8-layer model on a built-in procedural scene.
    Render(Box<render::RenderArgs>),
    /// Process an RGB-D sequence (folders of frames) with one hologram session, overlapping the CNN of the
    /// next frame with the optics of the current one; reports per-frame latency and FPS.
    Video(Box<video::VideoArgs>),
    /// Benchmark the CNNs (every variant, precision, size and thread count: ms, FPS, GFLOP/s), the post-CNN
    /// stages and the end-to-end pipeline; prints a Markdown table (docs/BENCHMARKS.md).
    Bench(Box<bench::BenchArgs>),
    /// Compute a reference hologram with the silhouette-mask layer-based method (paper Eq. 1-4), encode it for
    /// a phase-only SLM and write the SLM patterns, the midpoint hologram and simulated reconstructions.
    ///
    /// Without --rgb/--depth it runs on a built-in procedural scene (no data needed).
    Reference(Box<reference::ReferenceArgs>),
    /// Propagate a complex field stored in .npy with the angular spectrum method (paper Eq. 2), for checks
    /// against other implementations.
    Propagate(propagate::PropagateArgs),
    /// Generate a training dataset: random-scene layered depth images with their SM-LBM midpoint holograms
    /// (paper section "MIT-CGH-4K-V2"), in .npz shards with a manifest.json (format: docs/DATASET.md).
    Dataset(Box<dataset::DatasetArgs>),
    /// Encode a complex midpoint hologram (.npy) for a phase-only SLM: offset propagation (Eq. 6), double phase
    /// (Eq. 7, DPM/AA-DPM/BL-DPM), and the simulated post-encoding midpoint hologram (Eq. 8-10), for checks
    /// against other implementations.
    Encode(Box<encode::EncodeArgs>),
    /// Compute the non-learned baselines of the model card (Maimone-style layer-based hologram; SM-LBM +
    /// AA-DPM at each SLM offset) from the RGB-D input of every scene of a dataset split, as .npy midpoint
    /// holograms for the Python evaluator (`--baseline NAME=FOLDER`).
    Baselines(Box<baselines::BaselinesArgs>),
    /// Compare two output folders of `holo render` (e.g. the same command on x86-64 and on aarch64): the
    /// midpoint hologram, the SLM codes and the simulated reconstructions.
    Compare(compare::CompareArgs),
    /// Display profiles (docs/DISPLAYS.md): `holo display check FILE` says which shipped CNNs serve a display,
    /// at what estimated cost, or why not and what would.
    Display(display::DisplayArgs),
    /// Calibrate the display (paper Methods, Eq. 12-13): test patterns, a per-pixel phase look-up table from
    /// camera captures into a .holocal file, its curves as .npy, and a simulated SLM to try it on.
    Calibrate(calibrate::CalibrateArgs),
}

/// glibc's malloc keeps freed frame-sized buffers in its heaps once a large free has raised its mmap
/// threshold (up to 32 MB), so a 1080p run would stay ~170 MB above what it uses. A threshold fixed at 1 MB
/// hands every buffer of a megabyte or more back to the system when freed. It is set in-process, first thing
/// in `main` (before any large allocation), with `mallopt(M_MMAP_THRESHOLD)`, which also turns glibc's dynamic
/// threshold off, as the environment variable `MALLOC_MMAP_THRESHOLD_` would. An earlier `holo` re-executed
/// itself with that variable set; under qemu-user without binfmt the exec handed the ELF to `/bin/sh`. A
/// value the user sets in the environment wins. Other C libraries (musl, Apple's, Android's) have no such
/// threshold.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn fixed_mmap_threshold() {
    const THRESHOLD_BYTES: libc::c_int = 1 << 20;
    if std::env::var_os("MALLOC_MMAP_THRESHOLD_").is_some() {
        return;
    }
    // SAFETY: `mallopt` only sets a parameter of glibc's allocator; M_MMAP_THRESHOLD takes any value up to
    // HEAP_MAX/2 (32 MB on 64-bit), and 1 MB is within it. It runs before any other thread exists.
    #[allow(unsafe_code)]
    let ok = unsafe { libc::mallopt(libc::M_MMAP_THRESHOLD, THRESHOLD_BYTES) };
    if ok != 1 {
        eprintln!("note: mallopt(M_MMAP_THRESHOLD) refused; glibc's default threshold stays");
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn fixed_mmap_threshold() {}

/// A closed pipe ends `holo` quietly, as it does other command-line tools (`holo display check FILE | head`):
/// Rust ignores SIGPIPE, so a write to a closed pipe would fail and `println!` would panic instead.
#[cfg(unix)]
fn quiet_on_closed_pipe() {
    // SAFETY: `signal` only sets the disposition of SIGPIPE back to the default (terminate), before any other
    // thread exists; SIG_DFL is a valid disposition.
    #[allow(unsafe_code)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

#[cfg(not(unix))]
fn quiet_on_closed_pipe() {}

fn main() {
    fixed_mmap_threshold();
    quiet_on_closed_pipe();
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("info"))
        .format_timestamp(None)
        .init();
    let cli = Cli::parse();
    if let Err(err) = tensorholo::io::set_input_limits(tensorholo::io::InputLimits {
        max_image_pixels: cli.max_image_pixels,
        max_file_bytes: cli.max_file_bytes,
    }) {
        eprintln!("error: {err}");
        std::process::exit(2);
    }
    // Ctrl-C (SIGINT/SIGTERM): remove the temporary file of any write in progress and exit 130. Outputs
    // already written are complete (written under a temporary name, then renamed), and the run's report, which
    // every command removes first and writes last, is absent: the folder is visibly an incomplete run.
    if let Err(e) = ctrlc::set_handler(|| {
        let n = tensorholo::io::remove_temporary_files();
        eprintln!(
            "interrupted: stopped{}; the output folder has no new report, so it holds an incomplete run",
            if n > 0 {
                format!(" and removed {n} partly written file(s)")
            } else {
                String::new()
            }
        );
        std::process::exit(130);
    }) {
        log::warn!("cannot install the Ctrl-C handler: {e}");
    }
    // A panic is a bug whatever the input: report it as one (the panic message above says where) with its
    // own exit code, instead of an abort trace.
    let outcome = std::panic::catch_unwind(move || match cli.command {
        Command::Render(args) => render::run(&args),
        Command::Video(args) => video::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Reference(args) => reference::run(&args),
        Command::Propagate(args) => propagate::run(&args),
        Command::Dataset(args) => dataset::run(&args),
        Command::Encode(args) => encode::run(&args),
        Command::Baselines(args) => baselines::run(&args),
        Command::Compare(args) => compare::run(&args),
        Command::Calibrate(args) => calibrate::run(&args),
        // Exit status for scripts: 1 where the display is not served.
        Command::Display(args) => display::run(&args).map(|served| {
            if !served {
                std::process::exit(1);
            }
        }),
    });
    match outcome {
        Ok(Ok(())) => {}
        Ok(Err(err)) => {
            eprintln!("error: {err:#}");
            // The output guard's refusal is a usage error (the command line names an output among its
            // inputs), like the argument parser's: exit code 2. Every other refusal: 1.
            let usage = err
                .chain()
                .any(|e| e.is::<output::OutputGuard>() || e.is::<output::UsageError>());
            std::process::exit(if usage { output::EXIT_USAGE } else { 1 });
        }
        Err(_) => {
            eprintln!(
                "error: holo stopped on an internal error (a panic, reported above). This is a bug in holo, not \
                 in your input: please report it with the command line. Outputs of this run may be incomplete."
            );
            std::process::exit(EXIT_BUG);
        }
    }
}

/// Exit code of a panic (`EX_SOFTWARE` of sysexits.h: an internal software error).
const EXIT_BUG: i32 = 70;
