// One layer of the TensorHolo residual CNN (training/tensorholo_training/model.py, ResidualCNN): a 3×3
// convolution with zero padding 1, bias, optional ReLU and optional residual add, in one pass:
//
//   out[o, y, x] = act(bias[o] + Σ_c Σ_{dy,dx} w[o, c, dy, dx] · in_c(y + dy − 1, x + dx − 1)) + res[o, y, x]
//
// where in_c is channel c of the concatenation of two inputs (the last layer reads concat(s_{N−1}, x); other
// layers have c_b = 0), each input value is shifted by its buffer's offset (the hologram CNN centres its input
// by −0.5: in = x − 0.5 inside the frame, 0 in the padding), act is ReLU where `relu` = 1, and res is added
// where `residual` = 1 (the layer then writes s_{i+1} = y_i + s_{i−1} directly, so no separate add pass).
//
// Bindings (group 0):
//   0: uniform Layer { h, w, c_a, c_b, c_out, relu, residual, offset_a, offset_b }
//   1: storage read  in_a: array<f32>, [c_a, H, W]
//   2: storage read  in_b: array<f32>, [c_b, H, W] (any buffer when c_b = 0)
//   3: storage read  weights: array<f32>, [c_out, c_a + c_b, 3, 3] (as in the ONNX file)
//   4: storage read  bias: array<f32>, [c_out]
//   5: storage read  res: array<f32>, [c_out, H, W] (any buffer when residual = 0)
//   6: storage write out: array<f32>, [c_out, H, W]
//
// Tiling: a workgroup is a 16×16 block of pixels and a block of 4 output channels (grid: ceil(W/16),
// ceil(H/16), ceil(c_out/4)). For each input channel the workgroup stages the 18×18 input tile (the block and
// its 1-pixel halo) in workgroup memory, once, and every invocation reuses each staged value for 9 taps × 4
// output channels (vec4 accumulator): 36 multiply-adds per value read from memory instead of 1.

struct Layer {
    h: u32,
    w: u32,
    c_a: u32,
    c_b: u32,
    c_out: u32,
    relu: u32,
    residual: u32,
    offset_a: f32,
    offset_b: f32,
}

@group(0) @binding(0) var<uniform> layer: Layer;
@group(0) @binding(1) var<storage, read> in_a: array<f32>;
@group(0) @binding(2) var<storage, read> in_b: array<f32>;
@group(0) @binding(3) var<storage, read> weights: array<f32>;
@group(0) @binding(4) var<storage, read> bias: array<f32>;
@group(0) @binding(5) var<storage, read> res: array<f32>;
@group(0) @binding(6) var<storage, read_write> out: array<f32>;

const TILE: u32 = 16u;
const HALO: u32 = 18u;

var<workgroup> tile: array<f32, 324>;

// Input channel c at (y, x), shifted by its offset; 0 outside the frame (zero padding of the centred input).
fn load(c: u32, y: i32, x: i32) -> f32 {
    if (y < 0 || x < 0 || y >= i32(layer.h) || x >= i32(layer.w)) {
        return 0.0;
    }
    let p = u32(y) * layer.w + u32(x);
    let n = layer.h * layer.w;
    if (c < layer.c_a) {
        return in_a[c * n + p] - layer.offset_a;
    }
    return in_b[(c - layer.c_a) * n + p] - layer.offset_b;
}

fn weight(o: u32, c: u32, k: u32) -> f32 {
    if (o >= layer.c_out) {
        return 0.0;
    }
    return weights[(o * (layer.c_a + layer.c_b) + c) * 9u + k];
}

@compute @workgroup_size(16, 16)
fn conv3x3(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>,
           @builtin(local_invocation_index) li: u32) {
    let x0 = i32(wg.x * TILE) - 1;
    let y0 = i32(wg.y * TILE) - 1;
    let o0 = wg.z * 4u;
    let channels = layer.c_a + layer.c_b;
    var acc = vec4<f32>(0.0);
    for (var c = 0u; c < channels; c++) {
        // Stage the 18×18 tile of channel c (324 values, 256 invocations: two rounds).
        for (var t = li; t < HALO * HALO; t += 256u) {
            tile[t] = load(c, y0 + i32(t / HALO), x0 + i32(t % HALO));
        }
        workgroupBarrier();
        for (var k = 0u; k < 9u; k++) {
            let v = tile[(lid.y + k / 3u) * HALO + lid.x + k % 3u];
            let wv = vec4<f32>(weight(o0, c, k), weight(o0 + 1u, c, k), weight(o0 + 2u, c, k),
                               weight(o0 + 3u, c, k));
            acc += v * wv;
        }
        workgroupBarrier();
    }
    let x = wg.x * TILE + lid.x;
    let y = wg.y * TILE + lid.y;
    if (x >= layer.w || y >= layer.h) {
        return;
    }
    let n = layer.h * layer.w;
    let p = y * layer.w + x;
    for (var j = 0u; j < 4u; j++) {
        let o = o0 + j;
        if (o < layer.c_out) {
            var v = acc[j] + bias[o];
            if (layer.relu == 1u) {
                v = max(v, 0.0);
            }
            if (layer.residual == 1u) {
                v += res[o * n + p];
            }
            out[o * n + p] = v;
        }
    }
}
