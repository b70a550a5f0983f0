//! `holo video`: an RGB-D sequence through one [`HologramSession`],
//! with the hologram CNN of frame n + 1 overlapping the optics of frame n; per-frame latency and FPS.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use ndarray::Axis;
use serde_json::json;
use tensorholo::encoding::{PhaseContinuity, TemporalSummary};
use tensorholo::foveation::Gaze;
use tensorholo::io::{ensure_not_input, save_u8_png};
use tensorholo::pipeline::{Backend, HologramPipeline, HologramSession, SlmFrame};
use tensorholo::refine::{FrameRefinement, FrameRefiner, RefinedFrame};
use tensorholo::scene::{
    load_rgbd_with_confidence, open_frame_folders, open_recording, DepthRange, FrameFolders,
    LoadOptions, Recording, RecordingFrame, RecordingKind, RgbdFrame,
};
use tensorholo::synthesis::SceneLayer;
use tensorholo::HoloError;

/// Arguments of `holo video`.
#[derive(Debug, Args)]
#[command(after_long_help = EXAMPLES)]
pub struct VideoArgs {
    /// Folder of RGB frames (PNG, JPEG or PPM); frames are paired with --depth-dir by file stem, in name order.
    #[arg(long, required_unless_present = "recording", requires = "depth_dir")]
    rgb_dir: Option<PathBuf>,
    /// Folder of depth frames with the same stems as the RGB frames.
    #[arg(long, requires = "rgb_dir")]
    depth_dir: Option<PathBuf>,
    /// Folder of depth confidence maps (8-bit, at the depth maps' resolution) with the same stems as the
    /// depth frames: pixels below --min-confidence are invalid.
    #[arg(long, requires = "depth_dir")]
    confidence_dir: Option<PathBuf>,
    /// A phone recording as its app exports it: Record3D's "EXR + JPG" export (rgb/, depth/*.exr,
    /// metadata.json) or a Stray Scanner folder (rgb/ extracted from rgb.mp4, depth/, confidence/,
    /// odometry.csv); frames in the order of the recording's timestamps, its confidence maps applied
    /// (docs/VIDEO.md).
    #[arg(long, conflicts_with_all = ["rgb_dir", "depth_dir", "confidence_dir", "skip_unmatched"])]
    recording: Option<PathBuf>,
    #[command(flatten)]
    depth: crate::args::DepthArgs,
    #[command(flatten)]
    model: crate::model_args::ModelArgs,
    /// Process at most this many frames.
    #[arg(long)]
    limit: Option<usize>,
    /// Skip RGB frames without a depth frame of the same stem (and depth frames without an RGB one) with a
    /// warning, instead of refusing the sequence.
    #[arg(long)]
    skip_unmatched: bool,
    /// Write each frame's SLM patterns as frames/NNNNN_phase_{r,g,b}.png (inside the timed loop, as a
    /// display would consume them).
    #[arg(long)]
    save_frames: bool,
    #[command(flatten)]
    refine: crate::refine::RefineArgs,
    /// Shift each colour's codes so that its global phase follows the previous frame's (a global phase changes
    /// nothing the viewer sees; with the linear look-up table the shift is exact): less phase churn for the SLM
    /// to settle (report.json's `temporal`). Not with a calibrated look-up table (--calibration or the
    /// profile's), where a code shift is not a phase shift.
    #[arg(long)]
    align_phase: bool,
    /// Output folder for report.json (and frames/).
    #[arg(long)]
    out: PathBuf,
}

const EXAMPLES: &str = "\
Examples:
  holo video --rgb-dir ../shared/data/redwood_livingroom_seq/color \\
      --depth-dir ../shared/data/redwood_livingroom_seq/depth --depth-encoding mm16 --size 384x512 --out out/video
      the 5-frame Redwood sequence (metric range from the first frame, kept for the whole sequence)
  holo video --recording my-record3d-export --size 1080x1920 --out out/phone
      an iPhone LiDAR recording as Record3D exports it (EXR + JPG), or a Stray Scanner folder
  holo video ... --refine 10 --refine-init previous --out out/refined
      each frame's SLM pattern refined 10 iterations against its SM-LBM focal stack, each frame starting
      from the previous frame's refined pattern (docs/REFINE.md)

