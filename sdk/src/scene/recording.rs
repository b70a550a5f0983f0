//! Phone RGB-D recordings as the apps export them (cargo feature `research`), listed frame by frame for
//! [`crate::scene::load_rgbd_with_confidence`]:
//!
//! | app | layout | depth | confidence | time |
//! |---|---|---|---|---|
//! | Record3D ("EXR + JPG" export) | `rgb/N.jpg`, `depth/N.exr`, `metadata.json` (or `metadata`) | float metres, OpenEXR ([`DepthEncoding::Metres`]) | `confidence/N.png` where present | `frameTimestamps`, `fps` |
//! | Stray Scanner | `rgb/NNNNNN.png` (extracted from `rgb.mp4`), `depth/NNNNNN.png`, `camera_matrix.csv`, `odometry.csv` | 16-bit millimetres ([`DepthEncoding::Millimetres16`]) | `confidence/NNNNNN.png` (0/1/2) | `odometry.csv`'s `timestamp` per `frame` |
//!
//! Stray Scanner keeps its colour as a video (`rgb.mp4`); extract its frames first, numbered from 0 as its
//! depth files are: `ffmpeg -i rgb.mp4 -start_number 0 rgb/%06d.png`. Frames pair by the number in their file
//! names (`7.jpg` and `000007.png` are frame 7) and run in the order of the recording's timestamps, or of
//! their numbers where it has none.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::depth::DepthEncoding;
use crate::error::{HoloError, Result};

/// Which app's layout a recording folder has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RecordingKind {
    /// Record3D's "EXR + JPG" export.
    Record3d,
    /// Stray Scanner's folder, colour frames extracted into `rgb/`.
    StrayScanner,
    /// A folder of colour frames and one of depth frames paired by file stem
    /// ([`super::frame_folders::open_frame_folders`]).
    FrameFolders,
}

/// One frame of a [`Recording`]: its files and time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordingFrame {
    /// The number in its file names.
    pub number: u64,
    /// The colour image.
    pub rgb: PathBuf,
    /// The depth map (the recording's [`Recording::encoding`]).
    pub depth: PathBuf,
    /// The depth map's confidence map, where the recording has one.
    pub confidence: Option<PathBuf>,
    /// Seconds on the recording's clock, where it gives them.
    pub time_s: Option<f64>,
}

/// A phone recording's frames in time order, their depth encoding, and what the app recorded about them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Recording {
    /// The app's layout.
    pub kind: RecordingKind,
    /// The folder.
    pub dir: PathBuf,
    /// How its depth files store depth.
    pub encoding: DepthEncoding,
    /// The frames, in time order.
    pub frames: Vec<RecordingFrame>,
    /// Frames per second: the app's figure (Record3D), else from the timestamps.
    pub fps: Option<f64>,
    /// The colour camera's intrinsics `[fx, fy, cx, cy]` in colour pixels, where recorded.
    pub intrinsics: Option<[f64; 4]>,
}

/// Record3D's `metadata.json`: what this reader uses of it (other keys are kept by the app and ignored).
#[derive(Debug, Deserialize)]
struct Record3dMetadata {
    /// Intrinsic matrix, column-major: `[fx, 0, 0, 0, fy, 0, cx, cy, 1]`.
    #[serde(rename = "K", default)]
    k: Option<[f64; 9]>,
    #[serde(default)]
    fps: Option<f64>,
    #[serde(rename = "frameTimestamps", default)]
    frame_timestamps: Option<Vec<f64>>,
}

/// What the entry at `path` is, for a message: "a folder", "a file", "a character device", "a FIFO", "a
/// socket", "a block device", a symbolic link followed to say what it leads to ("a symbolic link to a
/// character device"), "a looping symbolic link" or "a dangling symbolic link". `None` where nothing is there.
fn entry_kind(path: &Path) -> Option<String> {
    let entry = std::fs::symlink_metadata(path).ok()?;
    if !entry.file_type().is_symlink() {
        return Some(type_name(entry.file_type()).into());
    }
    Some(match std::fs::metadata(path) {
        Ok(target) => format!("a symbolic link to {}", type_name(target.file_type())),
        // ELOOP: too many levels of symbolic links.
        Err(e) if e.raw_os_error() == Some(40) => "a looping symbolic link".into(),
        Err(_) => match std::fs::read_link(path) {
            Ok(to) => format!("a dangling symbolic link (to `{}`)", to.display()),
            Err(_) => "a dangling symbolic link".into(),
        },
    })
}

