//! The display calibration file (`.holocal`): one versioned binary file per display holding, per colour, the
//! phase look-up table (linear, global or tiled per-pixel) and optionally the laser intensity scaling map.
//!
//! Layout (all integers little-endian; `docs/CALIBRATION.md` has the full specification):
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `HOLOCAL\0` |
//! | 4 | format version (`u32`, currently 1) |
//! | 4 | header length `n` (`u32`, at most 1 MiB) |
//! | `n` | header, UTF-8 JSON: SLM `height`, `width`, and per colour (R, G, B) its `wavelength_m`, `lut` (`representation`: `linear`, `global` or `tiled`; `tile: [h, w]` for tiled) and `intensity` (`true`/`false`), plus free-form `notes` |
//! | … | payload: per colour in order, the LUT's curves (`u16` phase × 4096 per code, 256 per curve: one for global, one per tile row-major for tiled) then, if present, the intensity scale map (`u16` × 65535, `[height, width]`) |
//! | 4 | CRC-32 (IEEE) of every byte before it |
//!
//! Reading checks the magic, version, lengths (with checked arithmetic, before allocating), the checksum, the
//! header's consistency and every curve, so a truncated, corrupt or foreign file is refused with a message
//! that says which.

use std::path::Path;

use ndarray::Array2;
use serde::{Deserialize, Serialize};

use super::lut::{LutRepresentation, PhaseCurve, PhaseLut, TiledCurves, CODES};
use crate::error::{invalid, HoloError, Result};

/// File magic.
const MAGIC: &[u8; 8] = b"HOLOCAL\0";
/// Current format version.
pub const FORMAT_VERSION: u32 = 1;
/// Largest header accepted (bytes).
const MAX_HEADER: usize = 1 << 20;
/// Largest SLM side accepted (pixels): an 8K panel is 7680 wide.
const MAX_SIDE: usize = 16384;
/// Colour names in file order.
pub const COLOUR_NAMES: [&str; 3] = ["red", "green", "blue"];

/// One colour's calibration: wavelength, look-up table and optional intensity scale map.
#[derive(Debug, Clone)]
pub struct ColourCalibration {
    /// Laser wavelength in metres (informative; checked against the pipeline's optics when loaded there).
    pub wavelength_m: f64,
    /// Phase → code look-up table.
    pub lut: PhaseLut,
    /// Target-amplitude scale `[height, width]` in `[0, 1]` from the laser intensity calibration
    /// ([`super::intensity`]), or `None`.
    pub intensity_scale: Option<Array2<f32>>,
}

/// A display's calibration: SLM size and, per colour (R, G, B), a [`ColourCalibration`].
#[derive(Debug, Clone)]
pub struct DisplayCalibration {
    /// SLM height in pixels.
    pub height: usize,
    /// SLM width in pixels.
    pub width: usize,
    /// Per colour, R, G, B.
    pub colours: [ColourCalibration; 3],
    /// Free-form notes stored in the header (how and when it was calibrated).
    pub notes: String,
}

#[derive(Serialize, Deserialize)]
struct Header {
    height: usize,
    width: usize,
    colours: Vec<ColourHeader>,
    #[serde(default)]
    notes: String,
}

#[derive(Serialize, Deserialize)]
struct ColourHeader {
    name: String,
    wavelength_m: f64,
    lut: LutHeader,
    intensity: bool,
}

#[derive(Serialize, Deserialize)]
struct LutHeader {
    representation: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tile: Option<[usize; 2]>,
}

impl DisplayCalibration {
    /// The calibration of an ideal display: linear LUTs, no intensity map, default wavelengths.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a size of 0 or above 16384 on either side.
    pub fn linear(height: usize, width: usize) -> Result<Self> {
        check_size(height, width)?;
        let wl = crate::optics::OpticalSetup::default().wavelengths_m;
        Ok(Self {
            height,
            width,
            colours: std::array::from_fn(|c| ColourCalibration {
                wavelength_m: wl[c],
                lut: PhaseLut::linear(),
                intensity_scale: None,
            }),
            notes: String::new(),
        })
    }

