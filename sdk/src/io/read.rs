//! The one bounded reader of every input file ([`read_bytes`], [`read_text`]): display profiles, tuning
//! files, calibrations, aberration files, models, `.npy` arrays, images, dataset manifests and shard records.
//!
//! - It reads at most a limit, counting the bytes it actually reads, not the size `stat()` reports: a pipe,
//!   `/dev/stdin` or a file that grows cannot make it allocate more. The limit is the process's
//!   [`InputLimits::max_file_bytes`], at most [`MAX_TEXT_BYTES`] for JSON text and [`MAX_STREAM_BYTES`] for
//!   anything that is not a regular file (a pipe has no size to check first).
//! - It reads each file once, so a pipe, a FIFO fed once or `--display /dev/stdin` is read whole.
//! - It refuses what is not a file, before reading: a folder, a device (`/dev/zero` and `/dev/urandom` never
//!   end), a socket, naming what the path is.

use std::io::Read;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{HoloError, Result};

/// The most bytes of JSON text read from one file (a display profile, a tuning, an aberration file, a
/// dataset manifest or shard record), whatever [`InputLimits::max_file_bytes`] says: 16 MiB, thousands of
/// times the largest such file the SDK writes.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// The most bytes read from anything that is not a regular file (a pipe, a FIFO, `/dev/stdin`), whose size
/// cannot be checked before reading: 512 MiB, whatever [`InputLimits::max_file_bytes`] says.
pub const MAX_STREAM_BYTES: u64 = 512 << 20;

/// Limits on what an input file may make the SDK allocate, checked before anything is allocated
/// ([`set_input_limits`] raises them for the whole process; the CLI's `--max-image-pixels` and
/// `--max-file-bytes` do).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct InputLimits {
    /// Largest image decoded, in pixels (default 100 M: a 48 MP phone photo, an 8K frame, twice over). Read
    /// from the file's header first; above it the file is refused naming the limit.
    pub max_image_pixels: u64,
    /// Largest input file read whole, in bytes (images, depth maps, `.npy`; default 4 GiB).
    pub max_file_bytes: u64,
}

impl Default for InputLimits {
    fn default() -> Self {
        Self {
            max_image_pixels: DEFAULT_MAX_IMAGE_PIXELS,
            max_file_bytes: DEFAULT_MAX_FILE_BYTES,
        }
    }
}

const DEFAULT_MAX_IMAGE_PIXELS: u64 = 100_000_000;
const DEFAULT_MAX_FILE_BYTES: u64 = 4 << 30;
static MAX_IMAGE_PIXELS: AtomicU64 = AtomicU64::new(DEFAULT_MAX_IMAGE_PIXELS);
static MAX_FILE_BYTES: AtomicU64 = AtomicU64::new(DEFAULT_MAX_FILE_BYTES);

/// The input limits in force ([`InputLimits::default`] unless [`set_input_limits`] changed them).
pub fn input_limits() -> InputLimits {
    InputLimits {
        max_image_pixels: MAX_IMAGE_PIXELS.load(Ordering::Relaxed),
        max_file_bytes: MAX_FILE_BYTES.load(Ordering::Relaxed),
    }
}

/// Sets the input limits of the whole process (e.g. to read a 200 MP panorama).
///
/// Errors: [`HoloError::InvalidParameter`] for a limit of 0.
pub fn set_input_limits(limits: InputLimits) -> Result<()> {
    if limits.max_image_pixels == 0 || limits.max_file_bytes == 0 {
        return Err(crate::error::invalid(
            "input limits",
            format!("limits must be ≥ 1, got {limits:?}"),
        ));
    }
    MAX_IMAGE_PIXELS.store(limits.max_image_pixels, Ordering::Relaxed);
    MAX_FILE_BYTES.store(limits.max_file_bytes, Ordering::Relaxed);
    Ok(())
}

/// What a file holds, for its limit ([`read_limited`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// Binary data: images, depth maps, models, `.npy`, calibrations.
    Data,
    /// JSON text.
    Text,
}

/// Reads a whole input file, at most [`InputLimits::max_file_bytes`] (and [`MAX_STREAM_BYTES`] from a pipe),
/// counting what it reads; refuses a folder, a device or a socket before reading.
///
/// Errors: [`HoloError::Io`] naming the file where it cannot be read; [`HoloError::InvalidData`] naming it
/// for a folder, a device, a socket, or more bytes than the limit (and how to raise it).
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    read_limited(path, Kind::Data)
}

