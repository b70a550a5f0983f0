//! Every available kernel row against the reference; row bands; the zero border; dispatch; errors.

use super::f32::Conv3x3F32;
use super::inputs::Inputs;
use super::reference::{self, RefU8Params};
use super::registry::{self, Algorithm};
use super::table;
use super::u8s8::{Conv3x3U8, Conv3x3U8Spec};
use crate::buffer::planar::RowPlanar;
use crate::error::KernelError;
use crate::isa::Isa;
use crate::quant::QuantU8;
use crate::test_rng::Rng;

/// f32 rows this CPU can run; prints the ones it skips.
pub(crate) fn f32_rows() -> Vec<&'static str> {
    let mut names = Vec::new();
    for r in table::f32_rows() {
        if r.info.is_available() {
            names.push(r.info.name);
        } else {
            println!("SKIPPED {}: this CPU lacks {}", r.info.name, r.info.isa);
        }
    }
    names
}

#[derive(Clone, Copy, Debug)]
struct Case {
    ca: usize,
    cb: usize,
    cout: usize,
    h: usize,
    w: usize,
    relu: bool,
    residual: bool,
    planar: bool,
}

/// The reference output of each `(c_a, c_b, c_out, h, w, relu, residual, seed)` this test thread has met.
type RefKey = (usize, usize, usize, usize, usize, bool, bool, u64);
thread_local! {
    static REFERENCES: std::cell::RefCell<std::collections::HashMap<RefKey, std::rc::Rc<reference::RefF32>>> =
        std::cell::RefCell::new(std::collections::HashMap::new());
}

/// Runs `row` on `case` (whole frame) and compares with the reference within 1e-5 of Σ|w·x|; checks the
/// border. Returns the output (planar) for further comparisons.
fn check_f32(row: &str, case: Case, seed: u64) -> Vec<f32> {
    let Case {
        ca,
        cb,
        cout,
        h,
        w,
        relu,
        residual,
        planar,
    } = case;
    let mut rng = Rng::new(seed);
    let cin = ca + cb;
    let a = rng.vec(ca * h * w);
    let b = rng.vec(cb * h * w);
    let wt = rng.vec(cout * cin * 9);
    let bias = rng.vec(cout);
    let res = rng.vec(cout * h * w);
    // The reference depends on the case and the seed only, not on the row: computed once for every row (in
    // f64 with the Winograd magnitudes, it dominated this suite under qemu-aarch64 in CI).
    let key = (ca, cb, cout, h, w, relu, residual, seed);
    let want = REFERENCES.with(|cache| {
        std::rc::Rc::clone(cache.borrow_mut().entry(key).or_insert_with(|| {
            std::rc::Rc::new(reference::conv_f32(
                &a,
                ca,
                &b,
                cb,
                h,
                w,
                &wt,
                &bias,
                cout,
                relu,
                residual.then_some(&res[..]),
            ))
        }))
    });
    let plan = Conv3x3F32::with_kernel(&wt, &bias, cin, cout, relu, row).unwrap();
    assert_eq!(plan.kernel().name, row);
    let ba = RowPlanar::from_planar(&a, ca, h, w, None).unwrap();
    let bb = (cb > 0).then(|| RowPlanar::from_planar(&b, cb, h, w, None).unwrap());
    let br = RowPlanar::from_planar(&res, cout, h, w, None).unwrap();
    let mut inputs = Inputs::new(&ba);
    if let Some(bb) = &bb {
        inputs = inputs.concat(bb);
    }
    if residual {
        inputs = inputs.residual(&br);
    }
    let got = if planar {
        let mut out = vec![f32::NAN; cout * h * w];
        plan.run_planar(inputs, &mut out, 0..h).unwrap();
        out
    } else {
        let mut out = RowPlanar::new(cout, h, w).unwrap();
        plan.run(inputs, &mut out, 0..h).unwrap();
        assert!(out.border_is_clean(), "{row} {case:?}: border written");
        out.to_planar()
    };
    let algorithm = plan.kernel().algorithm;
    for (k, (&g, &r)) in got.iter().zip(&want.out).enumerate() {
        let tol = match algorithm {
            Algorithm::Direct => 1e-5 * want.mag[k] + 1e-30,
            Algorithm::Winograd2x2 => winograd_tolerance(cin, want.wino[k]),
            Algorithm::Winograd4x4 => winograd_tolerance(cin, want.wino4[k]),
        };
        assert!(
            ((g - r) as f64).abs() <= tol,
            "{row} {case:?}: value {k} (o {}, y {}, x {}) = {g}, reference {r}, tolerance {tol}",
            k / (h * w),
            k / w % h,
            k % w
        );
    }
    got
}

/// The error bound stated for Winograd F(2×2, 3×3) rows (kernels/README.md): `(C_in + 10)·u·scale`, `u` =
/// 2⁻²⁴ the unit roundoff and `scale` the reference's [`wino`](reference::RefF32::wino) magnitude (each
/// output value sums `16·C_in` products of transformed values after about 10 roundings in the transforms).
fn winograd_tolerance(cin: usize, scale: f64) -> f64 {
    (cin + 10) as f64 * f64::from(f32::EPSILON) / 2.0 * scale + 1e-30
}

const C_INS: [(usize, usize); 9] = [
    (4, 0),
    (6, 0),
    (8, 0),
    (14, 0),
    (20, 0),
    (24, 0),
    (28, 0),
    (24, 4),
    (8, 6),
];
const C_OUTS: [usize; 3] = [6, 8, 24];
const HS: [usize; 4] = [1, 2, 3, 7];
const WS: [usize; 12] = [1, 5, 7, 11, 15, 16, 17, 33, 47, 48, 49, 53];

#[test]
fn f32_rows_match_reference_on_layer_shapes() {
    let mut n = 0;
    for row in f32_rows() {
        for (i, &(ca, cb)) in C_INS.iter().enumerate() {
            for (j, &cout) in C_OUTS.iter().enumerate() {
                for (k, &h) in HS.iter().enumerate() {
                    let idx = i * 12 + j * 4 + k;
                    let case = Case {
                        ca,
                        cb,
                        cout,
                        h,
                        w: WS[idx % WS.len()],
                        relu: idx % 2 == 0,
                        residual: (idx / 2) % 2 == 0,
                        planar: idx % 3 == 0,
                    };
                    check_f32(row, case, idx as u64);
                    n += 1;
                }
            }
        }
    }
    println!("{n} cases");
}

#[test]
fn f32_rows_match_reference_on_every_width_to_66() {
    for row in f32_rows() {
        for w in 1..=66 {
            for planar in [false, true] {
                let case = Case {
                    ca: 5,
                    cb: 3,
                    cout: 6,
                    h: 2,
                    w,
                    relu: true,
                    residual: true,
                    planar,
                };
                check_f32(row, case, w as u64);
            }
        }
    }
}

#[test]
fn f32_rows_agree_with_each_other_and_scalar() {
    // Not bit-exact (different summation order is allowed in f32), but close.
    let case = Case {
        ca: 24,
        cb: 0,
        cout: 24,
        h: 5,
        w: 41,
        relu: true,
        residual: true,
        planar: true,
    };
    let outs: Vec<Vec<f32>> = f32_rows().iter().map(|r| check_f32(r, case, 9)).collect();
    for o in &outs[1..] {
        for (a, b) in o.iter().zip(&outs[0]) {
            assert!((a - b).abs() <= 1e-4 * (1.0 + b.abs()));
        }
    }
}

