//! The native engine against tract on every shipped f32 CNN, on random inputs; threads, ISAs, `spawn`, bad
//! input and the engine choice.

use std::sync::Arc;

use ndarray::Array3;
use tensorholo_kernels::{Algorithm, Isa};

use super::native::{
    table_plan as native_plan, Choice, NativeInt8Plan, NativePlan, PlanSpec, Rows, TABLE_ROWS,
};
use super::{select, CnnEngine, CnnPlan};
use crate::cnn::{CnnOptions, ConvAlgorithm, PlanRequest, ThreadCount};
use crate::error::HoloError;
use crate::model::{embedded, HologramModel, ModelConfig, Precision};

/// Deterministic input in [0, 1) (xorshift), with a few exact 0s and 1s (invalid LDI points, clipped depth).
fn input(c: usize, h: usize, w: usize, seed: u64) -> Array3<f32> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    Array3::from_shape_fn((c, h, w), |_| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        match s % 23 {
            0 => 0.0,
            1 => 1.0,
            _ => (s >> 40) as f32 / (1u64 << 24) as f32,
        }
    })
}

fn shipped() -> Vec<HologramModel> {
    let cfg = |offset_m| ModelConfig {
        offset_m,
        ..ModelConfig::default()
    };
    let mut v = Vec::new();
    for layers in [8, 15, 30] {
        if let Ok(m) = embedded::hologram_model(layers, Precision::F32, &cfg(0.0)) {
            v.push(m);
        }
    }
    for mm in [6, 12] {
        v.push(embedded::prefilter_model(mm, Precision::F32, &cfg(mm as f64 * 1e-3)).unwrap());
    }
    v
}

/// Largest |a − b| over both outputs, and the largest |b|.
#[cfg(feature = "tract")]
fn diff(a: &(Array3<f32>, Array3<f32>), b: &(Array3<f32>, Array3<f32>)) -> (f32, f32) {
    let mut d = 0.0f32;
    let mut m = 0.0f32;
    for (x, y) in [(&a.0, &b.0), (&a.1, &b.1)] {
        assert_eq!(x.dim(), y.dim());
        for (p, q) in x.iter().zip(y) {
            d = d.max((p - q).abs());
            m = m.max(q.abs());
        }
    }
    (d, m)
}

#[test]
#[cfg(feature = "tract")]
fn native_matches_tract_on_every_shipped_f32_model() {
    let (h, w) = (23, 37);
    for model in shipped() {
        let graph = model.cnn_graph().unwrap();
        let x = input(graph.in_channels, h, w, 7);
        let tract = crate::cnn::tract::TractModel::new(&model)
            .unwrap()
            .plan(h, w)
            .unwrap()
            .run_outputs(x.view())
            .unwrap();
        let isas: Vec<Isa> = [Isa::Scalar, Isa::detect()].into();
        for isa in isas {
            for threads in [1, 3] {
                let mut plan = NativePlan::new(
                    graph.clone(),
                    PlanSpec::new(h, w, threads, isa),
                    Choice::table_or(None),
                )
                .unwrap();
                let native = plan.run_outputs(x.view()).unwrap();
                let (d, m) = diff(&native, &tract);
                println!(
                    "{} {} ×{threads}: max |native − tract| {d:.2e} (max |tract| {m:.2})",
                    model.source_name(),
                    plan.kernel_name()
                );
                assert!(d <= 2e-5 * m.max(1.0), "{}: {d}", model.source_name());
                // Non-trivial outputs: a broken engine returning zeros would fail above, not pass here.
                assert!(m > 0.1);
            }
        }
    }
}

#[test]
fn threads_and_spawned_plans_give_bit_identical_frames() {
    let model = &shipped()[0];
    let graph = model.cnn_graph().unwrap();
    let (h, w) = (19, 70);
    let isa = Isa::detect();
    let x = input(graph.in_channels, h, w, 3);
    for conv in [
        Algorithm::Direct,
        Algorithm::Winograd2x2,
        Algorithm::Winograd4x4,
    ] {
        let plan = |threads| {
            NativePlan::new(
                graph.clone(),
                PlanSpec::new(h, w, threads, isa),
                Choice::table_or(Some(conv)),
            )
            .unwrap()
        };
        let a = plan(1).run_outputs(x.view()).unwrap();
        for threads in [2, 3, 4, 40] {
            let mut many = plan(threads);
            assert_eq!(
                many.run_outputs(x.view()).unwrap(),
                a,
                "{conv:?} {threads} threads"
            );
            let mut copy = many.spawn();
            assert_eq!(copy.run_outputs(x.view()).unwrap(), a);
        }
    }
    let mut one = NativePlan::new(
        graph.clone(),
        PlanSpec::new(h, w, 1, isa),
        Choice::table_or(None),
    )
    .unwrap();
    let a = one.run_outputs(x.view()).unwrap();
    for threads in [2, 4, 40] {
        let mut many = NativePlan::new(
            graph.clone(),
            PlanSpec::new(h, w, threads, isa),
            Choice::table_or(None),
        )
        .unwrap();
        assert_eq!(many.run_outputs(x.view()).unwrap(), a, "{threads} threads");
        let mut copy = many.spawn();
        assert_eq!(copy.run_outputs(x.view()).unwrap(), a);
    }
    // A second frame through the same plan: no state leaks from the first.
    let y = input(graph.in_channels, h, w, 4);
    let b = one.run_outputs(y.view()).unwrap();
    let mut fresh =
        NativePlan::new(graph, PlanSpec::new(h, w, 1, isa), Choice::table_or(None)).unwrap();
    assert_eq!(fresh.run_outputs(y.view()).unwrap(), b);
    assert_ne!(a, b);
}

