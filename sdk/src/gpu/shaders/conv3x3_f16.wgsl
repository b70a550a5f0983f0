// conv3x3.wgsl with the CNN's hidden activations stored as f16 and the products taken in f16, accumulated in
// f32 (GpuPrecision::F16; needs the device's SHADER_F16). The network input and the last layer's output stay
// f32 (they come from and go to the CPU-packed input and the f32 heads). Same formula, tiling and grid as
// conv3x3.wgsl:
//
//   out[o, y, x] = act(bias[o] + Σ_c Σ_{dy,dx} w[o, c, dy, dx] · in_c(y + dy − 1, x + dx − 1)) + res[o, y, x]
//
// Bindings (group 0); which of the f32/f16 variants a layer reads and writes is set by its uniform:
//   0: uniform Layer { h, w, c_a, c_b, c_out, relu, residual, offset_a, offset_b, a_is_f16, out_is_f16 }
//   1: storage read  in_a32: array<f32>, [c_a, H, W] (layer 0: the network input)
//   2: storage read  in_a16: array<f16>, [c_a, H, W] (hidden layers: s_i)
//   3: storage read  in_b32: array<f32>, [c_b, H, W] (the last layer's concat: the network input)
//   4: storage read  weights: array<f32>, [c_out, c_a + c_b, 3, 3]
//   5: storage read  bias: array<f32>, [c_out]
//   6: storage read  res16: array<f16>, [c_out, H, W] (s_{i−1} where residual = 1)
//   7: storage write out16: array<f16>, [c_out, H, W] (hidden layers)
//   8: storage write out32: array<f32>, [c_out, H, W] (the last layer)
// Unused bindings take any buffer. Grid: ceil(W/16), ceil(H/16), ceil(c_out/4); workgroup 16×16.

enable f16;

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
    a_is_f16: u32,
    out_is_f16: u32,
}

@group(0) @binding(0) var<uniform> layer: Layer;
@group(0) @binding(1) var<storage, read> in_a32: array<f32>;
@group(0) @binding(2) var<storage, read> in_a16: array<f16>;
@group(0) @binding(3) var<storage, read> in_b32: array<f32>;
@group(0) @binding(4) var<storage, read> weights: array<f32>;
@group(0) @binding(5) var<storage, read> bias: array<f32>;
@group(0) @binding(6) var<storage, read> res16: array<f16>;
@group(0) @binding(7) var<storage, read_write> out16: array<f16>;
@group(0) @binding(8) var<storage, read_write> out32: array<f32>;

const TILE: u32 = 16u;
const HALO: u32 = 18u;

var<workgroup> tile: array<f16, 324>;

fn load(c: u32, y: i32, x: i32) -> f16 {
    if (y < 0 || x < 0 || y >= i32(layer.h) || x >= i32(layer.w)) {
        return 0.0h;
    }
    let p = u32(y) * layer.w + u32(x);
    let n = layer.h * layer.w;
    if (c < layer.c_a) {
        if (layer.a_is_f16 == 1u) {
            return in_a16[c * n + p] - f16(layer.offset_a);
        }
        return f16(in_a32[c * n + p] - layer.offset_a);
    }
    return f16(in_b32[(c - layer.c_a) * n + p] - layer.offset_b);
}

fn weight(o: u32, c: u32, k: u32) -> f16 {
    if (o >= layer.c_out) {
        return 0.0h;
    }
    return f16(weights[(o * (layer.c_a + layer.c_b) + c) * 9u + k]);
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
        for (var t = li; t < HALO * HALO; t += 256u) {
            tile[t] = load(c, y0 + i32(t / HALO), x0 + i32(t % HALO));
        }
        workgroupBarrier();
        for (var k = 0u; k < 9u; k++) {
            let v = tile[(lid.y + k / 3u) * HALO + lid.x + k % 3u];
            let wv = vec4<f16>(weight(o0, c, k), weight(o0 + 1u, c, k), weight(o0 + 2u, c, k),
                               weight(o0 + 3u, c, k));
            // f16 products, f32 sums.
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
                v += f32(res16[o * n + p]);
            }
            if (layer.out_is_f16 == 1u) {
                out16[o * n + p] = f16(v);
            } else {
                out32[o * n + p] = v;
            }
        }
    }
}
