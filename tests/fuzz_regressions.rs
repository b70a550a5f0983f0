//! The fuzz harnesses (`fuzz/src/lib.rs`, shared with the cargo-fuzz targets) on stable, in CI:
//!
//! 1. every input committed under `tests/fixtures/fuzz/<target>/` (crashes cargo-fuzz found, kept as
//!    regressions, and hand-made edge cases) is replayed through its harness;
//! 2. each harness runs on seeds made here from synthetic data (valid files of every format the target parses)
//!    and on deterministic mutations of them: every truncation length of the small ones, and byte flips;
//! 3. `write_seed_corpus` (ignored; run by hand, docs/FUZZING.md) writes the same seeds to `fuzz/corpus/`.
//!
//! A harness panics on a violated invariant (e.g. an accepted image with an amplitude outside `[0, 1]`), so
//! each replay is a real check. The seeds are also checked to be accepted where valid, so that a harness that
//! silently refuses everything is caught.

#[allow(dead_code)]
#[path = "../fuzz/src/lib.rs"]
mod harness;

use std::io::Cursor;
use std::path::{Path, PathBuf};

use tensorholo::scene::{decode_depth_bytes, decode_rgb_bytes, DepthEncoding};
use tensorholo::slm::{DisplayCalibration, LutRepresentation, PhaseCurve, PhaseLut, TiledCurves};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/fuzz")
}

fn encode(img: image::DynamicImage, format: image::ImageFormat) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, format).expect("encodes");
    out.into_inner()
}

/// A 16-bit greyscale ramp with a hole (0 = invalid in most encodings).
fn depth16(w: u32, h: u32) -> image::DynamicImage {
    image::DynamicImage::ImageLuma16(image::ImageBuffer::from_fn(w, h, |x, y| {
        image::Luma([if x == 1 && y == 1 {
            0
        } else {
            (500 + 40 * x + 70 * y) as u16
        }])
    }))
}

fn rgb8(w: u32, h: u32) -> image::DynamicImage {
    image::DynamicImage::ImageRgb8(image::ImageBuffer::from_fn(w, h, |x, y| {
        image::Rgb([(x * 20) as u8, (y * 30) as u8, ((x + y) * 9) as u8])
    }))
}

/// Kinect PGM, little-endian 16-bit samples ≤ 2047 (the NYU layout).
fn kinect_pgm(w: usize, h: usize) -> Vec<u8> {
    let mut out = format!("P5\n# kinect\n{w} {h}\n2047\n").into_bytes();
    for i in 0..w * h {
        out.extend_from_slice(&((300 + 7 * i) as u16 % 2048).to_le_bytes());
    }
    out
}

