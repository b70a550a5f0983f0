//! Winograd F(2×2, 3×3) convolution, written once for every register type ([`ConvF32`]: the AVX2, AVX-512 and
//! NEON registers, and plain `f32` for the portable row).
//!
//! A 2×2 output tile `Y` comes from the 4×4 input tile `d` above it (Lavin & Gray 2016):
//! `Y = Aᵀ [Σ_c U_c ⊙ V_c] A`, with `V_c = Bᵀ d_c B` (input transform) and `U_c = G g_c Gᵀ` (the 3×3 filter
//! transformed once, at plan time, by [`pack_winograd_f32`](crate::pack::pack_winograd_f32)):
//!
//! ```text
//!      ⎡1  0 −1  0⎤       ⎡1    0    0 ⎤       ⎡1  1  1  0⎤
//! Bᵀ = ⎢0  1  1  0⎥   G = ⎢½    ½    ½ ⎥  Aᵀ = ⎣0  1 −1 −1⎦
//!      ⎢0 −1  1  0⎥       ⎢½   −½    ½ ⎥
//!      ⎣0  1  0 −1⎦       ⎣0    0    1 ⎦
//! ```
//!
//! The 16 products `M_k = Σ_c U_k[o][c]·V_k[c]` are 16 small matrix products (`C_out × C_in` by `C_in ×
//! tiles`), computed with the direct kernels' register tile: `G` output channels × `NV` registers of tiles,
//! one broadcast weight per channel and step. The lanes hold consecutive tiles along the row, so the input
//! transform loads rows deinterleaved (even and odd columns) and the output transform interleaves its two
//! columns back into pixels before the epilogue (bias, ReLU, residual, the zero right border), which is the
//! direct kernels'.
//!
//! Work per chunk of `T = NV·LANES` tiles (2 output rows × `2T` pixels): the input transform of every input
//! channel into a thread's scratch `V[16][C_in][T]`, then per output-channel group the 16 products into
//! `M[G][16][T]` and the output transform of those `G` channels. 24 → 24 with AVX2 (`T` = 16): `V` 24 KiB
//! and `M` 6 KiB stay in L1/L2; the packed `U` (36 KiB) streams from L2 at about 4 bytes a cycle.
//!
//! Rows are paired by frame row (`parity`, from [`Inputs::frame_row`](crate::Inputs::frame_row)): a band that
//! starts or ends inside a pair computes the whole pair and writes only its own row. Output row 0 of a tile
//! does not read input row 3, nor row 1 input row 0 (`Aᵀ`'s rows and `Bᵀ`'s columns), so the row a band
//! does not own is replaced by a neighbour and the kept row is bit-identical to the one a whole-frame run
//! computes: any split into bands, windows or threads gives the same frame.

use super::job::{F32Job, F32Out};
use super::simd_f32::{store_pixels, ConvF32};
use std::cell::Cell;

thread_local! {
    /// Each thread's scratch (`V` then `M`), grown on first use and kept: no allocation per frame.
    static SCRATCH: Cell<Vec<f32>> = const { Cell::new(Vec::new()) };
}

/// The scratch (f32 values) a Winograd row with `points` products per tile (16 for F(2×2, 3×3), 36 for
/// F(4×4, 3×3)) and a tile of `oc_tile` output channels × `tiles` tiles needs for `c_in` input channels:
/// `V[points][C_in][tiles]` and `M[G][points][tiles]`.
pub(crate) fn scratch_len(points: usize, c_in: usize, oc_tile: usize, tiles: usize) -> usize {
    points * tiles * (c_in + oc_tile)
}

/// The calling thread's scratch, at least `need` values long (grown if not); hand it back with
/// [`put_scratch`].
pub(super) fn take_scratch(need: usize) -> Vec<f32> {
    let mut scratch = SCRATCH.take();
    if scratch.len() < need {
        scratch.resize(need, 0.0);
    }
    scratch
}

/// Gives the scratch back to the calling thread, for its next call.
pub(super) fn put_scratch(scratch: Vec<f32>) {
    SCRATCH.set(scratch);
}

