//! Phase look-up tables: the SLM's response (phase displayed by each 8-bit code) and its inverse (target
//! phase → code), global or per pixel in a compact tiled form (paper Methods, "Compensating hardware
//! imperfection", Fig. 11).
//!
//! A response curve gives, for codes `k = 0..=255`, the phase in radians that code `k` displays relative to
//! code 0 (so `φ(0) = 0`), non-decreasing. The inverse is what the pipeline needs: each wrapped target phase
//! `θ ∈ [0, 2π)` from double phase encoding (Eq. 7) becomes the code whose response is nearest. The inverse
//! treats code 256 as code 0 one cycle later (phase 2π): an SLM whose range is below 2π sends phases in the gap
//! `(φ(255), 2π)` to code 255 or 0, whichever is nearer in code space; an SLM whose range exceeds 2π uses the
//! codes up to the one displaying 2π.
//!
//! **Per-pixel tables, compactly.** A full table at 1920×1080 × 3 colours × 256 codes is 1.6 GB. A real panel's
//! response varies smoothly (liquid-crystal cell gap, heating), so [`TiledCurves`] stores one curve per tile
//! of `tile × tile` pixels (16-bit fixed point) and evaluates a pixel's curve by bilinear interpolation
//! between the four nearest tile centres. At 1080p with 16-pixel tiles, three colours take 12.5 MB
//! (`docs/CALIBRATION.md`). Applying it interpolates the tiles' inverse
//! tables (fractional codes at 256 phase bins), which is allocation-free and needs no search.

use std::f32::consts::TAU;

use crate::error::{invalid, HoloError, Result};

/// Number of SLM codes (8-bit).
pub const CODES: usize = 256;

/// Phase bins of an inverse table: `θ_j = 2π·j/INVERSE_BINS`, `j = 0..=INVERSE_BINS`.
const INVERSE_BINS: usize = 256;
/// Fixed-point scale of an inverse table entry (fractional code × 128; code 256 → 32768).
const INVERSE_SCALE: f32 = 128.0;
/// Fixed-point scale of stored curves: `phase_rad = q / CURVE_SCALE` (resolution 2.4e-4 rad, up to 16 rad).
pub(crate) const CURVE_SCALE: f32 = 4096.0;
/// Largest phase a stored curve may reach (radians), `u16::MAX / CURVE_SCALE`.
pub const MAX_CURVE_PHASE: f32 = u16::MAX as f32 / CURVE_SCALE;

/// The phase response of one pixel, tile or whole panel: `phases[k]` is the phase in radians that code `k`
/// displays relative to code 0 (`phases[0] = 0`), non-decreasing, at most [`MAX_CURVE_PHASE`].
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseCurve {
    phases: Box<[f32; CODES]>,
}

impl PhaseCurve {
    /// A curve from 256 phases in radians (code 0 first). The phase of code 0 is subtracted (a global phase
    /// offset is invisible), so the stored curve starts at 0.
    ///
    /// Errors: [`HoloError::InvalidData`] if there are not exactly 256 values, any is NaN or infinite, the
    /// curve decreases anywhere by more than 1e-4 rad (smaller decreases, float noise, are flattened), or its
    /// range exceeds [`MAX_CURVE_PHASE`].
    pub(crate) fn new(phases: &[f32]) -> Result<Self> {
        if phases.len() != CODES {
            return Err(HoloError::InvalidData(format!(
                "a phase curve has {CODES} values (codes 0–255), got {}",
                phases.len()
            )));
        }
        if let Some(k) = phases.iter().position(|p| !p.is_finite()) {
            return Err(HoloError::InvalidData(format!(
                "phase curve value of code {k} is {}",
                phases[k]
            )));
        }
        let mut out = Box::new([0f32; CODES]);
        let base = phases[0];
        let mut prev = 0f32;
        for (k, (o, &p)) in out.iter_mut().zip(phases).enumerate() {
            let v = p - base;
            if v < prev - 1e-4 {
                return Err(HoloError::InvalidData(format!(
                    "phase curve decreases at code {k} ({:.4} rad after {:.4} rad); a look-up table needs a \
                     non-decreasing response",
                    v, prev
                )));
            }
            *o = v.max(prev);
            prev = *o;
        }
        if prev > MAX_CURVE_PHASE {
            return Err(HoloError::InvalidData(format!(
                "phase curve reaches {prev:.3} rad; at most {MAX_CURVE_PHASE:.3} rad (about 5π) is supported"
            )));
        }
        Ok(Self { phases: out })
    }

    /// The ideal linear SLM of [`LinearLut`](crate::encoding::LinearLut): code `k` displays `2π·k/256`.
    pub fn linear() -> Self {
        Self::gamma(TAU * 255.0 / 256.0, 1.0).expect("valid model")
    }

