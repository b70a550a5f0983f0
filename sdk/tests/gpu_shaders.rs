//! Every WGSL shader of the GPU path translated as the phones' drivers will see it, without a Mac or a phone:
//! naga (wgpu's shader compiler) parses and validates each file, then writes Metal Shading Language (what
//! wgpu hands to Metal on iOS) and SPIR-V (Vulkan on Android) for every entry point. A construct that Metal or
//! Vulkan would reject fails here, in CI, instead of at session creation on a user's phone.

use naga::back::{msl, spv};
use naga::valid::{Capabilities, ValidationFlags, Validator};
use tensorholo::gpu::shaders::{Shader, ALL};

fn validated(shader: &Shader) -> (naga::Module, naga::valid::ModuleInfo) {
    let module = naga::front::wgsl::parse_str(shader.source)
        .unwrap_or_else(|e| panic!("{}: {}", shader.name, e.emit_to_string(shader.source)));
    let caps = if shader.f16 {
        Capabilities::SHADER_FLOAT16
    } else {
        Capabilities::empty()
    };
    let info = Validator::new(ValidationFlags::all(), caps)
        .validate(&module)
        .unwrap_or_else(|e| panic!("{}: {}", shader.name, e.emit_to_string(shader.source)));
    assert!(
        !module.entry_points.is_empty(),
        "{} has no entry point",
        shader.name
    );
    (module, info)
}

#[test]
fn every_shader_is_listed_once_and_its_file_exists() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/gpu/shaders");
    let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".wgsl"))
        .collect();
    on_disk.sort();
    let mut listed: Vec<String> = ALL.iter().map(|s| s.name.to_string()).collect();
    listed.sort();
    assert_eq!(
        listed, on_disk,
        "shaders.rs::ALL must list every .wgsl file once"
    );
    for s in ALL {
        assert_eq!(
            s.f16,
            s.source.contains("enable f16;"),
            "{}: the f16 flag must match `enable f16;`",
            s.name
        );
    }
}

#[test]
fn every_shader_translates_to_metal_shading_language() {
    for shader in ALL {
        let (module, info) = validated(shader);
        let options = msl::Options {
            // Metal 2.4: iOS 15 / A-series GPUs of the last years; f16 (`half`) is core MSL.
            lang_version: (2, 4),
            fake_missing_bindings: true,
            ..Default::default()
        };
        let (source, translation) =
            msl::write_string(&module, &info, &options, &msl::PipelineOptions::default())
                .unwrap_or_else(|e| panic!("{} → MSL: {e}", shader.name));
        for (ep, name) in module
            .entry_points
            .iter()
            .zip(&translation.entry_point_names)
        {
            if let Err(e) = name {
                panic!("{}::{} → MSL: {e}", shader.name, ep.name);
            }
        }
        assert!(
            source.contains("kernel void"),
            "{}: no compute kernel in MSL",
            shader.name
        );
    }
}

#[test]
fn every_shader_translates_to_spirv() {
    for shader in ALL {
        let (module, info) = validated(shader);
        let words = spv::write_vec(&module, &info, &spv::Options::default(), None)
            .unwrap_or_else(|e| panic!("{} → SPIR-V: {e}", shader.name));
        assert_eq!(
            words.first(),
            Some(&0x0723_0203),
            "{}: not SPIR-V",
            shader.name
        );
    }
}
