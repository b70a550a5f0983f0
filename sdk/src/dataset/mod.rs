//! The training dataset: random layered depth images paired with their SM-LBM midpoint holograms, as
//! in the paper's MIT-CGH-4K-V2 (section "MIT-CGH-4K-V2": 3800/100/100 samples of 384×384, 5-layer
//! LDIs, SM-LBM with 2048 planes or more).
//!
//! One *sample* is a random scene ([`crate::scene::random`]) rendered as an `L`-layer LDI and the
//! midpoint hologram that [`SmLbm`] computes from the **full** LDI (the ground truth the hologram CNN
//! learns, paper Fig. 3). Samples are written in `.npz` *shards* (NumPy zip archives, one per
//! `shard_size` consecutive samples of a split) next to a `manifest.json` that records everything
//! needed to read, check and regenerate them. The format is specified in `docs/DATASET.md`:
//!
//! | array | dtype | shape | content |
//! |---|---|---|---|
//! | `ldi` | float32 | `[N, 4·L, H, W]` | per layer `k` (front to back) channels `4k..4k+3` = R, G, B amplitude in `[0, 1]`, depth `d ∈ [0, 1]` (0 = near); invalid pixels: amplitude 0, depth 1 |
//! | `ldi_valid` | uint8 | `[N, L, H, W]` | 1 where layer `k` holds a point |
//! | `midpoint` | complex64 | `[N, 3, H, W]` | R, G, B midpoint hologram (complex field at `z = 0`) |
//! | `seed` | uint64 | `[N]` | scene seed ([`sample_seed`]) |
//! | `index` | uint64 | `[N]` | sample index within its split |
//!
//! Every sample is a pure function of (base seed, split, index) and the configuration, so generation
//! runs in parallel over samples (rayon; [`SmLbm`] parallelises colours inside a sample on the same
//! pool) and any sample can be regenerated alone ([`SampleGenerator::sample`]).

use std::path::{Path, PathBuf};
use std::time::Instant;

use ndarray::{s, Array, Array1, Array3, Array4, ArrayView3, Axis, Ix1, Ix4, Zip};
use ndarray_npy::NpzWriter;
use num_complex::Complex32;
use serde::{Deserialize, Serialize};

use crate::error::{invalid, HoloError, Result};
use crate::io::save_amplitude_png;
use crate::scene::{LayeredDepthImage, LdiLayer, RandomSceneConfig, RandomSceneGenerator};
use crate::splitmix::splitmix64;
use crate::synthesis::{
    ldi_layers, AberrationCorrectedSmLbm, AberrationCorrection, AberrationProfile, SmLbm,
};

mod shards;

pub use shards::{
    generate_shards, merge_shards, DatasetPlan, ShardRecord, ShardRun, ShardSelection,
    ShardStatistics, SHARD_RECORD_FORMAT, SHARD_RECORD_SUFFIX,
};

/// Value of the manifest's `format` field.
pub const FORMAT_NAME: &str = "tensorholo-ldi-hologram-dataset";
/// Version of the file format described in `docs/DATASET.md` (manifest field `format_version`).
pub const FORMAT_VERSION: u32 = 1;
/// File name of the manifest inside a dataset folder.
pub const MANIFEST_FILE: &str = "manifest.json";

/// A dataset split. Serialised in lower case (`"train"`, `"val"`, `"test"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Training samples (paper: 3800).
    Train,
    /// Validation samples (paper: 100).
    Val,
    /// Test samples (paper: 100).
    Test,
}

impl Split {
    /// The three splits in file order.
    pub const ALL: [Split; 3] = [Split::Train, Split::Val, Split::Test];

    /// Lower-case name, used in shard file names.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }

    /// Numeric id mixed into [`sample_seed`]: train 0, val 1, test 2.
    pub fn id(self) -> u64 {
        match self {
            Split::Train => 0,
            Split::Val => 1,
            Split::Test => 2,
        }
    }
}