Outputs in --out:
  report.json   per-frame timings (load+CNN, offset, pre-filter, encoding, frame period), mean FPS, whether the
                streamed first frame equals a single-frame render of it bit for bit, and the temporal numbers:
                per frame and in summary the SLM phase churn from the previous frame (mean wrapped |Δφ|,
                radians, and the share of pixels changing by more than π/2), with --align-phase the shifts
  frames/       with --save-frames: NNNNN_phase_r.png, _g, _b per frame";

/// The sequence: a recording's frames (`--recording`), or the folders' paired by stem (`--rgb-dir`,
/// `--depth-dir`, `--confidence-dir`, `--depth-encoding`, `--skip-unmatched`), as a [`Recording`].
fn frames_of(args: &VideoArgs) -> Result<Recording> {
    if let Some(dir) = &args.recording {
        if let Some(e) = args.depth.depth_encoding {
            bail!(
                "--depth-encoding {e} with --recording: a recording's depth encoding is its app's (metres for \
                 Record3D's OpenEXR, mm16 for Stray Scanner); leave it out"
            );
        }
        let recording = open_recording(dir)?;
        log::info!(
            "recording {} ({:?}): {} frames{}, depth {}{}",
            dir.display(),
            recording.kind,
            recording.frames.len(),
            recording
                .fps
                .map_or_else(String::new, |f| format!(" at {f:.1} FPS")),
            recording.encoding,
            if recording.frames.iter().any(|f| f.confidence.is_some()) {
                " with confidence maps"
            } else {
                ""
            }
        );
        return Ok(recording);
    }
    let (Some(rgb), Some(depth)) = (&args.rgb_dir, &args.depth_dir) else {
        bail!("give --rgb-dir and --depth-dir, or --recording");
    };
    let encoding = args
        .depth
        .depth_encoding
        .context("--depth-encoding is required (how the depth frames store depth)")?;
    Ok(open_frame_folders(&FrameFolders {
        rgb,
        depth,
        confidence: args.confidence_dir.as_deref(),
        encoding,
        skip_unmatched: args.skip_unmatched,
    })?)
}

/// Runs `stream` over `frames` pulled one ahead on a thread of their own (the next frame loads while the
/// stream computes this one), in order; the loader stops when the stream stops taking frames.
fn loaded_ahead<T: Send, R>(
    frames: impl Iterator<Item = T> + Send,
    stream: impl FnOnce(std::sync::mpsc::IntoIter<T>) -> R,
) -> R {
    std::thread::scope(|scope| {
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        scope.spawn(move || {
            for frame in frames {
                if tx.send(frame).is_err() {
                    break;
                }
            }
        });
        stream(rx.into_iter())
    })
}

/// The file `--save-frames` writes for frame `i`, colour `ch` (`r`, `g`, `b`).
fn frame_file(frames_dir: &Path, i: usize, ch: &str) -> PathBuf {
    frames_dir.join(format!("{i:05}_phase_{ch}.png"))
}

/// report.json's `temporal`: the phase churn between consecutive frames' patterns over the sequence
/// ([`PhaseContinuity`]); `null` for one frame.
fn temporal_summary(summary: Option<TemporalSummary>) -> serde_json::Value {
    match summary {
        None => serde_json::Value::Null,
        Some(s) => json!({
            "transitions": s.transitions,
            "mean_churn_rad": s.mean_churn_rad,
            "max_churn_rad": s.max_churn_rad,
            "mean_above_half_pi": s.mean_above_half_pi,
            "max_above_half_pi": s.max_above_half_pi,
            "align_phase": s.align_phase,
            "definition": "through the linear look-up table (code c = phase 2πc/256): mean wrapped |Δφ| between consecutive frames' codes, radians, and the share of (colour, pixel) values changing by more than π/2",
        }),
    }
}

/// The frame files each frame reads, for the output guards.
fn frame_inputs(frames: &[RecordingFrame]) -> Vec<&Path> {
    frames
        .iter()
        .flat_map(|f| {
            [
                Some(f.rgb.as_path()),
                Some(f.depth.as_path()),
                f.confidence.as_deref(),
            ]
        })
        .flatten()
        .collect()
}

