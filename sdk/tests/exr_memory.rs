//! An OpenEXR depth map is read within the decoders' memory budget whatever channels it declares (issue 80,
//! cause 2): a 32-channel file of 1024² pixels, one of them `Z`, is decoded in its depth channel only. Reading
//! every channel (as before) took 4 + 31 × 2 = 66 bytes a pixel (66 MiB here); the budget is 16 bytes a pixel
//! (16 MiB). Alone in its test binary, so that the process's peak resident memory is this test's.

use std::path::Path;

use exr::prelude::*;
use tensorholo::scene::{decode_depth_bytes, DepthEncoding};

const SIDE: usize = 1024;
/// The budget of every image decoder: 16 bytes a pixel.
const BUDGET_MIB: f64 = (SIDE * SIDE * 16) as f64 / (1 << 20) as f64;

fn status_mib(key: &str) -> Option<f64> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn depth_at(x: usize, y: usize) -> f32 {
    0.5 + ((x * 7 + y * 3) % 101) as f32 * 0.01
}

/// A ZIP-compressed OpenEXR file of `SIDE²` pixels: `Z` (f32 metres) and 31 half-float channels.
fn thirty_two_channels() -> Vec<u8> {
    let z: Vec<f32> = (0..SIDE * SIDE)
        .map(|i| depth_at(i % SIDE, i / SIDE))
        .collect();
    let other = vec![f16::from_f32(0.25); SIDE * SIDE];
    let mut list = vec![AnyChannel::new("Z", FlatSamples::F32(z))];
    for k in 0..31 {
        list.push(AnyChannel::new(
            format!("extra{k:02}").as_str(),
            FlatSamples::F16(other.clone()),
        ));
    }
    let layer = Layer::new(
        (SIDE, SIDE),
        LayerAttributes::default(),
        Encoding {
            compression: Compression::ZIP16,
            blocks: Blocks::ScanLines,
            line_order: LineOrder::Increasing,
        },
        AnyChannels::sort(list.into()),
    );
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(&mut out)
        .unwrap();
    out.into_inner()
}

#[test]
fn a_32_channel_openexr_depth_map_is_read_within_the_decoders_budget() {
    let bytes = thirty_two_channels();
    // The peak from here on (Linux: 5 to clear_refs resets VmHWM).
    let reset = std::fs::write("/proc/self/clear_refs", "5").is_ok();
    let before = status_mib("VmRSS:").expect("/proc/self/status (Linux)");
    let d = decode_depth_bytes(&bytes, Path::new("32.exr"), DepthEncoding::Metres)
        .expect("a 32-channel depth map within the budget decodes");
    let peak = status_mib("VmHWM:").unwrap();
    eprintln!(
        "32-channel {SIDE}² EXR ({} KiB): peak {peak:.0} MiB, {:.1} above the {before:.0} before (reset: {reset}, \
         budget {BUDGET_MIB} MiB)",
        bytes.len() / 1024,
        peak - before
    );
    assert_eq!(d.values.dim(), (SIDE, SIDE));
    for (y, x) in [(0, 0), (17, 900), (SIDE - 1, SIDE - 1), (512, 3)] {
        assert_eq!(d.values[[y, x]], depth_at(x, y), "({y}, {x})");
    }
    assert!(
        peak - before <= BUDGET_MIB,
        "decoding took {:.1} MiB above its start (budget {BUDGET_MIB})",
        peak - before
    );
}