    /// The gamma/range model `φ(k) = range·(k/255)^γ` in radians (`range = φ(255)`). `gamma(2π·255/256,
    /// 1.0)` is the linear SLM; a panel driven over `3π` at code 255 is `gamma(3π, γ)`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a range that is not in `(0, MAX_CURVE_PHASE]` or a gamma
    /// that is not in `[0.1, 10]`.
    pub fn gamma(range_rad: f32, gamma: f32) -> Result<Self> {
        if !(range_rad > 0.0 && range_rad <= MAX_CURVE_PHASE) {
            return Err(invalid(
                "range_rad",
                format!("must lie in (0, {MAX_CURVE_PHASE:.3}] rad, got {range_rad}"),
            ));
        }
        if !(0.1..=10.0).contains(&gamma) {
            return Err(invalid(
                "gamma",
                format!("must lie in [0.1, 10], got {gamma}"),
            ));
        }
        let mut phases = Box::new([0f32; CODES]);
        for (k, p) in phases.iter_mut().enumerate() {
            *p = range_rad * (k as f32 / 255.0).powf(gamma);
        }
        Ok(Self { phases })
    }

    /// Parses a CSV global look-up table: one `code,phase` row per code 0–255 (phase in radians, any order of
    /// rows, `#` comments, blank lines and one optional header row such as `code,phase_rad` are skipped).
    /// `source` names the file in errors.
    ///
    /// Errors: [`HoloError::InvalidData`] naming `source` and the line for a malformed row, a code outside
    /// 0–255, a repeated or missing code, or a curve `PhaseCurve::new` refuses.
    pub fn from_csv(text: &str, source: &str) -> Result<Self> {
        let mut phases = [f32::NAN; CODES];
        let mut seen = [false; CODES];
        let mut header_allowed = true;
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let bad = |why: String| {
                HoloError::InvalidData(format!("{source}, line {}: {why} (`{line}`)", i + 1))
            };
            let fields: Vec<&str> = line.split([',', ';', '\t']).map(str::trim).collect();
            if fields.len() != 2 {
                return Err(bad("expected two columns: code, phase in radians".into()));
            }
            let code = match fields[0].parse::<i64>() {
                Ok(c) => c,
                Err(_) if header_allowed => {
                    header_allowed = false;
                    continue;
                }
                Err(_) => return Err(bad(format!("`{}` is not an integer code", fields[0]))),
            };
            header_allowed = false;
            if !(0..CODES as i64).contains(&code) {
                return Err(bad(format!("code {code} is outside 0–255")));
            }
            let phase: f32 = fields[1]
                .parse()
                .map_err(|_| bad(format!("`{}` is not a phase in radians", fields[1])))?;
            let c = code as usize;
            if seen[c] {
                return Err(bad(format!("code {c} appears twice")));
            }
            seen[c] = true;
            phases[c] = phase;
        }
        if let Some(missing) = seen.iter().position(|s| !s) {
            let count = seen.iter().filter(|s| !**s).count();
            return Err(HoloError::InvalidData(format!(
                "{source}: {count} of the 256 codes have no row (first missing: code {missing})"
            )));
        }
        Self::new(&phases).map_err(|e| match e {
            HoloError::InvalidData(m) => HoloError::InvalidData(format!("{source}: {m}")),
            other => other,
        })
    }

    /// The phases in radians, code 0 first.
    pub fn phases(&self) -> &[f32; CODES] {
        &self.phases
    }

    /// The phase of code 255 (radians): the SLM's modulation range at this wavelength.
    pub(crate) fn range(&self) -> f32 {
        self.phases[CODES - 1]
    }

    /// The curve quantised to the stored 16-bit form (`q = round(φ·4096)`).
    pub(crate) fn to_fixed(&self) -> [u16; CODES] {
        let mut q = [0u16; CODES];
        for (o, &p) in q.iter_mut().zip(self.phases.iter()) {
            *o = (p * CURVE_SCALE).round().clamp(0.0, u16::MAX as f32) as u16;
        }
        q
    }

    /// The curve of stored 16-bit values (inverse of [`PhaseCurve::to_fixed`]); `what` names it in errors.
    pub(crate) fn from_fixed(q: &[u16], what: &str) -> Result<Self> {
        let phases: Vec<f32> = q.iter().map(|&v| v as f32 / CURVE_SCALE).collect();
        Self::new(&phases).map_err(|e| HoloError::InvalidData(format!("{what}: {e}")))
    }

    /// The inverse table: fractional codes (× 128) at target phases `θ_j = 2π·j/256`, `j = 0..=256`.
    fn inverse_table(&self, out: &mut [u16]) {
        debug_assert_eq!(out.len(), INVERSE_BINS + 1);
        // Extended curve: code 256 is code 0 one cycle later when the range is below 2π.
        let p = &self.phases;
        let mut k = 0usize;
        for (j, o) in out.iter_mut().enumerate() {
            let theta = TAU * j as f32 / INVERSE_BINS as f32;
            let kappa = loop {
                let (lo, hi) = if k + 1 < CODES {
                    (p[k], p[k + 1])
                } else if k + 1 == CODES && p[CODES - 1] < TAU {
                    (p[CODES - 1], TAU)
                } else {
                    // Past the last code (range ≥ 2π only reaches here at θ beyond it): the last code.
                    break (CODES - 1) as f32;
                };
                if theta <= hi {
                    let f = if hi > lo {
                        (theta - lo) / (hi - lo)
                    } else {
                        0.0
                    };
                    break k as f32 + f.clamp(0.0, 1.0);
                }
                k += 1;
            };
            *o = (kappa * INVERSE_SCALE).round() as u16;
        }
    }

    /// The code whose displayed phase is nearest `θ` (wrapped to `[0, 2π)` first), by the same rule as the
    /// inverse tables but without their interpolation: the naive reference of the tests.
    #[cfg(test)]
    pub(crate) fn nearest_code(&self, theta: f32) -> u8 {
        let t = crate::encoding::wrap_phase(theta);
        let mut best = (f32::INFINITY, 0u8);
        for (k, &p) in self.phases.iter().enumerate() {
            let d = (p - t).abs().min((p - t - TAU).abs());
            if d < best.0 {
                best = (d, k as u8);
            }
        }
        best.1
    }
}