fn npy_c8(descr: &str, shape: &str, values: usize) -> Vec<u8> {
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for i in 0..values {
        let v = i as f32 * 0.5 - 1.0;
        let b = if descr.starts_with('>') {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        out.extend_from_slice(&b);
        out.extend_from_slice(&b);
    }
    out
}

fn holocal_seeds() -> Vec<Vec<u8>> {
    let mut cal = DisplayCalibration::linear(6, 8).unwrap();
    let mut out = vec![cal.to_bytes().unwrap()];
    cal.colours[0].lut = PhaseLut::new(LutRepresentation::Global(
        PhaseCurve::gamma(2.2 * std::f32::consts::PI, 1.3).unwrap(),
    ));
    let tiles = (0..4)
        .map(|i| PhaseCurve::gamma((2.0 + 0.1 * i as f32) * std::f32::consts::PI, 1.1).unwrap())
        .collect();
    cal.colours[1].lut = PhaseLut::new(LutRepresentation::Tiled(
        TiledCurves::new(6, 8, 3, 4, tiles).unwrap(),
    ));
    cal.colours[2].intensity_scale = Some(ndarray::Array2::from_elem((6, 8), 0.75));
    out.push(cal.to_bytes().unwrap());
    out
}

/// A camera-frame harness input: the 17-byte description `harness::camera_frame` reads, then the buffers.
fn camera_seed(
    color_format: u8,
    depth_format: u8,
    rotation_fit: u8,
    split: u8,
    range: bool,
) -> Vec<u8> {
    let (cw, ch, dw, dh) = (6u8, 4u8, 3u8, 2u8);
    let bpp_c = [4usize, 4, 3][color_format as usize % 3];
    let bpp_d = [4usize, 2, 4, 2, 2, 2][depth_format as usize % 6];
    let mut out = vec![
        color_format,
        depth_format,
        rotation_fit,
        cw,
        ch,
        dw,
        dh,
        0,
        0,
        5,
        7,
        range as u8,
        8,
        48,
        split,
        0,
        0,
    ];
    let color: Vec<u8> = (0..cw as usize * ch as usize * bpp_c)
        .map(|i| (i * 37 % 256) as u8)
        .collect();
    let depth: Vec<u8> = (0..dw as usize * dh as usize)
        .flat_map(|i| {
            let z = 0.6 + 0.2 * i as f32;
            match (depth_format % 6, bpp_d) {
                (0, _) => z.to_le_bytes().to_vec(),
                (2, _) => (1.0 / z).to_le_bytes().to_vec(),
                (1, _) => half::f16::from_f32(z).to_le_bytes().to_vec(),
                (3, _) => half::f16::from_f32(1.0 / z).to_le_bytes().to_vec(),
                _ => ((z * 1000.0) as u16).to_le_bytes().to_vec(),
            }
        })
        .collect();
    // `split` is the fraction of the rest given to colour: pick it so that the seed's split is exact.
    let rest = color.len() + depth.len();
    let exact = (color.len() * 255).div_ceil(rest) as u8;
    out[14] = if split == 0 { exact } else { split };
    out.extend(color);
    out.extend(depth);
    out
}

/// Valid inputs of every format each target parses.
fn seeds(target: &str) -> Vec<Vec<u8>> {
    use image::ImageFormat::{Jpeg, Png, Pnm};
    let with = |pick: DepthEncoding, file: Vec<u8>| {
        let i = DepthEncoding::ALL.iter().position(|&e| e == pick).unwrap() as u8;
        [vec![i], file].concat()
    };
    match target {
        "depth_decode" => vec![
            with(DepthEncoding::Millimetres16, encode(depth16(7, 5), Png)),
            with(DepthEncoding::Tum5000, encode(depth16(4, 9), Png)),
            with(DepthEncoding::SunRotated, encode(depth16(5, 5), Pnm)),
            with(DepthEncoding::KinectDisparity, kinect_pgm(5, 3)),
            with(
                DepthEncoding::IphoneDisparity,
                encode(rgb8(8, 8).grayscale(), Jpeg),
            ),
            with(
                DepthEncoding::RelativeNearDark,
                encode(rgb8(6, 3).grayscale(), Png),
            ),
        ],
        "rgb_decode" => vec![
            encode(rgb8(7, 5), Png),
            encode(rgb8(9, 8), Jpeg),
            encode(rgb8(3, 4), Pnm),
            encode(depth16(4, 4), Png),
        ],
        "npy" => vec![
            npy_c8("<c8", "(1, 2, 3)", 6),
            npy_c8(">c8", "(2, 3)", 6),
            npy_c8("<c8", "(3, 1, 1)", 3),
        ],
        "holocal" => holocal_seeds()
            .into_iter()
            .map(|f| [vec![0u8], f].concat())
            .collect(),
        "onnx_model" => tensorholo::model::embedded::files()
            .filter(|(name, _)| {
                name.starts_with("holo8_rgbd.int8-qdq")
                    || name.starts_with("prefilter_6mm.int8-qdq")
            })
            .map(|(_, bytes)| bytes.to_vec())
            .collect(),
        "camera_frame" => (0..6u8)
            .map(|d| camera_seed(d % 3, d, d, 0, d % 2 == 0))
            .collect(),
        "display_profile" => [
            DISPLAY_PAPER,
            DISPLAY_LCOS,
            // A BOM, a name with non-ASCII text, one offset.
            "\u{feff}{\"name\": \"Ωmega 532\", \"pixel_pitch_m\": 6.4e-6, \"resolution\": [64, 96], \
             \"wavelengths_m\": [532e-9, 532e-9, 532e-9], \"volume_depth_m\": 3e-3, \"offsets_m\": [0.0]}",
        ]
        .map(|s| s.as_bytes().to_vec())
        .to_vec(),
        "aberration" => vec![ABERRATION.as_bytes().to_vec()],
        // What `holo calibrate aberration patterns` writes: a 64² SLM, green and blue, two distances.
        "spot_plan" => vec![serde_json::to_string_pretty(
            &tensorholo::slm::spots::SpotPlan::new(
                [64, 64],
                &tensorholo::optics::OpticalSetup::default(),
                &[1, 2],
                vec![-3e-3, 4e-3],
                2.0,
                32,
            )
            .unwrap(),
        )
        .unwrap()
        .into_bytes()],
        // A `--tune` run's tuning.json: two sessions and three rows.
        "saved_plans" => vec![SAVED_PLANS.as_bytes().to_vec()],
        // A one-sample dataset written by `holo dataset --shard 0/1` and merged (committed under
        // tests/fixtures/fuzz, so the replay test runs them too).
        "shard_record" | "manifest" => {
            std::fs::read_dir(fixtures().join(target))
                .unwrap()
                .map(|e| std::fs::read(e.unwrap().path()).unwrap())
                .collect()
        }
        // Uncompressed single-layer scan-line files: one f32 `Z` channel (Record3D's), a half-float `Y` beside
        // other channels, and one 32-bit unsigned channel.
        "exr_depth" => vec![
            exr_file(5, 3, &[("Z", 2)]),
            exr_file(4, 4, &[("A", 1), ("B", 2), ("Y", 1)]),
            exr_file(3, 2, &[("depth", 0)]),
        ],
        "record3d_metadata" => vec![
            br#"{"K": [1445.3, 0, 0, 0, 1445.3, 0, 962.1, 718.4, 1], "fps": 60,
                "frameTimestamps": [0.0, 0.0167, 0.0333], "w": 1920, "h": 1440}"#
                .to_vec(),
            br#"{"fps": 30}"#.to_vec(),
        ],
        "stray_odometry" => vec![
            harness::STRAY_ODOMETRY.as_bytes().to_vec(),
            // Rows in any order: frames run in timestamp order.
            b"timestamp,frame\n2.5,1\n1.5,2\n3.5,0\n".to_vec(),
        ],
        "stray_camera_matrix" => vec![
            harness::STRAY_CAMERA.as_bytes().to_vec(),
            b"500,0,320\n0,500.5,240\n0,0,1".to_vec(),
        ],
        other => panic!("no seeds for {other}"),
    }
}

