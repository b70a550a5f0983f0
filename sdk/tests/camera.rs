//! Phone camera buffers → `RgbdFrame` (`tensorholo::scene::camera`): every depth format against known
//! values, invalid pixels, row strides and byte orders, rotations, fits, low-resolution depth, and every
//! kind of bad input (with a property test of the buffer length rule).

use ndarray::{Array2, Axis};
use proptest::prelude::*;
use tensorholo::color::srgb8_to_amplitude;
use tensorholo::scene::*;
use tensorholo::HoloError;

const ALL_DEPTH: [DepthFormat; 6] = DepthFormat::ALL;
const ALL_COLOR: [ColorFormat; 3] = ColorFormat::ALL;
const ALL_ROT: [Rotation; 4] = [
    Rotation::Deg0,
    Rotation::Deg90,
    Rotation::Deg180,
    Rotation::Deg270,
];

/// A valid sample of `z` metres in `format` (Depth16 with confidence code `conf`).
fn encode(format: DepthFormat, z: f32, conf: u16) -> Vec<u8> {
    let mm = (z * 1000.0).round() as u16;
    match format {
        DepthFormat::MetresF32 => z.to_le_bytes().to_vec(),
        DepthFormat::MetresF16 => half::f16::from_f32(z).to_le_bytes().to_vec(),
        DepthFormat::DisparityF32 => (1.0 / z).to_le_bytes().to_vec(),
        DepthFormat::DisparityF16 => half::f16::from_f32(1.0 / z).to_le_bytes().to_vec(),
        DepthFormat::MillimetresU16 => mm.to_le_bytes().to_vec(),
        DepthFormat::Depth16 => (mm | conf << 13).to_le_bytes().to_vec(),
    }
}

/// Every kind of invalid sample of `format`.
fn invalid_samples(format: DepthFormat) -> Vec<Vec<u8>> {
    let floats = [
        0.0f32,
        -0.0,
        -1.5,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
    ];
    match format {
        DepthFormat::MetresF32 | DepthFormat::DisparityF32 => {
            floats.iter().map(|v| v.to_le_bytes().to_vec()).collect()
        }
        DepthFormat::MetresF16 | DepthFormat::DisparityF16 => floats
            .iter()
            .map(|&v| half::f16::from_f32(v).to_le_bytes().to_vec())
            .collect(),
        DepthFormat::MillimetresU16 => vec![0u16.to_le_bytes().to_vec()],
        DepthFormat::Depth16 => vec![
            0u16.to_le_bytes().to_vec(),                  // range 0
            (2u16 << 13).to_le_bytes().to_vec(),          // range 0, some confidence
            (1000u16 | 1 << 13).to_le_bytes().to_vec(),   // 1 m at confidence 0 %
            (0x1FFFu16 | 1 << 13).to_le_bytes().to_vec(), // 8.191 m at confidence 0 %
        ],
    }
}

/// Writes `h × w` pixels (each `px(y, x)` of `bpp` bytes) with a row stride (`0` = packed); padding
/// bytes are garbage (0xA5); `trim_last` drops the last row's padding.
fn pack(
    h: usize,
    w: usize,
    bpp: usize,
    stride: usize,
    trim_last: bool,
    px: impl Fn(usize, usize) -> Vec<u8>,
) -> Vec<u8> {
    let stride = if stride == 0 { w * bpp } else { stride };
    let mut out = vec![0xA5u8; stride * h];
    for y in 0..h {
        for x in 0..w {
            let p = px(y, x);
            assert_eq!(p.len(), bpp);
            out[y * stride + x * bpp..][..bpp].copy_from_slice(&p);
        }
    }
    if trim_last {
        out.truncate(stride * (h - 1) + w * bpp);
    }
    out
}

/// Bytes of one RGB pixel in `format` (alpha is garbage: it must be ignored).
fn color_px(format: ColorFormat, [r, g, b]: [u8; 3]) -> Vec<u8> {
    match format {
        ColorFormat::Rgba8 => vec![r, g, b, 0x3C],
        ColorFormat::Bgra8 => vec![b, g, r, 0xC3],
        ColorFormat::Rgb8 => vec![r, g, b],
    }
}

/// A deterministic, non-symmetric RGB pattern.
fn rgb_at(y: usize, x: usize) -> [u8; 3] {
    [
        (y * 37 + x * 11 + 5) as u8,
        (y * 7 + x * 53 + 100) as u8,
        (y * 91 + x * 3 + 200) as u8,
    ]
}

fn color_buf(
    format: ColorFormat,
    h: usize,
    w: usize,
    stride: usize,
    rgb: impl Fn(usize, usize) -> [u8; 3],
) -> ColorImageBuf {
    ColorImageBuf {
        data: pack(h, w, format.bytes_per_pixel(), stride, false, |y, x| {
            color_px(format, rgb(y, x))
        }),
        format,
        width: w,
        height: h,
        row_stride: stride,
    }
}

fn depth_buf(
    format: DepthFormat,
    h: usize,
    w: usize,
    stride: usize,
    z: impl Fn(usize, usize) -> f32,
) -> DepthImageBuf {
    DepthImageBuf {
        data: pack(h, w, format.bytes_per_pixel(), stride, false, |y, x| {
            encode(format, z(y, x), 0)
        }),
        format,
        width: w,
        height: h,
        row_stride: stride,
    }
}

