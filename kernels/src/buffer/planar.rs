//! The buffer itself: [`RowPlanar`]'s storage, layout and border (the [module documentation](crate::buffer)),
//! its element types, its construction and its plain (unquantised) fills and reads.

use crate::error::KernelError;

/// The widest pixel tile a kernel may use (pixels along a row); [`padded_width`] leaves this much slack.
pub const MAX_TILE: usize = 64;

/// Largest height, width or channel count accepted (keeps every index computation far from overflow).
pub const MAX_DIM: usize = 1 << 16;

/// The padded row length `Wp` used for a frame of width `w`: `round_up(w + 2 + MAX_TILE, 16)` elements
/// (pixels).
pub fn padded_width(w: usize) -> usize {
    (w + 2 + MAX_TILE).next_multiple_of(16)
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for u8 {}
}

/// An element type of a [`RowPlanar`] buffer (`f32` or `u8`); sealed.
pub trait Element: sealed::Sealed + Copy + Default + PartialEq + std::fmt::Debug + 'static {
    /// Channels interleaved per pixel: 1 for `f32`, 4 for `u8`.
    const INTERLEAVE: usize;
}
impl Element for f32 {
    const INTERLEAVE: usize = 1;
}
impl Element for u8 {
    const INTERLEAVE: usize = 4;
}

/// An activation buffer `[H+2][ceil(C/K)][Wp][K]` with a one-pixel border (K = 1 for `f32`, 4 for `u8`); see
/// the [module documentation](crate::buffer) for the layout and its invariants.
#[derive(Clone, Debug)]
pub struct RowPlanar<T: Element> {
    pub(super) c: usize,
    pub(super) h: usize,
    pub(super) w: usize,
    pub(super) wp: usize,
    pub(super) border: T,
    /// Storage with up to 64 bytes of slack in front: the buffer starts at `data[off]`, chosen so that
    /// column 1 of every row lies on a 64-byte boundary (fewer cache-line-splitting loads and stores). A
    /// clone may have another alignment; only speed depends on it.
    data: Vec<T>,
    off: usize,
    len: usize,
}

impl<T: Element> PartialEq for RowPlanar<T> {
    fn eq(&self, other: &Self) -> bool {
        (self.c, self.h, self.w, self.border) == (other.c, other.h, other.w, other.border)
            && self.as_slice() == other.as_slice()
    }
}

pub(crate) fn check_dims(c: usize, h: usize, w: usize) -> Result<(), KernelError> {
    for (what, value) in [("channels", c), ("height", h), ("width", w)] {
        if value == 0 || value > MAX_DIM {
            return Err(KernelError::Dimension { what, value });
        }
    }
    let groups = c.div_ceil(4) * 4;
    let total = (h + 2)
        .checked_mul(groups)
        .and_then(|x| x.checked_mul(padded_width(w)))
        .filter(|&n| n <= (isize::MAX as usize) / 8);
    if total.is_none() {
        return Err(KernelError::Dimension {
            what: "channels × height × width",
            value: c * h,
        });
    }
    Ok(())
}

impl<T: Element> RowPlanar<T> {
    fn with_border(c: usize, h: usize, w: usize, border: T) -> Result<Self, KernelError> {
        check_dims(c, h, w)?;
        let wp = padded_width(w);
        let groups = c.div_ceil(T::INTERLEAVE);
        let len = (h + 2) * groups * wp * T::INTERLEAVE;
        let size = std::mem::size_of::<T>();
        let data = vec![border; len + 64 / size];
        // Column 1 is 4 bytes into a row in both layouts (one f32, or one pixel of 4 u8).
        let addr = data.as_ptr() as usize;
        let off = (64 - (addr + 4) % 64) % 64 / size;
        Ok(Self {
            c,
            h,
            w,
            wp,
            border,
            data,
            off,
            len,
        })
    }

