//! The fuzz harnesses of tensorholo: one function per parser that user input reaches. Each takes arbitrary
//! bytes, must never panic, abort or allocate beyond the input limits, and checks the invariants of what it
//! accepts. The cargo-fuzz targets (`fuzz_targets/*.rs`, nightly) call these; the stable regression test
//! (`tests/fuzz_regressions.rs` of the workspace's integration-test crate) includes this file and replays every
//! input committed under `tests/fixtures/fuzz/<target>/`. How to run them: `docs/FUZZING.md`.
//!
//! Only `tensorholo`, `serde_json` and `crc32fast` are used here, so the file compiles in both places.

use std::path::Path;

use tensorholo::model::{HologramModel, ModelConfig, ModelKind};
use tensorholo::scene::{
    decode_depth_bytes, decode_rgb_bytes, CameraFrame, ColorFormat, ColorImage, DepthEncoding,
    DepthFormat, DepthImage, DepthRange, Fit, FrameOptions, Rotation,
};
use tensorholo::slm::DisplayCalibration;

/// Input limits of the harnesses: 4 M pixels a decoded image, 16 MiB a file. Lower than the defaults (100 M,
/// 4 GiB) so that an input whose header declares a huge image is refused or decoded quickly; the limit logic is
/// the same.
pub const FUZZ_LIMITS: tensorholo::io::InputLimits = tensorholo::io::InputLimits {
    max_image_pixels: 1 << 22,
    max_file_bytes: 1 << 24,
};

fn init() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| tensorholo::io::set_input_limits(FUZZ_LIMITS).expect("valid limits"));
}

/// A harness: arbitrary bytes in, a panic on a violated invariant.
pub type Harness = fn(&[u8]);

/// The harnesses by target name, for the regression test.
pub const TARGETS: [(&str, Harness); 16] = [
    ("depth_decode", depth_decode),
    ("rgb_decode", rgb_decode),
    ("npy", npy),
    ("holocal", holocal),
    ("onnx_model", onnx_model),
    ("camera_frame", camera_frame),
    ("display_profile", display_profile),
    ("aberration", aberration),
    ("shard_record", shard_record),
    ("manifest", manifest),
    ("spot_plan", spot_plan),
    ("saved_plans", saved_plans),
    ("exr_depth", exr_depth),
    ("record3d_metadata", record3d_metadata),
    ("stray_odometry", stray_odometry),
    ("stray_camera_matrix", stray_camera_matrix),
];

/// OpenEXR depth maps (`decode_depth_bytes` with the `metres` encoding, Record3D's depth): the header's size
/// and channels are checked against the decoders' budget before any pixel is read (the exr crate's parser is
/// not ours, the budget is). An accepted map is non-empty, within the pixel limit, metric, and its valid
/// samples are finite and positive.
pub fn exr_depth(data: &[u8]) {
    init();
    if let Ok(d) = decode_depth_bytes(data, Path::new("fuzz"), DepthEncoding::Metres) {
        let (h, w) = d.values.dim();
        assert!(
            h * w > 0 && (h * w) as u64 <= FUZZ_LIMITS.max_image_pixels,
            "{h}x{w}"
        );
        assert_eq!(d.valid.dim(), (h, w));
        assert!(d.metric);
        for (&v, &ok) in d.values.iter().zip(d.valid.iter()) {
            assert!(!ok || (v.is_finite() && v > 0.0), "valid depth {v}");
        }
    }
}