#[test]
fn winograd_matches_direct_on_every_shipped_f32_model() {
    // Winograd F(2×2, 3×3) and F(4×4, 3×3) against the direct kernels on every shipped f32 network, at the
    // active ISA and the portable one: the heads (or the pre-filter's raw output) within 2e-5 of the largest
    // value (the bound the native engine keeps against tract), and not bit-identical (the Winograd rows
    // really ran).
    let (h, w) = (23, 37);
    for model in shipped() {
        let graph = model.cnn_graph().unwrap();
        let x = input(graph.in_channels, h, w, 21);
        for (isa, winograd) in [Isa::Scalar, Isa::detect()]
            .into_iter()
            .flat_map(|i| [(i, Algorithm::Winograd2x2), (i, Algorithm::Winograd4x4)])
        {
            let run = |conv| {
                let mut p = NativePlan::new(
                    graph.clone(),
                    PlanSpec::new(h, w, 1, isa),
                    Choice::table_or(Some(conv)),
                )
                .unwrap();
                (p.run_outputs(x.view()).unwrap(), p.kernel_name())
            };
            let ((d, kd), (wg, kw)) = (run(Algorithm::Direct), run(winograd));
            let tag = if winograd == Algorithm::Winograd4x4 {
                "wino4x4"
            } else {
                "wino2x2"
            };
            assert!(!kd.contains("wino") && kw.contains(tag), "{kd} / {kw}");
            let (mut err, mut m) = (0.0f32, 0.0f32);
            for (a, b) in [(&wg.0, &d.0), (&wg.1, &d.1)] {
                for (p, q) in a.iter().zip(b) {
                    err = err.max((p - q).abs());
                    m = m.max(q.abs());
                }
            }
            println!(
                "{} {isa} {tag}: max |winograd − direct| {err:.2e} (max {m:.2})",
                model.source_name()
            );
            assert!(err <= 2e-5 * m.max(1.0), "{}: {err}", model.source_name());
            assert!(err > 0.0 && m > 0.1);
        }
    }
}

#[test]
fn bad_input_and_bad_weights_are_errors() {
    let model = &shipped()[0];
    let graph = model.cnn_graph().unwrap();
    let isa = Isa::detect();
    let mut plan = NativePlan::new(
        graph.clone(),
        PlanSpec::new(8, 9, 1, isa),
        Choice::table_or(None),
    )
    .unwrap();
    let wrong = Array3::<f32>::zeros((graph.in_channels, 8, 10));
    assert!(matches!(
        plan.run_outputs(wrong.view()),
        Err(HoloError::ShapeMismatch { .. })
    ));
    // A transposed (non-standard layout) view of the right shape is read correctly.
    let x = input(graph.in_channels, 8, 9, 5);
    let t = x.clone().reversed_axes().as_standard_layout().into_owned();
    let back = t.view().reversed_axes();
    assert_eq!(
        plan.run_outputs(back).unwrap(),
        plan.run_outputs(x.view()).unwrap()
    );
    assert!(matches!(
        NativePlan::new(
            graph.clone(),
            PlanSpec::new(8, 9, 0, isa),
            Choice::table_or(None)
        ),
        Err(HoloError::InvalidParameter {
            name: "threads",
            ..
        })
    ));
    let mut nan = (*graph).clone();
    nan.layers[2].weights[5] = f32::NAN;
    assert!(matches!(
        NativePlan::new(
            Arc::new(nan),
            PlanSpec::new(8, 9, 1, isa),
            Choice::table_or(None)
        ),
        Err(HoloError::InvalidData(_))
    ));
}

/// The native engine without its claim to outrun the others: `Auto` then times tract too.
#[cfg(feature = "tract")]
struct TimedNative;

#[cfg(feature = "tract")]
impl super::engine::Engine for TimedNative {
    fn id(&self) -> CnnEngine {
        super::native::NativeEngine.id()
    }
    fn supports(&self, nets: super::engine::Networks<'_>) -> crate::error::Result<()> {
        super::native::NativeEngine.supports(nets)
    }
    fn tune(
        &self,
        nets: super::engine::Networks<'_>,
        height: usize,
        width: usize,
        request: &PlanRequest,
        time_single: bool,
        to_beat: Option<f64>,
    ) -> crate::error::Result<super::engine::Tuning> {
        super::native::NativeEngine.tune(nets, height, width, request, time_single, to_beat)
    }
    fn plans(
        &self,
        nets: super::engine::Networks<'_>,
        height: usize,
        width: usize,
        request: &PlanRequest,
        tuning: &super::engine::Tuning,
    ) -> crate::error::Result<super::engine::EnginePlans> {
        super::native::NativeEngine.plans(nets, height, width, request, tuning)
    }
}