#[test]
fn f32_row_bands_are_bit_identical_and_touch_only_their_rows() {
    let (ca, cb, cout, h, w) = (14, 0, 24, 7, 37);
    let mut rng = Rng::new(5);
    let a = RowPlanar::from_planar(&rng.vec(ca * h * w), ca, h, w, None).unwrap();
    let res = RowPlanar::from_planar(&rng.vec(cout * h * w), cout, h, w, None).unwrap();
    let wt = rng.vec(cout * (ca + cb) * 9);
    let bias = rng.vec(cout);
    for row in f32_rows() {
        let plan = Conv3x3F32::with_kernel(&wt, &bias, ca + cb, cout, true, row).unwrap();
        let inputs = Inputs::new(&a).residual(&res);
        let mut whole = RowPlanar::new(cout, h, w).unwrap();
        plan.run(inputs, &mut whole, 0..h).unwrap();
        let mut whole_planar = vec![0.0; cout * h * w];
        plan.run_planar(inputs, &mut whole_planar, 0..h).unwrap();
        for bands in [vec![0, 1, 3, 7], vec![0, 4, 5, 6, 7], vec![0, 2, 7]] {
            let sentinel = vec![7.5f32; cout * h * w];
            let mut out = RowPlanar::from_planar(&sentinel, cout, h, w, None).unwrap();
            let mut planar = sentinel.clone();
            for win in bands.windows(2) {
                // Before the band runs, its rows still hold the sentinel and the others are untouched.
                plan.run(inputs, &mut out, win[0]..win[1]).unwrap();
                plan.run_planar(inputs, &mut planar, win[0]..win[1])
                    .unwrap();
                let done = out.to_planar();
                for o in 0..cout {
                    for y in 0..h {
                        for x in 0..w {
                            let k = (o * h + y) * w + x;
                            let expect_done = y < win[1];
                            let want = if expect_done {
                                whole.to_planar()[k]
                            } else {
                                7.5
                            };
                            assert_eq!(done[k].to_bits(), want.to_bits(), "{row} bands {bands:?}");
                            let want_p = if expect_done { whole_planar[k] } else { 7.5 };
                            assert_eq!(
                                planar[k].to_bits(),
                                want_p.to_bits(),
                                "{row} planar bands {bands:?}"
                            );
                        }
                    }
                }
                assert!(out.border_is_clean());
            }
        }
    }
}

/// A layer with two sources and a residual: `a` (`ca` channels), `b` (`cb`), `res` (`cout`), all `h × w`,
/// and its weights `[cout][ca + cb][3][3]` and bias, random from `seed`.
struct TwoSources {
    a: RowPlanar<f32>,
    b: RowPlanar<f32>,
    res: RowPlanar<f32>,
    wt: Vec<f32>,
    bias: Vec<f32>,
}

impl TwoSources {
    fn new([ca, cb, cout, h, w]: [usize; 5], seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let mut planes =
            |c: usize| RowPlanar::from_planar(&rng.vec(c * h * w), c, h, w, None).unwrap();
        let (a, b, res) = (planes(ca), planes(cb), planes(cout));
        Self {
            a,
            b,
            res,
            wt: rng.vec(cout * (ca + cb) * 9),
            bias: rng.vec(cout),
        }
    }
}

#[test]
fn f32_column_ranges_give_the_whole_rows_bits_and_touch_only_their_columns() {
    // `run_band_columns` (a column slab's layers, each computing fewer columns than the one before): the
    // computed columns bit-identical with the whole row's run, the columns before the range untouched, those
    // after it untouched or zero within one tile of its end; ranges that start off a tile, are empty or run
    // past the row are errors. Two sources and a residual; the row wide enough for several tiles of every
    // row (64 pixels at most).
    let (ca, cb, cout, h, w) = (9, 5, 8, 9, 203);
    let TwoSources {
        a,
        b,
        res,
        wt,
        bias,
    } = TwoSources::new([ca, cb, cout, h, w], 11);
    let max_tile = crate::buffer::planar::MAX_TILE;
    for row in f32_rows() {
        let plan = Conv3x3F32::with_kernel(&wt, &bias, ca + cb, cout, true, row).unwrap();
        let g = plan.kernel().column_group();
        let inputs = Inputs::new(&a).concat(&b).residual(&res);
        let mut whole = RowPlanar::new(cout, h, w).unwrap();
        plan.run(inputs, &mut whole, 0..h).unwrap();
        let whole = whole.to_planar();
        for cols in [
            0..w,
            0..17,
            4..w,
            8..150,
            64..129,
            12..13,
            196..203,
            132..200,
        ] {
            let sentinel = vec![7.5f32; cout * h * w];
            let mut out = RowPlanar::from_planar(&sentinel, cout, h, w, None).unwrap();
            for rows in [0..3, 3..h] {
                let mut band = out.band_mut(rows).unwrap();
                plan.run_band_columns(inputs, &mut band, cols.clone())
                    .unwrap();
            }
            let got = out.to_planar();
            for o in 0..cout {
                for y in 0..h {
                    for x in 0..w {
                        let k = (o * h + y) * w + x;
                        let v = got[k];
                        let at =
                            format!("{row} columns {cols:?}: channel {o}, row {y}, column {x}");
                        if cols.contains(&x) {
                            assert_eq!(v.to_bits(), whole[k].to_bits(), "{at}");
                        } else if x >= cols.end && x < cols.end + max_tile {
                            assert!(v == 7.5 || v.to_bits() == 0, "{at}: {v}");
                        } else {
                            assert_eq!(v, 7.5, "{at}");
                        }
                    }
                }
            }
            assert!(out.border_is_clean());
        }
        let mut out = RowPlanar::new(cout, h, w).unwrap();
        let mut band = out.band_mut(0..h).unwrap();
        let mut bad = vec![3..3, 0..w + 1, 200..w + 4];
        if g > 1 {
            bad.push(1..40);
            bad.push(g + 1..w);
        }
        for cols in bad {
            let e = plan.run_band_columns(inputs, &mut band, cols.clone());
            assert!(
                matches!(e, Err(KernelError::Shape { .. })),
                "{row} {cols:?}: {e:?}"
            );
        }
    }
}

#[test]
fn f32_bands_written_by_threads_equal_one_run() {
    // Every split of the rows into `bands_mut(n)` (n past H included), each band run on its own thread,
    // gives the bit-identical buffer of one whole-frame run, borders clean; `band_mut` refuses bad bands.
    let (ca, cb, cout, h, w) = (5, 3, 9, 5, 29);
    let TwoSources {
        a,
        b,
        res,
        wt,
        bias,
    } = TwoSources::new([ca, cb, cout, h, w], 11);
    for row in f32_rows() {
        let plan = Conv3x3F32::with_kernel(&wt, &bias, ca + cb, cout, true, row).unwrap();
        let inputs = Inputs::new(&a).concat(&b).residual(&res);
        let mut whole = RowPlanar::new(cout, h, w).unwrap();
        plan.run(inputs, &mut whole, 0..h).unwrap();
        for n in 1..=h + 2 {
            let mut out = RowPlanar::new(cout, h, w).unwrap();
            let bands = out.bands_mut(n);
            assert_eq!(bands.len(), n.min(h));
            let covered: Vec<usize> = bands.iter().flat_map(|b| b.rows()).collect();
            assert_eq!(covered, (0..h).collect::<Vec<_>>());
            std::thread::scope(|s| {
                for mut band in bands {
                    let plan = &plan;
                    s.spawn(move || plan.run_band(inputs, &mut band).unwrap());
                }
            });
            assert!(out == whole, "{row}: {n} bands");
            assert!(out.border_is_clean());
        }
        // split_at: both halves run separately give the same buffer; rows outside are refused.
        for y in 1..h {
            let mut out = RowPlanar::new(cout, h, w).unwrap();
            let band = out.band_mut(0..h).unwrap();
            let (mut top, mut bottom) = band.split_at(y).unwrap();
            assert_eq!((top.rows(), bottom.rows()), (0..y, y..h));
            plan.run_band(inputs, &mut bottom).unwrap();
            plan.run_band(inputs, &mut top).unwrap();
            assert!(out == whole, "{row}: split at {y}");
        }
        let mut out = RowPlanar::new(cout, h, w).unwrap();
        let band = out.band_mut(1..3).unwrap();
        assert!(matches!(band.split_at(1), Err(KernelError::Rows { .. })));
        let band = out.band_mut(1..3).unwrap();
        assert!(matches!(band.split_at(3), Err(KernelError::Rows { .. })));
        assert!(matches!(out.band_mut(2..2), Err(KernelError::Rows { .. })));
        assert!(matches!(
            out.band_mut(3..h + 1),
            Err(KernelError::Rows { .. })
        ));
        let mut other = RowPlanar::new(cout + 1, h, w).unwrap();
        let mut band = other.band_mut(0..h).unwrap();
        assert!(matches!(
            plan.run_band(inputs, &mut band),
            Err(KernelError::Shape { .. })
        ));
    }
}