/// The scene seed of sample `index` of `split` in a dataset of base seed `base_seed`:
/// `m(m(m(base_seed) ^ split.id()) ^ index)` with `m` the SplitMix64 finaliser (wrapping `u64`
/// arithmetic; constants in the source and `docs/DATASET.md`). The scene is then
/// [`crate::scene::random_ldi`]`(config, seed)`, i.e. a `ChaCha8Rng::seed_from_u64(seed)` stream.
pub fn sample_seed(base_seed: u64, split: Split, index: u64) -> u64 {
    splitmix64(splitmix64(splitmix64(base_seed) ^ split.id()) ^ index)
}

/// What to generate. `Default`: the random-scene defaults (384×384, 5 layers), SM-LBM with 2048 planes
/// and the paper's optics, seed 1, 8/2/2 samples, 16 samples per shard, deflate-compressed shards.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetConfig {
    /// Random scenes (size, layers, shapes, textures).
    pub scene: RandomSceneConfig,
    /// Ground-truth hologram synthesis: planes (`levels`), optics, propagation options.
    pub synthesis: SmLbm,
    /// With `Some`, the ground truth is the aberration-corrected SM-LBM of Eq. 5
    /// ([`AberrationCorrectedSmLbm`], `G·(G + 1)/2` propagations per colour; `docs/ABERRATION.md`).
    pub aberration: Option<AberrationCorrection>,
    /// Base seed ([`sample_seed`]).
    pub seed: u64,
    /// Training samples (paper: 3800).
    pub train: usize,
    /// Validation samples (paper: 100).
    pub val: usize,
    /// Test samples (paper: 100).
    pub test: usize,
    /// Samples per `.npz` shard (the last shard of a split may hold fewer).
    pub shard_size: usize,
    /// Deflate-compress the arrays inside each shard (as `numpy.savez_compressed`; about half the size,
    /// mostly from the sparse rear LDI layers); `numpy.load` reads both kinds.
    pub compress: bool,
}

impl Default for DatasetConfig {
    fn default() -> Self {
        Self {
            scene: RandomSceneConfig::default(),
            synthesis: SmLbm::default(),
            aberration: None,
            seed: 1,
            train: 8,
            val: 2,
            test: 2,
            shard_size: 16,
            compress: true,
        }
    }
}

impl DatasetConfig {
    /// The aberration-corrected synthesis, when [`DatasetConfig::aberration`] is set.
    pub fn corrected_synthesis(&self) -> Option<AberrationCorrectedSmLbm> {
        self.aberration
            .clone()
            .map(|a| self.synthesis.with_aberration(a))
    }

    /// Number of samples of `split`.
    pub fn count(&self, split: Split) -> usize {
        match split {
            Split::Train => self.train,
            Split::Val => self.val,
            Split::Test => self.test,
        }
    }

    /// Checks the configuration.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a bad scene configuration
    /// ([`RandomSceneConfig::validate`]), bad synthesis parameters (`levels`, optics; the aberration
    /// correction's offset and display, [`AberrationCorrectedSmLbm::validate`]), `shard_size`
    /// of 0, or no sample at all (`train + val + test = 0`), or more than 10⁸ samples per split.
    pub fn validate(&self) -> Result<()> {
        self.scene.validate()?;
        self.synthesis.validate()?;
        if let Some(a) = self.corrected_synthesis() {
            a.validate()?;
        }
        if self.shard_size == 0 {
            return Err(invalid("shard_size", "must be at least 1"));
        }
        if Split::ALL.iter().all(|&s| self.count(s) == 0) {
            return Err(invalid(
                "samples",
                "the dataset needs at least one sample (train + val + test > 0)",
            ));
        }
        if let Some(s) = Split::ALL.iter().find(|&&s| self.count(s) > 100_000_000) {
            return Err(invalid(
                "samples",
                format!(
                    "{} split: at most 10^8 samples, got {}",
                    s.name(),
                    self.count(*s)
                ),
            ));
        }
        Ok(())
    }
}

/// Occlusion statistics of one LDI.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LdiStatistics {
    /// Fraction of pixels valid in each layer `[L]` (layer 0 first).
    pub valid_fraction: Vec<f64>,
    /// Fraction of pixels with at least two valid layers: something is hidden behind what an RGB-D
    /// camera would see.
    pub multi_layer_fraction: f64,
    /// Mean number of valid layers per pixel.
    pub mean_valid_layers: f64,
}

