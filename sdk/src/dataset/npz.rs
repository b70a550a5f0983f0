//! The `.npz` shard files: [`write_shard`] and [`read_shard`] (arrays read with bounded memory), and the
//! atomic file writes every file of a dataset goes through.

use std::path::Path;

use ndarray::{Array, Array1, Array4, Axis, Ix1, Ix4};
use ndarray_npy::NpzWriter;
use num_complex::Complex32;

use super::sample::{ldi_from_tensor, ldi_tensor, Sample};
use crate::error::{invalid, HoloError, Result};
use crate::scene::LayeredDepthImage;

/// Reads array `name` (`name.npy` in the archive) of a shard with bounded memory: the entry's declared
/// uncompressed size must be within [`crate::io::InputLimits::max_file_bytes`], at most that many bytes are
/// decompressed, and the `.npy` header's shape is checked against those bytes before the array is allocated
/// (`ndarray-npy`'s `NpzReader` allocates by the declared shape first).
fn shard_array<T, D>(
    zip: &mut zip::ZipArchive<std::io::BufReader<std::fs::File>>,
    path: &Path,
    name: &str,
) -> Result<Array<T, D>>
where
    T: ndarray_npy::ReadableElement + ndarray_npy::ViewElement + Clone,
    D: ndarray::Dimension,
{
    use std::io::Read;
    let named = |reason: String| npz_error(path, format!("array `{name}`: {reason}"));
    let mut entry = zip
        .by_name(&format!("{name}.npy"))
        .map_err(|e| named(e.to_string()))?;
    let size = entry.size();
    let max = crate::io::input_limits().max_file_bytes;
    if size > max {
        return Err(named(format!(
            "{size} bytes uncompressed, above the input limit of {max} bytes (--max-file-bytes)"
        )));
    }
    let mut bytes = Vec::with_capacity(size as usize);
    (&mut entry)
        .take(size)
        .read_to_end(&mut bytes)
        .map_err(|e| named(e.to_string()))?;
    let array = crate::io::parse_npy::<T>(&bytes).map_err(|e| named(e.to_string()))?;
    array
        .into_dimensionality::<D>()
        .map_err(|e| named(format!("wrong rank ({e})")))
}