/// Both engines timed, each timing reported, the faster one kept.
#[cfg(feature = "tract")]
fn assert_auto_keeps_the_faster(report: &super::tuning::PlanReport) {
    let best = |e: CnnEngine| {
        report
            .candidates
            .iter()
            .filter(|c| c.engine == e)
            .filter_map(|c| c.seconds)
            .fold(f64::INFINITY, f64::min)
    };
    let (n, t) = (best(CnnEngine::Native), best(CnnEngine::Tract));
    assert!(n.is_finite() && t.is_finite(), "{:?}", report.candidates);
    let want = if n <= t {
        CnnEngine::Native
    } else {
        CnnEngine::Tract
    };
    assert_eq!(report.engine, want);
    assert!(
        report.engine_reason.starts_with("faster on this CPU"),
        "{}",
        report.engine_reason
    );
}

/// A native plan of `graph` (f32 or int8) for `h × w` frames on `threads` threads of `isa`'s rows in strips
/// of `strip` rows, its f32 layers on `conv`'s first row (the table's for `None`).
fn strip_plan(
    graph: &Arc<crate::model::CnnWeights>,
    (h, w): (usize, usize),
    threads: usize,
    isa: Isa,
    strip: usize,
    conv: Option<Algorithm>,
) -> Box<dyn CnnPlan> {
    let spec = PlanSpec {
        strip_rows: Some(strip),
        ..PlanSpec::new(h, w, threads, isa)
    };
    if graph.quant.is_some() {
        Box::new(NativeInt8Plan::new(graph.clone(), spec, &TABLE_ROWS).unwrap())
    } else {
        Box::new(NativePlan::new(graph.clone(), spec, Choice::table_or(conv)).unwrap())
    }
}

/// `request` on `engine`.
fn on(engine: CnnEngine, request: &PlanRequest) -> PlanRequest {
    PlanRequest {
        cnn: CnnOptions {
            engine,
            ..request.cnn
        },
        source: request.source.clone(),
    }
}

#[test]
#[cfg(feature = "tract")]
fn engine_choice_follows_the_request_and_the_file() {
    let cfg = ModelConfig {
        offset_m: 0.0,
        ..ModelConfig::default()
    };
    let f32_model = Arc::new(embedded::hologram_model(8, Precision::F32, &cfg).unwrap());
    let int8 = Arc::new(embedded::hologram_model(8, Precision::Int8QOperator, &cfg).unwrap());
    let request = PlanRequest {
        cnn: CnnOptions {
            threads: ThreadCount::Fixed(1),
            ..CnnOptions::default()
        },
        ..PlanRequest::default()
    };
    let request = &request;
    let x = input(4, 16, 24, 9);
    let native = select(&f32_model, None, 16, 24, &on(CnnEngine::Native, request)).unwrap();
    assert_eq!(native.report.engine, CnnEngine::Native);
    assert!(native
        .report
        .kernel
        .as_deref()
        .unwrap()
        .starts_with("conv3x3.f32."));
    let tract = select(&f32_model, None, 16, 24, &on(CnnEngine::Tract, request)).unwrap();
    assert_eq!(tract.report.engine, CnnEngine::Tract);
    let (mut a, mut b) = (native.hologram, tract.hologram);
    let (d, m) = diff(
        &a.run_outputs(x.view()).unwrap(),
        &b.run_outputs(x.view()).unwrap(),
    );
    assert!(d <= 2e-5 * m.max(1.0));
    // Auto without tuning is the plan table's engine, native, and nothing is timed.
    let table = select(&f32_model, None, 16, 24, &on(CnnEngine::Auto, request)).unwrap();
    assert_eq!(table.report.engine, CnnEngine::Native);
    assert!(
        table.report.engine_reason.starts_with("the plan table"),
        "{}",
        table.report.engine_reason
    );
    assert!(table.report.candidates.is_empty());
    assert_eq!(table.report.source, super::tuning::PlanOrigin::Table);
    assert_eq!(table.report.tuning_s, 0.0);
    // Tuned, Auto times the native engine first. Where it outruns tract on this CPU (its x86-64 SIMD rows),
    // tract is not timed and the report says why; otherwise both are timed and the faster one is kept. Both
    // rules run here: the second through a registry whose native engine does not claim to outrun the others.
    let tuned = PlanRequest {
        source: super::tuning::PlanSource::Tune,
        ..request.clone()
    };
    let request = &tuned;
    let auto = select(&f32_model, None, 16, 24, &on(CnnEngine::Auto, request)).unwrap();
    assert_eq!(auto.report.source, super::tuning::PlanOrigin::Tuned);
    use super::engine::Engine;
    match super::native::NativeEngine.outruns_the_others(Isa::detect()) {
        Some(why) => {
            assert_eq!(auto.report.engine, CnnEngine::Native);
            assert_eq!(auto.report.engine_reason, why);
            let tract: Vec<_> = auto
                .report
                .candidates
                .iter()
                .filter(|c| c.engine == CnnEngine::Tract)
                .collect();
            assert_eq!(tract.len(), 1, "{:?}", auto.report.candidates);
            assert!(tract[0].seconds.is_none());
            let skipped = tract[0].skipped.as_deref().unwrap();
            assert!(
                skipped.starts_with("not timed: the native engine runs its "),
                "{skipped}"
            );
        }
        None => assert_auto_keeps_the_faster(&auto.report),
    }
    let both: super::engine::Registry = &[&TimedNative, &super::tract::TractEngine];
    let timed = super::select::select(
        both,
        &f32_model,
        None,
        16,
        24,
        &on(CnnEngine::Auto, request),
    )
    .unwrap();
    assert_auto_keeps_the_faster(&timed.report);
    // int8 files: Native is refused with the reason, Auto runs tract and says why.
    let err = select(&int8, None, 16, 24, &on(CnnEngine::Native, request)).unwrap_err();
    assert!(matches!(
        err,
        HoloError::InvalidParameter { name: "engine", .. }
    ));
    assert!(err.to_string().contains("QOperator"), "{err}");
    let auto8 = select(&int8, None, 16, 24, &on(CnnEngine::Auto, request)).unwrap();
    assert_eq!(auto8.report.engine, CnnEngine::Tract);
    assert!(auto8.report.engine_reason.contains("QOperator"));
    // int8 QDQ files run natively, on the int8 kernels.
    let qdq = Arc::new(embedded::hologram_model(8, Precision::Int8Qdq, &cfg).unwrap());
    let native8 = select(&qdq, None, 16, 24, &on(CnnEngine::Native, request)).unwrap();
    assert_eq!(native8.report.engine, CnnEngine::Native);
    let kernel = native8.report.kernel.as_deref().unwrap();
    assert!(kernel.starts_with("conv3x3.u8s8."), "{kernel}");
    assert_eq!(CnnEngine::parse("native").unwrap(), CnnEngine::Native);
    assert!(CnnEngine::parse("onnx").is_err());
}