/// A recording folder of this thread for the recording harnesses, made once: Record3D's (`rgb/N.jpg`,
/// `depth/N.exr`, N = 0, 1, 2) or Stray Scanner's (`rgb/00000N.png`, `depth/00000N.png`, `odometry.csv` and
/// `camera_matrix.csv` valid). Listing a recording reads no frame, so the frame files are empty; each input
/// replaces one file.
fn recording_dir(kind: &str) -> std::path::PathBuf {
    let thread = format!("{:?}", std::thread::current().id());
    let thread: String = thread.chars().filter(char::is_ascii_digit).collect();
    let dir = std::env::temp_dir().join(format!(
        "tensorholo-fuzz-{kind}-{}-{thread}",
        std::process::id()
    ));
    if !dir.join("depth").is_dir() {
        for sub in ["rgb", "depth"] {
            std::fs::create_dir_all(dir.join(sub)).expect("a scratch folder");
        }
        for i in 0..3 {
            let (rgb, depth) = if kind == "record3d" {
                (format!("rgb/{i}.jpg"), format!("depth/{i}.exr"))
            } else {
                (format!("rgb/{i:06}.png"), format!("depth/{i:06}.png"))
            };
            std::fs::write(dir.join(rgb), b"").expect("a scratch file");
            std::fs::write(dir.join(depth), b"").expect("a scratch file");
        }
        if kind != "record3d" {
            std::fs::write(dir.join("odometry.csv"), STRAY_ODOMETRY).expect("a scratch file");
            std::fs::write(dir.join("camera_matrix.csv"), STRAY_CAMERA).expect("a scratch file");
        }
    }
    dir
}

/// Stray Scanner's `odometry.csv` of frames 0, 1, 2 (a header, then timestamp, frame and pose).
pub const STRAY_ODOMETRY: &str = "timestamp, frame, x, y, z, qx, qy, qz, qw\n\
    0.125, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0\n\
    0.1583, 1, 0.001, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0\n\
    0.1916, 2, 0.002, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0\n";

/// Stray Scanner's `camera_matrix.csv`: the 3 × 3 intrinsics of a 1920 × 1440 colour camera.
pub const STRAY_CAMERA: &str = "1445.3,0.0,962.1\n0.0,1445.3,718.4\n0.0,0.0,1.0\n";

/// The invariants of a listed recording of three frames.
fn check_recording(r: &tensorholo::scene::Recording) {
    assert_eq!(r.frames.len(), 3);
    assert!(
        r.fps.is_none_or(|f| f.is_finite() && f > 0.0),
        "fps {:?}",
        r.fps
    );
    let times: Vec<f64> = r.frames.iter().filter_map(|f| f.time_s).collect();
    assert!(times.iter().all(|t| t.is_finite()), "{times:?}");
    assert!(
        times.windows(2).all(|w| w[0] <= w[1]),
        "frames out of time order: {times:?}"
    );
    if let Some(k) = r.intrinsics {
        assert!(k.iter().all(|v| v.is_finite()), "{k:?}");
    }
}

/// Record3D's `metadata.json` (`scene::open_recording` on an export whose metadata is the input): an accepted
/// file lists the three frames in time order, with a finite positive frame rate if any.
pub fn record3d_metadata(data: &[u8]) {
    init();
    let dir = recording_dir("record3d");
    std::fs::write(dir.join("metadata.json"), data).expect("a scratch file");
    if let Ok(r) = tensorholo::scene::open_recording(&dir) {
        assert_eq!(r.kind, tensorholo::scene::RecordingKind::Record3d);
        check_recording(&r);
    }
}

/// Stray Scanner's `odometry.csv` (`scene::open_recording` on a folder whose odometry is the input): an
/// accepted file gives every frame a distinct finite time, or none, and a finite positive frame rate if any.
pub fn stray_odometry(data: &[u8]) {
    init();
    let dir = recording_dir("stray");
    std::fs::write(dir.join("odometry.csv"), data).expect("a scratch file");
    if let Ok(r) = tensorholo::scene::open_recording(&dir) {
        assert_eq!(r.kind, tensorholo::scene::RecordingKind::StrayScanner);
        check_recording(&r);
        let times: Vec<f64> = r.frames.iter().filter_map(|f| f.time_s).collect();
        assert!(
            times.windows(2).all(|w| w[0] < w[1]),
            "two frames at one time: {times:?}"
        );
    }
}

