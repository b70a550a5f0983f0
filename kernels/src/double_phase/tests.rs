//! The double phase rows: every path bit-identical with the portable one, the error bounds of the module
//! docs (dense grids here; the exhaustive sweeps behind them are `#[ignore]`d: run them with
//! `cargo test -p tensorholo-kernels --release -- --ignored double_phase`), the wrap and the codes as the
//! SDK's scalar definitions, and bad lengths refused.

use std::f32::consts::{PI, TAU};

use super::*;
use crate::test_rng::Rng;

/// The error of `got` against the exact `atan2(y, x)` (f64), modulo 2π (±π are the same angle).
fn atan2_err(y: f32, x: f32, got: f32) -> f64 {
    let exact = (y as f64).atan2(x as f64);
    let e = (got as f64 - exact).abs();
    e.min((e - std::f64::consts::TAU).abs())
}

/// The scalar reference: the SDK's definition before vectorising (libm `atan2f`/`acosf`, `f32::round`).
fn libm_phase(re: f32, im: f32, y: usize, x: usize, mean: f32, inv_a: f32) -> f32 {
    let theta = ((re * re + im * im).sqrt() * inv_a).min(1.0).acos();
    let p = im.atan2(re);
    let v = if (x + y) % 2 == 1 {
        p - mean - theta
    } else {
        p - mean + theta
    };
    wrap_phase(v)
}

fn libm_code(p: f32) -> u8 {
    ((wrap_phase(p) * (256.0 / TAU)).round() as u32 % 256) as u8
}

/// The SDK's wrap before this module (kept here as the reference the vector wrap must equal bit for bit).
fn old_wrap(phase: f32) -> f32 {
    if (-2.0 * TAU..2.0 * TAU).contains(&phase) {
        let mut w = phase;
        if w < 0.0 {
            w += TAU;
        }
        if w < 0.0 {
            w += TAU;
        }
        if w >= TAU {
            w -= TAU;
        }
        if w >= TAU {
            w -= TAU;
        }
        return if (0.0..TAU).contains(&w) { w } else { 0.0 };
    }
    let w = phase.rem_euclid(TAU);
    if w >= TAU {
        0.0
    } else {
        w
    }
}

fn paths() -> Vec<(String, Isa)> {
    crate::dispatch::available_paths("double_phase", PATHS)
}

/// A speckle-like row: amplitudes in [0, 1] (some exactly 0 and 1), phases uniform, some awkward values.
fn row(rng: &mut Rng, n: usize) -> Vec<f32> {
    let mut f = Vec::with_capacity(2 * n);
    for i in 0..n {
        let (a, p) = (rng.unit(), (rng.unit() - 0.5) * TAU);
        let (re, im) = match i % 23 {
            0 => (0.0, 0.0),
            1 => (-0.0, 0.0),
            2 => (-1.0, 0.0),
            3 => (-1.0, -0.0),
            4 => (1e-40, -3e-42),
            5 => (0.0, -0.5),
            _ => (a * p.cos(), a * p.sin()),
        };
        f.push(re);
        f.push(im);
    }
    f
}

#[test]
fn atan2_special_values_follow_ieee() {
    let cases = [
        (0.0f32, 0.0f32),
        (-0.0, 0.0),
        (0.0, -0.0),
        (-0.0, -0.0),
        (1.0, 0.0),
        (-1.0, 0.0),
        (0.0, -1.0),
        (-0.0, -1.0),
        (f32::INFINITY, f32::INFINITY),
        (f32::INFINITY, f32::NEG_INFINITY),
        (f32::NEG_INFINITY, f32::INFINITY),
        (f32::NEG_INFINITY, f32::NEG_INFINITY),
        (f32::INFINITY, 1.0),
        (1.0, f32::INFINITY),
        (1.0, f32::NEG_INFINITY),
        (-1.0, f32::NEG_INFINITY),
        (f32::MAX, f32::MAX),
        (f32::MAX, -f32::MAX),
        (f32::MAX * 0.5, f32::MAX),
        (1e-45, 1e-45),
        (1e-45, -1e-45),
        (1e-45, 1.0),
        (1.0, 1e-45),
        (3e-39, -7e-39),
    ];
    for (y, x) in cases {
        let got = atan2(y, x);
        let want = y.atan2(x);
        assert!(
            (got - want).abs() <= ATAN2_MAX_ERROR
                && got.is_sign_negative() == want.is_sign_negative(),
            "atan2({y}, {x}) = {got}, libm {want}"
        );
    }
    assert!(atan2(f32::NAN, 1.0).is_nan() && atan2(1.0, f32::NAN).is_nan());
    assert!(atan2(f32::NAN, f32::INFINITY).is_nan() && atan2(0.0, f32::NAN).is_nan());
    assert_eq!(atan2(0.0, -0.0), PI);
    assert_eq!(atan2(-0.0, -0.0), -PI);
}

