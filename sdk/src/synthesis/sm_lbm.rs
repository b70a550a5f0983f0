//! Silhouette-mask layer-based method (Matsushima et al.; paper Eq. 1–4 and Fig. 1) with ultra-dense depth
//! partition.

use std::collections::HashMap;
use std::f64::consts::TAU;
use std::sync::atomic::{AtomicU64, Ordering};

use ndarray::{Array3, ArrayView2, ArrayView3};
use num_complex::Complex32;

use crate::error::{invalid, HoloError, Result};
use crate::optics::{
    par_channels, Carrier, OpticalSetup, PropagationOptions, Propagator, Scratch, TransferFunction,
};

/// One layer of scene points, borrowed: amplitude `[3, H, W]` (R, G, B, linear amplitude ≥ 0), normalised depth
/// `[H, W]` (`d ∈ [0, 1]`, 0 = near) and, optionally, which pixels hold a point (`[H, W]`; all if `None`).
///
/// An RGB-D image is one such layer; a layered depth image (paper Fig. 1) is several, front to back.
#[derive(Debug, Clone, Copy)]
pub struct SceneLayer<'a> {
    /// Linear amplitude `[3, H, W]`.
    pub amplitude: ArrayView3<'a, f32>,
    /// Normalised depth `[H, W]` in `[0, 1]`, 0 = near.
    pub depth: ArrayView2<'a, f32>,
    /// Point presence `[H, W]`; `None` means every pixel holds a point.
    pub valid: Option<ArrayView2<'a, bool>>,
}

/// Configuration of the silhouette-mask layer-based method.
///
/// The depth volume is partitioned into `levels` planes at `d_n = n/(levels − 1)`; every scene point goes to its
/// nearest plane. Planes are processed back to front (Eq. 2–4): the running field is propagated to the next
/// non-empty plane (consecutive empty planes are merged into one propagation), multiplied by the binary
/// silhouette mask of that plane (Eq. 3: zero where the plane holds a point) and the plane's own field
/// `A_n · exp(i·2π·z_n/λ)` is added (Eq. 1 with Maimone et al.'s initial phase, Eq. 4). The result is
/// propagated to the midpoint plane `z = 0`.
///
/// Departure from Eq. 3: the silhouette is set where a plane holds a *point* (any valid pixel), not only where
/// its amplitude is positive, so black surfaces occlude too; with every amplitude positive the two agree.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SmLbm {
    /// Number of depth planes `N` (≥ 1; the paper uses up to 10,000 and finds 2048 sufficient, Fig. 2b).
    pub levels: usize,
    /// Display geometry (wavelengths, pitch, volume depth).
    pub setup: OpticalSetup,
    /// Angular spectrum options (padding, band limit).
    pub options: PropagationOptions,
    /// Apply the silhouette masks (Eq. 3). `false` gives the occlusion-unaware layer-based method (each plane
    /// simply added), the Maimone-style baseline.
    pub silhouette_masks: bool,
}

impl Default for SmLbm {
    fn default() -> Self {
        Self {
            levels: 2048,
            setup: OpticalSetup::default(),
            options: PropagationOptions::default(),
            silhouette_masks: true,
        }
    }
}

/// Scene points bucketed by depth plane, far planes first (shared with the aberration-corrected variant).
pub(super) struct Planes {
    /// `(level, first index into points, end)` sorted by decreasing level (back to front).
    pub(super) groups: Vec<(usize, usize, usize)>,
    /// `(pixel index, [r, g, b] amplitude)` grouped by plane.
    pub(super) points: Vec<(u32, [f32; 3])>,
}

impl Planes {
    /// The points `(pixel index, [r, g, b] amplitude)` of group `g` (an index into `groups`).
    pub(super) fn points_of(&self, g: usize) -> &[(u32, [f32; 3])] {
        let (_, start, end) = self.groups[g];
        &self.points[start..end]
    }
}

/// Maximum bytes of cached transfer functions per colour.
const TF_CACHE_BYTES: usize = 64 << 20;

/// Transfer functions between planes `gap` levels apart (`gap · dl` metres toward the viewer), cached up to
/// [`TF_CACHE_BYTES`] per colour and built on the fly beyond that.
pub(super) struct GapPropagation<'a> {
    prop: &'a Propagator,
    dl: f64,
    cache: HashMap<usize, TransferFunction>,
    capacity: usize,
}

impl<'a> GapPropagation<'a> {
    /// A cache for `prop` with plane spacing `dl` metres.
    pub(super) fn new(prop: &'a Propagator, dl: f64) -> Self {
        let capacity = TF_CACHE_BYTES / (prop.plan().spectrum_len() * 8).max(1);
        Self {
            prop,
            dl,
            cache: HashMap::new(),
            capacity,
        }
    }

