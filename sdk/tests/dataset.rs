//! Random scenes (LDIs by per-pixel depth sorting) and the dataset writer: determinism, LDI invariants,
//! occlusion, shards and manifest.

use std::fs;
use std::path::{Path, PathBuf};

use ndarray::{Array1, Array4};
use ndarray_npy::NpzReader;
use proptest::prelude::*;
use tensorholo::dataset::{
    generate, ldi_from_tensor, ldi_tensor, read_manifest, read_shard, sample_seed, shard_file_name,
    write_shard, DatasetConfig, GenerateOptions, LdiStatistics, SampleGenerator, Split,
    FORMAT_NAME, FORMAT_VERSION, MANIFEST_FILE,
};
use tensorholo::scene::{
    ldi_from_fragments, random_ldi, Fragment, LayeredDepthImage, RandomSceneConfig,
    RandomSceneGenerator,
};
use tensorholo::synthesis::{ldi_layers, SmLbm};
use tensorholo::{Complex32, HoloError};

/// A fresh, empty scratch folder under Cargo's per-target temporary folder.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("dataset_tests")
        .join(name);
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).unwrap();
    dir
}

fn small(h: usize, w: usize) -> RandomSceneConfig {
    RandomSceneConfig {
        height: h,
        width: w,
        ..RandomSceneConfig::default()
    }
}

/// Every invariant a random LDI must satisfy.
fn check_ldi(ldi: &LayeredDepthImage, layers: usize) {
    assert_eq!(ldi.num_layers(), layers);
    let ls = ldi.layers();
    assert!(
        ls[0].valid.iter().all(|&v| v),
        "layer 0 must be valid everywhere"
    );
    for (k, l) in ls.iter().enumerate() {
        for ((y, x), &ok) in l.valid.indexed_iter() {
            let d = l.depth[[y, x]];
            let a = [0, 1, 2].map(|c| l.amplitude[[c, y, x]]);
            if ok {
                assert!((0.0..=1.0).contains(&d), "layer {k} depth {d}");
                assert!(a.iter().all(|v| (0.0..=1.0).contains(v)), "{a:?}");
            } else {
                assert_eq!((d, a), (1.0, [0.0; 3]), "invalid pixel of layer {k}");
            }
            if k > 0 && ok {
                assert!(ls[k - 1].valid[[y, x]], "layer {k} valid behind a hole");
                assert!(
                    d >= ls[k - 1].depth[[y, x]],
                    "layer {k} in front of layer {}",
                    k - 1
                );
            }
        }
    }
}

#[test]
fn same_seed_same_scene_and_different_seed_different_scene() {
    let c = small(40, 56);
    let a = random_ldi(&c, 7).unwrap();
    let b = random_ldi(&c, 7).unwrap();
    assert_eq!(a, b);
    let (ta, va) = ldi_tensor(&a);
    let (tb, vb) = ldi_tensor(&b);
    assert_eq!(ta.as_slice().unwrap(), tb.as_slice().unwrap());
    assert_eq!(va, vb);
    let other = random_ldi(&c, 8).unwrap();
    assert_ne!(a, other);
    let (to, _) = ldi_tensor(&other);
    let differing = ta.iter().zip(to.iter()).filter(|(x, y)| x != y).count();
    assert!(differing > ta.len() / 2, "only {differing} values differ");
    // One generator shared by threads gives the same scenes as fresh ones.
    let g = RandomSceneGenerator::new(c.clone()).unwrap();
    assert_eq!(g.generate(7).unwrap(), a);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
    #[test]
    fn random_ldis_are_depth_sorted_and_first_layer_is_complete(
        seed in any::<u64>(),
        h in 4usize..40,
        w in 4usize..40,
        layers in 1usize..7,
        lo in 0usize..20,
        extra in 0usize..30,
        thin in 0.0f32..=1.0,
    ) {
        let c = RandomSceneConfig {
            height: h,
            width: w,
            layers,
            shape_count: [lo, lo + extra],
            thin_probability: thin,
            ..RandomSceneConfig::default()
        };
        let ldi = random_ldi(&c, seed).unwrap();
        check_ldi(&ldi, layers);
    }
}

