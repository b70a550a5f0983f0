//! SplitMix64 (Steele, Lea, Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014; the
//! reference C code is Vigna's `splitmix64.c`): a 64-bit-state generator whose outputs are fixed by the
//! algorithm, not by a crate version. Shared by the Table 2 focal depths ([`crate::evaluation`]) and the
//! dataset's seed derivation (`dataset::sample_seed`, feature `research`), so that the core library needs
//! no random-number crate.

/// Golden-ratio increment of the SplitMix64 state (`⌊2⁶⁴/φ⌋`, odd).
const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// The SplitMix64 output of state `x`: `x + γ` through the two xor-shift-multiply rounds of the
/// reference code (a bijection of `u64`). Equals the first output of [`SplitMix64::new`]`(x)`; the
/// dataset's `sample_seed` calls it the "SplitMix64 finaliser".
pub(crate) fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(GAMMA);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A seeded SplitMix64 stream.
#[derive(Debug, Clone)]
pub(crate) struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// The stream of seed `seed` (the reference code's initial state).
    pub(crate) fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// Next 64 random bits.
    pub(crate) fn next_u64(&mut self) -> u64 {
        let out = splitmix64(self.state);
        self.state = self.state.wrapping_add(GAMMA);
        out
    }

    /// Uniform `f64` in `[0, 1)`: the top 53 bits times `2⁻⁵³`.
    pub(crate) fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform integer in `[lo, hi)`, without bias (Lemire's multiply-shift with rejection, "Fast Random
    /// Integer Generation in an Interval", ACM TOMACS 2019). Returns `lo` for an empty range.
    pub(crate) fn below(&mut self, lo: usize, hi: usize) -> usize {
        let n = hi.saturating_sub(lo) as u64;
        if n == 0 {
            return lo;
        }
        let mut m = u128::from(self.next_u64()) * u128::from(n);
        if (m as u64) < n {
            // 2⁶⁴ mod n: the low products below it belong to an incomplete last period.
            let threshold = n.wrapping_neg() % n;
            while (m as u64) < threshold {
                m = u128::from(self.next_u64()) * u128::from(n);
            }
        }
        // (m >> 64) < n ≤ hi − lo, so the sum stays within usize.
        lo + (m >> 64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_published_reference_outputs() {
        // First outputs of Vigna's splitmix64.c with state 0 (the xoshiro seeding example).
        let mut g = SplitMix64::new(0);
        let got: Vec<u64> = (0..4).map(|_| g.next_u64()).collect();
        assert_eq!(
            got,
            [
                0xE220_A839_7B1D_CDAF,
                0x6E78_9E6A_A1B9_65F4,
                0x06C4_5D18_8009_454F,
                0xF88B_B8A8_724C_81EC
            ]
        );
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
    }

    #[test]
    fn floats_lie_in_the_unit_interval_with_the_uniform_mean() {
        let mut g = SplitMix64::new(42);
        let n = 100_000;
        let xs: Vec<f64> = (0..n).map(|_| g.next_f64()).collect();
        assert!(xs.iter().all(|x| (0.0..1.0).contains(x)));
        let mean = xs.iter().sum::<f64>() / n as f64;
        // Standard error of the mean of U(0,1): √(1/12/n) ≈ 0.0009; 5σ.
        assert!((mean - 0.5).abs() < 0.0046, "mean {mean}");
    }

    #[test]
    fn bounded_integers_are_in_range_and_uniform() {
        let mut g = SplitMix64::new(7);
        let (lo, hi) = (3usize, 10usize);
        let n = 70_000;
        let mut counts = [0usize; 7];
        for _ in 0..n {
            let v = g.below(lo, hi);
            assert!((lo..hi).contains(&v));
            counts[v - lo] += 1;
        }
        // Chi-square with 6 degrees of freedom: 22.5 is its 0.999 quantile.
        let e = n as f64 / 7.0;
        let chi2: f64 = counts.iter().map(|&c| (c as f64 - e).powi(2) / e).sum();
        assert!(chi2 < 22.5, "counts {counts:?}, chi² {chi2}");
        assert_eq!(g.below(5, 5), 5);
        assert_eq!(g.below(5, 6), 5);
        // A range spanning almost all of u64 still lands inside.
        let v = g.below(1, usize::MAX);
        assert!((1..usize::MAX).contains(&v));
    }
}