fn npz_error(path: &Path, reason: impl std::fmt::Display) -> HoloError {
    HoloError::Npy {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

pub(super) fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> HoloError + '_ {
    move |source| HoloError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes `bytes`-producing `write` to `path` atomically: into a hidden temporary file beside it,
/// then renamed over `path`.
pub(super) fn write_atomic(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| invalid("path", format!("`{}` has no file name", path.display())))?;
    if let Some(kind) = crate::io::node_at(path) {
        return Err(HoloError::InvalidData(format!(
            "output `{}` is {kind}: refusing to replace it with a dataset file (it is never renamed over nor \
             removed)",
            path.display()
        )));
    }
    let tmp = path.with_file_name(format!(".{}.partial", name.to_string_lossy()));
    let result = write(&tmp).and_then(|()| std::fs::rename(&tmp, path).map_err(io_error(path)));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `samples` (all of one size and layer count) as one `.npz` shard at `path`, arrays stacked
/// along axis 0 in the given order: `ldi` f32 `[N, 4·L, H, W]`, `ldi_valid` u8 `[N, L, H, W]`,
/// `midpoint` complex64 `[N, 3, H, W]`, `seed` u64 `[N]`, `index` u64 `[N]` (see the [`crate::dataset`] docs).
/// With `compress` the members are deflated. The file appears atomically (temporary file + rename).
///
/// Errors: [`HoloError::InvalidParameter`] (`samples`) for an empty slice;
/// [`HoloError::ShapeMismatch`] if samples differ in size or layer count; [`HoloError::Io`] /
/// [`HoloError::Npy`] naming `path` if writing fails.
pub fn write_shard(path: &Path, samples: &[Sample], compress: bool) -> Result<()> {
    let first = samples
        .first()
        .ok_or_else(|| invalid("samples", "a shard needs at least one sample"))?;
    let (l, h, w) = (
        first.ldi.num_layers(),
        first.ldi.height(),
        first.ldi.width(),
    );
    let n = samples.len();
    let mut ldi = Array4::<f32>::zeros((n, 4 * l, h, w));
    let mut valid = Array4::<u8>::zeros((n, l, h, w));
    let mut midpoint = Array4::<Complex32>::zeros((n, 3, h, w));
    for (i, sample) in samples.iter().enumerate() {
        let got = (
            sample.ldi.num_layers(),
            sample.ldi.height(),
            sample.ldi.width(),
        );
        if got != (l, h, w) || sample.midpoint.dim() != (3, h, w) {
            return Err(HoloError::ShapeMismatch {
                what: format!("sample {i} of the shard (LDI layers, height, width) vs sample 0"),
                expected: vec![l, h, w],
                got: vec![got.0, got.1, got.2],
            });
        }
        let (x, v) = ldi_tensor(&sample.ldi);
        ldi.index_axis_mut(Axis(0), i).assign(&x);
        valid.index_axis_mut(Axis(0), i).assign(&v);
        midpoint.index_axis_mut(Axis(0), i).assign(&sample.midpoint);
    }
    let seed = Array1::from_iter(samples.iter().map(|s| s.seed));
    let index = Array1::from_iter(samples.iter().map(|s| s.index as u64));
    write_atomic(path, |tmp| {
        let file = std::fs::File::create(tmp).map_err(io_error(tmp))?;
        let buf = std::io::BufWriter::with_capacity(1 << 20, file);
        let mut npz = if compress {
            NpzWriter::new_compressed(buf)
        } else {
            NpzWriter::new(buf)
        };
        let err = |e| npz_error(path, e);
        npz.add_array("ldi", &ldi).map_err(err)?;
        npz.add_array("ldi_valid", &valid).map_err(err)?;
        npz.add_array("midpoint", &midpoint).map_err(err)?;
        npz.add_array("seed", &seed).map_err(err)?;
        npz.add_array("index", &index).map_err(err)?;
        npz.finish().map_err(err)?;
        Ok(())
    })
}

/// The arrays of one shard, as written by [`write_shard`] (see the [`crate::dataset`] docs for layouts).
#[derive(Debug, Clone, PartialEq)]
pub struct Shard {
    /// `[N, 4·L, H, W]` f32: per layer R, G, B amplitude, depth.
    pub ldi: Array4<f32>,
    /// `[N, L, H, W]` u8: 1 where the layer holds a point.
    pub ldi_valid: Array4<u8>,
    /// `[N, 3, H, W]` complex64: R, G, B midpoint hologram.
    pub midpoint: Array4<Complex32>,
    /// `[N]` scene seeds.
    pub seed: Array1<u64>,
    /// `[N]` sample indices within the split.
    pub index: Array1<u64>,
}

impl Shard {
    /// Number of samples `N`.
    pub fn len(&self) -> usize {
        self.seed.len()
    }

    /// Whether the shard holds no sample.
    pub fn is_empty(&self) -> bool {
        self.seed.is_empty()
    }

    /// Sample `i` of the shard as an LDI.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`i`) out of range; as [`ldi_from_tensor`].
    pub fn sample_ldi(&self, i: usize) -> Result<LayeredDepthImage> {
        if i >= self.len() {
            return Err(invalid(
                "i",
                format!("sample {i} out of range (shard holds {})", self.len()),
            ));
        }
        ldi_from_tensor(
            self.ldi.index_axis(Axis(0), i),
            self.ldi_valid.index_axis(Axis(0), i),
        )
    }
}

/// Reads a shard written by [`write_shard`] (compressed or not) and checks that its arrays agree.
///
/// Errors: [`HoloError::Io`] if the file cannot be opened; [`HoloError::Npy`] naming `path` if it is
/// not an `.npz` archive, an array is missing or has the wrong dtype or rank;
/// [`HoloError::ShapeMismatch`] if the arrays disagree in `N`, `L`, `H` or `W`.
pub fn read_shard(path: &Path) -> Result<Shard> {
    let file = std::fs::File::open(path).map_err(io_error(path))?;
    let mut zip =
        zip::ZipArchive::new(std::io::BufReader::new(file)).map_err(|e| npz_error(path, e))?;
    let ldi = shard_array::<f32, Ix4>(&mut zip, path, "ldi")?;
    let ldi_valid = shard_array::<u8, Ix4>(&mut zip, path, "ldi_valid")?;
    let midpoint = shard_array::<Complex32, Ix4>(&mut zip, path, "midpoint")?;
    let seed = shard_array::<u64, Ix1>(&mut zip, path, "seed")?;
    let index = shard_array::<u64, Ix1>(&mut zip, path, "index")?;
    let (n, c, h, w) = ldi.dim();
    let l = c / 4;
    let mismatch = |what: &str, expected: Vec<usize>, got: &[usize]| HoloError::ShapeMismatch {
        what: format!("`{}`: {what}", path.display()),
        expected,
        got: got.to_vec(),
    };
    if c % 4 != 0 || c == 0 {
        return Err(mismatch(
            "ldi channels (4 per layer)",
            vec![n, 4 * l.max(1), h, w],
            ldi.shape(),
        ));
    }
    if ldi_valid.dim() != (n, l, h, w) {
        return Err(mismatch(
            "ldi_valid vs ldi",
            vec![n, l, h, w],
            ldi_valid.shape(),
        ));
    }
    if midpoint.dim() != (n, 3, h, w) {
        return Err(mismatch(
            "midpoint vs ldi",
            vec![n, 3, h, w],
            midpoint.shape(),
        ));
    }
    if seed.len() != n || index.len() != n {
        return Err(mismatch(
            "seed and index vs ldi",
            vec![n, n],
            &[seed.len(), index.len()],
        ));
    }
    Ok(Shard {
        ldi,
        ldi_valid,
        midpoint,
        seed,
        index,
    })
}
