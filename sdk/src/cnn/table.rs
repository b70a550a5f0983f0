//! The plan table: how a session's CNN plans are decided when nothing is timed ([`PlanSource::Table`], the
//! default). Every decision is a function of what does not change between runs (the build, the CPU's
//! features, the layer shapes, the size and the thread count), so the same command gives the same bits in
//! every process, whatever else the machine is doing. The entries come from benchmarks; each says where.
//!
//! | decision | the table | measured |
//! |---|---|---|
//! | engine ([`CnnEngine::Auto`]) | native wherever it runs the files; tract for int8 QOperator files, and for int8 files on the portable rows | [`engine`] |
//! | tract's layout ([`CnnLayout::Auto`]) | channels-first on x86-64; channels-last on aarch64 where tract can move the graph | [`tract_layout`] |
//! | threads ([`ThreadCount::Auto`](super::ThreadCount::Auto)) | the cores the CPU reports ([`super::default_threads`]) | `options.rs` |
//! | each f32 layer's kernel row (direct or Winograd, which tile) | [`ROWS`], per ISA class and layer shape; otherwise [`default_algorithm`]'s first row | each entry's `measured` |
//! | strips and column slabs (native engine) | rules of the plan's geometry: `native/strips.rs` (rows within a window budget), `native/slabs.rs` (slabs within a row budget) | their constants' docs |
//!
//! With [`PlanSource::Tune`] the same decisions are timed on the machine instead (`native/algorithm.rs`,
//! `select.rs`, `tract/`). To remake a row of this table on a machine: `benchmarks/plan_table.sh` runs
//! `holo render --tune` several times per network and ISA level and counts what the tunings chose.
//!
//! [`PlanSource::Table`]: super::PlanSource::Table
//! [`PlanSource::Tune`]: super::PlanSource::Tune

use tensorholo_kernels::{registry, Algorithm, Isa};

use super::options::{CnnEngine, ConvAlgorithm};

/// Where the AVX-512 rows were measured: the timed choice (`PlanSource::Tune`) of 7–49 processes per shape.
const ZEN4_AVX512: &str = "AMD EPYC Zen 4 (family 25, model 17; 2 vCPUs), AVX-512: the row most of 7–49 \
     processes' timing chose (16 × 384 band, best of 5 alternated runs; benchmarks/plan_table.sh HOLO 7, \
     2026-11-27)";
/// Where the AVX2 rows were measured.
const ZEN4_AVX2: &str =
    "the same Zen 4 under TENSORHOLO_ISA=avx2 (the AVX2 rows on an AVX-512 core; no \
     AVX2-only CPU measured): the row most processes' timing chose (benchmarks/plan_table.sh)";
/// Where the portable rows were measured.
const ZEN4_SCALAR: &str =
    "the same Zen 4 under TENSORHOLO_ISA=scalar: the row most processes' timing chose \
     (benchmarks/plan_table.sh)";
/// Where the NEON rows were measured.
const QEMU_NEON: &str = "guest instructions under qemu-aarch64 (no ARM hardware): one 24→24 layer F(4×4, 3×3) \
     5.04 M, F(2×2, 3×3) 6.88 M, direct 10.15 M; a holo8 frame with its pre-filter 322 / 418 / 519 M \
     (docs/BENCHMARKS.md)";

/// One entry: under ISA class `class` ([`f32_class`]), a `c_in → c_out` layer chosen among `algorithms` runs
/// `row`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RowEntry {
    pub(crate) class: Isa,
    pub(crate) c_in: usize,
    pub(crate) c_out: usize,
    pub(crate) algorithms: ConvAlgorithm,
    pub(crate) row: &'static str,
    pub(crate) measured: &'static str,
}

const fn entry(
    class: Isa,
    (c_in, c_out): (usize, usize),
    algorithms: ConvAlgorithm,
    row: &'static str,
    measured: &'static str,
) -> RowEntry {
    RowEntry {
        class,
        c_in,
        c_out,
        algorithms,
        row,
        measured,
    }
}

use ConvAlgorithm::{Auto, Direct};

