//! The box means' portable body (the method: [`crate::box_blur`]): chunks of [`CHUNK`] pixels, one square
//! size at a time over four contiguous runs of the table, compiled as it is (SSE2 / NEON) and inside
//! `#[target_feature]` functions (AVX2, AVX-512F). No FMA contraction, no reordering: every copy gives the
//! same bits.

use super::{Defocus, SatRow, CHUNK};

/// [`super::box_means`] on checked bounds (an index out of the table panics: the caller checked them).
#[inline(always)]
pub(crate) fn means_body(sat: SatRow<'_>, depth: &[f32], defocus: Defocus, out: &mut [f32]) {
    let SatRow {
        table,
        stride,
        row,
        x0,
    } = sat;
    let Defocus {
        gaze_depth,
        scale,
        max_half,
    } = defocus;
    let mut half = [0.0f64; CHUNK];
    let mut acc = [0.0f64; CHUNK];
    for (c, (depth, out)) in depth.chunks(CHUNK).zip(out.chunks_mut(CHUNK)).enumerate() {
        let m = depth.len();
        let x = x0 + c * CHUNK;
        let (half, acc) = (&mut half[..m], &mut acc[..m]);
        for (h, &d) in half.iter_mut().zip(depth) {
            *h = (f64::from((d - gaze_depth).abs()) * scale - 0.5).clamp(0.0, max_half);
        }
        let (lo, hi) = half
            .iter()
            .fold((max_half, 0.0f64), |(lo, hi), &h| (lo.min(h), hi.max(h)));
        acc.fill(0.0);
        // The sizes with a weight: `⌊lo⌋ ..= ⌊hi⌋ + 1` (a NaN depth reads sizes 0 and 1 and gives NaN).
        for k in (lo as usize)..=(hi as usize + 1) {
            let (top, bottom) = ((row - k) * stride, (row + k + 1) * stride);
            let right_top = &table[top + x + k + 1..][..m];
            let right_bottom = &table[bottom + x + k + 1..][..m];
            let left_top = &table[top + x - k..][..m];
            let left_bottom = &table[bottom + x - k..][..m];
            let side = (2 * k + 1) as f64;
            let (inv_area, j) = (1.0 / (side * side), k as f64);
            for (((((a, &h), &rb), &rt), &lb), &lt) in acc
                .iter_mut()
                .zip(&*half)
                .zip(right_bottom)
                .zip(right_top)
                .zip(left_bottom)
                .zip(left_top)
            {
                let weight = (1.0 - (h - j).abs()).max(0.0);
                *a += weight * ((rb - rt - lb + lt) * inv_area);
            }
        }
        for (o, &a) in out.iter_mut().zip(&*acc) {
            *o = a as f32;
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod x86 {
    use super::{means_body, Defocus, SatRow};

    /// # Safety
    /// The CPU has AVX2.
    #[target_feature(enable = "avx2")]
    pub(crate) unsafe fn means_avx2(sat: SatRow<'_>, depth: &[f32], d: Defocus, out: &mut [f32]) {
        means_body(sat, depth, d, out)
    }

    /// # Safety
    /// The CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(crate) unsafe fn means_avx512(sat: SatRow<'_>, depth: &[f32], d: Defocus, out: &mut [f32]) {
        means_body(sat, depth, d, out)
    }
}