/// Loads one frame of the sequence and checks it has the first frame's size.
fn load_frame(
    files: &RecordingFrame,
    recording: &Recording,
    options: &LoadOptions,
    size: (usize, usize),
) -> tensorholo::Result<RgbdFrame> {
    let (f, _) = load_rgbd_with_confidence(
        &files.rgb,
        &files.depth,
        files.confidence.as_deref(),
        recording.encoding,
        options,
    )?;
    if (f.height(), f.width()) != size {
        return Err(HoloError::ShapeMismatch {
            what: format!("frame {} vs the first frame", files.rgb.display()),
            expected: vec![size.0, size.1],
            got: vec![f.height(), f.width()],
        });
    }
    Ok(f)
}

/// Names frame `i`'s files.
fn frame_context(recording: &Recording, i: usize) -> String {
    let f = &recording.frames[i];
    format!(
        "frame {i} (`{}` + `{}`)",
        f.rgb.display(),
        f.depth.display()
    )
}

/// What the stream's sink does with each frame: the refinement, the temporal state, the saved frames, the
/// report's rows.
struct FrameSink<'a> {
    args: &'a VideoArgs,
    recording: &'a Recording,
    frames_dir: PathBuf,
    refiner: Option<FrameRefiner>,
    temporal: PhaseContinuity,
    rows: Vec<serde_json::Value>,
    first_codes: Option<ndarray::Array3<u8>>,
    written: Vec<PathBuf>,
    /// Seconds spent building SM-LBM targets and iterating.
    refine_s: (f64, f64),
    /// The frame whose error stopped the stream, and whether its refinement failed.
    failed: Option<(usize, bool)>,
}

impl FrameSink<'_> {
    /// Frame `i`'s result (`kept`: the frame's points, for a refinement's SM-LBM target).
    fn take(
        &mut self,
        i: usize,
        kept: Option<&RgbdFrame>,
        out: tensorholo::Result<&SlmFrame>,
    ) -> tensorholo::Result<()> {
        let out = out.inspect_err(|_| self.failed = Some((i, false)))?;
        let refined = match (&mut self.refiner, kept) {
            (Some(r), Some(frame)) => {
                let iterations = r.request().options.iterations;
                let refined = r
                    .refine(
                        &[SceneLayer::from(frame)],
                        None,
                        out.codes.view(),
                        &mut crate::refine::log_progress(iterations),
                    )
                    .inspect_err(|_| self.failed = Some((i, true)))?;
                self.refine_s.0 += refined.target_s;
                self.refine_s.1 += refined.report.iterations_s;
                let report = crate::refine::report(r, &refined, &self.args.refine.core);
                Some((refined, report))
            }
            _ => None,
        };
        let mut codes = refined.as_ref().map_or_else(
            || out.codes.clone(),
            |r: &(RefinedFrame, _)| r.0.codes.clone(),
        );
        let step = self.temporal.next(codes.view_mut())?;
        log_frame(i, out);
        if i == 0 {
            self.first_codes = Some(out.codes.clone());
        }
        if self.args.save_frames {
            for (c, ch) in ["r", "g", "b"].iter().enumerate() {
                let file = frame_file(&self.frames_dir, i, ch);
                save_u8_png(&file, codes.index_axis(Axis(0), c))?;
                self.written.push(file);
            }
        }
        let files = &self.recording.frames[i];
        self.rows.push(json!({
            "index": i,
            "rgb": crate::output::path_text(&files.rgb),
            "depth": crate::output::path_text(&files.depth),
            "confidence": files.confidence.as_deref().map(crate::output::path_text),
            "time_s": files.time_s,
            "timings_s": out.timings,
            "backend": out.backend,
            "amplitude_scale": refined.as_ref().map_or(out.amplitude_scale, |r| r.0.amplitude_scale),
            "refine": refined.map(|r| r.1),
            "temporal": step.map(|s| json!({
                "churn_rad": s.churn.mean_abs_rad,
                "above_half_pi": s.churn.above_half_pi,
                "aligned_shift_codes": s.aligned_shift_codes,
            })),
        }));
        Ok(())
    }
}

/// One frame's stage times in the log.
fn log_frame(i: usize, out: &SlmFrame) {
    let t = out.timings;
    if out.backend == Backend::Gpu {
        log::info!(
            "frame {i} (GPU): packing {:.1} ms, GPU {:.1} ms, period {:.1} ms",
            t.cnn_s * 1e3,
            t.gpu_s * 1e3,
            t.total_s * 1e3
        );
    } else {
        log::info!(
            "frame {i}: CNN {:.1} ms, offset {:.1} ms, pre-filter {:.1} ms, encoding {:.1} ms, period {:.1} ms",
            t.cnn_s * 1e3,
            t.offset_s * 1e3,
            t.prefilter_s * 1e3,
            t.encoding_s * 1e3,
            t.total_s * 1e3
        );
    }
}

