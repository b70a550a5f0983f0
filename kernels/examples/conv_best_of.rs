//! Direct against Winograd on one layer shape, alternated, best of N: less sensitive to a noisy host than
//! a criterion run of one row after the other.
//!
//! `cargo run --release -p tensorholo-kernels --example conv_best_of -- C_IN C_OUT WIDTH ROWS ROUNDS
//! [residual|plain] [FILTER]` (defaults: 24 24 384 16 30 plain). Prints, per available f32 row, the best time of a band of `ROWS` rows and its
//! effective GFLOP/s (`2·9·C_in·C_out` operations per output pixel, whatever the algorithm).
//! `FILTER` keeps only the rows whose name contains it (for instruction counts under qemu:
//! `benchmarks/qemu/layer_instructions.sh`).

use std::time::Instant;
use tensorholo_kernels::{registry, Conv3x3F32, Inputs, RowPlanar};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, d: usize| args.get(i).and_then(|a| a.parse().ok()).unwrap_or(d);
    let (c_in, c_out, w, h, rounds) = (arg(0, 24), arg(1, 24), arg(2, 384), arg(3, 16), arg(4, 30));
    let residual = args.get(5).is_some_and(|a| a == "residual");
    let values = |n: usize, seed: usize| -> Vec<f32> {
        (0..n)
            .map(|i| (((i + seed) * 7919) % 1000) as f32 / 1000.0 - 0.5)
            .collect()
    };
    let a = RowPlanar::from_planar(&values(c_in * h * w, 1), c_in, h, w, None).expect("a");
    let r = RowPlanar::from_planar(&values(c_out * h * w, 2), c_out, h, w, None).expect("r");
    let rows: Vec<_> = registry::f32_kernels()
        .filter(|k| k.is_available())
        .filter(|k| args.get(6).is_none_or(|f| k.name.contains(f.as_str())))
        .map(|k| {
            let plan = Conv3x3F32::with_kernel(
                &values(c_out * c_in * 9, 3),
                &values(c_out, 4),
                c_in,
                c_out,
                true,
                k.name,
            )
            .expect("plan");
            (k.name, plan)
        })
        .collect();
    let mut out = RowPlanar::new(c_out, h, w).expect("out");
    let mut best = vec![f64::INFINITY; rows.len()];
    for _ in 0..rounds {
        for (b, (_, plan)) in best.iter_mut().zip(&rows) {
            let mut inputs = Inputs::new(&a);
            if residual {
                inputs = inputs.residual(&r);
            }
            let t = Instant::now();
            plan.run(inputs, &mut out, 0..h).expect("run");
            *b = b.min(t.elapsed().as_secs_f64());
        }
    }
    let flop = (2 * 9 * c_in * c_out * w * h) as f64;
    println!("{c_in}→{c_out}, {h} rows × {w}, residual {residual}, best of {rounds}:");
    for ((name, _), b) in rows.iter().zip(&best) {
        println!(
            "  {name:48} {:8.3} ms {:7.1} GFLOP/s",
            b * 1e3,
            flop / b / 1e9
        );
    }
}