/// Grows the calling thread's scratch to at least `len` values now, so that no later call on this thread
/// allocates (a thread that first runs a Winograd layer after a plan's warm-up frames would otherwise).
pub(crate) fn reserve_scratch(len: usize) {
    let mut scratch = SCRATCH.take();
    if scratch.len() < len {
        scratch.resize(len, 0.0);
    }
    SCRATCH.set(scratch);
}

/// Computes rows `[job.y0, job.y1)` of the convolution with F(2×2, 3×3) tiles.
///
/// # Safety
/// The CPU has the ISA of `V`; `job` was checked by the safe API (as for the direct kernel, with weights
/// packed by `pack_winograd_f32` for `G`), and `2·V::LANES·NV ≤ MAX_TILE`, so every load and store stays
/// inside the padded rows.
#[inline(always)]
pub(crate) unsafe fn conv<V: ConvF32, const G: usize, const NV: usize>(
    job: &F32Job<'_>,
    out: &mut F32Out<'_>,
) {
    let t = V::LANES * NV;
    debug_assert!(2 * t <= crate::buffer::planar::MAX_TILE);
    let cin = job.ca + job.cb;
    let groups = job.cout.div_ceil(G);
    debug_assert!(job.weights.len() == 16 * groups * cin * G && job.bias.len() == groups * G);
    let v_len = 16 * cin * t;
    let mut scratch = take_scratch(scratch_len(16, cin, G, t));
    let (vbuf, mbuf) = scratch.split_at_mut(v_len);
    let srcs = [(job.a.as_ptr(), job.ca), (job.b.as_ptr(), job.cb)];
    let tiles = job.w.div_ceil(2);
    let (y0, y1) = (job.y0 as isize, job.y1 as isize);
    let mut y = y0;
    while y < y1 {
        let top = if (y as usize + job.phase).is_multiple_of(2) {
            y
        } else {
            y - 1
        };
        let write = [top >= y0, top + 1 < y1];
        // Input buffer rows `top..top + 4`; a row only the unwritten output row reads is replaced by its
        // neighbour (which the band may read).
        let rows = [
            if write[0] { top } else { top + 1 },
            top + 1,
            top + 2,
            if write[1] { top + 3 } else { top + 2 },
        ]
        .map(|r| r as usize);
        let mut t0 = 0;
        while t0 < tiles {
            // SAFETY: the caller's guarantees; `rows` are rows the band reads, `t0 < tiles`.
            unsafe { input_transform::<V, NV>(job, &srcs, rows, t0, vbuf) };
            for grp in 0..groups {
                // SAFETY: as above; `grp < groups`.
                unsafe {
                    products::<V, G, NV, 16>(job, vbuf, mbuf, grp);
                    output_transform::<V, G, NV>(job, out, mbuf, grp, top, write, t0);
                }
            }
            t0 += t;
        }
        y = top + 2;
    }
    put_scratch(scratch);
}