/// One pixel's bilinear weights along one axis of a [`TiledCurves`]: `(tile index a, tile index b, weight of
/// b)`.
pub(crate) type AxisWeight = (u32, u32, f32);

/// Per-pixel phase responses in compact form: one [`PhaseCurve`] per tile of `tile_height × tile_width`
/// pixels of an SLM of `height × width` pixels, tiles in row-major order `[rows, cols]`. A pixel's response is
/// the bilinear interpolation of the curves at the four nearest tile centres (clamped at the borders).
#[derive(Debug, Clone, PartialEq)]
pub struct TiledCurves {
    height: usize,
    width: usize,
    tile_height: usize,
    tile_width: usize,
    curves: Vec<PhaseCurve>,
}

impl TiledCurves {
    /// Tiles of `tile_height × tile_width` pixels over an SLM of `height × width`; `curves` holds
    /// `ceil(height/tile_height) · ceil(width/tile_width)` curves in row-major tile order.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a zero size or tile, or a tile larger than the SLM;
    /// [`HoloError::ShapeMismatch`] for the wrong number of curves.
    pub fn new(
        height: usize,
        width: usize,
        tile_height: usize,
        tile_width: usize,
        curves: Vec<PhaseCurve>,
    ) -> Result<Self> {
        if height == 0 || width == 0 {
            return Err(invalid(
                "slm size",
                format!("must be ≥ 1×1, got {height}×{width}"),
            ));
        }
        if tile_height == 0 || tile_width == 0 || tile_height > height || tile_width > width {
            return Err(invalid(
                "tile",
                format!(
                    "tile {tile_height}×{tile_width} must be ≥ 1×1 and no larger than the SLM \
                     ({height}×{width})"
                ),
            ));
        }
        let (rows, cols) = (height.div_ceil(tile_height), width.div_ceil(tile_width));
        if curves.len() != rows * cols {
            return Err(HoloError::ShapeMismatch {
                what: format!(
                    "tile curves of a {height}×{width} SLM in {tile_height}×{tile_width} tiles"
                ),
                expected: vec![rows, cols],
                got: vec![curves.len()],
            });
        }
        Ok(Self {
            height,
            width,
            tile_height,
            tile_width,
            curves,
        })
    }

    /// SLM size `(height, width)` in pixels.
    pub(crate) fn size(&self) -> (usize, usize) {
        (self.height, self.width)
    }

    /// Tile size `(height, width)` in pixels.
    pub fn tile(&self) -> (usize, usize) {
        (self.tile_height, self.tile_width)
    }

    /// Tile grid `(rows, cols)`.
    pub(crate) fn grid(&self) -> (usize, usize) {
        (
            self.height.div_ceil(self.tile_height),
            self.width.div_ceil(self.tile_width),
        )
    }

    /// The tile curves, row-major `[rows, cols]`.
    pub fn curves(&self) -> &[PhaseCurve] {
        &self.curves
    }

    /// The mean of all tile curves: the best global table for this panel.
    pub fn mean_curve(&self) -> PhaseCurve {
        let mut sum = [0f64; CODES];
        for c in &self.curves {
            for (s, &p) in sum.iter_mut().zip(c.phases.iter()) {
                *s += p as f64;
            }
        }
        let n = self.curves.len() as f64;
        let mean: Vec<f32> = sum.iter().map(|s| (s / n) as f32).collect();
        PhaseCurve::new(&mean).expect("a mean of valid curves is valid")
    }