#[test]
fn occlusion_is_heavy() {
    // Measured with the default configuration (100 scenes at 384x384): valid fraction per layer
    // ~[1.00, 0.79, 0.52, 0.29, 0.14], >= 2 layers at 79 % of pixels on average. 24 scenes at 96x96
    // (the same scenes scaled down) must stay well above 60 %, every rear layer must be used, and the
    // valid fraction must fall with the layer index (paper Fig. 1b).
    let c = small(96, 96);
    let n = 24;
    let mut valid = [0.0f64; 5];
    let mut multi = 0.0;
    for seed in 0..n {
        let st = LdiStatistics::of(&random_ldi(&c, seed).unwrap());
        for (a, v) in valid.iter_mut().zip(&st.valid_fraction) {
            *a += v / n as f64;
        }
        multi += st.multi_layer_fraction / n as f64;
    }
    eprintln!("96x96, {n} scenes: valid per layer {valid:.3?}, >= 2 layers {multi:.3}");
    assert!(
        multi > 0.6,
        "mean fraction of pixels with >= 2 layers {multi:.3}"
    );
    assert!((valid[0] - 1.0).abs() < 1e-12);
    assert!(valid[4] > 0.04, "layer 4 nearly empty: {valid:?}");
    assert!(valid.windows(2).all(|p| p[1] < p[0]), "{valid:?}");
}

/// Depth peeling (paper Algorithm 1): pass k keeps, per pixel, the nearest fragment strictly behind
/// the depth that pass k − 1 kept.
fn depth_peeling(
    h: usize,
    w: usize,
    layers: usize,
    frags: &[Fragment],
) -> Vec<Vec<Option<Fragment>>> {
    let mut prev = vec![f32::NEG_INFINITY; h * w];
    let mut out = Vec::new();
    for _ in 0..layers {
        let mut best: Vec<Option<Fragment>> = vec![None; h * w];
        for f in frags {
            let p = f.row as usize * w + f.col as usize;
            if f.depth > prev[p] && best[p].is_none_or(|b| f.depth < b.depth) {
                best[p] = Some(*f);
            }
        }
        for (p, b) in best.iter().enumerate() {
            prev[p] = b.map_or(f32::INFINITY, |b| b.depth);
        }
        out.push(best);
    }
    out
}

#[test]
fn per_pixel_sorting_matches_depth_peeling_on_a_hand_built_scene() {
    // 6x7 pixels: a background, two overlapping rectangles, a tilted bar and a single-pixel speck,
    // fragments emitted in an order unrelated to depth.
    let (h, w) = (6usize, 7usize);
    let mut frags = Vec::new();
    let mut rect = |r0: usize,
                    r1: usize,
                    c0: usize,
                    c1: usize,
                    depth: &dyn Fn(usize, usize) -> f32,
                    colour: f32| {
        for y in r0..r1 {
            for x in c0..c1 {
                frags.push(Fragment {
                    row: y as u32,
                    col: x as u32,
                    depth: depth(y, x),
                    amplitude: [colour, 1.0 - colour, 0.5 * colour],
                });
            }
        }
    };
    rect(1, 5, 1, 5, &|_, _| 0.4, 0.2); // mid square
    rect(0, h, 0, w, &|y, x| 0.9 + 0.01 * (y + x) as f32 / 10.0, 0.9); // background, tilted
    rect(2, 6, 3, 7, &|_, _| 0.25, 0.5); // nearer square overlapping the first
    rect(0, 6, 4, 5, &|y, _| 0.1 + 0.12 * y as f32, 0.7); // tilted bar crossing both
    rect(3, 4, 4, 5, &|_, _| 0.05, 0.05); // speck in front of everything
    let layers = 4;
    let ldi = ldi_from_fragments(h, w, layers, &frags).unwrap();
    let reference = depth_peeling(h, w, layers, &frags);
    let mut deepest = 0;
    for (k, (layer, peel)) in ldi.layers().iter().zip(&reference).enumerate() {
        for y in 0..h {
            for x in 0..w {
                match peel[y * w + x] {
                    Some(f) => {
                        assert!(layer.valid[[y, x]], "layer {k} ({y},{x})");
                        assert_eq!(layer.depth[[y, x]], f.depth, "layer {k} ({y},{x})");
                        for c in 0..3 {
                            assert_eq!(layer.amplitude[[c, y, x]], f.amplitude[c]);
                        }
                        deepest = deepest.max(k);
                    }
                    None => {
                        assert!(!layer.valid[[y, x]], "layer {k} ({y},{x})");
                        assert_eq!(layer.depth[[y, x]], 1.0);
                    }
                }
            }
        }
    }
    // The hand-built scene really has 4 surfaces at some pixel (speck, bar, near square, mid square).
    assert_eq!(deepest, 3);
    let bar_pixel = [0, 1, 2, 3].map(|k| ldi.layers()[k].depth[[3, 4]]);
    assert_eq!(bar_pixel, [0.05, 0.25, 0.4, 0.1 + 0.12 * 3.0]);
}