/// Stray Scanner's `camera_matrix.csv`: accepted intrinsics are finite, with positive focal lengths.
pub fn stray_camera_matrix(data: &[u8]) {
    init();
    let dir = recording_dir("stray-camera");
    std::fs::write(dir.join("camera_matrix.csv"), data).expect("a scratch file");
    if let Ok(r) = tensorholo::scene::open_recording(&dir) {
        check_recording(&r);
        let k = r.intrinsics.expect("a camera matrix was given");
        assert!(k[0] > 0.0 && k[1] > 0.0, "{k:?}");
    }
}

/// Spot calibration plans (`plan.json`, `SpotPlan::from_json_str`, as `holo calibrate aberration simulate | fit`
/// read them). An accepted plan is valid, within the SLM bound profiles share, and reads back from its own
/// JSON as itself.
pub fn spot_plan(data: &[u8]) {
    init();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(p) = tensorholo::slm::spots::SpotPlan::from_json_str(text, "fuzz") {
        p.validate().expect("an accepted plan is valid");
        let [h, w] = p.slm_size;
        assert!(h * w <= tensorholo::display::MAX_SLM_PIXELS, "{h}x{w}");
        let json = serde_json::to_string(&p).expect("a plan serialises");
        let back = tensorholo::slm::spots::SpotPlan::from_json_str(&json, "back")
            .expect("an accepted plan's own JSON reads back");
        assert_eq!(back, p);
    }
}

/// Saved CNN plans (`--tuning FILE`, a `GeneratorConfig`'s `saved_plans`: `SavedPlans::from_json`). An
/// accepted record reads back from its own JSON (sorted) as the same record.
pub fn saved_plans(data: &[u8]) {
    init();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(p) = tensorholo::cnn::SavedPlans::from_json(text) {
        let json = p.to_json();
        let back = tensorholo::cnn::SavedPlans::from_json(&json)
            .expect("an accepted record's own JSON reads back");
        assert_eq!(back.to_json(), json);
    }
}

/// Display profiles (`DisplayProfile::from_json_str`, as `--display` reads them). An accepted profile is
/// valid, within the bounds every command shares, and reads back from its own JSON as itself.
pub fn display_profile(data: &[u8]) {
    init();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(p) = tensorholo::display::DisplayProfile::from_json_str(text) {
        p.validate().expect("an accepted profile is valid");
        let [h, w] = p.resolution;
        assert!(h * w <= tensorholo::display::MAX_SLM_PIXELS, "{h}x{w}");
        assert!(p.offsets_m.len() <= tensorholo::display::MAX_OFFSETS);
        assert!(p.pixel_pitch_m.is_finite() && p.volume_depth_m.is_finite());
        let back = tensorholo::display::DisplayProfile::from_json_str(&p.to_json())
            .expect("a profile's own JSON reads back");
        assert_eq!(back.resolution, p.resolution);
        assert_eq!(back.offsets_m.len(), p.offsets_m.len());
    }
}

/// Aberration files (`AberrationProfile::from_json_str`, `--aberration`). An accepted file's coefficients
/// are finite and its JSON reads back.
pub fn aberration(data: &[u8]) {
    init();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(a) = tensorholo::display::AberrationProfile::from_json_str(text, "fuzz") {
        let json = a.to_json_string();
        let back = tensorholo::display::AberrationProfile::from_json_str(&json, "back")
            .expect("an accepted aberration file's own JSON reads back");
        assert_eq!(back, a);
    }
}

/// Dataset shard records (`<shard>.shard.json`, read by a merge): accepted records are of their format and
/// serialise back to a record that reads as the same.
pub fn shard_record(data: &[u8]) {
    init();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Some(r) = tensorholo::dataset::ShardRecord::from_json_str(text) {
        assert_eq!(r.format, tensorholo::dataset::SHARD_RECORD_FORMAT);
        let json = serde_json::to_string(&r).expect("a record serialises");
        assert_eq!(
            tensorholo::dataset::ShardRecord::from_json_str(&json),
            Some(r)
        );
    }
}