impl LdiStatistics {
    /// Statistics of `ldi`.
    pub fn of(ldi: &LayeredDepthImage) -> Self {
        let n = (ldi.height() * ldi.width()) as f64;
        let valid_fraction: Vec<f64> = ldi
            .layers()
            .iter()
            .map(|l| l.valid.iter().filter(|&&v| v).count() as f64 / n)
            .collect();
        let mut counts = ndarray::Array2::<u32>::zeros((ldi.height(), ldi.width()));
        for l in ldi.layers() {
            Zip::from(&mut counts)
                .and(&l.valid)
                .for_each(|c, &v| *c += u32::from(v));
        }
        let multi = counts.iter().filter(|&&c| c >= 2).count() as f64 / n;
        Self {
            mean_valid_layers: valid_fraction.iter().sum(),
            valid_fraction,
            multi_layer_fraction: multi,
        }
    }
}

/// One generated sample.
#[derive(Debug, Clone)]
pub struct Sample {
    /// Split it belongs to.
    pub split: Split,
    /// Index within the split.
    pub index: usize,
    /// Scene seed ([`sample_seed`]).
    pub seed: u64,
    /// The random scene, `L` layers of `[3, H, W]` amplitude, `[H, W]` depth and validity.
    pub ldi: LayeredDepthImage,
    /// Midpoint hologram `[3, H, W]` (R, G, B) of the full LDI by [`SmLbm::synthesize`].
    pub midpoint: Array3<Complex32>,
    /// Number of non-empty SM-LBM depth planes (propagations per colour).
    pub nonempty_planes: usize,
    /// Seconds spent generating the sample (scene and hologram) on its worker thread.
    pub seconds: f64,
}

/// Generates samples of one [`DatasetConfig`] (scene generator with its photos loaded, synthesis,
/// base seed). `Sync`: share one across threads.
#[derive(Debug, Clone)]
pub struct SampleGenerator {
    scenes: RandomSceneGenerator,
    synthesis: SmLbm,
    corrected: Option<AberrationCorrectedSmLbm>,
    seed: u64,
}

impl SampleGenerator {
    /// Validates `config` and loads its photos.
    ///
    /// Errors: as [`DatasetConfig::validate`] and [`RandomSceneGenerator::new`].
    pub fn new(config: &DatasetConfig) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            scenes: RandomSceneGenerator::new(config.scene.clone())?,
            synthesis: config.synthesis,
            corrected: config.corrected_synthesis(),
            seed: config.seed,
        })
    }

    /// The scene generator (configuration, photo list).
    pub fn scenes(&self) -> &RandomSceneGenerator {
        &self.scenes
    }

    /// The LDI of sample `index` of `split` (cheap: no hologram).
    ///
    /// Errors: as [`RandomSceneGenerator::generate`].
    pub fn ldi(&self, split: Split, index: usize) -> Result<LayeredDepthImage> {
        self.scenes
            .generate(sample_seed(self.seed, split, index as u64))
    }

    /// Sample `index` of `split`: its LDI and the SM-LBM midpoint hologram of all its layers (aberration
    /// corrected, Eq. 5, when the configuration says so).
    ///
    /// Errors: as [`RandomSceneGenerator::generate`], [`SmLbm::synthesize`] and
    /// [`AberrationCorrectedSmLbm::synthesize`].
    pub fn sample(&self, split: Split, index: usize) -> Result<Sample> {
        let t = Instant::now();
        let seed = sample_seed(self.seed, split, index as u64);
        let ldi = self.scenes.generate(seed)?;
        let layers = ldi_layers(&ldi);
        let nonempty_planes = self.synthesis.propagation_count(&layers)?;
        let midpoint = match &self.corrected {
            Some(c) => c.synthesize(&layers, &|_, _| {})?,
            None => self.synthesis.synthesize(&layers, &|_, _| {})?,
        };
        drop(layers);
        // A hologram that is not finite everywhere is no training target: refused before any shard holds it,
        // naming the settings it came from.
        let o = &self.synthesis.setup;
        check_finite_midpoint(midpoint.iter(), || {
            format!(
                "sample {index} of the {} split (seed {seed}): the SM-LBM midpoint hologram, at pitch {} m, \
                 wavelengths {:?} m, volume {} m and {} planes,",
                split.name(),
                o.pixel_pitch_m,
                o.wavelengths_m,
                o.volume_depth_m,
                self.synthesis.levels
            )
        })?;
        Ok(Sample {
            split,
            index,
            seed,
            ldi,
            midpoint,
            nonempty_planes,
            seconds: t.elapsed().as_secs_f64(),
        })
    }
}