#[test]
fn atan2_is_within_its_bound_on_a_dense_grid() {
    let mut worst = 0.0f64;
    // Every 61st non-negative f32 as y (all exponents, denormals), against x = ±1 and ±1.7.
    for bits in (0..0x7f80_0000u32).step_by(61 * 64) {
        let y = f32::from_bits(bits);
        for x in [1.0f32, -1.0, 1.7, -1.7] {
            for (yy, xx) in [(y, x), (-y, x), (x, y)] {
                worst = worst.max(atan2_err(yy, xx, atan2(yy, xx)));
            }
        }
    }
    let mut rng = Rng::new(0x1234_5678_9abc_def1);
    for _ in 0..300_000 {
        let (y, x) = (rng.any_finite(), rng.any_finite());
        worst = worst.max(atan2_err(y, x, atan2(y, x)));
        // Close ratios: both of one magnitude.
        let (u, v) = ((rng.unit() - 0.5) * 8.0, (rng.unit() - 0.5) * 8.0);
        worst = worst.max(atan2_err(u, v, atan2(u, v)));
    }
    println!("atan2 worst error {worst:e} rad");
    assert!(worst <= ATAN2_MAX_ERROR as f64, "{worst:e}");
}

#[test]
fn acos_is_within_its_bound_on_a_dense_grid() {
    let one = 1.0f32.to_bits();
    let mut worst = 0.0f64;
    for bits in (0..=one).step_by(257).chain(one - 4096..=one) {
        let x = f32::from_bits(bits);
        worst = worst.max((acos_unit(x) as f64 - (x as f64).acos()).abs());
    }
    println!("acos worst error {worst:e} rad");
    assert!(worst <= ACOS_MAX_ERROR as f64, "{worst:e}");
    assert_eq!(acos_unit(1.0), 0.0);
    assert!((acos_unit(0.0) - std::f32::consts::FRAC_PI_2).abs() <= 1e-7);
    assert!(acos_unit(f32::NAN).is_nan());
}

/// Runs `f` on `0..n` split into one contiguous part per thread; returns the parts' results.
fn split<T: Send>(n: u64, f: impl Fn(std::ops::Range<u64>) -> T + Sync) -> Vec<T> {
    let threads = std::thread::available_parallelism().map_or(1, |t| t.get()) as u64;
    let step = n.div_ceil(threads);
    std::thread::scope(|s| {
        let parts: Vec<_> = (0..threads)
            .map(|t| {
                let f = &f;
                s.spawn(move || f(t * step..((t + 1) * step).min(n)))
            })
            .collect();
        parts.into_iter().map(|p| p.join().unwrap()).collect()
    })
}

/// The worst `atan2` errors seen: against the exact value (f64) and against std's `atan2f` (modulo 2π).
#[derive(Default)]
struct Worst {
    exact: f64,
    std: f32,
}

impl Worst {
    /// Counts `p` = `atan2(y, x)`.
    fn note(&mut self, y: f32, x: f32, p: f32) {
        self.exact = self.exact.max(atan2_err(y, x, p));
        let d = (p - y.atan2(x)).abs();
        self.std = self.std.max(d.min(TAU - d));
    }

    /// The worst of several parts' worsts.
    fn of(parts: &[Worst]) -> (f64, f32) {
        let exact = parts.iter().fold(0.0f64, |a, p| a.max(p.exact));
        (exact, parts.iter().fold(0.0f32, |a, p| a.max(p.std)))
    }
}

