//! Per-pixel phase calibration from camera captures of double-phase test patterns (paper Methods, Eq. 12–13).
//!
//! The SLM shows 256 patterns ([`calibration_pattern`]): in every 2×2 block the top-right and bottom-left
//! pixels stay at code 0 (reference) and the top-left and bottom-right pixels show code `k`. A camera focused on
//! the SLM (through the Fourier filter, which removes the checkerboard's grating) sees each block at intensity
//! `I_k ∝ cos²((φ(k) − φ(0))/2)`: maximal at phase differences 0, 2π, …, minimal at π, 3π, ….
//!
//! [`calibrate`] streams the captures twice (never more than one capture in memory, so memory is bounded by
//! the SLM's size whatever the camera's resolution):
//! 1. every capture, downsampled to the SLM's resolution and averaged over each 2×2 block, updates each
//!    pixel's `I_min`, `I_max` and saturation count; pixels that saturate, stay dark or never modulate are
//!    marked unusable;
//! 2. the amplitude `√I_k` of the usable pixels is summed per tile, and per tile Eq. 12 gives
//!    `θ_k = 2·acos((√I_k − √I_min)/(√I_max − √I_min))` and Eq. 13 unwraps it into `φ_k` (`θ_k` up to the first
//!    minimum `k_min`, `2π − θ_k` up to the next maximum, then `2π + θ_k`, … for panels beyond 2π);
//! 3. each tile's `φ_k` gets a smoothed monotone fit (isotonic regression, pool adjacent violators, then a
//!    Gaussian smoothing with odd reflection at both ends, which keeps it monotone and linear trends exact):
//!    the paper fits a monotone GAM;
//! 4. the tile curves form the [`TiledCurves`] per-pixel table; inverting it to phase → code happens when the
//!    table is applied ([`super::PhaseLut`]).
//!
//! Departure from the paper, and why: Eq. 12–13 run on each tile's averaged amplitude rather than on single
//! pixels. `acos` near 1 turns camera noise of σ into a phase bias of about `2·√(2σ)` (0.1 rad at σ = 0.1 %),
//! always positive, which no later smoothing removes; averaging a tile's pixels first brings σ down by the
//! square root of their number. The compact table has one curve per tile anyway.

use std::f32::consts::TAU;

use rayon::prelude::*;
use serde::Serialize;

use super::lut::{PhaseCurve, TiledCurves, CODES};
use crate::error::{invalid, HoloError, Result};

/// A stack of the 256 calibration captures of one colour, each readable on demand at the SLM's resolution.
pub trait CaptureStack: Sync {
    /// SLM size `(height, width)` the captures are downsampled to.
    fn slm_size(&self) -> (usize, usize);
    /// Name of capture `k` for messages (a file name).
    fn name(&self, k: usize) -> String;
    /// Reads capture `k ∈ 0..256`, downsampled to `[height, width]` row-major, in units of the camera's full
    /// scale (`[0, 1]`), into `out`; `clipped[i]` is set where any camera pixel of SLM pixel `i` was at full
    /// scale.
    ///
    /// Errors: whatever reading the capture meets (missing file, wrong size, corrupt data), naming it.
    fn read(&self, k: usize, out: &mut [f32], clipped: &mut [bool]) -> Result<()>;
}

/// Settings of [`calibrate`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CalibrationOptions {
    /// Tile side in SLM pixels (even, ≥ 2): the spatial resolution of the per-pixel table. 0 (the default)
    /// picks `auto_tile`.
    pub tile: usize,
    /// A pixel that reaches full scale in more than this many captures is unusable (saturated). Default 0.
    pub max_clipped_captures: usize,
    /// A pixel whose brightest capture is below this fraction of full scale is unusable (dark). Default 0.02.
    pub dark_level: f32,
    /// A pixel whose `I_max − I_min` is below this fraction of `I_max` never modulates: unusable. Default 0.2.
    pub min_contrast: f32,
    /// A tile with fewer usable pixels than this fraction is filled from its nearest calibrated tile. Default
    /// 0.25.
    pub min_tile_usable: f32,
    /// Calibration fails if more than this fraction of the SLM's pixels is unusable, or more than this
    /// fraction of the tiles had to be filled. Default 0.1.
    pub max_unusable: f32,
    /// Standard deviation (codes) of the smoothing of the monotone fit. Default 2.
    pub smoothing_codes: f32,
    /// How the light left at the intensity minimum adds to the modulated light (default
    /// [`Background::Incoherent`]).
    pub background: Background,
}