/// The network-input tensor of an LDI: `ldi` `[4·L, H, W]` f32 (per layer R, G, B amplitude then depth;
/// invalid pixels amplitude 0 and depth 1) and `valid` `[L, H, W]` u8 (1 = point present). This is one
/// sample of the shard arrays `ldi` and `ldi_valid`, and the hologram CNN's input layout
/// (`docs/CONVENTIONS.md` §7.1).
pub fn ldi_tensor(ldi: &LayeredDepthImage) -> (Array3<f32>, Array3<u8>) {
    let (l, h, w) = (ldi.num_layers(), ldi.height(), ldi.width());
    let mut x = Array3::<f32>::zeros((4 * l, h, w));
    crate::model::contract::pack_ldi(ldi, x.view_mut())
        .expect("the tensor is allocated at the LDI's own [4·L, H, W]");
    let mut valid = Array3::<u8>::zeros((l, h, w));
    for (k, layer) in ldi.layers().iter().enumerate() {
        Zip::from(valid.index_axis_mut(Axis(0), k))
            .and(&layer.valid)
            .for_each(|o, &v| *o = u8::from(v));
    }
    (x, valid)
}

/// The inverse of [`ldi_tensor`]: an LDI from `ldi` `[4·L, H, W]` and `valid` `[L, H, W]`.
///
/// Errors: [`HoloError::ShapeMismatch`] if the shapes disagree or `4·L` channels do not match `L`
/// validity planes; otherwise as [`LayeredDepthImage::new`].
pub fn ldi_from_tensor(ldi: ArrayView3<f32>, valid: ArrayView3<u8>) -> Result<LayeredDepthImage> {
    let (c, h, w) = ldi.dim();
    let l = valid.dim().0;
    if c != 4 * l || valid.dim() != (l, h, w) || l == 0 {
        return Err(HoloError::ShapeMismatch {
            what: "LDI tensor [4*L, H, W] vs validity [L, H, W]".into(),
            expected: vec![4 * l.max(1), h, w],
            got: vec![c, valid.dim().1, valid.dim().2],
        });
    }
    let layers = (0..l)
        .map(|k| LdiLayer {
            amplitude: ldi.slice(s![4 * k..4 * k + 3, .., ..]).to_owned(),
            depth: ldi.index_axis(Axis(0), 4 * k + 3).to_owned(),
            valid: valid.index_axis(Axis(0), k).mapv(|v| v != 0),
        })
        .collect();
    LayeredDepthImage::new(layers)
}

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

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> HoloError + '_ {
    move |source| HoloError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes `bytes`-producing `write` to `path` atomically: into a hidden temporary file beside it,
/// then renamed over `path`.
fn write_atomic(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| invalid("path", format!("`{}` has no file name", path.display())))?;
    let tmp = path.with_file_name(format!(".{}.partial", name.to_string_lossy()));
    let result = write(&tmp).and_then(|()| std::fs::rename(&tmp, path).map_err(io_error(path)));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `samples` (all of one size and layer count) as one `.npz` shard at `path`, arrays stacked
/// along axis 0 in the given order: `ldi` f32 `[N, 4·L, H, W]`, `ldi_valid` u8 `[N, L, H, W]`,
/// `midpoint` complex64 `[N, 3, H, W]`, `seed` u64 `[N]`, `index` u64 `[N]` (see the module docs).
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

/// The arrays of one shard, as written by [`write_shard`] (see the module docs for layouts).
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

/// Who generated a dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GeneratorInfo {
    /// `"tensorholo"`.
    pub name: String,
    /// Crate version.
    pub version: String,
    /// Git commit of the generating source (`"unknown"` if not known; `-dirty` suffix for local changes).
    pub git_commit: String,
    /// Command line, if generated by a program that supplied it.
    pub command: Vec<String>,
}