#[test]
#[cfg(not(feature = "tract"))]
fn without_tract_the_native_engine_runs_everything_it_can_and_the_rest_is_refused() {
    let cfg = ModelConfig {
        offset_m: 0.0,
        ..ModelConfig::default()
    };
    let f32_model = Arc::new(embedded::hologram_model(8, Precision::F32, &cfg).unwrap());
    let request = PlanRequest {
        cnn: CnnOptions {
            threads: ThreadCount::Fixed(1),
            ..CnnOptions::default()
        },
        ..PlanRequest::default()
    };
    let request = &request;
    // Auto is the native engine, and says why.
    let auto = select(&f32_model, None, 16, 24, &on(CnnEngine::Auto, request)).unwrap();
    assert_eq!(auto.report.engine, CnnEngine::Native);
    assert!(
        auto.report.engine_reason.contains("`tract`"),
        "{}",
        auto.report.engine_reason
    );
    // Asking for tract is an error naming the feature.
    let err = select(&f32_model, None, 16, 24, &on(CnnEngine::Tract, request)).unwrap_err();
    assert!(matches!(
        err,
        HoloError::InvalidParameter { name: "engine", .. }
    ));
    assert!(err.to_string().contains("cargo feature `tract`"), "{err}");
    // The int8 QOperator form is not embedded, and asking for it says why.
    let err = embedded::hologram_cnn(8, Precision::Int8QOperator).unwrap_err();
    assert!(err.to_string().contains("cargo feature `tract`"), "{err}");
    // The same file, once not the TensorHolo CNN (one convolution unpadded), still loads (the model
    // layer is engine-neutral) but no engine of this build runs it: a pipeline refuses it up front,
    // naming the feature that would.
    use crate::model::ModelKind;
    use prost::Message;
    let bytes = embedded::hologram_cnn(8, Precision::F32).unwrap();
    let mut proto = crate::model::onnx::decode_model(bytes).unwrap();
    let graph = proto.graph.as_mut().unwrap();
    let conv = graph.node.iter_mut().find(|n| n.op_type == "Conv").unwrap();
    for a in conv.attribute.iter_mut().filter(|a| a.name == "pads") {
        a.ints = vec![0, 0, 0, 0];
    }
    let model = Arc::new(
        HologramModel::from_bytes(&proto.encode_to_vec(), ModelKind::Hologram, &cfg).unwrap(),
    );
    let err = super::check_runnable(&model).unwrap_err();
    assert!(matches!(err, HoloError::ModelContract { .. }), "{err}");
    super::check_runnable(&f32_model).expect("the unmodified file runs natively");
    assert!(err.to_string().contains("cargo feature `tract`"), "{err}");
}