/// How the residual light `I_min` at the intensity minimum combines with the modulated light, which decides
/// the normalised amplitude `r_k` whose `2·acos` is `θ_k` (Eq. 12).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum Background {
    /// In intensity (a camera's black level, ambient or scattered light): `r_k = √((I_k − I_min)/(I_max −
    /// I_min))`. Identical to Eq. 12 when `I_min = 0`; with 1 % of background, Eq. 12 would bias mid-range
    /// phases by about 0.1 rad.
    #[default]
    Incoherent,
    /// In amplitude, Eq. 12 verbatim: `r_k = (√I_k − √I_min)/(√I_max − √I_min)` (a residual field coherent
    /// with the modulated one).
    Coherent,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        Self {
            tile: 0,
            max_clipped_captures: 0,
            dark_level: 0.02,
            min_contrast: 0.2,
            min_tile_usable: 0.25,
            max_unusable: 0.1,
            smoothing_codes: 2.0,
            background: Background::Incoherent,
        }
    }
}

/// The default tile side for an SLM of `height × width`: `2·⌊min(H, W)/64⌋` clamped to 4–16 (64 px → 4,
/// 256 px → 8, ≥ 512 px → 16), enlarged (even) until three colours' tables fit in 16 MB (a 4K panel gets 32).
pub(crate) fn auto_tile(height: usize, width: usize) -> usize {
    let mut tile = (2 * (height.min(width) / 64)).clamp(4, 16);
    while 3 * height.div_ceil(tile) * width.div_ceil(tile) * CODES * 2 > 16 << 20 {
        tile += 2;
    }
    tile.min(height.min(width).max(2) & !1).max(2)
}

impl CalibrationOptions {
    /// The tile side these options give for an SLM of `height × width` ([`auto_tile`] for 0).
    pub(crate) fn tile_for(&self, height: usize, width: usize) -> usize {
        if self.tile == 0 {
            auto_tile(height, width)
        } else {
            self.tile
        }
    }

    fn validate(&self, height: usize, width: usize) -> Result<()> {
        let tile = self.tile_for(height, width);
        if tile < 2 || !tile.is_multiple_of(2) {
            return Err(invalid(
                "tile",
                format!("must be even and ≥ 2 (2×2 blocks), got {tile}"),
            ));
        }
        if tile > height.min(width) {
            return Err(invalid(
                "tile",
                format!("{tile} is larger than the {height}×{width} SLM"),
            ));
        }
        for (name, v) in [
            ("dark_level", self.dark_level),
            ("min_contrast", self.min_contrast),
            ("min_tile_usable", self.min_tile_usable),
            ("max_unusable", self.max_unusable),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(invalid(name, format!("must lie in [0, 1], got {v}")));
            }
        }
        if !(self.smoothing_codes >= 0.0 && self.smoothing_codes <= 32.0) {
            return Err(invalid(
                "smoothing_codes",
                format!("must lie in [0, 32], got {}", self.smoothing_codes),
            ));
        }
        Ok(())
    }
}

