//! Proves that after warm-up a CPU frame allocates nothing on the heap: a counting global allocator counts
//! every allocation of every thread (the colour workers included) around `HologramSession::render`. With the
//! native CNN engine the hologram CNN writes its heads straight into the colour workers' planes (a lean
//! session, `set_full_outputs(false)`, as the app library's generator runs) or into the two heads arrays a
//! session with full outputs keeps (`last_heads`, reused from frame to frame and read by the colour workers
//! where they are), and the pre-filter into the workers' idle complex fields.
//! Everything else (the CNN input read in place, offset propagation, double phase encoding, the calibrated
//! per-pixel look-up table, the output copy) runs in the session's own buffers. A tract session is counted
//! too, as a check that the counter sees the CNNs.
//!
//! Two allocations are allowed besides, in 5 frames, of at most 4,120 bytes each: rayon's job queues. A call
//! into a thread pool from outside it (each CNN plan's pool once per frame, the session's optics pool twice:
//! the encoding's two passes) pushes one job onto the pool's injector queue (crossbeam-deque's `Injector`),
//! which allocates its next block of 63 slots (1,520 bytes on x86-64) when one fills: a block every 63 frames
//! of a CNN pool, every 32 of the optics pool, whose turn may fall in the frames counted (it did in CI,
//! after the session's setup had timed its thread counts on the pool). And a pool thread's own deque
//! (crossbeam-deque's `Worker`) doubles its buffer when jobs queue up faster than the other thread steals
//! them, and halves it again later: on a loaded machine, 64 → 128 slots of 16 bytes (2,072 bytes with the
//! header; seen with two busy loops beside the test), 4,120 bytes for 256.
//!
//! This binary holds a single test so that no other test allocates concurrently.

use std::alloc::System;
use std::path::Path;
use std::sync::Arc;

use ndarray::{Array2, Array3};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};
use tensorholo::cnn::{cnn_plan, CnnEngine, CnnOptions, PlanRequest, ThreadCount};
use tensorholo::display::{AberrationProfile, AberrationSample};
use tensorholo::foveation::{FoveaRadius, FoveationOptions, Gaze};
use tensorholo::model::{HologramModel, ModelConfig, ModelKind};
use tensorholo::optics::ZernikeCoefficients;
use tensorholo::pipeline::{Backend, HologramPipeline, PipelineConfig};
use tensorholo::scene::RgbdFrame;
use tensorholo::slm::{DisplayCalibration, LutRepresentation, PhaseCurve, PhaseLut, TiledCurves};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// Allocations (including reallocations) of all threads while `f` runs, and the bytes they took.
fn allocations_during<T>(f: impl FnOnce() -> T) -> ((usize, usize), T) {
    let region = Region::new(GLOBAL);
    let out = f();
    let stats = region.change();
    (
        (
            stats.allocations + stats.reallocations,
            stats.bytes_allocated + stats.bytes_reallocated.max(0) as usize,
        ),
        out,
    )
}

/// The most bytes of one of rayon's queue allocations: an injector block or a deque buffer of 256 slots (see
/// the module docs).
const QUEUE_BLOCK_BYTES: usize = 4120;
/// The most queue allocations in the frames counted (see the module docs).
const QUEUE_BLOCKS: usize = 2;

/// Checks that `(count, bytes)` allocations are the `expected` ones of `expected_bytes` in all, or those and
/// at most [`QUEUE_BLOCKS`] of rayon's queue allocations.
fn assert_only((count, bytes): (usize, usize), expected: usize, expected_bytes: usize, what: &str) {
    let queue = count.saturating_sub(expected);
    assert!(
        count >= expected && queue <= QUEUE_BLOCKS,
        "{what}: {count} allocations, expected {expected} (and at most {QUEUE_BLOCKS} rayon queue blocks)"
    );
    assert!(
        bytes >= expected_bytes && bytes <= expected_bytes + queue * QUEUE_BLOCK_BYTES,
        "{what}: {bytes} bytes allocated, expected {expected_bytes} (+ {queue} queue block(s))"
    );
}

