//! The box means against a naive reference (direct sums of the image, the two squares interpolated) on random
//! images and depths, and every path against the portable body bit for bit.

use super::*;
use crate::test_rng::Rng;

/// A `h × w` image in `[0, 1)` and its summed-area table (`(h + 1) × (w + 1)`, f64).
fn image_and_table(rng: &mut Rng, h: usize, w: usize) -> (Vec<f32>, Vec<f64>) {
    let image: Vec<f32> = (0..h * w).map(|_| rng.unit()).collect();
    let stride = w + 1;
    let mut table = vec![0.0f64; (h + 1) * stride];
    for y in 0..h {
        let mut acc = 0.0f64;
        for x in 0..w {
            acc += f64::from(image[y * w + x]);
            table[(y + 1) * stride + x + 1] = table[y * stride + x + 1] + acc;
        }
    }
    (image, table)
}

/// The naive blurred pixel: direct means of the two squares, interpolated by the fraction of `h`.
fn naive(image: &[f32], w: usize, y: usize, x: usize, d: f32, defocus: Defocus) -> f64 {
    let h = (f64::from((d - defocus.gaze_depth).abs()) * defocus.scale - 0.5)
        .clamp(0.0, defocus.max_half);
    let mean = |k: usize| {
        let mut sum = 0.0f64;
        for yy in y - k..=y + k {
            for xx in x - k..=x + k {
                sum += f64::from(image[yy * w + xx]);
            }
        }
        sum / ((2 * k + 1) * (2 * k + 1)) as f64
    };
    let k = h.floor();
    let t = h - k;
    (1.0 - t) * mean(k as usize) + t * mean(k as usize + 1)
}

fn available_paths() -> Vec<(String, Isa)> {
    crate::dispatch::available_paths("box_means", PATHS)
}

/// Random depths (some at the gaze's depth exactly, some far beyond the largest half-width) on runs of every
/// length up to three chunks, against the naive reference; every path bit for bit with the portable body.
#[test]
fn box_means_match_direct_sums_on_every_path() {
    let mut rng = Rng::new(0xB0B);
    let (h, w) = (31, 3 * CHUNK + 40);
    let (image, table) = image_and_table(&mut rng, h, w);
    let defocus = Defocus {
        gaze_depth: 0.4,
        scale: 9.3,
        max_half: 5.7,
    };
    let k = 7; // ⌊max_half⌋ + 1 + 1: a margin of one beyond what the bounds need
    let paths = available_paths();
    let mut checked = 0;
    for n in [
        0,
        1,
        2,
        7,
        CHUNK - 1,
        CHUNK,
        CHUNK + 1,
        2 * CHUNK + 17,
        3 * CHUNK,
    ] {
        for (row, x0) in [(k, k), (h - k - 1, w - k - 1 - n), (15, k + 3)] {
            let depth: Vec<f32> = (0..n)
                .map(|i| match i % 9 {
                    0 => 0.4,
                    1 => 5.0,
                    // Smooth along the run as a scene's depth, with noise.
                    _ => 0.4 + 0.6 * ((i + row) as f32 / 50.0).sin() + 0.02 * rng.f(),
                })
                .collect();
            let sat = SatRow {
                table: &table,
                stride: w + 1,
                row,
                x0,
            };
            let mut portable = vec![f32::NAN; n];
            box_means(sat, &depth, defocus, &mut portable, Isa::Scalar).unwrap();
            for (i, (&got, &d)) in portable.iter().zip(&depth).enumerate() {
                let want = naive(&image, w, row, x0 + i, d, defocus);
                assert!(
                    (f64::from(got) - want).abs() <= 1e-6 * want.abs().max(1e-3),
                    "n {n} row {row} pixel {}: {got} vs {want}",
                    x0 + i
                );
                checked += 1;
            }
            for (name, isa) in &paths {
                let mut out = vec![f32::NAN; n];
                box_means(sat, &depth, defocus, &mut out, *isa).unwrap();
                let same = out
                    .iter()
                    .zip(&portable)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "{name}, n {n}: differs from the portable body");
            }
        }
    }
    assert!(checked > 1000, "{checked}");
}

/// At the gaze's depth the mean is the pixel itself, exactly; a depth whose half-width is a whole number
/// reads that one square alone.
#[test]
fn in_focus_pixels_are_the_image_and_whole_sizes_one_square() {
    let mut rng = Rng::new(7);
    let (h, w) = (20, 40);
    let (image, table) = image_and_table(&mut rng, h, w);
    let sat = SatRow {
        table: &table,
        stride: w + 1,
        row: 10,
        x0: 5,
    };
    let defocus = Defocus {
        gaze_depth: 0.25,
        scale: 2.5,
        max_half: 3.0,
    };
    let mut out = vec![0.0f32; 20];
    box_means(sat, &[0.25; 20], defocus, &mut out, Isa::detect()).unwrap();
    assert_eq!(out, image[10 * w + 5..10 * w + 25]);
    // |d − d_g|·2.5 − 0.5 = 1: the 3 × 3 mean alone.
    box_means(sat, &[0.85; 20], defocus, &mut out, Isa::detect()).unwrap();
    for (i, &o) in out.iter().enumerate() {
        let (y, x) = (10, 5 + i);
        let sum: f64 = (y - 1..=y + 1)
            .flat_map(|yy| (x - 1..=x + 1).map(move |xx| (yy, xx)))
            .map(|(yy, xx)| f64::from(image[yy * w + xx]))
            .sum();
        assert_eq!(o, (sum / 9.0) as f32, "pixel {x}");
    }
}

/// Squares that would leave the image, a short `out` and bad parameters are refused.
#[test]
fn bad_bounds_and_parameters_are_refused() {
    let (h, w) = (12, 30);
    let table = vec![0.0f64; (h + 1) * (w + 1)];
    let defocus = Defocus {
        gaze_depth: 0.5,
        scale: 4.0,
        max_half: 2.2,
    };
    let sat = |row, x0| SatRow {
        table: &table,
        stride: w + 1,
        row,
        x0,
    };
    let mut out = vec![0.0f32; 10];
    let depth = [0.5f32; 10];
    for (row, x0) in [(3, 3), (8, 17)] {
        assert!(box_means(sat(row, x0), &depth, defocus, &mut out, Isa::Scalar).is_ok());
    }
    for (row, x0) in [(2, 3), (3, 2), (9, 3), (3, 18)] {
        let err = box_means(sat(row, x0), &depth, defocus, &mut out, Isa::Scalar);
        assert!(
            matches!(err, Err(KernelError::Shape { .. })),
            "({row}, {x0}): {err:?}"
        );
    }
    let err = box_means(sat(3, 3), &depth, defocus, &mut out[..9], Isa::Scalar);
    assert!(matches!(err, Err(KernelError::Length { .. })), "{err:?}");
    for bad in [f64::NAN, -1.0, f64::INFINITY] {
        let d = Defocus {
            max_half: bad,
            ..defocus
        };
        let err = box_means(sat(3, 3), &depth, d, &mut out, Isa::Scalar);
        assert!(matches!(err, Err(KernelError::Parameter { .. })), "{err:?}");
        let d = Defocus {
            scale: bad,
            ..defocus
        };
        let err = box_means(sat(3, 3), &depth, d, &mut out, Isa::Scalar);
        assert!(matches!(err, Err(KernelError::Parameter { .. })), "{err:?}");
    }
}