/// SM-LBM parameters of the ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SynthesisInfo {
    /// `"SM-LBM"` (silhouette-mask layer-based method, paper Eq. 1–4, all LDI layers).
    pub method: String,
    /// Number of depth planes `N` at `d_n = n/(N − 1)`.
    pub levels: usize,
    /// Silhouette masks applied (Eq. 3).
    pub silhouette_masks: bool,
    /// Propagations zero-padded to `2H × 2W`.
    pub pad: bool,
    /// Matsushima band limit applied.
    pub band_limit: bool,
    /// Plane at which the hologram is given: `"midpoint (z = 0)"`.
    pub hologram_plane: String,
    /// Initial phase of the plane fields: Maimone et al., `exp(i·2π·z_n/λ)` (Eq. 1, 4).
    pub initial_phase: String,
    /// The aberration correction of Eq. 5, if the ground truth has one (absent otherwise, and in manifests
    /// written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aberration: Option<AberrationInfo>,
}

/// The aberration correction recorded in a manifest (`docs/ABERRATION.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AberrationInfo {
    /// The profile file as given ([`GenerateOptions::aberration_file`]), if known (written lossily if its
    /// name is not UTF-8).
    #[serde(serialize_with = "crate::io::lossy_path::option")]
    pub file: Option<PathBuf>,
    /// Signed distance in metres from the midpoint plane to the SLM plane; a plane at `z_N` is corrected with
    /// the coefficients at `z_N − slm_offset_m`.
    pub slm_offset_m: f64,
    /// The coefficients (the file's content, `tensorholo.aberration` format).
    pub profile: AberrationProfile,
}

/// Display geometry (`docs/CONVENTIONS.md` §3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OpticsInfo {
    /// R, G, B wavelengths in metres.
    pub wavelengths_m: [f64; 3],
    /// SLM pixel pitch in metres.
    pub pixel_pitch_m: f64,
    /// 3D volume depth in metres, centred on the midpoint hologram.
    pub volume_depth_m: f64,
    /// How normalised depth maps to position: `"z(d) = (0.5 - d) * volume_depth_m"`.
    pub depth_to_z: String,
}

/// The display profile a dataset was made for (`holo dataset --display FILE`, `docs/DISPLAYS.md`): what
/// [`OpticsInfo`] does not hold. The optics themselves (the profile's, with any single flag in its place)
/// are in [`DatasetPlan::optics`] (the manifest's `optics`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DisplayInfo {
    /// The profile file as given (written lossily if not UTF-8), `None` when the profile came from code.
    pub file: Option<String>,
    /// The profile's `name`.
    pub name: Option<String>,
    /// The SLM's `[height, width]` in pixels (the samples have the dataset's own `resolution`).
    pub slm_resolution: [usize; 2],
    /// The offsets `s` in metres the display runs at (Eq. 6), the first its default: the offsets to train
    /// pre-filters for.
    pub offsets_m: Vec<f64>,
    /// The profile's `.holocal` calibration (resolved path, lossy UTF-8), if any.
    pub calibration: Option<String>,
}

impl DisplayInfo {
    /// The record of `profile`, read from `file` if given.
    pub fn new(profile: &crate::display::DisplayProfile, file: Option<&Path>) -> Self {
        Self {
            file: file.map(|f| f.to_string_lossy().into_owned()),
            name: profile.name.clone(),
            slm_resolution: profile.resolution,
            offsets_m: profile.offsets_m.clone(),
            calibration: profile
                .calibration
                .as_ref()
                .map(|c| c.to_string_lossy().into_owned()),
        }
    }
}

/// One shard file of a split.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardInfo {
    /// File name inside the dataset folder (`<split>-<nnnnn>.npz`).
    pub file: String,
    /// Samples in it.
    pub samples: usize,
    /// Index (within the split) of its first sample; the rest follow consecutively.
    pub first_index: usize,
}

/// One split.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SplitInfo {
    /// Which split.
    pub name: Split,
    /// Number of samples.
    pub samples: usize,
    /// Its shards in order.
    pub shards: Vec<ShardInfo>,
}

