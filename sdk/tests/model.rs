//! The CNN loader and runner (`tensorholo::model`, docs/CONVENTIONS.md §7) on the tiny random-init fixtures
//! written by `fixtures/models/make_models.py` with the training package's own ONNX export.
// Some helpers and imports serve only the tests that compare with tract (cargo feature `tract`).
#![cfg_attr(not(feature = "tract"), allow(unused_imports, dead_code))]

use std::path::{Path, PathBuf};

use ndarray::{Array3, ArrayView3};
#[cfg(feature = "tract")]
use tensorholo::cnn::tract::TractModel;
use tensorholo::cnn::CnnLayout;
use tensorholo::model::{heads_to_field, HologramModel, ModelConfig, ModelKind};
use tensorholo::scene::RgbdFrame;
use tensorholo::HoloError;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/models")
        .join(name)
}

fn npy(name: &str) -> Array3<f32> {
    ndarray_npy::read_npy(fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn max_abs_diff(a: ArrayView3<f32>, b: ArrayView3<f32>) -> f32 {
    assert_eq!(a.shape(), b.shape());
    a.iter()
        .zip(b.iter())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

fn hologram(name: &str) -> HologramModel {
    HologramModel::from_path(fixture(name), ModelKind::Hologram, &ModelConfig::default())
        .unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn prefilter() -> HologramModel {
    HologramModel::from_path(
        fixture("holo8_rgbd.prefilter.onnx"),
        ModelKind::PreFilter,
        &ModelConfig::default(),
    )
    .unwrap()
}

/// tract's side of `model` (its plans, cached in the returned value).
#[cfg(feature = "tract")]
fn tract(model: &HologramModel) -> TractModel {
    TractModel::new(model).unwrap_or_else(|e| panic!("{}: {e}", model.source_name()))
}

/// Runs `model` on `io_{prefix}_{HxW}_input.npy` and compares both heads with the reference outputs.
#[cfg(feature = "tract")]
fn compare(model: &TractModel, prefix: &str, size: &str, reference: &str, tol: f32) -> (f32, f32) {
    compare_in(
        model,
        CnnLayout::ChannelsFirst,
        prefix,
        size,
        reference,
        tol,
    )
}

/// [`compare`] with a plan in `layout`.
#[cfg(feature = "tract")]
fn compare_in(
    model: &TractModel,
    layout: CnnLayout,
    prefix: &str,
    size: &str,
    reference: &str,
    tol: f32,
) -> (f32, f32) {
    let x = npy(&format!("io_{prefix}_{size}_input.npy"));
    let (_, h, w) = x.dim();
    let plan = model.plan_with_layout(h, w, layout).unwrap();
    assert_eq!(plan.layout(), layout);
    let (a, p) = plan.run_outputs(x.view()).unwrap();
    let [first, second] = model.kind().output_names();
    let da = max_abs_diff(
        a.view(),
        npy(&format!("io_{reference}_{size}_{first}.npy")).view(),
    );
    let dp = max_abs_diff(
        p.view(),
        npy(&format!("io_{reference}_{size}_{second}.npy")).view(),
    );
    assert!(
        da <= tol && dp <= tol,
        "{reference} {size}: max |Δ{first}| {da}, |Δ{second}| {dp} > {tol}"
    );
    // The complex output is exactly the outputs' field: heads → A·e^{i(p−0.5)2π}, or Re + i·Im.
    let field = plan.run(x.view()).unwrap();
    let want = match model.kind() {
        ModelKind::Hologram => heads_to_field(a.view(), p.view()).unwrap(),
        ModelKind::PreFilter => ndarray::Zip::from(&a)
            .and(&p)
            .map_collect(|&re, &im| num_complex::Complex32::new(re, im)),
    };
    assert_eq!(field, want);
    (da, dp)
}

#[test]
#[cfg(feature = "tract")]
fn f32_hologram_cnn_matches_pytorch_at_two_resolutions_from_one_file() {
    let m = hologram("holo8_rgbd.onnx");
    assert_eq!(m.kind(), ModelKind::Hologram);
    assert_eq!(m.input_channels(), 4);
    assert_eq!(m.metadata().layers, 8);
    assert_eq!(m.metadata().channels, Some(24));
    assert_eq!(m.metadata().trained_resolution, [384, 384]);
    assert_eq!(m.metadata().training_commit, "fixture");
    assert_eq!(m.metadata().precision, "f32");
    let t = tract(&m);
    compare(&t, "holo", "24x32", "holo", 1e-4);
    compare(&t, "holo", "16x20", "holo", 1e-4);
    // Second time: cached plans, same answer.
    compare(&t, "holo", "24x32", "holo", 1e-4);
    assert_eq!(t.planned_resolutions(), vec![(16, 20), (24, 32)]);
}

#[test]
#[cfg(feature = "tract")]
fn f32_prefilter_cnn_matches_pytorch() {
    let m = prefilter();
    assert_eq!(m.input_channels(), 6);
    let t = tract(&m);
    compare(&t, "pre", "24x32", "pre", 1e-4);
    compare(&t, "pre", "16x20", "pre", 1e-4);
}

#[test]
#[cfg(feature = "tract")]
fn field_is_amplitude_times_centred_phase() {
    let a = Array3::from_elem((3, 1, 2), 1.0f32);
    let mut p = Array3::from_elem((3, 1, 2), 0.5f32);
    p[[0, 0, 1]] = 0.75; // (0.75 − 0.5)·2π = π/2
    let f = heads_to_field(a.view(), p.view()).unwrap();
    assert!((f[[0, 0, 0]].re - 1.0).abs() < 1e-6 && f[[0, 0, 0]].im.abs() < 1e-6);
    assert!(f[[0, 0, 1]].re.abs() < 1e-6 && (f[[0, 0, 1]].im - 1.0).abs() < 1e-6);
}

#[test]
#[cfg(feature = "tract")]
fn run_frame_feeds_amplitude_then_depth() {
    let m = tract(&hologram("holo8_rgbd.onnx"));
    let x = npy("io_holo_16x20_input.npy");
    let frame = RgbdFrame::new(
        x.slice(ndarray::s![..3, .., ..]).to_owned(),
        x.slice(ndarray::s![3, .., ..]).to_owned(),
    )
    .unwrap();
    assert_eq!(m.run_frame(&frame).unwrap(), m.run(x.view()).unwrap());
    let pre = tract(&prefilter());
    assert!(matches!(
        pre.run_frame(&frame),
        Err(HoloError::InvalidParameter { .. })
    ));
}

#[test]
fn metadata_mismatch_is_refused_naming_key_and_values() {
    let bytes = std::fs::read(fixture("holo8_rgbd.onnx")).unwrap();
    // A pitch changed alone: the 8 µm model serves 6.4 µm only with the volume σ·6 mm = 3.84 mm.
    let mut cfg = ModelConfig::default();
    cfg.optics.pixel_pitch_m = 6.4e-6;
    let e = HologramModel::from_bytes(&bytes, ModelKind::Hologram, &cfg).unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(&e, HoloError::DisplayNotServed(r) if r.key == "tensorholo.volume_depth_m"),
        "{msg}"
    );
    assert!(
        msg.contains("0.006") && msg.contains("3.84 mm") && msg.contains("6.4 µm"),
        "{msg}"
    );
    // A pitch so fine that the paraxial mapping no longer holds: refused naming the pitch, whatever
    // the volume and offset.
    let mut cfg = ModelConfig::default();
    let sigma = (2.5e-6f64 / 8e-6).powi(2);
    cfg.optics.pixel_pitch_m = 2.5e-6;
    cfg.optics.volume_depth_m = sigma * 6e-3;
    cfg.offset_m = sigma * 6e-3;
    let e = HologramModel::from_bytes(&bytes, ModelKind::Hologram, &cfg).unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(&e, HoloError::DisplayNotServed(r) if r.key == "tensorholo.pixel_pitch_m"),
        "{msg}"
    );
    assert!(
        msg.contains("0.000008") && msg.contains("non-paraxial"),
        "{msg}"
    );

    let cfg = ModelConfig {
        offset_m: 12e-3,
        ..ModelConfig::default()
    };
    let e = HologramModel::from_bytes(&bytes, ModelKind::Hologram, &cfg).unwrap_err();
    assert!(
        matches!(&e, HoloError::DisplayNotServed(r) if r.key == "tensorholo.offset_m"),
        "{e}"
    );

    let mut cfg = ModelConfig::default();
    cfg.optics.wavelengths_m[2] = 473e-9;
    let e = HologramModel::from_bytes(&bytes, ModelKind::Hologram, &cfg).unwrap_err();
    assert!(
        matches!(&e, HoloError::DisplayNotServed(r) if r.key == "tensorholo.wavelengths_m"),
        "{e}"
    );

    let cfg = ModelConfig {
        input_layers: 5,
        ..ModelConfig::default()
    };
    let e = HologramModel::from_bytes(&bytes, ModelKind::Hologram, &cfg).unwrap_err();
    assert!(
        matches!(&e, HoloError::ModelMetadata { key, .. } if key == "tensorholo.input_layers"),
        "{e}"
    );

    // A hologram CNN where a pre-filter is expected.
    let e = HologramModel::from_bytes(&bytes, ModelKind::PreFilter, &ModelConfig::default())
        .unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(&e, HoloError::ModelMetadata { key, .. } if key == "tensorholo.kind"),
        "{msg}"
    );
    assert!(
        msg.contains("hologram-cnn") && msg.contains("prefilter-cnn"),
        "{msg}"
    );
}

#[test]
fn corrupt_truncated_or_empty_files_give_clear_errors() {
    let bytes = std::fs::read(fixture("holo8_rgbd.onnx")).unwrap();
    let cfg = ModelConfig::default();
    for (what, data) in [
        ("truncated", bytes[..bytes.len() / 2].to_vec()),
        (
            "garbage",
            (0..4096u32)
                .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
                .collect(),
        ),
        ("empty", Vec::new()),
        ("text", b"this is not an onnx file\n".to_vec()),
    ] {
        match HologramModel::from_bytes(&data, ModelKind::Hologram, &cfg) {
            Err(HoloError::ModelLoad {
                source_name,
                reason,
            }) => {
                assert_eq!(source_name, "<bytes>");
                assert!(!reason.is_empty(), "{what}");
            }
            Err(e) => panic!("{what}: unexpected error kind: {e}"),
            Ok(_) => panic!("{what}: a corrupt file was accepted"),
        }
    }
    let e = HologramModel::from_path(fixture("does-not-exist.onnx"), ModelKind::Hologram, &cfg)
        .unwrap_err();
    assert!(matches!(e, HoloError::Io { .. }), "{e}");
}

#[test]
fn onnx_with_other_inputs_is_refused() {
    let e = HologramModel::from_path(
        fixture("other_input.onnx"),
        ModelKind::Hologram,
        &ModelConfig::default(),
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, HoloError::ModelContract { .. }), "{msg}");
    assert!(msg.contains("`rgbd`") && msg.contains("image"), "{msg}");
}