fn type_name(t: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_char_device() {
            return "a character device";
        } else if t.is_block_device() {
            return "a block device";
        } else if t.is_fifo() {
            return "a FIFO";
        } else if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a folder"
    } else if t.is_file() {
        "a file"
    } else {
        "neither a file nor a folder"
    }
}

/// Whether the recording's entry `path` is a file (following links); an error naming what it is when it
/// exists as something else (a folder, a device, a FIFO, a looping or dangling link); `false` when absent.
fn is_file_entry(path: &Path, role: &str) -> Result<bool> {
    if std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return Ok(true);
    }
    match entry_kind(path) {
        None => Ok(false),
        Some(kind) => Err(HoloError::InvalidData(format!(
            "`{}` is {kind}, where {role} must be a file",
            path.display()
        ))),
    }
}

/// Whether the recording's entry `path` is a folder (following links); an error naming what it is when it
/// exists as something else; `false` when absent.
fn is_dir_entry(path: &Path, role: &str) -> Result<bool> {
    if std::fs::metadata(path).is_ok_and(|m| m.is_dir()) {
        return Ok(true);
    }
    match entry_kind(path) {
        None => Ok(false),
        Some(kind) => Err(HoloError::InvalidData(format!(
            "`{}` is {kind}, where {role} must be a folder",
            path.display()
        ))),
    }
}

/// Lists the recording in `dir` (Record3D or Stray Scanner, told apart by their files; see the module docs).
///
/// Errors: [`HoloError::InvalidData`] naming the folder or file: a folder of neither layout (saying what
/// each needs), Stray Scanner's colour still in `rgb.mp4` (with the command that extracts it), a frame file
/// without a number, a frame without its depth (or confidence, where the recording has confidence maps) or
/// depth without a colour frame (naming the frame), no frame, a metadata file that is not the app's (naming
/// the key), timestamps for fewer frames than there are; [`HoloError::Io`] for an unreadable folder or file.
pub fn open_recording(dir: &Path) -> Result<Recording> {
    let bad = |why: String| HoloError::InvalidData(format!("recording `{}`: {why}", dir.display()));
    if !dir.is_dir() {
        return Err(bad(match entry_kind(dir) {
            Some(kind) => format!("not a folder but {kind}"),
            None => "not a folder (nothing is there)".into(),
        }));
    }
    let mut metadata = None;
    for name in ["metadata.json", "metadata"] {
        let path = dir.join(name);
        if metadata.is_none() && is_file_entry(&path, "Record3D's metadata")? {
            metadata = Some(path);
        }
    }
    if let Some(metadata) = metadata {
        return open_record3d(dir, &metadata);
    }
    let mut stray = false;
    for (name, role) in [
        ("camera_matrix.csv", "Stray Scanner's intrinsics"),
        ("odometry.csv", "Stray Scanner's odometry"),
        ("rgb.mp4", "Stray Scanner's colour video"),
    ] {
        stray |= is_file_entry(&dir.join(name), role)?;
    }
    if stray {
        return open_stray_scanner(dir);
    }
    Err(bad(
        "neither a Record3D export (metadata.json, rgb/, depth/ with .exr files) nor a Stray Scanner folder \
         (camera_matrix.csv or odometry.csv, rgb/ extracted from rgb.mp4, depth/, confidence/)"
            .into(),
    ))
}

