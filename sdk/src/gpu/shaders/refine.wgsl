// The focal-stack refinement's element-wise steps (refine::model, docs/REFINE.md) around the spectral
// operations of spectral.wgsl / fft.wgsl, all three colours at once:
//   `phasor`     u = e^{iφ}; quantised: φ through the linear look-up table first (code = round(wrap(φ)·256/2π)
//                mod 256, shown phase 2π·code/256, as encoding::LinearLut)
//   `plane`      from U_d (in `work`) and the target T_d: per workgroup of one channel the partial sums
//                (⟨|U_d|, T_d⟩, ‖U_d‖²) (a fixed tree: the same bits on every run), then V_d = T_d·U_d/|U_d|
//                in place (0 where U_d = 0)
//   `reduce`     per channel (one workgroup each): A and B over planes and workgroups in a fixed order, and the
//                least-squares scale k = A/B (0 where B = 0) into sums[c] = (A, B, k, 0)
//   `adam`       g = 2k²·work − 2k·acc (work: F⁻¹{W·F{u}}, acc: F⁻¹{Σ_d conj(m_d)·F{V_d}}), ∂L/∂φ =
//                Im(g·conj(u)), and Adam's update of φ
// Through a display model (slm::model, docs/REFINE.md "Through a display model") the phase is the SLM's drive
// in radians of the linear table (codes v = φ·256/2π, clamped to 0…255, rounded where quantised) and three
// kernels stand for `phasor` and `adam`:
//   `model_phasor`   c' = K ∗ v (the colour's kernel, edges clamped), (R(c'), R'(c')) into `shown` (R the
//                    response: the bilinear blend of its four nearest tiles' curves at the pixel, one tile for
//                    a global table, linear between codes), u = S·(e^{iR(c')} + z)
//   `model_gradient` g as `adam`'s, dphi = Im(g·conj(S·e^{iR(c')}))·R'(c')
//   `model_adam`     ∂L/∂v = Kᵀ ∗ dphi (the clamped convolution's adjoint, gathered: every pixel whose
//                    clamped tap lands here), ∂L/∂φ = ∂L/∂v ÷ (2π/256), Adam's update, then the projected
//                    step: φ clamped to [0, 2π·255/256]
//
// Bindings (group 0; each entry point uses some):
//   0: uniform Params
//   1: uniform PlaneParams (the plane's index)
//   2: storage phase:   array<f32>,        [C, H, W] radians
//   3: storage unit:    array<vec2<f32>>,  [C, H, W]
//   4: storage work:    array<vec2<f32>>,  [C, H, W]
//   5: storage acc:     array<vec2<f32>>,  [C, H, W]
//   6: storage target:  array<f32>,        [D, C, H, W]
//   7: storage partial: array<vec2<f32>>,  [D, C, G] (G = `groups`, workgroups per channel plane)
//   8: storage sums:    array<vec4<f32>>,  [C]
//   9: storage mean:    array<f32>,        [C, H, W] (Adam's first moment)
//  10: storage square:  array<f32>,        [C, H, W] (Adam's second moment)
//  11: storage source:  array<vec2<f32>>,  [C, H, W] (the display model's S)
//  12: storage table:   array<f32>,        each colour's tile curves [tiles, 256] (radians) at its offset
//  13: storage weights: array<f32>,        each colour's kernel, row-major, at its offset
//  14: storage shown:   array<vec2<f32>>,  [C, H, W]: (R(K ∗ v), R'(K ∗ v))
//  15: storage dphi:    array<f32>,        [C, H, W]
//  16: storage info:    array<vec4<u32>>,  [C, 3]: (kernel rows, cols, offset, 0), (Re z, Im z, 0, 0) as f32
//                                          bits, (curves' offset, tiles per grid row, rows' and columns'
//                                          offsets into `axes`)
//  17: storage axes:    array<vec4<f32>>,  each colour's [H] row and [W] column tile weights (tile a, tile b,
//                                          weight of b, 0) at their offsets
// Grids: `phasor`, `adam` and the three `model_` kernels over C·H·W elements (1D, 256 per workgroup, spread
// over x/y); `plane` over H·W elements in x/y (the same spread) and the channel in z; `reduce` one workgroup
// per channel.

struct Params {
    hw: u32,
    channels: u32,
    groups: u32,
    planes: u32,
    quantised: u32,
    step: f32,
    beta1: f32,
    beta2: f32,
    epsilon: f32,
    c1: f32,
    c2: f32,
    width: u32,
}

struct PlaneParams {
    plane: u32,
}

