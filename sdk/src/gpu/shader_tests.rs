//! Every WGSL shader of the GPU path translated as the phones' drivers will see it, without a Mac or a phone:
//! naga (wgpu's shader compiler) parses and validates each file, then writes Metal Shading Language (what
//! wgpu hands to Metal on iOS) and SPIR-V (Vulkan on Android) for every entry point. A construct that Metal or
//! Vulkan would reject fails here, in CI, instead of at session creation on a user's phone.
//!
//! Every uniform struct is written twice, in WGSL and as a `#[repr(C)]` Rust struct whose bytes are uploaded
//! as is ([`super::context::GpuContext::uniform`]). naga reflects each WGSL struct; its members' names, offsets
//! and scalar types must be the Rust fields' (padding fields `_pad` aside), and the Rust size must be the
//! WGSL size rounded up to 16 bytes. Each module lists its structs (`uniform_layouts`).

use naga::back::{msl, spv};
use naga::valid::{Capabilities, ValidationFlags, Validator};
use naga::{ScalarKind, TypeInner};

use super::shaders::{Shader, ALL};

/// A scalar field type of a uniform struct, as naga names it.
pub(super) trait UniformScalar {
    const KIND: ScalarKind;
}
impl UniformScalar for u32 {
    const KIND: ScalarKind = ScalarKind::Uint;
}
impl UniformScalar for f32 {
    const KIND: ScalarKind = ScalarKind::Float;
}

/// The naga kind of the field that `field` projects (the closure only carries the type).
pub(super) fn kind_of<S, T: UniformScalar>(_field: fn(&S) -> &T) -> ScalarKind {
    T::KIND
}

/// A Rust uniform struct beside the WGSL struct it mirrors.
pub(super) struct UniformLayout {
    pub(super) shader: &'static Shader,
    /// The WGSL struct's name.
    pub(super) wgsl: &'static str,
    /// The Rust struct's name, for messages.
    pub(super) rust: &'static str,
    pub(super) size: usize,
    /// Named fields in declaration order: (name, offset in bytes, scalar kind).
    pub(super) fields: Vec<(&'static str, usize, ScalarKind)>,
}

/// `uniform_layout!(SHADER, "WgslStruct", RustStruct { field, … })`: the layout of `RustStruct`'s listed
/// (non-padding) fields.
macro_rules! uniform_layout {
    ($shader:expr, $wgsl:literal, $t:ident { $($f:ident),* $(,)? }) => {
        $crate::gpu::shader_tests::UniformLayout {
            shader: $shader,
            wgsl: $wgsl,
            rust: stringify!($t),
            size: std::mem::size_of::<$t>(),
            fields: vec![$((
                stringify!($f),
                std::mem::offset_of!($t, $f),
                $crate::gpu::shader_tests::kind_of(|s: &$t| &s.$f),
            )),*],
        }
    };
}
pub(super) use uniform_layout;

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
    let mut listed: Vec<String> = ALL.iter().map(|s| s.file.to_string()).collect();
    listed.sort();
    listed.dedup();
    let mut names: Vec<&str> = ALL.iter().map(|s| s.name).collect();
    names.sort();
    names.dedup();
    assert_eq!(names.len(), ALL.len(), "two shaders share a label");
    assert_eq!(listed, on_disk, "shaders.rs::ALL must use every .wgsl file");
    for s in ALL {
        assert_eq!(
            s.f16,
            s.source
                .lines()
                .any(|l| l.trim_start().starts_with("enable f16;")),
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

/// Every uniform struct of the GPU path: the Rust twin of each WGSL `var<uniform>` struct.
fn all_layouts() -> Vec<UniformLayout> {
    let mut v = Vec::new();
    v.extend(super::context::tests::uniform_layouts());
    v.extend(super::fft::uniform_layouts());
    v.extend(super::encode::uniform_layouts());
    v.extend(super::cnn::uniform_layouts());
    v.extend(super::session::uniform_layouts());
    v.extend(super::fovea::uniform_layouts());
    v.extend(super::refine::uniform_layouts());
    v
}

/// What differs between `l` and the WGSL struct it mirrors, or `None`.
fn layout_mismatch(l: &UniformLayout) -> Option<String> {
    let (module, _) = validated(l.shader);
    let what = format!("{} {} vs Rust {}", l.shader.name, l.wgsl, l.rust);
    let Some((members, span)) = module.types.iter().find_map(|(_, t)| match &t.inner {
        TypeInner::Struct { members, span } if t.name.as_deref() == Some(l.wgsl) => {
            Some((members, *span))
        }
        _ => None,
    }) else {
        return Some(format!("{what}: no such WGSL struct"));
    };
    let mut wgsl = Vec::new();
    for m in members {
        match module.types[m.ty].inner {
            TypeInner::Scalar(s) if s.width == 4 => {
                wgsl.push((
                    m.name.clone().unwrap_or_default(),
                    m.offset as usize,
                    s.kind,
                ));
            }
            ref other => return Some(format!("{what}: {:?} is {other:?}", m.name)),
        }
    }
    let rust: Vec<(String, usize, ScalarKind)> = l
        .fields
        .iter()
        .map(|&(n, o, k)| (n.to_string(), o, k))
        .collect();
    if wgsl != rust {
        return Some(format!(
            "{what}: members (name, offset, kind) differ:\n  WGSL {wgsl:?}\n  Rust {rust:?}"
        ));
    }
    if l.size != (span as usize).next_multiple_of(16) {
        return Some(format!(
            "{what}: Rust size {} is not the WGSL size {span} rounded up to 16",
            l.size
        ));
    }
    None
}

#[test]
fn every_uniform_struct_matches_its_rust_twin() {
    let layouts = all_layouts();
    for l in &layouts {
        if let Some(m) = layout_mismatch(l) {
            panic!("{m}");
        }
    }
    // Every struct a shader binds as `var<uniform>` has a Rust twin listed.
    for shader in ALL {
        let (module, _) = validated(shader);
        for (_, var) in module.global_variables.iter() {
            if var.space != naga::AddressSpace::Uniform {
                continue;
            }
            let name = module.types[var.ty].name.clone().unwrap_or_default();
            assert!(
                layouts
                    .iter()
                    .any(|l| l.shader.file == shader.file && l.wgsl == name),
                "{}: uniform struct {name} has no Rust twin in the layouts",
                shader.name
            );
        }
    }
}

#[test]
fn the_layout_check_catches_swapped_fields_and_a_wrong_size() {
    // `util.wgsl`'s `Params` is { n: u32, value: f32 }.
    #[allow(dead_code)]
    #[repr(C)]
    struct Swapped {
        value: f32,
        n: u32,
        _pad: [u32; 2],
    }
    #[allow(dead_code)]
    #[repr(C)]
    struct Unpadded {
        n: u32,
        value: f32,
    }
    #[allow(dead_code)]
    #[repr(C)]
    struct WrongKind {
        n: f32,
        value: f32,
        _pad: [u32; 2],
    }
    let swapped = uniform_layout!(&super::shaders::UTIL, "Params", Swapped { value, n });
    let unpadded = uniform_layout!(&super::shaders::UTIL, "Params", Unpadded { n, value });
    let kind = uniform_layout!(&super::shaders::UTIL, "Params", WrongKind { n, value });
    let missing = uniform_layout!(&super::shaders::UTIL, "Nope", Unpadded { n, value });
    for l in [&swapped, &unpadded, &kind, &missing] {
        let m = layout_mismatch(l);
        println!("{}: {m:?}", l.rust);
        assert!(m.is_some(), "{} passed", l.rust);
    }
}