#[test]
fn dispatch_selects_the_named_row_and_refuses_unavailable_isas() {
    #[cfg(target_arch = "x86_64")]
    let expected = [
        (Isa::Scalar, "conv3x3.f32.8x8.scalar"),
        (Isa::Avx2Fma, "conv3x3.f32.6x2.avx2"),
        (Isa::AvxVnni, "conv3x3.f32.6x2.avx2"),
        (Isa::Avx512, "conv3x3.f32.8x3.avx512"),
        (Isa::Avx512Vnni, "conv3x3.f32.8x3.avx512"),
    ];
    #[cfg(target_arch = "aarch64")]
    let expected = [
        (Isa::Scalar, "conv3x3.f32.8x8.scalar"),
        (Isa::Neon, "conv3x3.f32.8x3.neon"),
        (Isa::NeonDot, "conv3x3.f32.8x3.neon"),
        (Isa::NeonI8mm, "conv3x3.f32.8x3.neon"),
    ];
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let expected = [(Isa::Scalar, "conv3x3.f32.8x8.scalar")];
    let wt = vec![0.5; 8 * 4 * 9];
    // Per layer width: the row with the least output-channel padding, the better row on a tie; never the
    // scalar row under a vector level.
    #[cfg(target_arch = "x86_64")]
    let by_width = [
        (Isa::Avx512, 24, "conv3x3.f32.8x3.avx512"),
        (Isa::Avx512, 8, "conv3x3.f32.8x3.avx512"),
        (Isa::Avx512, 6, "conv3x3.f32.6x4.avx512"),
        (Isa::Avx2Fma, 8, "conv3x3.f32.6x2.avx2"),
        (Isa::Avx2Fma, 6, "conv3x3.f32.6x2.avx2"),
        (Isa::Scalar, 6, "conv3x3.f32.8x8.scalar"),
    ];
    #[cfg(target_arch = "aarch64")]
    let by_width = [
        (Isa::Neon, 6, "conv3x3.f32.8x3.neon"),
        (Isa::Scalar, 6, "conv3x3.f32.8x8.scalar"),
    ];
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let by_width = [(Isa::Scalar, 6, "conv3x3.f32.8x8.scalar")];
    for (isa, c_out, name) in by_width {
        assert_eq!(
            registry::selected_f32_for(isa, c_out).name,
            name,
            "{isa} {c_out}"
        );
        // The rows a plan may time: the selected one first, each once, of the algorithm, none a test row,
        // no scalar row under a vector level, every one under `isa`.
        for alg in [
            Algorithm::Direct,
            Algorithm::Winograd2x2,
            Algorithm::Winograd4x4,
        ] {
            let rows: Vec<_> = registry::f32_rows_of(isa, c_out, alg).collect();
            assert_eq!(
                rows[0].name,
                registry::selected_f32_algorithm(isa, c_out, alg).name
            );
            for (i, r) in rows.iter().enumerate() {
                assert_eq!(r.algorithm, alg, "{}", r.name);
                assert!(isa.includes(r.isa), "{isa}: {}", r.name);
                assert!(!r.name.starts_with("test."), "{}", r.name);
                assert!(
                    r.isa != Isa::Scalar || isa == Isa::Scalar,
                    "{isa}: {}",
                    r.name
                );
                assert!(rows[..i].iter().all(|o| o.name != r.name), "{}", r.name);
            }
        }
    }
    // Under AVX-512 a 6-channel layer may time all three tiles (the 6-channel AVX-512 one first).
    #[cfg(target_arch = "x86_64")]
    assert_eq!(
        registry::f32_rows_of(Isa::Avx512, 6, Algorithm::Direct)
            .map(|r| r.name)
            .collect::<Vec<_>>(),
        [
            "conv3x3.f32.6x4.avx512",
            "conv3x3.f32.8x3.avx512",
            "conv3x3.f32.6x2.avx2"
        ]
    );
    for (isa, name) in expected {
        assert_eq!(registry::selected_f32(isa).name, name);
        let from_name = Isa::from_name(isa.name());
        let plan = Conv3x3F32::new(&wt, &[0.0; 8], 4, 8, false, isa);
        if isa.is_available() {
            assert_eq!(from_name, Ok(isa));
            assert_eq!(plan.unwrap().kernel().name, name, "forced {isa}");
            println!("{isa}: available, selects {name}");
        } else {
            assert!(
                matches!(from_name, Err(KernelError::Isa { .. })),
                "{isa} should be refused"
            );
            assert!(matches!(plan, Err(KernelError::Isa { .. })));
            assert!(
                matches!(
                    Conv3x3F32::with_kernel(&wt, &[0.0; 8], 4, 8, false, name),
                    Err(KernelError::Kernel { .. })
                ) || registry::f32_kernels().any(|k| k.name == name && k.is_available())
            );
            println!("{isa}: not available on this CPU, refused");
        }
    }
    assert!(Isa::from_name("scalar").is_ok());
    assert!(matches!(
        Isa::from_name("sse9"),
        Err(KernelError::Isa { .. })
    ));
    let best = Isa::detect();
    assert!(best.is_available());
    for isa in Isa::available() {
        assert!(best.includes(isa) || isa == Isa::Scalar || !isa.includes(best));
    }
    assert!(matches!(
        Conv3x3F32::with_kernel(&wt, &[0.0; 8], 4, 8, false, "nope"),
        Err(KernelError::Kernel { .. })
    ));
}

#[test]
fn f32_bad_input_is_an_error_not_a_panic() {
    let wt = vec![0.1; 8 * 4 * 9];
    let plan = Conv3x3F32::new(&wt, &[0.0; 8], 4, 8, true, Isa::Scalar).unwrap();
    let a = RowPlanar::new(4, 3, 5).unwrap();
    let a6 = RowPlanar::new(6, 3, 5).unwrap();
    let small = RowPlanar::new(4, 3, 4).unwrap();
    let mut out = RowPlanar::new(8, 3, 5).unwrap();
    let mut out6 = RowPlanar::new(6, 3, 5).unwrap();
    assert!(matches!(
        plan.run(Inputs::new(&a6), &mut out, 0..3),
        Err(KernelError::Shape { .. })
    ));
    assert!(matches!(
        plan.run(Inputs::new(&a).concat(&a), &mut out, 0..3),
        Err(KernelError::Shape { .. })
    ));
    assert!(matches!(
        plan.run(Inputs::new(&small), &mut out, 0..3),
        Err(KernelError::Shape { .. })
    ));
    assert!(matches!(
        plan.run(Inputs::new(&a), &mut out6, 0..3),
        Err(KernelError::Shape { .. })
    ));
    assert!(matches!(
        plan.run(Inputs::new(&a).residual(&a), &mut out, 0..3),
        Err(KernelError::Shape { .. })
    ));
    assert!(matches!(
        plan.run(Inputs::new(&a), &mut out, 0..4),
        Err(KernelError::Rows { .. })
    ));
    #[allow(clippy::reversed_empty_ranges)]
    let reversed = 2..1;
    assert!(matches!(
        plan.run(Inputs::new(&a), &mut out, reversed),
        Err(KernelError::Rows { .. })
    ));
    assert!(matches!(
        plan.run(Inputs::new(&a), &mut out, 1..1),
        Err(KernelError::Rows { .. })
    ));
    let mut planar = vec![0.0; 8 * 3 * 5 - 1];
    assert!(matches!(
        plan.run_planar(Inputs::new(&a), &mut planar, 0..3),
        Err(KernelError::Length { .. })
    ));
    assert!(matches!(
        Conv3x3F32::new(&wt[1..], &[0.0; 8], 4, 8, true, Isa::Scalar),
        Err(KernelError::Length { .. })
    ));
    assert!(matches!(
        Conv3x3F32::new(&wt, &[0.0; 7], 4, 8, true, Isa::Scalar),
        Err(KernelError::Length { .. })
    ));
    assert!(matches!(
        Conv3x3F32::new(&[], &[], 0, 8, true, Isa::Scalar),
        Err(KernelError::Dimension { .. })
    ));
    assert!(plan.run(Inputs::new(&a), &mut out, 0..3).is_ok());
}

