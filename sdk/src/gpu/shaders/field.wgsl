// Conversions between the CNNs' real planes and the complex field the optics work on
// (model::contract: heads_to_field, pack_prefilter_colour).
//
// Bindings (group 0), for every entry point:
//   0: uniform Planes { n: pixels per channel (H·W), channels: 3 }
//   1: storage planes: array<f32>, [2·C, H, W]: the hologram CNN's heads (amplitude R, G, B then phase R, G, B)
//      or the pre-filter's input/output (Re R, G, B then Im R, G, B)
//   2: storage field: array<vec2<f32>>, [C, H, W] (re, im)
// Grid: C·n elements, 256 per workgroup, spread over x/y (kernel.rs: grid_1d).

struct Planes {
    n: u32,
    channels: u32,
}

@group(0) @binding(0) var<uniform> dims: Planes;
@group(0) @binding(1) var<storage, read_write> planes: array<f32>;
@group(0) @binding(2) var<storage, read_write> field: array<vec2<f32>>;

const TAU: f32 = 6.283185307179586;

fn index_of(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 256u;
}

// field = A·exp(i·(p − 0.5)·2π) (docs/CONVENTIONS.md §7.1: amplitude head A ∈ [0, √2], phase head p ∈ [0, 1]).
@compute @workgroup_size(256)
fn heads_to_field(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = index_of(gid, groups);
    if (e >= dims.channels * dims.n) {
        return;
    }
    let c = e / dims.n;
    let i = e % dims.n;
    let a = planes[c * dims.n + i];
    let theta = (planes[(dims.channels + c) * dims.n + i] - 0.5) * TAU;
    field[e] = a * vec2<f32>(cos(theta), sin(theta));
}

// planes = [Re field, Im field]: the pre-filter CNN's input (docs/CONVENTIONS.md §7.2, format 2).
@compute @workgroup_size(256)
fn field_to_planes(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = index_of(gid, groups);
    if (e >= dims.channels * dims.n) {
        return;
    }
    let c = e / dims.n;
    let i = e % dims.n;
    let v = field[e];
    planes[c * dims.n + i] = v.x;
    planes[(dims.channels + c) * dims.n + i] = v.y;
}

// field = Re + i·Im from the pre-filter CNN's output planes.
@compute @workgroup_size(256)
fn planes_to_field(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = index_of(gid, groups);
    if (e >= dims.channels * dims.n) {
        return;
    }
    let c = e / dims.n;
    let i = e % dims.n;
    field[e] = vec2<f32>(planes[c * dims.n + i], planes[(dims.channels + c) * dims.n + i]);
}
