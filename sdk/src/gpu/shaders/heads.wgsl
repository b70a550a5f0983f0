// The CNNs' output stages after the last convolution (training/tensorholo_training/model.py).
//
// `hologram_heads` — the hologram CNN's heads, in place on the last layer's raw output [6, H, W]:
//   amplitude (channels 0–2) = (tanh(o) + 1)·amp_scale (√2/2: amplitude in [0, √2]),
//   phase (channels 3–5) = (tanh(o) + 1)·phase_scale (1/2: phase in [0, 1], meaning (p − 0.5)·2π rad);
//   the scales are read from the ONNX graph and passed in.
//   0: uniform Heads { h, w, channels (6), taps (unused), amp_scale, phase_scale }
//   1: storage raw: array<f32>, [6, H, W], overwritten with [amplitude, phase]
//   Grid: 6·H·W elements (256 per workgroup, spread over x/y).
//
// `prefilter_base` — the DDPM pre-filter's fixed base filter added to the CNN's raw output:
//   out[c, y, x] = raw[c, y, x] + Σ_{dy,dx} base[c, dy, dx] · x[c, clamp(y + dy − r), clamp(x + dx − r)]
//   (a depthwise taps×taps convolution of the edge-replicated input: the AA-DPM blur; taps = 1 with weight 1 is
//   the identity base).
//   0: uniform Heads { h, w, channels (6), taps }
//   1: storage raw: array<f32>, [6, H, W], overwritten with the filtered field [Re R, G, B, Im R, G, B]
//   2: storage read input: array<f32>, [6, H, W], the pre-filter's input
//   3: storage read base: array<f32>, [6, taps, taps]
//   Grid: 6·H·W elements.

struct Heads {
    h: u32,
    w: u32,
    channels: u32,
    taps: u32,
    amp_scale: f32,
    phase_scale: f32,
}

@group(0) @binding(0) var<uniform> heads: Heads;
@group(0) @binding(1) var<storage, read_write> raw: array<f32>;
@group(0) @binding(2) var<storage, read> base_input: array<f32>;
@group(0) @binding(3) var<storage, read> base: array<f32>;

fn index_of(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 256u;
}

@compute @workgroup_size(256)
fn hologram_heads(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = index_of(gid, groups);
    let n = heads.h * heads.w;
    if (e >= heads.channels * n) {
        return;
    }
    let half = heads.channels / 2u;
    let scale = select(heads.phase_scale, heads.amp_scale, e / n < half);
    raw[e] = (tanh(raw[e]) + 1.0) * scale;
}

@compute @workgroup_size(256)
fn prefilter_base(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = index_of(gid, groups);
    let n = heads.h * heads.w;
    if (e >= heads.channels * n) {
        return;
    }
    let c = e / n;
    let y = i32((e % n) / heads.w);
    let x = i32(e % heads.w);
    let r = i32(heads.taps / 2u);
    var acc = 0.0;
    for (var dy = 0; dy < i32(heads.taps); dy++) {
        let yy = clamp(y + dy - r, 0, i32(heads.h) - 1);
        for (var dx = 0; dx < i32(heads.taps); dx++) {
            let xx = clamp(x + dx - r, 0, i32(heads.w) - 1);
            acc += base[(c * heads.taps + u32(dy)) * heads.taps + u32(dx)] * base_input[c * n + u32(yy) * heads.w + u32(xx)];
        }
    }
    raw[e] = raw[e] + acc;
}