/// int8 rows this CPU can run; prints the ones it skips.
pub(crate) fn u8_rows() -> Vec<&'static str> {
    let mut names = Vec::new();
    for r in table::u8_rows() {
        if r.info.is_available() {
            names.push(r.info.name);
        } else {
            println!("SKIPPED {}: this CPU lacks {}", r.info.name, r.info.isa);
        }
    }
    names
}

#[derive(Clone, Copy, Debug)]
struct QCase {
    ca: usize,
    cb: usize,
    cout: usize,
    h: usize,
    w: usize,
    relu: bool,
    residual: bool,
    u8_out: bool,
}

/// Random u8 data, weights over the whole s8 range, zero points ≠ 0 (different per buffer).
struct QData {
    a: Vec<u8>,
    b: Vec<u8>,
    r: Vec<u8>,
    wt: Vec<i8>,
    wscale: Vec<f32>,
    bias: Vec<f32>,
    zp: [u8; 4],
}

fn qdata(case: QCase, seed: u64) -> QData {
    let QCase {
        ca, cb, cout, h, w, ..
    } = case;
    let mut rng = Rng::new(seed);
    let mut bytes = |n: usize| {
        (0..n)
            .map(|_| (rng.next() >> 56) as u8)
            .collect::<Vec<u8>>()
    };
    let a = bytes(ca * h * w);
    let b = bytes(cb * h * w);
    let r = bytes(cout * h * w);
    let wt = bytes(cout * (ca + cb) * 9)
        .into_iter()
        .map(|v| v as i8)
        .collect();
    let z = bytes(4);
    let zp = [z[0] | 1, z[1] | 2, z[2], z[3] | 4];
    let mut rng = Rng::new(seed ^ 0xABCD);
    let wscale = (0..cout).map(|_| (1.0 + 0.5 * rng.f()) * 0.002).collect();
    let bias = rng.vec(cout);
    QData {
        a,
        b,
        r,
        wt,
        wscale,
        bias,
        zp,
    }
}

const IN_SCALE: f32 = 1.0 / 255.0;
const RES_SCALE: f32 = 0.02;
const OUT_SCALE: f32 = 0.01;

fn spec<'a>(case: QCase, d: &'a QData) -> Conv3x3U8Spec<'a> {
    Conv3x3U8Spec {
        weights: &d.wt,
        weight_scales: &d.wscale,
        bias: &d.bias,
        c_in_a: case.ca,
        c_in_b: case.cb,
        c_out: case.cout,
        input_scale: IN_SCALE,
        input_zero_point_a: d.zp[0],
        input_zero_point_b: d.zp[1],
        relu: case.relu,
        residual: case.residual.then_some(QuantU8 {
            scale: RES_SCALE,
            zero_point: d.zp[2],
        }),
        output: case.u8_out.then_some(QuantU8 {
            scale: OUT_SCALE,
            zero_point: d.zp[3],
        }),
    }
}

/// Runs `row` on `case` and requires bit-exact agreement with the reference; checks the border. Returns the
/// output (planar f32; u8 values as integers).
fn check_u8_data(row: &str, case: QCase, d: &QData) -> Vec<f32> {
    let QCase {
        ca,
        cb,
        cout,
        h,
        w,
        relu,
        residual,
        u8_out,
    } = case;
    let sp = spec(case, d);
    let plan = Conv3x3U8::with_kernel(&sp, row).unwrap();
    assert_eq!(plan.kernel().name, row);
    let mult: Vec<f32> = d.wscale.iter().map(|s| IN_SCALE * s).collect();
    let params = RefU8Params {
        weights: &d.wt,
        mult: &mult,
        bias: &d.bias,
        zp_a: d.zp[0],
        zp_b: d.zp[1],
        relu,
        residual: residual.then_some((&d.r[..], d.zp[2], RES_SCALE)),
        output: u8_out.then_some((1.0 / OUT_SCALE, d.zp[3])),
    };
    let want = reference::conv_u8(&d.a, ca, &d.b, cb, h, w, cout, &params);
    let ba = RowPlanar::from_planar_u8(&d.a, ca, h, w, d.zp[0]).unwrap();
    let bb = (cb > 0).then(|| RowPlanar::from_planar_u8(&d.b, cb, h, w, d.zp[1]).unwrap());
    let br = RowPlanar::from_planar_u8(&d.r, cout, h, w, d.zp[2]).unwrap();
    let mut inputs = Inputs::new(&ba);
    if let Some(bb) = &bb {
        inputs = inputs.concat(bb);
    }
    if residual {
        inputs = inputs.residual(&br);
    }
    let got: Vec<f32> = if u8_out {
        let mut out = RowPlanar::new_quantized(cout, h, w, d.zp[3]).unwrap();
        plan.run(inputs, &mut out, 0..h).unwrap();
        assert!(
            out.border_is_clean(),
            "{row} {case:?}: border or padding channels not the zero point"
        );
        out.to_planar().into_iter().map(f32::from).collect()
    } else {
        let mut out = vec![f32::NAN; cout * h * w];
        plan.run_planar(inputs, &mut out, 0..h).unwrap();
        out
    };
    for (k, (&g, &r)) in got.iter().zip(&want).enumerate() {
        assert!(
            g.to_bits() == r.to_bits() || (g == 0.0 && r == 0.0),
            "{row} {case:?}: value {k} (o {}, y {}, x {}) = {g}, reference {r}",
            k / (h * w),
            k / w % h,
            k % w
        );
    }
    got
}

fn check_u8(row: &str, case: QCase, seed: u64) -> Vec<f32> {
    check_u8_data(row, case, &qdata(case, seed))
}

#[test]
fn u8_rows_bit_exact_with_reference_on_layer_shapes() {
    let mut n = 0;
    for row in u8_rows() {
        for (i, &(ca, cb)) in C_INS.iter().enumerate() {
            for (j, &cout) in C_OUTS.iter().enumerate() {
                for (k, &h) in HS.iter().enumerate() {
                    let idx = i * 12 + j * 4 + k;
                    let case = QCase {
                        ca,
                        cb,
                        cout,
                        h,
                        w: WS[(idx + 5) % WS.len()],
                        relu: idx % 2 == 1,
                        residual: (idx / 2) % 2 == 1,
                        u8_out: idx % 3 != 0,
                    };
                    check_u8(row, case, idx as u64 + 100);
                    n += 1;
                }
            }
        }
    }
    println!("{n} cases");
}

#[test]
fn u8_rows_bit_exact_on_every_width_to_66() {
    for row in u8_rows() {
        for w in 1..=66 {
            for u8_out in [false, true] {
                let case = QCase {
                    ca: 5,
                    cb: 3,
                    cout: 6,
                    h: 2,
                    w,
                    relu: true,
                    residual: true,
                    u8_out,
                };
                check_u8(row, case, w as u64);
            }
        }
    }
}

