//! `holo video`: an RGB-D sequence through one [`HologramSession`](tensorholo::pipeline::HologramSession),
//! with the hologram CNN of frame n + 1 overlapping the optics of frame n; per-frame latency and FPS.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use ndarray::Axis;
use serde_json::json;
use tensorholo::encoding::{align_global_phase, phase_churn, PhaseChurn};
use tensorholo::io::{ensure_not_input, save_u8_png};
use tensorholo::pipeline::Backend;
use tensorholo::refine::FrameRefiner;
use tensorholo::scene::{
    load_rgbd_with_confidence, open_recording, DepthEncoding, DepthRange, LoadOptions, Recording,
    RgbdFrame,
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

/// One frame's files (and time, from a recording).
#[derive(Debug, Clone)]
struct FrameFiles {
    rgb: PathBuf,
    depth: PathBuf,
    confidence: Option<PathBuf>,
    time_s: Option<f64>,
}

/// The sequence's frames and their depth encoding: a recording's (`--recording`), or the folders' paired by
/// stem (`--rgb-dir`, `--depth-dir`, `--confidence-dir`, `--depth-encoding`).
fn frames_of(args: &VideoArgs) -> Result<(Vec<FrameFiles>, DepthEncoding, Option<Recording>)> {
    if let Some(dir) = &args.recording {
        if let Some(e) = args.depth.depth_encoding {
            bail!(
                "--depth-encoding {e} with --recording: a recording's depth encoding is its app's (metres for \
                 Record3D's OpenEXR, mm16 for Stray Scanner); leave it out"
            );
        }
        let recording = open_recording(dir)?;
        let frames = recording
            .frames
            .iter()
            .map(|f| FrameFiles {
                rgb: f.rgb.clone(),
                depth: f.depth.clone(),
                confidence: f.confidence.clone(),
                time_s: f.time_s,
            })
            .collect();
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
        return Ok((frames, recording.encoding, Some(recording)));
    }
    let (Some(rgb_dir), Some(depth_dir)) = (&args.rgb_dir, &args.depth_dir) else {
        bail!("give --rgb-dir and --depth-dir, or --recording");
    };
    let encoding = args
        .depth
        .depth_encoding
        .context("--depth-encoding is required (how the depth frames store depth)")?;
    let mut frames: Vec<FrameFiles> = pair_frames(rgb_dir, depth_dir, args.skip_unmatched)?
        .into_iter()
        .map(|(rgb, depth)| FrameFiles {
            rgb,
            depth,
            confidence: None,
            time_s: None,
        })
        .collect();
    if let Some(dir) = &args.confidence_dir {
        let maps: std::collections::HashMap<std::ffi::OsString, PathBuf> = list_files(dir)?
            .into_iter()
            .filter_map(|p| Some((p.file_stem()?.to_owned(), p)))
            .collect();
        for f in &mut frames {
            let map = f.depth.file_stem().and_then(|s| maps.get(s)).with_context(|| {
                format!(
                    "depth frame `{}` has no confidence map of the same name stem in --confidence-dir {}",
                    f.depth.display(),
                    dir.display()
                )
            })?;
            f.confidence = Some(map.clone());
        }
    }
    Ok((frames, encoding, None))
}

/// The files of `dir`, sorted by name, hidden files (`.DS_Store`) left out.
fn list_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read folder {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .filter(|p| {
            !p.file_name()
                .is_some_and(|n| n.as_encoded_bytes().starts_with(b"."))
        })
        .collect();
    v.sort();
    Ok(v)
}

/// Pairs the files of the two folders by stem (sorted by name; hidden files such as `.DS_Store` are ignored).
/// A file of either folder without a partner is an error naming it, unless `skip_unmatched` (then a warning).
fn pair_frames(
    rgb_dir: &Path,
    depth_dir: &Path,
    skip_unmatched: bool,
) -> Result<Vec<(PathBuf, PathBuf)>> {
    let (rgbs, depths) = (list_files(rgb_dir)?, list_files(depth_dir)?);
    let by_stem = |files: &[PathBuf]| -> std::collections::HashMap<std::ffi::OsString, PathBuf> {
        files
            .iter()
            .filter_map(|p| Some((p.file_stem()?.to_owned(), p.clone())))
            .collect()
    };
    let (rgb_stems, depth_stems) = (by_stem(&rgbs), by_stem(&depths));
    let mut pairs = Vec::new();
    let mut unmatched = Vec::new();
    for rgb in &rgbs {
        match rgb.file_stem().and_then(|s| depth_stems.get(s)) {
            Some(d) => pairs.push((rgb.clone(), d.clone())),
            None => unmatched.push(rgb.clone()),
        }
    }
    unmatched.extend(
        depths
            .iter()
            .filter(|d| d.file_stem().is_none_or(|s| !rgb_stems.contains_key(s)))
            .cloned(),
    );
    if !unmatched.is_empty() {
        let names: Vec<String> = unmatched
            .iter()
            .take(5)
            .map(|p| p.display().to_string())
            .collect();
        let more = unmatched.len().saturating_sub(5);
        let list = format!(
            "{}{}",
            names.join(", "),
            if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            }
        );
        if !skip_unmatched {
            bail!(
                "{} file(s) have no partner of the same name stem in the other folder: {list}; pair them, or \
                 pass --skip-unmatched to leave them out",
                unmatched.len()
            );
        }
        log::warn!(
            "skipping {} file(s) without a partner: {list}",
            unmatched.len()
        );
    }
    if pairs.is_empty() {
        bail!(
            "no RGB frame in {} has a depth frame of the same name stem in {}",
            rgb_dir.display(),
            depth_dir.display()
        );
    }
    Ok(pairs)
}