fn frame(color: ColorImageBuf, depth: DepthImageBuf, rotation: Rotation) -> CameraFrameBuf {
    CameraFrameBuf {
        color,
        depth,
        rotation,
        color_crop: None,
        confidence: None,
    }
}

/// Fixed range, linear in metres (so expected depths are simple), with the given fit.
fn fixed(fit: Fit, near: f32, far: f32) -> FrameOptions {
    FrameOptions {
        fit,
        range: Some(DepthRange::new(near, far).unwrap()),
        mapping: DepthMapping::LinearMetres,
        // These tests check the nearest rule's samples; the joint bilateral default has its own.
        depth_upsampling: DepthUpsampling::Nearest,
    }
}

/// The frame at the colour buffer's own rotated size (no resampling at all).
fn native(f: &CameraFrameBuf, options: &FrameOptions) -> RgbdFrame {
    let (h, w) = f.rotation.rotated_size(f.color.height, f.color.width);
    let options = FrameOptions {
        fit: Fit::Stretch,
        ..*options
    };
    f.view().to_rgbd(h, w, &options).unwrap().0
}

#[test]
fn every_depth_format_decodes_known_values_to_the_same_depth() {
    // 0.5 m, 1 m, 2 m, 0.25 m: exact in f16, as disparities (2, 1, 0.5, 4 1/m) and in millimetres.
    let z = [[0.5f32, 1.0], [2.0, 0.25]];
    let range = DepthRange::new(0.25, 2.0).unwrap();
    let options = FrameOptions {
        fit: Fit::Stretch,
        range: Some(range),
        mapping: DepthMapping::LinearDiopters,
        depth_upsampling: DepthUpsampling::Nearest,
    };
    let color = color_buf(ColorFormat::Rgb8, 2, 2, 0, rgb_at);
    let mut first: Option<RgbdFrame> = None;
    for format in ALL_DEPTH {
        // Depth16: confidence codes 0 (100 %), 2 (1/7), 7 (6/7) and 0 again: all valid.
        let confs = [[0u16, 2], [7, 0]];
        let depth = DepthImageBuf {
            data: pack(2, 2, format.bytes_per_pixel(), 0, false, |y, x| {
                encode(format, z[y][x], confs[y][x])
            }),
            format,
            width: 2,
            height: 2,
            row_stride: 0,
        };
        let decoded = depth.view().decode(Rotation::Deg0).unwrap();
        assert!(decoded.metric);
        assert!(decoded.valid.iter().all(|&v| v), "{format:?}");
        assert_eq!(
            decoded.values,
            Array2::from_shape_fn((2, 2), |(y, x)| z[y][x]),
            "{format:?}"
        );
        let (f, report) = frame(color.clone(), depth, Rotation::Deg0)
            .view()
            .to_rgbd(2, 2, &options)
            .unwrap();
        assert_eq!(report.range_used, Some(range));
        assert_eq!(report.invalid_fraction, 0.0);
        // Linear in diopters over [0.25, 2] m: d = (4 − 1/z)/3.5.
        for ((y, x), &d) in f.depth.indexed_iter() {
            let expected = (4.0 - 1.0 / z[y][x]) / 3.5;
            assert!((d - expected).abs() < 1e-6, "{format:?} ({y},{x}): {d}");
        }
        assert_eq!(
            f.depth[[0, 0]],
            DepthMapping::LinearDiopters.apply(0.5, &range)
        );
        match &first {
            None => first = Some(f),
            Some(f0) => assert_eq!(&f, f0, "{format:?} differs from MetresF32"),
        }
    }
}

#[test]
fn invalid_depth_pixels_are_filled_from_far_neighbours_never_near() {
    // 5×6: column 0 near (0.5 m → d = 0), the rest at 1 m (d = 0.5 over [0.5, 1.5] m in metres); both
    // exact in every format, disparities included.
    // Invalid samples at (2, 1), next to the near column, and inside the far region.
    let (h, w) = (5, 6);
    let holes = [(2usize, 1usize), (1, 3), (2, 4), (3, 3), (4, 5), (0, 2)];
    let options = fixed(Fit::Stretch, 0.5, 1.5);
    for format in ALL_DEPTH {
        for bad in invalid_samples(format) {
            let depth = DepthImageBuf {
                data: pack(h, w, format.bytes_per_pixel(), 0, false, |y, x| {
                    if holes.contains(&(y, x)) {
                        bad.clone()
                    } else {
                        encode(format, if x == 0 { 0.5 } else { 1.0 }, 0)
                    }
                }),
                format,
                width: w,
                height: h,
                row_stride: 0,
            };
            let decoded = depth.view().decode(Rotation::Deg0).unwrap();
            for ((y, x), &ok) in decoded.valid.indexed_iter() {
                assert_eq!(ok, !holes.contains(&(y, x)), "{format:?} {bad:?}");
                if !ok {
                    assert_eq!(decoded.values[[y, x]], 0.0);
                }
            }
            let color = color_buf(ColorFormat::Rgb8, h, w, 0, rgb_at);
            let (f, report) = frame(color, depth, Rotation::Deg0)
                .view()
                .to_rgbd(h, w, &options)
                .unwrap();
            assert_eq!(report.invalid_fraction, holes.len() as f32 / (h * w) as f32);
            for ((y, x), &d) in f.depth.indexed_iter() {
                let expected = if x == 0 { 0.0 } else { 0.5 };
                assert_eq!(d, expected, "{format:?} {bad:?} at ({y},{x})");
            }
        }
    }
}