/// Description of one array in every shard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArrayInfo {
    /// Member name (NumPy key).
    pub name: String,
    /// NumPy dtype (`float32`, `uint8`, `complex64`, `uint64`).
    pub dtype: String,
    /// Symbolic shape (`N` = samples in the shard, `L`, `H`, `W`).
    pub shape: Vec<String>,
    /// Content, units and layout.
    pub description: String,
}

/// Statistics over all samples of a generated dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetStatistics {
    /// Number of samples.
    pub samples: usize,
    /// Mean number of non-empty SM-LBM planes (propagations per colour) per sample.
    pub mean_nonempty_planes: f64,
    /// Fewest non-empty planes of any sample.
    pub min_nonempty_planes: usize,
    /// Most non-empty planes of any sample.
    pub max_nonempty_planes: usize,
    /// Mean fraction of valid pixels per LDI layer `[L]`.
    pub mean_valid_fraction: Vec<f64>,
    /// Mean fraction of pixels with at least two valid layers.
    pub mean_multi_layer_fraction: f64,
    /// Smallest such fraction of any sample.
    pub min_multi_layer_fraction: f64,
    /// Mean number of valid layers per pixel.
    pub mean_valid_layers: f64,
    /// Largest midpoint amplitude `|H|` over all samples and colours.
    pub max_midpoint_amplitude: f64,
    /// Mean midpoint amplitude `|H|` over all samples, colours and pixels.
    pub mean_midpoint_amplitude: f64,
    /// Mean seconds per sample on one worker (scene + SM-LBM, colours in parallel on the pool).
    pub mean_sample_seconds: f64,
    /// Wall-clock seconds of the whole generation.
    pub wall_seconds: f64,
    /// Worker threads used.
    pub threads: usize,
}

/// The `manifest.json` of a dataset folder (specified in `docs/DATASET.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// [`FORMAT_NAME`].
    pub format: String,
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Who generated it.
    pub generator: GeneratorInfo,
    /// Seconds since the Unix epoch when generation finished.
    pub created_unix_s: u64,
    /// What the dataset is (seed, resolution, synthesis, optics, display, scenes, shards, arrays): its keys
    /// sit at the manifest's top level.
    #[serde(flatten)]
    pub plan: DatasetPlan,
    /// Statistics over all samples.
    pub statistics: DatasetStatistics,
}

impl Manifest {
    /// The entry of `split`.
    pub fn split(&self, split: Split) -> Option<&SplitInfo> {
        self.plan.splits.iter().find(|s| s.name == split)
    }
}

/// Reads and checks `dir/manifest.json`.
///
/// Errors: [`HoloError::Io`] if unreadable; [`HoloError::InvalidData`] if it is not valid JSON of this
/// format, or another format or a newer version.
pub fn read_manifest(dir: &Path) -> Result<Manifest> {
    let path = dir.join(MANIFEST_FILE);
    Manifest::from_json_str(&crate::io::read_text(&path)?, &path.display().to_string())
}

impl Manifest {
    /// Parses and checks a manifest's JSON text; `source` names it in errors.
    ///
    /// Errors: [`HoloError::InvalidData`] naming `source` if it is not valid JSON of this format, or another
    /// format or a newer version.
    pub fn from_json_str(text: &str, source: &str) -> Result<Self> {
        let m: Manifest = serde_json::from_str(text).map_err(|e| {
            HoloError::InvalidData(format!("`{source}` is not a dataset manifest: {e}"))
        })?;
        if m.format != FORMAT_NAME || m.format_version > FORMAT_VERSION {
            return Err(HoloError::InvalidData(format!(
                "`{source}` has format {} version {}; this build reads {FORMAT_NAME} up to version \
                 {FORMAT_VERSION}",
                m.format, m.format_version
            )));
        }
        Ok(m)
    }
}

/// Refuses a midpoint hologram holding a NaN or an infinity (a training target must be finite everywhere);
/// `what` names the sample and the optics it came from.
///
/// Errors: [`HoloError::InvalidData`] naming `what` and the first element that is not finite.
fn check_finite_midpoint<'a>(
    midpoint: impl Iterator<Item = &'a Complex32>,
    what: impl FnOnce() -> String,
) -> Result<()> {
    let mut values = midpoint;
    match values.position(|v| !(v.re.is_finite() && v.im.is_finite())) {
        None => Ok(()),
        Some(bad) => Err(HoloError::InvalidData(format!(
            "{} holds a NaN or infinite value (element {bad}): these optics do not give a finite hologram; \
             nothing of this sample is written",
            what()
        ))),
    }
}

