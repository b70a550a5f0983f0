//! The GPU context on whatever adapter exists (CI: Mesa's lavapipe): kernels run, errors are typed, and
//! resources are counted. Skips with a message where no adapter exists, unless `TENSORHOLO_REQUIRE_GPU=1`.
#![cfg(feature = "gpu")]

use tensorholo::gpu::{GpuContext, GpuOptions};

mod gpu_common;

#[test]
fn software_adapters_are_refused_unless_allowed() {
    // Default options skip software adapters: on a machine with only lavapipe this is an error naming it.
    match GpuContext::new(&GpuOptions::default()) {
        Ok(ctx) => assert!(!ctx.info().is_software(), "{:?}", ctx.info()),
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.starts_with("GPU: no GPU adapter"), "{msg}");
        }
    }
    let Some(_) = gpu_common::context() else {
        return;
    };
    let err = GpuContext::new(&GpuOptions {
        allow_software: true,
        name_contains: Some("no such adapter 42".into()),
    })
    .unwrap_err();
    assert!(err.to_string().contains("adapters seen"), "{err}");
}

#[test]
fn info_reports_limits_above_the_webgpu_default_where_the_adapter_has_them() {
    let Some(ctx) = gpu_common::context() else {
        return;
    };
    let info = ctx.info();
    assert!(
        ["vulkan", "metal"].contains(&info.backend.as_str()),
        "{info:?}"
    );
    assert!(info.max_storage_binding_bytes >= 128 << 20, "{info:?}");
}