#[test]
fn equal_depths_keep_fragment_order_and_bad_fragments_are_refused() {
    let f = |depth: f32, a: f32| Fragment {
        row: 0,
        col: 0,
        depth,
        amplitude: [a; 3],
    };
    let ldi = ldi_from_fragments(1, 1, 3, &[f(0.5, 0.1), f(0.2, 0.2), f(0.5, 0.3)]).unwrap();
    let got: Vec<f32> = ldi
        .layers()
        .iter()
        .map(|l| l.amplitude[[0, 0, 0]])
        .collect();
    assert_eq!(got, [0.2, 0.1, 0.3]);
    let bad = |r: tensorholo::Result<LayeredDepthImage>| r.unwrap_err();
    assert!(matches!(
        bad(ldi_from_fragments(
            1,
            1,
            1,
            &[Fragment {
                row: 1,
                ..f(0.5, 0.1)
            }]
        )),
        HoloError::InvalidParameter {
            name: "fragments",
            ..
        }
    ));
    assert!(matches!(
        bad(ldi_from_fragments(1, 1, 1, &[f(f32::NAN, 0.1)])),
        HoloError::InvalidDepth(_)
    ));
    assert!(matches!(
        bad(ldi_from_fragments(1, 1, 1, &[f(1.5, 0.1)])),
        HoloError::InvalidDepth(_)
    ));
    assert!(matches!(
        bad(ldi_from_fragments(1, 1, 1, &[f(0.5, -0.1)])),
        HoloError::InvalidData(_)
    ));
    assert!(matches!(
        bad(ldi_from_fragments(1, 1, 0, &[f(0.5, 0.1)])),
        HoloError::InvalidParameter { name: "layers", .. }
    ));
    assert!(matches!(
        bad(ldi_from_fragments(0, 1, 1, &[])),
        HoloError::InvalidParameter { name: "size", .. }
    ));
}

#[test]
fn bad_scene_configurations_name_the_field() {
    let cases: [(RandomSceneConfig, &str); 6] = [
        (
            RandomSceneConfig {
                layers: 0,
                ..small(8, 8)
            },
            "layers",
        ),
        (
            RandomSceneConfig {
                height: 0,
                ..small(8, 8)
            },
            "size",
        ),
        (
            RandomSceneConfig {
                shape_count: [5, 4],
                ..small(8, 8)
            },
            "shape_count",
        ),
        (
            RandomSceneConfig {
                thin_probability: 1.5,
                ..small(8, 8)
            },
            "thin_probability",
        ),
        (
            RandomSceneConfig {
                shape_depth: [0.2, 1.2],
                ..small(8, 8)
            },
            "shape_depth",
        ),
        (
            RandomSceneConfig {
                shape_size: [0.0, 0.2],
                ..small(8, 8)
            },
            "shape_size",
        ),
    ];
    for (c, field) in cases {
        match random_ldi(&c, 0) {
            Err(HoloError::InvalidParameter { name, .. }) => assert_eq!(name, field),
            other => panic!("{field}: {other:?}"),
        }
    }
}

