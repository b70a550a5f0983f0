//! Physics tests of the angular spectrum method, offset propagation and the Fourier filter.

mod common;

use std::f64::consts::PI;

use common::{energy, rel_error, Rng};
use ndarray::Array3;
use num_complex::{Complex32, Complex64};
use tensorholo::optics::{
    propagate_colour, Carrier, EvenMultiplier, FourierFilter, OpticalSetup, PropagationOptions,
    Propagator,
};
use tensorholo::HoloError;

const PITCH: f64 = 8e-6;
const GREEN: f64 = 520e-9;

/// A random field whose spectrum is confined to |k| < n/4 on each axis (band-limited).
fn band_limited_field(h: usize, w: usize, seed: u64) -> Vec<Complex32> {
    let mut rng = Rng::new(seed);
    let mut field = vec![Complex32::default(); h * w];
    for _ in 0..24 {
        let kx = (rng.next() * (w / 4) as f32).floor() as f64 - (w / 8) as f64;
        let ky = (rng.next() * (h / 4) as f32).floor() as f64 - (h / 8) as f64;
        let amp = rng.next();
        let ph = rng.next() as f64 * 2.0 * PI;
        for y in 0..h {
            for x in 0..w {
                let a = 2.0 * PI * (kx * x as f64 / w as f64 + ky * y as f64 / h as f64) + ph;
                field[y * w + x] += Complex32::from_polar(amp, a as f32);
            }
        }
    }
    field
}

#[test]
fn propagating_z_then_minus_z_returns_the_band_limited_field() {
    let (h, w) = (48, 64);
    let field = band_limited_field(h, w, 1);
    let options = PropagationOptions {
        pad: false,
        band_limit: true,
    };
    let prop = Propagator::new(h, w, PITCH, GREEN, options).unwrap();
    let mut u = field.clone();
    prop.propagate_by(&mut u, 3e-3, Carrier::Keep).unwrap();
    assert!(
        rel_error(&u, &field) > 0.1,
        "3 mm must visibly change the field"
    );
    prop.propagate_by(&mut u, -3e-3, Carrier::Keep).unwrap();
    let err = rel_error(&u, &field);
    assert!(err < 1e-4, "round-trip relative error {err}");
}

#[test]
fn padded_round_trip_returns_a_compact_field() {
    let (h, w) = (64, 64);
    let mut field = vec![Complex32::default(); h * w];
    let mut rng = Rng::new(7);
    for y in 24..40 {
        for x in 24..40 {
            field[y * w + x] = Complex32::new(0.5 + rng.next(), 0.0);
        }
    }
    // Smooth it so that it stays compact over 0.5 mm.
    let prop = Propagator::new(
        h,
        w,
        PITCH,
        GREEN,
        PropagationOptions {
            pad: true,
            band_limit: true,
        },
    )
    .unwrap();
    let mut u = field.clone();
    prop.propagate_by(&mut u, 0.5e-3, Carrier::Keep).unwrap();
    prop.propagate_by(&mut u, -0.5e-3, Carrier::Keep).unwrap();
    let err = rel_error(&u, &field);
    assert!(err < 0.05, "padded round-trip relative error {err}");
}

#[test]
fn propagation_conserves_energy_parseval() {
    let (h, w) = (40, 56);
    let mut rng = Rng::new(3);
    let field: Vec<Complex32> = (0..h * w)
        .map(|_| Complex32::new(rng.next() - 0.5, rng.next() - 0.5))
        .collect();
    let prop = Propagator::new(h, w, PITCH, 638e-9, PropagationOptions::default()).unwrap();
    for z in [1e-3, -2.5e-3, 10e-3] {
        let mut u = field.clone();
        prop.propagate_by(&mut u, z, Carrier::Keep).unwrap();
        let (e0, e1) = (energy(&field), energy(&u));
        assert!(((e1 - e0) / e0).abs() < 1e-5, "z={z}: energy {e0} -> {e1}");
    }
}