/// What [`calibrate`] found: how many pixels and tiles were usable and why not, and the range of the
/// recovered responses.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationReport {
    /// SLM pixels.
    pub pixels: usize,
    /// Pixels that reached full scale in too many captures.
    pub saturated_pixels: usize,
    /// Pixels whose brightest capture stayed below the dark level.
    pub dark_pixels: usize,
    /// Pixels whose intensity never modulated (contrast below the minimum).
    pub flat_pixels: usize,
    /// Fraction of unusable pixels.
    pub unusable_fraction: f64,
    /// Tiles in the grid.
    pub tiles: usize,
    /// Tiles filled from a neighbour (too few usable pixels, or no minimum found).
    pub filled_tiles: usize,
    /// Tiles in which the intensity never reached a minimum (phase range below π).
    pub tiles_without_minimum: usize,
    /// Smallest and largest phase range `φ(255)` of the calibrated tiles (radians).
    pub range_rad: [f32; 2],
    /// Mean code of the first intensity minimum (phase π) over the tiles.
    pub mean_k_min: f32,
    /// Captures in which the most pixels clipped, `(capture index, pixels)`, worst first (at most 5).
    pub worst_clipping: Vec<(usize, usize)>,
}

/// One of the 256 calibration patterns `[height, width]`: code `k` on the top-left and bottom-right pixel of
/// every 2×2 block (`y` and `x` both even, or both odd), code 0 on the other two.
pub fn calibration_pattern(height: usize, width: usize, k: u8) -> ndarray::Array2<u8> {
    ndarray::Array2::from_shape_fn(
        (height, width),
        |(y, x)| if (y + x) % 2 == 0 { k } else { 0 },
    )
}

/// Per-pixel statistics of pass 1.
#[derive(Clone)]
struct PixelStats {
    min: Vec<f32>,
    max: Vec<f32>,
    clipped: Vec<u16>,
    /// Clipped pixels per capture.
    per_capture: Vec<usize>,
}

impl PixelStats {
    fn new(n: usize) -> Self {
        Self {
            min: vec![f32::INFINITY; n],
            max: vec![f32::NEG_INFINITY; n],
            clipped: vec![0; n],
            per_capture: vec![0; CODES],
        }
    }

    fn merge(mut self, o: Self) -> Self {
        for i in 0..self.min.len() {
            self.min[i] = self.min[i].min(o.min[i]);
            self.max[i] = self.max[i].max(o.max[i]);
            self.clipped[i] = self.clipped[i].saturating_add(o.clipped[i]);
        }
        for (a, b) in self.per_capture.iter_mut().zip(&o.per_capture) {
            *a += b;
        }
        self
    }
}

/// Averages each 2×2 block of `frame` (`[h, w]`) in place (an odd last row/column averages what it has); a
/// block is clipped if any of its pixels is.
fn block_average(frame: &mut [f32], clipped: &mut [bool], h: usize, w: usize) {
    for by in (0..h).step_by(2) {
        for bx in (0..w).step_by(2) {
            let (y1, x1) = ((by + 2).min(h), (bx + 2).min(w));
            let (mut s, mut n, mut c) = (0f32, 0f32, false);
            for y in by..y1 {
                for x in bx..x1 {
                    s += frame[y * w + x];
                    c |= clipped[y * w + x];
                    n += 1.0;
                }
            }
            for y in by..y1 {
                for x in bx..x1 {
                    frame[y * w + x] = s / n;
                    clipped[y * w + x] = c;
                }
            }
        }
    }
}

