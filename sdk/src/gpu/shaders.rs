//! The WGSL sources of the GPU path, one file per concept under `sdk/src/gpu/shaders/`, compiled into the
//! library. [`ALL`] lists them for the naga translation test (`sdk/tests/gpu_shaders.rs`), which checks each
//! against what Metal (MSL) and Vulkan (SPIR-V) accept without a Mac or a phone.

/// One WGSL source file.
#[derive(Debug, Clone, Copy)]
pub struct Shader {
    /// File name under `sdk/src/gpu/shaders/` (also the pipeline label).
    pub name: &'static str,
    /// The WGSL source.
    pub source: &'static str,
    /// Whether the source uses `enable f16;` (needs the adapter's `SHADER_F16`).
    pub f16: bool,
}

macro_rules! shader {
    ($name:literal) => {
        Shader {
            name: $name,
            source: include_str!(concat!("shaders/", $name)),
            f16: false,
        }
    };
}

/// Element-wise utilities: fill, copy, scale (`util.wgsl`).
pub const UTIL: Shader = shader!("util.wgsl");

/// Batched Stockham FFT passes along rows and the tiled transpose (`fft.wgsl`).
pub const FFT: Shader = shader!("fft.wgsl");

/// Embedding in / cropping from the zero-padded grid and the spectral multiply (`spectral.wgsl`).
pub const SPECTRAL: Shader = shader!("spectral.wgsl");

/// Heads → field and field ↔ `[Re, Im]` planes (`field.wgsl`).
pub const FIELD: Shader = shader!("field.wgsl");

/// The AA-DPM separable Gaussian blur (`blur.wgsl`).
pub const BLUR: Shader = shader!("blur.wgsl");

/// Double phase encoding passes, the normaliser reduction and the linear LUT (`double_phase.wgsl`).
pub const DOUBLE_PHASE: Shader = shader!("double_phase.wgsl");

/// One fused layer of the residual CNN: 3×3 convolution, bias, ReLU, residual add, concat (`conv3x3.wgsl`).
pub const CONV3X3: Shader = shader!("conv3x3.wgsl");

/// [`CONV3X3`] with f16 hidden activations and f16 products, f32 sums (`conv3x3_f16.wgsl`; `SHADER_F16`).
pub const CONV3X3_F16: Shader = Shader {
    name: "conv3x3_f16.wgsl",
    source: include_str!("shaders/conv3x3_f16.wgsl"),
    f16: true,
};

/// The CNNs' output stages: tanh heads, the pre-filter's base filter (`heads.wgsl`).
pub const HEADS: Shader = shader!("heads.wgsl");

/// Previews: SLM codes → displayed field, field → amplitude (`preview.wgsl`).
pub const PREVIEW: Shader = shader!("preview.wgsl");

/// Every shader of the GPU path.
pub const ALL: &[Shader] = &[
    UTIL,
    FFT,
    SPECTRAL,
    FIELD,
    BLUR,
    DOUBLE_PHASE,
    CONV3X3,
    CONV3X3_F16,
    HEADS,
    PREVIEW,
];