#[test]
fn tilted_plane_wave_matches_the_analytic_solution() {
    // u = exp(i2π fx x) on the grid is an eigenfunction: ASM multiplies it by exp(i2πz√(λ⁻² − fx² − fy²)).
    let (h, w) = (32, 48);
    let (kx, ky) = (5i64, -3i64);
    let (fx, fy) = (
        kx as f64 / (w as f64 * PITCH),
        ky as f64 / (h as f64 * PITCH),
    );
    let plane = |phase0: f64| -> Vec<Complex32> {
        (0..h * w)
            .map(|i| {
                let (y, x) = ((i / w) as f64, (i % w) as f64);
                let a = 2.0 * PI * (fx * x * PITCH + fy * y * PITCH) + phase0;
                Complex32::new(a.cos() as f32, a.sin() as f32)
            })
            .collect()
    };
    let z = 4e-3;
    let kz = (GREEN.powi(-2) - fx * fx - fy * fy).sqrt();
    let expected = plane((2.0 * PI * z * kz).rem_euclid(2.0 * PI));
    let prop = Propagator::new(h, w, PITCH, GREEN, PropagationOptions::default()).unwrap();
    let mut u = plane(0.0);
    prop.propagate_by(&mut u, z, Carrier::Keep).unwrap();
    let err = rel_error(&u, &expected);
    assert!(err < 1e-4, "relative error {err}");
}

#[test]
fn matches_a_naive_f64_dft_implementation_of_eq_2_on_random_input() {
    let (h, w) = (6, 10);
    let (pitch, lambda, z): (f64, f64, f64) = (0.4e-6, 633e-9, 20e-6);
    let mut rng = Rng::new(11);
    let field: Vec<Complex32> = (0..h * w)
        .map(|_| Complex32::new(rng.next() - 0.5, rng.next() - 0.5))
        .collect();
    // Naive: DFT, multiply by the transfer function (evanescent zeroed), inverse DFT.
    let dft = |input: &[Complex64], sign: f64| -> Vec<Complex64> {
        let mut out = vec![Complex64::default(); h * w];
        for ky in 0..h {
            for kx in 0..w {
                let mut acc = Complex64::default();
                for y in 0..h {
                    for x in 0..w {
                        let a = sign
                            * 2.0
                            * PI
                            * ((ky * y) as f64 / h as f64 + (kx * x) as f64 / w as f64);
                        acc += input[y * w + x] * Complex64::from_polar(1.0, a);
                    }
                }
                out[ky * w + kx] = acc;
            }
        }
        out
    };
    let input: Vec<Complex64> = field
        .iter()
        .map(|v| Complex64::new(v.re as f64, v.im as f64))
        .collect();
    let mut spec = dft(&input, -1.0);
    for ky in 0..h {
        for kx in 0..w {
            let sx = if kx < w.div_ceil(2) {
                kx as f64
            } else {
                kx as f64 - w as f64
            };
            let sy = if ky < h.div_ceil(2) {
                ky as f64
            } else {
                ky as f64 - h as f64
            };
            let (fx, fy) = (sx / (w as f64 * pitch), sy / (h as f64 * pitch));
            let arg = lambda.powi(-2) - fx * fx - fy * fy;
            spec[ky * w + kx] *= if arg > 0.0 {
                Complex64::from_polar(1.0, 2.0 * PI * z * arg.sqrt())
            } else {
                Complex64::default()
            };
        }
    }
    let naive: Vec<Complex32> = dft(&spec, 1.0)
        .into_iter()
        .map(|v| {
            Complex32::new(
                (v.re / (h * w) as f64) as f32,
                (v.im / (h * w) as f64) as f32,
            )
        })
        .collect();
    // pitch 0.4 µm with λ = 633 nm: the corner frequencies are evanescent, which the naive code zeroes too.
    let prop = Propagator::new(h, w, pitch, lambda, PropagationOptions::default()).unwrap();
    let mut u = field.clone();
    prop.propagate_by(&mut u, z, Carrier::Keep).unwrap();
    let err = rel_error(&u, &naive);
    assert!(err < 1e-5, "relative error vs naive {err}");
    assert!(
        energy(&u) < 0.99 * energy(&field),
        "evanescent energy must be lost"
    );
}

