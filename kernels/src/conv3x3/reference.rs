//! The obviously-correct reference: a direct loop over planar `[C][H][W]` data with zero padding, f64
//! accumulation for f32, exact i64 accumulation for int8. Tests only; never dispatched.

/// Reference output `[C_out][H][W]` and, per output value, `Σ|w·x|` (the scale of the rounding error an f32
/// kernel may make).
pub(crate) struct RefF32 {
    pub out: Vec<f32>,
    pub mag: Vec<f64>,
    /// Per output value, the scale of a Winograd F(2×2, 3×3) kernel's rounding error:
    /// `Σ_c (Σ|g_c|)·(Σ_{5×5}|d_c|) + |bias| + |residual|`, `g_c` the 3×3 filter of input channel `c` and
    /// `d_c` its inputs in the 5×5 neighbourhood (which holds every 4×4 input tile of the pixel).
    pub wino: Vec<f64>,
    /// The same for a Winograd F(4×4, 3×3) kernel: the inputs in the 9×9 neighbourhood, which holds every
    /// 6×6 input tile of the pixel.
    pub wino4: Vec<f64>,
}

/// The error scale of a Winograd kernel's output ([`RefF32::wino`], [`RefF32::wino4`]): every intermediate
/// (`V = Bᵀ d B`: sums of the tile's inputs; `U = G g Gᵀ`: at most `Σ|g|`; the output transform: sums of
/// products) is bounded by these sums, the inputs taken in the `(2r + 1)²` neighbourhood that holds every
/// input tile of the pixel (`r` = 2 for F(2×2, 3×3), 4 for F(4×4, 3×3)). Per output value; `input(c, y, x)`
/// is 0 outside the frame.
fn winograd_scale(
    input: &dyn Fn(usize, isize, isize) -> f64,
    weights: &[f32],
    cin: usize,
    (o, y, x): (usize, usize, usize),
    r: isize,
) -> f64 {
    let mut m = 0.0;
    for c in 0..cin {
        let g: f64 = weights[(o * cin + c) * 9..][..9]
            .iter()
            .map(|v| v.abs() as f64)
            .sum();
        let mut d = 0.0;
        for dy in -r..=r {
            for dx in -r..=r {
                d += input(c, y as isize + dy, x as isize + dx).abs();
            }
        }
        m += g * d;
    }
    m
}

/// `out[o][y][x] = bias[o] + Σ_{i,ky,kx} w[o][i][ky][kx] · in[i][y+ky−1][x+kx−1]` (zero outside), where `in`
/// is the channel concatenation of `a` (`ca` channels) and `b` (`cb` channels); then ReLU, then `+ residual`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn conv_f32(
    a: &[f32],
    ca: usize,
    b: &[f32],
    cb: usize,
    h: usize,
    w: usize,
    weights: &[f32],
    bias: &[f32],
    cout: usize,
    relu: bool,
    residual: Option<&[f32]>,
) -> RefF32 {
    let cin = ca + cb;
    let input = |i: usize, y: isize, x: isize| -> f64 {
        if y < 0 || x < 0 || y >= h as isize || x >= w as isize {
            return 0.0;
        }
        let (y, x) = (y as usize, x as usize);
        if i < ca {
            a[(i * h + y) * w + x] as f64
        } else {
            b[((i - ca) * h + y) * w + x] as f64
        }
    };
    let mut out = vec![0.0f32; cout * h * w];
    let mut mag = vec![0.0f64; cout * h * w];
    let mut wino = vec![0.0f64; cout * h * w];
    let mut wino4 = vec![0.0f64; cout * h * w];
    for o in 0..cout {
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0f64;
                let mut m = bias[o].abs() as f64;
                for i in 0..cin {
                    for ky in 0..3 {
                        for kx in 0..3 {
                            let wt = weights[((o * cin + i) * 3 + ky) * 3 + kx] as f64;
                            let v = input(
                                i,
                                y as isize + ky as isize - 1,
                                x as isize + kx as isize - 1,
                            );
                            s += wt * v;
                            m += (wt * v).abs();
                        }
                    }
                }
                let mut v = s + bias[o] as f64;
                if relu && v < 0.0 {
                    v = 0.0;
                }
                let k = (o * h + y) * w + x;
                let other = bias[o].abs() as f64 + residual.map_or(0.0, |r| r[k].abs() as f64);
                let wm = winograd_scale(&input, weights, cin, (o, y, x), 2) + other;
                let wm4 = winograd_scale(&input, weights, cin, (o, y, x), 4) + other;
                if let Some(r) = residual {
                    v += r[k] as f64;
                    m += r[k].abs() as f64;
                }
                out[k] = v as f32;
                mag[k] = m;
                wino[k] = wm;
                wino4[k] = wm4;
            }
        }
    }
    RefF32 {
        out,
        mag,
        wino,
        wino4,
    }
}

