//! OpenEXR depth maps ([`DepthEncoding::Metres`](super::DepthEncoding::Metres)): float z-depth in metres, as
//! Record3D exports an iPhone's LiDAR depth. Read through the exr crate (cargo feature `research`).

use std::io::Cursor;
use std::path::Path;

use exr::prelude::{read, ReadChannels, ReadLayers, ReadSpecificChannel, Vec2};
use ndarray::Array2;

use crate::error::{HoloError, Result};

/// Channel names taken for depth in a file with several channels, in this order (case-insensitive).
const DEPTH_CHANNELS: [&str; 4] = ["Z", "Y", "R", "depth"];

/// Bytes a decoder may allocate per pixel of the image, and at least (the budget of every image decoder:
/// [`crate::io`]'s PNG and PNM decoding).
const BYTES_PER_PIXEL: u64 = 16;
const BUDGET_FLOOR: u64 = 1 << 20;

/// The samples `[H, W]` of an OpenEXR file's depth channel (see [`DEPTH_CHANNELS`]) of its first layer at the
/// largest resolution, as f32 (half-precision files widened), before any validity rule. Only that channel is
/// read: what the read allocates (the channel, the largest decoded chunk: all its channels × lines × width ×
/// sample size, and the tables of chunk offsets) is counted from the header against the decoders' budget (16
/// bytes a pixel of the image, at least 1 MiB; the size against [`crate::io::InputLimits`]) before any pixel
/// is read. Channels that are skipped only count in that chunk.
///
/// Errors: [`HoloError::InvalidDepth`] naming `source` for a file the exr crate cannot read (truncated,
/// corrupt, deep data), an empty image, subsampled channels, or several channels none of which is named for
/// depth (listing them); [`HoloError::InvalidData`] above the pixel limit or the budget.
pub(crate) fn read_exr_depth(bytes: &[u8], source: &Path) -> Result<Array2<f32>> {
    let bad = |why: String| HoloError::InvalidDepth(format!("`{}`: {why}", source.display()));
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false)
        .map_err(|e| bad(format!("not a readable OpenEXR file ({e})")))?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| bad("an OpenEXR file without a layer".into()))?;
    if header.deep {
        return Err(bad("deep data, not a depth map".into()));
    }
    let (w, h) = (header.layer_size.0, header.layer_size.1);
    let pixels = crate::io::check_image_pixels(source, w as u64, h as u64)?;
    if w == 0 || h == 0 {
        return Err(bad("an empty image".into()));
    }
    let channels = &header.channels.list;
    let channel = if channels.len() == 1 {
        &channels[0]
    } else {
        DEPTH_CHANNELS
            .iter()
            .find_map(|want| {
                channels
                    .iter()
                    .find(|c| c.name.to_string().eq_ignore_ascii_case(want))
            })
            .ok_or_else(|| {
                let names: Vec<String> = channels.iter().map(|c| c.name.to_string()).collect();
                bad(format!(
                    "none of its channels ({}) is a depth channel ({})",
                    names.join(", "),
                    DEPTH_CHANNELS.join(", ")
                ))
            })?
    };
    if let Some(c) = channels.iter().find(|c| c.sampling != Vec2(1, 1)) {
        return Err(bad(format!(
            "channel `{}` is subsampled ({}×{}): subsampled files are not depth maps",
            c.name, c.sampling.0, c.sampling.1
        )));
    }
    // What the read allocates, from the header: the depth channel as f32, the largest chunk decoded (every
    // channel of its lines or tile), and the table of chunk offsets.
    let (block_w, block_h) = match header.blocks {
        exr::meta::BlockDescription::Tiles(t) => (t.tile_size.0.min(w), t.tile_size.1.min(h)),
        exr::meta::BlockDescription::ScanLines => {
            (w, header.compression.scan_lines_per_block().min(h))
        }
    };
    let pixel_bytes: u64 = channels
        .iter()
        .map(|c| c.sample_type.bytes_per_sample() as u64)
        .sum();
    let chunk = (block_w as u64)
        .saturating_mul(block_h as u64)
        .saturating_mul(pixel_bytes);
    let depth_bytes = pixels.saturating_mul(4);
    // The tables of chunk offsets, 8 bytes a chunk of every layer, are read first (a tiny tile makes them
    // large).
    let offsets = meta
        .headers
        .iter()
        .fold(0u64, |n, h| n.saturating_add(h.chunk_count as u64))
        .saturating_mul(8);
    let need = depth_bytes.saturating_add(chunk).saturating_add(offsets);
    let budget = pixels.saturating_mul(BYTES_PER_PIXEL).max(BUDGET_FLOOR);
    if need > budget {
        return Err(HoloError::InvalidData(format!(
            "`{}`: reading its depth channel `{}` takes {need} bytes (the channel's {depth_bytes}, a \
             decoded chunk of {chunk}: {} channels of {pixel_bytes} bytes a pixel × {block_h} lines × {block_w} \
             pixels, and its offset tables' {offsets}), above the decoders' budget of {budget} bytes for a \
             {w}×{h} image ({BYTES_PER_PIXEL} bytes a pixel, at least 1 MiB)",
            source.display(),
            channel.name,
            channels.len(),
        )));
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .specific_channels()
        .required(channel.name.clone())
        .collect_pixels(
            |size: Vec2<usize>, _| (size.0, vec![0f32; size.0 * size.1]),
            |(width, samples): &mut (usize, Vec<f32>), at: Vec2<usize>, (v,): (f32,)| {
                if let Some(s) = samples.get_mut(at.1 * *width + at.0) {
                    *s = v;
                }
            },
        )
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| bad(format!("cannot read its OpenEXR pixels ({e})")))?;
    let layer = image.layer_data;
    let (lw, lh) = (layer.size.0, layer.size.1);
    let (width, samples) = layer.channel_data.pixels;
    if (lw, lh) != (w, h) || width != w || samples.len() != w * h {
        return Err(bad(format!(
            "its layer holds {} samples for {w}×{h} pixels",
            samples.len()
        )));
    }
    Array2::from_shape_vec((h, w), samples)
        .map_err(|e| bad(format!("its samples do not fill {w}×{h} pixels ({e})")))
}