/// Runs the calibration of one colour (module docs): two streamed passes over the 256 captures of `stack`,
/// Eq. 12–13 per tile, a smoothed monotone fit. `progress(done, total)` is called after each capture read
/// (`total = 512`).
///
/// Errors: [`HoloError::InvalidParameter`] for bad options; the stack's own errors (missing or mismatched
/// capture, naming it); [`HoloError::InvalidData`] when the captures cannot
/// calibrate the panel, saying why and where: too many unusable pixels (saturated: the worst captures are
/// named; dark; not modulating), or a phase range below π (no intensity minimum) over too many tiles, with the
/// affected pixel region and the fraction of unusable pixels.
pub fn calibrate(
    stack: &dyn CaptureStack,
    options: &CalibrationOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<(TiledCurves, CalibrationReport)> {
    let (h, w) = stack.slm_size();
    options.validate(h, w)?;
    let n = h * w;
    let done = std::sync::atomic::AtomicU64::new(0);
    let tick = || {
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress(d, 2 * CODES as u64);
    };

    // Pass 1: per-pixel extremes and clipping, in parallel over captures (one buffer set per worker).
    let stats = (0..CODES)
        .into_par_iter()
        .try_fold(
            || (PixelStats::new(n), vec![0f32; n], vec![false; n]),
            |(mut st, mut frame, mut clipped), k| -> Result<_> {
                clipped.fill(false);
                stack.read(k, &mut frame, &mut clipped)?;
                block_average(&mut frame, &mut clipped, h, w);
                let mut count = 0;
                for i in 0..n {
                    let v = frame[i];
                    if !v.is_finite() {
                        return Err(HoloError::InvalidData(format!(
                            "capture {} holds a non-finite value",
                            stack.name(k)
                        )));
                    }
                    st.min[i] = st.min[i].min(v);
                    st.max[i] = st.max[i].max(v);
                    if clipped[i] {
                        st.clipped[i] = st.clipped[i].saturating_add(1);
                        count += 1;
                    }
                }
                st.per_capture[k] += count;
                tick();
                Ok((st, frame, clipped))
            },
        )
        .map(|r| r.map(|(st, _, _)| st))
        .try_reduce(|| PixelStats::new(n), |a, b| Ok(a.merge(b)))?;

    let (mut saturated, mut dark, mut flat) = (0usize, 0usize, 0usize);
    let mut usable = vec![false; n];
    let (mut bbox_min, mut bbox_max) = ((usize::MAX, usize::MAX), (0usize, 0usize));
    for (i, usable) in usable.iter_mut().enumerate() {
        let ok = if stats.clipped[i] as usize > options.max_clipped_captures {
            saturated += 1;
            false
        } else if stats.max[i] < options.dark_level {
            dark += 1;
            false
        } else if stats.max[i] - stats.min[i] < options.min_contrast * stats.max[i] {
            flat += 1;
            false
        } else {
            true
        };
        *usable = ok;
        if !ok {
            let (y, x) = (i / w, i % w);
            bbox_min = (bbox_min.0.min(y), bbox_min.1.min(x));
            bbox_max = (bbox_max.0.max(y), bbox_max.1.max(x));
        }
    }
    let unusable = saturated + dark + flat;
    let unusable_fraction = unusable as f64 / n as f64;
    let mut worst: Vec<(usize, usize)> = stats
        .per_capture
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, c)| *c > 0)
        .collect();
    worst.sort_by_key(|&(k, c)| (std::cmp::Reverse(c), k));
    worst.truncate(5);
    if unusable_fraction > options.max_unusable as f64 {
        let brightest = stats.max.iter().cloned().fold(0f32, f32::max);
        let mut why = Vec::new();
        if saturated > 0 {
            let names: Vec<String> = worst
                .iter()
                .map(|&(k, c)| format!("{} ({:.1} %)", stack.name(k), 100.0 * c as f64 / n as f64))
                .collect();
            why.push(format!(
                "{:.1} % saturated (full scale in some capture; worst: {}): lower the exposure",
                100.0 * saturated as f64 / n as f64,
                names.join(", ")
            ));
        }
        if dark > 0 {
            why.push(format!(
                "{:.1} % dark (brightest capture below {:.1} % of full scale; the brightest pixel of the stack \
                 reaches {:.2} %): raise the exposure or check the laser",
                100.0 * dark as f64 / n as f64,
                100.0 * options.dark_level,
                100.0 * brightest
            ));
        }
        if flat > 0 {
            why.push(format!(
                "{:.1} % never modulate (I_max − I_min below {:.0} % of I_max): check that the SLM shows the \
                 patterns and the camera is focused on it",
                100.0 * flat as f64 / n as f64,
                100.0 * options.min_contrast
            ));
        }
        return Err(HoloError::InvalidData(format!(
            "calibration captures unusable: {:.1} % of the SLM's pixels cannot be calibrated (at most {:.1} % \
             allowed), in rows {}–{}, columns {}–{}: {}",
            100.0 * unusable_fraction,
            100.0 * options.max_unusable,
            bbox_min.0,
            bbox_max.0,
            bbox_min.1,
            bbox_max.1,
            why.join("; ")
        )));
    }
    drop(stats);

    // Pass 2: per-tile sums of the usable pixels' intensity I_k.
    let tile = options.tile_for(h, w);
    let (rows, cols) = (h.div_ceil(tile), w.div_ceil(tile));
    let tiles = rows * cols;
    let mut tile_of = vec![0u32; n];
    let mut counts = vec![0u32; tiles];
    for i in 0..n {
        let t = (i / w / tile) * cols + (i % w) / tile;
        tile_of[i] = t as u32;
        if usable[i] {
            counts[t] += 1;
        }
    }
    let sums: Vec<Vec<f64>> = (0..CODES)
        .into_par_iter()
        .map_init(
            || (vec![0f32; n], vec![false; n]),
            |(frame, clipped), k| -> Result<Vec<f64>> {
                stack.read(k, frame, clipped)?;
                block_average(frame, clipped, h, w);
                let mut s = vec![0f64; tiles];
                for i in 0..n {
                    if usable[i] {
                        s[tile_of[i] as usize] += frame[i] as f64;
                    }
                }
                tick();
                Ok(s)
            },
        )
        .collect::<Result<_>>()?;

    // Eq. 12–13 and the monotone fit per tile.
    let min_count = (options.min_tile_usable * (tile * tile) as f32).max(1.0) as u32;
    let fitted: Vec<Option<(PhaseCurve, usize)>> = (0..tiles)
        .into_par_iter()
        .map(|t| {
            if counts[t] < min_count {
                return Ok(None);
            }
            let intensity: Vec<f64> = (0..CODES).map(|k| sums[k][t] / counts[t] as f64).collect();
            match unwrap_phase(&intensity, options.background) {
                Some((phi, k_min)) => {
                    let fit = monotone_fit(&phi, options.smoothing_codes);
                    Ok(Some((PhaseCurve::new(&fit)?, k_min)))
                }
                None => Ok(None),
            }
        })
        .collect::<Result<_>>()?;
    let no_minimum = (0..tiles)
        .filter(|&t| counts[t] >= min_count && fitted[t].is_none())
        .count();
    let filled = fitted.iter().filter(|f| f.is_none()).count();
    if filled as f64 > options.max_unusable as f64 * tiles as f64 || filled == tiles {
        let region = |pred: &dyn Fn(usize) -> bool| -> String {
            let bad: Vec<usize> = (0..tiles).filter(|&t| pred(t)).collect();
            if bad.is_empty() {
                return "none".into();
            }
            let (r0, r1) = (
                bad.iter().map(|t| t / cols).min().unwrap(),
                bad.iter().map(|t| t / cols).max().unwrap(),
            );
            let (c0, c1) = (
                bad.iter().map(|t| t % cols).min().unwrap(),
                bad.iter().map(|t| t % cols).max().unwrap(),
            );
            format!(
                "rows {}–{}, columns {}–{}",
                r0 * tile,
                ((r1 + 1) * tile).min(h) - 1,
                c0 * tile,
                ((c1 + 1) * tile).min(w) - 1
            )
        };
        let mut why = Vec::new();
        if no_minimum > 0 {
            why.push(format!(
                "in {:.1} % of the tiles ({}) the intensity never reaches a minimum: the SLM's phase range at \
                 this wavelength is below π (Eq. 12 needs the minimum at π), or the captures are out of order",
                100.0 * no_minimum as f64 / tiles as f64,
                region(&|t| counts[t] >= min_count && fitted[t].is_none())
            ));
        }
        let sparse = filled - no_minimum;
        if sparse > 0 {
            why.push(format!(
                "{:.1} % of the tiles ({}) have fewer than {:.0} % usable pixels",
                100.0 * sparse as f64 / tiles as f64,
                region(&|t| counts[t] < min_count),
                100.0 * options.min_tile_usable
            ));
        }
        return Err(HoloError::InvalidData(format!(
            "calibration failed in {:.1} % of the tiles (at most {:.1} % may be filled from neighbours); \
             {:.1} % of the pixels were unusable: {}",
            100.0 * filled as f64 / tiles as f64,
            100.0 * options.max_unusable,
            100.0 * unusable_fraction,
            why.join("; ")
        )));
    }
    let curves = fill_from_nearest(&fitted, rows, cols);
    let ranges: Vec<f32> = curves.iter().map(|c| c.range()).collect();
    let fitted_k: Vec<usize> = fitted.iter().flatten().map(|(_, k)| *k).collect();
    let report = CalibrationReport {
        pixels: n,
        saturated_pixels: saturated,
        dark_pixels: dark,
        flat_pixels: flat,
        unusable_fraction,
        tiles,
        filled_tiles: filled,
        tiles_without_minimum: no_minimum,
        range_rad: [
            ranges.iter().cloned().fold(f32::INFINITY, f32::min),
            ranges.iter().cloned().fold(0.0, f32::max),
        ],
        mean_k_min: fitted_k.iter().sum::<usize>() as f32 / fitted_k.len().max(1) as f32,
        worst_clipping: worst,
    };
    Ok((TiledCurves::new(h, w, tile, tile, curves)?, report))
}