fn shipped_qdq() -> Vec<HologramModel> {
    let cfg = |offset_m| ModelConfig {
        offset_m,
        ..ModelConfig::default()
    };
    let mut v = Vec::new();
    for layers in [8, 15, 30] {
        if let Ok(m) = embedded::hologram_model(layers, Precision::Int8Qdq, &cfg(0.0)) {
            v.push(m);
        }
    }
    for mm in [6, 12] {
        v.push(embedded::prefilter_model(mm, Precision::Int8Qdq, &cfg(mm as f64 * 1e-3)).unwrap());
    }
    let model = |bytes: &[u8]| {
        HologramModel::from_bytes(bytes, crate::model::ModelKind::PreFilter, &cfg(6e-3)).unwrap()
    };
    v.push(model(&all_int8_prefilter()));
    v.push(model(&rounded_base_prefilter()));
    v
}

/// The 6 mm int8 QDQ pre-filter as shipped before the pre-filters went mixed precision (every learned
/// convolution int8; `models/fixtures/prefilter_6mm_all_int8.int8-qdq.onnx`): the layout the hologram CNNs
/// still have, in a pre-filter.
fn all_int8_prefilter() -> Vec<u8> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../models/fixtures/prefilter_6mm_all_int8.int8-qdq.onnx"
    );
    std::fs::read(path).unwrap()
}

/// [`all_int8_prefilter`] as files exported before the blur kept its float input: its `Pad` reads the
/// input's `DequantizeLinear` (the input rounded to the first layer's grid).
fn rounded_base_prefilter() -> Vec<u8> {
    use prost::Message;
    let bytes = all_int8_prefilter();
    let mut proto = crate::model::onnx::decode_model(&bytes).unwrap();
    let graph = proto.graph.as_mut().unwrap();
    let input = graph.input[0].name.clone();
    // The output of the node of type `op` that reads `tensor`.
    let read_by = |op: &str, tensor: &str| {
        let node = graph
            .node
            .iter()
            .find(|n| n.op_type == op && n.input[0] == tensor);
        node.unwrap().output[0].clone()
    };
    let q = read_by("QuantizeLinear", &input);
    let dq = read_by("DequantizeLinear", &q);
    let pad = graph.node.iter_mut().find(|n| n.op_type == "Pad").unwrap();
    assert_eq!(
        pad.input[0], input,
        "the shipped file's blur reads the float input"
    );
    pad.input[0] = dq;
    proto.encode_to_vec()
}

/// Mean and max |a − b| over both outputs.
#[cfg(feature = "tract")]
fn mean_max(a: &(Array3<f32>, Array3<f32>), b: &(Array3<f32>, Array3<f32>)) -> (f32, f32) {
    let d: Vec<f32> =
        a.0.iter()
            .chain(a.1.iter())
            .zip(b.0.iter().chain(b.1.iter()))
            .map(|(x, y)| (x - y).abs())
            .collect();
    let mean = d.iter().sum::<f32>() / d.len() as f32;
    (mean, d.iter().fold(0.0f32, |m, &v| m.max(v)))
}

#[test]
#[cfg(feature = "tract")]
fn native_int8_matches_tract_on_every_shipped_qdq_model() {
    // tract executes the file node by node (every QuantizeLinear/DequantizeLinear); the native engine fuses
    // each layer and rounds once, as the current files do (older files round twice; rounding ties and the
    // order of sums still differ). Both stay within the models' int8 tolerance of PyTorch
    // (models/MODEL_CARD.md: hologram CNNs mean ≤ 2.7e-3, max ≤ 2.2e-2; pre-filters mean ≤ 2.2e-3, max ≤
    // 1.0e-2), so they must agree within twice that. Every ISA and thread count gives the
    // bit-identical frame of an all-int8 file (the int8 kernels are exact).
    let (h, w) = (21, 35);
    // Every layout is covered: all-int8 (the hologram CNNs, the earlier pre-filter), mixed precision (the
    // shipped pre-filters: f32 first and last layers), the blur on the rounded input (older files).
    let mut layouts = std::collections::BTreeSet::new();
    for model in shipped_qdq() {
        let graph = model.cnn_graph().unwrap();
        let quant = graph.quant.as_ref().unwrap();
        layouts.insert(match quant.layers[0] {
            None => "mixed",
            Some(_) if quant.base_reads_rounded_input => "rounded base",
            Some(_) => "int8",
        });
        let x = match model.kind() {
            crate::model::ModelKind::Hologram => input(graph.in_channels, h, w, 7),
            // A field of the pre-filter's range (about −0.05 … 0.7).
            crate::model::ModelKind::PreFilter => {
                input(graph.in_channels, h, w, 7).mapv(|v| 0.75 * v - 0.05)
            }
        };
        let tract = crate::cnn::tract::TractModel::new(&model)
            .unwrap()
            .plan(h, w)
            .unwrap()
            .run_outputs(x.view())
            .unwrap();
        let (limit_mean, limit_max) = match model.kind() {
            crate::model::ModelKind::Hologram => (2.0 * 2.7e-3, 2.0 * 2.2e-2),
            crate::model::ModelKind::PreFilter => (2.0 * 2.2e-3, 2.0 * 1.0e-2),
        };
        let mut first: Option<(Array3<f32>, Array3<f32>)> = None;
        for isa in [Isa::Scalar, Isa::detect()] {
            // The f32 first and last layers of a mixed-precision file sum in another order on each ISA: its
            // frames are bit-identical across thread counts, and within the tolerance across ISAs.
            if quant.layers[0].is_none() {
                first = None;
            }
            for threads in [1, 3] {
                let (mut plan, kernel) = native_plan(graph.clone(), h, w, threads, isa).unwrap();
                let native = plan.run_outputs(x.view()).unwrap();
                let (mean, max) = mean_max(&native, &tract);
                println!(
                    "{} {kernel} ×{threads}: |native − tract| mean {mean:.2e}, max {max:.2e}",
                    model.source_name()
                );
                assert!(
                    mean <= limit_mean && max <= limit_max,
                    "{}: mean {mean}, max {max}",
                    model.source_name()
                );
                match &first {
                    None => first = Some(native),
                    Some(f) => assert!(*f == native, "{} {kernel} ×{threads}", model.source_name()),
                }
            }
        }
        let (_, m) = diff(first.as_ref().unwrap(), &tract);
        assert!(m > 0.05, "non-trivial output");
    }
    assert_eq!(layouts.len(), 3, "{layouts:?}");
}

