//! The kernels compiled for this target, as the benchmarks and callers see them: the conv3x3 rows (their
//! own registry, [`crate::conv3x3::registry`], re-exported here) and, for the other families, the ISA levels
//! that have a copy of their own.

pub use crate::conv3x3::registry::*;
use crate::isa::Isa;

/// Every level at which the depthwise filter ([`crate::depthwise()`]) has a path of its own compiled for this
/// target (the CPU may lack some), best first; every other level runs the best of these that it includes.
pub fn depthwise_paths() -> impl Iterator<Item = Isa> {
    crate::depthwise::PATHS.iter().map(|p| p.isa)
}

/// The ISA levels with a copy of their own of the phasor rows ([`crate::phasor::phasors`]), best first.
pub fn phasor_paths() -> impl Iterator<Item = Isa> {
    crate::phasor::PATHS.iter().map(|p| p.isa)
}

/// The ISA levels with a copy of their own of the box means ([`crate::box_blur::box_means`]), best first.
pub fn box_means_paths() -> impl Iterator<Item = Isa> {
    crate::box_blur::PATHS.iter().map(|p| p.isa)
}

#[cfg(test)]
mod tests {
    use crate::dispatch::{assert_best_first_ending_portable, Path};

    fn levels<F>(paths: &[Path<F>]) -> Vec<crate::isa::Isa> {
        paths.iter().map(|p| p.isa).collect()
    }

    /// Every family's paths run best first and end with the portable one: dispatch always finds a path.
    #[test]
    fn every_family_lists_its_levels_best_first_ending_portable() {
        assert_best_first_ending_portable(&levels(crate::depthwise::PATHS));
        assert_best_first_ending_portable(&levels(crate::heads::PATHS));
        assert_best_first_ending_portable(&levels(crate::phasor::PATHS));
        assert_best_first_ending_portable(&levels(crate::box_blur::PATHS));
        assert_best_first_ending_portable(&levels(crate::double_phase::PATHS));
        assert_best_first_ending_portable(&levels(crate::spectral::PATHS));
        assert_best_first_ending_portable(&levels(crate::buffer::rows::PATHS));
    }
}
