//! PSNR / SSIM against scikit-image (fixture made by `fixtures/make_metrics_fixture.py`) and
//! properties every implementation must have.

use ndarray::{Array2, Array3, ArrayD, IxDyn};
use proptest::prelude::*;
use serde_json::Value;
use tensorholo::metrics::{psnr, ssim, ssim_multichannel};
use tensorholo::HoloError;

const FIXTURE: &str = include_str!("fixtures/metrics_fixture.json");

struct Case {
    name: String,
    reference: ArrayD<f32>,
    test: ArrayD<f32>,
    data_range: f32,
    psnr: f64,
    ssim: f64,
}

fn load_cases() -> (String, Vec<Case>) {
    let v: Value = serde_json::from_str(FIXTURE).expect("fixture is valid JSON");
    let denom = v["denominator"].as_f64().unwrap() as f32;
    let version = v["skimage_version"].as_str().unwrap().to_string();
    let decode = |a: &Value, shape: &[usize]| {
        let data: Vec<f32> = a
            .as_array()
            .unwrap()
            .iter()
            .map(|k| k.as_i64().unwrap() as f32 / denom)
            .collect();
        ArrayD::from_shape_vec(IxDyn(shape), data).unwrap()
    };
    let cases = v["cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let shape: Vec<usize> = c["shape"]
                .as_array()
                .unwrap()
                .iter()
                .map(|n| n.as_u64().unwrap() as usize)
                .collect();
            Case {
                name: c["name"].as_str().unwrap().to_string(),
                reference: decode(&c["reference"], &shape),
                test: decode(&c["test"], &shape),
                data_range: c["data_range"].as_f64().unwrap() as f32,
                psnr: c["psnr"].as_f64().unwrap(),
                ssim: c["ssim"].as_f64().unwrap(),
            }
        })
        .collect();
    (version, cases)
}

#[test]
fn matches_scikit_image_fixture() {
    let (version, cases) = load_cases();
    assert!(cases.len() >= 5, "fixture lost its cases");
    assert!(cases.iter().any(|c| c.reference.ndim() == 3));
    for c in &cases {
        let p = psnr(c.reference.view(), c.test.view(), c.data_range).unwrap();
        let s = match c.reference.ndim() {
            2 => ssim(
                c.reference.view().into_dimensionality().unwrap(),
                c.test.view().into_dimensionality().unwrap(),
                c.data_range,
            ),
            3 => ssim_multichannel(
                c.reference.view().into_dimensionality().unwrap(),
                c.test.view().into_dimensionality().unwrap(),
                c.data_range,
            ),
            n => panic!("unexpected rank {n}"),
        }
        .unwrap();
        eprintln!(
            "{:22} PSNR {p:.6} dB (Δ {:.1e}), SSIM {s:.8} (Δ {:.1e})",
            c.name,
            f64::from(p) - c.psnr,
            f64::from(s) - c.ssim
        );
        assert!(
            (f64::from(p) - c.psnr).abs() < 1e-4,
            "{}: PSNR {p} dB, skimage {version} says {}",
            c.name,
            c.psnr
        );
        assert!(
            (f64::from(s) - c.ssim).abs() < 1e-6,
            "{}: SSIM {s}, skimage {version} says {}",
            c.name,
            c.ssim
        );
    }
}

#[test]
fn psnr_known_value_and_identical_is_infinite() {
    let a = Array2::<f32>::zeros((4, 5));
    let b = Array2::<f32>::from_elem((4, 5), 0.1);
    // MSE = 0.01 → 10·log10(1 / 0.01) = 20 dB.
    assert!((psnr(a.view(), b.view(), 1.0).unwrap() - 20.0).abs() < 1e-5);
    // data_range 2 adds 20·log10(2) dB.
    assert!((psnr(a.view(), b.view(), 2.0).unwrap() - 26.020_6).abs() < 1e-4);
    assert_eq!(psnr(a.view(), a.view(), 1.0).unwrap(), f32::INFINITY);
}

#[test]
fn ssim_of_constant_offset_only_lowers_luminance_term() {
    let a = Array2::<f32>::from_elem((12, 12), 0.5);
    let b = Array2::<f32>::from_elem((12, 12), 0.6);
    // Constant images: contrast-structure term is 1; luminance term (2·μx·μy + C1)/(μx² + μy² + C1).
    let c1 = 1e-4f64;
    let want = (2.0 * 0.5 * 0.6 + c1) / (0.25 + 0.36 + c1);
    let got = f64::from(ssim(a.view(), b.view(), 1.0).unwrap());
    assert!((got - want).abs() < 1e-6, "{got} vs {want}");
}

#[test]
fn shape_mismatch_is_an_error() {
    let a = Array2::<f32>::zeros((16, 16));
    let b = Array2::<f32>::zeros((16, 17));
    assert!(matches!(
        psnr(a.view(), b.view(), 1.0),
        Err(HoloError::ShapeMismatch { .. })
    ));
    assert!(matches!(
        ssim(a.view(), b.view(), 1.0),
        Err(HoloError::ShapeMismatch { .. })
    ));
    let c = Array3::<f32>::zeros((3, 16, 16));
    let d = Array3::<f32>::zeros((2, 16, 16));
    assert!(matches!(
        ssim_multichannel(c.view(), d.view(), 1.0),
        Err(HoloError::ShapeMismatch { .. })
    ));
}

