//! What an output path names, looked at before anything is written to it (docs/INPUTS.md, "Outputs").
//!
//! - Nothing, a regular file, or a symbolic link to anything but a device, a FIFO or a socket (a file, a
//!   folder, nothing): the output is written atomically, to a temporary file beside it renamed over it; a link
//!   is replaced, not followed.
//! - A character device (`/dev/null`, a terminal), or a FIFO with a reader, itself or at the end of links:
//!   written straight into, never renamed over nor removed (so `--json /dev/stdout` and `--json /dev/null`
//!   work, and root's `/dev/null` stays a device).
//! - A FIFO with no reader: refused, naming the path, without waiting for a reader (opened non-blocking).
//! - A block device or a socket: refused, naming the path and what it is.
//! - A folder: refused, naming it.
//! - A link through `/proc` (`/dev/stdout`, `/dev/fd/N`, `/proc/self/fd/N`): a standard stream, written into
//!   whatever it leads to (a regular file is appended to, as the shell's redirection left it).

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{HoloError, Result};

/// Where an output goes ([`open_output`]).
pub(crate) enum Target {
    /// Written atomically: a temporary file beside the path, renamed over it.
    Replace,
    /// Written straight into this open node (a character device, a FIFO with a reader, a standard stream).
    Stream(NodeWriter),
}

/// An open output node. A FIFO is opened non-blocking (so that one without a reader is refused, not waited
/// on): a write it cannot take yet (a full pipe) is retried until the reader takes it or goes away.
pub(crate) struct NodeWriter {
    file: File,
}

impl Write for NodeWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        loop {
            match self.file.write(buf) {
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    std::thread::sleep(std::time::Duration::from_millis(1))
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                other => return other,
            }
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

/// What kind of node a file type is, for messages; `None` for a regular file, a folder or a link.
#[cfg(unix)]
fn node_kind(t: std::fs::FileType) -> Option<&'static str> {
    use std::os::unix::fs::FileTypeExt;
    if t.is_char_device() {
        Some("a character device")
    } else if t.is_block_device() {
        Some("a block device")
    } else if t.is_fifo() {
        Some("a FIFO")
    } else if t.is_socket() {
        Some("a socket")
    } else {
        None
    }
}

#[cfg(not(unix))]
fn node_kind(_: std::fs::FileType) -> Option<&'static str> {
    None
}

/// What `path` is, when it is something other than a regular file, a folder or nothing: a device, a FIFO or a
/// socket, itself or at the end of its links ("a character device", "a FIFO"…). `None` otherwise.
pub(crate) fn node_at(path: &Path) -> Option<&'static str> {
    std::fs::metadata(path)
        .ok()
        .and_then(|m| node_kind(m.file_type()))
}

/// Removes an output file at `path` that a program wrote or is about to replace (a previous run's report, a
/// failed run's partial output), unless it is what outputs are written into rather than replaced
/// (docs/INPUTS.md, "Outputs"): a device, a FIFO or a socket, itself or at the end of links, or a link
/// through `/proc` (`/dev/stdout`, `/dev/fd/1`, whatever it leads to). Those are left as they are. A link to
/// anything else is removed (the link, not what it leads to). Nothing there is not an error.
///
/// # Errors
/// [`HoloError::Io`] naming `path` if the removal fails.
pub fn remove_output(path: &Path) -> Result<()> {
    let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    if node_at(path).is_some() || (is_link && through_proc(path)) {
        return Ok(());
    }
    match std::fs::remove_file(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(source) => Err(HoloError::Io {
            path: path.to_path_buf(),
            source,
        }),
    }
}

/// A refused output: [`HoloError::InvalidData`] naming the path, then `why` (what it is).
fn refusal(path: &Path, why: String) -> HoloError {
    HoloError::InvalidData(format!("output `{}` {why}", path.display()))
}

/// Whether `path`, or a link on the way from it, lies under `/proc` (`/dev/stdout` → `/proc/self/fd/1`): a
/// standard stream of this process, which is written into whatever it is.
fn through_proc(path: &Path) -> bool {
    if !cfg!(target_os = "linux") {
        return false;
    }
    let under_proc = |p: &Path| {
        p.starts_with("/proc")
            || p.parent()
                .and_then(|d| d.canonicalize().ok())
                .is_some_and(|d| d.starts_with("/proc"))
    };
    let mut p: PathBuf = path.to_path_buf();
    for _ in 0..40 {
        // `/dev/fd/1` lies in `/proc/self/fd` once its folder (a link) is resolved.
        if under_proc(&p) {
            return true;
        }
        match std::fs::read_link(&p) {
            Ok(target) if target.is_absolute() => p = target,
            Ok(target) => p = p.parent().unwrap_or(Path::new("")).join(target),
            Err(_) => return false,
        }
    }
    false
}