#[test]
fn padded_strides_give_the_packed_frame() {
    let (h, w) = (6, 7);
    let z = |y: usize, x: usize| 0.4 + 0.1 * ((y * 3 + x * 5) % 11) as f32;
    let options = FrameOptions::default();
    for cf in ALL_COLOR {
        for df in [DepthFormat::MetresF32, DepthFormat::MillimetresU16] {
            let packed = frame(
                color_buf(cf, h, w, 0, rgb_at),
                depth_buf(df, h, w, 0, z),
                Rotation::Deg0,
            );
            let reference = packed.view().to_rgbd(5, 9, &options).unwrap();
            let c_row = w * cf.bytes_per_pixel();
            let d_row = w * df.bytes_per_pixel();
            for (pad, trim_last) in [
                (0usize, false),
                (5, false),
                (5, true),
                (64, true),
                (1, false),
            ] {
                let (cs, ds) = (c_row + pad, d_row + pad + 3);
                let mut f = frame(
                    color_buf(cf, h, w, cs, rgb_at),
                    depth_buf(df, h, w, ds, z),
                    Rotation::Deg0,
                );
                if trim_last {
                    f.color.data.truncate(cs * (h - 1) + c_row);
                    f.depth.data.truncate(ds * (h - 1) + d_row);
                }
                let got = f.view().to_rgbd(5, 9, &options).unwrap();
                assert_eq!(got, reference, "{cf:?} {df:?} pad {pad} trim {trim_last}");
            }
        }
    }
}

#[test]
fn byte_orders_give_identical_amplitude_in_rgb_order() {
    let (h, w) = (4, 5);
    // Pure primaries in the first row, the pattern elsewhere.
    let rgb = |y: usize, x: usize| match (y, x) {
        (0, 0) => [255, 0, 0],
        (0, 1) => [0, 255, 0],
        (0, 2) => [0, 0, 255],
        _ => rgb_at(y, x),
    };
    let depth = depth_buf(DepthFormat::MetresF32, h, w, 0, |_, x| 1.0 + x as f32);
    let frames: Vec<RgbdFrame> = ALL_COLOR
        .iter()
        .map(|&cf| {
            native(
                &frame(color_buf(cf, h, w, 0, rgb), depth.clone(), Rotation::Deg0),
                &FrameOptions::default(),
            )
        })
        .collect();
    assert_eq!(frames[0], frames[1]);
    assert_eq!(frames[0], frames[2]);
    let a = &frames[0].amplitude;
    for k in 0..3 {
        for c in 0..3 {
            assert_eq!(
                a[[c, 0, k]],
                if c == k { 1.0 } else { 0.0 },
                "primary {k} channel {c}"
            );
        }
    }
    for ((c, y, x), &v) in a.indexed_iter() {
        assert_eq!(v, srgb8_to_amplitude(rgb(y, x)[c]));
    }
}

/// Naive clockwise rotation by 90° of a `[.., H, W]`-indexed function, `k` times.
fn rot90_cw_2d(a: &Array2<f32>) -> Array2<f32> {
    let (h, w) = a.dim();
    // Output (W × H): output (i, j) shows input (h − 1 − j, i).
    Array2::from_shape_fn((w, h), |(i, j)| a[[h - 1 - j, i]])
}

#[test]
fn rotations_turn_colour_and_depth_together_as_documented() {
    let (h, w) = (2, 3);
    // Asymmetric pattern: every pixel distinct, in colour and in depth.
    let z = |y: usize, x: usize| 1.0 + (y * w + x) as f32 * 0.25;
    let options = fixed(Fit::Stretch, 0.5, 3.0);
    let color = color_buf(ColorFormat::Bgra8, h, w, 0, rgb_at);
    let depth = depth_buf(DepthFormat::MetresF16, h, w, 0, z);
    let upright = native(
        &frame(color.clone(), depth.clone(), Rotation::Deg0),
        &options,
    );
    let d_tl = upright.depth[[0, 0]];
    let a_tl = upright.amplitude[[0, 0, 0]];
    let mut expected_d = upright.depth.clone();
    let mut expected_a: Vec<Array2<f32>> = (0..3)
        .map(|c| upright.amplitude.index_axis(Axis(0), c).to_owned())
        .collect();
    for (k, rot) in ALL_ROT.into_iter().enumerate() {
        let f = native(&frame(color.clone(), depth.clone(), rot), &options);
        assert_eq!(f.depth, expected_d, "{rot:?} depth");
        for (c, expected) in expected_a.iter().enumerate() {
            assert_eq!(
                f.amplitude.index_axis(Axis(0), c),
                expected,
                "{rot:?} channel {c}"
            );
        }
        // Where the buffer's top-left pixel ends up.
        let (ho, wo) = (f.height(), f.width());
        let corner = [(0, 0), (0, wo - 1), (ho - 1, wo - 1), (ho - 1, 0)][k];
        assert_eq!(f.depth[corner], d_tl, "{rot:?}");
        assert_eq!(f.amplitude[[0, corner.0, corner.1]], a_tl, "{rot:?}");
        assert_eq!((ho, wo), if k % 2 == 0 { (h, w) } else { (w, h) });
        expected_d = rot90_cw_2d(&expected_d);
        expected_a = expected_a.iter().map(rot90_cw_2d).collect();
    }

    // Depth at half the colour resolution rotates with the colour: colour block (2y..2y+2, 2x..2x+2)
    // carries the id of depth pixel (y, x) in its red byte; after any rotation, every output pixel's depth
    // must still belong to its colour's id.
    let id_rgb = |y: usize, x: usize| [((y / 2) * 3 + x / 2) as u8 * 20, 0, 0];
    let color = color_buf(ColorFormat::Rgba8, 4, 6, 0, id_rgb);
    let depth = depth_buf(DepthFormat::MillimetresU16, 2, 3, 0, |y, x| {
        1.0 + (y * 3 + x) as f32 * 0.25
    });
    for rot in ALL_ROT {
        let f = native(&frame(color.clone(), depth.clone(), rot), &options);
        for ((y, x), &d) in f.depth.indexed_iter() {
            let id = (0..6)
                .find(|&i| f.amplitude[[0, y, x]] == srgb8_to_amplitude(i as u8 * 20))
                .unwrap();
            let expected = (1.0 + id as f32 * 0.25 - 0.5) / 2.5;
            assert!(
                (d - expected).abs() < 1e-6,
                "{rot:?} ({y},{x}): id {id}, d {d}"
            );
        }
    }
}