/// Eq. 12–13 on one intensity curve `I_k`: the normalised amplitude `r_k` (by the [`Background`] model)
/// gives `θ_k = 2·acos(r_k)`, unwrapped across the alternating minima (phase π, 3π, …) and maxima (2π, 4π, …).
/// Returns `φ_k` and `k_min` (the first minimum), or `None` if there is no minimum (phase range below π) or no
/// modulation.
fn unwrap_phase(intensity: &[f64], background: Background) -> Option<(Vec<f32>, usize)> {
    let lo = intensity
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min)
        .max(0.0);
    let hi = intensity.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    if hi - lo <= 1e-9 * hi.abs().max(1e-30) || hi.is_nan() || lo.is_nan() {
        return None;
    }
    let r: Vec<f64> = intensity
        .iter()
        .map(|&i| {
            let i = i.max(0.0);
            match background {
                Background::Incoherent => ((i - lo) / (hi - lo)).clamp(0.0, 1.0).sqrt(),
                Background::Coherent => {
                    ((i.sqrt() - lo.sqrt()) / (hi.sqrt() - lo.sqrt())).clamp(0.0, 1.0)
                }
            }
        })
        .collect();
    // Turning points: the extreme of each run below 0.1 (a minimum) or above 0.9 (a maximum), alternating; a
    // run ends only when it crosses 0.2 (resp. 0.8), so that noise at a threshold starts no false run. In a
    // run that lasts to the last code the extreme is still a turn: after it the phase keeps increasing on the
    // next branch (if the range ends just before the turn, the few codes after it are within noise of it).
    let mut turns = Vec::new();
    let mut k = 0usize;
    let mut want_min = true;
    loop {
        let enter = |v: f64| if want_min { v < 0.1 } else { v > 0.9 };
        let stay = |v: f64| if want_min { v < 0.2 } else { v > 0.8 };
        let Some(start) = (k..CODES).find(|&i| enter(r[i])) else {
            break;
        };
        let end = (start..CODES).find(|&i| !stay(r[i])).unwrap_or(CODES);
        let key = |i: usize| if want_min { r[i] } else { -r[i] };
        let ext = (start..end)
            .min_by(|&a, &b| key(a).partial_cmp(&key(b)).expect("finite"))
            .expect("non-empty run");
        if end == CODES {
            if turns.is_empty() && ext + 3 >= CODES {
                // The intensity falls until the last codes: the range does not pass π.
                return None;
            }
            if ext + 1 < CODES {
                turns.push(ext);
            }
            break;
        }
        turns.push(ext);
        k = end;
        want_min = !want_min;
    }
    let k_min = *turns.first()?;
    let mut phi = vec![0f32; CODES];
    let mut segment = 0usize;
    for (k, p) in phi.iter_mut().enumerate() {
        while segment < turns.len() && k > turns[segment] {
            segment += 1;
        }
        let theta = (2.0 * r[k].acos()) as f32;
        // Segment s: before the first minimum φ = θ; then 2π − θ; 2π + θ; 4π − θ; …
        let cycle = (segment.div_ceil(2)) as f32 * TAU;
        *p = if segment.is_multiple_of(2) {
            cycle + theta
        } else {
            cycle - theta
        };
    }
    Some((phi, k_min))
}

