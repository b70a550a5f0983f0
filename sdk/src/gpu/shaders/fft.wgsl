// Batched 1D FFT along the rows of complex buffers (Stockham auto-sort, mixed radix), and the transpose that
// turns columns into rows. A 2D transform is rows → transpose → rows, leaving the spectrum transposed
// `[C, W, H]`, the layout of the CPU path's spectral multipliers (optics::propagation::SpectralPlan).
//
// `stockham_pass` — one radix-R pass of a length-N FFT on every row:
//   0: uniform Pass { n, rows, ns (product of the radices of the earlier passes), radix (2..16),
//                     twiddle_stride (= n / (ns·radix)), sign (−1 forward, +1 inverse) }
//   1: storage read  src: array<vec2<f32>>, [rows, n] (re, im)
//   2: storage write dst: array<vec2<f32>>, [rows, n]
//   3: storage read  twiddles: array<vec2<f32>>, [n]: exp(−2πi·m/n), computed on the CPU in f64
//   Grid: x over the n / radix butterflies (64 per workgroup), y over rows (≤ 65 535).
//   After the passes of radices R_1 … R_k (Π R_i = n) the row holds its DFT, unnormalised, in natural order.
//
// `transpose` — [planes, rows, cols] → [planes, cols, rows] through a 16×16 tile in workgroup memory:
//   0: uniform Shape { rows, cols, planes }
//   1: storage read  src: array<vec2<f32>>, [planes, rows, cols]
//   2: storage write dst: array<vec2<f32>>, [planes, cols, rows]
//   Grid: (ceil(cols / 16), ceil(rows / 16), planes), workgroup 16×16.

struct Pass {
    n: u32,
    rows: u32,
    ns: u32,
    radix: u32,
    twiddle_stride: u32,
    sign: f32,
}

@group(0) @binding(0) var<uniform> pass_: Pass;
@group(0) @binding(1) var<storage, read> src: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> dst: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read> twiddles: array<vec2<f32>>;

const MAX_RADIX: u32 = 16u;
const TAU: f32 = 6.283185307179586;

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// exp(sign·2πi·m/n) from the forward table exp(−2πi·m/n): the inverse takes its conjugate.
fn twiddle(m: u32) -> vec2<f32> {
    let w = twiddles[m % pass_.n];
    return vec2<f32>(w.x, -pass_.sign * w.y);
}

@compute @workgroup_size(64)
fn stockham_pass(@builtin(global_invocation_id) gid: vec3<u32>) {
    let r = pass_.radix;
    let butterflies = pass_.n / r;
    let j = gid.x;
    let row = gid.y;
    if (j >= butterflies || row >= pass_.rows) {
        return;
    }
    let base = row * pass_.n;
    let k = j % pass_.ns;
    // Gather the R inputs j + p·n/R, each multiplied by its twiddle exp(∓2πi·k·p / (ns·R)).
    var v: array<vec2<f32>, MAX_RADIX>;
    for (var p = 0u; p < r; p++) {
        let x = src[base + j + p * butterflies];
        v[p] = cmul(x, twiddle(k * p * pass_.twiddle_stride));
    }
    // A direct DFT of length R (R ≤ 16): out[q] = Σ_p v[p]·exp(∓2πi·p·q/R), the R-th roots taken from the
    // same table (index p·q·(n/R) mod n).
    let out0 = (j / pass_.ns) * pass_.ns * r + k;
    for (var q = 0u; q < r; q++) {
        var acc = vec2<f32>(0.0, 0.0);
        for (var p = 0u; p < r; p++) {
            acc += cmul(v[p], twiddle(((p * q) % r) * butterflies));
        }
        dst[base + out0 + q * pass_.ns] = acc;
    }
}

struct Shape {
    rows: u32,
    cols: u32,
    planes: u32,
}

@group(0) @binding(0) var<uniform> shape: Shape;
@group(0) @binding(1) var<storage, read> t_src: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> t_dst: array<vec2<f32>>;

// 16 × 17: the extra column keeps the column reads free of bank conflicts.
var<workgroup> tile: array<vec2<f32>, 272>;

@compute @workgroup_size(16, 16)
fn transpose(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let plane = wg.z * shape.rows * shape.cols;
    // Read a 16×16 block of rows [16·wg.y, +16) × cols [16·wg.x, +16), coalesced along the row.
    let x = wg.x * 16u + lid.x;
    let y = wg.y * 16u + lid.y;
    if (x < shape.cols && y < shape.rows) {
        tile[lid.y * 17u + lid.x] = t_src[plane + y * shape.cols + x];
    }
    workgroupBarrier();
    // Write it transposed: output row = input column, coalesced along the output row.
    let ox = wg.y * 16u + lid.x;
    let oy = wg.x * 16u + lid.y;
    if (ox < shape.rows && oy < shape.cols) {
        t_dst[plane + oy * shape.rows + ox] = tile[lid.x * 17u + lid.y];
    }
}
