//! `holo video --recording`: phone recordings as Record3D and Stray Scanner export them, made here from the
//! Redwood sequence with depth at a quarter of the colour's resolution (as a phone's LiDAR), render exactly
//! as the same frames given as aligned folders; missing, truncated and mismatched frames are refused naming
//! them.

mod common;

use std::path::{Path, PathBuf};

use common::{holo, shared, stderr};

/// Redwood frame `i`'s colour file and its depth at 1/4 resolution (160×120), millimetres.
fn frame(i: usize) -> (PathBuf, image::ImageBuffer<image::Luma<u16>, Vec<u16>>) {
    let depth = image::open(shared(&format!("redwood_livingroom_seq/depth/{i:05}.png")))
        .unwrap()
        .to_luma16();
    let small =
        image::ImageBuffer::from_fn(160, 120, |x, y| *depth.get_pixel(4 * x + 2, 4 * y + 2));
    (
        shared(&format!("redwood_livingroom_seq/color/{i:05}.jpg")),
        small,
    )
}

/// A one-channel f32 OpenEXR file of `mm`'s depths in metres (`v/1000`, what `mm16` decodes to).
fn write_exr(path: &Path, mm: &image::ImageBuffer<image::Luma<u16>, Vec<u16>>) {
    use exr::prelude::*;
    let values: Vec<f32> = mm.pixels().map(|p| p.0[0] as f32 / 1000.0).collect();
    let channels = AnyChannels::sort(vec![AnyChannel::new("Y", FlatSamples::F32(values))].into());
    let size = (mm.width() as usize, mm.height() as usize);
    let layer = Layer::new(
        size,
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        channels,
    );
    Image::from_layer(layer).write().to_file(path).unwrap();
}

/// A confidence map (0/1/2) at the depth's resolution: 0 on a band where frame `i`'s depth is read wrong.
fn confidence(i: usize) -> image::GrayImage {
    image::GrayImage::from_fn(160, 120, |x, y| {
        image::Luma([if (40..70).contains(&x) && y > 20 + 5 * i as u32 {
            0
        } else if x < 20 {
            1
        } else {
            2
        }])
    })
}