/// An uncompressed single-layer scan-line OpenEXR file of `w × h` pixels with `channels` (name, pixel type:
/// 0 u32, 1 half, 2 f32; sorted by name as the format stores them), samples `1 + x/10 + y/100` (a valid depth
/// in metres), written by hand from the OpenEXR file layout (no exr crate in this test crate).
fn exr_file(w: i32, h: i32, channels: &[(&str, i32)]) -> Vec<u8> {
    fn attribute(out: &mut Vec<u8>, name: &str, kind: &str, value: &[u8]) {
        out.extend(name.as_bytes());
        out.push(0);
        out.extend(kind.as_bytes());
        out.push(0);
        out.extend((value.len() as i32).to_le_bytes());
        out.extend(value);
    }
    let mut sorted = channels.to_vec();
    sorted.sort_by_key(|c| c.0);
    let mut out = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
    let mut list = Vec::new();
    for (name, kind) in &sorted {
        list.extend(name.as_bytes());
        list.push(0);
        list.extend(kind.to_le_bytes());
        list.extend([0, 0, 0, 0]);
        list.extend(1i32.to_le_bytes());
        list.extend(1i32.to_le_bytes());
    }
    list.push(0);
    attribute(&mut out, "channels", "chlist", &list);
    attribute(&mut out, "compression", "compression", &[0]);
    let window: Vec<u8> = [0, 0, w - 1, h - 1]
        .iter()
        .flat_map(|v: &i32| v.to_le_bytes())
        .collect();
    attribute(&mut out, "dataWindow", "box2i", &window);
    attribute(&mut out, "displayWindow", "box2i", &window);
    attribute(&mut out, "lineOrder", "lineOrder", &[0]);
    attribute(&mut out, "pixelAspectRatio", "float", &1f32.to_le_bytes());
    attribute(&mut out, "screenWindowCenter", "v2f", &[0; 8]);
    attribute(&mut out, "screenWindowWidth", "float", &1f32.to_le_bytes());
    out.push(0);
    // One chunk a line: the offset table, then each line's y, size and samples, channel by channel.
    let line_bytes: i32 = sorted
        .iter()
        .map(|(_, kind)| if *kind == 1 { 2 } else { 4 } * w)
        .sum();
    let table_end = out.len() + 8 * h as usize;
    for y in 0..h as usize {
        out.extend(((table_end + y * (8 + line_bytes as usize)) as u64).to_le_bytes());
    }
    for y in 0..h {
        out.extend(y.to_le_bytes());
        out.extend(line_bytes.to_le_bytes());
        for (_, kind) in &sorted {
            for x in 0..w {
                let v = 1.0 + x as f32 / 10.0 + y as f32 / 100.0;
                match kind {
                    0 => out.extend((v.round() as u32).to_le_bytes()),
                    1 => out.extend(half::f16::from_f32(v).to_le_bytes()),
                    _ => out.extend(v.to_le_bytes()),
                }
            }
        }
    }
    out
}