#[test]
fn crop_keeps_the_centre_at_the_target_aspect() {
    // 20 × 40 landscape, every depth pixel distinct.
    let (h, w) = (20, 40);
    let z = |y: usize, x: usize| 0.5 + (y * w + x) as f32 * 0.002;
    let options = fixed(Fit::Crop, 0.5, 2.5);
    let full = frame(
        color_buf(ColorFormat::Rgba8, h, w, 0, rgb_at),
        depth_buf(DepthFormat::MetresF32, h, w, 0, z),
        Rotation::Deg0,
    );
    let reference = native(&full, &options);
    // Square target: the centre 20 × 20 (columns 10..30), scaled by 1/2 in both directions.
    let (sq, _) = full.view().to_rgbd(10, 10, &options).unwrap();
    for ((y, x), &d) in sq.depth.indexed_iter() {
        assert_eq!(d, reference.depth[[2 * y + 1, 10 + 2 * x + 1]], "({y},{x})");
    }
    // Same as stretching the centre window, cut out of the buffers with the row stride.
    let window = |bpp: usize| 10 * bpp..;
    let cropped = CameraFrame {
        color: ColorImage {
            data: &full.color.data[window(4)],
            width: 20,
            row_stride: w * 4,
            ..full.color.view()
        },
        depth: DepthImage {
            data: &full.depth.data[window(4)],
            width: 20,
            row_stride: w * 4,
            ..full.depth.view()
        },
        rotation: Rotation::Deg0,
        color_crop: None,
        confidence: None,
    };
    let stretched = cropped
        .to_rgbd(
            10,
            10,
            &FrameOptions {
                fit: Fit::Stretch,
                ..options
            },
        )
        .unwrap()
        .0;
    assert_eq!(sq, stretched);
    // Portrait 20 × 5 target: the centre 20 × 5 (columns 17..22), unscaled.
    let (tall, _) = full.view().to_rgbd(20, 5, &options).unwrap();
    for ((c, y, x), &a) in tall.amplitude.indexed_iter() {
        assert_eq!(a, reference.amplitude[[c, y, 17 + x]]);
    }
    for ((y, x), &d) in tall.depth.indexed_iter() {
        assert_eq!(d, reference.depth[[y, 17 + x]]);
    }
    // Same aspect ratio as the frame: nothing is cropped, Crop = Stretch.
    let (same, _) = full.view().to_rgbd(10, 20, &options).unwrap();
    assert_eq!(same, reference.resize(10, 20).unwrap());
}

#[test]
fn letterbox_pads_black_and_far_in_the_expected_bands() {
    let (h, w) = (20, 20);
    let z = |y: usize, x: usize| 0.5 + (y + x) as f32 * 0.01;
    let options = fixed(Fit::Letterbox, 0.4, 1.0);
    let f = frame(
        color_buf(ColorFormat::Rgb8, h, w, 0, |_, _| [255, 255, 255]),
        depth_buf(DepthFormat::DisparityF32, h, w, 0, z),
        Rotation::Deg0,
    );
    let reference = native(&f, &options);
    assert!(reference.depth.iter().all(|&d| d < 1.0));
    // (target, inner size, top-left of the picture): wide, tall and odd margins.
    for ((th, tw), (ih, iw), (y0, x0)) in [
        ((10, 30), (10, 10), (0, 10)),
        ((30, 10), (10, 10), (10, 0)),
        ((10, 25), (10, 10), (0, 7)),
        ((13, 8), (8, 8), (2, 0)),
        ((20, 20), (20, 20), (0, 0)),
    ] {
        let (out, _) = f.view().to_rgbd(th, tw, &options).unwrap();
        assert_eq!(out.depth.dim(), (th, tw));
        let inner = reference.resize(ih, iw).unwrap();
        for y in 0..th {
            for x in 0..tw {
                let inside = (y0..y0 + ih).contains(&y) && (x0..x0 + iw).contains(&x);
                for c in 0..3 {
                    let expected = if inside {
                        inner.amplitude[[c, y - y0, x - x0]]
                    } else {
                        0.0
                    };
                    assert_eq!(out.amplitude[[c, y, x]], expected, "{th}x{tw} ({y},{x})");
                }
                let expected = if inside {
                    inner.depth[[y - y0, x - x0]]
                } else {
                    1.0
                };
                assert_eq!(out.depth[[y, x]], expected, "{th}x{tw} ({y},{x})");
                if inside {
                    assert!(out.amplitude[[0, y, x]] > 0.99, "white picture inside");
                }
            }
        }
    }
}