/// Smoothed monotone fit of a curve: isotonic regression (pool adjacent violators), Gaussian smoothing of
/// standard deviation `sigma` codes with odd (point) reflection at both ends, shifted so that code 0 is 0.
pub(crate) fn monotone_fit(values: &[f32], sigma: f32) -> Vec<f32> {
    // Pool adjacent violators. Code 0 is the reference of Eq. 13: its phase is 0 by definition, and anchoring
    // it there (rather than at its noisy estimate) keeps the noise of the first codes out of the whole curve.
    let mut blocks: Vec<(f64, usize)> = Vec::with_capacity(values.len());
    for (k, &v) in values.iter().enumerate() {
        let v = if k == 0 { 0.0 } else { v };
        blocks.push((v as f64, 1));
        while blocks.len() > 1 {
            let (b, nb) = blocks[blocks.len() - 1];
            let (a, na) = blocks[blocks.len() - 2];
            if a <= b {
                break;
            }
            blocks.pop();
            let last = blocks.last_mut().expect("two blocks");
            *last = ((a * na as f64 + b * nb as f64) / (na + nb) as f64, na + nb);
        }
    }
    let iso: Vec<f64> = blocks
        .iter()
        .flat_map(|&(v, n)| std::iter::repeat_n(v, n))
        .collect();
    let n = iso.len() as isize;
    let smoothed: Vec<f64> = if sigma > 0.0 {
        let radius = (3.0 * sigma).ceil() as isize;
        let kernel: Vec<f64> = (-radius..=radius)
            .map(|i| (-(i * i) as f64 / (2.0 * (sigma as f64).powi(2))).exp())
            .collect();
        let norm: f64 = kernel.iter().sum();
        // Odd reflection: v(−i) = 2·v(0) − v(i), v(n−1+i) = 2·v(n−1) − v(n−1−i).
        let at = |i: isize| -> f64 {
            if i < 0 {
                2.0 * iso[0] - iso[(-i).min(n - 1) as usize]
            } else if i >= n {
                2.0 * iso[(n - 1) as usize] - iso[(2 * (n - 1) - i).max(0) as usize]
            } else {
                iso[i as usize]
            }
        };
        (0..n)
            .map(|i| {
                (-radius..=radius)
                    .zip(&kernel)
                    .map(|(j, k)| k * at(i + j))
                    .sum::<f64>()
                    / norm
            })
            .collect()
    } else {
        iso
    };
    let base = smoothed[0];
    let mut prev = 0f32;
    smoothed
        .iter()
        .map(|v| {
            prev = prev.max((v - base).max(0.0) as f32);
            prev
        })
        .collect()
}

