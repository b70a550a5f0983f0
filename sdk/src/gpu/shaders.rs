//! The WGSL sources of the GPU path, one file per concept under `sdk/src/gpu/shaders/`, compiled into the
//! library. [`ALL`] lists them for the naga tests (`shader_tests.rs`): each translates to what Metal (MSL)
//! and Vulkan (SPIR-V) accept without a Mac or a phone, and each uniform struct matches its Rust twin.

/// One WGSL shader: a file, or a file specialised by a prelude (the CNN layer in f32 and in f16).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shader {
    /// The pipeline label: the file name, with the variant for a specialised file.
    pub(crate) name: &'static str,
    /// File name under `sdk/src/gpu/shaders/`.
    #[cfg_attr(not(test), allow(dead_code))]
    pub(crate) file: &'static str,
    /// The WGSL source (the prelude, then the file).
    pub(crate) source: &'static str,
    /// Whether the source uses `enable f16;` (needs the adapter's `SHADER_F16`).
    pub(crate) f16: bool,
}

macro_rules! shader {
    ($name:literal) => {
        Shader {
            name: $name,
            file: $name,
            source: include_str!(concat!("shaders/", $name)),
            f16: false,
        }
    };
    ($name:literal, $variant:literal, $prelude:literal, $f16:literal) => {
        Shader {
            name: concat!($name, " (", $variant, ")"),
            file: $name,
            source: concat!($prelude, "\n", include_str!(concat!("shaders/", $name))),
            f16: $f16,
        }
    };
}

/// Element-wise utilities: fill, scale (`util.wgsl`; the context's own tests).
#[cfg(test)]
pub(crate) const UTIL: Shader = shader!("util.wgsl");

/// Batched Stockham FFT passes along rows and the tiled transpose (`fft.wgsl`).
pub(crate) const FFT: Shader = shader!("fft.wgsl");

/// Embedding in / cropping from the zero-padded grid and the spectral multiply (`spectral.wgsl`).
pub(crate) const SPECTRAL: Shader = shader!("spectral.wgsl");

/// Heads → field and field ↔ `[Re, Im]` planes (`field.wgsl`).
pub(crate) const FIELD: Shader = shader!("field.wgsl");

/// The AA-DPM separable Gaussian blur (`blur.wgsl`).
pub(crate) const BLUR: Shader = shader!("blur.wgsl");

/// Double phase encoding passes, the normaliser reduction and the linear LUT (`double_phase.wgsl`).
pub(crate) const DOUBLE_PHASE: Shader = shader!("double_phase.wgsl");

/// One fused layer of the residual CNN: 3×3 convolution, bias, ReLU, residual add, concat (`conv3x3.wgsl`),
/// hidden activations in f32.
pub(crate) const CONV3X3: Shader = shader!("conv3x3.wgsl", "f32", "alias act = f32;", false);

/// [`CONV3X3`] from the same file with f16 hidden activations (stored and staged), f32 products and sums
/// (`SHADER_F16`).
pub(crate) const CONV3X3_F16: Shader =
    shader!("conv3x3.wgsl", "f16", "enable f16; alias act = f16;", true);

/// The CNNs' output stages: tanh heads, the pre-filter's base filter (`heads.wgsl`).
pub(crate) const HEADS: Shader = shader!("heads.wgsl");

/// A foveated frame's band phase and composed heads: the tile's CNN heads, the periphery's blur, the blend
/// (`fovea.wgsl`).
pub(crate) const FOVEA: Shader = shader!("fovea.wgsl");

/// Previews: SLM codes → displayed field, field → amplitude (`preview.wgsl`).
pub(crate) const PREVIEW: Shader = shader!("preview.wgsl");

/// The focal-stack refinement's element-wise steps: phasors, plane terms and sums, Adam (`refine.wgsl`).
pub(crate) const REFINE: Shader = shader!("refine.wgsl");

/// Every shader of the GPU path.
#[cfg(test)]
pub(crate) const ALL: &[Shader] = &[
    UTIL,
    FFT,
    SPECTRAL,
    FIELD,
    BLUR,
    DOUBLE_PHASE,
    CONV3X3,
    CONV3X3_F16,
    HEADS,
    FOVEA,
    PREVIEW,
    REFINE,
];
