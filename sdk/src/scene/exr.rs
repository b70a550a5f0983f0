//! OpenEXR depth maps ([`DepthEncoding::Metres`](super::DepthEncoding::Metres)): float z-depth in metres, as
//! Record3D exports an iPhone's LiDAR depth. Read through the exr crate (cargo feature `research`).

use std::io::Cursor;
use std::path::Path;

use exr::prelude::{read, FlatSamples, ReadChannels, ReadLayers};
use ndarray::Array2;

use crate::error::{HoloError, Result};

/// Channel names taken for depth in a file with several channels, in this order (case-insensitive).
const DEPTH_CHANNELS: [&str; 4] = ["Z", "Y", "R", "depth"];

/// The samples `[H, W]` of an OpenEXR file's depth channel (see [`DEPTH_CHANNELS`]) of its first layer at the
/// largest resolution, as f32 (half-precision files widened), before any validity rule. The image size is
/// checked against [`crate::io::InputLimits`] from the header before the pixels are read.
///
/// Errors: [`HoloError::InvalidDepth`] naming `source` for a file the exr crate cannot read (truncated,
/// corrupt, deep data), an empty image, or several channels none of which is named for depth (listing them);
/// [`HoloError::InvalidData`] above the pixel limit.
pub(crate) fn read_exr_depth(bytes: &[u8], source: &Path) -> Result<Array2<f32>> {
    let bad = |why: String| HoloError::InvalidDepth(format!("`{}`: {why}", source.display()));
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false)
        .map_err(|e| bad(format!("not a readable OpenEXR file ({e})")))?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| bad("an OpenEXR file without a layer".into()))?;
    let size = header.layer_size;
    crate::io::check_image_pixels(source, size.0 as u64, size.1 as u64)?;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| bad(format!("cannot read its OpenEXR pixels ({e})")))?;
    let layer = image.layer_data;
    let (w, h) = (layer.size.0, layer.size.1);
    if w == 0 || h == 0 {
        return Err(bad("an empty image".into()));
    }
    let channels = &layer.channel_data.list;
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
    let samples: &FlatSamples = &channel.sample_data;
    if samples.len() != w * h {
        return Err(bad(format!(
            "channel `{}` holds {} samples for {w}×{h} pixels (subsampled channels are not depth maps)",
            channel.name,
            samples.len()
        )));
    }
    Array2::from_shape_vec((h, w), samples.values_as_f32().collect())
        .map_err(|e| bad(format!("its samples do not fill {w}×{h} pixels ({e})")))
}