fn open_record3d(dir: &Path, metadata: &Path) -> Result<Recording> {
    let text = crate::io::read_text(metadata)?;
    let meta: Record3dMetadata = crate::io::parse_json_object(&text, "Record3D's metadata")
        .map_err(|e| HoloError::InvalidData(format!("`{}`: {e}", metadata.display())))?;
    let mut frames = pair_frames(dir, true)?;
    if let Some(times) = &meta.frame_timestamps {
        for f in &mut frames {
            let t = usize::try_from(f.number)
                .ok()
                .and_then(|i| times.get(i))
                .ok_or_else(|| {
                    HoloError::InvalidData(format!(
                        "`{}`: `frameTimestamps` holds {} entries, none for frame {} (`{}`)",
                        metadata.display(),
                        times.len(),
                        f.number,
                        f.rgb.display()
                    ))
                })?;
            f.time_s = Some(*t);
        }
    }
    let intrinsics = meta.k.map(|k| [k[0], k[4], k[6], k[7]]);
    let fps = meta.fps.filter(|f| f.is_finite() && *f > 0.0);
    Ok(finish(
        RecordingKind::Record3d,
        dir,
        DepthEncoding::Metres,
        frames,
        fps,
        intrinsics,
    ))
}

fn open_stray_scanner(dir: &Path) -> Result<Recording> {
    if !is_dir_entry(&dir.join("rgb"), "the recording's `rgb/`")? {
        return Err(HoloError::InvalidData(format!(
            "recording `{}` (Stray Scanner): its colour is the video rgb.mp4; extract its frames into rgb/, \
             numbered from 0 as the depth files are: `ffmpeg -i rgb.mp4 -start_number 0 rgb/%06d.png`",
            dir.display()
        )));
    }
    let mut frames = pair_frames(dir, false)?;
    let odometry = dir.join("odometry.csv");
    if is_file_entry(&odometry, "Stray Scanner's odometry")? {
        let times = read_odometry_times(&odometry)?;
        for f in &mut frames {
            f.time_s = times.get(&f.number).copied();
        }
        if frames.iter().any(|f| f.time_s.is_none()) {
            // A partial clock orders nothing: the numbers do.
            frames.iter_mut().for_each(|f| f.time_s = None);
            log::warn!(
                "`{}` gives no timestamp for some frames: frames run in the order of their numbers",
                odometry.display()
            );
        }
    }
    let camera = dir.join("camera_matrix.csv");
    let intrinsics = if is_file_entry(&camera, "Stray Scanner's intrinsics")? {
        Some(read_camera_matrix(&camera)?)
    } else {
        None
    };
    Ok(finish(
        RecordingKind::StrayScanner,
        dir,
        DepthEncoding::Millimetres16,
        frames,
        None,
        intrinsics,
    ))
}

/// Sorts the frames by time (by number where there is no time) and derives the frame rate from the times
/// where the app gave none.
fn finish(
    kind: RecordingKind,
    dir: &Path,
    encoding: DepthEncoding,
    mut frames: Vec<RecordingFrame>,
    fps: Option<f64>,
    intrinsics: Option<[f64; 4]>,
) -> Recording {
    frames.sort_by(|a, b| {
        a.time_s
            .unwrap_or(0.0)
            .total_cmp(&b.time_s.unwrap_or(0.0))
            .then(a.number.cmp(&b.number))
    });
    let fps = fps.or_else(|| {
        let (first, last) = (frames.first()?.time_s?, frames.last()?.time_s?);
        (frames.len() > 1 && last > first).then(|| (frames.len() - 1) as f64 / (last - first))
    });
    // A span of 1e-300 s is positive, but no frame rate.
    let fps = fps.filter(|f| f.is_finite() && *f > 0.0);
    Recording {
        kind,
        dir: dir.to_path_buf(),
        encoding,
        frames,
        fps,
        intrinsics,
    }
}

