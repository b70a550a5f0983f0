//! Frame folders as a recording ([`RecordingKind::FrameFolders`]): a folder of colour frames and one of depth
//! frames (and optionally one of confidence maps), paired by file stem in name order — the layout a capture
//! script or a dataset (TUM, Redwood, a RealSense dump) leaves, read as [`open_recording`] reads an app's export.
//!
//! [`open_recording`]: super::recording::open_recording

use std::collections::HashMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};

use super::depth::DepthEncoding;
use super::recording::{Recording, RecordingFrame, RecordingKind};
use crate::error::{HoloError, Result};

/// The folders of a frame-folder sequence ([`open_frame_folders`]).
#[derive(Debug, Clone, Copy)]
pub struct FrameFolders<'a> {
    /// Colour frames (PNG, JPEG or PPM).
    pub rgb: &'a Path,
    /// Depth frames with the same file stems as the colour frames.
    pub depth: &'a Path,
    /// Confidence maps (8-bit, at the depth maps' resolution) with the same stems as the depth frames.
    pub confidence: Option<&'a Path>,
    /// How the depth frames store depth.
    pub encoding: DepthEncoding,
    /// Leave out a frame of either folder without a partner of the same stem (with a warning) instead of
    /// refusing the sequence.
    pub skip_unmatched: bool,
}