/// The file `--save-frames` writes for frame `i`, colour `ch` (`r`, `g`, `b`).
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

fn frame_file(frames_dir: &Path, i: usize, ch: &str) -> PathBuf {
    frames_dir.join(format!("{i:05}_phase_{ch}.png"))
}

/// report.json's `temporal`: the phase churn between consecutive frames' patterns
/// ([`tensorholo::encoding::phase_churn`]) over the sequence; `null` for one frame.
fn temporal_summary(churns: &[PhaseChurn], aligned: bool) -> serde_json::Value {
    if churns.is_empty() {
        return serde_json::Value::Null;
    }
    let n = churns.len() as f64;
    let mean = |f: fn(&PhaseChurn) -> f64| churns.iter().map(f).sum::<f64>() / n;
    let max = |f: fn(&PhaseChurn) -> f64| churns.iter().map(f).fold(0.0, f64::max);
    json!({
        "transitions": churns.len(),
        "mean_churn_rad": mean(|c| c.mean_abs_rad),
        "max_churn_rad": max(|c| c.mean_abs_rad),
        "mean_above_half_pi": mean(|c| c.above_half_pi),
        "max_above_half_pi": max(|c| c.above_half_pi),
        "align_phase": aligned,
        "definition": "through the linear look-up table (code c = phase 2πc/256): mean wrapped |Δφ| between consecutive frames' codes, radians, and the share of (colour, pixel) values changing by more than π/2",
    })
}

