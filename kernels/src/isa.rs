//! Instruction-set levels and their run-time detection. The crate reads no environment: a caller that lowers
//! the level passes it to each plan (`holo` maps `TENSORHOLO_ISA` onto the SDK's `CnnOptions::isa`).

use crate::error::KernelError;
use std::sync::OnceLock;

/// An instruction-set level. Each level is a set of CPU features; a kernel row of level `r` may run under a
/// selected level `s` when `s.includes(r)` (the features of `r` are a subset of those of `s`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Isa {
    /// Portable code, any CPU.
    Scalar,
    /// x86-64 AVX2 + FMA.
    Avx2Fma,
    /// x86-64 AVX2 + FMA + AVX-VNNI (256-bit `{vex} vpdpbusd`).
    AvxVnni,
    /// x86-64 AVX-512F + AVX-512BW (with AVX2 + FMA).
    Avx512,
    /// x86-64 AVX-512F/BW + AVX-512 VNNI (512-bit `vpdpbusd`).
    Avx512Vnni,
    /// aarch64 Advanced SIMD (always present on aarch64).
    Neon,
    /// aarch64 NEON + dot product (SDOT/UDOT, FEAT_DotProd).
    NeonDot,
    /// aarch64 NEON + dot product + i8mm (USDOT, FEAT_I8MM).
    NeonI8mm,
}

const F_AVX2FMA: u32 = 1;
const F_AVXVNNI: u32 = 2;
const F_AVX512: u32 = 4;
const F_AVX512VNNI: u32 = 8;
const F_NEON: u32 = 16;
const F_DOT: u32 = 32;
const F_I8MM: u32 = 64;

impl Isa {
    /// Every level, lowest first within each architecture.
    pub const ALL: [Isa; 8] = [
        Isa::Scalar,
        Isa::Avx2Fma,
        Isa::AvxVnni,
        Isa::Avx512,
        Isa::Avx512Vnni,
        Isa::Neon,
        Isa::NeonDot,
        Isa::NeonI8mm,
    ];

    /// The name used in kernel names and by `holo`'s `TENSORHOLO_ISA` (`scalar`, `avx2`, `avxvnni`, `avx512`,
    /// `avx512vnni`, `neon`, `neondot`, `neoni8mm`).
    pub fn name(self) -> &'static str {
        match self {
            Isa::Scalar => "scalar",
            Isa::Avx2Fma => "avx2",
            Isa::AvxVnni => "avxvnni",
            Isa::Avx512 => "avx512",
            Isa::Avx512Vnni => "avx512vnni",
            Isa::Neon => "neon",
            Isa::NeonDot => "neondot",
            Isa::NeonI8mm => "neoni8mm",
        }
    }

    fn features(self) -> u32 {
        match self {
            Isa::Scalar => 0,
            Isa::Avx2Fma => F_AVX2FMA,
            Isa::AvxVnni => F_AVX2FMA | F_AVXVNNI,
            Isa::Avx512 => F_AVX2FMA | F_AVX512,
            Isa::Avx512Vnni => F_AVX2FMA | F_AVX512 | F_AVX512VNNI,
            Isa::Neon => F_NEON,
            Isa::NeonDot => F_NEON | F_DOT,
            Isa::NeonI8mm => F_NEON | F_DOT | F_I8MM,
        }
    }

    /// True when every CPU feature of `other` is part of `self` (a kernel of level `other` may run when
    /// `self` is selected).
    pub fn includes(self, other: Isa) -> bool {
        other.features() & !self.features() == 0
    }

    /// Parses a name as written by [`Isa::name`] (case-insensitive). Unknown names are an
    /// [`KernelError::Isa`] error. Does not check availability (see [`Isa::from_name`]).
    pub fn parse(name: &str) -> Result<Isa, KernelError> {
        let lower = name.trim().to_ascii_lowercase();
        Isa::ALL
            .into_iter()
            .find(|i| i.name() == lower)
            .ok_or_else(|| KernelError::Isa {
                name: name.to_string(),
                why: "unknown ISA name",
            })
    }

    /// Parses a name and refuses an ISA this CPU does not have ([`KernelError::Isa`]).
    pub fn from_name(name: &str) -> Result<Isa, KernelError> {
        let isa = Isa::parse(name)?;
        if isa.is_available() {
            Ok(isa)
        } else {
            Err(KernelError::Isa {
                name: name.to_string(),
                why: "not available on this CPU",
            })
        }
    }

    /// True when this CPU has every feature of the level (detected once, at first use).
    pub fn is_available(self) -> bool {
        self.features() & !detected_features() == 0
    }

    /// Every level this CPU has, lowest first.
    pub fn available() -> Vec<Isa> {
        Isa::ALL.into_iter().filter(|i| i.is_available()).collect()
    }

    /// The best level of this CPU: the available level with the most features (for x86-64, AVX-512 VNNI before
    /// AVX-512 before AVX-VNNI before AVX2; for aarch64, i8mm before dot product before NEON).
    pub fn detect() -> Isa {
        const ORDER: [Isa; 8] = [
            Isa::Avx512Vnni,
            Isa::Avx512,
            Isa::AvxVnni,
            Isa::Avx2Fma,
            Isa::NeonI8mm,
            Isa::NeonDot,
            Isa::Neon,
            Isa::Scalar,
        ];
        ORDER
            .into_iter()
            .find(|i| i.is_available())
            .unwrap_or(Isa::Scalar)
    }
}

