// Element-wise utilities on flat arrays.
//
// Bindings (group 0):
//   0: uniform Params { n: u32 (elements), value: f32 (fill value / scale) }
//   1: storage read_write data: array<f32>, at least n elements
// Dispatch: ceil(n / 256) workgroups, spread over x and y (see kernel.rs: grid_1d).

struct Params {
    n: u32,
    value: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> data: array<f32>;

// Linear element index of a 1D dispatch spread over a 2D grid of workgroups of 256.
fn index_of(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 256u;
}

// data[i] = value
@compute @workgroup_size(256)
fn fill(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    if (i < params.n) {
        data[i] = params.value;
    }
}

// data[i] *= value
@compute @workgroup_size(256)
fn scale(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = index_of(gid, groups);
    if (i < params.n) {
        data[i] = data[i] * params.value;
    }
}