#[test]
fn u8_rows_do_not_saturate_at_extreme_values() {
    // 255 × 127 (and × −128) summed over 28·9 taps: 8.2 M, far beyond i16; zero points 0 and 255.
    let (ca, cb, cout, h, w) = (24, 4, 8, 3, 19);
    for (x, wv, zp) in [
        (255u8, 127i8, 0u8),
        (255, -128, 0),
        (0, -128, 255),
        (255, 127, 255),
    ] {
        let case = QCase {
            ca,
            cb,
            cout,
            h,
            w,
            relu: false,
            residual: false,
            u8_out: false,
        };
        let mut d = qdata(case, 1);
        d.a.fill(x);
        d.b.fill(x);
        d.wt.fill(wv);
        d.zp = [zp, zp, 0, 0];
        for row in u8_rows() {
            let got = check_u8_data(row, case, &d);
            assert!(
                got.iter().any(|&v| v != got[0]) || x == zp,
                "{row}: border pixels must differ"
            );
        }
    }
}

#[test]
fn u8_rows_agree_with_scalar_bit_exactly() {
    let case = QCase {
        ca: 24,
        cb: 0,
        cout: 24,
        h: 5,
        w: 53,
        relu: true,
        residual: true,
        u8_out: true,
    };
    let outs: Vec<Vec<f32>> = u8_rows().iter().map(|r| check_u8(r, case, 77)).collect();
    let scalar = outs.last().unwrap();
    for o in &outs {
        assert_eq!(o, scalar);
    }
}

#[test]
fn u8_row_bands_are_bit_identical_and_touch_only_their_rows() {
    let case = QCase {
        ca: 14,
        cb: 0,
        cout: 24,
        h: 7,
        w: 37,
        relu: true,
        residual: true,
        u8_out: true,
    };
    let d = qdata(case, 3);
    let sp = spec(case, &d);
    let (h, w, cout) = (case.h, case.w, case.cout);
    let a = RowPlanar::from_planar_u8(&d.a, case.ca, h, w, d.zp[0]).unwrap();
    let r = RowPlanar::from_planar_u8(&d.r, cout, h, w, d.zp[2]).unwrap();
    for row in u8_rows() {
        let plan = Conv3x3U8::with_kernel(&sp, row).unwrap();
        let inputs = Inputs::new(&a).residual(&r);
        let mut whole = RowPlanar::new_quantized(cout, h, w, d.zp[3]).unwrap();
        plan.run(inputs, &mut whole, 0..h).unwrap();
        let whole = whole.to_planar();
        let mut whole_f = vec![0.0; cout * h * w];
        plan.run_planar(inputs, &mut whole_f, 0..h).unwrap();
        for bands in [vec![0, 1, 3, 7], vec![0, 5, 6, 7]] {
            let sentinel = vec![201u8; cout * h * w];
            let mut out = RowPlanar::from_planar_u8(&sentinel, cout, h, w, d.zp[3]).unwrap();
            let mut planar = vec![7.5f32; cout * h * w];
            for win in bands.windows(2) {
                plan.run(inputs, &mut out, win[0]..win[1]).unwrap();
                plan.run_planar(inputs, &mut planar, win[0]..win[1])
                    .unwrap();
                let done = out.to_planar();
                for k in 0..cout * h * w {
                    let in_done = (k / w) % h < win[1];
                    assert_eq!(
                        done[k],
                        if in_done { whole[k] } else { 201 },
                        "{row} {bands:?}"
                    );
                    let want = if in_done { whole_f[k] } else { 7.5 };
                    assert_eq!(planar[k].to_bits(), want.to_bits(), "{row} {bands:?}");
                }
                assert!(out.border_is_clean());
            }
            // The same bands as raw f32 rows `[rows][C_out][W]`, each written into its own slice (what
            // threads do): the whole planar run, transposed, bit for bit.
            let mut rows_f = vec![7.5f32; h * cout * w];
            let mut rest = &mut rows_f[..];
            for win in bands.windows(2) {
                let (band, tail) = rest.split_at_mut((win[1] - win[0]) * cout * w);
                plan.run_rows_f32(inputs, band, win[0]..win[1]).unwrap();
                rest = tail;
            }
            for o in 0..cout {
                for y in 0..h {
                    for x in 0..w {
                        let (got, want) =
                            (rows_f[(y * cout + o) * w + x], whole_f[(o * h + y) * w + x]);
                        assert_eq!(
                            got.to_bits(),
                            want.to_bits(),
                            "{row} {bands:?} ({o}, {y}, {x})"
                        );
                    }
                }
            }
        }
        // A slice that is not the band's `rows·C_out·W` is refused.
        let mut short = vec![0.0f32; (2 * cout - 1) * w];
        assert!(matches!(
            plan.run_rows_f32(inputs, &mut short, 0..2),
            Err(crate::error::KernelError::Length { .. })
        ));
    }
}

#[test]
fn u8_bands_written_by_threads_equal_one_run() {
    // Every split into `bands_mut(n)`, each band on its own thread, gives the bit-identical buffer of one
    // whole-frame run; a band of a buffer with another zero point is refused.
    let case = QCase {
        ca: 24,
        cb: 0,
        cout: 24,
        h: 9,
        w: 29,
        relu: true,
        residual: true,
        u8_out: true,
    };
    let d = qdata(case, 11);
    let sp = spec(case, &d);
    let (h, w, cout) = (case.h, case.w, case.cout);
    let a = RowPlanar::from_planar_u8(&d.a, case.ca, h, w, d.zp[0]).unwrap();
    let r = RowPlanar::from_planar_u8(&d.r, cout, h, w, d.zp[2]).unwrap();
    for row in u8_rows() {
        let plan = &Conv3x3U8::with_kernel(&sp, row).unwrap();
        let inputs = Inputs::new(&a).residual(&r);
        let mut whole = RowPlanar::new_quantized(cout, h, w, d.zp[3]).unwrap();
        plan.run(inputs, &mut whole, 0..h).unwrap();
        for n in [1, 2, 3, 5, h + 2] {
            let mut out = RowPlanar::new_quantized(cout, h, w, d.zp[3]).unwrap();
            std::thread::scope(|s| {
                for mut band in out.bands_mut(n) {
                    s.spawn(move || plan.run_band(inputs, &mut band).unwrap());
                }
            });
            assert!(out == whole, "{row}: {n} bands");
            assert!(out.border_is_clean());
        }
        let mut other = RowPlanar::new_quantized(cout, h, w, d.zp[3] ^ 1).unwrap();
        let mut band = other.band_mut(0..h).unwrap();
        assert!(matches!(
            plan.run_band(inputs, &mut band),
            Err(KernelError::Shape { .. })
        ));
    }
}

#[test]
fn a_reused_u8_buffer_takes_a_new_zero_point() {
    // A buffer that held another layer's output (zero point 9), moved to zero point 200, gives the same
    // convolution output as a fresh buffer, and its border is clean; 6 channels leave 2 padding channels.
    let case = QCase {
        ca: 6,
        cb: 0,
        cout: 6,
        h: 5,
        w: 13,
        relu: false,
        residual: false,
        u8_out: true,
    };
    let mut d = qdata(case, 5);
    d.zp[3] = 200;
    let sp = spec(case, &d);
    let a = RowPlanar::from_planar_u8(&d.a, 6, 5, 13, d.zp[0]).unwrap();
    let plan = Conv3x3U8::new(&sp, Isa::detect()).unwrap();
    let mut fresh = RowPlanar::new_quantized(6, 5, 13, 200).unwrap();
    plan.run(Inputs::new(&a), &mut fresh, 0..5).unwrap();
    let old: Vec<u8> = (0..6 * 5 * 13).map(|i| (i * 7 % 251) as u8).collect();
    let mut reused = RowPlanar::from_planar_u8(&old, 6, 5, 13, 9).unwrap();
    reused.set_zero_point(200);
    assert_eq!(reused.zero_point(), 200);
    assert!(reused.border_is_clean());
    plan.run(Inputs::new(&a), &mut reused, 0..5).unwrap();
    assert!(reused == fresh);
}