    /// Refuses a calibration made for another SLM size than the `height × width` frames it is used with.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] naming both sizes.
    pub(crate) fn check_size(&self, height: usize, width: usize) -> Result<()> {
        if (self.height, self.width) != (height, width) {
            return Err(HoloError::ShapeMismatch {
                what: format!(
                    "frames vs the display calibration (made for a {}×{} SLM; render at that size)",
                    self.height, self.width
                ),
                expected: vec![self.height, self.width],
                got: vec![height, width],
            });
        }
        Ok(())
    }

    /// One line for logs and reports, e.g. `"1080×1920 SLM: red tiled (16×16 px), green global, blue linear;
    /// intensity map: green"`.
    pub fn summary(&self) -> String {
        let luts: Vec<String> = self
            .colours
            .iter()
            .zip(COLOUR_NAMES)
            .map(|(c, name)| match c.lut.representation() {
                LutRepresentation::Tiled(t) => {
                    format!("{name} tiled ({}×{} px)", t.tile().0, t.tile().1)
                }
                r => format!("{name} {}", r.name()),
            })
            .collect();
        let maps: Vec<&str> = self
            .colours
            .iter()
            .zip(COLOUR_NAMES)
            .filter(|(c, _)| c.intensity_scale.is_some())
            .map(|(_, name)| name)
            .collect();
        let maps = if maps.is_empty() {
            "none".to_string()
        } else {
            maps.join(", ")
        };
        format!(
            "{}×{} SLM: {}; intensity map: {maps}",
            self.height,
            self.width,
            luts.join(", ")
        )
    }

    /// The three colours' look-up tables (R, G, B).
    pub fn luts(&self) -> [&PhaseLut; 3] {
        [
            &self.colours[0].lut,
            &self.colours[1].lut,
            &self.colours[2].lut,
        ]
    }

    /// Whether any colour's look-up table is other than the linear one (codes then differ from an ideal SLM's).
    pub(crate) fn has_calibrated_lut(&self) -> bool {
        self.colours
            .iter()
            .any(|c| !matches!(c.lut.representation(), LutRepresentation::Linear))
    }

    /// Whether any colour has an intensity scale map.
    pub(crate) fn has_intensity(&self) -> bool {
        self.colours.iter().any(|c| c.intensity_scale.is_some())
    }