/// The measured rows: every f32 layer shape of the shipped networks (hologram CNNs 4→24, 24→24, 28→6; the LDI
/// CNN 20→24, 44→6; the pre-filters 6→8, 8→8, 14→6; the int8 pre-filters' f32 first and last layers, direct
/// only) per ISA class.
pub(crate) const ROWS: &[RowEntry] = &[
    // AVX-512 (both levels: VNNI changes only the int8 rows).
    entry(
        Isa::Avx512,
        (4, 24),
        Auto,
        "conv3x3.f32.wino4x4.24x1.avx512",
        ZEN4_AVX512,
    ),
    entry(
        Isa::Avx512,
        (24, 24),
        Auto,
        "conv3x3.f32.wino4x4.24x1.avx512",
        ZEN4_AVX512,
    ),
    entry(
        Isa::Avx512,
        (28, 6),
        Auto,
        "conv3x3.f32.wino4x4.8x1.avx512",
        ZEN4_AVX512,
    ),
    entry(
        Isa::Avx512,
        (20, 24),
        Auto,
        "conv3x3.f32.wino4x4.24x1.avx512",
        ZEN4_AVX512,
    ),
    entry(
        Isa::Avx512,
        (44, 6),
        Auto,
        "conv3x3.f32.wino4x4.8x1.avx512",
        ZEN4_AVX512,
    ),
    entry(
        Isa::Avx512,
        (6, 8),
        Auto,
        "conv3x3.f32.wino4x4.8x1.avx512",
        ZEN4_AVX512,
    ),
    entry(
        Isa::Avx512,
        (8, 8),
        Auto,
        "conv3x3.f32.wino4x4.8x1.avx512",
        ZEN4_AVX512,
    ),
    entry(
        Isa::Avx512,
        (14, 6),
        Auto,
        "conv3x3.f32.wino4x4.8x1.avx512",
        ZEN4_AVX512,
    ),
    entry(
        Isa::Avx512,
        (6, 8),
        Direct,
        "conv3x3.f32.8x3.avx512",
        ZEN4_AVX512,
    ),
    entry(
        Isa::Avx512,
        (14, 6),
        Direct,
        "conv3x3.f32.6x4.avx512",
        ZEN4_AVX512,
    ),
    // AVX2 + FMA (both levels).
    entry(
        Isa::Avx2Fma,
        (4, 24),
        Auto,
        "conv3x3.f32.wino4x4.6x2.avx2",
        ZEN4_AVX2,
    ),
    entry(
        Isa::Avx2Fma,
        (24, 24),
        Auto,
        "conv3x3.f32.wino4x4.6x2.avx2",
        ZEN4_AVX2,
    ),
    entry(
        Isa::Avx2Fma,
        (28, 6),
        Auto,
        "conv3x3.f32.6x2.avx2",
        ZEN4_AVX2,
    ),
    entry(
        Isa::Avx2Fma,
        (20, 24),
        Auto,
        "conv3x3.f32.wino4x4.6x2.avx2",
        ZEN4_AVX2,
    ),
    entry(
        Isa::Avx2Fma,
        (44, 6),
        Auto,
        "conv3x3.f32.wino2x2.6x2.avx2",
        ZEN4_AVX2,
    ),
    entry(
        Isa::Avx2Fma,
        (6, 8),
        Auto,
        "conv3x3.f32.wino4x4.6x2.avx2",
        ZEN4_AVX2,
    ),
    entry(
        Isa::Avx2Fma,
        (8, 8),
        Auto,
        "conv3x3.f32.wino4x4.6x2.avx2",
        ZEN4_AVX2,
    ),
    entry(
        Isa::Avx2Fma,
        (14, 6),
        Auto,
        "conv3x3.f32.6x2.avx2",
        ZEN4_AVX2,
    ),
    entry(
        Isa::Avx2Fma,
        (6, 8),
        Direct,
        "conv3x3.f32.6x2.avx2",
        ZEN4_AVX2,
    ),
    entry(
        Isa::Avx2Fma,
        (14, 6),
        Direct,
        "conv3x3.f32.6x2.avx2",
        ZEN4_AVX2,
    ),
    // NEON (every aarch64 level).
    entry(
        Isa::Neon,
        (4, 24),
        Auto,
        "conv3x3.f32.wino4x4.8x3.neon",
        QEMU_NEON,
    ),
    entry(
        Isa::Neon,
        (24, 24),
        Auto,
        "conv3x3.f32.wino4x4.8x3.neon",
        QEMU_NEON,
    ),
    entry(
        Isa::Neon,
        (28, 6),
        Auto,
        "conv3x3.f32.wino4x4.8x3.neon",
        QEMU_NEON,
    ),
    entry(
        Isa::Neon,
        (20, 24),
        Auto,
        "conv3x3.f32.wino4x4.8x3.neon",
        QEMU_NEON,
    ),
    entry(
        Isa::Neon,
        (44, 6),
        Auto,
        "conv3x3.f32.wino4x4.8x3.neon",
        QEMU_NEON,
    ),
    entry(
        Isa::Neon,
        (6, 8),
        Auto,
        "conv3x3.f32.wino4x4.8x3.neon",
        QEMU_NEON,
    ),
    entry(
        Isa::Neon,
        (8, 8),
        Auto,
        "conv3x3.f32.wino4x4.8x3.neon",
        QEMU_NEON,
    ),
    entry(
        Isa::Neon,
        (14, 6),
        Auto,
        "conv3x3.f32.wino4x4.8x3.neon",
        QEMU_NEON,
    ),
    entry(Isa::Neon, (6, 8), Direct, "conv3x3.f32.8x3.neon", QEMU_NEON),
    entry(
        Isa::Neon,
        (14, 6),
        Direct,
        "conv3x3.f32.8x3.neon",
        QEMU_NEON,
    ),
    // The portable rows.
    entry(
        Isa::Scalar,
        (4, 24),
        Auto,
        "conv3x3.f32.wino4x4.4x4.scalar",
        ZEN4_SCALAR,
    ),
    entry(
        Isa::Scalar,
        (24, 24),
        Auto,
        "conv3x3.f32.wino4x4.4x4.scalar",
        ZEN4_SCALAR,
    ),
    entry(
        Isa::Scalar,
        (28, 6),
        Auto,
        "conv3x3.f32.wino4x4.4x4.scalar",
        ZEN4_SCALAR,
    ),
    entry(
        Isa::Scalar,
        (20, 24),
        Auto,
        "conv3x3.f32.wino4x4.4x4.scalar",
        ZEN4_SCALAR,
    ),
    entry(
        Isa::Scalar,
        (44, 6),
        Auto,
        "conv3x3.f32.wino4x4.4x4.scalar",
        ZEN4_SCALAR,
    ),
    entry(
        Isa::Scalar,
        (6, 8),
        Auto,
        "conv3x3.f32.wino4x4.4x4.scalar",
        ZEN4_SCALAR,
    ),
    entry(
        Isa::Scalar,
        (8, 8),
        Auto,
        "conv3x3.f32.wino4x4.4x4.scalar",
        ZEN4_SCALAR,
    ),
    entry(
        Isa::Scalar,
        (14, 6),
        Auto,
        "conv3x3.f32.wino4x4.4x4.scalar",
        ZEN4_SCALAR,
    ),
    entry(
        Isa::Scalar,
        (6, 8),
        Direct,
        "conv3x3.f32.8x8.scalar",
        ZEN4_SCALAR,
    ),
    entry(
        Isa::Scalar,
        (14, 6),
        Direct,
        "conv3x3.f32.8x8.scalar",
        ZEN4_SCALAR,
    ),
];