/// `holo video` with `args` at 48×64 into `out`, every frame's codes saved.
fn video(args: &[&str], out: &Path) -> std::process::Output {
    let mut all = vec!["video", "--size", "48x64", "--save-frames"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", out.to_str().unwrap()]);
    holo(&all)
}

fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

/// The saved codes of every frame of a run, in order.
fn codes(out: &Path, frames: usize) -> Vec<Vec<u8>> {
    (0..frames)
        .flat_map(|i| ["r", "g", "b"].map(|c| out.join(format!("frames/{i:05}_phase_{c}.png"))))
        .map(|p| std::fs::read(p).unwrap())
        .collect()
}

/// Record3D's "EXR + JPG" export: frames numbered 0, 1, 2, 10 (not name order: 10 sorts before 2), depth
/// in OpenEXR metres at a quarter of the colour's resolution, metadata.json with intrinsics, fps and
/// timestamps. It renders bit for bit as the same frames in aligned folders (16-bit millimetre PNGs).
#[test]
fn a_record3d_export_renders_as_the_same_frames_in_folders() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("record3d");
    let (rgb_dir, depth_dir) = (dir.path().join("rgb"), dir.path().join("depth"));
    for d in [
        rec.join("rgb"),
        rec.join("depth"),
        rgb_dir.clone(),
        depth_dir.clone(),
    ] {
        std::fs::create_dir_all(d).unwrap();
    }
    let numbers = [0, 1, 2, 10];
    for (i, n) in numbers.iter().enumerate() {
        let (rgb, depth) = frame(i);
        std::fs::copy(&rgb, rec.join(format!("rgb/{n}.jpg"))).unwrap();
        write_exr(&rec.join(format!("depth/{n}.exr")), &depth);
        std::fs::copy(&rgb, rgb_dir.join(format!("f{i}.jpg"))).unwrap();
        depth.save(depth_dir.join(format!("f{i}.png"))).unwrap();
    }
    let times: Vec<f64> = (0..=10).map(|n| 100.0 + n as f64 / 60.0).collect();
    std::fs::write(
        rec.join("metadata.json"),
        serde_json::json!({
            "w": 640, "h": 480, "dw": 160, "dh": 120, "fps": 60,
            "K": [525.0, 0.0, 0.0, 0.0, 525.0, 0.0, 319.5, 239.5, 1.0],
            "frameTimestamps": times,
            "poses": [],
        })
        .to_string(),
    )
    .unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let o = video(&["--recording", rec.to_str().unwrap()], &a);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = video(
        &[
            "--rgb-dir",
            rgb_dir.to_str().unwrap(),
            "--depth-dir",
            depth_dir.to_str().unwrap(),
            "--depth-encoding",
            "mm16",
        ],
        &b,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(codes(&a, 4), codes(&b, 4));
    let r = report(&a);
    assert_eq!(r["recording"]["kind"], "record3d");
    assert_eq!(r["recording"]["fps"], 60.0);
    assert_eq!(r["recording"]["intrinsics_px"][0], 525.0);
    assert_eq!(r["depth_encoding"], "metres");
    let order: Vec<&str> = r["per_frame"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["rgb"].as_str().unwrap().rsplit('/').next().unwrap())
        .collect();
    assert_eq!(order, ["0.jpg", "1.jpg", "2.jpg", "10.jpg"]);
    assert_eq!(r["per_frame"][3]["time_s"], times[10]);

    // Refusals, each naming the frame or the file.
    let run = |tag: &str| {
        let o = video(
            &["--recording", rec.to_str().unwrap()],
            &dir.path().join(tag),
        );
        assert!(!o.status.success(), "{tag}");
        stderr(&o)
    };
    std::fs::rename(rec.join("depth/2.exr"), dir.path().join("2.exr")).unwrap();
    let e = run("missing");
    assert!(e.contains("frame 2") && e.contains("2.jpg"), "{e}");
    let bytes = std::fs::read(dir.path().join("2.exr")).unwrap();
    std::fs::write(rec.join("depth/2.exr"), &bytes[..bytes.len() / 3]).unwrap();
    let e = run("truncated");
    assert!(e.contains("2.exr"), "{e}");
    std::fs::write(rec.join("depth/2.exr"), &bytes).unwrap();
    std::fs::write(rec.join("depth/11.exr"), &bytes).unwrap();
    let e = run("unpaired");
    assert!(e.contains("frame 11") && e.contains("11.exr"), "{e}");
    std::fs::remove_file(rec.join("depth/11.exr")).unwrap();
    let o = video(
        &[
            "--recording",
            rec.to_str().unwrap(),
            "--depth-encoding",
            "mm16",
        ],
        &dir.path().join("encoding"),
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("leave it out"), "{}", stderr(&o));
}

/// A Stray Scanner folder (colour extracted from rgb.mp4, 16-bit millimetre depth and 0/1/2 confidence at a
/// quarter of the colour's resolution, odometry.csv whose timestamps put frame 1 before frame 0) renders as
/// the same frames, in the timestamps' order, given as folders with --confidence-dir; its confidence maps
/// change the holograms; a folder still holding its colour as rgb.mp4 is refused with the command that
/// extracts it.
#[test]
fn a_stray_scanner_folder_renders_in_time_order_with_its_confidence() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("stray");
    let folders = ["rgb", "depth", "confidence"].map(|f| dir.path().join(f));
    for d in ["rgb", "depth", "confidence"]
        .iter()
        .map(|f| rec.join(f))
        .chain(folders.iter().cloned())
    {
        std::fs::create_dir_all(d).unwrap();
    }
    // Recorded frames 0, 1, 2; by their timestamps frame 1 came first.
    let times = [0.20, 0.10, 0.30];
    let order = [1, 0, 2];
    for n in 0..3 {
        let (rgb, depth) = frame(n);
        std::fs::copy(&rgb, rec.join(format!("rgb/{n:06}.jpg"))).unwrap();
        depth.save(rec.join(format!("depth/{n:06}.png"))).unwrap();
        confidence(n)
            .save(rec.join(format!("confidence/{n:06}.png")))
            .unwrap();
    }
    for (k, &n) in order.iter().enumerate() {
        let (rgb, depth) = frame(n);
        std::fs::copy(&rgb, folders[0].join(format!("s{k}.jpg"))).unwrap();
        depth.save(folders[1].join(format!("s{k}.png"))).unwrap();
        confidence(n)
            .save(folders[2].join(format!("s{k}.png")))
            .unwrap();
    }
    let mut odometry = String::from("timestamp, frame, x, y, z, qx, qy, qz, qw\n");
    for (n, t) in times.iter().enumerate() {
        odometry += &format!("{t}, {n}, 0, 0, 0, 0, 0, 0, 1\n");
    }
    std::fs::write(rec.join("odometry.csv"), odometry).unwrap();
    std::fs::write(
        rec.join("camera_matrix.csv"),
        "1450.0,0.0,960.0\n0.0,1450.0,720.0\n0.0,0.0,1.0\n",
    )
    .unwrap();
    let (a, b, plain) = (
        dir.path().join("a"),
        dir.path().join("b"),
        dir.path().join("plain"),
    );
    let o = video(&["--recording", rec.to_str().unwrap()], &a);
    assert!(o.status.success(), "{}", stderr(&o));
    let folders_args = [
        "--rgb-dir",
        folders[0].to_str().unwrap(),
        "--depth-dir",
        folders[1].to_str().unwrap(),
        "--depth-encoding",
        "mm16",
    ];
    let mut with_confidence = folders_args.to_vec();
    with_confidence.extend_from_slice(&["--confidence-dir", folders[2].to_str().unwrap()]);
    let o = video(&with_confidence, &b);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(codes(&a, 3), codes(&b, 3));
    let o = video(&folders_args, &plain);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_ne!(codes(&a, 3), codes(&plain, 3));
    let r = report(&a);
    assert_eq!(r["recording"]["kind"], "stray-scanner");
    assert_eq!(r["recording"]["confidence_maps"], true);
    assert_eq!(r["recording"]["intrinsics_px"][2], 960.0);
    let fps = r["recording"]["fps"].as_f64().unwrap();
    assert!((fps - 10.0).abs() < 1e-9, "{fps}");
    let first = r["per_frame"][0]["rgb"].as_str().unwrap();
    assert!(first.ends_with("000001.jpg"), "{first}");
    assert_eq!(r["per_frame"][0]["time_s"], 0.10);

    // A confidence map of another size than its depth map: refused naming it.
    image::GrayImage::from_pixel(80, 60, image::Luma([2]))
        .save(rec.join("confidence/000002.png"))
        .unwrap();
    let o = video(
        &["--recording", rec.to_str().unwrap()],
        &dir.path().join("small"),
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("000002.png"), "{}", stderr(&o));
    // The colour still in rgb.mp4.
    std::fs::remove_dir_all(rec.join("rgb")).unwrap();
    std::fs::write(rec.join("rgb.mp4"), b"").unwrap();
    let o = video(
        &["--recording", rec.to_str().unwrap()],
        &dir.path().join("mp4"),
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("ffmpeg -i rgb.mp4 -start_number 0 rgb/%06d.png"),
        "{}",
        stderr(&o)
    );
}