#[test]
fn strips_of_any_height_give_the_whole_frame_bit_for_bit() {
    // The strip-mined run (windows of a few rows, each layer a row behind the one before) computes every
    // pixel with the same instructions as one strip covering the whole frame: any strip height, with 1 or 3
    // threads, gives the bit-identical frame, f32 and int8, hologram CNN and pre-filter (its concat reads the
    // input N rows later, and the frame's top and bottom edges fall inside strips). F(4×4, 3×3) puts each
    // layer 4 rows behind the one before and rounds the strips up to its 4-row tiles.
    let (h, w) = (17, 29);
    let isa = Isa::detect();
    let (mut f32s, mut int8s) = (shipped(), shipped_qdq());
    // f32: a hologram CNN and a pre-filter; int8: an all-int8 hologram CNN, a mixed-precision pre-filter (the
    // last shipped one) and an all-int8 pre-filter (the earlier shipped one).
    let mixed = int8s.len() - 3;
    let models = [
        f32s.swap_remove(0),
        f32s.pop().unwrap(),
        int8s.remove(mixed),
        int8s.swap_remove(0),
        int8s.pop().unwrap(),
    ];
    // f32: each convolution algorithm (Winograd tiles rows by frame row, whatever the strip or band).
    let runs = models.iter().flat_map(|m| {
        let algs: &[_] = match m.cnn_graph().unwrap().quant {
            Some(_) => &[None],
            None => &[
                Some(Algorithm::Direct),
                Some(Algorithm::Winograd2x2),
                Some(Algorithm::Winograd4x4),
            ],
        };
        algs.iter().map(move |&a| (m, a))
    });
    for (model, conv) in runs {
        let graph = model.cnn_graph().unwrap();
        let n = graph.layers.len();
        let x = input(graph.in_channels, h, w, 11).mapv(|v| 0.75 * v - 0.05);
        let y = input(graph.in_channels, h, w, 12);
        let plan =
            |strip: usize, threads: usize| strip_plan(&graph, (h, w), threads, isa, strip, conv);
        if let Some(q) = &graph.quant {
            let mixed =
                NativeInt8Plan::new(graph.clone(), PlanSpec::new(h, w, 1, isa), &TABLE_ROWS)
                    .unwrap()
                    .is_mixed();
            assert_eq!(mixed, q.layers[0].is_none(), "{}", model.source_name());
        }
        let mut whole = plan(h + 4 * n, 1);
        let (a, b) = (
            whole.run_outputs(x.view()).unwrap(),
            whole.run_outputs(y.view()).unwrap(),
        );
        for strip in [1, 2, 3, 5, 8, h - 1, h + n - 1, h + 4 * n - 5] {
            for threads in [1, 3] {
                let mut p = plan(strip, threads);
                let name = format!("{} {conv:?} strip {strip} ×{threads}", model.source_name());
                assert!(p.run_outputs(x.view()).unwrap() == a, "{name}");
                // A second frame through the same windows: nothing carried over from the first.
                assert!(p.run_outputs(y.view()).unwrap() == b, "{name}, 2nd frame");
            }
        }
        assert!(a != b);
    }
}