/// Reads a whole JSON (or other text) input file, at most [`MAX_TEXT_BYTES`], as [`read_bytes`] reads; a
/// UTF-8 byte-order mark is dropped.
///
/// Errors: as [`read_bytes`]; [`HoloError::InvalidData`] naming the file for text that is not UTF-8 (with
/// the byte offset).
pub fn read_text(path: &Path) -> Result<String> {
    let bytes = read_limited(path, Kind::Text)?;
    let text = String::from_utf8(bytes).map_err(|e| {
        HoloError::InvalidData(format!(
            "`{}` is not UTF-8 text (byte {} is not)",
            path.display(),
            e.utf8_error().valid_up_to()
        ))
    })?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

fn read_limited(path: &Path, kind: Kind) -> Result<Vec<u8>> {
    let io = |source| HoloError::Io {
        path: path.to_path_buf(),
        source,
    };
    let refuse = |what: &str| {
        Err(HoloError::InvalidData(format!(
            "`{}` is {what}, not a file to read",
            path.display()
        )))
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    let ft = meta.file_type();
    if ft.is_dir() {
        return refuse("a folder");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_char_device() || ft.is_block_device() {
            return refuse("a device (one such as /dev/zero or /dev/urandom never ends)");
        }
        if ft.is_socket() {
            return refuse("a socket");
        }
    }
    let regular = ft.is_file();
    let file_limit = input_limits().max_file_bytes;
    let mut limit = file_limit;
    if kind == Kind::Text {
        limit = limit.min(MAX_TEXT_BYTES);
    }
    if !regular {
        limit = limit.min(MAX_STREAM_BYTES);
    }
    let too_big = |size: String| {
        let raise = if limit == file_limit {
            " (raise it with --max-file-bytes or tensorholo::io::set_input_limits)"
        } else if kind == Kind::Text {
            " (the limit of a text input)"
        } else {
            " (the limit of a pipe)"
        };
        Err(HoloError::InvalidData(format!(
            "`{}` is {size}, above the input limit of {limit} bytes{raise}",
            path.display()
        )))
    };
    if regular && meta.len() > limit {
        return too_big(format!("{} bytes", meta.len()));
    }
    let file = std::fs::File::open(path).map_err(io)?;
    let capacity = if regular { meta.len().min(limit) } else { 0 };
    let mut bytes = Vec::with_capacity(capacity as usize);
    // One byte past the limit tells a file at the limit from a longer one.
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > limit {
        return too_big(format!("more than {limit} bytes (read until then)"));
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_and_folders_are_refused_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let e = read_bytes(dir.path()).unwrap_err();
        assert!(e.to_string().contains("is a folder"), "{e}");
        #[cfg(unix)]
        for dev in ["/dev/zero", "/dev/urandom"] {
            if std::path::Path::new(dev).exists() {
                let e = read_bytes(std::path::Path::new(dev)).unwrap_err();
                assert!(e.to_string().contains("is a device"), "{dev}: {e}");
                let e = read_text(std::path::Path::new(dev)).unwrap_err();
                assert!(e.to_string().contains("never ends"), "{dev}: {e}");
            }
        }
    }

    #[test]
    fn text_is_bounded_by_what_is_read_and_loses_its_byte_order_mark() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.json");
        std::fs::write(&p, "\u{feff}{\"a\": 1}").unwrap();
        assert_eq!(read_text(&p).unwrap(), "{\"a\": 1}");
        std::fs::write(&p, [0x7b, 0xff, 0x7d]).unwrap();
        let e = read_text(&p).unwrap_err();
        assert!(e.to_string().contains("not UTF-8 text (byte 1"), "{e}");
        // A text file above its limit is refused from its size, without reading.
        let f = std::fs::File::create(&p).unwrap();
        f.set_len(MAX_TEXT_BYTES + 1).unwrap();
        let e = read_text(&p).unwrap_err();
        assert!(e.to_string().contains("the limit of a text input"), "{e}");
        assert!(read_bytes(&p).is_ok());
    }

    /// A pipe is read once, whole, and bounded by what it delivers: a writer that never stops is cut at the
    /// limit (here the text limit) instead of filling the memory.
    #[cfg(unix)]
    #[test]
    fn a_fifo_is_read_once_and_an_endless_one_is_cut_at_the_limit() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        let status = std::process::Command::new("mkfifo").arg(&fifo).status();
        if !status.is_ok_and(|s| s.success()) {
            println!("SKIPPED: no mkfifo");
            return;
        }
        let writer = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::write(&fifo, b"{\"once\": true}"))
        };
        assert_eq!(read_text(&fifo).unwrap(), "{\"once\": true}");
        writer.join().unwrap().unwrap();
        let endless = {
            let fifo = fifo.clone();
            std::thread::spawn(move || {
                use std::io::Write;
                let mut f = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
                let block = vec![b' '; 1 << 20];
                // Stops when the reader closes its end (a broken pipe).
                while f.write_all(&block).is_ok() {}
            })
        };
        let e = read_text(&fifo).unwrap_err();
        assert!(e.to_string().contains("more than 16777216 bytes"), "{e}");
        endless.join().unwrap();
    }
}