/// docs/DISPLAYS.md's paper display and 3.74 µm LCoS.
const DISPLAY_PAPER: &str = r#"{"name": "HOLOEYE PLUTO-2 (paper)", "pixel_pitch_m": 8e-6,
  "resolution": [1080, 1920], "wavelengths_m": [638e-9, 520e-9, 450e-9], "volume_depth_m": 6e-3,
  "offsets_m": [6e-3, 12e-3, 0.0]}"#;
const DISPLAY_LCOS: &str = r#"{"name": "3.74 µm 4K LCoS", "pixel_pitch_m": 3.74e-6,
  "resolution": [2160, 3840], "wavelengths_m": [638e-9, 520e-9, 450e-9],
  "volume_depth_m": 1.3113375e-3, "offsets_m": [1.3113375e-3, 2.622675e-3, 0.0]}"#;
/// docs/ABERRATION.md's example file.
const ABERRATION: &str = r#"{"format": "tensorholo.aberration", "version": 1,
  "wavelengths_m": [638e-9, 520e-9, 450e-9], "pixel_pitch_m": 8e-6,
  "samples": [
    {"distance_m": -0.010, "coefficients": {"focus": 3.5, "astigmatism_vertical": 7.0}},
    {"distance_m": 0.010, "per_colour": [{"focus": 4.3, "astigmatism_vertical": 8.6},
                                         {"focus": 3.5, "astigmatism_vertical": 7.0},
                                         {"focus": 3.0, "astigmatism_vertical": 6.1}]}
  ]}"#;

/// A saved-plans record as `holo render --tune` writes it (tuning.json), for the scalar kernels (every build).
const SAVED_PLANS: &str = r#"{"format": "tensorholo.cnn-plans", "version": 1, "isa": "scalar",
  "origin": "tuned by tensorholo 0.1.0 (2 threads available)",
  "sessions": [
    {"network": "hologram-cnn-8-f32-in4", "resolution": [40, 72], "engine": "native",
     "layout": "channels-first", "threads": 2},
    {"network": "hologram-cnn-8-int8-qoperator-conv-in4", "resolution": [384, 384], "engine": "tract",
     "layout": "channels-last", "threads": null}
  ],
  "rows": [
    {"c_in": 4, "c_out": 24, "algorithms": "any", "row": "conv3x3.f32.8x8.scalar"},
    {"c_in": 24, "c_out": 24, "algorithms": "any", "row": "conv3x3.f32.wino4x4.4x4.scalar"},
    {"c_in": 28, "c_out": 6, "algorithms": "any", "row": "conv3x3.f32.wino2x2.4x4.scalar"}
  ]}"#;

/// Seeds the harness's parser must accept (so a harness that refuses everything fails this test).
fn check_seeds_accepted(target: &str, seeds: &[Vec<u8>]) {
    for (i, s) in seeds.iter().enumerate() {
        let ok = match target {
            "depth_decode" => decode_depth_bytes(
                &s[1..],
                Path::new("seed"),
                DepthEncoding::ALL[s[0] as usize],
            )
            .map(|_| ())
            .map_err(|e| e.to_string()),
            "rgb_decode" => decode_rgb_bytes(s, Path::new("seed"))
                .map(|_| ())
                .map_err(|e| e.to_string()),
            "npy" => tensorholo::io::parse_complex_npy(s, Path::new("seed"))
                .map(|_| ())
                .map_err(|e| e.to_string()),
            "holocal" => DisplayCalibration::from_bytes(&s[1..], "seed")
                .map(|_| ())
                .map_err(|e| e.to_string()),
            "display_profile" => std::str::from_utf8(s)
                .map_err(|e| e.to_string())
                .and_then(|t| {
                    tensorholo::display::DisplayProfile::from_json_str(t)
                        .map(|_| ())
                        .map_err(|e| e.to_string())
                }),
            "aberration" => tensorholo::display::AberrationProfile::from_json_str(
                std::str::from_utf8(s).unwrap(),
                "seed",
            )
            .map(|_| ())
            .map_err(|e| e.to_string()),
            "shard_record" => {
                tensorholo::dataset::ShardRecord::from_json_str(std::str::from_utf8(s).unwrap())
                    .map(|_| ())
                    .ok_or_else(|| "not a shard record".to_string())
            }
            "spot_plan" => tensorholo::slm::spots::SpotPlan::from_json_str(
                std::str::from_utf8(s).unwrap(),
                "seed",
            )
            .map(|_| ())
            .map_err(|e| e.to_string()),
            "saved_plans" => {
                tensorholo::cnn::SavedPlans::from_json(std::str::from_utf8(s).unwrap())
                    .map(|_| ())
                    .map_err(|e| e.to_string())
            }
            "exr_depth" => decode_depth_bytes(s, Path::new("seed"), DepthEncoding::Metres)
                .map(|_| ())
                .map_err(|e| e.to_string()),
            "record3d_metadata" | "stray_odometry" | "stray_camera_matrix" => {
                // The harness writes the seed into its recording folder and lists it; a refusal panics here.
                let name = match target {
                    "record3d_metadata" => "metadata.json",
                    "stray_odometry" => "odometry.csv",
                    _ => "camera_matrix.csv",
                };
                let dir = std::env::temp_dir().join(format!(
                    "tensorholo-seed-{target}-{}-{i}",
                    std::process::id()
                ));
                recording_seed_dir(&dir, target == "record3d_metadata");
                std::fs::write(dir.join(name), s).unwrap();
                let r = tensorholo::scene::open_recording(&dir)
                    .map(|_| ())
                    .map_err(|e| e.to_string());
                std::fs::remove_dir_all(&dir).unwrap();
                r
            }
            "manifest" => tensorholo::dataset::Manifest::from_json_str(
                std::str::from_utf8(s).unwrap(),
                "seed",
            )
            .map(|_| ())
            .map_err(|e| e.to_string()),
            _ => Ok(()),
        };
        if let Err(e) = ok {
            panic!("{target} seed {i} is refused: {e}");
        }
    }
}

