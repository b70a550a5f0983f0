use super::*;
use crate::error::KernelError;
use crate::quant::quantize;

#[test]
fn roundtrip_and_border() {
    let (c, h, w) = (3, 4, 5);
    let src: Vec<f32> = (0..c * h * w).map(|i| i as f32 + 1.0).collect();
    let scale = [1.0, 2.0, 1.0];
    let offset = [-0.5, 0.0, 1.0];
    let b = RowPlanar::from_planar(
        &src,
        c,
        h,
        w,
        Some(Affine {
            scale: &scale,
            offset: &offset,
        }),
    )
    .unwrap();
    assert!(b.border_is_clean());
    let back = b.to_planar();
    for ch in 0..c {
        for i in 0..h * w {
            let k = ch * h * w + i;
            assert_eq!(back[k], src[k] * scale[ch] + offset[ch]);
        }
    }
    assert_eq!(b.get(1, 2, 3), Some(src[(h + 2) * w + 3] * 2.0));
    for ch in 0..c {
        for y in 0..h {
            let k = (ch * h + y) * w;
            assert_eq!(b.row(ch, y).unwrap(), &back[k..k + w]);
        }
    }
    assert_eq!(b.row(c, 0), None);
    assert_eq!(b.row(0, h), None);
    assert!(b.padded_width() >= w + 2 + MAX_TILE);
    let mut bad = vec![0.0; 3];
    assert!(matches!(
        b.read_planar(&mut bad),
        Err(KernelError::Length { .. })
    ));
    assert!(RowPlanar::<f32>::new(0, 1, 1).is_err());
}

#[test]
fn u8_roundtrip_zero_point_border() {
    let (c, h, w) = (6, 3, 7);
    let src: Vec<u8> = (0..c * h * w).map(|i| (i * 7 % 251) as u8).collect();
    let b = RowPlanar::from_planar_u8(&src, c, h, w, 17).unwrap();
    assert_eq!(b.to_planar(), src);
    assert!(b.border_is_clean());
    // Column 1 of every row is 64-byte aligned.
    assert_eq!((b.as_slice().as_ptr() as usize + 4) % 64, 0);
    // Padding channels 6, 7 hold the zero point.
    assert_eq!(b.as_slice().len(), (h + 2) * 2 * b.padded_width() * 4);
    let mut corrupt = b.clone();
    let i = corrupt.index(6, 1, 1);
    corrupt.as_mut_slice()[i] = 0;
    assert!(!corrupt.border_is_clean());
}

#[test]
fn quantize_rounds_ties_to_even_and_clamps() {
    assert_eq!(quantize(2.5, 0), 2);
    assert_eq!(quantize(3.5, 0), 4);
    assert_eq!(quantize(-300.0, 10), 0);
    assert_eq!(quantize(1e30, 10), 255);
    assert_eq!(quantize(-0.5, 3), 3);
    // Against the definition, clamp(round_ties_even(x) + zp, 0, 255) with NaN → 0, on a sweep through every
    // half step of [-300, 600], the integers' neighbours, and the non-finite values.
    let mut xs: Vec<f32> = (-600..=1200).map(|i| i as f32 * 0.5).collect();
    xs.extend((-300..=600).flat_map(|i| [i as f32 - 1e-4, i as f32 + 1e-4]));
    xs.extend([
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        1e30,
        -1e30,
        4194304.5,
    ]);
    for zp in [0u8, 3, 127, 200, 255] {
        for &x in &xs {
            let want = if x.is_nan() {
                0
            } else {
                (x.round_ties_even() + zp as f32).clamp(0.0, 255.0) as u8
            };
            assert_eq!(quantize(x, zp), want, "x {x}, zp {zp}");
        }
    }
}