/// The exhaustive sweeps behind the module's bounds, on every path (release build, all cores: about a
/// minute on two; debug: far longer): `cargo test -p tensorholo-kernels --release -- --ignored
/// double_phase_exhaustive --nocapture`. Prints the worst errors against the exact value and against std's
/// f32 `atan2`/`acos`.
#[test]
#[ignore]
fn double_phase_exhaustive_bounds() {
    const XS: [f32; 6] = [1.0, -1.0, 1.7, -1.7, 0.0, -0.0];
    const BLOCK: u64 = 1 << 14;
    let paths = paths();
    // Every non-negative y (all 2³¹ of them up to +∞) against each x, through the row kernels of every path.
    let parts = split((0x7f80_0001u64).div_ceil(BLOCK), |blocks| {
        let mut worst = Worst::default();
        let mut field = vec![0.0f32; 2 * BLOCK as usize];
        let (mut want, mut got) = (vec![0.0f32; BLOCK as usize], vec![0.0f32; BLOCK as usize]);
        for blk in blocks {
            let lo = blk * BLOCK;
            let n = (BLOCK).min(0x7f80_0001 - lo) as usize;
            for x in XS {
                for i in 0..n {
                    field[2 * i] = x;
                    field[2 * i + 1] = f32::from_bits((lo + i as u64) as u32);
                }
                analyse_row(&field[..2 * n], &mut want[..n], Isa::Scalar).unwrap();
                for (name, isa) in &paths {
                    analyse_row(&field[..2 * n], &mut got[..n], *isa).unwrap();
                    let same = got[..n]
                        .iter()
                        .zip(&want[..n])
                        .all(|(a, b)| a.to_bits() == b.to_bits());
                    assert!(same, "{name}: x {x}, y bits from {lo:#x}");
                }
                for (i, &p) in want[..n].iter().enumerate() {
                    worst.note(field[2 * i + 1], x, p);
                }
            }
        }
        worst
    });
    let (worst, worst_std) = Worst::of(&parts);
    let parts = split(10_000_000, |r| {
        let mut rng = Rng::new(0x0dd_ba11 + r.start);
        let mut worst = Worst::default();
        for _ in r {
            let (y, x) = (rng.any_finite(), rng.any_finite());
            worst.note(y, x, atan2(y, x));
        }
        worst
    });
    let (worst_r, worst_r_std) = Worst::of(&parts);
    println!("atan2, every y ≥ 0 against x ∈ ±{{0, 1, 1.7}}: worst {worst:e} rad (std atan2f: {worst_std:e})");
    println!("atan2, 10⁷ random finite pairs: worst {worst_r:e} rad (std atan2f: {worst_r_std:e})");
    assert!(worst.max(worst_r) <= ATAN2_MAX_ERROR as f64);
    let parts = split(1.0f32.to_bits() as u64 + 1, |r| {
        let (mut exact, mut std) = (0.0f64, 0.0f32);
        for bits in r {
            let x = f32::from_bits(bits as u32);
            let a = acos_unit(x);
            exact = exact.max((a as f64 - (x as f64).acos()).abs());
            std = std.max((a - x.acos()).abs());
        }
        (exact, std)
    });
    let worst = parts.iter().fold(0.0f64, |a, p| a.max(p.0));
    let worst_std = parts.iter().fold(0.0f32, |a, p| a.max(p.1));
    println!("acos, every f32 in [0, 1]: worst {worst:e} rad (std acosf: {worst_std:e})");
    assert!(worst <= ACOS_MAX_ERROR as f64);
    split(TAU.to_bits() as u64, |r| {
        for bits in r {
            let p = f32::from_bits(bits as u32);
            assert_eq!(linear_code_wrapped(p), libm_code(p), "{p}");
            assert_eq!(wrap_phase(p).to_bits(), p.to_bits(), "{p}");
        }
    });
}

#[test]
fn wrap_and_codes_equal_the_scalar_definitions() {
    let mut rng = Rng::new(77);
    let mut values: Vec<f32> = (0..200_000)
        .map(|_| (rng.unit() - 0.5) * 8.0 * TAU)
        .collect();
    values.extend((0..200_000).map(|_| (rng.unit() - 0.5) * 2e4));
    values.extend([
        0.0,
        -0.0,
        -1e-9,
        -1e-30,
        TAU,
        -TAU,
        2.0 * TAU,
        -2.0 * TAU,
        1e30,
        -1e30,
    ]);
    // Every code boundary k + ½ (ties, away from zero) and its f32 neighbours.
    for k in 0..256 {
        let b = (k as f32 + 0.5) * (TAU / 256.0);
        for d in -3i32..=3 {
            values.push(f32::from_bits((b.to_bits() as i32 + d) as u32));
        }
    }
    for &v in &values {
        let w = wrap_phase(v);
        assert_eq!(w.to_bits(), old_wrap(v).to_bits(), "wrap {v}");
        assert!((0.0..TAU).contains(&w));
        assert_eq!(linear_code_wrapped(w), libm_code(v), "code {v}");
    }
    assert!(wrap_phase(f32::NAN).is_nan());
    assert_eq!(linear_code_wrapped(f32::NAN), libm_code(f32::NAN));
}

