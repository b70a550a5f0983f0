//! Measured single-thread peaks, to report kernels as a fraction of what the core can do.

use std::time::Instant;

use crate::conv3x3;
use crate::dispatch::{self, Path};
use crate::error::KernelError;
use crate::isa::Isa;

/// A peak loop: operations per iteration (a multiply-add counts 2) and the loop, which returns a value to
/// keep its chains alive.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Peak<T> {
    pub ops_per_iter: f64,
    pub run: unsafe fn(u64) -> T,
}

/// The f32 FMA peak loops (each level's widest FMA), best first; the loops live with the conv3x3 rows of
/// their ISA.
static F32_PEAKS: &[Path<Peak<f32>>] = &[
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx512,
        run: Peak {
            ops_per_iter: 24.0 * 16.0 * 2.0,
            run: conv3x3::f32_avx512::peak,
        },
    },
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx2Fma,
        run: Peak {
            ops_per_iter: 12.0 * 8.0 * 2.0,
            run: conv3x3::f32_avx2::peak,
        },
    },
    #[cfg(target_arch = "aarch64")]
    Path {
        isa: Isa::Neon,
        run: Peak {
            ops_per_iter: 24.0 * 4.0 * 2.0,
            run: conv3x3::f32_neon::peak,
        },
    },
    Path {
        isa: Isa::Scalar,
        run: Peak {
            ops_per_iter: 16.0 * 2.0,
            run: conv3x3::f32_scalar::peak,
        },
    },
];

/// The int8 peak loops (each level's best int8 instruction), best first.
static U8_PEAKS: &[Path<Peak<i32>>] = &[
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx512Vnni,
        run: Peak {
            ops_per_iter: 24.0 * 64.0 * 2.0,
            run: conv3x3::u8s8_avx512vnni::peak_avx512vnni,
        },
    },
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::AvxVnni,
        run: Peak {
            ops_per_iter: 12.0 * 32.0 * 2.0,
            run: conv3x3::u8s8_avxvnni::peak_avxvnni,
        },
    },
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx2Fma,
        run: Peak {
            ops_per_iter: 12.0 * 16.0 * 2.0,
            run: conv3x3::u8s8_avx2::peak_avx2,
        },
    },
    #[cfg(target_arch = "aarch64")]
    Path {
        isa: Isa::NeonI8mm,
        run: Peak {
            ops_per_iter: 24.0 * 16.0 * 2.0,
            run: conv3x3::u8s8_neoni8mm::peak_i8mm,
        },
    },
    #[cfg(target_arch = "aarch64")]
    Path {
        isa: Isa::NeonDot,
        run: Peak {
            ops_per_iter: 24.0 * 16.0 * 2.0,
            run: conv3x3::u8s8_neondot::peak_dot,
        },
    },
    #[cfg(target_arch = "aarch64")]
    Path {
        isa: Isa::Neon,
        run: Peak {
            ops_per_iter: 24.0 * 4.0 * 2.0,
            run: conv3x3::u8s8_neon::peak_wide,
        },
    },
    Path {
        isa: Isa::Scalar,
        run: Peak {
            ops_per_iter: 16.0 * 2.0,
            run: conv3x3::u8s8_scalar::peak,
        },
    },
];

/// Runs the peak loop `paths` picks under `isa` for `iters` iterations; returns the operations done and a
/// value to keep the loop alive. Errors: `isa` not available.
fn run<T: Copy>(paths: &[Path<Peak<T>>], isa: Isa, iters: u64) -> Result<(f64, T), KernelError> {
    let peak = dispatch::pick(paths, isa)?;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the loop it returned.
    let sink = unsafe { (peak.run)(iters) };
    Ok((iters as f64 * peak.ops_per_iter, sink))
}

/// Measures the f32 FMA peak of one thread with the widest FMA of `isa`: independent FMA chains in registers,
/// timed for about `millis` ms. Returns GFLOP/s (an FMA counts 2 FLOPs). Errors: `isa` not available.
pub fn f32_fma_gflops(isa: Isa, millis: u64) -> Result<f64, KernelError> {
    measure(millis, |iters| run(F32_PEAKS, isa, iters))
}

/// Runs the f32 FMA peak loop of `isa` for `iters` iterations (for benchmark harnesses that time it
/// themselves); returns the FLOPs done. Errors: `isa` not available.
pub fn f32_fma_loop(isa: Isa, iters: u64) -> Result<f64, KernelError> {
    let (flops, sink) = run(F32_PEAKS, isa, iters)?;
    std::hint::black_box(sink);
    Ok(flops)
}

/// Measures the int8 multiply-accumulate peak of one thread with the best int8 instruction of `isa`
/// (`vpdpbusd` for the VNNI levels, `vpmaddwd`+`vpaddd` for AVX2, `USDOT`/`SDOT`/`SMLAL` on aarch64, i32
/// multiply-add for scalar), timed for about `millis` ms. Returns GOP/s (a multiply-add counts 2).
/// Errors: `isa` not available.
pub fn int8_dot_gops(isa: Isa, millis: u64) -> Result<f64, KernelError> {
    measure(millis, |iters| {
        run(U8_PEAKS, isa, iters).map(|(ops, s)| (ops, s as f32))
    })
}

/// Runs the int8 peak loop of `isa` for `iters` iterations; returns the operations done. Errors: `isa` not
/// available.
pub fn int8_dot_loop(isa: Isa, iters: u64) -> Result<f64, KernelError> {
    let (ops, sink) = run(U8_PEAKS, isa, iters)?;
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
        crate::dispatch::assert_best_first_ending_portable(
            &F32_PEAKS.iter().map(|p| p.isa).collect::<Vec<_>>(),
        );
        crate::dispatch::assert_best_first_ending_portable(
            &U8_PEAKS.iter().map(|p| p.isa).collect::<Vec<_>>(),
        );
        for isa in Isa::ALL {
            if !isa.is_available() {
                assert!(f32_fma_gflops(isa, 1).is_err());
                assert!(int8_dot_gops(isa, 1).is_err());
            }
        }
    }
}