#[test]
fn window_rows_fill_copy_and_map_frame_rows() {
    // Rows of a window: border fill, copy (the carry between strips), and fills from other rows of a
    // taller frame, whole planar or plane by plane, agree with the whole-frame fills row for row.
    let (c, h, w, fh) = (5, 6, 9, 11);
    let src: Vec<f32> = (0..c * fh * w)
        .map(|i| (i % 97) as f32 * 0.25 - 3.0)
        .collect();
    let (scale, offset) = ([1.0, 2.0, 0.5, 1.0, -1.0], [0.0, -0.5, 0.25, 1.0, 0.0]);
    let affine = Affine {
        scale: &scale,
        offset: &offset,
    };
    let whole = RowPlanar::from_planar(&src, c, fh, w, Some(affine)).unwrap();
    let mut win = RowPlanar::new(c, h, w).unwrap();
    // Window rows 1..5 take frame rows 4..8: once from the planar frame, once plane by plane.
    win.band_mut(1..5)
        .unwrap()
        .fill_rows_from_planar(&src, fh, 4, Some(affine))
        .unwrap();
    let mut per_plane = RowPlanar::new(c, h, w).unwrap();
    for ch in 0..c {
        let plane = &src[ch * fh * w..(ch + 1) * fh * w];
        let mut band = per_plane.band_mut(1..5).unwrap();
        band.fill_channel_rows(ch, plane, 4, Some((scale[ch], offset[ch])))
            .unwrap();
    }
    assert_eq!(win, per_plane);
    for ch in 0..c {
        for i in 1..5 {
            assert_eq!(win.row(ch, i), whole.row(ch, i + 3), "({ch}, {i})");
        }
    }
    // Rows past the plane's end are refused, as is a channel past C.
    let mut band = per_plane.band_mut(0..6).unwrap();
    assert!(band.fill_channel_rows(0, &src[..fh * w], 6, None).is_err());
    assert!(band.fill_channel_rows(c, &src[..fh * w], 0, None).is_err());
    // A column slab of a wider plane: columns x0 .. x0 + w of rows `stride` values long.
    let (stride, x0) = (w + 7, 5);
    let wide: Vec<f32> = (0..fh * stride).map(|i| (i % 89) as f32 - 40.0).collect();
    let mut slab = RowPlanar::new(1, h, w).unwrap();
    slab.band_mut(1..5)
        .unwrap()
        .fill_channel_rows_at(0, &wide, [stride, x0], 4, Some((2.0, 1.0)))
        .unwrap();
    for i in 1..5 {
        let from = &wide[(i + 3) * stride + x0..(i + 3) * stride + x0 + w];
        let want: Vec<f32> = from.iter().map(|v| v * 2.0 + 1.0).collect();
        assert_eq!(slab.row(0, i), Some(&want[..]), "slab row {i}");
    }
    // Columns past the row's end are refused.
    let mut band = slab.band_mut(1..5).unwrap();
    assert!(band
        .fill_channel_rows_at(0, &wide, [stride, stride - w + 1], 4, None)
        .is_err());
    // Carry: rows 3..5 move to 0..2; then rows 2..6 are set to the border (zero), borders stay clean.
    let before = win.clone();
    win.copy_rows(3..5, 0).unwrap();
    win.fill_rows_with_border(2..6).unwrap();
    for ch in 0..c {
        assert_eq!(win.row(ch, 0), before.row(ch, 3));
        assert_eq!(win.row(ch, 1), before.row(ch, 4));
        for i in 2..6 {
            assert!(win.row(ch, i).unwrap().iter().all(|&v| v == 0.0));
        }
    }
    assert!(win.border_is_clean());
    assert!(win.copy_rows(3..6, 4).is_err());
    assert!(win.fill_rows_with_border(2..7).is_err());

    // u8: quantised rows of a taller frame, then requantised from other rows of another window.
    let q = RowPlanar::quantize_from_planar(&src, c, fh, w, 0.05, 7).unwrap();
    let mut qa = RowPlanar::new_quantized(c, h, w, 7).unwrap();
    qa.band_mut(0..6)
        .unwrap()
        .quantize_fill_rows(&src, fh, 5, 0.0, 0.05)
        .unwrap();
    let mut qb = RowPlanar::new_quantized(c, h, w, 7).unwrap();
    for ch in 0..c {
        let plane = &src[ch * fh * w..(ch + 1) * fh * w];
        qb.band_mut(0..6)
            .unwrap()
            .quantize_fill_channel_rows(ch, plane, 5, 0.0, 0.05)
            .unwrap();
    }
    assert_eq!(qa, qb);
    let mut cat = RowPlanar::new_quantized(c, 3, w, 200).unwrap();
    cat.band_mut(1..3)
        .unwrap()
        .requantize_rows_from(&qa, 2, 0.05, 0.1)
        .unwrap();
    for ch in 0..c {
        for x in 0..w {
            for (i, f) in [(1, 7), (2, 8)] {
                let real = (q.get(ch, f, x).unwrap() as f32 - 7.0) * 0.05;
                assert_eq!(cat.get(ch, i, x), Some(quantize(real / 0.1, 200)));
            }
            assert_eq!(cat.get(ch, 0, x), Some(200));
        }
    }
    assert!(cat.border_is_clean());
    let mut band = cat.band_mut(0..3).unwrap();
    assert!(band.requantize_rows_from(&qa, 4, 0.05, 0.1).is_err());
}

