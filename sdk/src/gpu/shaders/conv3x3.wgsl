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
//   CONV3X3:     `alias act = f32;`                  hidden activations stored as f32;
//   CONV3X3_F16: `enable f16; alias act = f16;`      hidden activations stored as f16 (half the memory traffic
//                                                    and workgroup memory; needs the device's SHADER_F16).
// `act` is the type of the stored hidden activations s_1 … s_{N−1} and of the staged input tile. Products and
// sums are f32 in both. The network input x and the last layer's output stay f32 (they come from the CPU-packed
// input and go to the f32 heads).
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
// Tiling (register blocking, as a GEMM micro-kernel): a workgroup of 16×8 invocations computes a block of
// 8 rows × 64 columns of pixels for 8 output channels (grid: ceil(W/64), ceil(H/8), ceil(c_out/8)). Each
// invocation holds 4 adjacent pixels of one row × 8 output channels: 32 f32 sums in eight vec4 registers.
// The input channels go through in rounds of 4: the workgroup stages the 4 channels' 10×66 input tile (the
// block and its 1-pixel halo) and their 4 × 9 × 8 weights in workgroup memory, once per round. Per input
// channel an invocation then reads one 3×6 patch (18 values) and 18 vec4 weights (the same address for the
// whole workgroup: a broadcast) for 288 multiply-adds: 8 per value read from workgroup memory, against 1 read
// per multiply-add untiled, and two barriers per 4 channels. Channels past c_a + c_b and output channels past
// c_out are staged as zeros (the pre-filter's 6 input channels take two rounds). Workgroup memory: 11.7 KB
// with f32 tiles, 6.4 KB with f16, within WebGPU's 16 KB default.
//
// Why this shape: docs/GPU.md, "Speed" (nine shapes timed on an NVIDIA H200). The grid in src/gpu/cnn.rs
// (BLOCK_COLUMNS, BLOCK_ROWS, BLOCK_CHANNELS) follows WG_X·PX, WG_Y and OUT below.

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

const WG_X: u32 = 16u;
const WG_Y: u32 = 8u;
const PX: u32 = 4u; // pixels per invocation, adjacent in a row (the unrolled sums below hold 4)
const OUT: u32 = 8u; // output channels per workgroup (the unrolled sums below hold 8)
const ROUND: u32 = 4u; // input channels staged per round
const BLOCK_W: u32 = WG_X * PX;
const BLOCK_H: u32 = WG_Y;
const HALO_W: u32 = BLOCK_W + 2u;
const HALO_H: u32 = BLOCK_H + 2u;
const PLANE: u32 = HALO_W * HALO_H;

// [ROUND, HALO_H, HALO_W]: the round's input tiles.
var<workgroup> tile: array<act, ROUND * PLANE>;
// [ROUND, 9, 2]: the round's weights, output channels o0..o0+3 then o0+4..o0+7 per (channel, tap).
var<workgroup> wtile: array<vec4<f32>, ROUND * 18u>;

