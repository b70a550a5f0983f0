//! `.npy` and PNG input/output, and the overwrite guard.

use std::fs;
use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, Axis, Slice};
use tensorholo::color::srgb8_to_amplitude;
use tensorholo::io::{
    ensure_not_input, parse_complex_npy, read_complex_npy, save_amplitude_png, save_u8_png,
    write_complex_npy, write_f32_npy,
};
use tensorholo::{Complex32, HoloError};

/// A fresh, empty scratch folder under Cargo's per-target temporary folder.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("io_tests")
        .join(name);
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).unwrap();
    dir
}

/// A version-1.0 `.npy` file built by hand (independent of the writer under test).
fn npy_bytes(descr: &str, fortran: bool, shape: &str, data: &[u8]) -> Vec<u8> {
    let fortran = if fortran { "True" } else { "False" };
    let mut header =
        format!("{{'descr': '{descr}', 'fortran_order': {fortran}, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

/// Header dictionary text of a `.npy` file (version 1.0 or 2.0).
fn npy_header(bytes: &[u8]) -> String {
    assert_eq!(&bytes[..6], b"\x93NUMPY");
    let (len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        _ => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
    };
    assert_eq!((start + len) % 64, 0, "header not 64-byte aligned");
    String::from_utf8(bytes[start..start + len].to_vec()).unwrap()
}

fn test_field() -> Array3<Complex32> {
    Array3::from_shape_fn((3, 4, 5), |(c, y, x)| {
        Complex32::new(
            (c * 100 + y * 10 + x) as f32 * 0.125 - 7.0,
            ((x * 31 + y * 17 + c) as f32).sin() * 1e-3,
        )
    })
}

fn bits(a: &Array3<Complex32>) -> Vec<(u32, u32)> {
    a.iter().map(|z| (z.re.to_bits(), z.im.to_bits())).collect()
}

#[test]
fn complex_npy_round_trip_is_bit_exact() {
    let dir = scratch("complex_round_trip");
    let mut field = test_field();
    field[[0, 0, 0]] = Complex32::new(f32::MIN_POSITIVE / 8.0, -0.0); // subnormal, negative zero
    field[[1, 2, 3]] = Complex32::new(f32::INFINITY, f32::NAN);
    field[[2, 3, 4]] = Complex32::new(f32::MAX, f32::EPSILON);
    let path = dir.join("field.npy");
    write_complex_npy(&path, field.view()).unwrap();
    let back = read_complex_npy(&path).unwrap();
    assert_eq!(back.dim(), (3, 4, 5));
    assert!(back.is_standard_layout());
    assert_eq!(bits(&back), bits(&field));

    // A non-contiguous, reversed view is written in logical C order.
    // (`s![]` cannot be used: the workspace forbids `unsafe_code`, which the macro allows.)
    let mut view = field.view();
    view.slice_axis_inplace(Axis(0), Slice::new(0, None, 2));
    view.slice_axis_inplace(Axis(1), Slice::new(0, None, -1));
    view.slice_axis_inplace(Axis(2), Slice::from(1..));
    assert!(!view.is_standard_layout());
    let path2 = dir.join("strided.npy");
    write_complex_npy(&path2, view).unwrap();
    assert_eq!(
        bits(&read_complex_npy(&path2).unwrap()),
        bits(&view.to_owned())
    );
}

#[test]
fn complex_npy_header_is_c8_c_order_chw() {
    let dir = scratch("complex_header");
    let field = test_field();
    let path = dir.join("field.npy");
    write_complex_npy(&path, field.view()).unwrap();
    let bytes = fs::read(&path).unwrap();
    let header = npy_header(&bytes);
    assert!(header.contains("'descr': '<c8'"), "{header}");
    assert!(header.contains("'fortran_order': False"), "{header}");
    assert!(header.contains("'shape': (3, 4, 5)"), "{header}");
    assert!(header.ends_with('\n'));
    // Data: 60 little-endian (re, im) f32 pairs in C order right after the header.
    let data = &bytes[bytes.len() - 3 * 4 * 5 * 8..];
    assert_eq!(bytes.len() - data.len(), 10 + header.len());
    let z = field[[0, 1, 2]];
    let k = (5 + 2) * 8; // [0, 1, 2] is element 0·20 + 1·5 + 2 in C order, 8 bytes each
    assert_eq!(&data[k..k + 4], &z.re.to_le_bytes());
    assert_eq!(&data[k + 4..k + 8], &z.im.to_le_bytes());
}

#[test]
fn reads_rank_2_as_one_channel_and_other_encodings() {
    let dir = scratch("complex_read_variants");
    // [H, W] = [2, 3] complex64, little-endian.
    let vals: Vec<Complex32> = (0..6)
        .map(|i| Complex32::new(i as f32, -(i as f32) / 2.0))
        .collect();
    let le: Vec<u8> = vals
        .iter()
        .flat_map(|z| [z.re.to_le_bytes(), z.im.to_le_bytes()].concat())
        .collect();
    let p = dir.join("hw.npy");
    fs::write(&p, npy_bytes("<c8", false, "(2, 3)", &le)).unwrap();
    let a = read_complex_npy(&p).unwrap();
    assert_eq!(a.dim(), (1, 2, 3));
    assert_eq!(a[[0, 1, 2]], vals[5]);

    // Big-endian complex64.
    let be: Vec<u8> = vals
        .iter()
        .flat_map(|z| [z.re.to_be_bytes(), z.im.to_be_bytes()].concat())
        .collect();
    let p = dir.join("be.npy");
    fs::write(&p, npy_bytes(">c8", false, "(1, 2, 3)", &be)).unwrap();
    assert_eq!(
        read_complex_npy(&p)
            .unwrap()
            .iter()
            .copied()
            .collect::<Vec<_>>(),
        vals
    );

    // complex128 is converted to complex64.
    let c16: Vec<u8> = vals
        .iter()
        .flat_map(|z| [(z.re as f64).to_le_bytes(), (z.im as f64).to_le_bytes()].concat())
        .collect();
    let p = dir.join("c16.npy");
    fs::write(&p, npy_bytes("<c16", false, "(2, 3)", &c16)).unwrap();
    let a = read_complex_npy(&p).unwrap();
    assert_eq!(a.dim(), (1, 2, 3));
    assert_eq!(a.iter().copied().collect::<Vec<_>>(), vals);

    // Fortran order: element (y, x) is stored at x·H + y; the result is C-contiguous.
    let fort: Vec<u8> = (0..3)
        .flat_map(|x| (0..2).map(move |y| y * 3 + x))
        .flat_map(|i| {
            let z = vals[i];
            [z.re.to_le_bytes(), z.im.to_le_bytes()].concat()
        })
        .collect();
    let p = dir.join("fortran.npy");
    fs::write(&p, npy_bytes("<c8", true, "(2, 3)", &fort)).unwrap();
    let a = read_complex_npy(&p).unwrap();
    assert!(a.is_standard_layout());
    assert_eq!(a.iter().copied().collect::<Vec<_>>(), vals);
}

fn assert_npy_error(path: &Path, needle: &str) {
    match read_complex_npy(path) {
        Err(e @ HoloError::Npy { .. }) => {
            let msg = e.to_string();
            assert!(msg.contains(&path.display().to_string()), "{msg}");
            assert!(msg.contains(needle), "{msg} should mention {needle}");
        }
        other => panic!("expected an Npy error, got {other:?}"),
    }
}

#[test]
fn wrong_dtype_rank_or_garbage_is_a_clear_error() {
    let dir = scratch("complex_read_errors");
    let p = dir.join("float64.npy");
    fs::write(&p, npy_bytes("<f8", false, "(2, 2)", &[0u8; 32])).unwrap();
    assert_npy_error(&p, "<f8");

    let p = dir.join("float32.npy");
    write_f32_npy(&p, Array2::<f32>::zeros((2, 2)).view()).unwrap();
    assert_npy_error(&p, "<f4");

    let p = dir.join("rank4.npy");
    fs::write(&p, npy_bytes("<c8", false, "(1, 1, 2, 2)", &[0u8; 32])).unwrap();
    assert_npy_error(&p, "rank");
    let p = dir.join("rank1.npy");
    fs::write(&p, npy_bytes("<c8", false, "(4,)", &[0u8; 32])).unwrap();
    assert_npy_error(&p, "rank");

    let p = dir.join("truncated.npy");
    fs::write(&p, npy_bytes("<c8", false, "(2, 2)", &[0u8; 20])).unwrap();
    assert!(matches!(read_complex_npy(&p), Err(HoloError::Npy { .. })));

    let p = dir.join("not_npy.npy");
    fs::write(&p, b"hello, world").unwrap();
    assert!(matches!(read_complex_npy(&p), Err(HoloError::Npy { .. })));

    let p = dir.join("missing.npy");
    match read_complex_npy(&p) {
        Err(HoloError::Io { path, .. }) => assert_eq!(path, p),
        other => panic!("expected Io error, got {other:?}"),
    }
}

#[test]
fn f32_npy_header_and_data() {
    let dir = scratch("f32_npy");
    let depth = Array2::from_shape_fn((2, 3), |(y, x)| y as f32 + x as f32 / 4.0);
    let p = dir.join("depth.npy");
    write_f32_npy(&p, depth.t()).unwrap(); // transposed view: written as (3, 2) C order
    let bytes = fs::read(&p).unwrap();
    let header = npy_header(&bytes);
    assert!(header.contains("'descr': '<f4'"), "{header}");
    assert!(header.contains("'fortran_order': False"), "{header}");
    assert!(header.contains("'shape': (3, 2)"), "{header}");
    let data: Vec<f32> = bytes[bytes.len() - 24..]
        .chunks(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(data, depth.t().iter().copied().collect::<Vec<_>>());

    // Write errors carry the path.
    let bad = dir.join("no_such_dir").join("x.npy");
    match write_f32_npy(&bad, depth.view()) {
        Err(HoloError::Io { path, .. }) => assert_eq!(path, bad),
        other => panic!("expected Io error, got {other:?}"),
    }
    assert!(write_complex_npy(&bad, Array3::<Complex32>::zeros((1, 1, 1)).view()).is_err());
}

#[test]
fn amplitude_png_round_trip_reproduces_srgb_codes() {
    let dir = scratch("amplitude_png");
    let (h, w) = (5, 7);
    let code_at = |c: usize, y: usize, x: usize| ((c * 97 + y * 37 + x * 11) % 256) as u8;
    let amp = Array3::from_shape_fn((3, h, w), |(c, y, x)| srgb8_to_amplitude(code_at(c, y, x)));
    let p = dir.join("rgb.png");
    save_amplitude_png(&p, amp.view(), 1.0).unwrap();
    let img = image::open(&p).unwrap();
    assert_eq!(img.color(), image::ColorType::Rgb8);
    let rgb = img.to_rgb8();
    assert_eq!(rgb.dimensions(), (w as u32, h as u32));
    for y in 0..h {
        for x in 0..w {
            let px = rgb.get_pixel(x as u32, y as u32).0;
            assert_eq!(px, [code_at(0, y, x), code_at(1, y, x), code_at(2, y, x)]);
        }
    }

    // `scale` multiplies amplitude: half amplitude = quarter intensity. NaN and negatives → black,
    // above-white clamps to 255. The extension does not choose the format.
    let mut amp2 = Array3::from_elem((1, 2, 3), 1.0f32);
    amp2[[0, 0, 1]] = f32::NAN;
    amp2[[0, 0, 2]] = -0.5;
    amp2[[0, 1, 0]] = 3.0;
    amp2[[0, 1, 1]] = f32::INFINITY;
    let p = dir.join("grey.out");
    save_amplitude_png(&p, amp2.view(), 0.5).unwrap();
    let img = image::ImageReader::open(&p)
        .unwrap()
        .with_guessed_format()
        .unwrap()
        .decode()
        .unwrap();
    assert_eq!(img.color(), image::ColorType::L8);
    let quarter = tensorholo::color::amplitude_to_srgb8(0.5);
    assert_eq!(quarter, 137); // sRGB code of linear 0.25
    assert_eq!(
        img.to_luma8().into_raw(),
        vec![quarter, 0, 0, 255, 255, quarter]
    );
}

#[test]
fn amplitude_png_rejects_bad_input() {
    let dir = scratch("amplitude_png_errors");
    let p = dir.join("x.png");
    let two = Array3::<f32>::zeros((2, 4, 4));
    assert!(matches!(
        save_amplitude_png(&p, two.view(), 1.0),
        Err(HoloError::ShapeMismatch { .. })
    ));
    let one = Array3::<f32>::zeros((3, 4, 4));
    for scale in [-1.0, f32::NAN, f32::INFINITY] {
        assert!(matches!(
            save_amplitude_png(&p, one.view(), scale),
            Err(HoloError::InvalidParameter { name: "scale", .. })
        ));
    }
    let empty = Array3::<f32>::zeros((3, 0, 4));
    assert!(matches!(
        save_amplitude_png(&p, empty.view(), 1.0),
        Err(HoloError::InvalidData(_))
    ));
    let bad = dir.join("missing_dir").join("x.png");
    match save_amplitude_png(&bad, one.view(), 1.0) {
        Err(e @ HoloError::Image { .. }) => assert!(e.to_string().contains("missing_dir")),
        other => panic!("expected Image error, got {other:?}"),
    }
}

#[test]
fn u8_png_round_trip() {
    let dir = scratch("u8_png");
    let codes = Array2::from_shape_fn((6, 9), |(y, x)| (y * 40 + x * 3) as u8);
    let p = dir.join("phase.png");
    save_u8_png(&p, codes.view()).unwrap();
    let img = image::open(&p).unwrap();
    assert_eq!(img.color(), image::ColorType::L8);
    let back = img.to_luma8();
    assert_eq!(back.dimensions(), (9, 6));
    assert_eq!(back.into_raw(), codes.iter().copied().collect::<Vec<_>>());
    // Non-contiguous view.
    let p = dir.join("phase_t.png");
    save_u8_png(&p, codes.t()).unwrap();
    let back = image::open(&p).unwrap().to_luma8();
    assert_eq!(back.dimensions(), (6, 9));
    assert_eq!(
        back.into_raw(),
        codes.t().iter().copied().collect::<Vec<_>>()
    );
    assert!(save_u8_png(&p, Array2::<u8>::zeros((0, 3)).view()).is_err());
}

/// `p` (absolute) spelled relative to the current directory, starting with `./` and using `..`.
fn relative_to_cwd(p: &Path) -> PathBuf {
    let cwd = std::env::current_dir().unwrap().canonicalize().unwrap();
    let p = p.canonicalize().unwrap();
    let common = cwd
        .components()
        .zip(p.components())
        .take_while(|(a, b)| a == b)
        .count();
    let mut rel = PathBuf::from(".");
    for _ in common..cwd.components().count() {
        rel.push("..");
    }
    for c in p.components().skip(common) {
        rel.push(c);
    }
    rel
}

#[test]
fn ensure_not_input_sees_through_path_spellings() {
    let dir = scratch("overwrite_guard");
    fs::create_dir_all(dir.join("sub")).unwrap();
    let input = dir.join("f.png");
    fs::write(&input, b"x").unwrap();
    let other = dir.join("g.png");
    fs::write(&other, b"y").unwrap();

    let dotted = dir.join(".").join("f.png");
    let dotdot = dir.join("sub").join("..").join("f.png");
    for out in [&input, &dotted, &dotdot] {
        match ensure_not_input(out, &[&other, &input]) {
            Err(HoloError::WouldOverwriteInput(p)) => assert_eq!(&p, out),
            r => panic!("{} should be refused, got {r:?}", out.display()),
        }
    }
    ensure_not_input(&other, &[&input]).unwrap();
    ensure_not_input(&dir.join("new.png"), &[&input, &other]).unwrap();
    ensure_not_input(&input, &[]).unwrap();

    // Neither side exists yet: compared after lexical normalisation under the existing parent.
    let a = dir.join("sub").join("..").join("later.npy");
    let b = dir.join("later.npy");
    assert!(ensure_not_input(&a, &[&b]).is_err());
    assert!(ensure_not_input(&dir.join("missing").join("..").join("f.png"), &[&input]).is_err());

    // Relative spelling from the current directory (`./../target/…` from `sdk/`).
    let rel = relative_to_cwd(&input);
    assert!(rel.is_relative());
    assert!(ensure_not_input(&rel, &[&input]).is_err());
    assert!(ensure_not_input(&input, &[&rel]).is_err());
    ensure_not_input(&relative_to_cwd(&other), &[&rel]).unwrap();

    #[cfg(unix)]
    {
        let link = dir.join("link.png");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        assert!(ensure_not_input(&link, &[&input]).is_err());
        let hard = dir.join("hard.png");
        fs::hard_link(&input, &hard).unwrap();
        assert!(ensure_not_input(&hard, &[&input]).is_err());
    }
}

#[test]
fn a_huge_declared_shape_is_refused_before_anything_is_allocated() {
    // A few bytes of data under a header declaring 3·10^15 (or overflowing) elements, in both byte orders:
    // refused from the bytes the file holds, without allocating the declared array (which would abort).
    let dir = scratch("huge_shape");
    for (descr, shape, needle) in [
        ("<c8", "(3, 1000000, 1000000000)", "more bytes"),
        (">c8", "(3, 1000000, 1000000000)", "more bytes"),
        ("<c8", "(3, 18446744073709551615, 2)", "overflow"),
        (">c16", "(1000000, 1000000)", "more bytes"),
    ] {
        let p = dir.join(format!(
            "huge{}.npy",
            &descr[..1].replace('<', "le").replace('>', "be")
        ));
        fs::write(&p, npy_bytes(descr, false, shape, &[0u8; 16])).unwrap();
        assert_npy_error(&p, needle);
    }
    // One byte short of a valid file: missing data, named.
    let p = dir.join("short.npy");
    fs::write(&p, npy_bytes(">c8", false, "(2, 2)", &[0u8; 31])).unwrap();
    assert_npy_error(&p, "more bytes");
}

#[test]
fn npy_bytes_parse_at_any_alignment_in_both_byte_orders() {
    // `parse_complex_npy` views the data in place, which needs alignment: a caller's buffer starting at an odd
    // address (a subslice, a network packet) must give the same field as the file, for either byte order.
    let vals: Vec<Complex32> = (0..6)
        .map(|i| Complex32::new(i as f32 + 0.25, -(i as f32)))
        .collect();
    for (descr, to_bytes) in [
        ("<c8", f32::to_le_bytes as fn(f32) -> [u8; 4]),
        (">c8", f32::to_be_bytes as fn(f32) -> [u8; 4]),
    ] {
        let data: Vec<u8> = vals
            .iter()
            .flat_map(|z| [to_bytes(z.re), to_bytes(z.im)].concat())
            .collect();
        let file = npy_bytes(descr, false, "(1, 2, 3)", &data);
        for shift in 0..8 {
            let mut buffer = vec![0xAAu8; shift];
            buffer.extend_from_slice(&file);
            let a = parse_complex_npy(&buffer[shift..], Path::new("packet")).unwrap();
            assert_eq!(a.dim(), (1, 2, 3), "{descr} at +{shift}");
            assert_eq!(
                a.iter().copied().collect::<Vec<_>>(),
                vals,
                "{descr} +{shift}"
            );
        }
        // Truncated by one byte at an odd offset: refused, naming the source.
        let mut buffer = vec![0u8; 3];
        buffer.extend_from_slice(&file[..file.len() - 1]);
        match parse_complex_npy(&buffer[3..], Path::new("packet")) {
            Err(HoloError::Npy { path, reason }) => {
                assert_eq!(path, Path::new("packet"));
                assert!(reason.contains("more bytes"), "{reason}");
            }
            other => panic!("{descr}: expected an Npy error, got {other:?}"),
        }
    }
}

#[test]
fn a_npy_header_length_beyond_the_file_is_refused_without_allocating_it() {
    // Found by the `npy` fuzz target: 17 bytes of format version 3 declaring a 4 GB header made ndarray-npy
    // allocate 4 GB before reading it. Refused from the length, naming the source.
    let bytes = fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/fuzz/npy/oom-v3-header-length-4gb"
    ))
    .unwrap();
    assert_eq!(bytes.len(), 17);
    match parse_complex_npy(&bytes, Path::new("tiny.npy")) {
        Err(HoloError::Npy { path, reason }) => {
            assert_eq!(path, Path::new("tiny.npy"));
            assert!(reason.contains("header declares"), "{reason}");
        }
        other => panic!("expected an Npy error, got {other:?}"),
    }
    // Version 1 (u16 length) and 2 (u32) likewise.
    for (version, len) in [(1u8, vec![0xff, 0x7f]), (2, vec![0xff, 0xff, 0xff, 0x7f])] {
        let mut b = b"\x93NUMPY".to_vec();
        b.extend([version, 0]);
        b.extend(len);
        b.extend(b"{'descr'");
        let e = parse_complex_npy(&b, Path::new("v.npy")).unwrap_err();
        assert!(e.to_string().contains("header declares"), "{e}");
    }
}

/// Issue 80: outputs look at what is at their path first. A character device or a FIFO with a reader is
/// written straight into, a FIFO with no reader, a block device or a socket is refused naming the path and what
/// it is; none is ever renamed over nor removed, itself or at the end of a symbolic link (docs/INPUTS.md,
/// "Outputs"). Before, every writer renamed a temporary file over the path: the node became a regular file.
#[cfg(target_os = "linux")]
mod output_nodes {
    use std::fs;
    use std::io::Read;
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    use std::path::{Path, PathBuf};
    use std::time::Duration;

    use ndarray::{Array2, Array3};
    use tensorholo::io::{
        save_u8_png, write_atomic, write_complex_npy, write_f32_npy, write_f32_npy_streaming,
    };
    use tensorholo::{Complex32, HoloError, Result};

    const O_NONBLOCK: i32 = 0o4000;

    /// A writer of one output file.
    type Writer = fn(&Path) -> Result<()>;

    /// Every single-file writer of the SDK, by name, writing `path`.
    fn writers() -> Vec<(&'static str, Writer)> {
        vec![
            ("write_atomic", |p| write_atomic(p, b"{\"a\": 1}\n")),
            ("write_complex_npy", |p| {
                write_complex_npy(p, Array3::<Complex32>::zeros((1, 4, 4)).view())
            }),
            ("write_f32_npy", |p| {
                write_f32_npy(p, Array2::<f32>::zeros((4, 4)).view())
            }),
            ("write_f32_npy_streaming", |p| {
                write_f32_npy_streaming(p, &[4, 4], 4, |_, b| {
                    b.fill(1.0);
                    Ok(())
                })
            }),
            ("save_u8_png", |p| {
                save_u8_png(p, Array2::<u8>::zeros((4, 4)).view())
            }),
        ]
    }

    fn scratch(name: &str) -> PathBuf {
        super::scratch(&format!("nodes-{name}"))
    }

    fn mkfifo(path: &Path) {
        let ok = std::process::Command::new("mkfifo")
            .arg(path)
            .status()
            .unwrap();
        assert!(ok.success(), "mkfifo {}", path.display());
    }

    /// `mknod PATH KIND MAJOR MINOR`; false (with a message) where it cannot be made (not root, a `nodev` file
    /// system).
    fn mknod(path: &Path, kind: &str, major: u32, minor: u32) -> bool {
        let made = std::process::Command::new("mknod")
            .arg(path)
            .args([kind, &major.to_string(), &minor.to_string()])
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if !made {
            eprintln!(
                "skipped: cannot mknod {} {kind} here (not root, or the folder's file system forbids nodes)",
                path.display()
            );
        }
        made
    }

    /// Runs `f` on a thread, failing the test if it has not returned within 20 s (a write waiting on a FIFO).
    fn within_time<T: Send + 'static>(what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(f());
        });
        rx.recv_timeout(Duration::from_secs(20))
            .unwrap_or_else(|_| panic!("{what} did not return: it waits"))
    }

    fn file_type(path: &Path) -> fs::FileType {
        fs::metadata(path).unwrap().file_type()
    }

    fn is_link(path: &Path) -> bool {
        fs::symlink_metadata(path).unwrap().file_type().is_symlink()
    }

    /// The refusal names the path and `what`, and leaves nothing beside it.
    fn assert_refused(e: HoloError, path: &Path, what: &str) {
        let text = e.to_string();
        assert!(
            text.contains(&path.display().to_string()) && text.contains(what),
            "{text}"
        );
        assert!(matches!(e, HoloError::InvalidData(_)), "{e:?}");
    }

    fn no_temporaries(dir: &Path) {
        let left: Vec<_> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .filter(|n| n.to_string_lossy().contains(".tmp-"))
            .collect();
        assert!(left.is_empty(), "temporary files left: {left:?}");
    }

    #[test]
    fn a_fifo_with_no_reader_is_refused_at_once_itself_or_through_a_link() {
        let dir = scratch("fifo-no-reader");
        let fifo = dir.join("out.fifo");
        mkfifo(&fifo);
        let link = dir.join("link.json");
        std::os::unix::fs::symlink(&fifo, &link).unwrap();
        for (name, write) in writers() {
            for path in [fifo.clone(), link.clone()] {
                let p = path.clone();
                let e = within_time(name, move || write(&p))
                    .expect_err(&format!("{name} wrote into a FIFO with no reader"));
                assert_refused(e, &path, "a FIFO with no reader");
                assert!(file_type(&fifo).is_fifo(), "{name}: the FIFO was replaced");
                assert!(is_link(&link), "{name}: the link was replaced");
            }
        }
        no_temporaries(&dir);
    }

    #[test]
    fn a_fifo_with_a_reader_is_written_into_itself_or_through_a_link() {
        let dir = scratch("fifo-reader");
        let fifo = dir.join("out.fifo");
        mkfifo(&fifo);
        let link = dir.join("link.npy");
        std::os::unix::fs::symlink(&fifo, &link).unwrap();
        // The read end, opened first (non-blocking, so that it needs no writer to open).
        let mut reader = fs::OpenOptions::new()
            .read(true)
            .custom_flags(O_NONBLOCK)
            .open(&fifo)
            .unwrap();
        for (name, write) in writers() {
            for path in [fifo.clone(), link.clone()] {
                let p = path.clone();
                within_time(name, move || write(&p)).unwrap_or_else(|e| panic!("{name}: {e}"));
                let mut got = Vec::new();
                let _ = reader.read_to_end(&mut got);
                assert!(
                    !got.is_empty(),
                    "{name} wrote nothing into {}",
                    path.display()
                );
                assert!(file_type(&fifo).is_fifo(), "{name}: the FIFO was replaced");
                assert!(is_link(&link), "{name}: the link was replaced");
            }
        }
        // More than a pipe holds (64 KiB): the write waits for the reader, which takes it all.
        let big = Array3::<Complex32>::from_elem((1, 256, 256), Complex32::new(1.0, -1.0));
        let expected = 256 * 256 * 8;
        let p = fifo.clone();
        let writer = std::thread::spawn(move || write_complex_npy(&p, big.view()));
        let mut got = Vec::new();
        let mut buf = vec![0u8; 1 << 16];
        loop {
            match reader.read(&mut buf) {
                Ok(n) if n > 0 => got.extend_from_slice(&buf[..n]),
                // Empty: done once the writer is (its data was read before the pipe emptied).
                _ if writer.is_finished() => break,
                _ => std::thread::sleep(Duration::from_millis(1)),
            }
        }
        writer.join().unwrap().unwrap();
        assert!(
            got.len() > expected && got.starts_with(b"\x93NUMPY"),
            "{}",
            got.len()
        );
        no_temporaries(&dir);
    }

    #[test]
    fn a_character_device_is_written_into_through_a_link_or_made_with_mknod() {
        let dir = scratch("char");
        let null_link = dir.join("null.json");
        std::os::unix::fs::symlink("/dev/null", &null_link).unwrap();
        let full_link = dir.join("full.json");
        std::os::unix::fs::symlink("/dev/full", &full_link).unwrap();
        for (name, write) in writers() {
            write(&null_link).unwrap_or_else(|e| panic!("{name} into /dev/null: {e}"));
            assert!(
                is_link(&null_link),
                "{name}: the link to /dev/null was replaced"
            );
            assert!(file_type(Path::new("/dev/null")).is_char_device());
            // /dev/full takes no byte: the write fails, naming the path, and the device stays.
            let e = write(&full_link).expect_err(&format!("{name} into /dev/full"));
            assert!(e.to_string().contains("full.json"), "{e}");
            assert!(
                is_link(&full_link),
                "{name}: the link to /dev/full was replaced"
            );
            assert!(file_type(Path::new("/dev/full")).is_char_device());
        }
        let node = dir.join("null-node");
        if mknod(&node, "c", 1, 3) {
            for (name, write) in writers() {
                write(&node).unwrap_or_else(|e| panic!("{name} into a char device: {e}"));
                assert!(
                    file_type(&node).is_char_device(),
                    "{name} replaced the device"
                );
            }
        }
        no_temporaries(&dir);
    }

    #[test]
    fn a_block_device_and_a_socket_are_refused_naming_them_itself_or_through_a_link() {
        let dir = scratch("block-socket");
        let socket = dir.join("out.sock");
        let _listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
        let socket_link = dir.join("socket.json");
        std::os::unix::fs::symlink(&socket, &socket_link).unwrap();
        let mut cases = vec![
            (socket.clone(), "a socket"),
            (socket_link.clone(), "a socket"),
        ];
        let block = dir.join("block");
        if mknod(&block, "b", 7, 0) {
            let block_link = dir.join("block.json");
            std::os::unix::fs::symlink(&block, &block_link).unwrap();
            cases.push((block.clone(), "a block device"));
            cases.push((block_link, "a block device"));
        }
        for (name, write) in writers() {
            for (path, what) in &cases {
                let e = write(path).expect_err(&format!("{name} wrote onto {what}"));
                assert_refused(e, path, what);
                let t = file_type(path);
                assert!(
                    t.is_socket() || t.is_block_device(),
                    "{name} replaced {what}"
                );
            }
        }
        assert!(is_link(&socket_link));
        no_temporaries(&dir);
    }

    #[test]
    fn remove_output_leaves_nodes_and_standard_streams_removes_files_and_links() {
        use tensorholo::io::remove_output;
        let dir = scratch("remove");
        let fifo = dir.join("fifo");
        mkfifo(&fifo);
        let null = dir.join("null");
        std::os::unix::fs::symlink("/dev/null", &null).unwrap();
        let stdout = dir.join("stdout");
        std::os::unix::fs::symlink("/proc/self/fd/1", &stdout).unwrap();
        let fd = dir.join("fd1");
        std::os::unix::fs::symlink("/dev/fd/1", &fd).unwrap();
        for kept in [&fifo, &null, &stdout, &fd] {
            remove_output(kept).unwrap();
            assert!(
                fs::symlink_metadata(kept).is_ok(),
                "{} removed",
                kept.display()
            );
        }
        let file = dir.join("report.json");
        fs::write(&file, "{}").unwrap();
        let link = dir.join("link.json");
        std::os::unix::fs::symlink(&file, &link).unwrap();
        remove_output(&link).unwrap();
        assert!(
            fs::symlink_metadata(&link).is_err() && file.is_file(),
            "the link, not its file"
        );
        remove_output(&file).unwrap();
        assert!(!file.exists());
        remove_output(&file).unwrap();
    }

    #[test]
    fn a_standard_stream_that_leads_nowhere_is_refused_not_replaced() {
        let dir = scratch("closed-stream");
        let link = dir.join("stdout");
        // No process keeps fd 987 open: the link through /proc leads nowhere.
        std::os::unix::fs::symlink("/proc/self/fd/987", &link).unwrap();
        for (name, write) in writers() {
            let e = write(&link).expect_err(name);
            assert_refused(e, &link, "a standard stream that leads nowhere");
            assert!(is_link(&link), "{name} replaced the link");
        }
        no_temporaries(&dir);
    }

    #[test]
    fn links_to_files_folders_and_nothing_are_replaced_not_followed() {
        let dir = scratch("links");
        let target = dir.join("target.txt");
        fs::write(&target, "keep").unwrap();
        let sub = dir.join("sub");
        fs::create_dir(&sub).unwrap();
        for (name, write) in writers() {
            for to in [target.as_path(), sub.as_path(), Path::new("/nonexistent/x")] {
                let link = dir.join("link");
                let _ = fs::remove_file(&link);
                std::os::unix::fs::symlink(to, &link).unwrap();
                write(&link)
                    .unwrap_or_else(|e| panic!("{name} over a link to {}: {e}", to.display()));
                assert!(fs::symlink_metadata(&link).unwrap().is_file(), "{name}");
            }
        }
        assert_eq!(fs::read_to_string(&target).unwrap(), "keep");
        assert_eq!(fs::read_dir(&sub).unwrap().count(), 0);
        // A folder itself is refused, naming it.
        let e = write_atomic(&sub, b"x").unwrap_err();
        assert_refused(e, &sub, "is a folder");
        no_temporaries(&dir);
    }
}