#[test]
fn stretch_equals_rgbd_frame_resize() {
    let (h, w) = (12, 17);
    let f = frame(
        color_buf(ColorFormat::Bgra8, h, w, 0, rgb_at),
        depth_buf(DepthFormat::Depth16, h, w, 0, |y, x| {
            0.3 + ((x * 7 + y) % 13) as f32 * 0.2
        }),
        Rotation::Deg90,
    );
    let options = FrameOptions {
        fit: Fit::Stretch,
        ..FrameOptions::default()
    };
    let reference = native(&f, &options);
    for (th, tw) in [(5, 30), (17, 12), (40, 9)] {
        let (out, report) = f.view().to_rgbd(th, tw, &options).unwrap();
        assert_eq!(out, reference.resize(th, tw).unwrap(), "{th}x{tw}");
        assert_eq!((report.color_size, report.depth_size), ((h, w), (h, w)));
    }
}

#[test]
fn low_resolution_depth_is_upsampled_without_mixing_depths() {
    // Depth at half the colour resolution with a diagonal step edge between 0.5 m and 3 m.
    let (hd, wd) = (8, 10);
    let z = |y: usize, x: usize| if x > y { 3.0 } else { 0.5 };
    let options = FrameOptions::default(); // automatic range, diopters, crop
    let f = frame(
        color_buf(ColorFormat::Rgb8, 2 * hd, 2 * wd, 0, rgb_at),
        depth_buf(DepthFormat::MillimetresU16, hd, wd, 0, z),
        Rotation::Deg0,
    );
    let (full, report) = f
        .view()
        .to_rgbd(
            2 * hd,
            2 * wd,
            &FrameOptions {
                fit: Fit::Stretch,
                ..options
            },
        )
        .unwrap();
    assert_eq!(
        report.range_used,
        Some(DepthRange {
            z_near_m: 0.5,
            z_far_m: 3.0
        })
    );
    assert_eq!(report.depth_size, (hd, wd));
    // Each depth pixel covers exactly its 2 × 2 colour block.
    for ((y, x), &d) in full.depth.indexed_iter() {
        assert_eq!(
            d,
            if z(y / 2, x / 2) == 3.0 { 1.0 } else { 0.0 },
            "({y},{x})"
        );
    }
    for (th, tw) in [(12, 20), (7, 7), (33, 50)] {
        for fit in [Fit::Crop, Fit::Stretch] {
            let (out, _) = f
                .view()
                .to_rgbd(th, tw, &FrameOptions { fit, ..options })
                .unwrap();
            assert!(
                out.depth.iter().all(|&d| d == 0.0 || d == 1.0),
                "{fit:?} {th}x{tw}"
            );
            assert!(out.depth.iter().any(|&d| d == 0.0) && out.depth.iter().any(|&d| d == 1.0));
        }
    }
}

/// `f` edited by `edit`, converted to the good frame's 4 × 6 with default options.
fn with<'a>(
    mut f: CameraFrame<&'a [u8]>,
    edit: impl FnOnce(&mut CameraFrame<&'a [u8]>),
) -> Result<(RgbdFrame, CameraFrameReport), HoloError> {
    edit(&mut f);
    f.to_rgbd(4, 6, &FrameOptions::default())
}

/// Asserts an `InvalidParameter` naming `name`, whose reason contains every string of `needles`.
#[track_caller]
fn assert_invalid(
    r: Result<(RgbdFrame, CameraFrameReport), HoloError>,
    name: &str,
    needles: &[&str],
) {
    match r {
        Err(HoloError::InvalidParameter { name: n, reason }) => {
            assert_eq!(n, name, "{reason}");
            for s in needles {
                assert!(reason.contains(s), "`{reason}` lacks `{s}`");
            }
        }
        Err(e) => panic!("expected InvalidParameter `{name}`, got {e}"),
        Ok(_) => panic!("expected InvalidParameter `{name}`, got Ok"),
    }
}