#[test]
fn rows_convert_between_f32_and_u8_as_onnx_quantize_and_dequantize() {
    // The mixed-precision layers' conversions: other rows of a window, element by element against the
    // ONNX definitions, borders untouched; mismatched shapes and rows past the source refused.
    let (c, h, w) = (6, 5, 7);
    let src: Vec<f32> = (0..c * h * w)
        .map(|i| ((i * 37) % 101) as f32 * 0.031 - 1.2)
        .collect();
    let f = RowPlanar::from_planar(&src, c, h, w, None).unwrap();
    let (scale, zp) = (0.0123, 97);
    let mut q = RowPlanar::new_quantized(c, 3, w, zp).unwrap();
    q.band_mut(1..3)
        .unwrap()
        .quantize_rows_from(&f, 2, scale)
        .unwrap();
    let mut back = RowPlanar::new(c, 4, w).unwrap();
    back.band_mut(2..4)
        .unwrap()
        .dequantize_rows_from(&q, 1, scale)
        .unwrap();
    for ch in 0..c {
        for x in 0..w {
            assert_eq!(q.get(ch, 0, x), Some(zp));
            for (i, fy) in [(1, 2), (2, 3)] {
                let v = f.get(ch, fy, x).unwrap();
                let want = (v / scale)
                    .round_ties_even()
                    .clamp(-(zp as f32), 255.0 - zp as f32);
                let got = q.get(ch, i, x).unwrap();
                assert_eq!(got as f32 - zp as f32, want, "({ch}, {i}, {x})");
                let deq = back.get(ch, i + 1, x).unwrap();
                assert_eq!(deq, (got as f32 - zp as f32) * scale);
                assert!((deq - v).abs() <= scale * 0.5 + 1e-6 || !(-1.19..=1.9).contains(&v));
            }
            assert_eq!(back.get(ch, 0, x), Some(0.0));
        }
    }
    assert!(q.border_is_clean() && back.border_is_clean());
    let mut band = q.band_mut(0..3).unwrap();
    assert!(band.quantize_rows_from(&f, 3, scale).is_err());
    assert!(band.quantize_rows_from(&f, 0, 0.0).is_err());
    let narrow = RowPlanar::new(c, h, w - 1).unwrap();
    assert!(band.quantize_rows_from(&narrow, 0, scale).is_err());
    let mut band = back.band_mut(0..4).unwrap();
    assert!(band.dequantize_rows_from(&q, 0, scale).is_err());
}

/// The conversion rows (`rows.rs`) under every level this CPU has against the portable body, bit for bit, on
/// random values and the edges of the grids: ties, values past either end of `[0, 255]`, ±0, ±∞ and NaN,
/// a length that is not a whole number of vectors, and slices of unequal length (the shortest counts).
#[test]
fn conversion_rows_on_every_level_equal_the_portable_body() {
    use super::rows::{dequantize_row, quantize_row, requantize_row};
    use crate::isa::Isa;
    let n = 203;
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let special = [
        0.0,
        -0.0,
        0.5,
        1.5,
        -0.5,
        2.5,
        1e9,
        -1e9,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        127.5,
        -128.5,
    ];
    let f32s: Vec<Vec<f32>> = (0..4)
        .map(|k| {
            (0..n + k)
                .map(|i| match i % 7 {
                    0 => special[(i / 7) % special.len()] * 0.05,
                    _ => ((next() >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 20.0,
                })
                .collect()
        })
        .collect();
    let bytes: Vec<u8> = (0..4 * n + 3).map(|_| next() as u8).collect();
    let rows = [&f32s[0][..], &f32s[1][..], &f32s[2][..], &f32s[3][..]];
    let run_all = |isa: Isa| {
        let mut q = vec![7u8; 4 * n + 5];
        quantize_row(isa, &mut q, rows, 131, 0.25, 0.05).unwrap();
        let mut d: Vec<Vec<f32>> = (0..4).map(|k| vec![-1.0; n + 2 - k]).collect();
        let [d0, d1, d2, d3] = &mut d[..] else {
            unreachable!()
        };
        dequantize_row(isa, &bytes, [d0, d1, d2, d3], 17.0, 0.031).unwrap();
        let mut r = vec![9u8; 4 * n + 1];
        requantize_row(isa, &mut r, &bytes, (131.0, 0.05), (3, 0.07)).unwrap();
        let d: Vec<u32> = d.iter().flatten().map(|v| v.to_bits()).collect();
        (q, d, r)
    };
    let want = run_all(Isa::Scalar);
    // The edges are reached: codes 0 and 255, and every pixel of the shortest row written, no more.
    assert!(want.0.contains(&0) && want.0.contains(&255));
    assert_eq!(want.0[4 * n..], [7; 5]);
    // Dequantised: the shortest row (n − 1 values) bounds every row; the values past it keep −1.
    let first_row = &want.1[..n + 2];
    assert_eq!(
        first_row[n - 2],
        ((bytes[4 * (n - 2)] as f32 - 17.0) * 0.031).to_bits()
    );
    assert_eq!(first_row[n - 1], (-1.0f32).to_bits());
    for isa in Isa::available() {
        assert!(run_all(isa) == want, "{isa:?}");
    }
}