    /// Bilinear weights along one axis: for each pixel, `(tile index a, tile index b, weight of b)`. Within the
    /// half tile beyond the outermost tile centres the two outermost tiles extrapolate linearly (weights
    /// outside `[0, 1]`), which follows a smooth response to the panel's edge better than clamping.
    fn axis_weights(len: usize, tile: usize) -> Vec<AxisWeight> {
        (0..len).map(|i| Self::axis_weight(i, len, tile)).collect()
    }

    /// The weights of [`TiledCurves::axis_weights`] for pixel `i` alone.
    fn axis_weight(i: usize, len: usize, tile: usize) -> AxisWeight {
        let n = len.div_ceil(tile);
        if n == 1 {
            return (0, 0, 0.0);
        }
        let t = ((i as f32 + 0.5) / tile as f32 - 0.5).clamp(-0.5, n as f32 - 0.5);
        let a = (t.floor().max(0.0) as usize).min(n - 2);
        (a as u32, a as u32 + 1, t - a as f32)
    }

    /// The response curve of pixel `(y, x)` (bilinear between tile centres), phases in radians.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a pixel outside the SLM.
    pub fn pixel_curve(&self, y: usize, x: usize) -> Result<[f32; CODES]> {
        if y >= self.height || x >= self.width {
            return Err(invalid(
                "pixel",
                format!(
                    "({y}, {x}) lies outside the {}×{} SLM",
                    self.height, self.width
                ),
            ));
        }
        let wy = Self::axis_weight(y, self.height, self.tile_height);
        let wx = Self::axis_weight(x, self.width, self.tile_width);
        let mut out = [0f32; CODES];
        self.blend(wy, wx, &mut out);
        Ok(out)
    }

    /// `out` (256 values) ← the bilinear blend of the four tile curves of row weights `wy`, column weights `wx`.
    fn blend(&self, wy: AxisWeight, wx: AxisWeight, out: &mut [f32]) {
        let cols = self.grid().1;
        out.fill(0.0);
        let corners = [
            (wy.0, wx.0, (1.0 - wy.2) * (1.0 - wx.2)),
            (wy.0, wx.1, (1.0 - wy.2) * wx.2),
            (wy.1, wx.0, wy.2 * (1.0 - wx.2)),
            (wy.1, wx.1, wy.2 * wx.2),
        ];
        for (ty, tx, wgt) in corners {
            let c = &self.curves[ty as usize * cols + tx as usize];
            for (o, &p) in out.iter_mut().zip(c.phases.iter()) {
                *o += wgt * p;
            }
        }
    }

    /// The phase code `code` displays under row weights `wy` and column weights `wx` (one value of
    /// [`TiledCurves::blend`]).
    #[inline]
    fn blend_at(&self, wy: AxisWeight, wx: AxisWeight, code: u8) -> f32 {
        let cols = self.grid().1;
        let at =
            |ty: u32, tx: u32| self.curves[ty as usize * cols + tx as usize].phases[code as usize];
        let top = at(wy.0, wx.0) * (1.0 - wx.2) + at(wy.0, wx.1) * wx.2;
        let bottom = at(wy.1, wx.0) * (1.0 - wx.2) + at(wy.1, wx.1) * wx.2;
        top * (1.0 - wy.2) + bottom * wy.2
    }

    /// The bilinear weights of every row and every column (`(tile a, tile b, weight of b)`), for
    /// [`TiledCurves::phase_and_slope`].
    pub(crate) fn row_and_column_weights(&self) -> (Vec<AxisWeight>, Vec<AxisWeight>) {
        (
            Self::axis_weights(self.height, self.tile_height),
            Self::axis_weights(self.width, self.tile_width),
        )
    }

    /// The phase in radians the drive `v` (a code as a number, linear between codes, clamped to the table) shows
    /// at the pixel of row weights `wy` and column weights `wx` ([`TiledCurves::row_and_column_weights`]; the
    /// bilinear blend of [`TiledCurves::pixel_curve`]), and its slope per code.
    #[inline]
    pub(crate) fn phase_and_slope(&self, wy: AxisWeight, wx: AxisWeight, v: f32) -> (f32, f32) {
        interpolate_codes(v, |k| self.blend_at(wy, wx, k))
    }

    /// Writes the response curves of rows `rows` of the SLM into `out` (`[rows.len(), width, 256]`
    /// row-major, radians).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for rows outside the SLM; [`HoloError::ShapeMismatch`] for an
    /// `out` of the wrong length.
    pub fn curves_of_rows(&self, rows: std::ops::Range<usize>, out: &mut [f32]) -> Result<()> {
        if rows.end > self.height || rows.start > rows.end {
            return Err(invalid(
                "rows",
                format!("{rows:?} is not within the SLM's {} rows", self.height),
            ));
        }
        let want = rows.len() * self.width * CODES;
        if out.len() != want {
            return Err(HoloError::ShapeMismatch {
                what: "curve rows buffer".into(),
                expected: vec![rows.len(), self.width, CODES],
                got: vec![out.len()],
            });
        }
        let wys = Self::axis_weights(self.height, self.tile_height);
        let wxs = Self::axis_weights(self.width, self.tile_width);
        for (r, y) in rows.enumerate() {
            for (x, wx) in wxs.iter().enumerate() {
                self.blend(
                    wys[y],
                    *wx,
                    &mut out[(r * self.width + x) * CODES..][..CODES],
                );
            }
        }
        Ok(())
    }

