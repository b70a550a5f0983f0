//! [`Kernel`]: one compute pipeline (a WGSL entry point), and the dispatch-grid helpers every kernel shares.

/// Invocations per workgroup of the 1D element-wise kernels (`@workgroup_size(256)`), within every adapter's
/// minimum limit (WebGPU guarantees 256).
pub const WORKGROUP_1D: u32 = 256;

/// Most workgroups per grid dimension that every adapter accepts (WebGPU's minimum limit).
pub const MAX_GROUPS_PER_DIM: u32 = 65_535;

/// A compute pipeline built from one WGSL entry point (made by the context, which counts it); its bind group
/// layout is derived from the shader (`layout: None`), so bind groups are made by binding number.
#[derive(Debug, Clone)]
pub struct Kernel {
    entry: &'static str,
    pipeline: wgpu::ComputePipeline,
}

impl Kernel {
    pub(crate) fn new(entry: &'static str, pipeline: wgpu::ComputePipeline) -> Self {
        Self { entry, pipeline }
    }

    /// The entry point.
    pub(crate) fn entry(&self) -> &'static str {
        self.entry
    }

    /// The wgpu pipeline.
    pub(crate) fn pipeline(&self) -> &wgpu::ComputePipeline {
        &self.pipeline
    }

    /// Records one dispatch of this kernel with `bind_group` over `groups` workgroups into `pass`.
    pub(crate) fn dispatch(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        bind_group: &wgpu::BindGroup,
        groups: [u32; 3],
    ) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
    }
}

/// Workgroups for `n` elements at [`WORKGROUP_1D`] per group, spread over x and y so that no dimension
/// exceeds [`MAX_GROUPS_PER_DIM`]. The shader recovers the element index as
/// `gid.x + gid.y · num_workgroups.x · 256` and skips indices `≥ n`.
pub(crate) fn grid_1d(n: usize) -> [u32; 3] {
    let groups = n.div_ceil(WORKGROUP_1D as usize).max(1);
    if groups <= MAX_GROUPS_PER_DIM as usize {
        [groups as u32, 1, 1]
    } else {
        let y = groups.div_ceil(MAX_GROUPS_PER_DIM as usize);
        let x = groups.div_ceil(y);
        [x as u32, y as u32, 1]
    }
}

/// Workgroups covering a `width × height (× depth)` grid with `tile = [tx, ty]` invocations per group.
pub(crate) fn grid_2d(width: usize, height: usize, depth: usize, tile: [u32; 2]) -> [u32; 3] {
    [
        width.div_ceil(tile[0] as usize).max(1) as u32,
        height.div_ceil(tile[1] as usize).max(1) as u32,
        depth.max(1) as u32,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_1d_covers_every_element_within_limits() {
        for n in [
            1usize,
            255,
            256,
            257,
            65_535 * 256,
            65_535 * 256 + 1,
            3 * 3840 * 2160,
        ] {
            let [x, y, z] = grid_1d(n);
            assert!(
                x <= MAX_GROUPS_PER_DIM && y <= MAX_GROUPS_PER_DIM && z == 1,
                "{n}: {x}×{y}"
            );
            assert!(
                (x as usize) * (y as usize) * 256 >= n,
                "{n}: {x}×{y} too small"
            );
            assert!(
                ((x as usize) * (y as usize - 1)) * 256 < n,
                "{n}: a whole idle row of groups"
            );
        }
    }
}