/// Writes a 2-colour PNG photo.
fn write_photo(path: &Path, w: u32, h: u32, a: [u8; 3], b: [u8; 3]) {
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        image::Rgb(if (x / 3 + y / 5) % 2 == 0 { a } else { b })
    });
    img.save(path).unwrap();
}

#[test]
fn photo_textures_are_used_deterministically() {
    let dir = scratch("photos");
    // Pure red/green photos: with photo_probability 1 every base texture is a crop of them.
    write_photo(&dir.join("a.png"), 40, 30, [255, 0, 0], [0, 255, 0]);
    write_photo(&dir.join("b.PNG"), 20, 50, [255, 0, 0], [0, 255, 0]);
    fs::write(dir.join("notes.txt"), "not a photo").unwrap();
    let c = RandomSceneConfig {
        photo_folder: Some(dir.clone()),
        photo_probability: 1.0,
        ..small(32, 32)
    };
    let g = RandomSceneGenerator::new(c.clone()).unwrap();
    assert_eq!(g.photo_paths().len(), 2);
    let a = g.generate(3).unwrap();
    assert_eq!(a, random_ldi(&c, 3).unwrap());
    let plain = random_ldi(&small(32, 32), 3).unwrap();
    assert_ne!(a, plain);
    // Blue only enters through overlays and shading-free procedural mixtures, so red/green dominate.
    let l0 = &a.layers()[0].amplitude;
    let (r, g_, b): (f32, f32, f32) = (
        l0.slice(ndarray::s![0, .., ..]).sum(),
        l0.slice(ndarray::s![1, .., ..]).sum(),
        l0.slice(ndarray::s![2, .., ..]).sum(),
    );
    assert!(r + g_ > 2.0 * b, "r {r} g {g_} b {b}");
    let empty = scratch("no_photos");
    let c = RandomSceneConfig {
        photo_folder: Some(empty),
        ..small(8, 8)
    };
    assert!(matches!(
        random_ldi(&c, 0),
        Err(HoloError::InvalidParameter {
            name: "photo_folder",
            ..
        })
    ));
}

fn tiny_config(train: usize, val: usize, test: usize, shard_size: usize) -> DatasetConfig {
    DatasetConfig {
        scene: small(24, 20),
        synthesis: SmLbm {
            levels: 16,
            ..SmLbm::default()
        },
        aberration: None,
        seed: 5,
        train,
        val,
        test,
        shard_size,
        compress: true,
    }
}

#[test]
fn sample_seeds_differ_across_splits_and_indices() {
    let mut seen = std::collections::HashSet::new();
    for split in Split::ALL {
        for i in 0..200 {
            assert!(seen.insert(sample_seed(1, split, i)));
        }
    }
    assert_ne!(
        sample_seed(1, Split::Train, 0),
        sample_seed(2, Split::Train, 0)
    );
    assert_eq!(sample_seed(1, Split::Val, 3), sample_seed(1, Split::Val, 3));
}