#[test]
fn too_small_for_the_window_is_an_error() {
    let a = Array2::<f32>::zeros((10, 30));
    assert!(matches!(
        ssim(a.view(), a.view(), 1.0),
        Err(HoloError::ShapeMismatch { .. })
    ));
    let a = Array2::<f32>::zeros((11, 11));
    assert_eq!(ssim(a.view(), a.view(), 1.0).unwrap(), 1.0);
    let c = Array3::<f32>::zeros((3, 11, 10));
    assert!(ssim_multichannel(c.view(), c.view(), 1.0).is_err());
    let c = Array3::<f32>::zeros((0, 11, 11));
    assert!(matches!(
        ssim_multichannel(c.view(), c.view(), 1.0),
        Err(HoloError::InvalidData(_))
    ));
}

#[test]
fn non_finite_values_and_bad_data_range_are_errors() {
    let a = Array2::<f32>::zeros((12, 12));
    let mut b = a.clone();
    b[[3, 4]] = f32::NAN;
    assert!(matches!(
        psnr(a.view(), b.view(), 1.0),
        Err(HoloError::InvalidData(_))
    ));
    assert!(matches!(
        ssim(a.view(), b.view(), 1.0),
        Err(HoloError::InvalidData(_))
    ));
    b[[3, 4]] = f32::INFINITY;
    assert!(matches!(
        ssim(b.view(), a.view(), 1.0),
        Err(HoloError::InvalidData(_))
    ));
    for r in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        assert!(matches!(
            psnr(a.view(), a.view(), r),
            Err(HoloError::InvalidParameter {
                name: "data_range",
                ..
            })
        ));
        assert!(matches!(
            ssim(a.view(), a.view(), r),
            Err(HoloError::InvalidParameter {
                name: "data_range",
                ..
            })
        ));
    }
    let e = Array2::<f32>::zeros((0, 3));
    assert!(psnr(e.view(), e.view(), 1.0).is_err());
}

#[test]
fn multichannel_is_mean_of_channels() {
    let r = Array3::from_shape_fn((3, 14, 15), |(c, y, x)| {
        ((x * 7 + y * 3 + c * 5) % 11) as f32 / 10.0
    });
    let t = r.mapv(|v| 0.9 * v + 0.05)
        + Array3::from_shape_fn((3, 14, 15), |(c, y, x)| ((x * y + c) % 5) as f32 * 0.01);
    let per: f32 = (0..3)
        .map(|c| {
            ssim(
                r.index_axis(ndarray::Axis(0), c),
                t.index_axis(ndarray::Axis(0), c),
                1.0,
            )
            .unwrap()
        })
        .sum::<f32>()
        / 3.0;
    let all = ssim_multichannel(r.view(), t.view(), 1.0).unwrap();
    assert!((all - per).abs() < 1e-6);
}

fn image(h: usize, w: usize) -> impl Strategy<Value = Array2<f32>> {
    proptest::collection::vec(0.0f32..=1.0, h * w)
        .prop_map(move |v| Array2::from_shape_vec((h, w), v).unwrap())
}

fn image_and_noise() -> impl Strategy<Value = (Array2<f32>, Array2<f32>)> {
    (11usize..24, 11usize..24).prop_flat_map(|(h, w)| {
        (
            image(h, w),
            image(h, w).prop_map(|n| n.mapv(|v| 2.0 * v - 1.0)),
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn ssim_of_an_image_with_itself_is_one((x, _n) in image_and_noise()) {
        prop_assert_eq!(ssim(x.view(), x.view(), 1.0).unwrap(), 1.0);
        prop_assert_eq!(psnr(x.view(), x.view(), 1.0).unwrap(), f32::INFINITY);
    }

    #[test]
    fn psnr_and_ssim_are_symmetric((x, n) in image_and_noise()) {
        let y = &x + &n.mapv(|v| 0.1 * v);
        prop_assert_eq!(psnr(x.view(), y.view(), 1.0).unwrap(), psnr(y.view(), x.view(), 1.0).unwrap());
        let (a, b) = (ssim(x.view(), y.view(), 1.0).unwrap(), ssim(y.view(), x.view(), 1.0).unwrap());
        prop_assert!((a - b).abs() < 1e-6, "{} vs {}", a, b);
        prop_assert!((-1.0..=1.0).contains(&a));
    }

    #[test]
    fn more_noise_lowers_ssim_and_psnr((x, n) in image_and_noise()) {
        let noisy = |s: f32| &x + &n.mapv(|v| s * v);
        let (y1, y2, y3) = (noisy(0.02), noisy(0.1), noisy(0.3));
        let s1 = ssim(x.view(), y1.view(), 1.0).unwrap();
        let s2 = ssim(x.view(), y2.view(), 1.0).unwrap();
        let s3 = ssim(x.view(), y3.view(), 1.0).unwrap();
        prop_assert!(1.0 > s1 && s1 > s2 && s2 > s3, "{} {} {}", s1, s2, s3);
        let p1 = psnr(x.view(), y1.view(), 1.0).unwrap();
        let p2 = psnr(x.view(), y2.view(), 1.0).unwrap();
        prop_assert!(p1 > p2);
    }
}