const TAU: f32 = 6.283185307179586;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<uniform> plane_params: PlaneParams;
@group(0) @binding(2) var<storage, read_write> phase: array<f32>;
@group(0) @binding(3) var<storage, read_write> unit: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read_write> work: array<vec2<f32>>;
@group(0) @binding(5) var<storage, read_write> acc: array<vec2<f32>>;
@group(0) @binding(6) var<storage, read> target_amp: array<f32>;
@group(0) @binding(7) var<storage, read_write> partial: array<vec2<f32>>;
@group(0) @binding(8) var<storage, read_write> sums: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read_write> mean: array<f32>;
@group(0) @binding(10) var<storage, read_write> square: array<f32>;
@group(0) @binding(11) var<storage, read> source: array<vec2<f32>>;
@group(0) @binding(12) var<storage, read> table: array<f32>;
@group(0) @binding(13) var<storage, read> weights: array<f32>;
@group(0) @binding(14) var<storage, read_write> shown: array<vec2<f32>>;
@group(0) @binding(15) var<storage, read_write> dphi: array<f32>;
@group(0) @binding(16) var<storage, read> info: array<vec4<u32>>;
@group(0) @binding(17) var<storage, read> axes: array<vec4<f32>>;

fn index_of(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 256u;
}

@compute @workgroup_size(256)
fn phasor(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    if (i >= params.channels * params.hw) {
        return;
    }
    var p = phase[i];
    if (params.quantised != 0u) {
        let wrapped = p - TAU * floor(p / TAU);
        let code = u32(round(wrapped * (256.0 / TAU))) % 256u;
        p = f32(code) * (TAU / 256.0);
    }
    unit[i] = vec2<f32>(cos(p), sin(p));
}

var<workgroup> lanes: array<vec2<f32>, 256>;

// The sum of every invocation's `s` over the workgroup, in a fixed tree (the same bits on every run); every
// invocation calls it (its barriers), the result is lanes[0].
fn tree_sum(lid: u32, s: vec2<f32>) -> vec2<f32> {
    lanes[lid] = s;
    workgroupBarrier();
    for (var half = 128u; half > 0u; half = half >> 1u) {
        if (lid < half) {
            lanes[lid] = lanes[lid] + lanes[lid + half];
        }
        workgroupBarrier();
    }
    return lanes[0];
}

@compute @workgroup_size(256)
fn plane(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let p = index_of(gid, groups);
    let c = gid.z;
    var s = vec2<f32>(0.0, 0.0);
    if (p < params.hw) {
        let i = c * params.hw + p;
        let u = work[i];
        let t = target_amp[(plane_params.plane * params.channels + c) * params.hw + p];
        let n2 = dot(u, u);
        let n = sqrt(n2);
        s = vec2<f32>(n * t, n2);
        var scale = 0.0;
        if (n > 0.0) {
            scale = t / n;
        }
        work[i] = u * scale;
    }
    let total = tree_sum(lid, s);
    if (lid == 0u) {
        let wg = p / 256u;
        partial[(plane_params.plane * params.channels + c) * params.groups + wg] = total;
    }
}

@compute @workgroup_size(256)
fn reduce(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let c = wid.x;
    var s = vec2<f32>(0.0, 0.0);
    for (var d = 0u; d < params.planes; d = d + 1u) {
        let base = (d * params.channels + c) * params.groups;
        for (var g = lid; g < params.groups; g = g + 256u) {
            s = s + partial[base + g];
        }
    }
    let total = tree_sum(lid, s);
    if (lid == 0u) {
        var k = 0.0;
        if (total.y > 0.0) {
            k = total.x / total.y;
        }
        sums[c] = vec4<f32>(total.x, total.y, k, 0.0);
    }
}

@compute @workgroup_size(256)
fn adam(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    if (i >= params.channels * params.hw) {
        return;
    }
    let k = sums[i / params.hw].z;
    let g = work[i] * (2.0 * k * k) - acc[i] * (2.0 * k);
    let u = unit[i];
    let grad = g.y * u.x - g.x * u.y;
    let m = params.beta1 * mean[i] + (1.0 - params.beta1) * grad;
    let v = params.beta2 * square[i] + (1.0 - params.beta2) * grad * grad;
    mean[i] = m;
    square[i] = v;
    phase[i] = phase[i] - params.step * (m / params.c1) / (sqrt(v / params.c2) + params.epsilon);
}

// Radians of the linear table per code, and the largest drive (code 255).
const SLOPE: f32 = 0.02454369260617026;
const MAX_DRIVE: f32 = 6.258641614573416;

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// The drive (codes as numbers) of element i.
fn drive_of(i: u32) -> f32 {
    let v = clamp(phase[i] / SLOPE, 0.0, 255.0);
    if (params.quantised != 0u) {
        return round(v);
    }
    return v;
}

// Code k's phase under the tiles `t` (info's third entry) at row weights `ry` and column weights `rx`: the
// bilinear blend of the four tiles' curves (as slm::TiledCurves).
fn curve_at(t: vec4<u32>, ry: vec4<f32>, rx: vec4<f32>, k: u32) -> f32 {
    let top = t.x + u32(ry.x) * t.y * 256u + k;
    let bottom = t.x + u32(ry.y) * t.y * 256u + k;
    let left = u32(rx.x) * 256u;
    let right = u32(rx.y) * 256u;
    let upper = table[top + left] * (1.0 - rx.z) + table[top + right] * rx.z;
    let lower = table[bottom + left] * (1.0 - rx.z) + table[bottom + right] * rx.z;
    return upper * (1.0 - ry.z) + lower * ry.z;
}