#[test]
fn evanescent_plane_wave_is_removed() {
    // Pitch 0.25 µm: the Nyquist frequency 2e6 /m exceeds 1/λ ≈ 1.57e6 /m, so a Nyquist stripe is evanescent.
    let (h, w, pitch) = (8, 8, 0.25e-6);
    let u0: Vec<Complex32> = (0..h * w)
        .map(|i| Complex32::new(if (i % w) % 2 == 0 { 1.0 } else { -1.0 }, 0.0))
        .collect();
    let prop = Propagator::new(h, w, pitch, 638e-9, PropagationOptions::default()).unwrap();
    let mut u = u0.clone();
    prop.propagate_by(&mut u, 1e-6, Carrier::Keep).unwrap();
    assert!(
        energy(&u) < 1e-8 * energy(&u0),
        "energy left {}",
        energy(&u)
    );
}

#[test]
fn padding_turns_circular_into_linear_convolution() {
    // A point near the left edge: without padding its diffraction wraps around to the right edge.
    let (h, w) = (32, 64);
    let mut point = vec![Complex32::default(); h * w];
    point[16 * w + 1] = Complex32::new(1.0, 0.0);
    let right_energy = |pad: bool| {
        let prop = Propagator::new(
            h,
            w,
            PITCH,
            638e-9,
            PropagationOptions {
                pad,
                band_limit: false,
            },
        )
        .unwrap();
        let mut u = point.clone();
        prop.propagate_by(&mut u, 2e-3, Carrier::Keep).unwrap();
        (0..h)
            .flat_map(|y| (w - 12..w).map(move |x| y * w + x))
            .map(|i| u[i].norm_sqr() as f64)
            .sum::<f64>()
            / energy(&u)
    };
    let (circular, linear) = (right_energy(false), right_energy(true));
    assert!(
        circular > 0.05,
        "unpadded: wrapped energy fraction {circular}"
    );
    assert!(
        linear < 0.1 * circular,
        "padded: {linear} vs unpadded {circular}"
    );
}

#[test]
fn offset_carrier_keeps_a_plane_wave_phase_at_zero() {
    let setup = OpticalSetup::default();
    let mut field = Array3::from_elem((3, 8, 8), Complex32::new(0.7, 0.0));
    propagate_colour(
        &mut field,
        &setup,
        6e-3,
        Carrier::Remove,
        PropagationOptions::default(),
    )
    .unwrap();
    for v in field.iter() {
        assert!((v - Complex32::new(0.7, 0.0)).norm() < 1e-5, "{v}");
    }
    let mut kept = Array3::from_elem((3, 8, 8), Complex32::new(0.7, 0.0));
    propagate_colour(
        &mut kept,
        &setup,
        6e-3,
        Carrier::Keep,
        PropagationOptions::default(),
    )
    .unwrap();
    for (c, lambda) in setup.wavelengths_m.iter().enumerate() {
        let expected = (2.0 * PI * 6e-3 / lambda).rem_euclid(2.0 * PI);
        let got = (kept[[c, 3, 3]].arg() as f64).rem_euclid(2.0 * PI);
        let d = (got - expected).abs();
        assert!(
            d.min(2.0 * PI - d) < 1e-3,
            "colour {c}: phase {got} vs {expected}"
        );
    }
    // Offset forward (Eq. 6) then back (Eq. 10) is the identity.
    let mut rng = Rng::new(5);
    let orig = Array3::from_shape_fn((3, 16, 24), |_| Complex32::new(rng.next(), rng.next()));
    let mut f = orig.clone();
    propagate_colour(
        &mut f,
        &setup,
        12e-3,
        Carrier::Remove,
        PropagationOptions::default(),
    )
    .unwrap();
    propagate_colour(
        &mut f,
        &setup,
        -12e-3,
        Carrier::Remove,
        PropagationOptions::default(),
    )
    .unwrap();
    let err = rel_error(f.as_slice().unwrap(), orig.as_slice().unwrap());
    assert!(err < 1e-4, "{err}");
}