/// `V = Bᵀ d B` of every input channel for tiles `t0..t0 + T` of the row pair whose input buffer rows are
/// `rows`, into `vbuf[16][C_in][T]`.
///
/// # Safety
/// As [`conv`]; `t0 < ceil(w/2)`: columns `2·t0 ..< 2·(t0 + T) + 2 ≤ w + 1 + MAX_TILE < wp`.
#[inline(always)]
unsafe fn input_transform<V: ConvF32, const NV: usize>(
    job: &F32Job<'_>,
    srcs: &[(*const f32, usize); 2],
    rows: [usize; 4],
    t0: usize,
    vbuf: &mut [f32],
) {
    let (l, wp) = (V::LANES, job.wp);
    let t = l * NV;
    let cin = job.ca + job.cb;
    let vp = vbuf.as_mut_ptr();
    let mut c = 0;
    for &(src, cs) in srcs {
        for ic in 0..cs {
            // SAFETY: buffer rows `rows[r] ≤ h + 1` of channel `ic < cs` of a `(h + 2)·cs·wp` source.
            let row = rows.map(|r| unsafe { src.add((r * cs + ic) * wp + 2 * t0) });
            for v in 0..NV {
                // SAFETY: columns inside the padded rows (see above); `vbuf` holds `16·C_in·T` values and
                // `(k·C_in + c)·T + v·l + l` stays inside it (`k < 16`, `c < C_in`, `v·l + l ≤ T`); register
                // arithmetic on the caller's ISA. (No closures here: a closure is not compiled with the
                // caller's `#[target_feature]`s, and the intrinsics it calls would not be inlined.)
                unsafe {
                    // The next chunk's columns of the four rows: 96 interleaved streams (24 channels × 4
                    // rows) are too many for the hardware prefetcher (perf: the loads stalled).
                    for r in row {
                        prefetch_lines::<V>(r.wrapping_add(2 * t + 2 * v * l), 2 * l);
                    }
                    let h1 = row_transform::<V>(row[1].add(2 * v * l));
                    let h2 = row_transform::<V>(row[2].add(2 * v * l));
                    let at = vp.add(c * t + v * l);
                    let step = cin * t;
                    for j in 0..4 {
                        V::store(at.add((4 + j) * step), V::add(h1[j], h2[j]));
                        V::store(at.add((8 + j) * step), V::sub(h2[j], h1[j]));
                    }
                    let h0 = row_transform::<V>(row[0].add(2 * v * l));
                    for j in 0..4 {
                        V::store(at.add(j * step), V::sub(h0[j], h2[j]));
                    }
                    let h3 = row_transform::<V>(row[3].add(2 * v * l));
                    for j in 0..4 {
                        V::store(at.add((12 + j) * step), V::sub(h1[j], h3[j]));
                    }
                }
            }
            c += 1;
        }
    }
}

/// The row transform `d B` of one input row for `LANES` tiles from `p` (the first tile's first column): the
/// tiles' four columns `c0..c3` loaded deinterleaved, `[c0 − c2, c1 + c2, c2 − c1, c1 − c3]`.
///
/// # Safety
/// The ISA of `V`; `2·LANES + 2` readable values at `p`.
#[inline(always)]
unsafe fn row_transform<V: ConvF32>(p: *const f32) -> [V; 4] {
    // SAFETY: the caller's guarantees.
    unsafe {
        let (c0, c1) = V::load_deinterleaved(p);
        let (c2, c3) = V::load_deinterleaved(p.add(2));
        [
            V::sub(c0, c2),
            V::add(c1, c2),
            V::sub(c2, c1),
            V::sub(c1, c3),
        ]
    }
}

/// The `P` products `M_k[g] = Σ_c U_k[grp·G + g][c]·V_k[c]` of output-channel group `grp` (`P` = 16 for
/// F(2×2, 3×3), 36 for F(4×4, 3×3)), into `mbuf[G][P][T]`.
///
/// # Safety
/// As [`conv`]; `grp < groups`; `vbuf` holds this chunk's transformed inputs `V[P][C_in][T]` and the
/// weights are packed `[P][groups][C_in][G]`.
#[inline(always)]
pub(super) unsafe fn products<V: ConvF32, const G: usize, const NV: usize, const P: usize>(
    job: &F32Job<'_>,
    vbuf: &[f32],
    mbuf: &mut [f32],
    grp: usize,
) {
    let l = V::LANES;
    let t = l * NV;
    let cin = job.ca + job.cb;
    let groups = job.cout.div_ceil(G);
    for k in 0..P {
        // SAFETY: the caller guarantees the ISA; the accumulators are plain registers.
        let mut acc = [[unsafe { V::zero() }; NV]; G];
        // SAFETY: `U` is `[16][groups][C_in][G]`: this (k, grp) block's `C_in·G` weights are inside.
        let mut wptr = unsafe { job.weights.as_ptr().add((k * groups + grp) * cin * G) };
        // SAFETY: `V_k` is `C_in·T` values inside `vbuf`.
        let mut xptr = unsafe { vbuf.as_ptr().add(k * cin * t) };
        for _ in 0..cin {
            let mut xv = acc[0];
            for (v, x) in xv.iter_mut().enumerate() {
                // SAFETY: `v·l + l ≤ T` values of this channel's row of `V_k`.
                *x = unsafe { V::load(xptr.add(v * l)) };
            }
            // SAFETY: `G` weights of this step; the caller's ISA.
            unsafe { V::fma_step(&mut acc, &xv, wptr) };
            // SAFETY: at most one past the block's (and `V_k`'s) end.
            unsafe {
                wptr = wptr.add(G);
                xptr = xptr.add(t);
            }
        }
        for (g, accg) in acc.iter().enumerate() {
            for (v, &a) in accg.iter().enumerate() {
                // SAFETY: `mbuf` holds `G·P·T` values.
                unsafe { V::store(mbuf.as_mut_ptr().add((g * P + k) * t + v * l), a) };
            }
        }
    }
}