#[test]
fn quantize_fill_and_requantize_follow_onnx() {
    // ONNX QuantizeLinear: round half to even of x / scale, plus the zero point, saturated.
    let (c, h, w) = (5, 3, 4);
    let src: Vec<f32> = (0..c * h * w).map(|i| i as f32 * 0.0125 - 0.4).collect();
    let (offset, scale, zp) = (-0.1f32, 0.025f32, 17u8);
    let mut b = RowPlanar::new_quantized(c, h, w, zp).unwrap();
    b.quantize_fill(&src, offset, scale).unwrap();
    assert!(b.border_is_clean());
    let got = b.to_planar();
    for (i, (&x, &q)) in src.iter().zip(&got).enumerate() {
        let want = (((x + offset) / scale).round_ties_even() + zp as f32).clamp(0.0, 255.0) as u8;
        assert_eq!(q, want, "element {i}: {x}");
    }
    // Ties go to even: (x + offset) / scale = 2.5 exactly → 2.
    let mut t = RowPlanar::new_quantized(1, 1, 1, 0).unwrap();
    t.quantize_fill(&[0.0625], 0.0, 0.025).unwrap();
    assert_eq!(t.get(0, 0, 0), Some(2));
    // Requantising: dequantise with the source grid, quantise with the target's.
    let (scale2, zp2) = (0.04f32, 3u8);
    let mut r = RowPlanar::new_quantized(c, h, w, zp2).unwrap();
    r.requantize_from(&b, scale, scale2).unwrap();
    assert!(r.border_is_clean());
    for (&q, &q2) in got.iter().zip(&r.to_planar()) {
        let real = (q as f32 - zp as f32) * scale;
        let want = ((real / scale2).round_ties_even() + zp2 as f32).clamp(0.0, 255.0) as u8;
        assert_eq!(q2, want);
    }
    assert!(b.quantize_fill(&src[1..], 0.0, scale).is_err());
    assert!(b.quantize_fill(&src, 0.0, 0.0).is_err());
    let other = RowPlanar::new_quantized(c, h, w + 1, 0).unwrap();
    assert!(r.requantize_from(&other, scale, scale2).is_err());
    // The same two fills done band by band (one band per thread in the int8 engine) give the same buffers,
    // and a band writes only its own rows.
    for split in 1..h {
        let mut b2 = RowPlanar::new_quantized(c, h, w, zp).unwrap();
        let mut r2 = RowPlanar::new_quantized(c, h, w, zp2).unwrap();
        let (_top, mut bottom) = b2.band_mut(0..h).unwrap().split_at(split).unwrap();
        bottom.quantize_fill(&src, offset, scale).unwrap();
        assert!((0..c).all(|ch| (0..split).all(|y| (0..w).all(|x| b2.get(ch, y, x) == Some(zp)))));
        b2.band_mut(0..split)
            .unwrap()
            .quantize_fill(&src, offset, scale)
            .unwrap();
        assert_eq!(b2, b, "split at {split}");
        for mut band in r2.bands_mut(2) {
            band.requantize_from(&b2, scale, scale2).unwrap();
        }
        assert_eq!(r2, r, "split at {split}");
        assert!(r2.border_is_clean());
    }
    let mut band = b.band_mut(0..1).unwrap();
    assert!(matches!(
        band.quantize_fill(&src[1..], 0.0, scale),
        Err(KernelError::Length { .. })
    ));
}

#[test]
fn u8_dispatch_selects_the_named_row() {
    #[cfg(target_arch = "x86_64")]
    let expected = [
        (Isa::Scalar, "conv3x3.u8s8.8x8.scalar"),
        (Isa::Avx2Fma, "conv3x3.u8s8.4x1.avx2"),
        (Isa::AvxVnni, "conv3x3.u8s8.4x2.avxvnni"),
        (Isa::Avx512, "conv3x3.u8s8.4x1.avx2"),
        (Isa::Avx512Vnni, "conv3x3.u8s8.8x3.avx512vnni"),
    ];
    #[cfg(target_arch = "aarch64")]
    let expected = [
        (Isa::Scalar, "conv3x3.u8s8.8x8.scalar"),
        (Isa::Neon, "conv3x3.u8s8.4x1.neon"),
        (Isa::NeonDot, "conv3x3.u8s8.8x3.neondot"),
        (Isa::NeonI8mm, "conv3x3.u8s8.8x3.neoni8mm"),
    ];
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let expected = [(Isa::Scalar, "conv3x3.u8s8.8x8.scalar")];
    let case = QCase {
        ca: 4,
        cb: 0,
        cout: 8,
        h: 1,
        w: 1,
        relu: false,
        residual: false,
        u8_out: true,
    };
    let d = qdata(case, 0);
    for (isa, name) in expected {
        assert_eq!(registry::selected_u8(isa).name, name);
        let plan = Conv3x3U8::new(&spec(case, &d), isa);
        if isa.is_available() {
            assert_eq!(plan.unwrap().kernel().name, name);
            println!("{isa}: available, int8 selects {name}");
        } else {
            assert!(matches!(plan, Err(KernelError::Isa { .. })));
            println!("{isa}: not available on this CPU, refused");
        }
    }
}

#[test]
fn u8_bad_input_is_an_error_not_a_panic() {
    let case = QCase {
        ca: 4,
        cb: 0,
        cout: 8,
        h: 3,
        w: 5,
        relu: true,
        residual: false,
        u8_out: true,
    };
    let d = qdata(case, 0);
    let sp = spec(case, &d);
    let plan = Conv3x3U8::new(&sp, Isa::Scalar).unwrap();
    let a = RowPlanar::from_planar_u8(&d.a, 4, 3, 5, d.zp[0]).unwrap();
    let a_wrong_zp = RowPlanar::from_planar_u8(&d.a, 4, 3, 5, d.zp[0].wrapping_add(1)).unwrap();
    let mut out = RowPlanar::new_quantized(8, 3, 5, d.zp[3]).unwrap();
    let mut out_wrong_zp = RowPlanar::new_quantized(8, 3, 5, d.zp[3].wrapping_add(1)).unwrap();
    assert!(plan.run(Inputs::new(&a), &mut out, 0..3).is_ok());
    assert!(matches!(
        plan.run(Inputs::new(&a_wrong_zp), &mut out, 0..3),
        Err(KernelError::Shape { .. })
    ));
    assert!(matches!(
        plan.run(Inputs::new(&a), &mut out_wrong_zp, 0..3),
        Err(KernelError::Shape { .. })
    ));
    assert!(matches!(
        plan.run(Inputs::new(&a).residual(&out.clone()), &mut out, 0..3),
        Err(KernelError::Shape { .. })
    ));
    assert!(matches!(
        plan.run(Inputs::new(&a), &mut out, 2..9),
        Err(KernelError::Rows { .. })
    ));
    let mut planar = vec![0.0; 8 * 3 * 5 + 1];
    assert!(matches!(
        plan.run_planar(Inputs::new(&a), &mut planar, 0..3),
        Err(KernelError::Length { .. })
    ));
    let f32_plan = Conv3x3U8::new(&Conv3x3U8Spec { output: None, ..sp }, Isa::Scalar).unwrap();
    assert!(matches!(
        f32_plan.run(Inputs::new(&a), &mut out, 0..3),
        Err(KernelError::Shape { .. })
    ));
    let mut bad = sp;
    bad.input_scale = f32::NAN;
    assert!(matches!(
        Conv3x3U8::new(&bad, Isa::Scalar),
        Err(KernelError::Parameter { .. })
    ));
    let mut bad = sp;
    bad.weights = &d.wt[1..];
    assert!(matches!(
        Conv3x3U8::new(&bad, Isa::Scalar),
        Err(KernelError::Length { .. })
    ));
    let mut bad = sp;
    bad.weight_scales = &[0.0; 8];
    assert!(matches!(
        Conv3x3U8::new(&bad, Isa::Scalar),
        Err(KernelError::Parameter { .. })
    ));
    let wide = vec![0i8; 8 * 4097 * 9];
    let mut bad = sp;
    bad.weights = &wide;
    bad.c_in_a = 4097;
    assert!(matches!(
        Conv3x3U8::new(&bad, Isa::Scalar),
        Err(KernelError::Dimension { .. })
    ));
    let needs_res = Conv3x3U8::new(
        &Conv3x3U8Spec {
            residual: Some(QuantU8 {
                scale: 1.0,
                zero_point: 3,
            }),
            ..sp
        },
        Isa::Scalar,
    )
    .unwrap();
    assert!(matches!(
        needs_res.run(Inputs::new(&a), &mut out, 0..3),
        Err(KernelError::Shape { .. })
    ));
}

