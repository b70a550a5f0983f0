//! One CNN file on the native engine at one size, alone: the best and the median of N runs after a warm-up
//! run (what `holo bench` does for the shipped hologram CNNs, here for any file, the pre-filters included).
//!
//! `cargo run --release -p tensorholo --example cnn_time -- FILE KIND HEIGHT WIDTH THREADS RUNS [ALGORITHM]`,
//! `KIND` `hologram` or `prefilter`, `ALGORITHM` `auto` (the default), `direct`, `winograd2x2` or
//! `winograd4x4`; e.g. `… models/prefilter_6mm.onnx prefilter 1080 1920 2 7`. Prints the kernel
//! rows the plan runs, then `FILE HxW tT: min … med … ms`. The input is a fixed pattern in the file's
//! channels; `run_outputs` allocates the two output arrays each run (a session writes into its own planes).
//! `ALGORITHM` pins the algorithm, as `TENSORHOLO_CONV` does for `holo`; the rows otherwise come from the plan
//! table.

use std::sync::Arc;
use std::time::Instant;

use tensorholo::cnn::{
    cnn_plan, CnnEngine, CnnLayout, CnnOptions, ConvAlgorithm, PlanRequest, ThreadCount,
};
use tensorholo::model::{HologramModel, ModelConfig, ModelKind};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: cnn_time FILE hologram|prefilter HEIGHT WIDTH THREADS RUNS [ALGORITHM]";
    let num = |i: usize| -> usize {
        args.get(i)
            .and_then(|a| a.parse().ok())
            .filter(|&n: &usize| n > 0)
            .unwrap_or_else(|| panic!("{usage}"))
    };
    let (file, kind) = match (args.first(), args.get(1).map(String::as_str)) {
        (Some(f), Some("hologram")) => (f, ModelKind::Hologram),
        (Some(f), Some("prefilter")) => (f, ModelKind::PreFilter),
        _ => panic!("{usage}"),
    };
    let (h, w, threads, runs) = (num(2), num(3), num(4), num(5));
    let model = HologramModel::from_path(file, kind, &ModelConfig::default())
        .unwrap_or_else(|e| panic!("{file}: {e}"));
    let conv = args
        .get(6)
        .map_or(Ok(ConvAlgorithm::Auto), |v| ConvAlgorithm::parse(v))
        .unwrap_or_else(|e| panic!("ALGORITHM: {e}"));
    let request = PlanRequest {
        cnn: CnnOptions {
            engine: CnnEngine::Native,
            layout: CnnLayout::Auto,
            threads: ThreadCount::Fixed(threads),
            algorithm: conv,
            ..CnnOptions::default()
        },
        ..PlanRequest::default()
    };
    let (mut plan, report) =
        cnn_plan(&Arc::new(model), h, w, &request).unwrap_or_else(|e| panic!("plan: {e}"));
    println!("kernel rows: {}", report.kernel.as_deref().unwrap_or("-"));
    let c = plan.input_dim().0;
    let x = ndarray::Array3::<f32>::from_shape_fn((c, h, w), |(c, y, x)| {
        ((c * 7 + y * 3 + x) % 17) as f32 / 17.0 - 0.3
    });
    plan.run_outputs(x.view()).expect("warm-up run");
    let mut ms: Vec<f64> = (0..runs)
        .map(|_| {
            let t = Instant::now();
            plan.run_outputs(x.view()).expect("run");
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    println!(
        "{file} {h}x{w} t{threads}: min {:.1} med {:.1} ms",
        ms[0],
        ms[runs / 2]
    );
}