/// The files of `dir/sub` by the number in their names (hidden files left out). `None` where the folder
/// does not exist.
fn numbered(dir: &Path, sub: &str) -> Result<Option<BTreeMap<u64, PathBuf>>> {
    let folder = dir.join(sub);
    if !is_dir_entry(&folder, &format!("the recording's `{sub}/`"))? {
        return Ok(None);
    }
    let entries = std::fs::read_dir(&folder).map_err(|source| HoloError::Io {
        path: folder.clone(),
        source,
    })?;
    let mut out = BTreeMap::new();
    for entry in entries {
        let path = entry
            .map_err(|source| HoloError::Io {
                path: folder.clone(),
                source,
            })?
            .path();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        if name.as_deref().is_none_or(|n| n.starts_with('.')) {
            continue;
        }
        // A frame file that is a folder, a device, a FIFO or a broken link is named for what it is, not
        // taken as missing.
        is_file_entry(&path, "a frame")?;
        let number = path
            .file_stem()
            .and_then(|s| s.to_str())
            .filter(|s| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|s| s.parse::<u64>().ok())
            .ok_or_else(|| {
                HoloError::InvalidData(format!(
                    "`{}`: a recording's frame files are named by their number (`12.jpg`, `000012.png`)",
                    path.display()
                ))
            })?;
        if let Some(other) = out.insert(number, path.clone()) {
            return Err(HoloError::InvalidData(format!(
                "`{}` and `{}` are both frame {number}",
                other.display(),
                path.display()
            )));
        }
    }
    Ok(Some(out))
}

/// Pairs `rgb/`, `depth/` and, where it exists, `confidence/` by frame number; `exr_depth`: Record3D's depth
/// files must be OpenEXR.
fn pair_frames(dir: &Path, exr_depth: bool) -> Result<Vec<RecordingFrame>> {
    let missing = |sub: &str| {
        HoloError::InvalidData(format!(
            "recording `{}` has no {sub}/ folder",
            dir.display()
        ))
    };
    let rgb = numbered(dir, "rgb")?.ok_or_else(|| missing("rgb"))?;
    let depth = numbered(dir, "depth")?.ok_or_else(|| missing("depth"))?;
    let confidence = numbered(dir, "confidence")?;
    let mut frames = Vec::with_capacity(rgb.len());
    for (&number, rgb_path) in &rgb {
        let depth_path = depth.get(&number).ok_or_else(|| {
            HoloError::InvalidData(format!(
                "frame {number}: `{}` has no depth map in `{}`",
                rgb_path.display(),
                dir.join("depth").display()
            ))
        })?;
        if exr_depth
            && !depth_path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
        {
            return Err(HoloError::InvalidData(format!(
                "frame {number}: `{}` is not an .exr file (Record3D's export stores depth as OpenEXR: choose \
                 \"EXR + JPG\" when exporting)",
                depth_path.display()
            )));
        }
        let confidence_path = match &confidence {
            Some(c) => Some(c.get(&number).cloned().ok_or_else(|| {
                HoloError::InvalidData(format!(
                    "frame {number}: `{}` has no confidence map in `{}` (the recording has confidence maps for \
                     other frames)",
                    rgb_path.display(),
                    dir.join("confidence").display()
                ))
            })?),
            None => None,
        };
        frames.push(RecordingFrame {
            number,
            rgb: rgb_path.clone(),
            depth: depth_path.clone(),
            confidence: confidence_path,
            time_s: None,
        });
    }
    if let Some((&number, path)) = depth.iter().find(|(n, _)| !rgb.contains_key(n)) {
        return Err(HoloError::InvalidData(format!(
            "frame {number}: depth map `{}` has no colour frame in `{}`",
            path.display(),
            dir.join("rgb").display()
        )));
    }
    if frames.is_empty() {
        return Err(HoloError::InvalidData(format!(
            "recording `{}` has no frame in rgb/",
            dir.display()
        )));
    }
    Ok(frames)
}

/// The comma-separated numbers of one line of a CSV file.
fn csv_numbers(line: &str) -> Option<Vec<f64>> {
    line.split(',')
        .map(|v| v.trim().parse::<f64>().ok())
        .collect()
}