    /// Channels `C` (not counting padding channels).
    pub fn channels(&self) -> usize {
        self.c
    }
    /// Frame height `H` in pixels (without the border).
    pub fn height(&self) -> usize {
        self.h
    }
    /// Frame width `W` in pixels (without the border).
    pub fn width(&self) -> usize {
        self.w
    }
    /// The padded row length `Wp` in pixels ([`padded_width`]).
    pub fn padded_width(&self) -> usize {
        self.wp
    }
    /// The raw storage, `[H+2][ceil(C/K)][Wp][K]` elements.
    pub fn as_slice(&self) -> &[T] {
        &self.data[self.off..self.off + self.len]
    }
    pub(crate) fn as_mut_slice(&mut self) -> &mut [T] {
        &mut self.data[self.off..self.off + self.len]
    }
    /// Elements of one buffer row: `ceil(C/K) · Wp · K`.
    pub(crate) fn row_stride(&self) -> usize {
        self.groups() * self.wp * T::INTERLEAVE
    }
    /// Channel groups `ceil(C/K)` stored per buffer row.
    pub(crate) fn groups(&self) -> usize {
        self.c.div_ceil(T::INTERLEAVE)
    }

    /// Index in [`as_slice`](Self::as_slice) of channel `c`, buffer row `r` (0..H+2), buffer column `j`
    /// (0..Wp).
    pub(super) fn index(&self, c: usize, r: usize, j: usize) -> usize {
        let k = T::INTERLEAVE;
        ((r * self.groups() + c / k) * self.wp + j) * k + c % k
    }

    /// The value of channel `c` at pixel `(y, x)` (frame coordinates, without the border); `None` outside.
    pub fn get(&self, c: usize, y: usize, x: usize) -> Option<T> {
        (c < self.c && y < self.h && x < self.w)
            .then(|| self.as_slice()[self.index(c, y + 1, x + 1)])
    }