impl std::fmt::Display for Isa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

fn detected_features() -> u32 {
    static FEATURES: OnceLock<u32> = OnceLock::new();
    *FEATURES.get_or_init(detect_features)
}

#[cfg(target_arch = "x86_64")]
fn detect_features() -> u32 {
    let mut f = 0;
    if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
        f |= F_AVX2FMA;
        if is_x86_feature_detected!("avxvnni") {
            f |= F_AVXVNNI;
        }
        if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512bw") {
            f |= F_AVX512;
            if is_x86_feature_detected!("avx512vnni") {
                f |= F_AVX512VNNI;
            }
        }
    }
    f
}

#[cfg(target_arch = "aarch64")]
fn detect_features() -> u32 {
    let mut f = 0;
    if std::arch::is_aarch64_feature_detected!("neon") {
        f |= F_NEON;
        if std::arch::is_aarch64_feature_detected!("dotprod") {
            f |= F_DOT;
            if std::arch::is_aarch64_feature_detected!("i8mm") {
                f |= F_I8MM;
            }
        }
    }
    f
}

#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
fn detect_features() -> u32 {
    0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_only_available_levels_are_taken() {
        for isa in Isa::ALL {
            assert_eq!(Isa::parse(&isa.name().to_uppercase()), Ok(isa));
            let got = Isa::from_name(isa.name());
            if isa.is_available() {
                assert_eq!(got, Ok(isa));
            } else {
                assert!(
                    matches!(got, Err(KernelError::Isa { .. })),
                    "{isa} must be refused"
                );
            }
        }
        assert!(matches!(Isa::parse("sse9"), Err(KernelError::Isa { .. })));
        assert!(Isa::detect().is_available());
        assert!(Isa::available().contains(&Isa::Scalar));
    }

    #[test]
    fn levels_include_their_subsets() {
        assert!(Isa::Avx512Vnni.includes(Isa::Avx512));
        assert!(Isa::Avx512.includes(Isa::Avx2Fma));
        assert!(!Isa::Avx512.includes(Isa::AvxVnni));
        assert!(!Isa::Avx2Fma.includes(Isa::Avx512));
        assert!(Isa::NeonI8mm.includes(Isa::NeonDot));
        assert!(!Isa::Neon.includes(Isa::NeonDot));
        assert!(Isa::ALL.iter().all(|i| i.includes(Isa::Scalar)));
        assert!(Isa::Scalar.is_available());
    }
}