#[test]
fn the_prefilter_base_is_added_once_to_every_row_as_the_rows_are_written() {
    // The pre-filter's depthwise base filter is added to each strip's rows as the last layer writes them
    // (FusedBase), not in a pass over the whole output afterwards. Its frame must be the same network with a
    // zero base, plus the base filter applied to the whole input afterwards (`depthwise_rows`, accumulating:
    // the separate pass's operations), bit for bit: for the f32 pre-filter and the mixed-precision int8 one,
    // any strip height and thread count, so that a row missed or added twice at a strip's or the frame's edge,
    // or a channel's base on another, shows. (A frame of several column slabs takes the separate pass:
    // `column_slabs_give_the_whole_frame_bit_for_bit` holds it to the fused one.)
    let (h, w) = (19, 27);
    let isa = Isa::detect();
    let (mut f32s, mut int8s) = (shipped(), shipped_qdq());
    let mixed = int8s.len() - 3;
    for model in [f32s.pop().unwrap(), int8s.remove(mixed)] {
        let graph = model.cnn_graph().unwrap();
        let crate::model::CnnOutput::Prefilter { taps, base } = &graph.output else {
            panic!("{}: not a pre-filter", model.source_name());
        };
        let (taps, base) = (*taps, base.clone());
        assert!(base.iter().any(|&v| v != 0.0));
        let mut zero = (*graph).clone();
        if let crate::model::CnnOutput::Prefilter { base, .. } = &mut zero.output {
            base.fill(0.0);
        }
        let zero = Arc::new(zero);
        let x = input(graph.in_channels, h, w, 21).mapv(|v| 0.75 * v - 0.05);
        let plan = |g: &Arc<crate::model::CnnWeights>, strip: usize, threads: usize| {
            strip_plan(g, (h, w), threads, isa, strip, Some(Algorithm::Direct))
        };
        let (mut re0, mut im0) = plan(&zero, h, 1).run_outputs(x.view()).unwrap();
        // The separate pass: channel c of the six outputs (Re planes, then Im) gets the base of input c.
        let k2 = taps * taps;
        for c in 0..6 {
            let out = if c < 3 { &mut re0 } else { &mut im0 };
            let mut plane = out.index_axis_mut(ndarray::Axis(0), c % 3);
            let input_plane = x.index_axis(ndarray::Axis(0), c);
            tensorholo_kernels::depthwise_rows(
                input_plane.as_slice().unwrap(),
                h,
                w,
                &base[c * k2..(c + 1) * k2],
                taps,
                0..h,
                plane.as_slice_mut().unwrap(),
                true,
                isa,
            )
            .unwrap();
        }
        // `usize::MAX` (an environment setting of any size): one strip, as `h + 3`.
        for strip in [1, 4, 7, h + 3, usize::MAX] {
            for threads in [1, 3] {
                let name = format!("{} strip {strip} ×{threads}", model.source_name());
                let (re, im) = plan(&graph, strip, threads).run_outputs(x.view()).unwrap();
                assert!(re == re0 && im == im0, "{name}");
            }
        }
    }
}

#[test]
fn column_slabs_give_the_whole_frame_bit_for_bit() {
    // A frame run as column slabs side by side (each as if it were the frame, its edges spoiling the columns
    // within its halo, which it does not keep; each layer computing only the columns the layers after it
    // read) gives the whole frame's bits: the f32 hologram CNN and pre-filter, each algorithm (the Winograd
    // tiles of slab and frame coincide) and the timed mix, frames whose width is and is not a multiple of 4,
    // 1 and 3 threads, two frames through the same windows.
    let isa = Isa::detect();
    let mut f32s = shipped();
    let models = [f32s.swap_remove(0), f32s.pop().unwrap()];
    for model in &models {
        let graph = model.cnn_graph().unwrap();
        // Each algorithm on every layer (`Some`), the plan table's rows (`None`), and the layer shapes cycling
        // through the three algorithms (`mixed`: layers of different tile widths in one network).
        for (conv, mixed) in [
            (Some(Algorithm::Direct), false),
            (Some(Algorithm::Winograd2x2), false),
            (Some(Algorithm::Winograd4x4), false),
            (None, false),
            (None, true),
        ] {
            for (h, w) in [(13, 301), (9, 298)] {
                let x = input(graph.in_channels, h, w, 21).mapv(|v| 0.75 * v - 0.05);
                let y = input(graph.in_channels, h, w, 22);
                let plan = |slabs: usize, threads: usize| {
                    let spec = PlanSpec {
                        slabs: Some(slabs),
                        ..PlanSpec::new(h, w, threads, isa)
                    };
                    let mixed_rows = Rows::mixed(&graph, isa);
                    let choice = if mixed {
                        Choice::Rows(&mixed_rows, ConvAlgorithm::Auto)
                    } else {
                        Choice::table_or(conv)
                    };
                    NativePlan::new(graph.clone(), spec, choice).unwrap()
                };
                let mut whole = plan(1, 1);
                assert_eq!(whole.slab_count(), 1);
                let (a, b) = (
                    whole.run_outputs(x.view()).unwrap(),
                    whole.run_outputs(y.view()).unwrap(),
                );
                // More slabs than the frame has columns (an environment setting of any size): the whole frame.
                let mut many = plan(usize::MAX, 1);
                assert_eq!(many.slab_count(), 1);
                assert!(many.run_outputs(x.view()).unwrap() == a);
                for slabs in [2, 3, 4] {
                    for threads in [1, 3] {
                        let mut p = plan(slabs, threads);
                        let name = format!(
                            "{} {conv:?} (mixed: {mixed}) {h}×{w}, {slabs} slabs ×{threads}",
                            model.source_name()
                        );
                        assert_eq!(p.slab_count(), slabs, "{name}");
                        assert!(p.run_outputs(x.view()).unwrap() == a, "{name}");
                        assert!(p.run_outputs(y.view()).unwrap() == b, "{name}, 2nd frame");
                    }
                }
            }
        }
    }
}