    /// Propagates `field` from one plane to the plane `gap` levels nearer the viewer (Eq. 2).
    pub(super) fn propagate(
        &mut self,
        field: &mut [Complex32],
        gap: usize,
        scratch: &mut Scratch,
    ) -> Result<()> {
        let distance = gap as f64 * self.dl;
        if !self.cache.contains_key(&gap) && self.cache.len() < self.capacity {
            self.cache
                .insert(gap, self.prop.transfer_function(distance, Carrier::Keep)?);
        }
        match self.cache.get(&gap) {
            Some(tf) => self.prop.propagate(field, tf, scratch),
            None => self.prop.propagate(
                field,
                &self.prop.transfer_function(distance, Carrier::Keep)?,
                scratch,
            ),
        }
    }
}

impl SmLbm {
    /// Checks `levels` and the optical setup.
    pub(crate) fn validate(&self) -> Result<()> {
        self.setup.validate()?;
        if self.levels == 0 || self.levels > 1 << 20 {
            return Err(invalid(
                "levels",
                format!("must lie in 1..=1048576, got {}", self.levels),
            ));
        }
        Ok(())
    }

    /// Normalised depth of plane `n`.
    pub(super) fn plane_depth(&self, n: usize) -> f64 {
        if self.levels == 1 {
            0.5
        } else {
            n as f64 / (self.levels - 1) as f64
        }
    }

    /// Nearest plane of normalised depth `d`.
    fn plane_of(&self, d: f32) -> usize {
        (d as f64 * (self.levels - 1) as f64).round() as usize
    }

    /// Plane spacing `dl` in metres (0 for a single plane).
    pub(super) fn plane_spacing_m(&self) -> f64 {
        if self.levels > 1 {
            self.setup.volume_depth_m / (self.levels - 1) as f64
        } else {
            0.0
        }
    }

    /// Eq. 1: the field of plane `level`'s points at wavelength `lambda`, with Maimone et al.'s initial phase
    /// `exp(i·2π·z_n/λ)` (computed in f64): the factor that multiplies a point's amplitude.
    pub(super) fn initial_phase(&self, level: usize, lambda: f64) -> Complex32 {
        let z = self.setup.depth_to_z(self.plane_depth(level));
        let (s, co) = (TAU * (z / lambda).fract()).sin_cos();
        Complex32::new(co as f32, s as f32)
    }