#[test]
#[cfg(feature = "tract")]
fn wrong_input_size_is_an_error_and_the_model_stays_usable() {
    let m = tract(&hologram("holo8_rgbd.onnx"));
    let plan = m.plan(24, 32).unwrap();
    assert_eq!(plan.input_dim(), (4, 24, 32));
    let small = npy("io_holo_16x20_input.npy");
    let e = plan.run(small.view()).unwrap_err();
    assert!(matches!(e, HoloError::ShapeMismatch { .. }), "{e}");
    let three = Array3::<f32>::zeros((3, 24, 32));
    assert!(matches!(
        m.run(three.view()),
        Err(HoloError::ShapeMismatch { .. })
    ));
    let mut nan = Array3::<f32>::zeros((4, 24, 32));
    nan[[0, 1, 2]] = f32::NAN;
    assert!(matches!(
        plan.run(nan.view()),
        Err(HoloError::InvalidData(_))
    ));
    assert!(matches!(
        m.plan(0, 32),
        Err(HoloError::InvalidParameter { .. })
    ));
    compare(&m, "holo", "24x32", "holo", 1e-4);
}

/// int8 files from `export.quantize_int8`. tract 0.23 runs both forms (QOperator `QLinearConv` and QDQ, the
/// latter parsed with value infos ignored); they are compared with onnxruntime's outputs of the same file.
/// Measured on x86-64: bit-identical to onnxruntime (the quantised last conv leaves 193 distinct output
/// values), while int8 vs f32 differ by up to 5e-3; the tolerance allows about one output quantum of
/// rounding difference on other CPUs.
#[test]
#[cfg(feature = "tract")]
fn int8_qoperator_and_qdq_files_load_and_run() {
    for (file, tag) in [
        ("holo8_rgbd.int8-qop.onnx", "holo_int8-qop"),
        ("holo8_rgbd.int8-qdq.onnx", "holo_int8-qdq"),
    ] {
        let model = hologram(file);
        assert!(model.metadata().precision.starts_with("int8-"), "{file}");
        let m = tract(&model);
        let (da, dp) = compare(&m, "holo", "24x32", tag, 0.02);
        eprintln!("{file}: tract vs onnxruntime max |Δamplitude| {da:.2e}, |Δphase| {dp:.2e}");
        let x = npy("io_holo_16x20_input.npy");
        assert_eq!(m.run(x.view()).unwrap().dim(), (3, 16, 20));
        if tag.ends_with("qdq") {
            // QDQ is float convolutions between quantise/dequantise pairs: it moves channels-last too.
            compare_in(&m, CnnLayout::ChannelsLast, "holo", "24x32", tag, 0.02);
        } else {
            // tract 0.23 cannot move a quantised convolution (`QLinearConv`) channels-last: a clear error,
            // and the model stays usable in its own layout.
            let err = m
                .plan_with_layout(16, 20, CnnLayout::ChannelsLast)
                .unwrap_err();
            assert!(
                matches!(&err, HoloError::InvalidParameter { name, reason }
                    if *name == "layout" && reason.contains("nhwc") && reason.contains(file)),
                "{file}: {err}"
            );
            assert_eq!(m.run(x.view()).unwrap().dim(), (3, 16, 20));
        }
    }
}