#[test]
fn fourier_filter_removes_the_checkerboard_and_keeps_low_frequencies() {
    let (h, w) = (24, 32);
    let filter = FourierFilter::new(h, w).unwrap();
    let mut scratch = filter.plan().scratch();
    let low = band_limited_field(h, w, 9);
    let mut u = low.clone();
    filter.apply(&mut u, &mut scratch).unwrap();
    assert!(
        rel_error(&u, &low) < 1e-5,
        "low frequencies must pass unchanged"
    );
    let checker: Vec<Complex32> = (0..h * w)
        .map(|i| Complex32::new(if (i / w + i % w) % 2 == 0 { 1.0 } else { -1.0 }, 0.0))
        .collect();
    let mut u = checker.clone();
    filter.apply(&mut u, &mut scratch).unwrap();
    assert!(energy(&u) < 1e-8 * energy(&checker));
    // Radius min(H, W)/2 = 12 index units: (12, 0) passes, (12, 1) does not.
    let (inside, outside) = (
        filter.mask().iter().filter(|&&m| m == 1.0).count(),
        filter.mask().iter().filter(|&&m| m == 0.0).count(),
    );
    assert_eq!(inside + outside, h * w);
    let expected_inside = (-12i64..=11)
        .flat_map(|ky| (-16i64..=15).map(move |kx| (kx, ky)))
        .filter(|(kx, ky)| kx * kx + ky * ky <= 144)
        .count();
    assert_eq!(inside, expected_inside);
}

#[test]
fn bad_parameters_are_clear_errors() {
    let opts = PropagationOptions::default();
    for (pitch, lambda) in [
        (0.0, GREEN),
        (-1e-6, GREEN),
        (PITCH, 0.0),
        (PITCH, f64::NAN),
    ] {
        let err = Propagator::new(8, 8, pitch, lambda, opts).unwrap_err();
        assert!(matches!(err, HoloError::InvalidParameter { .. }), "{err}");
    }
    assert!(Propagator::new(0, 8, PITCH, GREEN, opts).is_err());
    let prop = Propagator::new(8, 8, PITCH, GREEN, opts).unwrap();
    assert!(prop
        .transfer_function(f64::INFINITY, Carrier::Keep)
        .is_err());
    let mut wrong = vec![Complex32::default(); 63];
    let err = prop
        .propagate_by(&mut wrong, 1e-3, Carrier::Keep)
        .unwrap_err();
    assert!(err.to_string().contains("shape mismatch"), "{err}");
    let mut nan = Array3::from_elem((3, 4, 4), Complex32::new(f32::NAN, 0.0));
    assert!(propagate_colour(
        &mut nan,
        &OpticalSetup::default(),
        1e-3,
        Carrier::Keep,
        opts
    )
    .is_err());
}

#[test]
fn focal_stack_with_aperture_removes_the_checkerboard_term_at_the_field_plane() {
    // A smooth field plus a Nyquist checkerboard: the aperture keeps the first and removes the second.
    let (h, w) = (32, 48);
    let smooth = band_limited_field(h, w, 12);
    let field = Array3::from_shape_fn((3, h, w), |(_, y, x)| {
        smooth[y * w + x] + Complex32::new(if (x + y) % 2 == 0 { 3.0 } else { -3.0 }, 0.0)
    });
    let setup = OpticalSetup::default();
    let opts = PropagationOptions::default();
    let with =
        tensorholo::optics::focal_stack(field.view(), &setup, 0.0, &[0.5], opts, true).unwrap();
    let without =
        tensorholo::optics::focal_stack(field.view(), &setup, 0.0, &[0.5], opts, false).unwrap();
    for c in 0..3 {
        for y in 0..h {
            for x in 0..w {
                let expected = smooth[y * w + x].norm();
                assert!((with[0][[c, y, x]] - expected).abs() < 1e-3);
            }
        }
    }
    let max_dev = (0..h * w)
        .map(|i| (without[0][[0, i / w, i % w]] - smooth[i].norm()).abs())
        .fold(0.0f32, f32::max);
    assert!(
        max_dev > 1.0,
        "without the aperture the checkerboard stays: {max_dev}"
    );
}