    /// Checks the layers and buckets their points by depth plane; returns `(height, width, planes)`.
    pub(super) fn bucket(&self, layers: &[SceneLayer]) -> Result<(usize, usize, Planes)> {
        let first = layers
            .first()
            .ok_or_else(|| invalid("layers", "at least one scene layer is needed"))?;
        let (c, h, w) = first.amplitude.dim();
        if c != 3 || h == 0 || w == 0 {
            return Err(HoloError::ShapeMismatch {
                what: "scene amplitude (expected [3, height, width])".into(),
                expected: vec![3, h.max(1), w.max(1)],
                got: vec![c, h, w],
            });
        }
        for (i, layer) in layers.iter().enumerate() {
            if layer.amplitude.dim() != (3, h, w) {
                return Err(HoloError::ShapeMismatch {
                    what: format!("amplitude of layer {i} vs layer 0"),
                    expected: vec![3, h, w],
                    got: layer.amplitude.shape().to_vec(),
                });
            }
            if layer.depth.dim() != (h, w) {
                return Err(HoloError::ShapeMismatch {
                    what: format!("depth map vs amplitude of layer {i}"),
                    expected: vec![h, w],
                    got: layer.depth.shape().to_vec(),
                });
            }
            if let Some(v) = layer.valid {
                if v.dim() != (h, w) {
                    return Err(HoloError::ShapeMismatch {
                        what: format!("validity mask vs amplitude of layer {i}"),
                        expected: vec![h, w],
                        got: v.shape().to_vec(),
                    });
                }
            }
        }
        let mut entries: Vec<(u32, u32, [f32; 3])> = Vec::with_capacity(h * w * layers.len());
        let mut last_level_at_pixel = vec![u32::MAX; h * w];
        for (i, layer) in layers.iter().enumerate() {
            for ((y, x), &d) in layer.depth.indexed_iter() {
                if let Some(v) = layer.valid {
                    if !v[[y, x]] {
                        continue;
                    }
                }
                if !(0.0..=1.0).contains(&d) {
                    return Err(HoloError::InvalidDepth(format!(
                        "layer {i} pixel (row {y}, column {x}) has depth {d}; normalised depth must lie in [0, 1]"
                    )));
                }
                let a = [
                    layer.amplitude[[0, y, x]],
                    layer.amplitude[[1, y, x]],
                    layer.amplitude[[2, y, x]],
                ];
                if a.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
                    return Err(HoloError::InvalidData(format!(
                        "layer {i} pixel (row {y}, column {x}) has amplitude {a:?}; amplitudes must be finite and ≥ 0"
                    )));
                }
                let p = y * w + x;
                let level = self.plane_of(d) as u32;
                // A rear LDI layer quantised onto the same plane as a front one is hidden by it.
                if last_level_at_pixel[p] == level {
                    continue;
                }
                last_level_at_pixel[p] = level;
                entries.push((level, p as u32, a));
            }
        }
        if entries.is_empty() {
            return Err(HoloError::InvalidDepth(
                "the scene has no valid point: nothing to synthesise".into(),
            ));
        }
        entries.sort_by_key(|e| std::cmp::Reverse(e.0));
        let mut groups = Vec::new();
        let mut start = 0;
        for i in 1..=entries.len() {
            if i == entries.len() || entries[i].0 != entries[start].0 {
                groups.push((entries[start].0 as usize, start, i));
                start = i;
            }
        }
        let points = entries.into_iter().map(|(_, p, a)| (p, a)).collect();
        Ok((h, w, Planes { groups, points }))
    }

    /// Number of angular-spectrum propagations per colour that [`SmLbm::synthesize`] performs on `layers`
    /// (one per non-empty plane; for progress reporting).
    ///
    /// Errors: as [`SmLbm::synthesize`].
    pub fn propagation_count(&self, layers: &[SceneLayer]) -> Result<usize> {
        self.validate()?;
        Ok(self.bucket(layers)?.2.groups.len())
    }

    /// Computes the midpoint hologram `[3, H, W]` (R, G, B, complex) of a scene given as layers (front to back).
    ///
    /// `progress(done, total)` is called after every propagation (from worker threads; colours run in
    /// parallel), `total = 3 ·` [`SmLbm::propagation_count`].
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a bad configuration (zero levels, bad setup);
    /// [`HoloError::ShapeMismatch`] when layers disagree in size; [`HoloError::InvalidDepth`] for a depth
    /// outside `[0, 1]` (NaN included) or a scene without any valid point; [`HoloError::InvalidData`] for a
    /// negative or non-finite amplitude.
    pub fn synthesize(
        &self,
        layers: &[SceneLayer],
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<Array3<Complex32>> {
        self.validate()?;
        let (h, w, planes) = self.bucket(layers)?;
        let props = self.setup.propagators(h, w, self.options)?;
        let total = 3 * planes.groups.len() as u64;
        let done = AtomicU64::new(0);
        let mut field = Array3::<Complex32>::zeros((3, h, w));
        par_channels(&mut field, |c, slice| {
            let prop = &props[c];
            let lambda = prop.wavelength_m();
            let mut scratch = prop.plan().scratch();
            let mut gaps = GapPropagation::new(prop, self.plane_spacing_m());
            let mut prev_level: Option<usize> = None;
            for (g, &(level, _, _)) in planes.groups.iter().enumerate() {
                if let Some(prev) = prev_level {
                    // Back to front: from plane `prev` (farther) to plane `level`, distance (prev − level)·dl > 0.
                    gaps.propagate(slice, prev - level, &mut scratch)?;
                    done.fetch_add(1, Ordering::Relaxed);
                    progress(done.load(Ordering::Relaxed), total);
                }
                let initial = self.initial_phase(level, lambda);
                for &(p, a) in planes.points_of(g) {
                    let p = p as usize;
                    let own = initial * a[c];
                    // Eq. 3–4: silhouette mask then addition of the plane's own field.
                    slice[p] = if self.silhouette_masks {
                        own
                    } else {
                        slice[p] + own
                    };
                }
                prev_level = Some(level);
            }
            // Final propagation from the nearest non-empty plane to the midpoint plane z = 0.
            let last = prev_level.expect("at least one plane");
            let z_last = self.setup.depth_to_z(self.plane_depth(last));
            if z_last != 0.0 {
                prop.propagate(
                    slice,
                    &prop.transfer_function(-z_last, Carrier::Keep)?,
                    &mut scratch,
                )?;
            }
            done.fetch_add(1, Ordering::Relaxed);
            progress(done.load(Ordering::Relaxed), total);
            Ok(())
        })?;
        Ok(field)
    }
}
