//! Winograd F(4×4, 3×3) convolution, written once for every register type ([`ConvF32`]), as
//! [`wino2x2`](super::wino2x2) is for F(2×2, 3×3).
//!
//! A 4×4 output tile `Y` comes from the 6×6 input tile `d` above it (Lavin & Gray 2016; the points 0, ±1, ±2
//! and ∞): `Y = Aᵀ [Σ_c U_c ⊙ V_c] A`, with `V_c = Bᵀ d_c B` and `U_c = G g_c Gᵀ` (packed once, at plan time,
//! by [`pack_winograd4_f32`](crate::pack::pack_winograd4_f32)):
//!
//! ```text
//!      ⎡4  0 −5  0  1  0⎤       ⎡ 1/4     0     0 ⎤       ⎡1  1  1  1  1  0⎤
//!      ⎢0 −4 −4  1  1  0⎥       ⎢−1/6  −1/6  −1/6 ⎥  Aᵀ = ⎢0  1 −1  2 −2  0⎥
//! Bᵀ = ⎢0  4 −4 −1  1  0⎥   G = ⎢−1/6   1/6  −1/6 ⎥       ⎢0  1  1  4  4  0⎥
//!      ⎢0 −2 −1  2  1  0⎥       ⎢1/24  1/12   1/6 ⎥       ⎣0  1 −1  8 −8  1⎦
//!      ⎢0  2 −1 −2  1  0⎥       ⎢1/24 −1/12   1/6 ⎥
//!      ⎣0  4  0 −5  0  1⎦       ⎣  0     0      1 ⎦
//! ```
//!
//! 36 products per tile and input channel make 16 outputs: 2.25 multiply-adds per output and input channel,
//! against 9 for the direct convolution and 4 for F(2×2, 3×3). The 36 products are small matrix products
//! computed with the direct kernels' register tile (`G` output channels × `NV` registers of tiles;
//! [`products`](super::wino2x2::products), shared with F(2×2, 3×3)). Lanes hold consecutive tiles along
//! the row: the input transform loads each row transposed by quadruples ([`ConvF32::load_stride4`], the
//! tile's columns 0–3; columns 4–5 are the next tile's 0–1, [`ConvF32::next_columns`]) and the output
//! transform transposes its four columns back into pixels
//! ([`ConvF32::interleave4`]) before the direct kernels' epilogue (bias, ReLU, residual, the zero right
//! border).
//!
//! Work per chunk of `T = NV·LANES` tiles (4 output rows × `4T` pixels): the input transform of every input
//! channel into a thread's scratch `V[36][C_in][T]`, then per output-channel group the 36 products into
//! `M[G][36][T]` and the output transform of those `G` channels. 24 → 24 with AVX-512 (`T` = 16): `V` 54 KiB
//! and `M` 18 KiB, in L2.
//!
//! Rows are grouped by frame row: kernel row `y` starts a group when `y + phase` is a multiple of 4
//! ([`Inputs::frame_row`](crate::Inputs::frame_row)). A band that starts or ends inside a group computes the
//! whole group and writes only its own rows. Unlike F(2×2, 3×3), the rows of a group depend on input rows
//! beyond their own 3×3 neighbourhood (output rows 1 and 2 on input rows 1–4 of the tile, row 0 on 0–4, row 3
//! on 1–5), so such a band reads up to two rows above and below the rows the band itself needs: they must
//! hold the frame's values for the bits to be those of a whole-frame run (whole frames always do; windowed
//! callers align their bands to groups, [`KernelInfo::row_group`](crate::KernelInfo::row_group)). Input rows
//! past the operand's buffer (the last group of a frame whose height is not a multiple of 4) read as the
//! nearest buffer row, the zero border, as a taller frame's padding would.

use super::job::{F32Job, F32Out};
use super::simd_f32::{store_pixels, ConvF32};
use super::wino2x2::{prefetch_lines, products, put_scratch, take_scratch};