#[test]
fn even_transfer_function_quarter_applies_bit_identically() {
    // The offset transfer function (Eq. 6, carrier removed, band limit on) depends on the frequency radius
    // only: its quarter (a fourth of the memory) applies the bit-identical propagation, for odd and even
    // sizes, padded or not. A multiplier that is not even has no quarter form.
    for (h, w, pad) in [(16, 24, false), (17, 13, false), (9, 20, true)] {
        let opts = PropagationOptions {
            pad,
            ..PropagationOptions::default()
        };
        let prop = Propagator::new(h, w, PITCH, GREEN, opts).unwrap();
        let tf = prop.transfer_function(6e-3, Carrier::Remove).unwrap();
        let plan = prop.plan();
        let even = EvenMultiplier::from_full(plan, tf.values())
            .unwrap()
            .expect("the offset transfer function is even");
        assert!(even.bytes() * 3 <= tf.values().len() * 8 + 64 * (h + w));
        let field = band_limited_field(h, w, 5);
        let (mut a, mut b) = (field.clone(), field.clone());
        let mut scratch = plan.scratch();
        plan.apply(&mut a, tf.values(), &mut scratch).unwrap();
        plan.apply_even(&mut b, &even, &mut scratch).unwrap();
        assert!(a.iter().zip(&b).all(|(x, y)| x == y), "{h}×{w} pad {pad}");
        // With row hooks: the field made by `before` (from nothing) and read back by `after`, chunk by chunk
        // or whole when padded, is the same propagation; kept in the field, or (unpadded) seen by `after`
        // alone, the field left with the column pass's values.
        for keep in [true, false] {
            let (mut c, mut seen) = (
                vec![Complex32::new(f32::NAN, f32::NAN); h * w],
                vec![Complex32::default(); h * w],
            );
            plan.apply_even_rows(
                &mut c,
                &even,
                &mut scratch,
                |f, rows| {
                    f[rows.start * w..rows.end * w]
                        .copy_from_slice(&field[rows.start * w..rows.end * w])
                },
                keep,
                |chunk, rows, _| seen[rows.start * w..rows.end * w].copy_from_slice(chunk),
            )
            .unwrap();
            let same = |v: &[Complex32]| a.iter().zip(v).all(|(x, y)| x == y);
            assert!(same(&seen), "{h}×{w} pad {pad} keep {keep}");
            assert_eq!(same(&c), keep || pad, "{h}×{w} pad {pad} keep {keep}");
        }
        assert!(
            rel_error(&a, &field) > 1e-3,
            "the propagation changed the field"
        );
        // The inverse of a kept spectrum (the focal stack's form): the same with the quarter.
        let mut spectrum = vec![Complex32::default(); plan.spectrum_len()];
        plan.forward(&field, &mut spectrum, &mut scratch).unwrap();
        plan.inverse(&spectrum, tf.values(), &mut a, &mut scratch)
            .unwrap();
        plan.inverse_even(&spectrum, &even, &mut b, &mut scratch)
            .unwrap();
        assert!(a.iter().zip(&b).all(|(x, y)| x == y), "{h}×{w} pad {pad}");
        // One value off its mirror: not even.
        let mut odd = tf.values().to_vec();
        odd[1] *= 1.5;
        assert!(EvenMultiplier::from_full(plan, &odd).unwrap().is_none());
        assert!(EvenMultiplier::from_full(plan, &odd[1..]).is_err());
    }
}

#[test]
fn even_transfer_function_computed_on_its_quarter_equals_the_full_ones_quarter() {
    // A session computes only the quarter (`Propagator::even_transfer_function`): the same values, bit for
    // bit, as the quarter of the full transfer function, for odd and even sizes, padded or not, with and
    // without the band limit, both carriers, and both signs of the distance.
    for (h, w, pad) in [
        (16, 24, false),
        (17, 13, false),
        (9, 20, true),
        (1, 7, false),
    ] {
        for band_limit in [false, true] {
            let opts = PropagationOptions { pad, band_limit };
            let prop = Propagator::new(h, w, PITCH, GREEN, opts).unwrap();
            for carrier in [Carrier::Keep, Carrier::Remove] {
                for z in [6e-3, -2.5e-3] {
                    let full = prop.transfer_function(z, carrier).unwrap();
                    let want = EvenMultiplier::from_full(prop.plan(), full.values())
                        .unwrap()
                        .expect("even");
                    let got = prop.even_transfer_function(z, carrier).unwrap();
                    assert_eq!(
                        got, want,
                        "{h}×{w} pad {pad} band limit {band_limit} {carrier:?} {z}"
                    );
                }
            }
        }
    }
    let prop = Propagator::new(8, 8, PITCH, GREEN, PropagationOptions::default()).unwrap();
    assert!(prop
        .even_transfer_function(f64::NAN, Carrier::Remove)
        .is_err());
}