/// Dataset manifests (`manifest.json`, read by training and by a merge's rerun): accepted manifests are of
/// this format and read back from their own JSON.
pub fn manifest(data: &[u8]) {
    init();
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(m) = tensorholo::dataset::Manifest::from_json_str(text, "fuzz") {
        let json = serde_json::to_string(&m).expect("a manifest serialises");
        let back = tensorholo::dataset::Manifest::from_json_str(&json, "back")
            .expect("a manifest's own JSON reads back");
        assert_eq!(back, m);
    }
}

/// Depth decoders (PNG, PGM/PPM with the hand-written Kinect PGM reader, JPEG): byte 0 picks the encoding,
/// the rest is the file. Accepted maps: valid samples finite and (metric encodings) positive.
pub fn depth_decode(data: &[u8]) {
    init();
    let Some((&pick, file)) = data.split_first() else {
        return;
    };
    let encoding = DepthEncoding::ALL[pick as usize % DepthEncoding::ALL.len()];
    if let Ok(d) = decode_depth_bytes(file, Path::new("fuzz"), encoding) {
        assert_eq!(d.values.dim(), d.valid.dim());
        assert!(!d.values.is_empty());
        for (&v, &ok) in d.values.iter().zip(d.valid.iter()) {
            if ok {
                assert!(v.is_finite(), "{encoding}: valid sample {v}");
                if d.metric {
                    assert!(v > 0.0, "{encoding}: valid metric depth {v}");
                }
            }
        }
    }
}

/// Colour image decoding (PNG, JPEG strictly, PNM): accepted images are `[3, H, W]` amplitudes in `[0, 1]`.
pub fn rgb_decode(data: &[u8]) {
    init();
    if let Ok(a) = decode_rgb_bytes(data, Path::new("fuzz")) {
        assert_eq!(a.shape()[0], 3);
        assert!(a.iter().all(|v| (0.0..=1.0).contains(v)));
    }
}

/// The `.npy` complex-field reader: an accepted array holds as many elements as its shape says (the reader
/// must have checked the declared shape against the bytes before allocating).
pub fn npy(data: &[u8]) {
    init();
    if let Ok(a) = tensorholo::io::parse_complex_npy(data, Path::new("fuzz")) {
        assert_eq!(a.len(), a.shape().iter().product::<usize>());
        assert!(a.is_standard_layout());
    }
}

/// The `.holocal` display-calibration parser. Byte 0 odd: the harness rewrites the trailing CRC-32 so that
/// mutations reach the header and payload checks behind the checksum. An accepted file must serialise back to
/// a file that parses to the same bytes again.
pub fn holocal(data: &[u8]) {
    init();
    let Some((&flags, file)) = data.split_first() else {
        return;
    };
    let mut file = file.to_vec();
    if flags & 1 == 1 && file.len() >= 4 {
        let body = file.len() - 4;
        let crc = crc32fast::hash(&file[..body]);
        file[body..].copy_from_slice(&crc.to_le_bytes());
    }
    if let Ok(cal) = DisplayCalibration::from_bytes(&file, "fuzz") {
        let again = cal.to_bytes().expect("a parsed calibration serialises");
        let reparsed = DisplayCalibration::from_bytes(&again, "again").expect("its bytes parse");
        assert_eq!(reparsed.to_bytes().expect("serialises"), again);
    }
}