/// Shard file name: `<split>-<nnnnn>.npz`.
pub fn shard_file_name(split: Split, shard: usize) -> String {
    format!("{}-{shard:05}.npz", split.name())
}

fn array_infos() -> Vec<ArrayInfo> {
    let info = |name: &str, dtype: &str, shape: &[&str], description: &str| ArrayInfo {
        name: name.into(),
        dtype: dtype.into(),
        shape: shape.iter().map(|s| s.to_string()).collect(),
        description: description.into(),
    };
    vec![
        info(
            "ldi",
            "float32",
            &["N", "4*L", "H", "W"],
            "layered depth image, layers front to back; channel 4k+c of layer k: c = 0, 1, 2 R, G, B \
             amplitude (sqrt of linear intensity, [0, 1]), c = 3 normalised depth d in [0, 1] \
             (0 = near, z(d) = (0.5 - d) * volume_depth_m from the midpoint plane); invalid pixels \
             have amplitude 0 and depth 1",
        ),
        info(
            "ldi_valid",
            "uint8",
            &["N", "L", "H", "W"],
            "1 where layer k holds a scene point, else 0; layer 0 is 1 everywhere; \
             ldi_valid[:, k+1] <= ldi_valid[:, k]",
        ),
        info(
            "midpoint",
            "complex64",
            &["N", "3", "H", "W"],
            "R, G, B midpoint hologram: complex field at z = 0 (centre of the 3D volume) computed by \
             SM-LBM from all L layers; unnormalised (a plane wave of amplitude a has |H| = a)",
        ),
        info("seed", "uint64", &["N"], "scene seed of each sample"),
        info("index", "uint64", &["N"], "index of each sample within its split"),
    ]
}

/// Options of [`generate`] that are not part of the dataset's content.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GenerateOptions {
    /// Replace a dataset already in the folder (its `manifest.json`, same-named shards, and shards
    /// its manifest listed that the new one does not). Without it, a folder holding a manifest is
    /// refused.
    pub overwrite: bool,
    /// Git commit of the generating source, recorded in the manifest (`None` → `"unknown"`).
    pub git_commit: Option<String>,
    /// Command line recorded in the manifest.
    pub command: Vec<String>,
    /// The aberration profile's file, recorded in the manifest with [`DatasetConfig::aberration`].
    pub aberration_file: Option<PathBuf>,
    /// The display profile the dataset is made for, recorded in the manifest ([`DatasetPlan::display`]). Its
    /// optics must be [`DatasetConfig::synthesis`]'s unless a single flag overrode them: only the record is
    /// taken from here.
    pub display: Option<DisplayInfo>,
}