/// Runs `holo video`.
pub fn run(args: &VideoArgs) -> Result<()> {
    // The display profile, read once: a bad one stops the command before anything is written; the files it
    // names are inputs too.
    let profile = args.model.profile()?;
    let profile_files = crate::model_args::ModelArgs::profile_files(profile.as_ref());
    let t_all = Instant::now();
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
    crate::output::guard("--out", &args.out, &guarded)?;
    let refine = args.refine.request(true)?;
    args.refine.core.check_display_model_use(false)?;
    let (mut pairs, encoding, recording) = frames_of(args)?;
    if let Some(n) = args.limit {
        if n == 0 {
            bail!("--limit must be at least 1");
        }
        pairs.truncate(n);
    }
    // Foveated frames: one gaze for every frame (--gaze) or a row per frame (--gaze-track).
    let gazes = match (args.model.fovea.gaze()?, &args.model.fovea.gaze_track) {
        (Some(g), _) => Some(vec![g; pairs.len()]),
        (None, Some(track)) => Some(crate::fovea::read_gaze_track(track, pairs.len())?),
        (None, None) => None,
    };
    let inputs: Vec<&Path> = pairs
        .iter()
        .flat_map(|f| {
            [
                Some(f.rgb.as_path()),
                Some(f.depth.as_path()),
                f.confidence.as_deref(),
            ]
        })
        .flatten()
        .collect();
    ensure_not_input(&args.out.join("report.json"), &inputs)?;
    let frames_dir = args.out.join("frames");
    if args.save_frames {
        // Every frame file is checked before the first is written (the input folder may be --out/frames).
        for i in 0..pairs.len() {
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
    let result = (|| -> Result<()> {
        // One metric range for the whole sequence (the first frame's percentiles unless given), so that the
        // depth mapping does not flicker from frame to frame.
        let mut options = args.depth.load_options()?;
        let first_files = &pairs[0];
        let (first, first_report) = load_rgbd_with_confidence(
            &first_files.rgb,
            &first_files.depth,
            first_files.confidence.as_deref(),
            encoding,
            &options,
        )
        .with_context(|| format!("frame 0 (`{}`)", first_files.rgb.display()))?;
        if options.range.is_none() {
            options.range = first_report.range_used;
        }
        let range: Option<DepthRange> = options.range;
        let (h, w) = (first.height(), first.width());
        let t = Instant::now();
        let mut session = pipeline
            .session(h, w)
            .map_err(|e| args.model.plans.blame(e))?;
        let session_s = t.elapsed().as_secs_f64();
        args.model
            .plans
            .write_tuning(&args.out, session.plan_report())?;
        if args.model.plans.tune {
            written.push(args.out.join("tuning.json"));
        }
        log::info!(
            "{} frames of {h}×{w}, depth range {:?} m, {}-layer CNN {}, offset {} mm",
            pairs.len(),
            range.map(|r| (r.z_near_m, r.z_far_m)),
            args.model.layers,
            args.model.precision(),
            pipeline.config().offset_m * 1e3
        );

        let loader = |files: &FrameFiles, options: &LoadOptions| -> tensorholo::Result<RgbdFrame> {
            let (f, _) = load_rgbd_with_confidence(
                &files.rgb,
                &files.depth,
                files.confidence.as_deref(),
                encoding,
                options,
            )?;
            if (f.height(), f.width()) != (h, w) {
                return Err(HoloError::ShapeMismatch {
                    what: format!("frame {} vs the first frame", files.rgb.display()),
                    expected: vec![h, w],
                    got: vec![f.height(), f.width()],
                });
            }
            Ok(f)
        };
        if args.align_phase && pipeline.calibration().is_some() {
            bail!(
                "--align-phase shifts the codes, which is a global phase only through the linear look-up table; \
                 this run sends its codes through a display calibration (--calibration or the --display profile's)"
            );
        }
        let mut rows = Vec::new();
        let mut first_codes = None;
        // The last pattern sent, for the churn and the alignment.
        let mut previous: Option<ndarray::Array3<u8>> = None;
        let mut churns = Vec::new();
        let mut refiner = match refine {
            Some(request) => Some(
                FrameRefiner::for_pipeline(
                    request,
                    &pipeline,
                    session.backend_report(),
                    args.model.thread_count(),
                )?
                .with_display_model(args.refine.core.display_model()?)
                .map_err(|e| anyhow::Error::new(e).context("--display-model"))?,
            ),
            None => None,
        };
        // A refinement's error, to report as it is (the stream stops on it).
        let mut refine_error = None;
        let mut refine_s = (0.0f64, 0.0f64);
        let t_stream = Instant::now();
        let opts = options;
        // The frame whose error stops the stream, to name its files.
        let mut failed = None;
        let frames = pairs.iter().enumerate().map(|(i, p)| {
            let t = Instant::now();
            let frame = loader(p, &opts).inspect(|_| {
                log::debug!(
                    "loaded {} in {:.1} ms",
                    p.rgb.display(),
                    t.elapsed().as_secs_f64() * 1e3
                )
            });
            // A refinement needs the frame's points again (its SM-LBM target) after the CNN has it.
            let kept = match (&refine, &frame) {
                (Some(_), Ok(f)) => Some(f.clone()),
                _ => None,
            };
            ((i, kept), frame)
        });
        let sink = |(i, kept): (usize, Option<RgbdFrame>),
                    out: tensorholo::Result<&tensorholo::pipeline::SlmFrame>| {
            let out = out.inspect_err(|_| failed = Some(i))?;
            let refined = match (&mut refiner, &kept) {
                (Some(r), Some(frame)) => {
                    let iterations = r.request().options.iterations;
                    match r.refine(
                        &[SceneLayer::from(frame)],
                        None,
                        out.codes.view(),
                        &mut crate::refine::log_progress(iterations),
                    ) {
                        Ok(refined) => {
                            refine_s.0 += refined.target_s;
                            refine_s.1 += refined.report.iterations_s;
                            let report = crate::refine::report(r, &refined);
                            Some((refined, report))
                        }
                        Err(e) => {
                            failed = Some(i);
                            // The stream's own error is what stops it; the refinement's is reported.
                            let text = e.to_string();
                            refine_error = Some(e);
                            return Err(HoloError::Cancelled(text));
                        }
                    }
                }
                _ => None,
            };
            let mut codes = refined
                .as_ref()
                .map_or_else(|| out.codes.clone(), |r| r.0.codes.clone());
            let (shifts, churn) = match &previous {
                Some(p) => {
                    let shifts = if args.align_phase {
                        Some(align_global_phase(p.view(), codes.view_mut())?)
                    } else {
                        None
                    };
                    (shifts, Some(phase_churn(p.view(), codes.view())?))
                }
                None => (None, None),
            };
            churns.extend(churn);
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
            if i == 0 {
                first_codes = Some(out.codes.clone());
            }
            if args.save_frames {
                for (c, ch) in ["r", "g", "b"].iter().enumerate() {
                    let file = frame_file(&frames_dir, i, ch);
                    save_u8_png(&file, codes.index_axis(Axis(0), c))?;
                    written.push(file);
                }
            }
            previous = Some(codes);
            rows.push(json!({
                    "index": i,
                    "rgb": crate::output::path_text(&pairs[i].rgb),
                    "depth": crate::output::path_text(&pairs[i].depth),
                    "confidence": pairs[i].confidence.as_deref().map(crate::output::path_text),
                    "time_s": pairs[i].time_s,
                    "timings_s": t,
                    "backend": out.backend,
                    "amplitude_scale": refined.as_ref().map_or(out.amplitude_scale, |r| r.0.amplitude_scale),
                    "refine": refined.map(|r| r.1),
                    "temporal": churn.map(|c| json!({
                        "churn_rad": c.mean_abs_rad,
                        "above_half_pi": c.above_half_pi,
                        "aligned_shift_codes": shifts,
                    })),
                }));
            Ok(())
        };
        // The next frame is decoded on a thread of its own while this one computes.
        let streamed = loaded_ahead(frames, |frames| match &gazes {
            None => session.render_stream_each(frames, sink),
            Some(gazes) => session.render_foveated_stream_each(
                frames.map(|((i, kept), frame)| ((i, kept), frame.map(|f| (f, gazes[i])))),
                sink,
            ),
        });
        if let Some(e) = refine_error {
            let i = failed.unwrap_or(0);
            return Err(anyhow::Error::new(e).context(format!(
                "frame {i} (`{}` + `{}`)",
                pairs[i].rgb.display(),
                pairs[i].depth.display()
            )));
        }
        let n = streamed.with_context(|| match failed {
            Some(i) => format!(
                "frame {i} (`{}` + `{}`)",
                pairs[i].rgb.display(),
                pairs[i].depth.display()
            ),
            None => "the video stream".to_string(),
        })?;
        let stream_s = t_stream.elapsed().as_secs_f64();
        // The streamed output must equal a single-frame render of the same frame.
        let first_frame = loader(&pairs[0], &options)?;
        let single = match &gazes {
            Some(g) => session.render_foveated(&first_frame, &g[0])?,
            None => session.render(&first_frame)?,
        }
        .codes
        .clone();
        let identical = first_codes.as_ref() == Some(&single);
        if !identical {
            log::warn!("streamed frame 0 differs from its single-frame render");
        }
        let periods: Vec<f64> = rows
            .iter()
            .skip(1)
            .filter_map(|r| r["timings_s"]["total_s"].as_f64())
            .collect();
        let mean_period = if periods.is_empty() {
            stream_s / n.max(1) as f64
        } else {
            periods.iter().sum::<f64>() / periods.len() as f64
        };
        let report = json!({
            "tensorholo_version": env!("CARGO_PKG_VERSION"),
            "command": crate::output::command_line(),
            "frames": n,
            "size": [h, w],
            "depth_range_m": range.map(|r| [r.z_near_m, r.z_far_m]),
            "depth_encoding": encoding,
            "recording": recording.as_ref().map(|r| json!({
                "kind": r.kind,
                "dir": crate::output::path_text(&r.dir),
                "fps": r.fps,
                "intrinsics_px": r.intrinsics,
                "frames": r.frames.len(),
                "confidence_maps": r.frames.iter().any(|f| f.confidence.is_some()),
            })),
            "models": models,
            "pipeline": pipeline.config(),
            "session_setup_s": session_s,
            "cnn_plan": session.plan_report(),
            "backend": session.backend_report(),
            "stream_s": stream_s,
            "fps_overall": n as f64 / stream_s,
            "fps_steady": if mean_period > 0.0 { 1.0 / mean_period } else { 0.0 },
            "mean_period_after_first_s": mean_period,
            "stream_equals_single_frame": identical,
            "fovea": gazes.as_ref().map(|_| json!({
                "gaze": if args.model.fovea.gaze_track.is_some() { "track" } else { "fixed" },
                "gaze_track": args.model.fovea.gaze_track.as_deref().map(crate::output::path_text),
                "first_frame": session.fovea_report(),
            })),
            "refine_target_s": refine.map(|_| refine_s.0),
            "refine_iterations_s": refine.map(|_| refine_s.1),
            "temporal": temporal_summary(&churns, args.align_phase),
            "per_frame": rows,
            "total_s": t_all.elapsed().as_secs_f64(),
        });
        crate::args::write_json(&args.out.join("report.json"), &report)?;
        log::info!(
            "{n} frames in {:.2} s: {:.2} FPS overall, {:.2} FPS after the first frame; report in {}",
            stream_s,
            n as f64 / stream_s,
            if mean_period > 0.0 {
                1.0 / mean_period
            } else {
                0.0
            },
            args.out.display()
        );
        Ok(())
    })();
    if result.is_err() {
        remove_written(&written, &created);
    }
    result
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
