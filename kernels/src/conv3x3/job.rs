//! The job contract between a plan and a kernel row: what a kernel reads ([`F32Job`], [`U8Job`]: every
//! shape, length and the row band checked by the safe API) and where it writes ([`F32Out`], [`U8Out`]).
//! The plans build jobs, the ISA files consume them; neither needs the other.

/// Everything an f32 kernel needs, checked by the safe API: the sources (`a` with `ca` channels, `b` with `cb`,
/// possibly 0), the frame `h × w` with padded row `wp`, the packed weights `[group][C_in][3][3][G]` and bias
/// `[group·G]` of the kernel's `G`, and the output rows `[y0, y1)`.
pub(crate) struct F32Job<'a> {
    pub a: &'a [f32],
    pub ca: usize,
    pub b: &'a [f32],
    pub cb: usize,
    pub h: usize,
    pub w: usize,
    pub wp: usize,
    pub weights: &'a [f32],
    pub bias: &'a [f32],
    pub cout: usize,
    pub relu: bool,
    pub residual: Option<&'a [f32]>,
    pub y0: usize,
    pub y1: usize,
    /// Winograd rows: the frame row of kernel row 0, modulo 4. Kernel row `y` is the top row of an F(2×2, 3×3)
    /// tile when `y + phase` is even, of an F(4×4, 3×3) tile when it is a multiple of 4 (tiles hold frame rows
    /// `2j, 2j + 1`, or `4j .. 4j + 4`, whatever the band or window, so any split gives the same bits).
    /// Direct rows ignore it.
    pub phase: usize,
}

/// Where an f32 kernel writes: a [`RowPlanar`](crate::buffer::RowPlanar) buffer of `C_out` channels
/// (`[H+2][C_out][Wp]`) or a planar `[C_out][H][W]` slice.
pub(crate) enum F32Out<'a> {
    /// Buffer rows of a `[H+2][C_out][Wp]` buffer: `data[0]` is element `base` of the whole buffer (a band of
    /// rows, [`RowBand`](crate::buffer::RowBand)); the kernel writes only rows `y0..y1`, which lie inside it.
    Rows {
        data: &'a mut [f32],
        base: usize,
    },
    Planar(&'a mut [f32]),
}

/// Everything an int8 kernel needs, checked by the safe API: sources `a`/`b` in the u8 layout with `ga`/`gb`
/// channel groups of 4, packed weights (bytes; i8 or i16 per the row's
/// [`PackKind`](crate::registry::PackKind)), per output channel (padded to the tile) the i32 accumulator
/// start (zero-point corrections), the f32 multiplier and bias; the residual `(buffer, zero point, scale)`;
/// the output quantisation `1/scale` and zero point.
pub(crate) struct U8Job<'a> {
    pub a: &'a [u8],
    pub ga: usize,
    pub b: &'a [u8],
    pub gb: usize,
    pub w: usize,
    pub wp: usize,
    pub weights: &'a [u8],
    pub init: &'a [i32],
    pub mult: &'a [f32],
    pub bias: &'a [f32],
    pub cout: usize,
    pub relu: bool,
    pub residual: Option<(&'a [u8], f32, f32)>,
    pub out_inv: f32,
    /// Read by the SIMD rows only (none on other architectures).
    #[cfg_attr(
        not(any(target_arch = "x86_64", target_arch = "aarch64")),
        allow(dead_code)
    )]
    pub out_zp: f32,
    pub out_zp_u8: u8,
    pub y0: usize,
    pub y1: usize,
}

/// Where an int8 kernel writes: a u8 [`RowPlanar`](crate::buffer::RowPlanar) (`[H+2][C_out/4][Wp][4]`) or raw
/// f32.
pub(crate) enum U8Out<'a> {
    /// Buffer rows of a u8 buffer: `data[0]` is element `base` of the whole buffer (a band of rows,
    /// [`RowBand`](crate::buffer::RowBand)); the kernel writes only rows `y0..y1`, which lie inside it.
    Rows { data: &'a mut [u8], base: usize },
    /// Raw f32: output channel `o`, row `y`, pixel `x` at `data[o·c_stride + y·y_stride + x − base]`
    /// (planar `[C_out][H][W]`: `c_stride = H·W`, `y_stride = W`, `base = 0`; a band of rows `y0..` of
    /// `[H][C_out][W]`: `c_stride = W`, `y_stride = C_out·W`, `base = y0·C_out·W`).
    F32 {
        data: &'a mut [f32],
        c_stride: usize,
        y_stride: usize,
        base: usize,
    },
}

impl U8Out<'_> {
    /// Index in `data` of the f32 output `(o, y, x)` (only for [`U8Out::F32`]).
    #[inline(always)]
    pub(crate) fn f32_index(
        c_stride: usize,
        y_stride: usize,
        base: usize,
        o: usize,
        y: usize,
        x: usize,
    ) -> usize {
        o * c_stride + y * y_stride + x - base
    }
}

/// The `#[target_feature]` entry points of the kernel rows, each one call of a generic loop instantiated
/// with the ISA's register type and tile: `entry_points!("features", Job, Out; $(#[attr])* fn name =
/// loop::<V, G, NV>; …)` defines `pub(crate) unsafe fn name(job: &Job<'_>, out: &mut Out<'_>)` with the
/// given attributes (the doc comment and its `# Safety` section, `#[cfg(test)]`) for each. Every tile it is
/// given fits `MAX_TILE` (the table's tests run every row on every width).
macro_rules! entry_points {
    ($features:literal, $job:ident, $out:ident; $($(#[$attr:meta])* fn $name:ident = $body:expr;)+) => {$(
        $(#[$attr])*
        #[target_feature(enable = $features)]
        pub(crate) unsafe fn $name(job: &$job<'_>, out: &mut $out<'_>) {
            // SAFETY: the features are enabled here and present on the CPU, the job was checked by the safe
            // API (the caller's guarantees), and the tile fits `MAX_TILE`.
            unsafe { $body(job, out) }
        }
    )+};
}
pub(crate) use entry_points;
