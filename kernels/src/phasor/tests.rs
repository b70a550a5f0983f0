//! The phasor rows against the exact value (f64) and against each other. The dense grids here stand for the
//! exhaustive sweep behind the module's bound, which is `#[ignore]`d: run it with
//! `cargo test -p tensorholo-kernels --release -- --ignored phasor_exhaustive --nocapture`.

use super::*;
use crate::test_rng::Rng;

fn available_paths() -> Vec<(String, Isa)> {
    crate::dispatch::available_paths("phasors", PATHS)
}

/// The exact `(a·cos θ, a·sin θ)` of `θ = 2π·(p − 0.5)`, `p − 0.5` rounded to f32 as the definition does.
fn exact(a: f32, p: f32) -> (f64, f64) {
    let t = (p - 0.5) as f64;
    // The whole turns removed exactly before the f64 product, so that a huge `t` keeps its fraction.
    let f = t - t.round();
    let th = 2.0 * std::f64::consts::PI * f;
    (a as f64 * th.cos(), a as f64 * th.sin())
}

/// The largest component error of [`phasor`] over `ps` (amplitude 1), in units of `|a|`.
fn worst_error(ps: impl Iterator<Item = f32>) -> f64 {
    ps.map(|p| {
        let (re, im) = phasor(1.0, p);
        let (er, ei) = exact(1.0, p);
        (re as f64 - er).abs().max((im as f64 - ei).abs())
    })
    .fold(0.0, f64::max)
}

/// Phase heads over `[0, 1]` (every 257th f32, the ends and the quarter turns) and far outside it.
fn phase_values() -> Vec<f32> {
    let one = 1.0f32.to_bits();
    let mut v: Vec<f32> = (0..=one).step_by(257).map(f32::from_bits).collect();
    v.extend([0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0, -0.0]);
    v.extend([
        1e-30,
        -1e-30,
        3.5,
        -7.25,
        1e6 + 0.25,
        4_194_304.5,
        8_388_607.5,
        1e10,
        -1e10,
    ]);
    let mut bits = Rng::new(0x2545_F491_4F6C_DD1D);
    // Any sign and exponent up to 2³⁰ turns.
    v.extend((0..20_000).map(|_| {
        let e = (bits.next() % 60) as i32 - 30;
        (bits.unit() * 2.0 - 1.0) * 2f32.powi(e)
    }));
    v
}

#[test]
fn phasor_is_within_its_bound_of_the_exact_value() {
    let worst = worst_error(phase_values().into_iter());
    assert!(
        worst <= PHASOR_MAX_ERROR as f64,
        "worst component error {worst:e} > {PHASOR_MAX_ERROR:e}"
    );
    // The bound is tight enough to mean something: it is reached within a factor of 4.
    assert!(worst > PHASOR_MAX_ERROR as f64 / 4.0, "{worst:e}");
}

#[test]
fn quarter_turns_and_whole_turns_are_exact() {
    // p − 0.5 = 0, ±¼, ±½: cos and sin are 0 and ±1 exactly.
    for (p, c, s) in [
        (0.5f32, 1.0f32, 0.0f32),
        (0.75, 0.0, 1.0),
        (1.0, -1.0, 0.0),
        (0.25, 0.0, -1.0),
        (0.0, -1.0, 0.0),
        (1e7 + 0.5, 1.0, 0.0),
        (2.5e9, 1.0, 0.0),
        (4_194_304.5, 1.0, 0.0),
        (4_194_305.0, -1.0, 0.0),
    ] {
        let (re, im) = phasor(2.0, p);
        assert_eq!(
            (re.abs(), im.abs()),
            (2.0 * c.abs(), 2.0 * s.abs()),
            "p = {p}"
        );
        if c != 0.0 {
            assert_eq!(re, 2.0 * c, "p = {p}");
        }
        if s != 0.0 {
            assert_eq!(im, 2.0 * s, "p = {p}");
        }
    }
}

#[test]
fn phasor_is_periodic_and_odd_in_the_turn() {
    let mut bits = Rng::new(7);
    for _ in 0..10_000 {
        let t = bits.unit() - 0.5;
        let (s, c) = sincos_turns(t);
        // A whole turn more (exact in f32 for |t| < 1) gives the same values.
        let (s1, c1) = sincos_turns(t + 3.0);
        let exact_shift = (t + 3.0) - 3.0 == t;
        if exact_shift {
            assert_eq!((s, c), (s1, c1), "t = {t}");
        }
        let (sn, cn) = sincos_turns(-t);
        assert_eq!((sn, cn), (-s, c), "t = {t}");
        assert!((s * s + c * c - 1.0).abs() < 4e-7, "t = {t}");
    }
}