/// Replaces missing tile curves by the nearest calibrated tile's (breadth-first over the grid).
fn fill_from_nearest(
    fitted: &[Option<(PhaseCurve, usize)>],
    rows: usize,
    cols: usize,
) -> Vec<PhaseCurve> {
    let mut source: Vec<Option<usize>> = fitted
        .iter()
        .enumerate()
        .map(|(i, f)| f.as_ref().map(|_| i))
        .collect();
    let mut queue: std::collections::VecDeque<usize> =
        (0..fitted.len()).filter(|&i| source[i].is_some()).collect();
    while let Some(t) = queue.pop_front() {
        let (r, c) = (t / cols, t % cols);
        let neighbours = [
            (r > 0).then(|| t - cols),
            (r + 1 < rows).then(|| t + cols),
            (c > 0).then(|| t - 1),
            (c + 1 < cols).then(|| t + 1),
        ];
        for nb in neighbours.into_iter().flatten() {
            if source[nb].is_none() {
                source[nb] = source[t];
                queue.push_back(nb);
            }
        }
    }
    source
        .iter()
        .map(|s| {
            fitted[s.expect("at least one calibrated tile")]
                .as_ref()
                .expect("calibrated")
                .0
                .clone()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::PI;

    /// Intensities with 2 % of incoherent background.
    fn intensity_of(curve: &PhaseCurve) -> Vec<f64> {
        curve
            .phases()
            .iter()
            .map(|p| ((p / 2.0).cos() as f64).powi(2) * 0.9 + 0.02)
            .collect()
    }

    #[test]
    fn unwrapping_recovers_ranges_below_and_beyond_two_pi() {
        for range in [1.3 * PI, 1.9 * PI, 2.0 * PI, 2.5 * PI, 3.4 * PI] {
            let truth = PhaseCurve::gamma(range, 1.3).unwrap();
            let (phi, k_min) =
                unwrap_phase(&intensity_of(&truth), Background::Incoherent).expect("has a minimum");
            let err = phi
                .iter()
                .zip(truth.phases().iter())
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f32>()
                / CODES as f32;
            assert!(err.sqrt() < 0.02, "range {range}: rms {}", err.sqrt());
            let want = truth.phases().iter().position(|&p| p >= PI).unwrap();
            assert!(
                k_min.abs_diff(want) <= 1,
                "range {range}: k_min {k_min} vs {want}"
            );
        }
    }

    #[test]
    fn a_range_below_pi_has_no_minimum() {
        let truth = PhaseCurve::gamma(0.8 * PI, 1.0).unwrap();
        assert!(unwrap_phase(&intensity_of(&truth), Background::Incoherent).is_none());
        assert!(unwrap_phase(&[0.5; CODES], Background::Coherent).is_none());
    }

    #[test]
    fn monotone_fit_is_monotone_and_keeps_lines() {
        let line: Vec<f32> = (0..CODES).map(|k| 0.02 * k as f32).collect();
        let fit = monotone_fit(&line, 2.0);
        for (a, b) in fit.iter().zip(&line) {
            assert!((a - b).abs() < 1e-4, "{a} vs {b}");
        }
        let mut rng = crate::splitmix::SplitMix64::new(3);
        let noisy: Vec<f32> = line
            .iter()
            .map(|v| v + 0.2 * (rng.next_f64() as f32 - 0.5))
            .collect();
        let fit = monotone_fit(&noisy, 2.0);
        assert!(fit.windows(2).all(|w| w[1] >= w[0]));
        assert_eq!(fit[0], 0.0);
        let rms = |v: &[f32]| {
            (v.iter()
                .zip(&line)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f32>()
                / CODES as f32)
                .sqrt()
        };
        let (before, after) = (rms(&noisy), rms(&fit));
        assert!(
            after < 0.5 * before,
            "smoothing should average noise out: rms {before} → {after}"
        );
    }

    #[test]
    fn patterns_follow_the_two_by_two_layout() {
        let p = calibration_pattern(4, 6, 77);
        assert_eq!(p[[0, 0]], 77);
        assert_eq!(p[[1, 1]], 77);
        assert_eq!(p[[0, 1]], 0);
        assert_eq!(p[[1, 0]], 0);
        assert_eq!(p[[3, 5]], 77);
    }
}
