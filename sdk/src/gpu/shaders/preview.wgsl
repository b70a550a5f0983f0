// What a viewer sees (optics::reconstruct: post_encoding_midpoint, focal_stack), for previews on the phone:
// the phase-only field the SLM displays for its 8-bit codes, and the amplitude of a propagated field.
//
// `codes_to_field` — field[e] = scale·exp(i·2π·code[e]/256) (the linear LUT's phase, encoding::LinearLut):
//   0: uniform Preview { n: elements (3·H·W), scale: the encoding's amplitude normaliser a }
//   1: storage read codes: array<u32>, ceil(n / 4) words, four codes per word, little-endian
//   2: storage field: array<vec2<f32>>, [3, H, W]
// `magnitude` — amplitude[e] = |field[e]|:
//   0: uniform Preview
//   2: storage read field: array<vec2<f32>>, [3, H, W]
//   3: storage amplitude: array<f32>, [3, H, W]
// Grid: n elements (256 per workgroup, spread over x/y).

struct Preview {
    n: u32,
    scale: f32,
}

@group(0) @binding(0) var<uniform> preview: Preview;
@group(0) @binding(1) var<storage, read> codes: array<u32>;
@group(0) @binding(2) var<storage, read_write> field: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> amplitude: array<f32>;

const TAU: f32 = 6.283185307179586;

fn index_of(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 256u;
}

@compute @workgroup_size(256)
fn codes_to_field(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = index_of(gid, groups);
    if (e >= preview.n) {
        return;
    }
    let code = (codes[e / 4u] >> (8u * (e % 4u))) & 255u;
    let p = f32(code) * (TAU / 256.0);
    field[e] = preview.scale * vec2<f32>(cos(p), sin(p));
}

@compute @workgroup_size(256)
fn magnitude(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let e = index_of(gid, groups);
    if (e >= preview.n) {
        return;
    }
    amplitude[e] = length(field[e]);
}