    /// Bytes of the stored form (16 bits per code per tile).
    pub fn stored_bytes(&self) -> usize {
        self.curves.len() * CODES * 2
    }
}

/// A response at the drive `v` (a code as a number), linear between the codes `phase_of(k)`, `k` clamped to
/// 0…255, and its slope per code.
#[inline]
pub(crate) fn interpolate_codes(v: f32, phase_of: impl Fn(u8) -> f32) -> (f32, f32) {
    let i = (v.floor() as isize).clamp(0, CODES as isize - 2) as u8;
    let (a, b) = (phase_of(i), phase_of(i + 1));
    let slope = b - a;
    (a + (v - f32::from(i)) * slope, slope)
}

/// How one colour's look-up table is represented.
#[derive(Debug, Clone, PartialEq)]
pub enum LutRepresentation {
    /// The ideal linear SLM ([`crate::encoding::LinearLut`]): code `c` displays `2π·c/256`.
    Linear,
    /// One response for every pixel.
    Global(PhaseCurve),
    /// Per-pixel responses as bilinearly interpolated tile curves.
    Tiled(TiledCurves),
}

impl LutRepresentation {
    /// Short name: `linear`, `global` or `tiled`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Linear => "linear",
            Self::Global(_) => "global",
            Self::Tiled(_) => "tiled",
        }
    }
}

/// A colour's phase → code look-up table, ready to apply: the representation plus its inverse tables
/// (built once; applying allocates nothing).
#[derive(Debug, Clone)]
pub struct PhaseLut {
    representation: LutRepresentation,
    /// Inverse tables, `(INVERSE_BINS + 1)` entries per curve (one curve for `Global`, one per tile).
    inverse: Vec<u16>,
    /// Per SLM row: (tile row a, tile row b, weight of b); per column likewise (`Tiled` only).
    rows: Vec<AxisWeight>,
    cols: Vec<AxisWeight>,
    grid_cols: usize,
}

impl PhaseLut {
    /// The LUT of the representation (inverse tables built here).
    pub fn new(representation: LutRepresentation) -> Self {
        let stride = INVERSE_BINS + 1;
        let (inverse, rows, cols, grid_cols) = match &representation {
            LutRepresentation::Linear => (Vec::new(), Vec::new(), Vec::new(), 0),
            LutRepresentation::Global(c) => {
                let mut inv = vec![0u16; stride];
                c.inverse_table(&mut inv);
                (inv, Vec::new(), Vec::new(), 0)
            }
            LutRepresentation::Tiled(t) => {
                let mut inv = vec![0u16; stride * t.curves.len()];
                for (c, out) in t.curves.iter().zip(inv.chunks_exact_mut(stride)) {
                    c.inverse_table(out);
                }
                (
                    inv,
                    TiledCurves::axis_weights(t.height, t.tile_height),
                    TiledCurves::axis_weights(t.width, t.tile_width),
                    t.grid().1,
                )
            }
        };
        Self {
            representation,
            inverse,
            rows,
            cols,
            grid_cols,
        }
    }

    /// The ideal linear LUT.
    pub fn linear() -> Self {
        Self::new(LutRepresentation::Linear)
    }

    /// The representation.
    pub fn representation(&self) -> &LutRepresentation {
        &self.representation
    }

    /// The SLM size a per-pixel LUT is made for (`None` for linear and global tables, which fit any size).
    pub(crate) fn size(&self) -> Option<(usize, usize)> {
        match &self.representation {
            LutRepresentation::Tiled(t) => Some(t.size()),
            _ => None,
        }
    }

    /// The phase in radians that `code` displays at pixel `(y, x)` (relative to code 0).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a pixel outside a per-pixel LUT's SLM.
    pub fn displayed_phase(&self, y: usize, x: usize, code: u8) -> Result<f32> {
        Ok(match &self.representation {
            LutRepresentation::Linear => crate::encoding::LinearLut.phase(code),
            LutRepresentation::Global(c) => c.phases[code as usize],
            LutRepresentation::Tiled(t) => t.pixel_curve(y, x)?[code as usize],
        })
    }