/// Products per tile: the 6×6 transformed tile.
pub(crate) const POINTS: usize = 36;

/// The constants of the transforms, as registers.
#[derive(Clone, Copy)]
struct Consts<V> {
    two: V,
    four: V,
    eight: V,
    minus_four: V,
    minus_five: V,
}

impl<V: ConvF32> Consts<V> {
    /// # Safety
    /// The ISA of `V`.
    #[inline(always)]
    unsafe fn new() -> Self {
        // SAFETY: broadcasts of local values on the caller's ISA.
        unsafe {
            Self {
                two: V::load_splat(&2.0),
                four: V::load_splat(&4.0),
                eight: V::load_splat(&8.0),
                minus_four: V::load_splat(&-4.0),
                minus_five: V::load_splat(&-5.0),
            }
        }
    }
}

/// Computes rows `[job.y0, job.y1)` of the convolution with F(4×4, 3×3) tiles.
///
/// # Safety
/// The CPU has the ISA of `V`; `job` was checked by the safe API (as for the direct kernel, with weights
/// packed by `pack_winograd4_f32` for `G`), and `4·V::LANES·NV ≤ MAX_TILE`, so every load and store stays
/// inside the padded rows.
#[inline(always)]
pub(crate) unsafe fn conv<V: ConvF32, const G: usize, const NV: usize>(
    job: &F32Job<'_>,
    out: &mut F32Out<'_>,
) {
    let t = V::LANES * NV;
    debug_assert!(4 * t <= crate::buffer::planar::MAX_TILE);
    let cin = job.ca + job.cb;
    let groups = job.cout.div_ceil(G);
    debug_assert!(job.weights.len() == POINTS * groups * cin * G && job.bias.len() == groups * G);
    let v_len = POINTS * cin * t;
    let mut scratch = take_scratch(super::wino2x2::scratch_len(POINTS, cin, G, t));
    let (vbuf, mbuf) = scratch.split_at_mut(v_len);
    // Each source with the number of buffer rows its view holds from kernel row 0 (the view runs to the end
    // of the operand's buffer, from its first row's column `cols.start` on, fewer than a row's values:
    // `Conv3x3F32::run_band_columns`; rounded up, those rows still count).
    let rows_of = |s: &[f32], cs: usize| {
        if cs == 0 {
            0
        } else {
            s.len().div_ceil(cs * job.wp)
        }
    };
    let srcs = [
        (job.a.as_ptr(), job.ca, rows_of(job.a, job.ca)),
        (job.b.as_ptr(), job.cb, rows_of(job.b, job.cb)),
    ];
    let tiles = job.w.div_ceil(4);
    let (y0, y1) = (job.y0 as isize, job.y1 as isize);
    // SAFETY: the caller guarantees the ISA.
    let k = unsafe { Consts::<V>::new() };
    let mut y = y0;
    while y < y1 {
        let top = y - (y + job.phase as isize).rem_euclid(4);
        let write = [0, 1, 2, 3].map(|dy| (y0..y1).contains(&(top + dy)));
        let mut t0 = 0;
        while t0 < tiles {
            // SAFETY: the caller's guarantees; rows are clamped into each view; `t0 < tiles`.
            unsafe { input_transform::<V, NV>(job, &srcs, top, t0, vbuf, k) };
            for grp in 0..groups {
                // SAFETY: as above; `grp < groups`.
                unsafe {
                    products::<V, G, NV, POINTS>(job, vbuf, mbuf, grp);
                    output_transform::<V, G, NV>(job, out, mbuf, grp, top, write, t0, k);
                }
            }
            t0 += t;
        }
        y = top + 4;
    }
    put_scratch(scratch);
}

