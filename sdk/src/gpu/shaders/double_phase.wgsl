// Double phase encoding (paper Eq. 7; encoding::double_phase) and the linear look-up table, in three kernels
// with no CPU round trip:
//   `analyse`  pass 1: φ = arg H into `phase`, and per workgroup the partial max |H|² and Σφ of its channel;
//   `finish`   the global normaliser a = √(max over colours of max |H|²) and each channel's mean phase Σφ/N,
//              into `stats`;
//   `encode`   pass 2: P = φ − mean ± acos(min(|H|/a, 1)), + where x + y is even, wrapped to [0, 2π), into
//              `phase`, and the 8-bit codes round(P·256/2π) mod 256 (LinearLut), four per u32.
//
// Bindings (group 0), for every entry point:
//   0: uniform Dims { h, w, channels (3), groups_per_channel (G) }
//   1: storage read  field: array<vec2<f32>>, [C, H, W]
//   2: storage       phase: array<f32>, [C, H, W] (radians)
//   3: storage       partials: array<vec2<f32>>, [C, G] (max |H|², Σφ) per workgroup of `analyse`
//   4: storage       stats: array<f32, 8> = [a, mean_r, mean_g, mean_b, max_sq_r, max_sq_g, max_sq_b, invalid]
//                    (invalid = 1 when a is 0 or not finite: a hologram that is zero everywhere)
//   5: storage       codes: array<u32>, ceil(C·H·W / 4) words, code of element e in byte e % 4 of word e / 4
//   6: storage read  fixed: array<f32>, 4: a normaliser given from outside (fixed[0] > 0: a foveated frame's,
//                    foveation::FOVEATED_NORMALISER_GAIN · max A) used instead of the field's own; 0: the
//                    field's own. `invalid` always follows the field's own.
// Grids: `analyse` (G, C) workgroups of 256, each looping over its channel with stride 256·G; `finish` one
// workgroup of 256; `encode` ceil(C·H·W / 4) invocations (256 per workgroup, spread over x/y).

struct Dims {
    h: u32,
    w: u32,
    channels: u32,
    groups_per_channel: u32,
}

@group(0) @binding(0) var<uniform> dims: Dims;
@group(0) @binding(1) var<storage, read> field: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> phase: array<f32>;
@group(0) @binding(3) var<storage, read_write> partials: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read_write> stats: array<f32, 8>;
@group(0) @binding(5) var<storage, read_write> codes: array<u32>;
@group(0) @binding(6) var<storage, read> fixed: array<f32>;

const TAU: f32 = 6.283185307179586;

var<workgroup> red_max: array<f32, 256>;
var<workgroup> red_sum: array<f32, 256>;

// Tree reduction of red_max/red_sum over the workgroup; the result lands in element 0.
fn reduce(lid: u32) {
    for (var s = 128u; s > 0u; s = s >> 1u) {
        workgroupBarrier();
        if (lid < s) {
            red_max[lid] = max(red_max[lid], red_max[lid + s]);
            red_sum[lid] = red_sum[lid] + red_sum[lid + s];
        }
    }
    workgroupBarrier();
}

@compute @workgroup_size(256)
fn analyse(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>) {
    let lid = lid3.x;
    let c = wg.y;
    let n = dims.h * dims.w;
    let stride = 256u * dims.groups_per_channel;
    var m = 0.0;
    var s = 0.0;
    for (var i = wg.x * 256u + lid; i < n; i += stride) {
        let v = field[c * n + i];
        let p = atan2(v.y, v.x);
        phase[c * n + i] = p;
        m = max(m, dot(v, v));
        s += p;
    }
    red_max[lid] = m;
    red_sum[lid] = s;
    reduce(lid);
    if (lid == 0u) {
        partials[c * dims.groups_per_channel + wg.x] = vec2<f32>(red_max[0], red_sum[0]);
    }
}

@compute @workgroup_size(256)
fn finish(@builtin(local_invocation_id) lid3: vec3<u32>) {
    let lid = lid3.x;
    let g = dims.groups_per_channel;
    var a_sq = 0.0;
    for (var c = 0u; c < dims.channels; c++) {
        var m = 0.0;
        var s = 0.0;
        for (var j = lid; j < g; j += 256u) {
            let p = partials[c * g + j];
            m = max(m, p.x);
            s += p.y;
        }
        red_max[lid] = m;
        red_sum[lid] = s;
        reduce(lid);
        if (lid == 0u) {
            stats[1u + c] = red_sum[0] / f32(dims.h * dims.w);
            stats[4u + c] = red_max[0];
        }
        a_sq = max(a_sq, red_max[0]);
        workgroupBarrier();
    }
    if (lid == 0u) {
        let own = sqrt(a_sq);
        stats[0] = select(own, fixed[0], fixed[0] > 0.0);
        // own > 0 is false for 0 and NaN; own − own ≠ 0 for ±∞.
        stats[7] = select(1.0, 0.0, own > 0.0 && (own - own) == 0.0);
    }
}

// The wrapped double phase value of element e (channel c, pixel i) and its 8-bit code.
fn encode_one(e: u32, inv_a: f32) -> u32 {
    let n = dims.h * dims.w;
    let c = e / n;
    let i = e % n;
    let y = i / dims.w;
    let x = i % dims.w;
    let v = field[e];
    let theta = acos(min(length(v) * inv_a, 1.0));
    var value = phase[e] - stats[1u + c];
    if (((x + y) & 1u) == 1u) {
        value -= theta;
    } else {
        value += theta;
    }
    var wrapped = value - TAU * floor(value / TAU);
    if (wrapped >= TAU || wrapped < 0.0) {
        wrapped = 0.0;
    }
    phase[e] = wrapped;
    // floor(x + 0.5): half away from zero for x ≥ 0, as Rust's f32::round on the CPU (WGSL's round() rounds
    // half to even).
    return u32(floor(wrapped * (256.0 / TAU) + 0.5)) % 256u;
}

@compute @workgroup_size(256)
fn encode(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let word = gid.x + gid.y * groups.x * 256u;
    let total = dims.channels * dims.h * dims.w;
    if (word * 4u >= total) {
        return;
    }
    let inv_a = 1.0 / stats[0];
    var packed = 0u;
    for (var k = 0u; k < 4u; k++) {
        let e = word * 4u + k;
        if (e < total) {
            packed = packed | (encode_one(e, inv_a) << (8u * k));
        }
    }
    codes[word] = packed;
}