    /// Converts one colour's wrapped phase pattern `[height, width]` (radians; any value is wrapped to
    /// `[0, 2π)` first) into 8-bit codes, row-major, allocation-free.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if `phase` or `codes` is not `height · width` long, or a per-pixel
    /// LUT was made for another SLM size.
    pub fn apply(
        &self,
        height: usize,
        width: usize,
        phase: &[f32],
        codes: &mut [u8],
    ) -> Result<()> {
        self.check_plane(height, width, phase.len(), codes.len())?;
        let bins = INVERSE_BINS as f32 / TAU;
        let stride = INVERSE_BINS + 1;
        match &self.representation {
            LutRepresentation::Linear => {
                for (c, &p) in codes.iter_mut().zip(phase) {
                    *c = crate::encoding::LinearLut.code(p);
                }
            }
            LutRepresentation::Global(_) => {
                let inv = &self.inverse[..stride];
                for (c, &p) in codes.iter_mut().zip(phase) {
                    let (j, f) = bin(p, bins);
                    *c = to_code(lerp(inv[j], inv[j + 1], f));
                }
            }
            LutRepresentation::Tiled(_) => {
                for (y, (prow, crow)) in phase
                    .chunks_exact(width)
                    .zip(codes.chunks_exact_mut(width))
                    .enumerate()
                {
                    let (ta, tb, wy) = self.rows[y];
                    let row_a = ta as usize * self.grid_cols;
                    let row_b = tb as usize * self.grid_cols;
                    for ((c, &p), &(xa, xb, wx)) in crow.iter_mut().zip(prow).zip(&self.cols) {
                        let (j, f) = bin(p, bins);
                        let at = |t: usize| {
                            let tab = &self.inverse[t * stride + j..][..2];
                            lerp(tab[0], tab[1], f)
                        };
                        let top =
                            at(row_a + xa as usize) * (1.0 - wx) + at(row_a + xb as usize) * wx;
                        let bottom =
                            at(row_b + xa as usize) * (1.0 - wx) + at(row_b + xb as usize) * wx;
                        *c = to_code(top * (1.0 - wy) + bottom * wy);
                    }
                }
            }
        }
        Ok(())
    }
}

impl PhaseLut {
    /// Checks one colour's pattern buffers (`a_len`, `b_len` values) against `[height, width]` and a per-pixel
    /// LUT's SLM size.
    fn check_plane(&self, height: usize, width: usize, a_len: usize, b_len: usize) -> Result<()> {
        let n = height
            .checked_mul(width)
            .ok_or_else(|| invalid("size", format!("{height}×{width} overflows")))?;
        if a_len != n || b_len != n {
            return Err(HoloError::ShapeMismatch {
                what: "SLM pattern buffers vs the LUT's [H, W]".into(),
                expected: vec![height, width],
                got: vec![a_len, b_len],
            });
        }
        match self.size() {
            Some((h, w)) if (h, w) != (height, width) => Err(HoloError::ShapeMismatch {
                what: "SLM pattern vs the per-pixel look-up table's SLM".into(),
                expected: vec![h, w],
                got: vec![height, width],
            }),
            _ => Ok(()),
        }
    }

    /// The forward direction of [`PhaseLut::apply`]: the phase in radians (relative to code 0, not wrapped)
    /// that each code of one colour's pattern `codes` (`[height, width]`, row-major) displays, into `out`
    /// (same length); allocation-free. What a viewer of a calibrated display sees (the preview).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] as [`PhaseLut::apply`].
    pub(crate) fn displayed_phases(
        &self,
        height: usize,
        width: usize,
        codes: &[u8],
        out: &mut [f32],
    ) -> Result<()> {
        self.check_plane(height, width, codes.len(), out.len())?;
        match &self.representation {
            LutRepresentation::Linear => {
                for (o, &c) in out.iter_mut().zip(codes) {
                    *o = crate::encoding::LinearLut.phase(c);
                }
            }
            LutRepresentation::Global(curve) => {
                for (o, &c) in out.iter_mut().zip(codes) {
                    *o = curve.phases[c as usize];
                }
            }
            LutRepresentation::Tiled(t) => {
                for (y, (orow, crow)) in out
                    .chunks_exact_mut(width)
                    .zip(codes.chunks_exact(width))
                    .enumerate()
                {
                    for ((o, &c), &wx) in orow.iter_mut().zip(crow).zip(&self.cols) {
                        *o = t.blend_at(self.rows[y], wx, c);
                    }
                }
            }
        }
        Ok(())
    }
}

/// Bin index `j ∈ [0, 255]` and fraction of a phase (wrapped first).
#[inline]
fn bin(phase: f32, bins_per_rad: f32) -> (usize, f32) {
    let u = crate::encoding::wrap_phase(phase) * bins_per_rad;
    let j = (u as usize).min(INVERSE_BINS - 1);
    (j, u - j as f32)
}

#[inline]
fn lerp(a: u16, b: u16, f: f32) -> f32 {
    a as f32 + (b as f32 - a as f32) * f
}