/// The ONNX model loader with its metadata and contract checks, as both kinds of CNN with the default display,
/// and, for a file that loads, the SDK's own reading of its layers (`HologramModel::cnn_graph`, what the native
/// engine and the GPU run; the load itself in a build without tract).
pub fn onnx_model(data: &[u8]) {
    init();
    for kind in [ModelKind::Hologram, ModelKind::PreFilter] {
        if let Ok(model) = HologramModel::from_bytes(data, kind, &ModelConfig::default()) {
            // What a pipeline asks of a file: the native engine's graph reader, then (with the `tract`
            // feature) tract's parser and typing.
            let _ = tensorholo::cnn::check_runnable(&std::sync::Arc::new(model));
        }
    }
}

/// The camera-frame conversion behind the app bindings (`HologramGenerator.render` of a raw RGBA/BGRA/RGB
/// buffer and a raw f32/f16/u16 depth buffer with row strides and a rotation). Bytes 0–16 describe the
/// buffers (formats, sizes up to 255·257 pixels a side, strides, target size, fit, range); the rest is split
/// between the two buffers. An accepted frame has the target size, amplitudes in `[0, 1]` and depth in
/// `[0, 1]`, all finite.
pub fn camera_frame(data: &[u8]) {
    init();
    if data.len() < 17 {
        return;
    }
    let (head, rest) = data.split_at(17);
    let color_format = ColorFormat::ALL[head[0] as usize % ColorFormat::ALL.len()];
    let depth_format = DepthFormat::ALL[head[1] as usize % DepthFormat::ALL.len()];
    let rotation = [
        Rotation::Deg0,
        Rotation::Deg90,
        Rotation::Deg180,
        Rotation::Deg270,
    ][head[2] as usize % 4];
    let fit = [Fit::Crop, Fit::Letterbox, Fit::Stretch][(head[2] / 4) as usize % 3];
    // Sizes: mostly small (fast), sometimes huge (which the buffer cannot hold: must be refused unallocated).
    let side = |b: u8, big: bool| b as usize * if big { 257 } else { 1 };
    let (cw, ch) = (
        side(head[3], head[16] & 1 == 1),
        side(head[4], head[16] & 2 == 2),
    );
    let (dw, dh) = (
        side(head[5], head[16] & 4 == 4),
        side(head[6], head[16] & 8 == 8),
    );
    // Stride: a row plus 0–126 bytes of padding, or (high bit) any value, too short included.
    let stride = |b: u8, w: usize, bpp: usize| {
        if b & 0x80 == 0 {
            w * bpp + b as usize
        } else {
            (b & 0x7F) as usize
        }
    };
    let color_stride = stride(head[7], cw, color_format.bytes_per_pixel());
    let depth_stride = stride(head[8], dw, depth_format.bytes_per_pixel());
    let (th, tw) = (head[9] as usize, head[10] as usize);
    let range = (head[11] & 1 == 1).then(|| DepthRange {
        z_near_m: head[12] as f32 / 16.0,
        z_far_m: head[13] as f32 / 16.0,
    });
    let split = rest.len() * head[14] as usize / 255;
    let (color, depth) = rest.split_at(split);
    let frame = CameraFrame {
        color: ColorImage {
            data: color,
            format: color_format,
            width: cw,
            height: ch,
            row_stride: color_stride,
        },
        depth: DepthImage {
            data: depth,
            format: depth_format,
            width: dw,
            height: dh,
            row_stride: depth_stride,
        },
        rotation,
        color_crop: None,
        confidence: None,
    };
    let options = FrameOptions {
        fit,
        range,
        ..FrameOptions::default()
    };
    if let Ok((f, _report)) = frame.to_rgbd(th, tw, &options) {
        assert_eq!((f.height(), f.width()), (th, tw));
        let bad = f.amplitude.iter().find(|v| !(0.0..=1.0).contains(*v));
        assert!(
            bad.is_none(),
            "amplitude {bad:?} outside [0, 1] ({options:?}, {th}x{tw})"
        );
        let bad = f.depth.iter().find(|v| !(0.0..=1.0).contains(*v));
        assert!(
            bad.is_none(),
            "depth {bad:?} outside [0, 1] ({options:?}, {th}x{tw})"
        );
    }
}