/// The frames of `folders` paired by file stem, in name order (hidden files such as `.DS_Store` ignored), as
/// a [`Recording`] of kind [`RecordingKind::FrameFolders`]: `dir` the colour folder, each frame's `number`
/// its place in name order, no times, no frame rate, no intrinsics.
///
/// Errors: [`HoloError::InvalidData`] naming the files: a frame of either folder without a partner of the same
/// stem (up to five named; unless `skip_unmatched`), no pair at all, a depth frame without a confidence map
/// of its stem; [`HoloError::Io`] for a folder that cannot be read.
pub fn open_frame_folders(folders: &FrameFolders<'_>) -> Result<Recording> {
    let (rgbs, depths) = (list_files(folders.rgb)?, list_files(folders.depth)?);
    let (rgb_stems, depth_stems) = (by_stem(&rgbs), by_stem(&depths));
    let mut pairs = Vec::new();
    let mut unmatched = Vec::new();
    for rgb in &rgbs {
        match rgb.file_stem().and_then(|s| depth_stems.get(s)) {
            Some(d) => pairs.push((rgb.clone(), d.clone())),
            None => unmatched.push(rgb.clone()),
        }
    }
    unmatched.extend(
        depths
            .iter()
            .filter(|d| d.file_stem().is_none_or(|s| !rgb_stems.contains_key(s)))
            .cloned(),
    );
    if !unmatched.is_empty() {
        let list = name_list(&unmatched);
        if !folders.skip_unmatched {
            return Err(HoloError::InvalidData(format!(
                "{} file(s) have no partner of the same name stem in the other folder: {list}; pair them, or \
                 leave them out (`skip_unmatched`, holo video --skip-unmatched)",
                unmatched.len()
            )));
        }
        log::warn!(
            "skipping {} file(s) without a partner: {list}",
            unmatched.len()
        );
    }
    if pairs.is_empty() {
        return Err(HoloError::InvalidData(format!(
            "no RGB frame in {} has a depth frame of the same name stem in {}",
            folders.rgb.display(),
            folders.depth.display()
        )));
    }
    let maps = match folders.confidence {
        Some(dir) => Some((dir, by_stem(&list_files(dir)?))),
        None => None,
    };
    let frames = pairs
        .into_iter()
        .enumerate()
        .map(|(i, (rgb, depth))| {
            let confidence = match &maps {
                Some((dir, maps)) => Some(
                    depth
                        .file_stem()
                        .and_then(|s| maps.get(s))
                        .cloned()
                        .ok_or_else(|| {
                            HoloError::InvalidData(format!(
                                "depth frame `{}` has no confidence map of the same name stem in {}",
                                depth.display(),
                                dir.display()
                            ))
                        })?,
                ),
                None => None,
            };
            Ok(RecordingFrame {
                number: i as u64,
                rgb,
                depth,
                confidence,
                time_s: None,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Recording {
        kind: RecordingKind::FrameFolders,
        dir: folders.rgb.to_path_buf(),
        encoding: folders.encoding,
        frames,
        fps: None,
        intrinsics: None,
    })
}

/// The files of `dir`, sorted by name, hidden files (`.DS_Store`) left out.
fn list_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| HoloError::Io {
        path: dir.to_path_buf(),
        source: e,
    })?;
    let mut v: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .filter(|p| {
            !p.file_name()
                .is_some_and(|n| n.as_encoded_bytes().starts_with(b"."))
        })
        .collect();
    v.sort();
    Ok(v)
}

/// The files by stem.
fn by_stem(files: &[PathBuf]) -> HashMap<OsString, PathBuf> {
    files
        .iter()
        .filter_map(|p| Some((p.file_stem()?.to_owned(), p.clone())))
        .collect()
}

/// Up to five names, then how many more.
fn name_list(files: &[PathBuf]) -> String {
    let names: Vec<String> = files
        .iter()
        .take(5)
        .map(|p| p.display().to_string())
        .collect();
    let more = files.len().saturating_sub(5);
    if more > 0 {
        format!("{} and {more} more", names.join(", "))
    } else {
        names.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn touch(dir: &Path, names: &[&str]) {
        std::fs::create_dir_all(dir).unwrap();
        for n in names {
            std::fs::write(dir.join(n), b"x").unwrap();
        }
    }

    /// Pairs by stem in name order whatever the extensions, hidden files ignored; a frame without a partner is
    /// refused naming it, or left out with `skip_unmatched`; confidence maps by the depth's stem.
    #[test]
    fn frame_folders_pair_by_stem_in_name_order() {
        let root = std::env::temp_dir().join(format!("th-folders-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let (rgb, depth, conf) = (root.join("rgb"), root.join("depth"), root.join("conf"));
        touch(
            &rgb,
            &["002.jpg", "000.png", "001.jpg", ".DS_Store", "009.jpg"],
        );
        touch(&depth, &["001.png", "000.png", "002.png"]);
        touch(&conf, &["000.png", "001.png", "002.png"]);
        let mut folders = FrameFolders {
            rgb: &rgb,
            depth: &depth,
            confidence: None,
            encoding: DepthEncoding::Millimetres16,
            skip_unmatched: false,
        };
        let e = open_frame_folders(&folders).unwrap_err().to_string();
        assert!(
            e.contains("009.jpg") && e.contains("--skip-unmatched"),
            "{e}"
        );
        folders.skip_unmatched = true;
        folders.confidence = Some(&conf);
        let r = open_frame_folders(&folders).unwrap();
        assert_eq!(r.kind, RecordingKind::FrameFolders);
        assert_eq!(r.encoding, DepthEncoding::Millimetres16);
        let names: Vec<_> = r
            .frames
            .iter()
            .map(|f| {
                (
                    f.number,
                    f.rgb.file_name().unwrap().to_owned(),
                    f.depth.file_name().unwrap().to_owned(),
                    f.confidence
                        .as_ref()
                        .unwrap()
                        .file_name()
                        .unwrap()
                        .to_owned(),
                )
            })
            .collect();
        assert_eq!(
            names,
            [
                (0, "000.png".into(), "000.png".into(), "000.png".into()),
                (1, "001.jpg".into(), "001.png".into(), "001.png".into()),
                (2, "002.jpg".into(), "002.png".into(), "002.png".into()),
            ]
        );
        // A depth frame without its confidence map is named.
        std::fs::remove_file(conf.join("001.png")).unwrap();
        let e = open_frame_folders(&folders).unwrap_err().to_string();
        assert!(e.contains("001.png") && e.contains("confidence"), "{e}");
        // No pair at all.
        let empty = root.join("empty");
        touch(&empty, &[]);
        folders.depth = &empty;
        let e = open_frame_folders(&folders).unwrap_err().to_string();
        assert!(e.contains("no RGB frame"), "{e}");
        std::fs::remove_dir_all(&root).unwrap();
    }
}