#[test]
fn every_path_is_bit_identical_with_the_portable_body() {
    let mut rng = Rng::new(0xfeed);
    for n in (0..=40).chain([1920, 1921]) {
        let f = row(&mut rng, n);
        let mut want = vec![0.0f32; n];
        let stats = analyse_row(&f, &mut want, Isa::Scalar).unwrap();
        let mut want_codes = vec![0u8; n];
        let mut want_enc = want.clone();
        encode_row(
            &f,
            &mut want_enc,
            Some(&mut want_codes),
            n % 2 == 1,
            0.3,
            1.0,
            Isa::Scalar,
        )
        .unwrap();
        for (name, isa) in paths() {
            let mut p = vec![f32::NAN; n];
            let s = analyse_row(&f, &mut p, isa).unwrap();
            assert_eq!(s.0.to_bits(), stats.0.to_bits(), "{name} n {n}");
            assert_eq!(s.1.to_bits(), stats.1.to_bits(), "{name} n {n}");
            let same = p.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "{name} n {n}");
            let mut c = vec![0u8; n];
            encode_row(&f, &mut p, Some(&mut c), n % 2 == 1, 0.3, 1.0, isa).unwrap();
            let same = p
                .iter()
                .zip(&want_enc)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same && c == want_codes, "{name} n {n}");
        }
    }
}

#[test]
fn rows_match_libm_within_the_phase_bound_and_one_code_step() {
    let mut rng = Rng::new(0xabcdef);
    let (mut pixels, mut differ, mut worst) = (0usize, 0usize, 0.0f32);
    for n in [1usize, 7, 8, 9, 15, 16, 17, 1920, 1921] {
        for y in 0..12usize {
            let f = row(&mut rng, n);
            let mean = (rng.unit() - 0.5) * TAU;
            for (_, isa) in paths() {
                let mut p = vec![0.0f32; n];
                let (max, sum) = analyse_row(&f, &mut p, isa).unwrap();
                let (mut want_max, mut want_sum) = (0.0f32, 0.0f64);
                for (i, &pi) in p.iter().enumerate() {
                    let (re, im) = (f[2 * i], f[2 * i + 1]);
                    let e = atan2_err(im, re, pi);
                    assert!(e <= ATAN2_MAX_ERROR as f64, "atan2({im}, {re}) = {pi}");
                    want_max = want_max.max(re * re + im * im);
                    want_sum += im.atan2(re) as f64;
                }
                assert_eq!(max, want_max);
                assert!(
                    (sum - want_sum).abs() <= 1e-6 * (1.0 + n as f64),
                    "{sum} {want_sum}"
                );
                let inv_a = 1.0 / want_max.sqrt().max(1e-30);
                let mut c = vec![0u8; n];
                encode_row(&f, &mut p, Some(&mut c), y % 2 == 1, mean, inv_a, isa).unwrap();
                for x in 0..n {
                    let want = libm_phase(f[2 * x], f[2 * x + 1], y, x, mean, inv_a);
                    let d = (p[x] - want).abs();
                    let d = d.min(TAU - d);
                    worst = worst.max(d);
                    assert!(
                        d <= PHASE_MAX_ERROR,
                        "n {n} x {x} y {y}: {} vs {want}",
                        p[x]
                    );
                    let (a, b) = (c[x], libm_code(want));
                    let step = a.wrapping_sub(b).min(b.wrapping_sub(a));
                    assert!(step <= 1, "code {a} vs {b}");
                    differ += (step != 0) as usize;
                    pixels += 1;
                }
            }
        }
    }
    println!("phase worst {worst:e} rad; codes differing {differ} of {pixels}");
    // About 2·1.2e-6 / 0.0245 ≈ 1e-4 of the pixels could sit that close to a code boundary.
    assert!(differ * 2000 <= pixels, "{differ} of {pixels} codes differ");
}

#[test]
fn a_mean_far_outside_the_circle_still_wraps() {
    let f = [0.6f32, 0.8, -1.0, 0.0, 0.0, 1.0];
    for (_, isa) in paths() {
        let mut p = [0.0f32; 3];
        analyse_row(&f, &mut p, isa).unwrap();
        let arg = p;
        encode_row(&f, &mut p, None, false, 1000.0, 1.0, isa).unwrap();
        for x in 0..3 {
            let want = libm_phase(f[2 * x], f[2 * x + 1], 0, x, 1000.0, 1.0);
            let d = (p[x] - want).abs();
            assert!(
                d.min(TAU - d) <= 1e-3,
                "{} vs {want} (arg {})",
                p[x],
                arg[x]
            );
            assert!((0.0..TAU).contains(&p[x]));
        }
    }
}