/// Generates a whole dataset into `out_dir` in this process: every shard of every split
/// ([`generate_shards`] with [`ShardSelection::ALL`]: samples in parallel on the current rayon pool, each
/// shard and its record written while the next ones compute), then `manifest.json` ([`merge_shards`],
/// see [`Manifest`]). `progress(done, total)` is called after every sample (from worker threads). Returns
/// the manifest written.
///
/// Nothing is written unless the configuration is valid. A folder that already holds a
/// `manifest.json` is refused unless [`GenerateOptions::overwrite`]. Photos (inputs) are never
/// overwritten. Files appear atomically; an interrupted run leaves no manifest, so the folder is not
/// mistaken for a dataset, and a rerun keeps the shards it had finished (`shards` module docs).
///
/// Errors: as [`generate_shards`] and [`merge_shards`].
pub fn generate(
    out_dir: &Path,
    config: &DatasetConfig,
    options: &GenerateOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<Manifest> {
    // Shards of a replaced dataset that the new one does not have go, with their records.
    let stale: Vec<String> = if options.overwrite {
        let mut files: Vec<String> = read_manifest(out_dir)
            .map(|old| {
                old.plan
                    .splits
                    .iter()
                    .flat_map(|s| s.shards.iter().map(|f| f.file.clone()))
                    .collect()
            })
            .unwrap_or_default();
        if let Ok(entries) = std::fs::read_dir(out_dir) {
            files.extend(entries.flatten().filter_map(|e| {
                e.file_name()
                    .to_str()
                    .and_then(|n| n.strip_suffix(SHARD_RECORD_SUFFIX))
                    .map(str::to_string)
            }));
        }
        files
    } else {
        Vec::new()
    };
    let run = generate_shards(out_dir, config, options, ShardSelection::ALL, progress)?;
    let current: std::collections::HashSet<&str> = run
        .written
        .iter()
        .chain(&run.kept)
        .map(String::as_str)
        .collect();
    for file in &stale {
        let plain = Path::new(file)
            .file_name()
            .is_some_and(|n| n == file.as_str());
        if plain && file.ends_with(".npz") && !current.contains(file.as_str()) {
            let _ = std::fs::remove_file(out_dir.join(file));
            let _ = std::fs::remove_file(out_dir.join(format!("{file}{SHARD_RECORD_SUFFIX}")));
        }
    }
    // Generation has already refused a manifest it may not replace (without `overwrite`).
    merge_shards(out_dir, true)
}

/// Saves previews of an LDI into `dir`: `<stem>_rgb.png` (layer 0 amplitude, sRGB), `<stem>_depth.png`
/// (layer 0 depth, grey, white = far) and `<stem>_layers.png` (all layers side by side: amplitudes in
/// the top row, depths in the bottom row, invalid pixels dark red). Returns the paths written.
///
/// Errors: [`HoloError::Io`] if `dir` cannot be created; as [`save_amplitude_png`].
pub fn save_ldi_previews(dir: &Path, stem: &str, ldi: &LayeredDepthImage) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(io_error(dir))?;
    let (l, h, w) = (ldi.num_layers(), ldi.height(), ldi.width());
    let first = &ldi.layers()[0];
    let rgb = dir.join(format!("{stem}_rgb.png"));
    save_amplitude_png(&rgb, first.amplitude.view(), 1.0)?;
    // Grey PNG of intensity d: amplitude √d.
    let depth = dir.join(format!("{stem}_depth.png"));
    let d = first.depth.mapv(f32::sqrt).insert_axis(Axis(0));
    save_amplitude_png(&depth, d.view(), 1.0)?;
    let mut mosaic = Array3::<f32>::zeros((3, 2 * h, l * w));
    const INVALID: [f32; 3] = [0.6, 0.0, 0.0];
    for (k, layer) in ldi.layers().iter().enumerate() {
        for y in 0..h {
            for x in 0..w {
                let ok = layer.valid[[y, x]];
                let dv = layer.depth[[y, x]].sqrt();
                for c in 0..3 {
                    mosaic[[c, y, k * w + x]] = if ok {
                        layer.amplitude[[c, y, x]]
                    } else {
                        INVALID[c]
                    };
                    mosaic[[c, h + y, k * w + x]] = if ok { dv } else { INVALID[c] };
                }
            }
        }
    }
    let layers = dir.join(format!("{stem}_layers.png"));
    save_amplitude_png(&layers, mosaic.view(), 1.0)?;
    Ok(vec![rgb, depth, layers])
}

#[cfg(test)]
mod finite_tests {
    use super::*;

    #[test]
    fn a_midpoint_with_a_nan_or_infinity_is_refused_naming_the_sample_and_element() {
        let mut field = [Complex32::new(0.5, -0.25); 12];
        assert!(check_finite_midpoint(field.iter(), || "sample 0".into()).is_ok());
        for (i, bad) in [
            (7, Complex32::new(f32::NAN, 0.0)),
            (3, Complex32::new(0.0, f32::INFINITY)),
        ] {
            let old = field[i];
            field[i] = bad;
            let e = check_finite_midpoint(field.iter(), || "sample 4 at pitch 1e-310 m".into())
                .unwrap_err()
                .to_string();
            assert!(e.contains(&format!("element {i}")), "{e}");
            assert!(
                e.contains("pitch 1e-310 m") && e.contains("nothing of this sample is written"),
                "{e}"
            );
            field[i] = old;
        }
    }
}
