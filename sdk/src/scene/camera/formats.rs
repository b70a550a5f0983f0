//! Pixel formats of phone camera buffers: the colour's byte layout ([`ColorFormat`]) and the depth's sample
//! format ([`DepthFormat`]), with the decoding of one pixel.

use serde::Serialize;

use crate::scene::depth::DepthEncoding;

/// Byte layout of an interleaved 8-bit colour buffer. Values are sRGB-encoded; alpha is ignored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum ColorFormat {
    /// 4 bytes per pixel in memory order R, G, B, A (e.g. Android `PixelFormat.RGBA_8888`,
    /// `HardwareBuffer.RGBA_8888`).
    Rgba8,
    /// 4 bytes per pixel in memory order B, G, R, A: iOS `kCVPixelFormatType_32BGRA`.
    Bgra8,
    /// 3 bytes per pixel in memory order R, G, B (packed RGB, as the `image` crate's `RgbImage`).
    Rgb8,
}

impl ColorFormat {
    /// Every colour format (for exhaustive tests and fuzzing).
    pub const ALL: [ColorFormat; 3] = [ColorFormat::Rgba8, ColorFormat::Bgra8, ColorFormat::Rgb8];

    /// Bytes per pixel: 4 for [`Rgba8`](Self::Rgba8) and [`Bgra8`](Self::Bgra8), 3 for
    /// [`Rgb8`](Self::Rgb8).
    pub fn bytes_per_pixel(&self) -> usize {
        match self {
            ColorFormat::Rgba8 | ColorFormat::Bgra8 => 4,
            ColorFormat::Rgb8 => 3,
        }
    }

    /// Byte offsets of R, G and B inside one pixel.
    /// Byte offsets of R, G and B inside one pixel.
    pub(super) fn rgb_offsets(&self) -> [usize; 3] {
        match self {
            ColorFormat::Rgba8 | ColorFormat::Rgb8 => [0, 1, 2],
            ColorFormat::Bgra8 => [2, 1, 0],
        }
    }
}

/// Sample format of a phone depth buffer; every format is **little-endian**.
///
/// | variant | source | bytes | z in metres |
/// |---|---|---|---|
/// | [`MetresF32`](Self::MetresF32) | `AVDepthData` `kCVPixelFormatType_DepthFloat32` | 4 | `v` |
/// | [`MetresF16`](Self::MetresF16) | `AVDepthData` `kCVPixelFormatType_DepthFloat16` | 2 | `v` |
/// | [`DisparityF32`](Self::DisparityF32) | `AVDepthData` `kCVPixelFormatType_DisparityFloat32` | 4 | `1/v` (`v` in 1/m) |
/// | [`DisparityF16`](Self::DisparityF16) | `AVDepthData` `kCVPixelFormatType_DisparityFloat16` | 2 | `1/v` (`v` in 1/m) |
/// | [`MillimetresU16`](Self::MillimetresU16) | ARCore `Frame.acquireDepthImage16Bits` | 2 | `v/1000` |
/// | [`Depth16`](Self::Depth16) | Android `ImageFormat.DEPTH16` | 2 | `(v & 0x1FFF)/1000` |
///
/// Invalid pixels (never read as near; filled later by [`crate::scene::fill_invalid`]): any sample whose z
/// is 0, NaN, ±∞ or negative (so a disparity of 0, NaN, ±∞ or negative too), and for
/// [`Depth16`](Self::Depth16) a confidence code of 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum DepthFormat {
    /// IEEE 754 binary32 z-depth in metres (iOS `DepthFloat32`).
    MetresF32,
    /// IEEE 754 binary16 z-depth in metres (iOS `DepthFloat16`), decoded with the `half` crate.
    MetresF16,
    /// IEEE 754 binary32 disparity in 1/m (iOS `DisparityFloat32`): z = 1/v metres.
    DisparityF32,
    /// IEEE 754 binary16 disparity in 1/m (iOS `DisparityFloat16`): z = 1/v metres.
    DisparityF16,
    /// Unsigned 16-bit z-depth in millimetres (ARCore `acquireDepthImage16Bits`): z = v/1000 m, 0 = no
    /// depth.
    MillimetresU16,
    /// Android `ImageFormat.DEPTH16`: the low 13 bits are the range in millimetres (z = range/1000 m), the
    /// high 3 bits a confidence code `c`: 0 means 100 % confidence, 1 means 0 %, 2..=7 mean `(c − 1)/7`.
    /// A pixel with range 0 or confidence code 1 is invalid; every other confidence is accepted.
    Depth16,
}