/// A recording folder of three frames (empty files) for the recording seeds: Record3D's or Stray Scanner's.
fn recording_seed_dir(dir: &Path, record3d: bool) {
    for sub in ["rgb", "depth"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    for i in 0..3 {
        let (rgb, depth) = if record3d {
            (format!("rgb/{i}.jpg"), format!("depth/{i}.exr"))
        } else {
            (format!("rgb/{i:06}.png"), format!("depth/{i:06}.png"))
        };
        std::fs::write(dir.join(rgb), b"").unwrap();
        std::fs::write(dir.join(depth), b"").unwrap();
    }
    if !record3d {
        std::fs::write(dir.join("odometry.csv"), harness::STRAY_ODOMETRY).unwrap();
        std::fs::write(dir.join("camera_matrix.csv"), harness::STRAY_CAMERA).unwrap();
    }
}

#[test]
fn committed_fuzz_findings_replay_without_panic() {
    let root = fixtures();
    let mut replayed = 0;
    for (name, harness) in harness::TARGETS {
        let dir = root.join(name);
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries {
            let path = entry.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            eprintln!("{name}: {}", path.display());
            harness(&bytes);
            replayed += 1;
        }
    }
    // Every target directory name must be a harness (a typo would silently skip its findings).
    for entry in std::fs::read_dir(&root).expect("tests/fixtures/fuzz exists") {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        assert!(
            name == "README.md" || harness::TARGETS.iter().any(|(t, _)| *t == name),
            "tests/fixtures/fuzz/{name} is not a fuzz target"
        );
    }
    assert!(
        replayed > 0,
        "no committed fuzz inputs under {}",
        root.display()
    );
}

#[test]
fn harnesses_hold_on_seeds_truncations_and_byte_flips() {
    for (name, harness) in harness::TARGETS {
        let seeds = seeds(name);
        assert!(!seeds.is_empty());
        check_seeds_accepted(name, &seeds);
        for seed in &seeds {
            harness(seed);
            // The ONNX files are large and tract's loader slow in a test build: a few cuts and flips.
            let step = if name == "onnx_model" {
                seed.len() / 7 + 1
            } else {
                1
            };
            for len in (0..seed.len()).step_by(step) {
                harness(&seed[..len]);
            }
            let mut flipped = seed.clone();
            for i in (0..seed.len()).step_by(step.max(3)) {
                for value in [0x00, 0xFF, flipped[i] ^ 0x01, flipped[i].wrapping_add(0x80)] {
                    let old = flipped[i];
                    flipped[i] = value;
                    harness(&flipped);
                    flipped[i] = old;
                }
            }
        }
    }
}

/// Writes the seeds to `fuzz/corpus/<target>/` for `cargo fuzz run` (docs/FUZZING.md).
#[test]
#[ignore = "writes fuzz/corpus; run by hand before fuzzing"]
fn write_seed_corpus() {
    for (name, _) in harness::TARGETS {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../fuzz/corpus")
            .join(name);
        std::fs::create_dir_all(&dir).unwrap();
        for (i, seed) in seeds(name).iter().enumerate() {
            std::fs::write(dir.join(format!("seed-{i}")), seed).unwrap();
        }
    }
}