#[test]
fn non_finite_heads_are_reported() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        for (name, isa) in available_paths() {
            for at in [0usize, 5, 16, 20] {
                let mut a = vec![0.5f32; 21];
                let mut p = vec![0.3f32; 21];
                let mut out = vec![0.0; 42];
                assert!(phasors(&a, &p, &mut out, isa).unwrap());
                a[at] = bad;
                assert!(!phasors(&a, &p, &mut out, isa).unwrap(), "{name}, a[{at}]");
                a[at] = 0.5;
                p[at] = bad;
                assert!(!phasors(&a, &p, &mut out, isa).unwrap(), "{name}, p[{at}]");
                if bad.is_nan() {
                    assert!(out[2 * at].is_nan() && out[2 * at + 1].is_nan(), "{name}");
                }
            }
        }
    }
}

#[test]
fn every_path_and_the_in_place_form_are_bit_identical_to_the_portable_body() {
    let mut bits = Rng::new(0x9E37_79B9_7F4A_7C15);
    for n in (0..40).chain([63, 64, 65, 100, 257]) {
        let a: Vec<f32> = (0..n).map(|_| bits.unit() * 1.5).collect();
        let p: Vec<f32> = (0..n).map(|_| bits.unit() * 3.0 - 1.0).collect();
        let mut want = vec![0.0f32; 2 * n];
        for i in 0..n {
            (want[2 * i], want[2 * i + 1]) = phasor(a[i], p[i]);
        }
        for (name, isa) in available_paths() {
            let mut out = vec![f32::NAN; 2 * n];
            assert!(phasors(&a, &p, &mut out, isa).unwrap());
            let mut buf = a.clone();
            buf.resize(2 * n, f32::NAN);
            assert!(phasors_in_place(&mut buf, &p, isa).unwrap());
            for i in 0..2 * n {
                assert_eq!(
                    out[i].to_bits(),
                    want[i].to_bits(),
                    "{name}, n = {n}, value {i}"
                );
                assert_eq!(
                    buf[i].to_bits(),
                    want[i].to_bits(),
                    "{name} in place, n = {n}, value {i}"
                );
            }
        }
    }
}

#[test]
fn wrong_lengths_are_refused() {
    let isa = Isa::Scalar;
    let mut out = vec![0.0; 8];
    assert!(matches!(
        phasors(&[0.0; 4], &[0.0; 3], &mut out, isa),
        Err(KernelError::Length { .. })
    ));
    assert!(matches!(
        phasors(&[0.0; 4], &[0.0; 4], &mut out[..7], isa),
        Err(KernelError::Length { .. })
    ));
    assert!(matches!(
        phasors_in_place(&mut out, &[0.0; 5], isa),
        Err(KernelError::Length { .. })
    ));
}

/// The exhaustive sweep behind [`PHASOR_MAX_ERROR`]: every f32 phase head in `[0, 1]` (release build, all
/// cores), plus 10⁷ random heads of any sign and exponent. Prints the worst error, and libm's
/// (`from_polar` with the angle rounded to f32) for comparison.
#[test]
#[ignore]
fn phasor_exhaustive_bound() {
    let one = 1.0f32.to_bits() as u64;
    let threads = std::thread::available_parallelism().map_or(1, |t| t.get()) as u64;
    let step = (one + 1).div_ceil(threads);
    let (ours, libm) = std::thread::scope(|s| {
        let parts: Vec<_> = (0..threads)
            .map(|k| {
                s.spawn(move || {
                    let (mut w, mut l) = (0.0f64, 0.0f64);
                    for b in k * step..((k + 1) * step).min(one + 1) {
                        let p = f32::from_bits(b as u32);
                        let (re, im) = phasor(1.0, p);
                        let (er, ei) = exact(1.0, p);
                        w = w.max((re as f64 - er).abs()).max((im as f64 - ei).abs());
                        let th = (p - 0.5) * std::f32::consts::TAU;
                        l = l
                            .max((th.cos() as f64 - er).abs())
                            .max((th.sin() as f64 - ei).abs());
                    }
                    (w, l)
                })
            })
            .collect();
        parts
            .into_iter()
            .map(|h| h.join().unwrap())
            .fold((0.0f64, 0.0f64), |a, b| (a.0.max(b.0), a.1.max(b.1)))
    });
    let mut bits = Rng::new(0xD1B5_4A32_D192_ED03);
    let random = worst_error((0..10_000_000).map(|_| {
        let e = (bits.next() % 80) as i32 - 40;
        (bits.unit() * 2.0 - 1.0) * 2f32.powi(e)
    }));
    println!(
        "phasor on [0, 1]: worst {ours:e}; libm from_polar: {libm:e}; random heads: {random:e}"
    );
    assert!(ours.max(random) <= PHASOR_MAX_ERROR as f64);
}
