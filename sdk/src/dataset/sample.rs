//! One sample (a random LDI and the SM-LBM midpoint hologram of all its layers), the generator of samples,
//! an LDI's occlusion statistics, and the tensor layout of an LDI that the shards and the CNN share.

use std::time::Instant;

use ndarray::{s, Array3, ArrayView3, Axis, Zip};
use num_complex::Complex32;
use serde::{Deserialize, Serialize};

use super::config::{sample_seed, DatasetConfig, Split};
use crate::error::{HoloError, Result};
use crate::scene::{LayeredDepthImage, LdiLayer, RandomSceneGenerator};
use crate::synthesis::{ldi_layers, AberrationCorrectedSmLbm, SmLbm};

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