impl DepthFormat {
    /// Every depth format (for exhaustive tests and fuzzing).
    pub const ALL: [DepthFormat; 6] = [
        DepthFormat::MetresF32,
        DepthFormat::MetresF16,
        DepthFormat::DisparityF32,
        DepthFormat::DisparityF16,
        DepthFormat::MillimetresU16,
        DepthFormat::Depth16,
    ];

    /// Bytes per sample: 4 for the f32 formats, 2 for the others.
    pub fn bytes_per_pixel(&self) -> usize {
        match self {
            DepthFormat::MetresF32 | DepthFormat::DisparityF32 => 4,
            DepthFormat::MetresF16
            | DepthFormat::DisparityF16
            | DepthFormat::MillimetresU16
            | DepthFormat::Depth16 => 2,
        }
    }

    /// Decodes one little-endian sample of `bytes_per_pixel()` bytes to metres; `None` if invalid.
    pub(super) fn decode_sample(&self, b: &[u8]) -> Option<f32> {
        let f32_le = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        let f16_le = |b: &[u8]| half::f16::from_le_bytes([b[0], b[1]]).to_f32();
        let u16_le = |b: &[u8]| u16::from_le_bytes([b[0], b[1]]);
        let z = match self {
            DepthFormat::MetresF32 => f32_le(b),
            DepthFormat::MetresF16 => f16_le(b),
            DepthFormat::DisparityF32 => 1.0 / f32_le(b),
            DepthFormat::DisparityF16 => 1.0 / f16_le(b),
            DepthFormat::MillimetresU16 => {
                return DepthEncoding::Millimetres16.decode_sample(u16_le(b))
            }
            DepthFormat::Depth16 => {
                let v = u16_le(b);
                if v >> 13 == 1 {
                    return None; // confidence 0 %
                }
                return DepthEncoding::Millimetres16.decode_sample(v & 0x1FFF);
            }
        };
        // Rejects 0, NaN, ±inf and negatives (for disparity: 1/0 = inf, 1/inf = 0, 1/NaN = NaN).
        (z.is_finite() && z > 0.0).then_some(z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth16_range_and_confidence() {
        let dec = |v: u16| DepthFormat::Depth16.decode_sample(&v.to_le_bytes());
        assert_eq!(dec(500), Some(0.5)); // confidence code 0 = 100 %
        assert_eq!(dec(500 | 1 << 13), None); // code 1 = 0 %
        for c in 2..8u16 {
            assert_eq!(dec(500 | c << 13), Some(0.5), "confidence code {c}");
        }
        assert_eq!(dec(0x1FFF), Some(8.191));
        assert_eq!(dec(0), None);
        assert_eq!(dec(7 << 13), None); // range 0 whatever the confidence
    }

    #[test]
    fn float_formats_reject_non_physical_values() {
        for v in [
            0.0f32,
            -0.0,
            -1.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            for f in [DepthFormat::MetresF32, DepthFormat::DisparityF32] {
                assert_eq!(f.decode_sample(&v.to_le_bytes()), None, "{f:?} {v}");
            }
            let h = half::f16::from_f32(v).to_le_bytes();
            for f in [DepthFormat::MetresF16, DepthFormat::DisparityF16] {
                assert_eq!(f.decode_sample(&h), None, "{f:?} {v}");
            }
        }
        // Disparity so small that 1/v overflows f32: invalid, not infinitely far.
        assert_eq!(
            DepthFormat::DisparityF32.decode_sample(&1e-40f32.to_le_bytes()),
            None
        );
        assert_eq!(
            DepthFormat::DisparityF32.decode_sample(&4.0f32.to_le_bytes()),
            Some(0.25)
        );
    }
}
