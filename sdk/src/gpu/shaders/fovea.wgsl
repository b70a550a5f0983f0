// A foveated frame's midpoint hologram (docs/FOVEATION.md; the CPU's foveation::Periphery::compose): the
// hologram CNN's heads on the tile within R of the gaze, the colour image blurred per pixel by its defocus at
// the band's phase beyond R + B, their linear blend between. Three kernels, no CPU round trip:
//   `band_sum`    per workgroup, the partial Σ U_cnn·A over the band's pixels (R < r < R + B) of the tile, per
//                 colour: (Σ A_cnn·A·cos φ, Σ A_cnn·A·sin φ), φ = (p − 0.5)·2π, A the image's amplitude;
//   `band_phase`  θ_c = atan2 of the partials' sum (0 where it vanishes), into `theta`;
//   `compose`     the heads [6, H, W] of the foveated field.
//
// The blur of a pixel at normalised depth d: half-width h = clamp(|d − d_g|·s_c − 1/2, 0, max_hw) with
// s_c = blur_px_c·√π/2 (the square of a disc's area, radius blur_px_c·|d − d_g|), the mean of the image over
// the squares of half-widths ⌊h⌋ and ⌊h⌋ + 1, each clipped to the frame, weighted by the fraction of h: the
// CPU's formula, summed directly over the boxes (the larger at most (2·max_hw + 1)² values).
//
// Bindings (group 0):
//   0: uniform Fovea (below); gaze = (gx + gx_frac, gy + gy_frac) pixels, gx = ⌊gaze x⌋
//   1: storage read  tile: array<f32>, [6, th, tw]: the tile CNN's heads (amplitude R, G, B, phase R, G, B)
//   2: storage read  image: array<f32>, [4, H, W]: the amplitude R, G, B (after intensity maps), the depth
//   3: storage       partials: array<vec2<f32>>, [3, groups] (`band_sum`, `band_phase`)
//   4: storage       theta: array<f32>, 4: θ R, G, B (radians), unused
//   5: storage       heads: array<f32>, [6, H, W]: the foveated field's heads (`compose`)
// Grids: `band_sum` (groups, 3) workgroups of 256, each looping over the tile with stride 256·groups;
// `band_phase` one workgroup of 256; `compose` 3·H·W invocations (256 per workgroup, spread over x/y).

struct Fovea {
    h: u32,
    w: u32,
    th: u32,
    tw: u32,
    oy: u32,
    ox: u32,
    groups: u32,
    max_hw: f32,
    gx: f32,
    gy: f32,
    gx_frac: f32,
    gy_frac: f32,
    r_in: f32,
    band: f32,
    gaze_depth: f32,
    scale_r: f32,
    scale_g: f32,
    scale_b: f32,
}

@group(0) @binding(0) var<uniform> fov: Fovea;
@group(0) @binding(1) var<storage, read> tile: array<f32>;
@group(0) @binding(2) var<storage, read> image: array<f32>;
@group(0) @binding(3) var<storage, read_write> partials: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read_write> theta: array<f32>;
@group(0) @binding(5) var<storage, read_write> heads: array<f32>;

const TAU: f32 = 6.283185307179586;

var<workgroup> red: array<vec2<f32>, 256>;

fn reduce(lid: u32) {
    for (var s = 128u; s > 0u; s = s >> 1u) {
        workgroupBarrier();
        if (lid < s) {
            red[lid] = red[lid] + red[lid + s];
        }
    }
    workgroupBarrier();
}

// The squared distance of frame pixel (y, x) from the gaze.
fn dist2(y: u32, x: u32) -> f32 {
    let dx = (f32(x) - fov.gx) - fov.gx_frac;
    let dy = (f32(y) - fov.gy) - fov.gy_frac;
    return dx * dx + dy * dy;
}