mod prop {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]
        #[test]
        fn f32_random_shapes(ca in 1usize..12, cb in 0usize..5, cout in 1usize..26, h in 1usize..5,
                             w in 1usize..70, relu: bool, residual: bool, planar: bool, seed: u64) {
            for row in f32_rows() {
                check_f32(row, Case { ca, cb, cout, h, w, relu, residual, planar }, seed);
            }
        }

        #[test]
        fn u8_random_shapes(ca in 1usize..12, cb in 0usize..7, cout in 1usize..26, h in 1usize..5,
                            w in 1usize..70, relu: bool, residual: bool, u8_out: bool, seed: u64) {
            for row in u8_rows() {
                check_u8(row, QCase { ca, cb, cout, h, w, relu, residual, u8_out }, seed);
            }
        }
    }
}

/// Frame rows `first..first + rows` of a planar `[c][h][w]` frame as a planar `[c][rows][w]` window; rows
/// outside the frame hold `pad` (the zero padding's value).
fn window_of<T: Copy>(
    frame: &[T],
    c: usize,
    h: usize,
    w: usize,
    first: isize,
    rows: usize,
    pad: T,
) -> Vec<T> {
    let mut out = vec![pad; c * rows * w];
    for ch in 0..c {
        for i in 0..rows {
            let f = first + i as isize;
            if (0..h as isize).contains(&f) {
                let src = (ch * h + f as usize) * w;
                out[(ch * rows + i) * w..(ch * rows + i + 1) * w]
                    .copy_from_slice(&frame[src..src + w]);
            }
        }
    }
    out
}

/// Output rows `f0..f1` and, for the output, `a`, `b` and the residual, `(first frame row, interior rows)`.
type WindowCase = (usize, usize, [(isize, usize); 4]);

/// Window layouts for [`Inputs::shifted`] tests on a frame of `h` rows: output rows `f0..f1`, and for the
/// output and each operand the frame row of its interior row 0 and its height (operands hold the rows the
/// band reads and a few more, on either side; the output window starts earlier than the band). For rows whose
/// tiles span `group` = 4 rows ([`KernelInfo::row_group`](crate::KernelInfo::row_group)): bands that start at a
/// group, the sources holding the rows to one past the last group's end (frame rows past the frame included,
/// as the SDK's strips hold them).
fn window_cases(h: usize, group: usize) -> Vec<WindowCase> {
    let mut cases = Vec::new();
    let mut rng = Rng::new(77);
    let bands: &[(usize, usize)] = if group == 1 {
        &[(0, h), (0, 3), (4, 9), (h - 2, h), (5, 6)]
    } else {
        &[(0, h), (0, 4), (4, 12), (8, h), (4, 9), (12, h), (0, 1)]
    };
    for &(f0, f1) in bands {
        let below = (f1 - f0).div_ceil(group) * group + f0 - f1 + 1;
        // Interior rows: frame rows `f0 − above − before .. f1 + below + after`.
        let mut pick = |above: isize, below: isize| {
            let before = (rng.next() % 3) as isize;
            let after = (rng.next() % 3) as isize;
            let first = f0 as isize - above - before;
            (first, (f1 as isize + below + after - first) as usize)
        };
        let out = pick(0, 0);
        let a = pick(1, below as isize);
        let b = pick(1, below as isize);
        let r = pick(0, 0);
        cases.push((f0, f1, [out, a, b, r]));
    }
    cases
}

#[test]
fn f32_shifted_windows_equal_the_whole_frame() {
    // A layer computed on windows (each buffer holding other frame rows, rows outside the frame zero) writes
    // the bit-identical rows of the whole-frame run, for every row, with a concat and a residual; a window
    // that misses a row the band reads is refused.
    let (ca, cb, cout, h, w) = (14, 4, 24, 13, 37);
    let mut rng = Rng::new(9);
    let (fa, fb, fr) = (
        rng.vec(ca * h * w),
        rng.vec(cb * h * w),
        rng.vec(cout * h * w),
    );
    let wt = rng.vec(cout * (ca + cb) * 9);
    let bias = rng.vec(cout);
    let whole_bufs = [
        RowPlanar::from_planar(&fa, ca, h, w, None).unwrap(),
        RowPlanar::from_planar(&fb, cb, h, w, None).unwrap(),
        RowPlanar::from_planar(&fr, cout, h, w, None).unwrap(),
    ];
    for row in f32_rows() {
        let plan = Conv3x3F32::with_kernel(&wt, &bias, ca + cb, cout, true, row).unwrap();
        let mut whole = RowPlanar::new(cout, h, w).unwrap();
        let inputs = Inputs::new(&whole_bufs[0])
            .concat(&whole_bufs[1])
            .residual(&whole_bufs[2]);
        plan.run(inputs, &mut whole, 0..h).unwrap();
        let whole = whole.to_planar();
        for (f0, f1, [(fo, ho), (fa0, ha), (fb0, hb), (fr0, hr)]) in
            window_cases(h, plan.kernel().row_group())
        {
            let win = |src: &[f32], c, first, rows| {
                RowPlanar::from_planar(&window_of(src, c, h, w, first, rows, 0.0), c, rows, w, None)
                    .unwrap()
            };
            let (a, b, r) = (
                win(&fa, ca, fa0, ha),
                win(&fb, cb, fb0, hb),
                win(&fr, cout, fr0, hr),
            );
            let mut out = RowPlanar::new(cout, ho, w).unwrap();
            let inputs = Inputs::new(&a)
                .concat(&b)
                .residual(&r)
                .shifted(fa0 - fo, fb0 - fo, fr0 - fo)
                .frame_row(fo);
            let band = (f0 as isize - fo) as usize..(f1 as isize - fo) as usize;
            plan.run(inputs, &mut out, band.clone()).unwrap();
            let got = out.to_planar();
            for o in 0..cout {
                for i in 0..ho {
                    let f = fo + i as isize;
                    for x in 0..w {
                        let g = got[(o * ho + i) * w + x];
                        let want = if band.contains(&i) {
                            whole[(o * h + f as usize) * w + x]
                        } else {
                            0.0
                        };
                        assert_eq!(
                            g.to_bits(),
                            want.to_bits(),
                            "{row} rows {f0}..{f1} ({o}, {f}, {x})"
                        );
                    }
                }
            }
            assert!(out.border_is_clean());
            // One row too few above the band in source a: refused, nothing written.
            let short = Inputs::new(&a).concat(&b).residual(&r).shifted(
                fa0 - fo + (band.start as isize - (fa0 - fo)) + 1,
                fb0 - fo,
                fr0 - fo,
            );
            assert!(matches!(
                plan.run(short, &mut out, band.clone()),
                Err(KernelError::Shape { .. })
            ));
            if plan.kernel().row_group() > 1 && band.len() > 1 {
                // A band that starts inside a group: refused.
                let inside = band.start + 1..band.end;
                assert!(matches!(
                    plan.run(inputs, &mut out, inside),
                    Err(KernelError::Shape { .. })
                ));
            }
            if plan.kernel().row_group() > 1 {
                // Source a one row short of the row below the last group (its bottom border row standing for
                // the last group's last row): refused.
                let g = plan.kernel().row_group();
                let need_end = f0 + (f1 - f0).div_ceil(g) * g + 1;
                let a_short = win(&fa, ca, fa0, (need_end as isize - fa0 - 2) as usize);
                let short = Inputs::new(&a_short)
                    .concat(&b)
                    .residual(&r)
                    .shifted(fa0 - fo, fb0 - fo, fr0 - fo)
                    .frame_row(fo);
                assert!(matches!(
                    plan.run(short, &mut out, band.clone()),
                    Err(KernelError::Shape { .. })
                ));
            }
        }
    }
}

