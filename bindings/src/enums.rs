//! The configuration's enums ([`GeneratorConfig`](crate::GeneratorConfig)'s `input`, `precision`, `prefilter`, `backend`,
//! `gpu_precision`, `engine`), each converting to and from the core's with `From`, and `mirror_enum!`, which
//! writes those conversions for an enum that mirrors the core's variant for variant (the frame enums of
//! [`crate::frames`] too).

use tensorholo::model::DEFAULT_INT8;

/// Writes `From` both ways between a bindings enum and the core enum it mirrors variant for variant:
/// `mirror_enum!(Fit <=> scene::Fit { Crop, Letterbox, Stretch });`. A variant missing on either side fails
/// to compile.
macro_rules! mirror_enum {
    ($ours:ident <=> $core:ty { $($variant:ident),+ $(,)? }) => {
        impl From<$ours> for $core {
            fn from(value: $ours) -> Self {
                match value {
                    $($ours::$variant => Self::$variant,)+
                }
            }
        }

        impl From<$core> for $ours {
            fn from(value: $core) -> Self {
                match value {
                    $(<$core>::$variant => Self::$variant,)+
                }
            }
        }
    };
}
pub(crate) use mirror_enum;

/// Weight format of the shipped CNNs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum Precision {
    /// 32-bit float (the default).
    F32,
    /// 8-bit integer weights (the int8 form that loses at most 0.5 dB; see the model card).
    Int8,
}

impl From<Precision> for tensorholo::model::Precision {
    /// `Int8` is the library's int8 form, [`DEFAULT_INT8`].
    fn from(precision: Precision) -> Self {
        match precision {
            Precision::F32 => Self::F32,
            Precision::Int8 => DEFAULT_INT8,
        }
    }
}

impl From<tensorholo::model::Precision> for Precision {
    /// Both int8 forms of the core are `Int8`.
    fn from(precision: tensorholo::model::Precision) -> Self {
        match precision {
            tensorholo::model::Precision::F32 => Self::F32,
            tensorholo::model::Precision::Int8QOperator | tensorholo::model::Precision::Int8Qdq => {
                Self::Int8
            }
        }
    }
}

/// The scene the hologram CNN takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum SceneInput {
    /// One RGB-D frame per hologram ([`HologramGenerator::render`](crate::HologramGenerator::render); the default).
    Rgbd,
    /// A layered depth image of up to 5 layers front to back ([`HologramGenerator::render_ldi`](crate::HologramGenerator::render_ldi); the shipped
    /// 8-layer LDI CNN, paper Fig. 1). `render` still works: a frame is a one-layer LDI.
    Ldi,
}

mirror_enum!(SceneInput <=> tensorholo::model::SceneInput { Rgbd, Ldi });

/// Whether the DDPM pre-filter CNN runs (paper Eq. 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum PrefilterMode {
    /// Where one is shipped for the offset (6 or 12 mm) and was trained with this CNN depth (the default).
    Auto,
    /// Never: AA-DPM encoding.
    Off,
    /// Always; an error at an offset without a shipped pre-filter.
    Required,
}

mirror_enum!(PrefilterMode <=> tensorholo::pipeline::PrefilterMode { Auto, Off, Required });

/// Where frames are computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum Backend {
    /// The phone's GPU (Metal, Vulkan) where the first frame agrees with the CPU, else the CPU (the default).
    Auto,
    /// The CPU (tract and rustfft), the reference.
    Cpu,
    /// The GPU always; an `Unsupported` error at creation where there is none.
    Gpu,
}

mirror_enum!(Backend <=> tensorholo::pipeline::Backend { Auto, Cpu, Gpu });

/// The GPU CNNs' arithmetic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum GpuPrecision {
    /// f16 where the GPU has it, else f32 (the default).
    Auto,
    /// f32.
    F32,
    /// f16 activations, f32 products and sums: half the GPU memory; f32 where the GPU lacks f16.
    F16,
}

mirror_enum!(GpuPrecision <=> tensorholo::pipeline::GpuPrecision { Auto, F32, F16 });

/// The engine that runs the CNNs on the CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum CnnEngine {
    /// Time tensorholo's own kernels and tract when the generator is created and keep the faster (the
    /// default).
    Auto,
    /// tensorholo's own direct 3×3 convolution kernels (f32 and int8 models).
    Native,
    /// tract.
    Tract,
}

mirror_enum!(CnnEngine <=> tensorholo::cnn::CnnEngine { Auto, Native, Tract });