/// Stray Scanner's `odometry.csv`: a header, then `timestamp, frame, x, y, z, qx, qy, qz, qw` per frame.
fn read_odometry_times(path: &Path) -> Result<BTreeMap<u64, f64>> {
    let text = crate::io::read_text(path)?;
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<String> = lines
        .next()
        .unwrap_or_default()
        .split(',')
        .map(|h| h.trim().to_ascii_lowercase())
        .collect();
    let column = |name: &str| header.iter().position(|h| h == name);
    let (Some(t), Some(f)) = (column("timestamp"), column("frame")) else {
        return Err(HoloError::InvalidData(format!(
            "`{}`: its header names no `timestamp` and `frame` columns (Stray Scanner's odometry)",
            path.display()
        )));
    };
    let mut rows: BTreeMap<u64, (f64, usize)> = BTreeMap::new();
    for (i, line) in lines.enumerate() {
        let values = csv_numbers(line)
            .filter(|v| v.len() > t.max(f))
            .ok_or_else(|| {
                HoloError::InvalidData(format!(
                    "`{}`, line {}: not {} comma-separated numbers",
                    path.display(),
                    i + 2,
                    header.len()
                ))
            })?;
        let frame = values[f];
        if !(frame >= 0.0 && frame.fract() == 0.0 && values[t].is_finite()) {
            return Err(HoloError::InvalidData(format!(
                "`{}`, line {}: frame {frame} at {} s is not a frame number and a time",
                path.display(),
                i + 2,
                values[t]
            )));
        }
        let line = i + 2;
        if let Some((_, first)) = rows.insert(frame as u64, (values[t], line)) {
            return Err(HoloError::InvalidData(format!(
                "`{}`, line {line}: frame {frame} is listed twice (first on line {first})",
                path.display()
            )));
        }
    }
    // Frames run in timestamp order, in any order in the file; two frames at one time have no order, and a
    // span that overflows has no frame rate.
    let mut by_time: Vec<(f64, u64, usize)> =
        rows.iter().map(|(&f, &(t, line))| (t, f, line)).collect();
    by_time.sort_by(|a, b| a.0.total_cmp(&b.0));
    if let Some(w) = by_time.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(HoloError::InvalidData(format!(
            "`{}`: frames {} (line {}) and {} (line {}) are both at {} s: two frames at one timestamp",
            path.display(),
            w[0].1,
            w[0].2,
            w[1].1,
            w[1].2,
            w[0].0
        )));
    }
    if let (Some(first), Some(last)) = (by_time.first(), by_time.last()) {
        let span = last.0 - first.0;
        if by_time.len() > 1 && !(span.is_finite() && span > 0.0) {
            return Err(HoloError::InvalidData(format!(
                "`{}`: its timestamps span {span} s (first {} s, last {} s): not a finite, positive time",
                path.display(),
                first.0,
                last.0
            )));
        }
    }
    Ok(rows.into_iter().map(|(f, (t, _))| (f, t)).collect())
}

/// Stray Scanner's `camera_matrix.csv`: the 3 × 3 intrinsic matrix, one row per line.
fn read_camera_matrix(path: &Path) -> Result<[f64; 4]> {
    let text = crate::io::read_text(path)?;
    let rows: Option<Vec<Vec<f64>>> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(csv_numbers)
        .collect();
    match rows.as_deref() {
        Some([a, b, c]) if a.len() == 3 && b.len() == 3 && c.len() == 3 => {
            let k = [a[0], b[1], a[2], b[2]];
            if k.iter().all(|v| v.is_finite()) && k[0] > 0.0 && k[1] > 0.0 {
                Ok(k)
            } else {
                Err(HoloError::InvalidData(format!(
                    "`{}`: focal lengths {} and {} px, centre ({}, {}) px: intrinsics are finite, with positive \
                     focal lengths",
                    path.display(),
                    k[0],
                    k[1],
                    k[2],
                    k[3]
                )))
            }
        }
        _ => Err(HoloError::InvalidData(format!(
            "`{}`: not a 3 × 3 matrix of comma-separated numbers (Stray Scanner's intrinsics)",
            path.display()
        ))),
    }
}