#[test]
fn u8_shifted_windows_equal_the_whole_frame() {
    // As the f32 test, bit-exact, for u8 outputs and for raw f32 rows (the last layer's), windows padded
    // with each buffer's zero point.
    let case = QCase {
        ca: 14,
        cb: 4,
        cout: 24,
        h: 13,
        w: 37,
        relu: true,
        residual: true,
        u8_out: true,
    };
    let d = qdata(case, 21);
    let sp = spec(case, &d);
    let (ca, cb, cout, h, w) = (case.ca, case.cb, case.cout, case.h, case.w);
    let whole_bufs = [
        RowPlanar::from_planar_u8(&d.a, ca, h, w, d.zp[0]).unwrap(),
        RowPlanar::from_planar_u8(&d.b, cb, h, w, d.zp[1]).unwrap(),
        RowPlanar::from_planar_u8(&d.r, cout, h, w, d.zp[2]).unwrap(),
    ];
    for row in u8_rows() {
        let plan = Conv3x3U8::with_kernel(&sp, row).unwrap();
        let inputs = Inputs::new(&whole_bufs[0])
            .concat(&whole_bufs[1])
            .residual(&whole_bufs[2]);
        let mut whole = RowPlanar::new_quantized(cout, h, w, d.zp[3]).unwrap();
        plan.run(inputs, &mut whole, 0..h).unwrap();
        let whole = whole.to_planar();
        let mut whole_f = vec![0.0; cout * h * w];
        plan.run_planar(inputs, &mut whole_f, 0..h).unwrap();
        for (f0, f1, [(fo, ho), (fa0, ha), (fb0, hb), (fr0, hr)]) in window_cases(h, 1) {
            let win = |src: &[u8], c, first, rows, zp| {
                RowPlanar::from_planar_u8(&window_of(src, c, h, w, first, rows, zp), c, rows, w, zp)
                    .unwrap()
            };
            let a = win(&d.a, ca, fa0, ha, d.zp[0]);
            let b = win(&d.b, cb, fb0, hb, d.zp[1]);
            let r = win(&d.r, cout, fr0, hr, d.zp[2]);
            let mut out = RowPlanar::new_quantized(cout, ho, w, d.zp[3]).unwrap();
            let inputs =
                Inputs::new(&a)
                    .concat(&b)
                    .residual(&r)
                    .shifted(fa0 - fo, fb0 - fo, fr0 - fo);
            let band = (f0 as isize - fo) as usize..(f1 as isize - fo) as usize;
            plan.run(inputs, &mut out, band.clone()).unwrap();
            let got = out.to_planar();
            let mut rows_f = vec![7.5f32; band.len() * cout * w];
            plan.run_rows_f32(inputs, &mut rows_f, band.clone())
                .unwrap();
            for o in 0..cout {
                for i in 0..ho {
                    let f = fo + i as isize;
                    for x in 0..w {
                        let want = if band.contains(&i) {
                            whole[(o * h + f as usize) * w + x]
                        } else {
                            d.zp[3]
                        };
                        assert_eq!(
                            got[(o * ho + i) * w + x],
                            want,
                            "{row} rows {f0}..{f1} ({o}, {f}, {x})"
                        );
                        if band.contains(&i) {
                            let g = rows_f[((i - band.start) * cout + o) * w + x];
                            let want = whole_f[(o * h + f as usize) * w + x];
                            assert_eq!(
                                g.to_bits(),
                                want.to_bits(),
                                "{row} raw rows ({o}, {f}, {x})"
                            );
                        }
                    }
                }
            }
            assert!(out.border_is_clean());
            // A residual window that misses the band's last row: refused.
            let short = Inputs::new(&a).concat(&b).residual(&r).shifted(
                fa0 - fo,
                fb0 - fo,
                band.end as isize - hr as isize - 1,
            );
            assert!(matches!(
                plan.run(short, &mut out, band.clone()),
                Err(KernelError::Shape { .. })
            ));
            // A planar output takes whole frames only.
            let mut planar = vec![0.0; cout * ho * w];
            assert!(plan.run_planar(inputs, &mut planar, band.clone()).is_err());
        }
    }
}

#[test]
fn shifts_of_absent_operands_are_ignored() {
    // A plan that reads only `a`: whatever offsets are given for the absent concat and residual, the call
    // is checked and computed on `a`'s offset alone (they must not move the kernel's row origin past the
    // band, which would read outside `a`), f32 and u8 alike.
    let (ca, cout, h, w) = (8, 8, 9, 21);
    let mut rng = Rng::new(4);
    let src = rng.vec(ca * h * w);
    let a = RowPlanar::from_planar(&src, ca, h, w, None).unwrap();
    let (wt, bias) = (rng.vec(cout * ca * 9), rng.vec(cout));
    let q = Conv3x3U8::new(
        &Conv3x3U8Spec {
            weights: &(0..cout * ca * 9)
                .map(|i| (i % 7) as i8 - 3)
                .collect::<Vec<_>>(),
            weight_scales: &vec![0.01; cout],
            bias: &bias,
            c_in_a: ca,
            c_in_b: 0,
            c_out: cout,
            input_scale: 0.02,
            input_zero_point_a: 9,
            input_zero_point_b: 9,
            relu: true,
            residual: None,
            output: Some(QuantU8 {
                scale: 0.05,
                zero_point: 3,
            }),
        },
        Isa::detect(),
    )
    .unwrap();
    let qa = RowPlanar::quantize_from_planar(&src, ca, h, w, 0.02, 9).unwrap();
    for row in f32_rows() {
        let plan = Conv3x3F32::with_kernel(&wt, &bias, ca, cout, true, row).unwrap();
        let (mut want, mut got) = (
            RowPlanar::new(cout, h, w).unwrap(),
            RowPlanar::new(cout, h, w).unwrap(),
        );
        plan.run(Inputs::new(&a), &mut want, 0..3).unwrap();
        plan.run(Inputs::new(&a).shifted(0, 50, -50), &mut got, 0..3)
            .unwrap();
        assert_eq!(got, want, "{row}");
    }
    let (mut want, mut got) = (
        RowPlanar::new_quantized(cout, h, w, 3).unwrap(),
        RowPlanar::new_quantized(cout, h, w, 3).unwrap(),
    );
    q.run(Inputs::new(&qa), &mut want, 0..3).unwrap();
    q.run(Inputs::new(&qa).shifted(0, 50, 50), &mut got, 0..3)
        .unwrap();
    assert_eq!(got, want);
    assert!(q
        .run(Inputs::new(&qa).shifted(1, 0, 0), &mut got, 0..3)
        .is_err());
}