#[test]
fn bad_inputs_give_typed_errors() {
    let good = frame(
        color_buf(ColorFormat::Rgba8, 4, 6, 0, rgb_at),
        depth_buf(DepthFormat::MetresF32, 2, 3, 0, |_, _| 1.0),
        Rotation::Deg0,
    );
    let opts = FrameOptions::default();
    assert!(good.view().to_rgbd(4, 6, &opts).is_ok());
    let g = good.view();
    // Zero sizes.
    assert_invalid(with(g, |f| f.color.width = 0), "color", &["width 0"]);
    assert_invalid(with(g, |f| f.color.height = 0), "color", &["height 0"]);
    assert_invalid(with(g, |f| f.depth.width = 0), "depth", &["width 0"]);
    assert_invalid(with(g, |f| f.depth.height = 0), "depth", &["height 0"]);
    // Stride shorter than a row (24 bytes of colour, 12 of depth).
    assert_invalid(
        with(g, |f| f.color.row_stride = 23),
        "color_row_stride",
        &["23", "24"],
    );
    assert_invalid(
        with(g, |f| f.depth.row_stride = 11),
        "depth_row_stride",
        &["11", "12"],
    );
    // Short and long buffers: expected vs got bytes.
    let c = &good.color.data;
    let d = &good.depth.data;
    assert_invalid(
        with(g, |f| f.color.data = &c[..95]),
        "color",
        &["at least 96", "got 95"],
    );
    assert_invalid(
        with(g, |f| f.depth.data = &d[..23]),
        "depth",
        &["at least 24", "got 23"],
    );
    let long_c = [c.as_slice(), &[0]].concat();
    let long_d = [d.as_slice(), &[0]].concat();
    assert_invalid(
        with(g, |f| f.color.data = &long_c),
        "color",
        &["at most 96", "got 97"],
    );
    assert_invalid(
        with(g, |f| f.depth.data = &long_d),
        "depth",
        &["at most 24", "got 25"],
    );
    // Stride 30 > 24: 3·30 + 24 = 114 to 4·30 = 120 bytes (the last row's padding may be absent).
    let padded = vec![9u8; 121];
    for len in [114, 117, 120] {
        assert!(with(g, |f| {
            f.color.row_stride = 30;
            f.color.data = &padded[..len];
        })
        .is_ok());
    }
    assert_invalid(
        with(g, |f| {
            f.color.row_stride = 30;
            f.color.data = &padded[..113];
        }),
        "color",
        &["at least 114", "got 113"],
    );
    assert_invalid(
        with(g, |f| {
            f.color.row_stride = 30;
            f.color.data = &padded;
        }),
        "color",
        &["at most 120", "got 121"],
    );
    // Sizes no camera makes: refused by their pixel count before any arithmetic on bytes (the image limit);
    // then a stride overflowing usize: stride·(height − 1).
    assert_invalid(
        with(g, |f| f.color.width = usize::MAX / 2),
        "color",
        &["pixels, more than"],
    );
    assert_invalid(
        with(g, |f| f.depth.width = usize::MAX / 3),
        "depth",
        &["pixels, more than"],
    );
    assert_invalid(
        with(g, |f| {
            f.depth.width = 1;
            f.depth.height = 3;
            f.depth.row_stride = usize::MAX / 2;
        }),
        "depth",
        &["overflows"],
    );
    assert_invalid(
        with(g, |f| {
            f.color.height = usize::MAX;
            f.color.width = usize::MAX;
        }),
        "color",
        &["pixels, more than"],
    );
    // Target size and range.
    assert_invalid(good.view().to_rgbd(0, 6, &opts), "height", &[]);
    assert_invalid(good.view().to_rgbd(4, 0, &opts), "width", &[]);
    assert_invalid(good.view().to_rgbd(usize::MAX, 2, &opts), "size", &[]);
    assert_invalid(good.view().to_rgbd(1 << 40, 1 << 40, &opts), "size", &[]);
    let bad_range = FrameOptions {
        range: Some(DepthRange {
            z_near_m: 2.0,
            z_far_m: 1.0,
        }),
        ..opts
    };
    assert_invalid(good.view().to_rgbd(4, 6, &bad_range), "depth_range", &[]);
    // Every depth pixel invalid, in every format, with an automatic and a fixed range.
    for format in ALL_DEPTH {
        for bad in invalid_samples(format) {
            let depth = DepthImageBuf {
                data: pack(2, 3, format.bytes_per_pixel(), 0, false, |_, _| bad.clone()),
                format,
                width: 3,
                height: 2,
                row_stride: 0,
            };
            for o in [opts, fixed(Fit::Crop, 0.5, 2.0)] {
                let f = CameraFrame {
                    depth: depth.view(),
                    ..good.view()
                };
                match f.to_rgbd(4, 6, &o) {
                    Err(HoloError::InvalidDepth(msg)) => {
                        assert!(msg.contains("all 6 pixels"), "{msg}")
                    }
                    other => panic!("{format:?} {bad:?}: expected InvalidDepth, got {other:?}"),
                }
            }
        }
    }
}

/// The documented length rule, in exact (`u128`) arithmetic.
fn length_rule(len: usize, w: usize, h: usize, bpp: usize, stride: usize) -> bool {
    let (len, w, h, bpp, stride) = (
        len as u128,
        w as u128,
        h as u128,
        bpp as u128,
        stride as u128,
    );
    let row = w * bpp;
    let stride = if stride == 0 { row } else { stride };
    if w == 0 || h == 0 || stride < row {
        return false;
    }
    // A product beyond u128 (sizes near usize::MAX) is certainly more than `len`.
    let min = stride.checked_mul(h - 1).and_then(|m| m.checked_add(row));
    let max = stride.checked_mul(h);
    min.is_some_and(|m| m <= len) && max.is_none_or(|m| len <= m)
}

/// A buffer length to try: `any_len` (`pick` 0), or the smallest (`pick` 1) or largest (`pick` 2)
/// allowed length plus `delta`, when that is a small number of bytes.
fn test_len(
    pick: usize,
    delta: i64,
    any_len: usize,
    w: usize,
    h: usize,
    bpp: usize,
    stride: usize,
) -> usize {
    let row = w as u128 * bpp as u128;
    let stride = if stride == 0 { row } else { stride as u128 };
    let bound = match pick {
        1 => stride
            .checked_mul((h as u128).saturating_sub(1))
            .and_then(|m| m.checked_add(row)),
        2 => stride.checked_mul(h as u128),
        _ => None,
    };
    match bound {
        Some(b) if b < 4096 => (b as i64 + delta).max(0) as usize,
        _ => any_len,
    }
}

fn size_strategy() -> impl Strategy<Value = usize> {
    prop_oneof![
        4 => 0usize..6,
        1 => Just(usize::MAX),
        1 => Just(usize::MAX / 2),
        1 => Just(usize::MAX / 3 + 1),
        1 => (1usize << 62)..=usize::MAX,
    ]
}