/// `V = Bᵀ d B` of every input channel for tiles `t0..t0 + T` of the row group whose input buffer rows are
/// `top..top + 6` (each clamped into its source's view), into `vbuf[36][C_in][T]` (point `6i + j`: row `i`,
/// column `j` of the transformed tile).
///
/// # Safety
/// As [`conv`]; `t0 < ceil(w/4)`: columns `4·t0 ..< 4·(t0 + T) + 2 ≤ w + 1 + MAX_TILE < wp`.
#[inline(always)]
unsafe fn input_transform<V: ConvF32, const NV: usize>(
    job: &F32Job<'_>,
    srcs: &[(*const f32, usize, usize); 2],
    top: isize,
    t0: usize,
    vbuf: &mut [f32],
    k: Consts<V>,
) {
    let (l, wp) = (V::LANES, job.wp);
    let t = l * NV;
    let cin = job.ca + job.cb;
    let step = cin * t;
    let vp = vbuf.as_mut_ptr();
    let mut c = 0;
    for &(src, cs, avail) in srcs {
        if cs == 0 {
            continue;
        }
        // (`avail ≥ 3`: the view holds the band's own rows, checked; `min` before `max` never panics.)
        let rows = [0, 1, 2, 3, 4, 5].map(|i| (top + i).min(avail as isize - 1).max(0) as usize);
        for ic in 0..cs {
            // SAFETY: buffer rows `rows[i] < avail` of channel `ic < cs` of the source's view.
            let row = rows.map(|r| unsafe { src.add((r * cs + ic) * wp + 4 * t0) });
            for v in 0..NV {
                // SAFETY: columns inside the padded rows (see above); `vbuf` holds `36·C_in·T` values and
                // `(p·C_in + c)·T + v·l + l` stays inside it (`p < 36`, `c < C_in`, `v·l + l ≤ T`); register
                // arithmetic on the caller's ISA. (No closures: they would not inherit the caller's
                // `#[target_feature]`s.)
                unsafe {
                    for r in row {
                        prefetch_lines::<V>(r.wrapping_add(4 * t + 4 * v * l), 4 * l);
                    }
                    let mut h = [[V::zero(); 6]; 6];
                    for (hi, r) in h.iter_mut().zip(row) {
                        *hi = row_transform::<V>(r.add(4 * v * l), k);
                    }
                    let at = vp.add(c * t + v * l);
                    // Column `j` of the six rows' transforms (an index across the rows, not an iterator).
                    #[allow(clippy::needless_range_loop)]
                    for j in 0..6 {
                        let col = bt6([h[0][j], h[1][j], h[2][j], h[3][j], h[4][j], h[5][j]], k);
                        for (i, &x) in col.iter().enumerate() {
                            V::store(at.add((6 * i + j) * step), x);
                        }
                    }
                }
            }
            c += 1;
        }
    }
}

/// The row transform `d B` of one input row for `LANES` tiles from `p` (the first tile's first column): the
/// tiles' six columns (quadruples transposed at `p`, columns 4 and 5 from the next quadruples:
/// [`ConvF32::next_columns`]), then `Bᵀ` on them.
///
/// # Safety
/// The ISA of `V`; `4·LANES + 2` readable values at `p`.
#[inline(always)]
unsafe fn row_transform<V: ConvF32>(p: *const f32, k: Consts<V>) -> [V; 6] {
    // SAFETY: the caller's guarantees.
    unsafe {
        let [c0, c1, c2, c3] = V::load_stride4(p);
        let [c4, c5] = V::next_columns(p, c0, c1);
        bt6([c0, c1, c2, c3, c4, c5], k)
    }
}

/// `Bᵀ x` for six registers (one column or row of a tile per lane):
/// `[4x₀ − 5x₂ + x₄, (x₄ − 4x₂) ± (x₃ − 4x₁), (x₄ − x₂) ± 2(x₃ − x₁), x₅ + 4x₁ − 5x₃]`.
///
/// # Safety
/// The ISA of `V`.
#[inline(always)]
unsafe fn bt6<V: ConvF32>(x: [V; 6], k: Consts<V>) -> [V; 6] {
    // SAFETY: register arithmetic on the caller's ISA.
    unsafe {
        let p = V::fma(x[4], x[2], k.minus_four);
        let q = V::fma(x[3], x[1], k.minus_four);
        let r = V::sub(x[4], x[2]);
        let s = V::sub(x[3], x[1]);
        let s = V::add(s, s);
        [
            V::fma(V::fma(x[4], x[0], k.four), x[2], k.minus_five),
            V::add(p, q),
            V::sub(p, q),
            V::add(r, s),
            V::sub(r, s),
            V::fma(V::fma(x[5], x[1], k.four), x[3], k.minus_five),
        ]
    }
}

