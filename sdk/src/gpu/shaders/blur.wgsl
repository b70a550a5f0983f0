// The AA-DPM pre-filter (TensorHolo V1): a separable Gaussian blur of the complex field, edges clamped
// (encoding::double_phase::blur_separable), as two passes through a scratch buffer.
//
// Bindings (group 0):
//   0: uniform Blur { h, w, channels, taps (odd) }
//   1: storage read  src: array<vec2<f32>>, [C, H, W]
//   2: storage write dst: array<vec2<f32>>, [C, H, W]
//   3: storage read  kernel: array<f32>, [taps], normalised Gaussian weights computed on the CPU
// `blur_rows` (along x) field → scratch, then `blur_cols` (along y) scratch → field.
// Grid: C·H·W elements, 256 per workgroup, spread over x/y.

struct Blur {
    h: u32,
    w: u32,
    channels: u32,
    taps: u32,
}

@group(0) @binding(0) var<uniform> blur: Blur;
@group(0) @binding(1) var<storage, read> src: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> dst: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read> weights: array<f32>;

fn index_of(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 256u;
}

@compute @workgroup_size(256)
fn blur_rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = index_of(gid, groups);
    if (e >= blur.channels * blur.h * blur.w) {
        return;
    }
    let row = e - e % blur.w;
    let x = i32(e % blur.w);
    let r = i32(blur.taps / 2u);
    var acc = vec2<f32>(0.0, 0.0);
    for (var j = 0; j < i32(blur.taps); j++) {
        let xx = clamp(x + j - r, 0, i32(blur.w) - 1);
        acc += src[row + u32(xx)] * weights[j];
    }
    dst[e] = acc;
}

@compute @workgroup_size(256)
fn blur_cols(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = index_of(gid, groups);
    let plane = blur.h * blur.w;
    if (e >= blur.channels * plane) {
        return;
    }
    let c = e / plane;
    let y = i32((e % plane) / blur.w);
    let x = e % blur.w;
    let r = i32(blur.taps / 2u);
    var acc = vec2<f32>(0.0, 0.0);
    for (var j = 0; j < i32(blur.taps); j++) {
        let yy = clamp(y + j - r, 0, i32(blur.h) - 1);
        acc += src[c * plane + u32(yy) * blur.w + x] * weights[j];
    }
    dst[e] = acc;
}