fn stride_strategy() -> impl Strategy<Value = usize> {
    prop_oneof![
        6 => 0usize..30,
        1 => Just(usize::MAX),
        1 => (1usize << 62)..=usize::MAX,
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn colour_buffer_is_accepted_iff_the_length_rule_holds(
        fi in 0usize..3, w in size_strategy(), h in size_strategy(), stride in stride_strategy(),
        pick in 0usize..3, delta in -2i64..=2, any_len in 0usize..140,
    ) {
        let format = ALL_COLOR[fi];
        let len = test_len(pick, delta, any_len, w, h, format.bytes_per_pixel(), stride);
        let data = vec![77u8; len];
        let depth = depth_buf(DepthFormat::MillimetresU16, 1, 1, 0, |_, _| 1.0);
        let f = CameraFrame {
            color: ColorImage { data: &data[..], format, width: w, height: h, row_stride: stride },
            depth: depth.view(),
            rotation: Rotation::Deg90,
            color_crop: None,
            confidence: None,
        };
        let ok = length_rule(len, w, h, format.bytes_per_pixel(), stride);
        let r = f.to_rgbd(3, 2, &FrameOptions::default());
        prop_assert_eq!(f.color.validate().is_ok(), ok);
        match r {
            Ok((frame, _)) => {
                prop_assert!(ok);
                let expected = srgb8_to_amplitude(77);
                prop_assert!(frame.amplitude.iter().all(|&a| (a - expected).abs() < 1e-5));
            }
            Err(HoloError::InvalidParameter { name, .. }) => {
                prop_assert!(!ok);
                prop_assert!(name == "color" || name == "color_row_stride", "{}", name);
            }
            Err(e) => prop_assert!(false, "unexpected error {}", e),
        }
    }

    #[test]
    fn depth_buffer_is_accepted_iff_the_length_rule_holds(
        fi in 0usize..6, w in size_strategy(), h in size_strategy(), stride in stride_strategy(),
        pick in 0usize..3, delta in -2i64..=2, any_len in 0usize..140,
    ) {
        let format = ALL_DEPTH[fi];
        let len = test_len(pick, delta, any_len, w, h, format.bytes_per_pixel(), stride);
        // 0x01 bytes are a valid positive depth in every format.
        let data = vec![1u8; len];
        let color = color_buf(ColorFormat::Rgb8, 3, 4, 0, rgb_at);
        let f = CameraFrame {
            color: color.view(),
            depth: DepthImage { data: &data[..], format, width: w, height: h, row_stride: stride },
            rotation: Rotation::Deg270,
            color_crop: None,
            confidence: None,
        };
        let ok = length_rule(len, w, h, format.bytes_per_pixel(), stride);
        prop_assert_eq!(f.depth.validate().is_ok(), ok);
        match f.to_rgbd(2, 5, &FrameOptions::default()) {
            Ok((frame, report)) => {
                prop_assert!(ok);
                prop_assert_eq!(report.invalid_fraction, 0.0);
                prop_assert!(frame.depth.iter().all(|d| (0.0..=1.0).contains(d)));
            }
            Err(HoloError::InvalidParameter { name, .. }) => {
                prop_assert!(!ok);
                prop_assert!(name == "depth" || name == "depth_row_stride", "{}", name);
            }
            Err(e) => prop_assert!(false, "unexpected error {}", e),
        }
    }

    #[test]
    fn random_frames_convert_to_valid_frames(
        h in 1usize..9, w in 1usize..9, hd in 0usize..8, wd in 0usize..8, rot in 0usize..4,
        fit in 0usize..3, th in 1usize..12, tw in 1usize..12,
        seed in any::<u64>(),
    ) {
        // Depth at most the colour's resolution (a nearest downsampling could drop every valid pixel).
        let (hd, wd) = (1 + hd % h, 1 + wd % w);
        // Random depths in [0.3, 5] m with ~20 % holes (at least one valid pixel).
        let mut s = seed;
        let mut next = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 33) as u32 };
        let zs: Vec<Option<f32>> = (0..hd * wd)
            .map(|i| if i > 0 && next() % 5 == 0 { None } else { Some(0.3 + (next() % 4700) as f32 / 1000.0) })
            .collect();
        let depth = DepthImageBuf {
            data: pack(hd, wd, 4, 0, false, |y, x| zs[y * wd + x].unwrap_or(f32::NAN).to_le_bytes().to_vec()),
            format: DepthFormat::MetresF32, width: wd, height: hd, row_stride: 0,
        };
        let f = frame(color_buf(ColorFormat::Rgba8, h, w, 0, rgb_at), depth, ALL_ROT[rot]);
        let options = FrameOptions {
            fit: [Fit::Crop, Fit::Letterbox, Fit::Stretch][fit],
            depth_upsampling: DepthUpsampling::Nearest,
            ..FrameOptions::default()
        };
        let (out, report) = f.view().to_rgbd(th, tw, &options).unwrap();
        prop_assert_eq!(out.depth.dim(), (th, tw));
        // A valid frame: RgbdFrame::new accepts it unchanged.
        prop_assert_eq!(RgbdFrame::new(out.amplitude.clone(), out.depth.clone()).unwrap(), out.clone());
        let n_invalid = zs.iter().filter(|z| z.is_none()).count();
        prop_assert_eq!(report.invalid_fraction, n_invalid as f32 / (hd * wd) as f32);
        // Depth only takes values of the normalised valid input (nearest everywhere; holes filled from
        // valid neighbours) plus 1 in letterbox margins.
        let r = report.range_used.unwrap();
        let allowed: Vec<f32> = zs.iter().flatten().map(|&z| DepthMapping::LinearDiopters.apply(z, &r)).collect();
        prop_assert!(out.depth.iter().all(|d| allowed.contains(d) || (fit == 1 && *d == 1.0)));
        // The joint bilateral default: a valid frame too, its depths within the valid inputs' span (weighted
        // means of them; holes filled from them), plus 1 in letterbox margins.
        let guided = FrameOptions { depth_upsampling: DepthUpsampling::JointBilateral, ..options };
        let (out, _) = f.view().to_rgbd(th, tw, &guided).unwrap();
        let (lo, hi) = allowed.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        prop_assert!(out.depth.iter().all(|&d| (lo - 1e-6..=hi + 1e-6).contains(&d) || (fit == 1 && d == 1.0)));
    }
}