/// `Aᵀ m` for six registers: `[m₀ + a + c, b + 2d, a + 4c, b + 8d + m₅]` with `a, b = m₁ ± m₂` and
/// `c, d = m₃ ± m₄`.
///
/// # Safety
/// The ISA of `V`.
#[inline(always)]
unsafe fn at6<V: ConvF32>(m: [V; 6], k: Consts<V>) -> [V; 4] {
    // SAFETY: register arithmetic on the caller's ISA.
    unsafe {
        let (a, b) = (V::add(m[1], m[2]), V::sub(m[1], m[2]));
        let (c, d) = (V::add(m[3], m[4]), V::sub(m[3], m[4]));
        [
            V::add(V::add(m[0], a), c),
            V::fma(b, d, k.two),
            V::fma(a, c, k.four),
            V::add(V::fma(b, d, k.eight), m[5]),
        ]
    }
}

/// `Y = Aᵀ M A + bias` of group `grp`'s channels, then ReLU, residual and store of the output rows of the
/// group at kernel row `top` that `write` selects, tiles `t0..t0 + T` (pixels `4·t0 ..< 4·(t0 + T)`).
///
/// # Safety
/// As [`conv`]; `mbuf` holds the group's products; the rows `write` selects are inside the band.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn output_transform<V: ConvF32, const G: usize, const NV: usize>(
    job: &F32Job<'_>,
    out: &mut F32Out<'_>,
    mbuf: &[f32],
    grp: usize,
    top: isize,
    write: [bool; 4],
    t0: usize,
    k: Consts<V>,
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
            // SAFETY: `mbuf[g][p][v·l ..]` inside the `G·36·T` scratch; register arithmetic on the ISA.
            let z = unsafe {
                let m = mbuf.as_ptr().add(g * POINTS * t + v * l);
                // The column transform of each of the six columns: `z[r][j]`, output row `r`.
                let mut z = [[V::zero(); 6]; 4];
                for j in 0..6 {
                    let mut mj = [V::zero(); 6];
                    for (i, x) in mj.iter_mut().enumerate() {
                        *x = V::load(m.add((6 * i + j) * t));
                    }
                    let col = at6(mj, k);
                    for (zr, &c) in z.iter_mut().zip(&col) {
                        zr[j] = c;
                    }
                }
                z
            };
            for (dy, zr) in z.iter().enumerate() {
                if !write[dy] {
                    continue;
                }
                let y = (top + dy as isize) as usize;
                // SAFETY: register arithmetic on the caller's ISA; row `y` is in the band, pixels
                // `px + q·l ≤ 4·(t0 + T) − l < w + MAX_TILE − LANES` (`4·t0 ≤ w − 1`, `4T ≤ MAX_TILE`): inside
                // the padded row (`store_pixels`).
                unsafe {
                    let mut cols = at6(*zr, k);
                    for c in cols.iter_mut() {
                        *c = V::add(*c, b);
                    }
                    let px = 4 * (t0 + v * l);
                    if let Some(res) = job.residual {
                        // The next chunk's residual values (as for the inputs).
                        let at = ((y + 1) * job.cout + o) * job.wp + 1 + px + 4 * t;
                        prefetch_lines::<V>(res.as_ptr().wrapping_add(at), 4 * l);
                    }
                    for (q, p) in V::interleave4(cols).into_iter().enumerate() {
                        store_pixels(job, out, p, o, y, px + q * l);
                    }
                }
            }
        }
    }
}