/// The ISA level whose f32 rows `isa` runs (the f32 rows do not use VNNI, the dot product or i8mm): AVX-512
/// for both AVX-512 levels, AVX2 for AVX2 and AVX-VNNI, NEON for every aarch64 level.
pub(crate) fn f32_class(isa: Isa) -> Isa {
    match isa {
        Isa::Avx512 | Isa::Avx512Vnni => Isa::Avx512,
        Isa::Avx2Fma | Isa::AvxVnni => Isa::Avx2Fma,
        Isa::Neon | Isa::NeonDot | Isa::NeonI8mm => Isa::Neon,
        Isa::Scalar => Isa::Scalar,
    }
}

/// The algorithm of a layer shape the table does not list: F(4×4, 3×3), which won every listed shape but the
/// AVX2 rows of 6-channel outputs; direct there (output channels under 8 on AVX2); the one algorithm of a
/// pinned set.
pub(crate) fn default_algorithm(isa: Isa, c_out: usize, algorithms: ConvAlgorithm) -> Algorithm {
    match algorithms {
        ConvAlgorithm::Auto if f32_class(isa) == Isa::Avx2Fma && c_out < 8 => Algorithm::Direct,
        ConvAlgorithm::Auto => Algorithm::Winograd4x4,
        set => set.algorithms()[0],
    }
}

