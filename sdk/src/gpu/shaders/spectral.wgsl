// The element-wise steps around the FFTs of a spectral operation (optics::propagation::SpectralPlan::apply):
// embedding a field in the (zero-padded) computational grid, cropping it back, and multiplying a spectrum by a
// multiplier (transfer function, Fourier filter) with the inverse-FFT normalisation folded in.
//
// `embed` / `crop` — field [C, H, W] ↔ work [C, Hc, Wc], the field at offset ((Hc − H)/2, (Wc − W)/2),
// zeros around it (embed writes every work element):
//   0: uniform Grid { h, w, hc, wc, oy, ox, channels }
//   1: storage field: array<vec2<f32>>, [C, H, W]
//   2: storage work:  array<vec2<f32>>, [C, Hc, Wc]
//   Grid: embed over C·Hc·Wc elements, crop over C·H·W (1D, 256 per workgroup, spread over x/y).
//
// `multiply` — spectrum[i] *= multiplier[i], all [C, Wc, Hc] (transposed spectrum); `multiply_conj_add`
// sum[i] += conj(multiplier[i])·spectrum[i] instead (an operation's adjoint summed over several, e.g. the
// refinement's gradient over its loss planes):
//   0: uniform Grid (channels·hc·wc elements)
//   1: storage spectrum: array<vec2<f32>>
//   2: storage read multiplier: array<vec2<f32>>
//   3: storage sum: array<vec2<f32>> (multiply_conj_add only)

struct Grid {
    h: u32,
    w: u32,
    hc: u32,
    wc: u32,
    oy: u32,
    ox: u32,
    channels: u32,
}

@group(0) @binding(0) var<uniform> grid: Grid;
@group(0) @binding(1) var<storage, read_write> field: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> work: array<vec2<f32>>;

fn index_of(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 256u;
}

@compute @workgroup_size(256)
fn embed(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    let plane = grid.hc * grid.wc;
    if (i >= grid.channels * plane) {
        return;
    }
    let c = i / plane;
    let y = (i % plane) / grid.wc;
    let x = i % grid.wc;
    var v = vec2<f32>(0.0, 0.0);
    if (y >= grid.oy && y < grid.oy + grid.h && x >= grid.ox && x < grid.ox + grid.w) {
        v = field[(c * grid.h + (y - grid.oy)) * grid.w + (x - grid.ox)];
    }
    work[i] = v;
}

@compute @workgroup_size(256)
fn crop(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    let plane = grid.h * grid.w;
    if (i >= grid.channels * plane) {
        return;
    }
    let c = i / plane;
    let y = (i % plane) / grid.w;
    let x = i % grid.w;
    field[i] = work[(c * grid.hc + y + grid.oy) * grid.wc + x + grid.ox];
}

@group(0) @binding(1) var<storage, read_write> spectrum: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read> multiplier: array<vec2<f32>>;

@compute @workgroup_size(256)
fn multiply(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    if (i >= grid.channels * grid.hc * grid.wc) {
        return;
    }
    let a = spectrum[i];
    let b = multiplier[i];
    spectrum[i] = vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

@group(0) @binding(3) var<storage, read_write> sum: array<vec2<f32>>;

@compute @workgroup_size(256)
fn multiply_conj_add(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    if (i >= grid.channels * grid.hc * grid.wc) {
        return;
    }
    let a = spectrum[i];
    let b = multiplier[i];
    sum[i] = sum[i] + vec2<f32>(a.x * b.x + a.y * b.y, a.y * b.x - a.x * b.y);
}