    /// Serialises to the `.holocal` format.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if a per-pixel LUT or intensity map is for another size.
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        check_size(self.height, self.width)?;
        let mut colours = Vec::new();
        let mut payload: Vec<u8> = Vec::new();
        for (c, col) in self.colours.iter().enumerate() {
            let lut = match col.lut.representation() {
                LutRepresentation::Linear => LutHeader {
                    representation: "linear".into(),
                    tile: None,
                },
                LutRepresentation::Global(curve) => {
                    push_curve(&mut payload, curve);
                    LutHeader {
                        representation: "global".into(),
                        tile: None,
                    }
                }
                LutRepresentation::Tiled(t) => {
                    if t.size() != (self.height, self.width) {
                        return Err(HoloError::ShapeMismatch {
                            what: format!(
                                "{} per-pixel LUT vs the calibration's SLM",
                                COLOUR_NAMES[c]
                            ),
                            expected: vec![self.height, self.width],
                            got: vec![t.size().0, t.size().1],
                        });
                    }
                    for curve in t.curves() {
                        push_curve(&mut payload, curve);
                    }
                    LutHeader {
                        representation: "tiled".into(),
                        tile: Some([t.tile().0, t.tile().1]),
                    }
                }
            };
            if let Some(map) = &col.intensity_scale {
                if map.dim() != (self.height, self.width) {
                    return Err(HoloError::ShapeMismatch {
                        what: format!("{} intensity map vs the calibration's SLM", COLOUR_NAMES[c]),
                        expected: vec![self.height, self.width],
                        got: map.shape().to_vec(),
                    });
                }
                for &v in map.iter() {
                    let q = (v.clamp(0.0, 1.0) * 65535.0).round() as u16;
                    payload.extend_from_slice(&q.to_le_bytes());
                }
            }
            colours.push(ColourHeader {
                name: COLOUR_NAMES[c].into(),
                wavelength_m: col.wavelength_m,
                lut,
                intensity: col.intensity_scale.is_some(),
            });
        }
        let header = serde_json::to_vec(&Header {
            height: self.height,
            width: self.width,
            colours,
            notes: self.notes.clone(),
        })
        .map_err(|e| HoloError::Internal(format!("calibration header: {e}")))?;
        let mut out = Vec::with_capacity(20 + header.len() + payload.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        out.extend_from_slice(&(header.len() as u32).to_le_bytes());
        out.extend_from_slice(&header);
        out.extend_from_slice(&payload);
        let crc = crc32fast::hash(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        Ok(out)
    }

    /// Parses a `.holocal` file's bytes; `source` names it in errors.
    ///
    /// Errors: [`HoloError::Calibration`] naming `source` for a file that is not a calibration file, a newer
    /// format version, a truncated or over-long file, a checksum mismatch (corruption), an inconsistent
    /// header (unknown representation, tile larger than the SLM, size of 0 or above 16384) or an invalid curve
    /// (decreasing).
    pub fn from_bytes(bytes: &[u8], source: &str) -> Result<Self> {
        let err = |reason: String| HoloError::Calibration {
            source_name: source.to_string(),
            reason,
        };
        if bytes.len() < 20 || &bytes[..8] != MAGIC {
            return Err(err(
                "not a display calibration file (no HOLOCAL header; make one with `holo calibrate lut`)"
                    .into(),
            ));
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        if version != FORMAT_VERSION {
            return Err(err(format!(
                "format version {version}; this build reads version {FORMAT_VERSION}"
            )));
        }
        let header_len = u32::from_le_bytes(bytes[12..16].try_into().expect("4 bytes")) as usize;
        if header_len > MAX_HEADER {
            return Err(err(format!(
                "header of {header_len} bytes (at most {MAX_HEADER})"
            )));
        }
        let body_end = bytes.len() - 4;
        if 16 + header_len > body_end {
            return Err(err(format!(
                "truncated: {} bytes, but the header alone needs {}",
                bytes.len(),
                16 + header_len + 4
            )));
        }
        let stored_crc = u32::from_le_bytes(bytes[body_end..].try_into().expect("4 bytes"));
        let header: Header = serde_json::from_slice(&bytes[16..16 + header_len]).map_err(|e| {
            err(format!(
                "unreadable header ({e}); the file is corrupt or truncated"
            ))
        })?;
        check_size(header.height, header.width).map_err(|e| err(e.to_string()))?;
        if header.colours.len() != 3 {
            return Err(err(format!(
                "{} colours; expected 3 (R, G, B)",
                header.colours.len()
            )));
        }
        let (h, w) = (header.height, header.width);
        // Expected payload size, with checked arithmetic, before touching the payload.
        let mut need = 0usize;
        for col in &header.colours {
            let curves = match (col.lut.representation.as_str(), col.lut.tile) {
                ("linear", _) => 0,
                ("global", _) => 1,
                ("tiled", Some([th, tw])) => {
                    if th == 0 || tw == 0 || th > h || tw > w {
                        return Err(err(format!(
                            "{} LUT tile {th}×{tw} does not fit the {h}×{w} SLM",
                            col.name
                        )));
                    }
                    h.div_ceil(th) * w.div_ceil(tw)
                }
                ("tiled", None) => {
                    return Err(err(format!("{} tiled LUT without a tile size", col.name)))
                }
                (other, _) => {
                    return Err(err(format!(
                        "{} LUT has unknown representation `{other}` (linear, global, tiled)",
                        col.name
                    )))
                }
            };
            need = need
                .checked_add(curves * CODES * 2)
                .and_then(|n| n.checked_add(if col.intensity { h * w * 2 } else { 0 }))
                .ok_or_else(|| err("payload size overflows".into()))?;
        }
        let payload = &bytes[16 + header_len..body_end];
        if payload.len() != need {
            return Err(err(format!(
                "{} by {} bytes: the header describes {need} bytes of tables, the file holds {}",
                if payload.len() < need {
                    "truncated"
                } else {
                    "too long"
                },
                need.abs_diff(payload.len()),
                payload.len()
            )));
        }
        let crc = crc32fast::hash(&bytes[..body_end]);
        if crc != stored_crc {
            return Err(err(format!(
                "checksum mismatch (stored {stored_crc:08x}, computed {crc:08x}): the file is corrupt"
            )));
        }
        let mut at = 0usize;
        let mut take_u16 = |n: usize| -> Vec<u16> {
            let out = payload[at..at + 2 * n]
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect();
            at += 2 * n;
            out
        };
        let mut colours = Vec::with_capacity(3);
        for (c, col) in header.colours.iter().enumerate() {
            if !(col.wavelength_m > 0.0 && col.wavelength_m < 1e-5) {
                return Err(err(format!(
                    "{} wavelength {} m is not a visible/near-IR wavelength",
                    col.name, col.wavelength_m
                )));
            }
            let name = COLOUR_NAMES[c];
            let representation = match col.lut.representation.as_str() {
                "linear" => LutRepresentation::Linear,
                "global" => LutRepresentation::Global(
                    PhaseCurve::from_fixed(&take_u16(CODES), &format!("{name} global LUT"))
                        .map_err(|e| err(e.to_string()))?,
                ),
                _ => {
                    let [th, tw] = col.lut.tile.expect("checked above");
                    let n = h.div_ceil(th) * w.div_ceil(tw);
                    let q = take_u16(n * CODES);
                    let curves = q
                        .chunks_exact(CODES)
                        .enumerate()
                        .map(|(i, q)| PhaseCurve::from_fixed(q, &format!("{name} LUT tile {i}")))
                        .collect::<Result<Vec<_>>>()
                        .map_err(|e| err(e.to_string()))?;
                    LutRepresentation::Tiled(
                        TiledCurves::new(h, w, th, tw, curves).map_err(|e| err(e.to_string()))?,
                    )
                }
            };
            let intensity_scale = if col.intensity {
                let q = take_u16(h * w);
                Some(
                    Array2::from_shape_vec((h, w), q.iter().map(|&v| v as f32 / 65535.0).collect())
                        .expect("sized above"),
                )
            } else {
                None
            };
            colours.push(ColourCalibration {
                wavelength_m: col.wavelength_m,
                lut: PhaseLut::new(representation),
                intensity_scale,
            });
        }
        let colours: [ColourCalibration; 3] = colours.try_into().expect("three colours");
        Ok(Self {
            height: h,
            width: w,
            colours,
            notes: header.notes,
        })
    }

    /// Reads a `.holocal` file (at most 1 GiB).
    ///
    /// Errors: [`HoloError::Io`] if it cannot be read; as [`DisplayCalibration::from_bytes`].
    pub fn read(path: &Path) -> Result<Self> {
        let len = std::fs::metadata(path)
            .map_err(|source| HoloError::Io {
                path: path.to_path_buf(),
                source,
            })?
            .len();
        if len > 1 << 30 {
            return Err(HoloError::Calibration {
                source_name: path.display().to_string(),
                reason: format!("{len} bytes; a calibration file is at most 1 GiB"),
            });
        }
        let bytes = crate::io::read_bytes(path)?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }

    /// Writes the file atomically (a temporary file in the same folder, then renamed over `path`).
    ///
    /// Errors: [`HoloError::Io`] naming the path; as [`DisplayCalibration::to_bytes`].
    pub fn write(&self, path: &Path) -> Result<()> {
        let bytes = self.to_bytes()?;
        crate::io::write_atomic(path, &bytes)
    }
}

fn push_curve(out: &mut Vec<u8>, curve: &PhaseCurve) {
    for q in curve.to_fixed() {
        out.extend_from_slice(&q.to_le_bytes());
    }
}

fn check_size(height: usize, width: usize) -> Result<()> {
    if height == 0 || width == 0 || height > MAX_SIDE || width > MAX_SIDE {
        return Err(invalid(
            "slm size",
            format!("must be between 1 and {MAX_SIDE} pixels on each side, got {height}×{width}"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> DisplayCalibration {
        let mut cal = DisplayCalibration::linear(20, 30).unwrap();
        cal.colours[1].lut = PhaseLut::new(LutRepresentation::Global(
            PhaseCurve::gamma(7.0, 1.3).unwrap(),
        ));
        let curves = (0..12)
            .map(|i| PhaseCurve::gamma(6.0 + 0.1 * i as f32, 1.1).unwrap())
            .collect();
        cal.colours[2].lut = PhaseLut::new(LutRepresentation::Tiled(
            TiledCurves::new(20, 30, 8, 8, curves).unwrap(),
        ));
        cal.colours[0].intensity_scale = Some(Array2::from_shape_fn((20, 30), |(y, x)| {
            0.5 + 0.01 * (y + x) as f32
        }));
        cal.notes = "test".into();
        cal
    }

    #[test]
    fn round_trip_keeps_every_table() {
        let cal = sample();
        let bytes = cal.to_bytes().unwrap();
        let back = DisplayCalibration::from_bytes(&bytes, "t.holocal").unwrap();
        assert_eq!(
            (back.height, back.width, back.notes.as_str()),
            (20, 30, "test")
        );
        for c in 0..3 {
            let (a, b) = (
                cal.colours[c].lut.representation(),
                back.colours[c].lut.representation(),
            );
            assert_eq!(a.name(), b.name());
            for (y, x, k) in [(0, 0, 255u8), (19, 29, 128), (7, 13, 40)] {
                let (pa, pb) = (
                    cal.colours[c].lut.displayed_phase(y, x, k).unwrap(),
                    back.colours[c].lut.displayed_phase(y, x, k).unwrap(),
                );
                assert!((pa - pb).abs() <= 1.3e-4, "colour {c}: {pa} vs {pb}");
            }
        }
        let (a, b) = (
            cal.colours[0].intensity_scale.as_ref().unwrap(),
            back.colours[0].intensity_scale.as_ref().unwrap(),
        );
        assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5));
        assert!(back.colours[1].intensity_scale.is_none());
    }

    #[test]
    fn corrupt_truncated_and_foreign_files_are_refused() {
        let bytes = sample().to_bytes().unwrap();
        let msg = |b: &[u8]| {
            DisplayCalibration::from_bytes(b, "d.holocal")
                .unwrap_err()
                .to_string()
        };
        // Every truncation is refused, and never panics.
        for cut in [0, 5, 19, 40, bytes.len() / 2, bytes.len() - 1] {
            let m = msg(&bytes[..cut]);
            assert!(m.contains("d.holocal"), "{m}");
        }
        assert!(msg(&bytes[..bytes.len() - 7]).contains("truncated"));
        // One flipped bit in the payload: checksum.
        let mut flipped = bytes.clone();
        let i = bytes.len() - 100;
        flipped[i] ^= 0x10;
        assert!(msg(&flipped).contains("checksum"), "{}", msg(&flipped));
        // A flipped bit in the header is either unreadable JSON or a checksum mismatch.
        let mut h = bytes.clone();
        h[20] ^= 0x01;
        let m = msg(&h);
        assert!(
            m.contains("checksum") || m.contains("header") || m.contains("corrupt"),
            "{m}"
        );
        assert!(msg(b"P5\n2 2\n255\n....................").contains("not a display calibration"));
        let mut v2 = bytes.clone();
        v2[8] = 2;
        assert!(msg(&v2).contains("version 2"));
        // Every single-byte corruption is refused (no panic, never accepted silently).
        for i in (0..bytes.len()).step_by(7) {
            let mut b = bytes.clone();
            b[i] = b[i].wrapping_add(1);
            assert!(
                DisplayCalibration::from_bytes(&b, "x").is_err(),
                "byte {i} corrupted but accepted"
            );
        }
    }

    #[test]
    fn other_resolutions_are_refused() {
        let cal = sample();
        cal.check_size(20, 30).unwrap();
        let e = cal.check_size(1080, 1920).unwrap_err().to_string();
        assert!(e.contains("20×30") && e.contains("1080"), "{e}");
    }
}