/// Fractional code × 128 → 8-bit code (code 256 wraps to 0).
#[inline]
fn to_code(kappa_fixed: f32) -> u8 {
    // Interpolating between tiles may step past code 256 (= code 0 a cycle later) or below 0: clamp.
    ((kappa_fixed / INVERSE_SCALE)
        .round()
        .clamp(0.0, CODES as f32) as u32
        % CODES as u32) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn wrapped_distance(a: f32, b: f32) -> f32 {
        let d = (a - b).rem_euclid(TAU);
        d.min(TAU - d)
    }

    #[test]
    fn linear_curve_matches_the_linear_lut_everywhere() {
        let lut = PhaseLut::new(LutRepresentation::Global(PhaseCurve::linear()));
        let linear = PhaseLut::linear();
        let phase: Vec<f32> = (0..4096).map(|i| i as f32 * TAU / 4096.0 - 0.3).collect();
        let (mut a, mut b) = (vec![0u8; 4096], vec![0u8; 4096]);
        lut.apply(1, 4096, &phase, &mut a).unwrap();
        linear.apply(1, 4096, &phase, &mut b).unwrap();
        let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        // Ties at exact half codes may round either way through the fixed-point table.
        assert!(
            differ <= 8,
            "{differ} of 4096 codes differ from the linear LUT"
        );
        for (x, y) in a.iter().zip(&b) {
            let d = (*x as i32 - *y as i32).rem_euclid(256);
            assert!(d == 0 || d == 1 || d == 255);
        }
    }

    #[test]
    fn csv_round_trip_and_errors() {
        let curve = PhaseCurve::gamma(2.3 * std::f32::consts::PI, 1.4).unwrap();
        let mut csv = String::from("# measured\ncode,phase_rad\n");
        for (k, p) in curve.phases().iter().enumerate().rev() {
            csv.push_str(&format!("{k},{p}\n"));
        }
        let back = PhaseCurve::from_csv(&csv, "lut.csv").unwrap();
        for (a, b) in back.phases().iter().zip(curve.phases().iter()) {
            assert!((a - b).abs() < 1e-6);
        }
        let missing: String = csv
            .lines()
            .filter(|l| !l.starts_with("17,"))
            .collect::<Vec<_>>()
            .join("\n");
        let e = PhaseCurve::from_csv(&missing, "lut.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("lut.csv") && e.contains("code 17"), "{e}");
        let dup = format!("{csv}3,0.5\n");
        let e = PhaseCurve::from_csv(&dup, "lut.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("appears twice") && e.contains("line"), "{e}");
        let decreasing = csv.replace("100,", "100,-").replace("100,--", "100,-");
        let e = PhaseCurve::from_csv(&decreasing, "lut.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("decreases at code 100"), "{e}");
        let e = PhaseCurve::from_csv("0,nan\n", "x.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.csv"), "{e}");
    }

    #[test]
    fn ranges_below_and_above_two_pi_pick_the_nearest_displayable_phase() {
        for (range, gamma) in [
            (1.6 * std::f32::consts::PI, 1.0),
            (2.7 * std::f32::consts::PI, 1.6),
        ] {
            let curve = PhaseCurve::gamma(range, gamma).unwrap();
            let lut = PhaseLut::new(LutRepresentation::Global(curve.clone()));
            let n = 2000;
            let phase: Vec<f32> = (0..n).map(|i| i as f32 * TAU / n as f32).collect();
            let mut codes = vec![0u8; n];
            lut.apply(1, n, &phase, &mut codes).unwrap();
            for (&p, &c) in phase.iter().zip(&codes) {
                let got = wrapped_distance(curve.phases()[c as usize], p);
                let best = wrapped_distance(curve.phases()[curve.nearest_code(p) as usize], p);
                // Within the gap of an SLM below 2π the table may pick the other end; elsewhere it is within
                // a fraction of the local code step of the best code.
                let in_gap = p > curve.range() && range < TAU;
                if !in_gap {
                    assert!(
                        got <= best + 0.02,
                        "range {range}: θ {p} → code {c}: {got} vs best {best}"
                    );
                }
            }
        }
    }

    fn smooth_tiles(h: usize, w: usize, tile: usize) -> TiledCurves {
        let (rows, cols) = (h.div_ceil(tile), w.div_ceil(tile));
        let curves = (0..rows * cols)
            .map(|i| {
                let (r, c) = (
                    (i / cols) as f32 / rows as f32,
                    (i % cols) as f32 / cols as f32,
                );
                PhaseCurve::gamma(TAU * (1.15 + 0.1 * r - 0.05 * c), 0.8 + 0.6 * c).unwrap()
            })
            .collect();
        TiledCurves::new(h, w, tile, tile, curves).unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        /// The interpolated inverse tables agree with a naive search on the interpolated per-pixel curve.
        #[test]
        fn tiled_apply_matches_a_naive_search(seed in 0u64..1000, tile in 3usize..9) {
            let (h, w) = (17, 23);
            let tiles = smooth_tiles(h, w, tile);
            let lut = PhaseLut::new(LutRepresentation::Tiled(tiles.clone()));
            let mut rng = crate::splitmix::SplitMix64::new(seed);
            let phase: Vec<f32> = (0..h * w).map(|_| (rng.next_f64() * 7.0 - 0.5) as f32).collect();
            let mut codes = vec![0u8; h * w];
            lut.apply(h, w, &phase, &mut codes).unwrap();
            // Pixels between tile centres (the half tile at the border extrapolates, where interpolated
            // inverses drift further from the extrapolated curve with these extreme tiles).
            let inner = |len: usize, i: usize| {
                let t = (i as f32 + 0.5) / tile as f32 - 0.5;
                t >= 0.0 && t <= (len.div_ceil(tile) - 1) as f32
            };
            for y in (0..h).filter(|&y| inner(h, y)) {
                for x in (0..w).filter(|&x| inner(w, x)) {
                    let i = y * w + x;
                    let curve = PhaseCurve::new(&tiles.pixel_curve(y, x).unwrap()).unwrap();
                    let best = curve.nearest_code(phase[i]);
                    let t = crate::encoding::wrap_phase(phase[i]);
                    let got = wrapped_distance(curve.phases()[codes[i] as usize], t);
                    let want = wrapped_distance(curve.phases()[best as usize], t);
                    // In the gap of a pixel whose range is below 2π, either end (code 255 or 0) will do.
                    if curve.range() < TAU && t > curve.range() {
                        let got = wrapped_distance(curve.phases()[codes[i] as usize], t);
                        let gap = TAU - curve.range();
                        prop_assert!(got <= gap + 0.03, "gap phase {t} → code {} ({got}, gap {gap})", codes[i]);
                        continue;
                    }
                    // Within a code step of the target, or nearly as near as the best code.
                    let k = codes[i] as usize;
                    let step = curve.phases()[(k + 1).min(CODES - 1)] - curve.phases()[k.saturating_sub(1)];
                    // Interpolated inverses are not the inverse of the interpolated curve: these test tiles differ by
                    // 10 % in range and 75 % in gamma across 20 pixels (a real panel's far less). Where neighbouring
                    // tiles' ranges straddle 2π, codes near 2π can be off by a few steps (docs/CALIBRATION.md).
                    let tol = 0.07;
                    prop_assert!(got <= want + tol || got <= step + 0.01, "pixel ({y},{x}) θ {t}: code {} ({got}) vs {best} ({want})", codes[i]);
                }
            }
        }
    }

    #[test]
    fn tiled_curves_interpolate_between_tile_centres() {
        // 5-pixel tiles: pixel 7's centre (7.5) is the centre of tile 1; pixel 9 lies 0.4 of the way to tile 2.
        let tiles = smooth_tiles(30, 40, 5);
        let c = tiles.pixel_curve(7, 12).unwrap();
        let part = tiles.pixel_curve(9, 12).unwrap();
        let (t12, t22) = (&tiles.curves()[10], &tiles.curves()[18]);
        for k in 0..CODES {
            assert!((c[k] - t12.phases()[k]).abs() < 1e-5);
            assert!((part[k] - (0.6 * t12.phases()[k] + 0.4 * t22.phases()[k])).abs() < 1e-4);
        }
        let mut rows = vec![0f32; 2 * 40 * CODES];
        tiles.curves_of_rows(6..8, &mut rows).unwrap();
        assert_eq!(&rows[(40 + 12) * CODES..][..CODES], &c[..]);
        assert!(tiles.pixel_curve(30, 0).is_err());
        assert!(PhaseLut::new(LutRepresentation::Tiled(tiles))
            .apply(29, 40, &vec![0.0; 29 * 40], &mut vec![0; 29 * 40])
            .is_err());
    }

    #[test]
    fn displayed_phases_are_each_pixels_curve_at_its_code() {
        let (h, w) = (13, 21);
        let mut rng = crate::splitmix::SplitMix64::new(5);
        let codes: Vec<u8> = (0..h * w).map(|_| (rng.next_f64() * 256.0) as u8).collect();
        for repr in [
            LutRepresentation::Linear,
            LutRepresentation::Global(PhaseCurve::gamma(7.2, 1.3).unwrap()),
            LutRepresentation::Tiled(smooth_tiles(h, w, 4)),
        ] {
            let lut = PhaseLut::new(repr);
            let mut out = vec![0f32; h * w];
            lut.displayed_phases(h, w, &codes, &mut out).unwrap();
            for (i, (&c, &p)) in codes.iter().zip(&out).enumerate() {
                let want = lut.displayed_phase(i / w, i % w, c).unwrap();
                assert!((p - want).abs() < 1e-5, "pixel {i}: {p} vs {want}");
            }
            // Shapes are checked, a per-pixel LUT's size too.
            assert!(lut
                .displayed_phases(h, w, &codes[1..], &mut out[1..])
                .is_err());
        }
        let tiled = PhaseLut::new(LutRepresentation::Tiled(smooth_tiles(h, w, 4)));
        assert!(tiled
            .displayed_phases(w, h, &codes, &mut vec![0f32; h * w])
            .is_err());
    }
}