/// The table's kernel row, and where it was measured, for a `c_in → c_out` f32 layer chosen among
/// `algorithms` under `isa`: the entry of `isa`'s class ([`ROWS`]); for a pinned algorithm, the entry chosen
/// among every algorithm where it is of that algorithm; otherwise the first row of [`default_algorithm`]
/// (`tensorholo_kernels::registry::f32_rows_of`: the least channel padding). Always a row `isa` may run.
pub(crate) fn row(
    isa: Isa,
    c_in: usize,
    c_out: usize,
    algorithms: ConvAlgorithm,
) -> (&'static str, &'static str) {
    let runnable = |name: &str| {
        algorithms
            .algorithms()
            .iter()
            .flat_map(|&alg| registry::f32_rows_of(isa, c_out, alg))
            .any(|k| k.name == name)
    };
    let class = f32_class(isa);
    let listed = |set: ConvAlgorithm| {
        ROWS.iter()
            .find(|e| e.class == class && (e.c_in, e.c_out, e.algorithms) == (c_in, c_out, set))
            .filter(|e| runnable(e.row))
    };
    if let Some(e) = listed(algorithms).or_else(|| listed(ConvAlgorithm::Auto)) {
        return (e.row, e.measured);
    }
    let alg = default_algorithm(isa, c_out, algorithms);
    let first = registry::f32_rows_of(isa, c_out, alg)
        .next()
        .map_or_else(|| registry::selected_f32_for(isa, c_out).name, |k| k.name);
    (
        first,
        "not measured: the default algorithm's row with the least channel padding",
    )
}

/// The table's engine for networks that `native` and `tract` (whether this build has each and it runs the
/// files) can run, `int8` where one of them is int8, with the native kernels at `isa`: the engine and why.
/// `None` where neither can.
///
/// Measured: native 2.3–3.5× tract's best in f32 and 11–20× in int8 on Zen 3, Zen 4 and Zen 5
/// (docs/BENCHMARKS.md); on ARM 2.3× fewer instructions than tract for holo8 (qemu-aarch64 guest
/// instructions, no ARM hardware); on the portable rows (`TENSORHOLO_ISA=scalar`, Zen 4, holo8 at 384², 2
/// threads, `holo bench --skip-pipeline --engine native,tract`) native f32 110.9 ms against tract 194.4, but
/// int8 QDQ 1075.5 ms against tract 253.1.
pub(crate) fn engine(
    isa: Isa,
    int8: bool,
    native: bool,
    tract: bool,
) -> Option<(CnnEngine, String)> {
    let portable_int8 = isa == Isa::Scalar && int8;
    match (native, tract) {
        (true, true) if portable_int8 => Some((
            CnnEngine::Tract,
            "the plan table: tract for int8 files on the portable rows (4.3× the native portable int8 rows)"
                .into(),
        )),
        (true, _) => Some((
            CnnEngine::Native,
            format!(
                "the plan table: the native engine on its {} rows (2.3–20× tract's best wherever measured)",
                isa.name()
            ),
        )),
        (false, true) => Some((
            CnnEngine::Tract,
            "the plan table: tract, the only engine of this build that runs these files".into(),
        )),
        (false, false) => None,
    }
}