#[test]
fn shards_read_back_with_shapes_dtypes_and_the_direct_sm_lbm_hologram() {
    let dir = scratch("shard");
    let config = tiny_config(3, 0, 0, 3);
    let g = SampleGenerator::new(&config).unwrap();
    let samples: Vec<_> = (0..3).map(|i| g.sample(Split::Train, i).unwrap()).collect();
    for compress in [false, true] {
        let path = dir.join(format!("s{compress}.npz"));
        write_shard(&path, &samples, compress).unwrap();
        let shard = read_shard(&path).unwrap();
        assert_eq!(shard.ldi.dim(), (3, 20, 24, 20));
        assert_eq!(shard.ldi_valid.dim(), (3, 5, 24, 20));
        assert_eq!(shard.midpoint.dim(), (3, 3, 24, 20));
        assert_eq!(shard.index, Array1::from(vec![0u64, 1, 2]));
        // dtypes: reading a member as another type fails.
        let mut npz = NpzReader::new(fs::File::open(&path).unwrap()).unwrap();
        let mut names = npz.names().unwrap();
        names.sort();
        assert_eq!(names, ["index", "ldi", "ldi_valid", "midpoint", "seed"]);
        assert!(npz
            .by_name::<ndarray::OwnedRepr<f64>, ndarray::Ix4>("ldi")
            .is_err());
        assert!(npz
            .by_name::<ndarray::OwnedRepr<f32>, ndarray::Ix4>("ldi")
            .is_ok());
        assert!(npz
            .by_name::<ndarray::OwnedRepr<bool>, ndarray::Ix4>("ldi_valid")
            .is_err());
        assert!(npz
            .by_name::<ndarray::OwnedRepr<Complex32>, ndarray::Ix4>("midpoint")
            .is_ok());
        for (i, s) in samples.iter().enumerate() {
            assert_eq!(shard.seed[i], sample_seed(5, Split::Train, i as u64));
            // The LDI round-trips, and equals the scene regenerated from the stored seed.
            let ldi = shard.sample_ldi(i).unwrap();
            assert_eq!(ldi, s.ldi);
            assert_eq!(ldi, random_ldi(&config.scene, shard.seed[i]).unwrap());
            // The stored hologram is exactly SM-LBM run directly on that LDI.
            let direct = config
                .synthesis
                .synthesize(&ldi_layers(&ldi), &|_, _| {})
                .unwrap();
            assert_eq!(shard.midpoint.index_axis(ndarray::Axis(0), i), direct);
            assert!(direct.iter().any(|v| v.norm() > 0.05));
        }
    }
    assert!(write_shard(&dir.join("empty.npz"), &[], false).is_err());
}

#[test]
fn ldi_tensor_layout_and_its_inverse() {
    let ldi = random_ldi(&small(10, 12), 4).unwrap();
    let (x, v) = ldi_tensor(&ldi);
    assert_eq!(x.dim(), (20, 10, 12));
    let l1 = &ldi.layers()[1];
    for ((y, xx), &ok) in l1.valid.indexed_iter() {
        assert_eq!(v[[1, y, xx]], u8::from(ok));
        assert_eq!(x[[4 + 3, y, xx]], if ok { l1.depth[[y, xx]] } else { 1.0 });
        assert_eq!(
            x[[4 + 1, y, xx]],
            if ok { l1.amplitude[[1, y, xx]] } else { 0.0 }
        );
    }
    assert_eq!(ldi_from_tensor(x.view(), v.view()).unwrap(), ldi);
    let wrong = v.slice(ndarray::s![0..4, .., ..]);
    assert!(matches!(
        ldi_from_tensor(x.view(), wrong),
        Err(HoloError::ShapeMismatch { .. })
    ));
}