/// Pass 1 on the two planes and pass 2 on the magnitudes give, on every path, the phases, statistics, pattern
/// and codes of the interleaved rows bit for bit (NaN, ∞, zeros and partial last steps included), and `|H|`
/// is the value pass 2 computes from the pairs.
#[test]
fn planar_rows_equal_the_interleaved_rows_on_every_path() {
    let mut rng = Rng::new(0xbead);
    for n in (0..=40).chain([1920, 1921]) {
        let mut f = row(&mut rng, n);
        for (i, v) in [(5, f32::NAN), (9, f32::INFINITY), (12, f32::NEG_INFINITY)] {
            if i < f.len() {
                f[i] = v;
            }
        }
        let re: Vec<f32> = f.iter().step_by(2).copied().collect();
        let im: Vec<f32> = f.iter().skip(1).step_by(2).copied().collect();
        for (name, isa) in paths() {
            let mut want = vec![0.0f32; n];
            let stats = analyse_row(&f, &mut want, isa).unwrap();
            let (mut arg, mut abs) = (im.clone(), vec![f32::NAN; n]);
            let s = analyse_planes_row(&re, &mut arg, &mut abs, isa).unwrap();
            assert_eq!(s.0.to_bits(), stats.0.to_bits(), "{name} n {n}");
            assert_eq!(s.1.to_bits(), stats.1.to_bits(), "{name} n {n}");
            let same = arg
                .iter()
                .zip(&want)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "{name} n {n}: arg");
            let mag = re.iter().zip(&im).map(|(r, i)| (r * r + i * i).sqrt());
            assert!(
                abs.iter().zip(mag).all(|(a, m)| a.to_bits() == m.to_bits()),
                "{name} n {n}: |H|"
            );
            for (mean, inv_a) in [(0.3, 1.0), (-2.0, 1.7), (40.0, 0.5)] {
                let (mut p, mut q) = (want.clone(), arg.clone());
                let (mut c, mut d) = (vec![0u8; n], vec![1u8; n]);
                let odd = n % 2 == 1;
                encode_row(&f, &mut p, Some(&mut c), odd, mean, inv_a, isa).unwrap();
                encode_abs_row(&abs, &mut q, Some(&mut d), odd, mean, inv_a, isa).unwrap();
                let same = p.iter().zip(&q).all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same && c == d, "{name} n {n} mean {mean}");
                let mut r = arg.clone();
                encode_abs_row(&abs, &mut r, None, odd, mean, inv_a, isa).unwrap();
                assert!(r.iter().zip(&q).all(|(a, b)| a.to_bits() == b.to_bits()));
            }
        }
    }
}

#[test]
fn bad_lengths_are_refused() {
    let f = [0.0f32; 6];
    let mut p = [0.0f32; 2];
    assert!(matches!(
        analyse_row(&f, &mut p, Isa::Scalar),
        Err(KernelError::Length { .. })
    ));
    let mut p = [0.0f32; 3];
    let mut c = [0u8; 2];
    assert!(matches!(
        encode_row(&f, &mut p, Some(&mut c), false, 0.0, 1.0, Isa::Scalar),
        Err(KernelError::Length { .. })
    ));
    let (re, mut im, mut abs) = ([0.0f32; 3], [0.0f32; 3], [0.0f32; 2]);
    assert!(matches!(
        analyse_planes_row(&re, &mut im, &mut abs, Isa::Scalar),
        Err(KernelError::Length { .. })
    ));
    assert!(matches!(
        analyse_planes_row(&re[..2], &mut im, &mut abs[..], Isa::Scalar),
        Err(KernelError::Length { .. })
    ));
    assert!(matches!(
        encode_abs_row(&abs, &mut im, None, false, 0.0, 1.0, Isa::Scalar),
        Err(KernelError::Length { .. })
    ));
    assert!(matches!(
        encode_abs_row(
            &abs,
            &mut im[..2],
            Some(&mut c[..1]),
            false,
            0.0,
            1.0,
            Isa::Scalar
        ),
        Err(KernelError::Length { .. })
    ));
}