// Colour c's response at pixel p to drive v and its slope per code (linear between codes, clamped to the
// table).
fn respond(c: u32, p: u32, v: f32) -> vec2<f32> {
    let t = info[3u * c + 2u];
    let ry = axes[t.z + p / params.width];
    let rx = axes[t.w + p % params.width];
    let k = u32(clamp(floor(v), 0.0, 254.0));
    let a = curve_at(t, ry, rx, k);
    let b = curve_at(t, ry, rx, k + 1u);
    return vec2<f32>(a + (v - f32(k)) * (b - a), b - a);
}

// Element i of a [C, H, W] plane: its channel, its pixel's index, row and column, and the plane's size.
struct Pixel {
    c: u32,
    p: u32,
    y: i32,
    x: i32,
    h: i32,
    w: i32,
}

fn pixel_of(i: u32) -> Pixel {
    let c = i / params.hw;
    let p = i - c * params.hw;
    let w = params.width;
    return Pixel(c, p, i32(p / w), i32(p % w), i32(params.hw / w), i32(w));
}

// A colour's crosstalk kernel: its rows and columns, its offset into `weights` and its half sizes.
struct Kernel {
    rows: u32,
    cols: u32,
    offset: u32,
    half_rows: i32,
    half_cols: i32,
}

fn kernel_of(c: u32) -> Kernel {
    let k = info[3u * c];
    return Kernel(k.x, k.y, k.z, i32(k.x / 2u), i32(k.y / 2u));
}

@compute @workgroup_size(256)
fn model_phasor(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    if (i >= params.channels * params.hw) {
        return;
    }
    let at = pixel_of(i);
    let c = at.c;
    let k = kernel_of(c);
    var sum = 0.0;
    for (var a = 0u; a < k.rows; a = a + 1u) {
        let yy = u32(clamp(at.y + i32(a) - k.half_rows, 0, at.h - 1));
        for (var b = 0u; b < k.cols; b = b + 1u) {
            let xx = u32(clamp(at.x + i32(b) - k.half_cols, 0, at.w - 1));
            let v = drive_of(c * params.hw + yy * params.width + xx);
            sum = sum + weights[k.offset + a * k.cols + b] * v;
        }
    }
    let r = respond(c, at.p, sum);
    shown[i] = r;
    let z = bitcast<vec2<f32>>(info[3u * c + 1u].xy);
    unit[i] = cmul(source[i], vec2<f32>(cos(r.x), sin(r.x)) + z);
}

@compute @workgroup_size(256)
fn model_gradient(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    if (i >= params.channels * params.hw) {
        return;
    }
    let c = i / params.hw;
    let k = sums[c].z;
    let g = work[i] * (2.0 * k * k) - acc[i] * (2.0 * k);
    let r = shown[i];
    let m = cmul(source[i], vec2<f32>(cos(r.x), sin(r.x)));
    dphi[i] = (g.y * m.x - g.x * m.y) * r.y;
}

// The indices j in [0, n) with clamp(j + d, 0, n − 1) = q, as an inclusive range (empty when x > y).
fn preimage(q: i32, d: i32, n: i32) -> vec2<i32> {
    var lo = q - d;
    var hi = q - d;
    if (q == 0) {
        lo = 0;
    }
    if (q == n - 1) {
        hi = n - 1;
    }
    return vec2<i32>(max(lo, 0), min(hi, n - 1));
}

@compute @workgroup_size(256)
fn model_adam(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    if (i >= params.channels * params.hw) {
        return;
    }
    let at = pixel_of(i);
    let c = at.c;
    let k = kernel_of(c);
    var sum = 0.0;
    for (var a = 0u; a < k.rows; a = a + 1u) {
        let rows = preimage(at.y, i32(a) - k.half_rows, at.h);
        for (var b = 0u; b < k.cols; b = b + 1u) {
            let cols = preimage(at.x, i32(b) - k.half_cols, at.w);
            let kv = weights[k.offset + a * k.cols + b];
            for (var yy = rows.x; yy <= rows.y; yy = yy + 1) {
                for (var xx = cols.x; xx <= cols.y; xx = xx + 1) {
                    sum = sum + kv * dphi[c * params.hw + u32(yy) * params.width + u32(xx)];
                }
            }
        }
    }
    let grad = sum / SLOPE;
    let m = params.beta1 * mean[i] + (1.0 - params.beta1) * grad;
    let v = params.beta2 * square[i] + (1.0 - params.beta2) * grad * grad;
    mean[i] = m;
    square[i] = v;
    let next = phase[i] - params.step * (m / params.c1) / (sqrt(v / params.c2) + params.epsilon);
    phase[i] = clamp(next, 0.0, MAX_DRIVE);
}