/// The table's tract layout on this architecture; a graph tract cannot move channels-last (int8 QOperator
/// files) then runs channels-first.
///
/// Measured: x86-64, `holo bench --skip-pipeline --engine tract --layout nchw,nhwc`, Zen 4, 2 threads, holo8:
/// f32 177 / 376 ms at 384² and 3020 / 4966 ms at 1080p, int8 QDQ 294 / 459 and 3973 / 6268 (nchw / nhwc);
/// aarch64: a holo8 frame at 192² 873 M guest instructions channels-last against 1315 M channels-first under
/// qemu (docs/BENCHMARKS.md).
#[cfg(feature = "tract")]
pub(crate) fn tract_layout() -> super::options::CnnLayout {
    use super::options::CnnLayout;
    if cfg!(target_arch = "aarch64") {
        CnnLayout::ChannelsLast
    } else {
        CnnLayout::ChannelsFirst
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_entry_names_a_row_of_its_class_and_algorithms() {
        // The entries of this target's classes (the NEON rows exist in aarch64 builds only; CI runs these
        // tests under qemu-aarch64 too).
        let compiled = |class: Isa| registry::f32_kernels().any(|k| f32_class(k.isa) == class);
        let mut checked = 0;
        for e in ROWS.iter().filter(|e| compiled(e.class)) {
            checked += 1;
            let k = registry::f32_kernels()
                .find(|k| k.name == e.row)
                .unwrap_or_else(|| panic!("{}: no such row", e.row));
            assert!(
                e.algorithms.algorithms().contains(&k.algorithm),
                "{}: not of {}",
                e.row,
                e.algorithms.name()
            );
            assert!(e.class.includes(k.isa), "{}", e.row);
            assert!(!e.measured.is_empty());
        }
        assert!(checked >= 20, "{checked} entries of this target's classes");
        // No shape listed twice for one class and set.
        for (i, a) in ROWS.iter().enumerate() {
            for b in &ROWS[i + 1..] {
                assert!(
                    (a.class, a.c_in, a.c_out, a.algorithms)
                        != (b.class, b.c_in, b.c_out, b.algorithms),
                    "{a:?} twice"
                );
            }
        }
    }

    #[test]
    fn the_table_gives_its_entries_and_runnable_defaults() {
        for isa in Isa::available() {
            for e in ROWS.iter().filter(|e| e.class == f32_class(isa)) {
                assert_eq!(row(isa, e.c_in, e.c_out, e.algorithms).0, e.row);
            }
            // A pinned algorithm takes the listed row where it is of that algorithm, else its first row.
            for (c_in, c_out) in [(24, 24), (3, 5), (64, 6)] {
                for set in [
                    ConvAlgorithm::Auto,
                    ConvAlgorithm::Direct,
                    ConvAlgorithm::Winograd2x2,
                    ConvAlgorithm::Winograd4x4,
                ] {
                    let (name, _) = row(isa, c_in, c_out, set);
                    let k = registry::f32_kernels().find(|k| k.name == name).unwrap();
                    assert!(
                        set.algorithms().contains(&k.algorithm),
                        "{name} for {set:?}"
                    );
                    assert!(isa.includes(k.isa), "{name} under {}", isa.name());
                }
            }
        }
        // Unlisted shapes: F(4×4, 3×3), but direct for 6-channel outputs on AVX2.
        assert_eq!(
            default_algorithm(Isa::Avx512, 6, ConvAlgorithm::Auto),
            Algorithm::Winograd4x4
        );
        assert_eq!(
            default_algorithm(Isa::AvxVnni, 6, ConvAlgorithm::Auto),
            Algorithm::Direct
        );
        assert_eq!(
            default_algorithm(Isa::Avx2Fma, 6, ConvAlgorithm::Winograd2x2),
            Algorithm::Winograd2x2
        );
    }

    #[test]
    fn the_engine_rule_prefers_native_but_for_portable_int8() {
        let native = |isa, int8| engine(isa, int8, true, true).unwrap().0;
        assert_eq!(native(Isa::Avx512Vnni, true), CnnEngine::Native);
        assert_eq!(native(Isa::NeonDot, true), CnnEngine::Native);
        assert_eq!(native(Isa::Scalar, false), CnnEngine::Native);
        assert_eq!(native(Isa::Scalar, true), CnnEngine::Tract);
        assert_eq!(
            engine(Isa::Scalar, true, true, false).unwrap().0,
            CnnEngine::Native
        );
        assert_eq!(
            engine(Isa::Avx2Fma, true, false, true).unwrap().0,
            CnnEngine::Tract
        );
        assert!(engine(Isa::Avx2Fma, false, false, false).is_none());
    }
}