/// Quantisation of the int8 reference layer.
pub(crate) struct RefU8Params<'a> {
    pub weights: &'a [i8],
    pub mult: &'a [f32],
    pub bias: &'a [f32],
    pub zp_a: u8,
    pub zp_b: u8,
    pub relu: bool,
    /// Residual planar `[C_out][H][W]` u8, its zero point and scale.
    pub residual: Option<(&'a [u8], u8, f32)>,
    /// Output `1/scale` and zero point; `None`: f32 output.
    pub output: Option<(f32, u8)>,
}

/// int8 reference on planar u8 `[C][H][W]` data: exact `acc = Σ w·(q − zp)` (i64; zero padding is real 0),
/// then the epilogue spelled out: `(acc as f32)·mult + bias`, ReLU, `+ (r − r_zp)·r_scale`, and
/// `clamp(round_ties_even(v·inv) + zp, 0, 255)` for u8 output. Returns f32 values (u8 outputs as integers).
#[allow(clippy::too_many_arguments)]
pub(crate) fn conv_u8(
    a: &[u8],
    ca: usize,
    b: &[u8],
    cb: usize,
    h: usize,
    w: usize,
    cout: usize,
    p: &RefU8Params<'_>,
) -> Vec<f32> {
    let cin = ca + cb;
    let input = |i: usize, y: isize, x: isize| -> i64 {
        if y < 0 || x < 0 || y >= h as isize || x >= w as isize {
            return 0;
        }
        let (y, x) = (y as usize, x as usize);
        if i < ca {
            a[(i * h + y) * w + x] as i64 - p.zp_a as i64
        } else {
            b[((i - ca) * h + y) * w + x] as i64 - p.zp_b as i64
        }
    };
    let mut out = vec![0.0f32; cout * h * w];
    for o in 0..cout {
        for y in 0..h {
            for x in 0..w {
                let mut acc: i64 = 0;
                for i in 0..cin {
                    for ky in 0..3 {
                        for kx in 0..3 {
                            let wt = p.weights[((o * cin + i) * 3 + ky) * 3 + kx] as i64;
                            acc += wt
                                * input(
                                    i,
                                    y as isize + ky as isize - 1,
                                    x as isize + kx as isize - 1,
                                );
                        }
                    }
                }
                let acc = i32::try_from(acc).expect("i32 accumulator");
                let mut v = (acc as f32) * p.mult[o] + p.bias[o];
                if p.relu && v <= 0.0 {
                    v = 0.0;
                }
                let k = (o * h + y) * w + x;
                if let Some((r, rzp, rs)) = p.residual {
                    v += (r[k] as f32 - rzp as f32) * rs;
                }
                if let Some((inv, zp)) = p.output {
                    let q = (v * inv).round_ties_even() + zp as f32;
                    v = q.clamp(0.0, 255.0);
                }
                out[k] = v;
            }
        }
    }
    out
}