/// The output guards: every input folder and file (frames, models, profile, gaze track) kept from `--out`.
fn guard_outputs(args: &VideoArgs, profile_files: &[(&str, PathBuf)]) -> Result<()> {
    let mut guarded: Vec<crate::output::Input> = [
        ("--rgb-dir", &args.rgb_dir),
        ("--depth-dir", &args.depth_dir),
        ("--confidence-dir", &args.confidence_dir),
        ("--recording", &args.recording),
    ]
    .into_iter()
    .filter_map(|(flag, dir)| Some(crate::output::Input::folder(flag, dir.as_ref()?)))
    .collect();
    guarded.extend(args.model.guard_inputs());
    if let Some(track) = &args.model.fovea.gaze_track {
        guarded.push(crate::output::Input::file("--gaze-track", track));
    }
    guarded.extend(
        profile_files
            .iter()
            .map(|(what, f)| crate::output::Input::file(what, f)),
    );
    crate::output::guard("--out", &args.out, &guarded)
}

/// Runs `holo video`.
pub fn run(args: &VideoArgs) -> Result<()> {
    // The display profile, read once: a bad one stops the command before anything is written; the files it
    // names are inputs too.
    let profile = args.model.profile()?;
    let profile_files = crate::model_args::ModelArgs::profile_files(profile.as_ref());
    let t_all = Instant::now();
    guard_outputs(args, &profile_files)?;
    let refine = args.refine.request(true)?;
    args.refine.core.check_display_model_use(false)?;
    let mut recording = frames_of(args)?;
    let recorded_frames = recording.frames.len();
    if let Some(n) = args.limit {
        if n == 0 {
            bail!("--limit must be at least 1");
        }
        recording.frames.truncate(n);
    }
    // Foveated frames: one gaze for every frame (--gaze) or a row per frame (--gaze-track).
    let n = recording.frames.len();
    let gazes = match (args.model.fovea.gaze()?, &args.model.fovea.gaze_track) {
        (Some(g), _) => Some(vec![g; n]),
        (None, Some(track)) => Some(crate::fovea::read_gaze_track(track, n)?),
        (None, None) => None,
    };
    let inputs = frame_inputs(&recording.frames);
    ensure_not_input(&args.out.join("report.json"), &inputs)?;
    let frames_dir = args.out.join("frames");
    if args.save_frames {
        // Every frame file is checked before the first is written (the input folder may be --out/frames).
        for i in 0..n {
            for ch in ["r", "g", "b"] {
                ensure_not_input(&frame_file(&frames_dir, i, ch), &inputs)?;
            }
        }
    }
    let subfolders: &[&Path] = if args.save_frames {
        &[&frames_dir]
    } else {
        &[]
    };
    // A display no model serves stops the command before anything is written (an old report goes).
    let (pipeline, models) = crate::output::before_writing(
        &args.out,
        args.model
            .pipeline(tensorholo::model::SceneInput::Rgbd, profile.as_ref()),
    )?;
    // What this run creates, removed again if it fails: a refused video leaves nothing (its old report is gone
    // already, so the folder does not read as a complete run).
    let created: Vec<PathBuf> = [&args.out, &frames_dir]
        .into_iter()
        .filter(|d| !d.exists())
        .cloned()
        .collect();
    crate::output::start_run(&args.out, subfolders, Some(&args.out.join("report.json")))?;
    let mut written: Vec<PathBuf> = Vec::new();
    let run = Video {
        args,
        recording: &recording,
        recorded_frames,
        pipeline: &pipeline,
        gazes: gazes.as_deref(),
        refine,
        frames_dir,
    };
    let result = run
        .stream(&mut written)
        .and_then(|(streamed, session)| run.report(streamed, session, models, t_all));
    if result.is_err() {
        remove_written(&written, &created);
    }
    result
}

/// One `holo video` run, its inputs checked and its outputs guarded.
struct Video<'a> {
    args: &'a VideoArgs,
    recording: &'a Recording,
    /// The recording's frames before `--limit`.
    recorded_frames: usize,
    pipeline: &'a HologramPipeline,
    gazes: Option<&'a [Gaze]>,
    refine: Option<FrameRefinement>,
    frames_dir: PathBuf,
}

