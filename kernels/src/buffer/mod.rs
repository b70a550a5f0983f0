//! Activation buffers with a one-pixel border: [`RowPlanar`].
//!
//! # Layout and invariants
//!
//! A `RowPlanar<T>` of `C` channels and `H × W` pixels stores `H + 2` buffer rows; buffer row `r` holds frame
//! row `r − 1` (rows 0 and `H + 1` are the top and bottom border). Each buffer row holds, for each channel
//! group, `Wp` columns; column 0 is the left border, columns `1..=W` the pixels, columns `W+1..Wp` the right
//! border. `Wp = padded_width(W) = round_up(W + 2 + MAX_TILE, 16)`, so a kernel may load up to [`MAX_TILE`]
//! pixels past the last tile start without leaving the row, and store whole vectors of up to `MAX_TILE`
//! pixels (with the lanes past `W` set to the border value).
//!
//! * `f32`: logical shape `[H+2][C][Wp]`, one value per element; the border is `0.0`.
//! * `u8`: logical shape `[H+2][ceil(C/4)][Wp][4]`: four consecutive input channels of one pixel are
//!   adjacent, so one 32-bit lane holds the four `u8` inputs of a dot-product instruction (`vpdpbusd`,
//!   `UDOT`/`USDOT`). `C` is padded up to a multiple of 4 with channels that hold the zero point. The border
//!   (and the padding channels) hold the buffer's **zero point** `zp`, the quantised value of real 0, so
//!   zero padding of the convolution is exact for asymmetric activations; the packing code folds the
//!   constant `−zp·Σw` into the accumulator's start value.
//!
//! Kernels write only the interior (rows `1..=H`, columns `1..=W`) plus the right border of the rows they
//! compute, which they rewrite with the border value; rows 0 and `H + 1` and column 0 are never written.
//! [`RowPlanar::border_is_clean`] checks the invariant.

pub(crate) mod band;
pub(crate) mod planar;
mod quant_fill;
pub(crate) mod rows;
#[cfg(test)]
mod tests;

pub use band::RowBand;
pub use planar::{padded_width, Affine, Element, RowPlanar, MAX_DIM, MAX_TILE};