/// Issue 80: a refused `holo video --save-frames` leaves nothing: the frames it wrote before the frame that
/// stopped it are removed, with the `frames/` folder it made; an old report.json in `--out` is removed first.
/// Before, the first frames' patterns stayed.
#[test]
fn a_refused_video_removes_the_frames_it_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let (rgb_dir, depth_dir) = (dir.path().join("rgb"), dir.path().join("depth"));
    std::fs::create_dir_all(&rgb_dir).unwrap();
    std::fs::create_dir_all(&depth_dir).unwrap();
    for i in 0..3 {
        let (rgb, depth) = frame(i);
        std::fs::copy(&rgb, rgb_dir.join(format!("f{i}.jpg"))).unwrap();
        depth.save(depth_dir.join(format!("f{i}.png"))).unwrap();
    }
    // The third depth map is truncated: frames 0 and 1 render (and are saved) before it stops the run.
    let last = depth_dir.join("f2.png");
    let bytes = std::fs::read(&last).unwrap();
    std::fs::write(&last, &bytes[..bytes.len() / 2]).unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("report.json"), "{}").unwrap();
    let o = video(
        &[
            "--rgb-dir",
            rgb_dir.to_str().unwrap(),
            "--depth-dir",
            depth_dir.to_str().unwrap(),
            "--depth-encoding",
            "mm16",
        ],
        &out,
    );
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("f2.png"), "{e}");
    let left: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert!(left.is_empty(), "a refused video left {left:?}");
}