@compute @workgroup_size(256)
fn band_sum(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>) {
    let lid = lid3.x;
    let c = wg.y;
    let m = fov.th * fov.tw;
    let n = fov.h * fov.w;
    let r_out = fov.r_in + fov.band;
    let r_in2 = fov.r_in * fov.r_in;
    let r_out2 = r_out * r_out;
    var acc = vec2<f32>(0.0, 0.0);
    for (var i = wg.x * 256u + lid; i < m; i += 256u * fov.groups) {
        let y = fov.oy + i / fov.tw;
        let x = fov.ox + i % fov.tw;
        let r2 = dist2(y, x);
        if (r2 > r_in2 && r2 < r_out2) {
            let a = tile[c * m + i] * image[c * n + y * fov.w + x];
            let phi = (tile[(3u + c) * m + i] - 0.5) * TAU;
            acc += a * vec2<f32>(cos(phi), sin(phi));
        }
    }
    red[lid] = acc;
    reduce(lid);
    if (lid == 0u) {
        partials[c * fov.groups + wg.x] = red[0];
    }
}

@compute @workgroup_size(256)
fn band_phase(@builtin(local_invocation_id) lid3: vec3<u32>) {
    let lid = lid3.x;
    for (var c = 0u; c < 3u; c++) {
        var acc = vec2<f32>(0.0, 0.0);
        for (var j = lid; j < fov.groups; j += 256u) {
            acc += partials[c * fov.groups + j];
        }
        red[lid] = acc;
        reduce(lid);
        if (lid == 0u) {
            let s = red[0];
            theta[c] = select(atan2(s.y, s.x), 0.0, s.x == 0.0 && s.y == 0.0);
        }
        workgroupBarrier();
    }
}

// The mean of colour c's image over the square of half-width k around (y, x), clipped to the frame.
fn box_mean(c: u32, y: i32, x: i32, k: i32) -> f32 {
    let r0 = max(y - k, 0);
    let r1 = min(y + k, i32(fov.h) - 1);
    let c0 = max(x - k, 0);
    let c1 = min(x + k, i32(fov.w) - 1);
    let base = c * fov.h * fov.w;
    var sum = 0.0;
    for (var yy = r0; yy <= r1; yy++) {
        let row = base + u32(yy) * fov.w;
        var rs = 0.0;
        for (var xx = c0; xx <= c1; xx++) {
            rs += image[row + u32(xx)];
        }
        sum += rs;
    }
    return sum / f32((r1 - r0 + 1) * (c1 - c0 + 1));
}

// The blurred amplitude of colour c at (y, x), depth d.
fn blurred(c: u32, y: u32, x: u32, d: f32) -> f32 {
    var s = fov.scale_r;
    if (c == 1u) {
        s = fov.scale_g;
    } else if (c == 2u) {
        s = fov.scale_b;
    }
    let hw = clamp(abs(d - fov.gaze_depth) * s - 0.5, 0.0, fov.max_hw);
    let kf = floor(hw);
    let t = hw - kf;
    let k = i32(kf);
    let m = box_mean(c, i32(y), i32(x), k);
    if (t > 0.0) {
        return m + t * (box_mean(c, i32(y), i32(x), k + 1) - m);
    }
    return m;
}

@compute @workgroup_size(256)
fn compose(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = gid.x + gid.y * groups.x * 256u;
    let n = fov.h * fov.w;
    if (e >= 3u * n) {
        return;
    }
    let c = e / n;
    let i = e % n;
    let y = i / fov.w;
    let x = i % fov.w;
    let r2 = dist2(y, x);
    let r_out = fov.r_in + fov.band;
    let m = fov.th * fov.tw;
    // The tile's pixel (clamped: the geometry keeps every pixel within R + B inside the tile).
    let ty = min(y - min(y, fov.oy), fov.th - 1u);
    let tx = min(x - min(x, fov.ox), fov.tw - 1u);
    let t = ty * fov.tw + tx;
    if (r2 <= fov.r_in * fov.r_in) {
        heads[e] = tile[c * m + t];
        heads[(3u + c) * n + i] = tile[(3u + c) * m + t];
        return;
    }
    let b = blurred(c, y, x, image[3u * n + i]);
    let th = theta[c];
    if (r2 >= r_out * r_out) {
        heads[e] = b;
        heads[(3u + c) * n + i] = th / TAU + 0.5;
        return;
    }
    let wgt = (r_out - sqrt(r2)) / fov.band;
    let phi = (tile[(3u + c) * m + t] - 0.5) * TAU;
    let v = wgt * tile[c * m + t] * vec2<f32>(cos(phi), sin(phi))
        + (1.0 - wgt) * b * vec2<f32>(cos(th), sin(th));
    heads[e] = length(v);
    heads[(3u + c) * n + i] = atan2(v.y, v.x) / TAU + 0.5;
}