/// `Y = Aᵀ M A + bias` of group `grp`'s channels, then ReLU, residual and store of the output rows of the
/// pair at kernel row `top` that `write` selects, tiles `t0..t0 + T` (pixels `2·t0 ..< 2·(t0 + T)`).
///
/// # Safety
/// As [`conv`]; `mbuf` holds the group's products; the rows `write` selects are inside the band.
#[inline(always)]
unsafe fn output_transform<V: ConvF32, const G: usize, const NV: usize>(
    job: &F32Job<'_>,
    out: &mut F32Out<'_>,
    mbuf: &[f32],
    grp: usize,
    top: isize,
    write: [bool; 2],
    t0: usize,
) {
    let l = V::LANES;
    let t = l * NV;
    for g in 0..G {
        let o = grp * G + g;
        if o >= job.cout {
            break;
        }
        // SAFETY: `o < groups·G = bias.len()`.
        let b = unsafe { V::load_splat(job.bias.as_ptr().add(o)) };
        for v in 0..NV {
            // SAFETY: `mbuf[g][k][v·l ..]` inside the `G·16·T` scratch; register arithmetic on the ISA.
            let ys = unsafe {
                let m = mbuf.as_ptr().add(g * 16 * t + v * l);
                let mut r0 = [V::zero(); 4];
                let mut r1 = [V::zero(); 4];
                for j in 0..4 {
                    let (m1, m2) = (V::load(m.add((4 + j) * t)), V::load(m.add((8 + j) * t)));
                    r0[j] = V::add(V::add(V::load(m.add(j * t)), m1), m2);
                    r1[j] = V::sub(V::sub(m1, m2), V::load(m.add((12 + j) * t)));
                }
                [output_columns(r0, b), output_columns(r1, b)]
            };
            for (dy, &(even, odd)) in ys.iter().enumerate() {
                if !write[dy] {
                    continue;
                }
                let y = (top + dy as isize) as usize;
                // SAFETY: register arithmetic on the caller's ISA; row `y` is in the band, pixels
                // `px < 2·(t0 + T) ≤ w + 1 + MAX_TILE − LANES` inside the padded row.
                unsafe {
                    let (p0, p1) = V::interleave(even, odd);
                    let px = 2 * (t0 + v * l);
                    if let Some(res) = job.residual {
                        // The next chunk's residual values (as for the inputs: 48 streams).
                        let at = ((y + 1) * job.cout + o) * job.wp + 1 + px + 2 * t;
                        prefetch_lines::<V>(res.as_ptr().wrapping_add(at), 2 * l);
                    }
                    store_pixels(job, out, p0, o, y, px);
                    store_pixels(job, out, p1, o, y, px + l);
                }
            }
        }
    }
}

/// The column transform of one output row of `LANES` tiles, `(r0 + r1 + r2, r1 − r2 − r3)`, plus the bias.
///
/// # Safety
/// The ISA of `V`.
#[inline(always)]
unsafe fn output_columns<V: ConvF32>(r: [V; 4], b: V) -> (V, V) {
    // SAFETY: register arithmetic on the caller's ISA.
    unsafe {
        (
            V::add(V::add(V::add(r[0], r[1]), r[2]), b),
            V::add(V::sub(V::sub(r[1], r[2]), r[3]), b),
        )
    }
}

/// Prefetches the cache lines of `n` values from `p` (16 f32 a line).
///
/// # Safety
/// The ISA of `V` (a prefetch never faults; `p` is computed with wrapping arithmetic).
#[inline(always)]
pub(super) unsafe fn prefetch_lines<V: ConvF32>(p: *const f32, n: usize) {
    for line in (0..n).step_by(16) {
        // SAFETY: a prefetch never faults.
        unsafe { V::prefetch(p.wrapping_add(line)) };
    }
}