    /// True when every element outside the interior (rows 0 and `H+1`, column 0, columns past `W`, padding
    /// channels) holds the border value (0 for `f32`, the zero point for `u8`). For tests and debug checks.
    pub fn border_is_clean(&self) -> bool {
        let k = T::INTERLEAVE;
        let groups = self.groups();
        for r in 0..self.h + 2 {
            for g in 0..groups {
                for j in 0..self.wp {
                    for l in 0..k {
                        let c = g * k + l;
                        let inside = r >= 1 && r <= self.h && j >= 1 && j <= self.w && c < self.c;
                        if !inside
                            && self.as_slice()[((r * groups + g) * self.wp + j) * k + l]
                                != self.border
                        {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    fn check_planar(&self, len: usize) -> Result<(), KernelError> {
        let expected = self.c * self.h * self.w;
        if len != expected {
            return Err(KernelError::Length {
                what: "planar [C][H][W] slice",
                expected,
                got: len,
            });
        }
        Ok(())
    }

    /// Copies the interior out to a planar `[C][H][W]` slice. Errors: `out.len() != C·H·W`.
    pub fn read_planar(&self, out: &mut [T]) -> Result<(), KernelError> {
        self.check_planar(out.len())?;
        let (h, w) = (self.h, self.w);
        for c in 0..self.c {
            for y in 0..h {
                for x in 0..w {
                    out[(c * h + y) * w + x] = self.as_slice()[self.index(c, y + 1, x + 1)];
                }
            }
        }
        Ok(())
    }

    /// The interior as a planar `[C][H][W]` vector.
    pub fn to_planar(&self) -> Vec<T> {
        let mut out = vec![T::default(); self.c * self.h * self.w];
        // The length is right by construction.
        let _ = self.read_planar(&mut out);
        out
    }

    /// Fills the interior from a planar `[C][H][W]` slice, converting each value with `f(channel, value)`.
    pub(super) fn fill_with<S: Copy>(
        &mut self,
        src: &[S],
        f: impl Fn(usize, S) -> T,
    ) -> Result<(), KernelError> {
        self.check_planar(src.len())?;
        let (h, w, k) = (self.h, self.w, T::INTERLEAVE);
        for c in 0..self.c {
            for y in 0..h {
                // Row y of channel c: `w` elements `k` apart from column 1 (one slice, one bounds check).
                let start = self.index(c, y + 1, 1);
                let dst = &mut self.as_mut_slice()[start..start + (w - 1) * k + 1];
                let row = &src[(c * h + y) * w..(c * h + y + 1) * w];
                for (d, &v) in dst.iter_mut().step_by(k).zip(row) {
                    *d = f(c, v);
                }
            }
        }
        Ok(())
    }
}

/// A per-channel affine map `x·scale[c] + offset[c]` applied while filling a buffer (e.g. input centring
/// `x − 0.5`: scale 1, offset −0.5). Both slices have one value per channel.
#[derive(Clone, Copy, Debug)]
pub struct Affine<'a> {
    /// Multiplier per channel.
    pub scale: &'a [f32],
    /// Offset per channel, added after the multiplication.
    pub offset: &'a [f32],
}

impl RowPlanar<f32> {
    /// A zeroed buffer of `c` channels and `h × w` pixels. Errors: a zero or too large dimension
    /// ([`KernelError::Dimension`]).
    pub fn new(c: usize, h: usize, w: usize) -> Result<Self, KernelError> {
        Self::with_border(c, h, w, 0.0)
    }

    /// A buffer filled from a planar `[c][h][w]` slice, with an optional per-channel affine map. Errors: as
    /// [`new`](Self::new) and [`fill_from_planar`](Self::fill_from_planar).
    pub fn from_planar(
        src: &[f32],
        c: usize,
        h: usize,
        w: usize,
        affine: Option<Affine<'_>>,
    ) -> Result<Self, KernelError> {
        let mut b = Self::new(c, h, w)?;
        b.fill_from_planar(src, affine)?;
        Ok(b)
    }

    /// The `W` interior values of channel `c` on frame row `y`; `None` outside the buffer.
    pub fn row(&self, c: usize, y: usize) -> Option<&[f32]> {
        (c < self.c && y < self.h).then(|| {
            let at = self.index(c, y + 1, 1);
            &self.as_slice()[at..at + self.w]
        })
    }

    /// Overwrites the interior from a planar `[C][H][W]` slice, applying `x·scale[c] + offset[c]` when
    /// `affine` is given. Errors: `src.len() != C·H·W` or an affine slice whose length is not `C`
    /// ([`KernelError::Length`]).
    pub fn fill_from_planar(
        &mut self,
        src: &[f32],
        affine: Option<Affine<'_>>,
    ) -> Result<(), KernelError> {
        match affine {
            None => self.fill_with(src, |_, v| v),
            Some(a) => {
                for (what, s) in [("affine scale", a.scale), ("affine offset", a.offset)] {
                    if s.len() != self.c {
                        return Err(KernelError::Length {
                            what,
                            expected: self.c,
                            got: s.len(),
                        });
                    }
                }
                self.fill_with(src, |c, v| v * a.scale[c] + a.offset[c])
            }
        }
    }
}

impl RowPlanar<u8> {
    /// A buffer of `c` channels and `h × w` pixels whose every element (border, padding channels, interior)
    /// holds the zero point `zp`. Errors: a zero or too large dimension.
    pub fn new_quantized(c: usize, h: usize, w: usize, zp: u8) -> Result<Self, KernelError> {
        Self::with_border(c, h, w, zp)
    }

    /// The zero point: the value of the border and of the padding channels.
    pub fn zero_point(&self) -> u8 {
        self.border
    }

    /// A buffer filled from a planar `[c][h][w]` slice of quantised values with zero point `zp`.
    pub fn from_planar_u8(
        src: &[u8],
        c: usize,
        h: usize,
        w: usize,
        zp: u8,
    ) -> Result<Self, KernelError> {
        let mut b = Self::new_quantized(c, h, w, zp)?;
        b.fill_with(src, |_, v| v)?;
        Ok(b)
    }
    /// Makes `zp` the buffer's zero point: every element outside the interior (border rows and columns,
    /// padding channels) is rewritten with it, the interior is left as it is (a layer overwrites it next). A
    /// ring of buffers reused by layers whose outputs have different zero points calls this before each
    /// layer; it writes only the border (no work when the zero point does not change).
    pub fn set_zero_point(&mut self, zp: u8) {
        if zp == self.border {
            return;
        }
        self.border = zp;
        let (h, w, wp, groups, c) = (self.h, self.w, self.wp, self.groups(), self.c);
        let data = self.as_mut_slice();
        let row = groups * wp * 4;
        data[..row].fill(zp);
        data[(h + 1) * row..(h + 2) * row].fill(zp);
        for r in 1..=h {
            for g in 0..groups {
                let at = (r * groups + g) * wp * 4;
                data[at..at + 4].fill(zp);
                data[at + (w + 1) * 4..at + wp * 4].fill(zp);
                // Padding channels of the last group (C not a multiple of 4).
                if g == groups - 1 && c % 4 != 0 {
                    for j in 1..=w {
                        data[at + j * 4 + c % 4..at + j * 4 + 4].fill(zp);
                    }
                }
            }
        }
    }
}
