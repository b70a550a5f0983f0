//! Measured single-thread peaks, to report kernels as a fraction of what the core can do.

use crate::error::KernelError;
use crate::isa::Isa;
use crate::ops;
use std::time::Instant;

/// Measures the f32 FMA peak of one thread with the widest FMA of `isa`: independent FMA chains in registers,
/// timed for about `millis` ms. Returns GFLOP/s (an FMA counts 2 FLOPs). Errors: `isa` not available.
pub fn f32_fma_gflops(isa: Isa, millis: u64) -> Result<f64, KernelError> {
    measure(millis, |iters| ops::run_peak_f32(isa, iters))
}

/// Runs the f32 FMA peak loop of `isa` for `iters` iterations (for benchmark harnesses that time it
/// themselves); returns the FLOPs done. Errors: `isa` not available.
pub fn f32_fma_loop(isa: Isa, iters: u64) -> Result<f64, KernelError> {
    let (flops, sink) = ops::run_peak_f32(isa, iters)?;
    std::hint::black_box(sink);
    Ok(flops)
}

/// Measures the int8 multiply-accumulate peak of one thread with the best int8 instruction of `isa`
/// (`vpdpbusd` for the VNNI levels, `vpmaddwd`+`vpaddd` for AVX2, `USDOT`/`SDOT`/`SMLAL` on aarch64, i32
/// multiply-add for scalar), timed for about `millis` ms. Returns GOP/s (a multiply-add counts 2).
/// Errors: `isa` not available.
pub fn int8_dot_gops(isa: Isa, millis: u64) -> Result<f64, KernelError> {
    measure(millis, |iters| {
        ops::run_peak_u8(isa, iters).map(|(ops, s)| (ops, s as f32))
    })
}

/// Runs the int8 peak loop of `isa` for `iters` iterations; returns the operations done. Errors: `isa` not
/// available.
pub fn int8_dot_loop(isa: Isa, iters: u64) -> Result<f64, KernelError> {
    let (ops, sink) = ops::run_peak_u8(isa, iters)?;
    std::hint::black_box(sink);
    Ok(ops)
}

fn measure(
    millis: u64,
    mut run: impl FnMut(u64) -> Result<(f64, f32), KernelError>,
) -> Result<f64, KernelError> {
    let mut iters = 1u64 << 10;
    let target = millis.max(1) as f64 / 1000.0;
    loop {
        let t = Instant::now();
        let (ops, sink) = run(iters)?;
        std::hint::black_box(sink);
        let dt = t.elapsed().as_secs_f64();
        if dt >= target || iters >= 1 << 40 {
            return Ok(ops / dt / 1e9);
        }
        iters = (iters as f64 * (target / dt.max(1e-6)).clamp(2.0, 100.0) * 1.1) as u64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peaks_are_positive() {
        for isa in Isa::available() {
            let g = f32_fma_gflops(isa, 5).unwrap();
            println!("f32 FMA peak {isa}: {g:.1} GFLOP/s");
            assert!(g > 0.0);
            let q = int8_dot_gops(isa, 5).unwrap();
            println!("int8 peak {isa}: {q:.1} GOP/s");
            assert!(q > 0.0);
        }
        for isa in Isa::ALL {
            if !isa.is_available() {
                assert!(f32_fma_gflops(isa, 1).is_err());
                assert!(int8_dot_gops(isa, 1).is_err());
            }
        }
    }
}