#[test]
fn generate_writes_consistent_shards_and_manifest_and_refuses_an_existing_dataset() {
    let dir = scratch("generate");
    let config = tiny_config(3, 1, 2, 2);
    let calls = std::sync::atomic::AtomicU64::new(0);
    let manifest = generate(&dir, &config, &GenerateOptions::default(), &|_, total| {
        assert_eq!(total, 6);
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    })
    .unwrap();
    assert_eq!(calls.into_inner(), 6);
    assert_eq!(read_manifest(&dir).unwrap(), manifest);
    assert_eq!(
        (manifest.format.as_str(), manifest.format_version),
        (FORMAT_NAME, FORMAT_VERSION)
    );
    assert_eq!(manifest.plan.resolution, [24, 20]);
    assert_eq!(manifest.plan.ldi_layers, 5);
    assert_eq!(manifest.plan.synthesis.levels, 16);
    assert_eq!(manifest.plan.optics.wavelengths_m, [638e-9, 520e-9, 450e-9]);
    assert_eq!(manifest.generator.git_commit, "unknown");
    assert_eq!(manifest.statistics.samples, 6);
    assert!(manifest.statistics.mean_nonempty_planes >= 1.0);
    assert!(manifest.statistics.max_nonempty_planes <= 16);
    let counts: Vec<(Split, usize, Vec<usize>)> = manifest
        .plan
        .splits
        .iter()
        .map(|s| {
            (
                s.name,
                s.samples,
                s.shards.iter().map(|f| f.samples).collect(),
            )
        })
        .collect();
    assert_eq!(
        counts,
        [
            (Split::Train, 3, vec![2, 1]),
            (Split::Val, 1, vec![1]),
            (Split::Test, 2, vec![2])
        ]
    );
    let g = SampleGenerator::new(&config).unwrap();
    for split in &manifest.plan.splits {
        let mut next = 0;
        for (k, f) in split.shards.iter().enumerate() {
            assert_eq!(f.file, shard_file_name(split.name, k));
            assert_eq!(f.first_index, next);
            let shard = read_shard(&dir.join(&f.file)).unwrap();
            assert_eq!(shard.len(), f.samples);
            for i in 0..f.samples {
                let index = f.first_index + i;
                assert_eq!(shard.index[i], index as u64);
                assert_eq!(shard.seed[i], sample_seed(5, split.name, index as u64));
                assert_eq!(
                    shard.sample_ldi(i).unwrap(),
                    g.ldi(split.name, index).unwrap()
                );
            }
            next += f.samples;
        }
        assert_eq!(next, split.samples);
    }
    // No temporary files are left behind.
    let names: Vec<String> = fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.starts_with('.')), "{names:?}");

    // An existing dataset is refused without overwrite ...
    let err = generate(&dir, &config, &GenerateOptions::default(), &|_, _| {}).unwrap_err();
    assert!(
        matches!(
            err,
            HoloError::InvalidParameter {
                name: "out_dir",
                ..
            }
        ),
        "{err}"
    );
    assert!(dir.join("train-00001.npz").exists());
    // ... and replaced with it; shards of the old dataset that the new one lacks are removed.
    let smaller = tiny_config(2, 1, 0, 2);
    let options = GenerateOptions {
        overwrite: true,
        git_commit: Some("abc123".into()),
        command: vec!["holo".into(), "dataset".into()],
        ..GenerateOptions::default()
    };
    let m2 = generate(&dir, &smaller, &options, &|_, _| {}).unwrap();
    assert_eq!(m2.generator.git_commit, "abc123");
    assert!(!dir.join("train-00001.npz").exists());
    assert!(!dir.join("test-00000.npz").exists());
    assert!(dir.join("train-00000.npz").exists() && dir.join(MANIFEST_FILE).exists());
    assert_eq!(read_shard(&dir.join("train-00000.npz")).unwrap().len(), 2);
}