#[test]
fn a_1080p_plan_keeps_its_activations_to_a_few_rows() {
    // The strip height follows the window budget: at 1080p the 8-layer network's windows (24 channels,
    // 0.19 MB a row in f32) hold 8–16 rows, not the frame's 1080.
    let model = &shipped()[0];
    let graph = model.cnn_graph().unwrap();
    let isa = Isa::detect();
    let plan = NativePlan::new(
        graph,
        PlanSpec::new(1080, 1920, 2, isa),
        Choice::table_or(None),
    )
    .unwrap();
    let rows = plan.strip_rows();
    assert!((8..=16).contains(&rows), "{rows} rows per strip");
}

#[test]
fn an_input_given_plane_by_plane_gives_the_same_frame() {
    // `run_planes` (the pre-filter's input read in place from the colour workers' planes) equals
    // `run_outputs` on the same values gathered into `[C, H, W]`, bit for bit, on the native engine (f32
    // and int8, whose base filter reads the planes too) and on tract; a wrong plane count or length is a
    // shape error.
    let (h, w) = (13, 21);
    let isa = Isa::detect();
    for model in [shipped().pop().unwrap(), shipped_qdq().pop().unwrap()] {
        let graph = model.cnn_graph().unwrap();
        let x = input(graph.in_channels, h, w, 5).mapv(|v| 0.75 * v - 0.05);
        let planes: Vec<Vec<f32>> = x
            .outer_iter()
            .map(|p| p.iter().copied().collect())
            .collect();
        let refs: Vec<&[f32]> = planes.iter().map(|p| &p[..]).collect();
        #[allow(unused_mut)]
        let mut plans: Vec<Box<dyn CnnPlan>> =
            vec![native_plan(graph.clone(), h, w, 2, isa).unwrap().0];
        #[cfg(feature = "tract")]
        plans.push(Box::new(
            crate::cnn::tract::TractModel::new(&model)
                .unwrap()
                .plan(h, w)
                .unwrap(),
        ));
        for plan in &mut plans {
            let whole = plan.run_outputs(x.view()).unwrap();
            assert!(
                plan.run_planes(&refs).unwrap() == whole,
                "{}",
                model.source_name()
            );
            assert!(matches!(
                plan.run_planes(&refs[1..]),
                Err(HoloError::ShapeMismatch { .. })
            ));
            let short = [&refs[0][1..]; 6];
            assert!(plan.run_planes(&short[..graph.in_channels]).is_err());
        }
    }
}

/// The early stop of [`CnnEngine::Auto`]: tract's likeliest candidate (the most threads, the first layout)
/// is timed first; against a time it cannot plausibly beat, the others are left untimed with the reason and
/// the report is not cached, so a later tract request times them all; against a time it can beat, all are
/// timed.
#[test]
#[cfg(feature = "tract")]
fn tract_stops_after_its_likeliest_candidate_when_another_engine_is_far_faster() {
    use super::options::CnnLayout;
    use super::tract::TractModel;
    use super::tuning::{auto_thread_candidates, PlanSource, PLAUSIBLE_FACTOR};
    let m = embedded::hologram_model(8, Precision::F32, &ModelConfig::default()).unwrap();
    let request = &PlanRequest {
        source: PlanSource::Tune,
        cnn: CnnOptions {
            layout: CnnLayout::Auto,
            threads: ThreadCount::Auto,
            ..CnnOptions::default()
        },
    };
    let threads = auto_thread_candidates();
    let all = CnnLayout::ALL.len() * threads.len();

    let tract = TractModel::new(&m).unwrap();
    let r = tract.tuning(24, 40, request, Some(1e-9)).unwrap();
    let timed: Vec<_> = r
        .candidates
        .iter()
        .filter(|c| c.seconds.is_some())
        .collect();
    assert_eq!(timed.len(), 1, "{:?}", r.candidates);
    assert_eq!(
        (timed[0].layout, timed[0].threads),
        (CnnLayout::ALL[0], threads.last().copied())
    );
    assert_eq!(r.candidates.len(), all);
    for c in r.candidates.iter().filter(|c| c.seconds.is_none()) {
        let why = c.skipped.as_deref().unwrap();
        assert!(
            why.starts_with("not timed") && why.contains(&format!("{PLAUSIBLE_FACTOR}×")),
            "{why}"
        );
    }
    // Not cached: without a time to beat every candidate is timed.
    let r = tract.tuning(24, 40, request, None).unwrap();
    assert_eq!(
        r.candidates.iter().filter(|c| c.seconds.is_some()).count(),
        all
    );

    let fresh = TractModel::new(&m).unwrap();
    let r = fresh.tuning(24, 40, request, Some(1e9)).unwrap();
    assert_eq!(
        r.candidates.iter().filter(|c| c.seconds.is_some()).count(),
        all
    );
}