/// Looks at what `path` names before an output is written to it, and opens it when it is to be written
/// straight into (the rule in the module docs).
///
/// Errors: [`HoloError::InvalidData`] naming `path` and what it is for a FIFO with no reader, a block device,
/// a socket or a folder; [`HoloError::Io`] naming `path` for a node that cannot be opened for writing.
pub(crate) fn open_output(path: &Path) -> Result<Target> {
    let Ok(entry) = std::fs::symlink_metadata(path) else {
        // Nothing there (or an unreadable folder on the way): the atomic write says what is wrong, if anything.
        return Ok(Target::Replace);
    };
    let stream = entry.file_type().is_symlink() && through_proc(path);
    let meta = if entry.file_type().is_symlink() {
        match std::fs::metadata(path) {
            Ok(m) => m,
            // A standard stream that is closed (`/dev/stdout` with no fd 1): never replaced.
            Err(_) if stream => return Err(refusal(
                path,
                "is a standard stream that leads nowhere (closed): refusing to replace its link"
                    .into(),
            )),
            // A dangling or looping link: replaced.
            Err(_) => return Ok(Target::Replace),
        }
    } else {
        entry.clone()
    };
    if entry.is_dir() {
        return Err(refusal(
            path,
            "is a folder: name a file to write the output to".into(),
        ));
    }
    let Some(kind) = node_kind(meta.file_type()) else {
        if stream && meta.is_file() {
            let file = std::fs::OpenOptions::new()
                .append(true)
                .open(path)
                .map_err(|source| HoloError::Io {
                    path: path.to_path_buf(),
                    source,
                })?;
            return Ok(Target::Stream(NodeWriter { file }));
        }
        if stream {
            // A standard stream open on a folder: its link is never replaced.
            return Err(refusal(
                path,
                "is a standard stream open on a folder: refusing to replace its link".into(),
            ));
        }
        return Ok(Target::Replace);
    };
    let via = if entry.file_type().is_symlink() {
        " (at the end of its symbolic link)"
    } else {
        ""
    };
    match kind {
        "a character device" => {
            let file = std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .map_err(|source| HoloError::Io {
                    path: path.to_path_buf(),
                    source,
                })?;
            Ok(Target::Stream(NodeWriter { file }))
        }
        "a FIFO" => open_fifo(path, via),
        other => Err(refusal(
            path,
            format!(
                "is {other}{via}: refusing to write an output onto it (it is never replaced nor removed); \
                 name a regular file, a character device such as /dev/null, or a FIFO with a reader"
            ),
        )),
    }
}

/// Opens a FIFO for writing without waiting for a reader: one with no reader is refused.
#[cfg(unix)]
fn open_fifo(path: &Path, via: &str) -> Result<Target> {
    use std::os::unix::fs::OpenOptionsExt;
    #[cfg(any(target_os = "linux", target_os = "android"))]
    const O_NONBLOCK: i32 = 0o4000;
    #[cfg(not(any(target_os = "linux", target_os = "android")))]
    const O_NONBLOCK: i32 = 0x0004;
    /// ENXIO: a non-blocking open for writing of a FIFO that no process has open for reading.
    const ENXIO: i32 = 6;
    match std::fs::OpenOptions::new()
        .write(true)
        .custom_flags(O_NONBLOCK)
        .open(path)
    {
        Ok(file) => Ok(Target::Stream(NodeWriter { file })),
        Err(e) if e.raw_os_error() == Some(ENXIO) => Err(refusal(
            path,
            format!(
                "is a FIFO with no reader{via}: refusing to wait for one (start its reader first, or name a \
                 regular file)"
            ),
        )),
        Err(source) => Err(HoloError::Io {
            path: path.to_path_buf(),
            source,
        }),
    }
}

#[cfg(not(unix))]
fn open_fifo(path: &Path, _via: &str) -> Result<Target> {
    Err(refusal(path, "is a FIFO".into()))
}