// Input channel c at (y, x), shifted by its offset; 0 outside the frame (zero padding of the centred input) and
// past the last channel (a round's padding).
fn load(c: u32, y: i32, x: i32) -> act {
    if (c >= layer.c_a + layer.c_b || y < 0 || x < 0 || y >= i32(layer.h) || x >= i32(layer.w)) {
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

// Weight of output channel o, input channel c, tap k (row-major 3×3); 0 past either's last channel.
fn weight(o: u32, c: u32, k: u32) -> f32 {
    let channels = layer.c_a + layer.c_b;
    if (o >= layer.c_out || c >= channels) {
        return 0.0;
    }
    return weights[(o * channels + c) * 9u + k];
}

// Bias, ReLU, residual add and store of output channels o0..o0+7 (`lo`, `hi`) at pixel (x, y).
fn finish(x: u32, y: u32, o0: u32, lo: vec4<f32>, hi: vec4<f32>) {
    if (x >= layer.w || y >= layer.h) {
        return;
    }
    let n = layer.h * layer.w;
    let p = y * layer.w + x;
    for (var j = 0u; j < OUT; j++) {
        let o = o0 + j;
        if (o >= layer.c_out) {
            return;
        }
        var v = select(hi[j & 3u], lo[j & 3u], j < 4u) + bias[o];
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

@compute @workgroup_size(WG_X, WG_Y)
fn conv3x3(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>,
           @builtin(local_invocation_index) li: u32) {
    let x0 = i32(wg.x * BLOCK_W) - 1;
    let y0 = i32(wg.y * BLOCK_H) - 1;
    let o0 = wg.z * OUT;
    let channels = layer.c_a + layer.c_b;
    // Sums: a_p for output channels o0..o0+3 at pixel p of the invocation, b_p for o0+4..o0+7.
    var a0 = vec4<f32>(0.0);
    var a1 = vec4<f32>(0.0);
    var a2 = vec4<f32>(0.0);
    var a3 = vec4<f32>(0.0);
    var b0 = vec4<f32>(0.0);
    var b1 = vec4<f32>(0.0);
    var b2 = vec4<f32>(0.0);
    var b3 = vec4<f32>(0.0);
    for (var c0 = 0u; c0 < channels; c0 += ROUND) {
        // Stage the round: ROUND · PLANE input values and ROUND · 18 weight vectors.
        for (var t = li; t < ROUND * PLANE; t += WG_X * WG_Y) {
            let r = t % PLANE;
            tile[t] = load(c0 + t / PLANE, y0 + i32(r / HALO_W), x0 + i32(r % HALO_W));
        }
        for (var t = li; t < ROUND * 18u; t += WG_X * WG_Y) {
            let c = c0 + t / 18u;
            let k = (t % 18u) / 2u;
            let o = o0 + 4u * (t % 2u);
            wtile[t] = vec4<f32>(weight(o, c, k), weight(o + 1u, c, k), weight(o + 2u, c, k),
                                 weight(o + 3u, c, k));
        }
        workgroupBarrier();
        for (var cc = 0u; cc < ROUND; cc++) {
            for (var dy = 0u; dy < 3u; dy++) {
                let at = cc * PLANE + (lid.y + dy) * HALO_W + lid.x * PX;
                let i0 = f32(tile[at]);
                let i1 = f32(tile[at + 1u]);
                let i2 = f32(tile[at + 2u]);
                let i3 = f32(tile[at + 3u]);
                let i4 = f32(tile[at + 4u]);
                let i5 = f32(tile[at + 5u]);
                let wk = (cc * 9u + dy * 3u) * 2u;
                var lo = wtile[wk];
                var hi = wtile[wk + 1u];
                a0 += i0 * lo;
                b0 += i0 * hi;
                a1 += i1 * lo;
                b1 += i1 * hi;
                a2 += i2 * lo;
                b2 += i2 * hi;
                a3 += i3 * lo;
                b3 += i3 * hi;
                lo = wtile[wk + 2u];
                hi = wtile[wk + 3u];
                a0 += i1 * lo;
                b0 += i1 * hi;
                a1 += i2 * lo;
                b1 += i2 * hi;
                a2 += i3 * lo;
                b2 += i3 * hi;
                a3 += i4 * lo;
                b3 += i4 * hi;
                lo = wtile[wk + 4u];
                hi = wtile[wk + 5u];
                a0 += i2 * lo;
                b0 += i2 * hi;
                a1 += i3 * lo;
                b1 += i3 * hi;
                a2 += i4 * lo;
                b2 += i4 * hi;
                a3 += i5 * lo;
                b3 += i5 * hi;
            }
        }
        workgroupBarrier();
    }
    let x = wg.x * BLOCK_W + lid.x * PX;
    let y = wg.y * BLOCK_H + lid.y;
    finish(x, y, o0, a0, b0);
    finish(x + 1u, y, o0, a1, b1);
    finish(x + 2u, y, o0, a2, b2);
    finish(x + 3u, y, o0, a3, b3);
}
