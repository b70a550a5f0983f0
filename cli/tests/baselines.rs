//! End-to-end tests of `holo baselines`: the Maimone-style and SM-LBM + AA-DPM baselines of a tiny
//! dataset's test split, checked against the SDK and against each other (physics, not only shapes).

mod common;

use common::{holo, stderr};

use std::path::Path;

use ndarray::{s, Array3, Axis};
use ndarray_npy::read_npy;
use num_complex::Complex32;
use tensorholo::dataset::read_shard;
use tensorholo::metrics::psnr;
use tensorholo::synthesis::{SceneLayer, SmLbm};

/// A 1/1/2-scene dataset of 16x24 pixels, 5 LDI layers, 64 SM-LBM planes.
fn tiny_dataset(dir: &Path) {
    let o = holo(&[
        "dataset",
        "--out",
        dir.to_str().unwrap(),
        "--train",
        "1",
        "--val",
        "1",
        "--test",
        "2",
        "--size",
        "16x24",
        "--levels",
        "64",
        "--previews",
        "0",
        "--threads=2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

fn npy(path: &Path) -> Array3<Complex32> {
    read_npy(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Relative L2 distance `‖a − b‖ / ‖b‖`.
fn relative_l2(a: &Array3<Complex32>, b: &Array3<Complex32>) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        num += f64::from((x - y).norm_sqr());
        den += f64::from(y.norm_sqr());
    }
    (num / den).sqrt()
}

fn amplitude(a: &Array3<Complex32>) -> Array3<f32> {
    a.mapv(|v| v.norm())
}

fn npy_files(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".npy"))
        .collect();
    names.sort();
    names
}

#[test]
fn baselines_match_the_sdk_and_lose_only_encoding() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    tiny_dataset(&ds);
    let o = holo(&[
        "baselines",
        "--dataset",
        ds.to_str().unwrap(),
        "--split",
        "test",
        "--threads",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = ds.join("baselines");

    // (c) One file per test scene in every baseline folder, and the report.
    let folders = [
        "maimone",
        "smlbm-aadpm-0mm",
        "smlbm-aadpm-6mm",
        "smlbm-aadpm-12mm",
    ];
    for folder in folders {
        assert_eq!(
            npy_files(&out.join(folder)),
            ["00000.npy", "00001.npy"],
            "{folder}"
        );
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("baselines.json")).unwrap())
            .unwrap();
    assert_eq!(report["split"], "test");
    assert_eq!(report["count"], 2);
    assert_eq!(report["levels"], 64);
    assert_eq!(report["offsets_mm"], serde_json::json!([0.0, 6.0, 12.0]));
    assert_eq!(report["optics"]["pixel_pitch_m"], 8e-6);
    assert_eq!(report["command"][1], "baselines");
    let listed: Vec<&str> = report["baselines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["folder"].as_str().unwrap())
        .collect();
    assert_eq!(listed, folders);
    assert!(report["seconds_per_scene"]["total"].as_f64().unwrap() > 0.0);

    let shard = read_shard(&ds.join("test-00000.npz")).unwrap();
    assert_eq!(shard.len(), 2);
    let smlbm = SmLbm {
        levels: 64,
        ..SmLbm::default()
    };
    let unmasked = SmLbm {
        silhouette_masks: false,
        ..smlbm
    };
    let mut occluded_scenes = 0;
    for i in 0..shard.len() {
        let name = format!("{i:05}.npy");
        let rgbd = shard.ldi.slice(s![i, 0..4, .., ..]);
        let layer = [SceneLayer {
            amplitude: rgbd.slice(s![0..3, .., ..]),
            depth: rgbd.index_axis(Axis(0), 3),
            valid: None,
        }];
        let ground_truth = shard.midpoint.index_axis(Axis(0), i).to_owned();

        // (a) Maimone = SM-LBM without silhouette masks on the RGB-D layer, recomputed by the SDK ...
        let maimone = npy(&out.join("maimone").join(&name));
        assert_eq!(maimone.dim(), (3, 16, 24));
        let expected = unmasked.synthesize(&layer, &|_, _| {}).unwrap();
        let d = relative_l2(&maimone, &expected);
        eprintln!("scene {i}: maimone vs SDK recomputation (relative L2) {d:.1e}");
        assert!(d < 1e-5, "scene {i}: maimone vs SDK recomputation {d}");
        // ... which is not the ground truth where occluded layers exist (and lacks its occlusion).
        let hidden = shard
            .ldi_valid
            .slice(s![i, 1, .., ..])
            .iter()
            .filter(|&&v| v != 0)
            .count();
        let d_gt = relative_l2(&maimone, &ground_truth);
        eprintln!(
            "scene {i}: {hidden} pixels with a second layer, maimone vs ground truth {d_gt:.3}"
        );
        if hidden > 0 {
            occluded_scenes += 1;
            assert!(
                d_gt > 0.2,
                "scene {i}: maimone too close to the ground truth ({d_gt})"
            );
        }

        // (b) AA-DPM at 0 mm loses only the encoding: amplitude close to SM-LBM of the same layer.
        let masked = smlbm.synthesize(&layer, &|_, _| {}).unwrap();
        let reference = amplitude(&masked);
        let mut psnrs = Vec::new();
        let mut posts = Vec::new();
        for folder in &folders[1..] {
            let post = npy(&out.join(folder).join(&name));
            assert_eq!(post.dim(), (3, 16, 24));
            assert!(post.iter().all(|v| v.is_finite()));
            psnrs.push(psnr(reference.view(), amplitude(&post).view(), 1.0).unwrap());
            posts.push(post);
        }
        let vs_maimone = psnr(reference.view(), amplitude(&maimone).view(), 1.0).unwrap();
        eprintln!(
            "scene {i}: amplitude PSNR vs masked SM-LBM of layer 0: AA-DPM 0/6/12 mm {psnrs:.2?} dB, \
             maimone {vs_maimone:.2} dB"
        );
        // Measured 17.4 and 20.8 dB at 0 mm (17.4-21.6 dB at 6 and 12 mm) on the two scenes.
        assert!(psnrs[0] > 15.0, "scene {i}: AA-DPM 0 mm {} dB", psnrs[0]);
        assert!(psnrs.iter().all(|&p| p > 15.0), "scene {i}: {psnrs:?}");
        // Each offset is its own encoding (the SLM sees a different field), not a copy.
        for k in 1..posts.len() {
            let d = relative_l2(&posts[k], &posts[0]);
            assert!(d > 1e-2, "scene {i}: offset {k} equals 0 mm ({d})");
        }
        // The 0 mm encoding reproduces SM-LBM better than the occlusion-unaware hologram does.
        assert!(
            psnrs[0] > vs_maimone,
            "scene {i}: {psnrs:?} vs {vs_maimone}"
        );
    }
    assert!(occluded_scenes > 0, "no test scene has occluded content");

    // --limit and a rerun over existing files: only the first scene, overwritten in place.
    let out2 = dir.path().join("limited");
    let o = holo(&[
        "baselines",
        "--dataset",
        ds.to_str().unwrap(),
        "--out",
        out2.to_str().unwrap(),
        "--limit",
        "1",
        "--offsets-mm",
        "6",
        "--levels",
        "32",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(npy_files(&out2.join("maimone")), ["00000.npy"]);
    assert_eq!(npy_files(&out2.join("smlbm-aadpm-6mm")), ["00000.npy"]);
    assert!(!out2.join("smlbm-aadpm-0mm").exists());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out2.join("baselines.json")).unwrap())
            .unwrap();
    assert_eq!(report["count"], 1);
    assert_eq!(report["levels"], 32);
}

#[test]
fn baselines_arguments_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    tiny_dataset(&ds);
    let shard = ds.join("test-00000.npz");
    let before = std::fs::read(&shard).unwrap();
    let ds = ds.to_str().unwrap();
    let missing = dir.path().join("nothing");
    let missing = missing.to_str().unwrap();
    let cases: [(&[&str], &str); 6] = [
        (&["baselines", "--dataset", missing], "has no manifest.json"),
        (
            &["baselines", "--dataset", ds, "--split", "dev"],
            "unknown split `dev`",
        ),
        (&["baselines", "--dataset", ds, "--limit", "0"], "--limit"),
        (
            &["baselines", "--dataset", ds, "--offsets-mm", "0,NaN"],
            "finite",
        ),
        (
            &["baselines", "--dataset", ds, "--offsets-mm", "inf"],
            "finite",
        ),
        (
            &["baselines", "--dataset", ds, "--out", ds],
            "is the input folder",
        ),
    ];
    for (args, needle) in cases {
        let o = holo(args);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr(&o).contains(needle), "{args:?}: {}", stderr(&o));
    }
    assert!(!Path::new(ds).join("baselines").exists());
    assert!(!Path::new(ds).join("maimone").exists());
    assert_eq!(std::fs::read(&shard).unwrap(), before);
}