/// Issue 80: `--refine-levels` is checked at its flag, in every command that takes it, before any work
/// (1 to 2²⁰, the synthesis's bound: was blamed on "`levels`", in `holo video` only at the first frame); the
/// refinement refuses frames under 11 × 11 as render does (`holo bench --refine` printed `inf → inf (NaN)`).
#[test]
fn refinement_bounds_are_named_on_their_flags() {
    let dir = tempfile::tempdir().unwrap();
    let (rgb, depth) = frame(0);
    let frames = dir.path().join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let depth_file = frames.join("d.png");
    depth.save(&depth_file).unwrap();
    let (rgb, depth_file) = (rgb.to_str().unwrap(), depth_file.to_str().unwrap());
    let out = dir.path().join("out");
    let out = out.to_str().unwrap();
    for levels in ["0", "1048577", "99999999999"] {
        for args in [
            vec![
                "render",
                "--rgb",
                rgb,
                "--depth",
                depth_file,
                "--depth-encoding",
                "mm16",
                "--size",
                "48x64",
            ],
            vec![
                "video",
                "--rgb-dir",
                frames.to_str().unwrap(),
                "--depth-dir",
                frames.to_str().unwrap(),
            ],
        ] {
            let mut args = args.clone();
            args.extend(["--refine", "2", "--refine-levels", levels, "--out", out]);
            let o = holo(&args);
            let e = stderr(&o);
            assert!(
                !o.status.success() && e.contains("--refine-levels") && !e.contains("frame 0"),
                "{} --refine-levels {levels}: {e}",
                args[0]
            );
            assert!(!Path::new(out).exists(), "{}: wrote {out}", args[0]);
        }
    }
    let o = holo(&[
        "bench",
        "--skip-cnn",
        "--skip-pipeline",
        "--refine",
        "2",
        "--sizes",
        "8x8",
        "--threads",
        "1",
    ]);
    let (e, text) = (stderr(&o), String::from_utf8_lossy(&o.stdout).into_owned());
    assert!(
        !o.status.success()
            && e.contains("--sizes 8x8")
            && e.contains("11×11")
            && !text.contains("NaN"),
        "{e}\n{text}"
    );
}

/// Issue 80: a depth map whose valid depths leave no usable pixel once normalised (1e-40 m everywhere: 1/z
/// overflows) is refused naming the file in every command that reads one, and leaves no output behind.
#[test]
fn a_depth_map_that_leaves_no_usable_pixel_is_refused_naming_it_in_every_command() {
    use exr::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let (rgb_dir, depth_dir) = (dir.path().join("rgb"), dir.path().join("depth"));
    std::fs::create_dir_all(&rgb_dir).unwrap();
    std::fs::create_dir_all(&depth_dir).unwrap();
    let (rgb, _) = frame(0);
    std::fs::copy(&rgb, rgb_dir.join("a.jpg")).unwrap();
    let depth = depth_dir.join("a.exr");
    let channels = AnyChannels::sort(
        vec![AnyChannel::new(
            "Z",
            FlatSamples::F32(vec![1e-40; 160 * 120]),
        )]
        .into(),
    );
    let layer = Layer::new(
        (160, 120),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        channels,
    );
    Image::from_layer(layer).write().to_file(&depth).unwrap();
    let (rgb, depth) = (rgb_dir.join("a.jpg"), depth);
    let (rgb, depth) = (rgb.to_str().unwrap(), depth.to_str().unwrap());
    let out = dir.path().join("out");
    let out_s = out.to_str().unwrap();
    let single = |command: &'static str| {
        vec![
            command,
            "--rgb",
            rgb,
            "--depth",
            depth,
            "--depth-encoding",
            "metres",
            "--size",
            "48x64",
        ]
    };
    for mut args in [
        single("render"),
        single("reference"),
        vec![
            "video",
            "--rgb-dir",
            rgb_dir.to_str().unwrap(),
            "--depth-dir",
            depth_dir.to_str().unwrap(),
            "--depth-encoding",
            "metres",
            "--size",
            "48x64",
            "--save-frames",
        ],
    ] {
        args.extend(["--out", out_s]);
        let o = holo(&args);
        let e = stderr(&o);
        assert!(
            !o.status.success() && e.contains("a.exr") && e.contains("no usable pixel"),
            "{}: {e}",
            args[0]
        );
        assert!(!out.exists(), "{} left {out_s}", args[0]);
    }
}