#[test]
fn owned_buffers_round_trip() {
    let f = frame(
        color_buf(ColorFormat::Rgb8, 3, 4, 13, rgb_at),
        depth_buf(DepthFormat::DisparityF16, 3, 4, 0, |y, _| 1.0 + y as f32),
        Rotation::Deg180,
    );
    let view = f.view();
    assert_eq!(view.to_buf(), f);
    let (a, ra) = view.to_rgbd(6, 6, &FrameOptions::default()).unwrap();
    let (b, rb) = f
        .clone()
        .view()
        .to_rgbd(6, 6, &FrameOptions::default())
        .unwrap();
    assert_eq!((&a, &ra), (&b, &rb));
    // Report serialises like DepthReport.
    let json = serde_json::to_value(&rb).unwrap();
    assert_eq!(json["color_size"], serde_json::json!([3, 4]));
    assert!(json["range_used"]["z_near_m"].as_f64().unwrap() > 0.9);
}

/// A depth buffer's confidence (ARKit's 0/1/2, ARCore's 0–255): samples below the buffer's minimum are
/// invalid, so the frame equals the one whose depth buffer holds invalid samples there, under every rotation
/// (the confidence turns with the depth) and with a row stride; a low-confidence near block is never read as
/// near; a confidence buffer of another size than the depth is refused naming `confidence`.
#[test]
fn low_confidence_depth_samples_are_invalid_under_every_rotation() {
    let (hc, wc, hd, wd) = (12, 16, 6, 8);
    let near = |y: usize, x: usize| (1..3).contains(&y) && (2..5).contains(&x);
    let z = move |y: usize, x: usize| {
        if near(y, x) {
            0.3
        } else {
            1.0 + 0.1 * x as f32
        }
    };
    let rating = move |y: usize, x: usize| -> u8 {
        if near(y, x) {
            0
        } else if x == 0 {
            1
        } else {
            2
        }
    };
    let options = fixed(Fit::Stretch, 0.25, 2.0);
    for rotation in ALL_ROT {
        for (min, scale) in [(1u8, 1u8), (128, 100)] {
            let color = color_buf(ColorFormat::Rgba8, hc, wc, 0, rgb_at);
            let depth = depth_buf(DepthFormat::MetresF32, hd, wd, 0, z);
            let stride = wd + 3;
            let confidence = ConfidenceImageBuf {
                data: pack(hd, wd, 1, stride, false, |y, x| {
                    vec![rating(y, x).saturating_mul(scale)]
                }),
                min_confidence: min,
                width: wd,
                height: hd,
                row_stride: stride,
            };
            let mut with = frame(color.clone(), depth, rotation);
            with.confidence = Some(confidence);
            // The same frame with its depth invalid (0 m) where the confidence is low (on ARCore's scale,
            // 100 < 128: the medium column too).
            let holes = depth_buf(DepthFormat::MetresF32, hd, wd, 0, move |y, x| {
                if rating(y, x).saturating_mul(scale) < min {
                    0.0
                } else {
                    z(y, x)
                }
            });
            let expected = native(&frame(color.clone(), holes, rotation), &options);
            let got = native(&with, &options);
            assert_eq!(got, expected, "{rotation:?}, min {min}");
            let plain = native(
                &frame(
                    color,
                    depth_buf(DepthFormat::MetresF32, hd, wd, 0, z),
                    rotation,
                ),
                &options,
            );
            let nearest = |f: &RgbdFrame| f.depth.iter().fold(f32::INFINITY, |m, &d| m.min(d));
            assert!(nearest(&plain) < 0.05, "{rotation:?}: {}", nearest(&plain));
            assert!(nearest(&got) > 0.3, "{rotation:?}: {}", nearest(&got));
        }
    }
    let mut wrong = frame(
        color_buf(ColorFormat::Rgba8, hc, wc, 0, rgb_at),
        depth_buf(DepthFormat::MetresF32, hd, wd, 0, z),
        Rotation::Deg0,
    );
    wrong.confidence = Some(ConfidenceImageBuf {
        data: vec![2; hd * wd / 2],
        min_confidence: 1,
        width: wd / 2,
        height: hd,
        row_stride: 0,
    });
    let e = wrong.view().to_rgbd(hc, wc, &options).unwrap_err();
    assert!(
        matches!(&e, HoloError::InvalidParameter { name, .. } if *name == "confidence"),
        "{e}"
    );
}
