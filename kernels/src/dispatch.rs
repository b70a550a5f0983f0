//! The dispatch rule every kernel family shares. A family lists its [`Path`]s, one per ISA level that has a
//! copy of its own, best level first and the portable path last, next to its safe API (`depthwise/mod.rs`,
//! `heads/mod.rs`, `phasor/mod.rs`, `double_phase/mod.rs`, `spectral/mod.rs`, `buffer/rows.rs`, the peak
//! loops in `peak.rs`; the conv3x3 rows, which carry more than a level, in `conv3x3/table.rs`). Under a
//! selected level `s` it runs the first path whose level `s` includes ([`pick`]): a level lists only what
//! its instructions compile, a lower level's copy serves the rest, and the portable path serves any CPU
//! (e.g. `avx512vnni` runs the `avx512` heads).
//!
//! [`pick`] is the check behind every call of a kernel through `unsafe` outside the ISA files: the level
//! asked for is available on this CPU, and it includes the level of the path returned.

use crate::error::KernelError;
use crate::isa::Isa;

/// One ISA level's copy of a family's kernels: the level they need and the entry (a function, or the
/// family's struct of functions).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Path<F> {
    /// The level every function of `run` needs.
    pub isa: Isa,
    /// The kernels.
    pub run: F,
}

/// The entry of the best of `paths` (best first) that `isa` includes. Errors: `isa` not available on this
/// CPU ([`KernelError::Isa`]), or no path under it (never for a table that ends with the portable path).
pub(crate) fn pick<F: Copy>(paths: &[Path<F>], isa: Isa) -> Result<F, KernelError> {
    if !isa.is_available() {
        return Err(KernelError::Isa {
            name: isa.name().into(),
            why: "not available on this CPU",
        });
    }
    paths
        .iter()
        .find(|p| isa.includes(p.isa))
        .map(|p| p.run)
        .ok_or_else(|| KernelError::Isa {
            name: isa.name().into(),
            why: "no kernel of this kind compiled for it",
        })
}

/// Tests: the levels of `paths` that this CPU has (a `SKIPPED` line for each it lacks), as `(name, level)`,
/// best first.
#[cfg(test)]
pub(crate) fn available_paths<F>(module: &str, paths: &[Path<F>]) -> Vec<(String, Isa)> {
    paths
        .iter()
        .map(|p| p.isa)
        .filter(|i| {
            let ok = i.is_available();
            if !ok {
                println!("SKIPPED {module}.{i}: this CPU lacks {i}");
            }
            ok
        })
        .map(|i| (format!("{module}.{i}"), i))
        .collect()
}

/// Tests: the levels of a table run best first (none includes a later one without being it) and end with
/// the portable level, so that dispatch always finds a path.
#[cfg(test)]
pub(crate) fn assert_best_first_ending_portable(levels: &[Isa]) {
    for (i, a) in levels.iter().enumerate() {
        for b in &levels[..i] {
            assert!(!a.includes(*b), "{a} listed after {b}");
        }
    }
    assert_eq!(levels.last(), Some(&Isa::Scalar), "{levels:?}");
}