#[test]
fn bad_dataset_configurations_are_refused_before_writing() {
    let dir = scratch("bad").join("out");
    for (config, name) in [
        (tiny_config(0, 0, 0, 2), "samples"),
        (tiny_config(1, 0, 0, 0), "shard_size"),
        (
            DatasetConfig {
                synthesis: SmLbm {
                    levels: 0,
                    ..SmLbm::default()
                },
                ..tiny_config(1, 0, 0, 1)
            },
            "levels",
        ),
    ] {
        match generate(&dir, &config, &GenerateOptions::default(), &|_, _| {}) {
            Err(HoloError::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
            other => panic!("{name}: {other:?}"),
        }
        assert!(!dir.exists());
    }
}

#[test]
fn a_shard_with_inconsistent_arrays_is_refused() {
    let dir = scratch("inconsistent");
    let path = dir.join("bad.npz");
    let mut npz = ndarray_npy::NpzWriter::new(fs::File::create(&path).unwrap());
    npz.add_array("ldi", &Array4::<f32>::zeros((2, 8, 4, 4)))
        .unwrap();
    npz.add_array("ldi_valid", &Array4::<u8>::zeros((2, 3, 4, 4)))
        .unwrap();
    npz.add_array("midpoint", &Array4::<Complex32>::zeros((2, 3, 4, 4)))
        .unwrap();
    npz.add_array("seed", &Array1::<u64>::zeros(2)).unwrap();
    npz.add_array("index", &Array1::<u64>::zeros(2)).unwrap();
    npz.finish().unwrap();
    assert!(matches!(
        read_shard(&path),
        Err(HoloError::ShapeMismatch { .. })
    ));
    fs::write(&path, b"not a zip").unwrap();
    assert!(matches!(read_shard(&path), Err(HoloError::Npy { .. })));
}

#[test]
fn an_aberration_corrected_dataset_records_its_correction_and_stores_the_corrected_hologram() {
    use tensorholo::display::AberrationProfile;
    use tensorholo::optics::ZernikeCoefficients;
    use tensorholo::synthesis::AberrationCorrection;
    let dir = scratch("aberration");
    let profile = AberrationProfile::uniform(ZernikeCoefficients {
        astigmatism_vertical: 2.0,
        ..ZernikeCoefficients::ZERO
    });
    let config = DatasetConfig {
        synthesis: SmLbm {
            levels: 6,
            ..SmLbm::default()
        },
        aberration: Some(AberrationCorrection {
            profile: profile.clone(),
            slm_offset_m: 3e-3,
        }),
        ..tiny_config(1, 0, 0, 1)
    };
    let options = GenerateOptions {
        aberration_file: Some(PathBuf::from("calibration/aberration.json")),
        ..GenerateOptions::default()
    };
    let manifest = generate(&dir, &config, &options, &|_, _| {}).unwrap();
    assert_eq!(read_manifest(&dir).unwrap(), manifest);
    let info = manifest
        .plan
        .synthesis
        .aberration
        .as_ref()
        .expect("recorded");
    assert_eq!(info.profile, profile);
    assert_eq!(info.slm_offset_m, 3e-3);
    assert_eq!(
        info.file.as_deref(),
        Some(Path::new("calibration/aberration.json"))
    );
    assert!(manifest.plan.synthesis.method.contains("aberration"));
    let shard = read_shard(&dir.join(shard_file_name(Split::Train, 0))).unwrap();
    let ldi = shard.sample_ldi(0).unwrap();
    let expected = config
        .corrected_synthesis()
        .unwrap()
        .synthesize(&ldi_layers(&ldi), &|_, _| {})
        .unwrap();
    let plain = config
        .synthesis
        .synthesize(&ldi_layers(&ldi), &|_, _| {})
        .unwrap();
    let stored = shard.midpoint.index_axis(ndarray::Axis(0), 0);
    let diff = |a: &ndarray::Array3<Complex32>| {
        stored
            .iter()
            .zip(a.iter())
            .map(|(x, y)| (x - y).norm())
            .fold(0.0f32, f32::max)
    };
    assert!(diff(&expected) < 1e-5, "{}", diff(&expected));
    assert!(diff(&plain) > 1e-3, "{}", diff(&plain));
}

#[test]
fn a_shard_declaring_a_huge_array_is_refused_before_allocating_it() {
    // A 300-byte .npz whose `ldi.npy` header declares 4·10^15 floats: ndarray-npy's NpzReader allocates the
    // declared shape first (an abort); the shard reader checks the header against the entry's bytes.
    use std::io::Write;
    let dir = scratch("huge_shard");
    let path = dir.join("train-00000.npz");
    let mut zip = zip::ZipWriter::new(fs::File::create(&path).unwrap());
    let mut header =
        "{'descr': '<f4', 'fortran_order': False, 'shape': (1000, 20, 1000000, 200000), }"
            .to_string();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut npy = b"\x93NUMPY\x01\x00".to_vec();
    npy.extend((header.len() as u16).to_le_bytes());
    npy.extend(header.as_bytes());
    npy.extend([0u8; 64]);
    zip.start_file("ldi.npy", zip::write::SimpleFileOptions::default())
        .unwrap();
    zip.write_all(&npy).unwrap();
    zip.finish().unwrap();
    match read_shard(&path) {
        Err(HoloError::Npy { path: p, reason }) => {
            assert_eq!(p, path);
            assert!(
                reason.contains("`ldi`") && reason.contains("more bytes"),
                "{reason}"
            );
        }
        other => panic!("expected an Npy error, got {:?}", other.map(|s| s.len())),
    }
    // A missing array is named too.
    let mut zip = zip::ZipWriter::new(fs::File::create(&path).unwrap());
    zip.start_file("other.npy", zip::write::SimpleFileOptions::default())
        .unwrap();
    zip.write_all(&npy).unwrap();
    zip.finish().unwrap();
    let e = read_shard(&path).unwrap_err();
    assert!(e.to_string().contains("`ldi`"), "{e}");
}