/// The channels-last plan (the whole graph moved NHWC by tract) computes the same network: it matches the
/// PyTorch reference like the channels-first plan, at two sizes, for the hologram CNN, while taking and
/// returning `[C, H, W]` arrays. Both plans of one resolution live side by side in the model's cache.
#[test]
#[cfg(feature = "tract")]
fn channels_last_plans_match_pytorch_with_the_same_chw_interface() {
    let m = tract(&hologram("holo8_rgbd.onnx"));
    for size in ["24x32", "16x20"] {
        compare_in(&m, CnnLayout::ChannelsLast, "holo", size, "holo", 1e-4);
        compare_in(&m, CnnLayout::ChannelsFirst, "holo", size, "holo", 1e-4);
    }
    assert_eq!(m.planned_resolutions(), vec![(16, 20), (24, 32)]);
    let pre = tract(&prefilter());
    // The pre-filter's graph (format 2: residual on the fixed blur, outputs split into real and imaginary
    // parts) does not move to channels-last in tract 0.23: refused clearly, and the model stays usable.
    // The pipeline runs it channels-first anyway (it measured 2.1× slower channels-last in format 1).
    let e = pre
        .plan_with_layout(24, 32, CnnLayout::ChannelsLast)
        .unwrap_err();
    assert!(
        matches!(&e, HoloError::InvalidParameter { name, .. } if *name == "layout"),
        "{e}"
    );
    compare_in(&pre, CnnLayout::ChannelsFirst, "pre", "24x32", "pre", 1e-4);
    // What tract runs differs (rows of ≥ 128 pixels): channels-first takes tract's direct spatial
    // convolution, channels-last pads explicitly and gathers a lazy im2col for a matrix product.
    let ops = |layout| -> Vec<String> {
        m.plan_with_layout(8, 128, layout)
            .unwrap()
            .operators()
            .into_iter()
            .map(|(_, op)| op)
            .collect()
    };
    let (first, last) = (ops(CnnLayout::ChannelsFirst), ops(CnnLayout::ChannelsLast));
    let count = |ops: &[String], name: &str| ops.iter().filter(|op| *op == name).count();
    assert_eq!(count(&first, "DirectSpatialConv"), 8, "{first:?}");
    assert_eq!(count(&last, "DirectSpatialConv"), 0, "{last:?}");
    assert_eq!(count(&last, "LazyIm2col"), 8, "{last:?}");
    assert_eq!(count(&last, "Pad"), 8, "{last:?}");
}