/// What the stream left for the report.
struct Streamed {
    frames: usize,
    size: (usize, usize),
    range: Option<DepthRange>,
    options: LoadOptions,
    session_s: f64,
    stream_s: f64,
    rows: Vec<serde_json::Value>,
    first_codes: Option<ndarray::Array3<u8>>,
    temporal: Option<TemporalSummary>,
    refine_s: (f64, f64),
}

impl Video<'_> {
    /// The session on the first frame's size, then every frame through it (the next frame decoded on a thread
    /// of its own while this one computes). `written`: the files written so far.
    fn stream(&self, written: &mut Vec<PathBuf>) -> Result<(Streamed, HologramSession)> {
        let (args, recording) = (self.args, self.recording);
        // One metric range for the whole sequence (the first frame's percentiles unless given), so that the
        // depth mapping does not flicker from frame to frame.
        let mut options = args.depth.load_options()?;
        let first_files = &recording.frames[0];
        let (first, first_report) = load_rgbd_with_confidence(
            &first_files.rgb,
            &first_files.depth,
            first_files.confidence.as_deref(),
            recording.encoding,
            &options,
        )
        .with_context(|| format!("frame 0 (`{}`)", first_files.rgb.display()))?;
        if options.range.is_none() {
            options.range = first_report.range_used;
        }
        let size = (first.height(), first.width());
        let t = Instant::now();
        let mut session = self
            .pipeline
            .session(size.0, size.1)
            .map_err(|e| args.model.plans.blame(e))?;
        let session_s = t.elapsed().as_secs_f64();
        args.model
            .plans
            .write_tuning(&args.out, session.plan_report())?;
        if args.model.plans.tune {
            written.push(args.out.join("tuning.json"));
        }
        log::info!(
            "{} frames of {}×{}, depth range {:?} m, {}-layer CNN {}, offset {} mm",
            recording.frames.len(),
            size.0,
            size.1,
            options.range.map(|r| (r.z_near_m, r.z_far_m)),
            args.model.layers,
            args.model.precision(),
            self.pipeline.config().offset_m * 1e3
        );
        let temporal = PhaseContinuity::new(args.align_phase, self.pipeline.calibration().is_some())
            .map_err(|_| {
                anyhow::anyhow!(
                    "--align-phase shifts the codes, which is a global phase only through the linear look-up \
                     table; this run sends its codes through a display calibration (--calibration or the \
                     --display profile's)"
                )
            })?;
        let refiner = match self.refine {
            Some(request) => Some(args.refine.core.display_models()?.apply(
                FrameRefiner::for_pipeline(
                    request,
                    self.pipeline,
                    session.backend_report(),
                    args.model.thread_count(),
                )?,
            )?),
            None => None,
        };
        let mut sink = FrameSink {
            args,
            recording,
            frames_dir: self.frames_dir.clone(),
            refiner,
            temporal,
            rows: Vec::new(),
            first_codes: None,
            written: Vec::new(),
            refine_s: (0.0, 0.0),
            failed: None,
        };
        let t_stream = Instant::now();
        let refining = self.refine.is_some();
        let frames = recording.frames.iter().enumerate().map(|(i, p)| {
            let t = Instant::now();
            let frame = load_frame(p, recording, &options, size).inspect(|_| {
                log::debug!(
                    "loaded {} in {:.1} ms",
                    p.rgb.display(),
                    t.elapsed().as_secs_f64() * 1e3
                )
            });
            // A refinement needs the frame's points again (its SM-LBM target) after the CNN has it.
            let kept = match (refining, &frame) {
                (true, Ok(f)) => Some(f.clone()),
                _ => None,
            };
            ((i, kept), frame)
        });
        let take = |(i, kept): (usize, Option<RgbdFrame>), out: tensorholo::Result<&SlmFrame>| {
            sink.take(i, kept.as_ref(), out)
        };
        let streamed = loaded_ahead(frames, |frames| match self.gazes {
            None => session.render_stream_each(frames, take),
            Some(gazes) => session.render_foveated_stream_each(
                frames.map(|((i, kept), frame)| ((i, kept), frame.map(|f| (f, gazes[i])))),
                take,
            ),
        });
        written.append(&mut sink.written);
        let count = streamed.with_context(|| match sink.failed {
            Some((i, true)) => format!("refining {}", frame_context(recording, i)),
            Some((i, false)) => frame_context(recording, i),
            None => "the video stream".to_string(),
        })?;
        Ok((
            Streamed {
                frames: count,
                size,
                range: options.range,
                options,
                session_s,
                stream_s: t_stream.elapsed().as_secs_f64(),
                rows: sink.rows,
                first_codes: sink.first_codes,
                temporal: sink.temporal.summary(),
                refine_s: sink.refine_s,
            },
            session,
        ))
    }

    /// Checks the streamed first frame against a single-frame render of it and writes report.json.
    fn report(
        &self,
        s: Streamed,
        mut session: HologramSession,
        models: serde_json::Value,
        t_all: Instant,
    ) -> Result<()> {
        let (args, recording) = (self.args, self.recording);
        // The streamed output must equal a single-frame render of the same frame.
        let first_frame = load_frame(&recording.frames[0], recording, &s.options, s.size)?;
        let single = match self.gazes {
            Some(g) => session.render_foveated(&first_frame, &g[0])?,
            None => session.render(&first_frame)?,
        }
        .codes
        .clone();
        let identical = s.first_codes.as_ref() == Some(&single);
        if !identical {
            log::warn!("streamed frame 0 differs from its single-frame render");
        }
        let periods: Vec<f64> = s
            .rows
            .iter()
            .skip(1)
            .filter_map(|r| r["timings_s"]["total_s"].as_f64())
            .collect();
        let mean_period = if periods.is_empty() {
            s.stream_s / s.frames.max(1) as f64
        } else {
            periods.iter().sum::<f64>() / periods.len() as f64
        };
        let fps_steady = if mean_period > 0.0 {
            1.0 / mean_period
        } else {
            0.0
        };
        // An app's export is a recording in the report; folders paired by stem are not.
        let app = (recording.kind != RecordingKind::FrameFolders).then_some(recording);
        let report = json!({
            "tensorholo_version": env!("CARGO_PKG_VERSION"),
            "command": crate::output::command_line(),
            "frames": s.frames,
            "size": [s.size.0, s.size.1],
            "depth_range_m": s.range.map(|r| [r.z_near_m, r.z_far_m]),
            "depth_encoding": recording.encoding,
            "recording": app.map(|r| json!({
                "kind": r.kind,
                "dir": crate::output::path_text(&r.dir),
                "fps": r.fps,
                "intrinsics_px": r.intrinsics,
                "frames": self.recorded_frames,
                "confidence_maps": r.frames.iter().any(|f| f.confidence.is_some()),
            })),
            "models": models,
            "pipeline": self.pipeline.config(),
            "session_setup_s": s.session_s,
            "cnn_plan": session.plan_report(),
            "backend": session.backend_report(),
            "stream_s": s.stream_s,
            "fps_overall": s.frames as f64 / s.stream_s,
            "fps_steady": fps_steady,
            "mean_period_after_first_s": mean_period,
            "stream_equals_single_frame": identical,
            "fovea": self.gazes.map(|_| json!({
                "gaze": if args.model.fovea.gaze_track.is_some() { "track" } else { "fixed" },
                "gaze_track": args.model.fovea.gaze_track.as_deref().map(crate::output::path_text),
                "first_frame": session.fovea_report(),
            })),
            "refine_target_s": self.refine.map(|_| s.refine_s.0),
            "refine_iterations_s": self.refine.map(|_| s.refine_s.1),
            "temporal": temporal_summary(s.temporal),
            "per_frame": s.rows,
            "total_s": t_all.elapsed().as_secs_f64(),
        });
        crate::args::write_json(&args.out.join("report.json"), &report)?;
        log::info!(
            "{} frames in {:.2} s: {:.2} FPS overall, {fps_steady:.2} FPS after the first frame; report in {}",
            s.frames,
            s.stream_s,
            s.frames as f64 / s.stream_s,
            args.out.display()
        );
        Ok(())
    }
}

/// Removes the files a failed run wrote (never a device or a FIFO it wrote into), then the folders it created
/// if they are empty, innermost first.
fn remove_written(written: &[PathBuf], created: &[PathBuf]) {
    for path in written {
        let _ = tensorholo::io::remove_output(path);
    }
    for dir in created.iter().rev() {
        let _ = std::fs::remove_dir(dir);
    }
}
