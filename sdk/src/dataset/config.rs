//! What a dataset holds and how it is generated: [`DatasetConfig`] (scenes, synthesis, seed, splits,
//! shards), the splits and their seeds ([`sample_seed`]), and [`GenerateOptions`], what a run records beside
//! the content (with the display profile's record, [`DisplayInfo`]).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{invalid, Result};
use crate::scene::RandomSceneConfig;
use crate::splitmix::splitmix64;
use crate::synthesis::{AberrationCorrectedSmLbm, AberrationCorrection, SmLbm};

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
    pub(crate) fn id(self) -> u64 {
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
    pub(crate) fn count(&self, split: Split) -> usize {
        match split {
            Split::Train => self.train,
            Split::Val => self.val,
            Split::Test => self.test,
        }
    }

    /// Checks the configuration.
    ///
    /// Errors: [`HoloError::InvalidParameter`](crate::HoloError::InvalidParameter) for a bad scene
    /// configuration (`RandomSceneConfig::validate`), bad synthesis parameters (`levels`, optics; the
    /// aberration correction's offset and display, `AberrationCorrectedSmLbm::validate`), `shard_size`
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

/// Options of [`generate`](crate::dataset::generate) that are not part of the dataset's content.
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
    /// The display profile the dataset is made for, recorded in the manifest ([`DatasetPlan::display`](crate::dataset::DatasetPlan::display)). Its
    /// optics must be [`DatasetConfig::synthesis`]'s unless a single flag overrode them: only the record is
    /// taken from here.
    pub display: Option<DisplayInfo>,
}

/// The display profile a dataset was made for (`holo dataset --display FILE`, `docs/DISPLAYS.md`): what
/// [`OpticsInfo`](crate::dataset::OpticsInfo) does not hold. The optics themselves (the profile's, with any single flag in its place)
/// are in [`DatasetPlan::optics`](crate::dataset::DatasetPlan::optics) (the manifest's `optics`).
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
