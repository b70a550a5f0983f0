// One layer of the TensorHolo residual CNN (training/tensorholo_training/model.py, ResidualCNN): a 3×3
// convolution with zero padding 1, bias, optional ReLU and optional residual add, in one pass:
//
//   out[o, y, x] = relu(bias[o] + Σ_c Σ_{dy,dx} w[o, c, dy, dx] · in_c(y + dy − 1, x + dx − 1)) + res[o, y, x]
//
// where in_c is channel c of the concatenation of two inputs (the last layer reads concat(s_{N−1}, x); other
// layers have c_b = 0), each input value is shifted by its buffer's offset (the hologram CNN centres its input
// by −0.5: in = x − 0.5 inside the frame, 0 in the padding), relu applies where `relu` = 1, and res is added
// where `residual` = 1 (the layer then writes s_{i+1} = y_i + s_{i−1} directly, so no separate add pass).
//
// One source, two precisions (GpuPrecision; src/gpu/shaders.rs prepends the line that picks one):
//   CONV3X3:     `alias act = f32;`                  hidden activations and products in f32;
//   CONV3X3_F16: `enable f16; alias act = f16;`      hidden activations stored as f16, products in f16, sums in
//                                                    f32 (needs the device's SHADER_F16).
// `act` is the type of the hidden activations s_1 … s_{N−1} and of the products. The network input x and the
// last layer's output stay f32 (they come from the CPU-packed input and go to the f32 heads).
//
// Bindings (group 0); which of the f32/act variants a layer reads and writes is set by its uniform:
//   0: uniform Layer { h, w, c_a, c_b, c_out, relu, residual, offset_a, offset_b, a_hidden, out_hidden }
//   1: storage read  in_x: array<f32>, [c_a, H, W] (layer 0, a_hidden = 0: the network input)
//   2: storage read  in_s: array<act>, [c_a, H, W] (later layers, a_hidden = 1: s_i)
//   3: storage read  in_b: array<f32>, [c_b, H, W] (the last layer's concat: the network input)
//   4: storage read  weights: array<f32>, [c_out, c_a + c_b, 3, 3] (as in the ONNX file)
//   5: storage read  bias: array<f32>, [c_out]
//   6: storage read  res: array<act>, [c_out, H, W] (s_{i−1} where residual = 1)
//   7: storage write out_s: array<act>, [c_out, H, W] (out_hidden = 1: s_{i+1})
//   8: storage write out_y: array<f32>, [c_out, H, W] (out_hidden = 0: the last layer)
// Unused bindings take any buffer that does not alias the layer's written one.
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
    a_hidden: u32,
    out_hidden: u32,
}

@group(0) @binding(0) var<uniform> layer: Layer;
@group(0) @binding(1) var<storage, read> in_x: array<f32>;
@group(0) @binding(2) var<storage, read> in_s: array<act>;
@group(0) @binding(3) var<storage, read> in_b: array<f32>;
@group(0) @binding(4) var<storage, read> weights: array<f32>;
@group(0) @binding(5) var<storage, read> bias: array<f32>;
@group(0) @binding(6) var<storage, read> res: array<act>;
@group(0) @binding(7) var<storage, read_write> out_s: array<act>;
@group(0) @binding(8) var<storage, read_write> out_y: array<f32>;

const TILE: u32 = 16u;
const HALO: u32 = 18u;

var<workgroup> tile: array<act, 324>;

// Input channel c at (y, x), shifted by its offset; 0 outside the frame (zero padding of the centred input).
fn load(c: u32, y: i32, x: i32) -> act {
    if (y < 0 || x < 0 || y >= i32(layer.h) || x >= i32(layer.w)) {
        return act(0.0);
    }
    let p = u32(y) * layer.w + u32(x);
    let n = layer.h * layer.w;
    if (c < layer.c_a) {
        if (layer.a_hidden == 1u) {
            return in_s[c * n + p] - act(layer.offset_a);
        }
        return act(in_x[c * n + p] - layer.offset_a);
    }
    return act(in_b[(c - layer.c_a) * n + p] - layer.offset_b);
}

fn weight(o: u32, c: u32, k: u32) -> act {
    if (o >= layer.c_out) {
        return act(0.0);
    }
    return act(weights[(o * (layer.c_a + layer.c_b) + c) * 9u + k]);
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
            let wv = vec4<act>(weight(o0, c, k), weight(o0 + 1u, c, k), weight(o0 + 2u, c, k),
                               weight(o0 + 3u, c, k));
            // Products in act, sums in f32.
            acc += vec4<f32>(v * wv);
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
                v += f32(res[o * n + p]);
            }
            if (layer.out_hidden == 1u) {
                out_s[o * n + p] = act(v);
            } else {
                out_y[o * n + p] = v;
            }
        }
    }
}