/// `ModelPlan::profile` times every evaluated operator of the plan once, and its operators are the plan's.
#[test]
#[cfg(feature = "tract")]
fn profile_times_each_operator_of_the_plan() {
    let m = tract(&hologram("holo8_rgbd.onnx"));
    let x = npy("io_holo_24x32_input.npy");
    let plan = m.plan(24, 32).unwrap();
    let timings = plan.profile(x.view()).unwrap();
    let operators = plan.operators();
    assert!(timings.len() >= 8, "{timings:?}");
    for t in &timings {
        assert!(t.seconds >= 0.0 && t.seconds.is_finite());
        assert!(
            operators
                .iter()
                .any(|(node, op)| *node == t.node && *op == t.op),
            "{t:?} not among {operators:?}"
        );
    }
    // Bad input is refused as by run_outputs.
    assert!(matches!(
        plan.profile(x.slice(ndarray::s![.., ..16, ..]))
            .unwrap_err(),
        HoloError::ShapeMismatch { .. }
    ));
}

/// Format 2 changed the pre-filter's I/O to `[Re H, Im H]` → `real`, `imag`: a format-1 (amplitude/phase)
/// pre-filter is refused by its metadata with a message saying what to do; a format-1 hologram CNN (same I/O in
/// both versions) still loads, and a format newer than this SDK is refused.
#[test]
fn format_1_prefilters_are_refused_and_format_1_hologram_cnns_load() {
    use tensorholo::model::{ModelMetadata, FORMAT_VERSION, PREFILTER_FORMAT_VERSION};
    let pre = prefilter();
    assert_eq!(pre.metadata().format_version, PREFILTER_FORMAT_VERSION);
    assert_eq!(pre.metadata().hologram_layers, Some(8));
    let mut raw = pre.metadata().raw.clone();
    raw.insert("tensorholo.hologram_layers".into(), "eight".into());
    let e = ModelMetadata::from_props(raw).unwrap_err();
    assert!(e.to_string().contains("hologram_layers"), "{e}");
    assert_eq!(ModelKind::PreFilter.output_names(), ["real", "imag"]);
    let key = "tensorholo.format_version".to_string();
    let with_version = |raw: &std::collections::BTreeMap<String, String>, v: Option<&str>| {
        let mut raw = raw.clone();
        match v {
            Some(v) => raw.insert(key.clone(), v.into()),
            None => raw.remove(&key),
        };
        ModelMetadata::from_props(raw)
    };
    for old in [Some("1"), None] {
        let e = with_version(&pre.metadata().raw, old).unwrap_err();
        assert!(
            matches!(&e, HoloError::ModelMetadata { key, .. } if key == "tensorholo.format_version"),
            "{e}"
        );
        assert!(e.to_string().contains("amplitude/phase"), "{e}");
    }
    let newer = (FORMAT_VERSION + 1).to_string();
    assert!(with_version(&pre.metadata().raw, Some(&newer)).is_err());
    let holo = hologram("holo8_rgbd.onnx");
    assert_eq!(holo.metadata().format_version, 1);
    assert_eq!(
        with_version(&holo.metadata().raw, None)
            .unwrap()
            .format_version,
        1
    );
    assert!(with_version(&holo.metadata().raw, Some("2")).is_ok());
    assert!(with_version(&holo.metadata().raw, Some(&newer)).is_err());
}

#[test]
#[cfg(feature = "tract")]
fn a_model_that_panics_tract_is_a_load_error_not_a_crash() {
    // Found by the `onnx_model` fuzz target: a mutated hologram CNN whose convolution has fewer kernel
    // dimensions than its input makes tract 0.23 panic (index out of bounds in its padding computation) while
    // typing the graph. tract runs under catch_unwind: the file is refused as malformed, by tract's side of
    // the model and when a pipeline is made (the file is not the TensorHolo CNN, so no other engine runs it).
    let bytes = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/fuzz/onnx_model/tract-padding-panic"
    ))
    .unwrap();
    let model = std::sync::Arc::new(
        HologramModel::from_bytes(&bytes, ModelKind::Hologram, &ModelConfig::default()).unwrap(),
    );
    for e in [
        TractModel::new(&model).unwrap_err(),
        tensorholo::cnn::check_runnable(&model).unwrap_err(),
    ] {
        assert!(
            matches!(&e, HoloError::ModelLoad { reason, .. } if reason.contains("panicked")),
            "{e}"
        );
    }
}