fn load(name: &str, kind: ModelKind) -> Arc<HologramModel> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/models")
        .join(name);
    Arc::new(HologramModel::from_path(path, kind, &ModelConfig::default()).unwrap())
}

#[test]
fn cpu_frames_allocate_nothing_after_warm_up() {
    let (h, w) = (32, 48);
    let frames: Vec<RgbdFrame> = (0..6)
        .map(|i| {
            let amp = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
                ((x * 3 + y * 5 + c + i) % 9) as f32 / 8.0
            });
            let depth = Array2::from_shape_fn((h, w), |(y, x)| ((x + y + i) % 7) as f32 / 6.0);
            RgbdFrame::new(amp, depth).unwrap()
        })
        .collect();
    // A per-pixel (tiled) look-up table on every colour.
    let mut cal = DisplayCalibration::linear(h, w).unwrap();
    for (c, col) in cal.colours.iter_mut().enumerate() {
        let curves = (0..4 * 6)
            .map(|t| PhaseCurve::gamma(7.0 + 0.05 * (t + c) as f32, 1.1).unwrap())
            .collect();
        let tiles = TiledCurves::new(h, w, 8, 8, curves).unwrap();
        col.lut = PhaseLut::new(LutRepresentation::Tiled(tiles));
    }
    let cal = Arc::new(cal);
    // The viewer's aberration correction (astigmatism, per colour): one more spectral multiply per row.
    let aberration = Arc::new(
        AberrationProfile::new(vec![AberrationSample {
            distance_m: 0.0,
            coefficients: [0.5, 1.0, 2.0].map(|a| ZernikeCoefficients {
                astigmatism_oblique: a,
                ..ZernikeCoefficients::ZERO
            }),
        }])
        .unwrap(),
    );
    for (prefilter, calibrated, corrected) in [
        (true, false, false),
        (false, false, false),
        (false, true, false),
        (false, false, true),
    ] {
        let pre = prefilter.then(|| load("holo8_rgbd.prefilter.onnx", ModelKind::PreFilter));
        let hologram = load("holo8_rgbd.onnx", ModelKind::Hologram);
        let engines: &[CnnEngine] = if cfg!(feature = "tract") {
            &[CnnEngine::Native, CnnEngine::Tract]
        } else {
            &[CnnEngine::Native]
        };
        for (&engine, full) in engines.iter().flat_map(|e| [(e, true), (e, false)]) {
            let config = PipelineConfig {
                offset_m: 6e-3,
                // Allocation counting is about the CPU path's colour workers.
                backend: Backend::Cpu,
                cnn: CnnOptions {
                    engine,
                    ..CnnOptions::default()
                },
                ..PipelineConfig::default()
            };
            let mut pipeline =
                HologramPipeline::new(hologram.clone(), pre.clone(), config).unwrap();
            if calibrated {
                pipeline = pipeline.with_calibration(cal.clone()).unwrap();
            }
            if corrected {
                pipeline = pipeline.with_aberration(aberration.clone()).unwrap();
            }
            let mut session = pipeline.session(h, w).unwrap();
            session.set_full_outputs(full);
            // Warm-up: thread-local channel contexts, the CNNs' first run.
            session.render(&frames[0]).unwrap();
            let (mut allocations, mut bytes) = (0, 0);
            let mut last = session.output().codes.clone();
            for f in &frames[1..] {
                let ((n, b), r) = allocations_during(|| session.render(f).map(|_| ()));
                r.unwrap();
                allocations += n;
                bytes += b;
                assert_ne!(session.output().codes, last, "frames must differ");
                if calibrated {
                    // The calibrated tables ran: their codes are not the linear table's of the same phase.
                    let linear =
                        tensorholo::encoding::phase_to_codes(session.output().phase.view());
                    assert_ne!(
                        session.output().codes,
                        linear,
                        "the calibration was not applied"
                    );
                }
                last = session.output().codes.clone();
            }
            println!(
                "{engine}, pre-filter {prefilter}, calibrated {calibrated}, corrected {corrected}, full \
                 outputs {full}: \
                 {allocations} allocations in 5 frames"
            );
            match engine {
                CnnEngine::Native => {
                    assert_only((allocations, bytes), 0, 0, "nothing");
                    if full {
                        // The kept heads are this frame's: the midpoint hologram of the last frame's codes.
                        let heads = session.last_heads().expect("full outputs keep the heads");
                        assert!(heads.amplitude.iter().any(|&a| a > 0.0));
                    }
                }
                _ => assert!(
                    allocations > 5 * 2,
                    "the counter must see tract's allocations"
                ),
            }
        }
    }

    // Foveated frames (the hologram and pre-filter CNNs on their tiles, the periphery's tables, the gaze's
    // window): a gaze that jumps across the frame, each corner, allocates nothing either.
    let gazes = [
        (24.0, 16.0),
        (0.0, 0.0),
        (47.5, 31.5),
        (-0.5, 31.0),
        (40.0, 2.0),
    ];
    for full in [true, false] {
        let config = PipelineConfig {
            offset_m: 6e-3,
            backend: Backend::Cpu,
            cnn: CnnOptions {
                engine: CnnEngine::Native,
                ..CnnOptions::default()
            },
            foveation: Some(FoveationOptions {
                radius: FoveaRadius::Pixels { pixels: 5.0 },
                band_px: 4.0,
                ..FoveationOptions::default()
            }),
            ..PipelineConfig::default()
        };
        let pre = load("holo8_rgbd.prefilter.onnx", ModelKind::PreFilter);
        let hologram = load("holo8_rgbd.onnx", ModelKind::Hologram);
        let pipeline = HologramPipeline::new(hologram, Some(pre), config).unwrap();
        let mut session = pipeline.session(h, w).unwrap();
        session.set_full_outputs(full);
        let gaze = |(x, y)| Gaze {
            x,
            y,
            depth_m: None,
        };
        session
            .render_foveated(&frames[0], &gaze(gazes[0]))
            .unwrap();
        let (mut allocations, mut bytes) = (0, 0);
        for (f, &g) in frames[1..].iter().zip(&gazes) {
            let ((n, b), r) =
                allocations_during(|| session.render_foveated(f, &gaze(g)).map(|_| ()));
            r.unwrap();
            assert!(!session.fovea_report().unwrap().covers_frame);
            allocations += n;
            bytes += b;
        }
        println!("foveated, full outputs {full}: {allocations} allocations in 5 frames");
        assert_only((allocations, bytes), 0, 0, "foveated frames");
    }

    // The native CNN engine, 1 and 2 threads: after warm-up a run allocates exactly its two output arrays
    // (the plan's contract returns owned arrays); every activation buffer and the thread pool are the plan's.
    let model = load("holo8_rgbd.onnx", ModelKind::Hologram);
    let input = Array3::from_shape_fn((4, h, w), |(c, y, x)| {
        ((c + 2 * y + 3 * x) % 10) as f32 / 9.0
    });
    for threads in [1, 2] {
        let request = PlanRequest {
            cnn: CnnOptions {
                engine: CnnEngine::Native,
                threads: ThreadCount::Fixed(threads),
                ..CnnOptions::default()
            },
            ..PlanRequest::default()
        };
        let (mut plan, _) = cnn_plan(&model, h, w, &request).unwrap();
        plan.run_outputs(input.view()).unwrap();
        let ((n, bytes), _) = allocations_during(|| {
            for _ in 0..5 {
                plan.run_outputs(input.view()).unwrap();
            }
        });
        println!("native engine, {threads} thread(s): {n} allocations in 5 runs");
        // The heads: amplitude and phase, `[3, H, W]` f32 each.
        assert_only(
            (n, bytes),
            5 * 2,
            5 * 2 * 3 * h * w * 4,
            &format!("{threads} threads"),
        );
    }
}
