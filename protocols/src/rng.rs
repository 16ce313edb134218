//! Seeded randomness with algorithms pinned in this crate.
//!
//! Every random choice of a protocol (shuffles, sides, A/B assignment, which staircase comes
//! next) and of a simulated observer draws from a ChaCha20 stream whose seed is derived from the
//! study seed and a purpose tag. The sampling algorithms (uniform integers, shuffle, normal
//! deviates) are written here rather than taken from `rand` so that a logged seed regenerates the
//! same trials whatever `rand` version a later build links.

use rand_chacha::ChaCha20Rng;
use rand_core::{Rng as _, SeedableRng as _};

/// Purpose tags mixed into derived seeds so that independent choices use independent streams.
pub mod purpose {
    /// The trial plan of one subject (order, sides, repeats, interleaving).
    pub const PLAN: u64 = 0x706c_616e;
    /// Per-trial choices made while a session runs (staircase sides, interleaving).
    pub const TRIAL: u64 = 0x7472_6961;
    /// A simulated observer's per-subject constants (bias).
    pub const OBSERVER_SUBJECT: u64 = 0x6f62_7375;
    /// A simulated observer's answer to one trial.
    pub const OBSERVER_TRIAL: u64 = 0x6f62_7472;
    /// A simulated observer's replays of one screen shown whole (MUSHRA).
    pub const OBSERVER_SCREEN: u64 = 0x6f62_7363;
    /// The order of a live staircase's clips for one subject.
    pub const LIVE_CLIPS: u64 = 0x6c69_7665;
    /// Balanced reference sides of one pair of subjects.
    pub const SIDES: u64 = 0x7369_6465;
}

/// SplitMix64 finaliser (Steele, Lea & Flood 2014), used to mix seeds and tags.
fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Derives a seed from a base seed and a list of tags (subject index, purpose, trial index).
pub fn derive_seed(seed: u64, tags: &[u64]) -> u64 {
    tags.iter()
        .fold(splitmix64(seed), |acc, &t| splitmix64(acc ^ splitmix64(t)))
}

/// A seeded random stream with the few samplers the protocols need.
#[derive(Debug, Clone)]
pub struct StudyRng {
    inner: ChaCha20Rng,
}

impl StudyRng {
    /// A stream for `seed` and `tags` (see [`derive_seed`]).
    pub fn new(seed: u64, tags: &[u64]) -> Self {
        Self {
            inner: ChaCha20Rng::seed_from_u64(derive_seed(seed, tags)),
        }
    }

    /// Next raw 64-bit value.
    pub fn next_u64(&mut self) -> u64 {
        self.inner.next_u64()
    }

    /// Uniform integer in `0..n` (Lemire's nearly-divisionless method with rejection); 0 when
    /// `n` is 0.
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 {
            return 0;
        }
        let threshold = n.wrapping_neg() % n;
        loop {
            let m = u128::from(self.next_u64()) * u128::from(n);
            if (m as u64) >= threshold {
                return (m >> 64) as u64;
            }
        }
    }

    /// Uniform index in `0..len`.
    pub fn index(&mut self, len: usize) -> usize {
        self.below(len as u64) as usize
    }

    /// Uniform float in `[0, 1)` with 53 random bits.
    pub fn unit_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1_u64 << 53) as f64)
    }

    /// `true` with probability one half.
    pub fn coin(&mut self) -> bool {
        self.next_u64() >> 63 == 1
    }

    /// Fisher-Yates shuffle in place.
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            let j = self.index(i + 1);
            items.swap(i, j);
        }
    }

    /// Standard normal deviate (Box-Muller, one of the pair).
    pub fn normal(&mut self) -> f64 {
        // 1 - u is in (0, 1], so the logarithm is finite.
        let u1 = 1.0 - self.unit_f64();
        let u2 = self.unit_f64();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn below_stays_in_range_and_covers_it() {
        let mut rng = StudyRng::new(7, &[1]);
        let mut seen = [0_u32; 5];
        for _ in 0..5000 {
            let v = rng.below(5);
            assert!(v < 5);
            seen[v as usize] += 1;
        }
        assert!(seen.iter().all(|&c| c > 800), "{seen:?}");
    }

    #[test]
    fn same_seed_same_stream_other_tag_other_stream() {
        let a: Vec<u64> = (0..4)
            .map({
                let mut r = StudyRng::new(3, &[9]);
                move |_| r.next_u64()
            })
            .collect();
        let b: Vec<u64> = (0..4)
            .map({
                let mut r = StudyRng::new(3, &[9]);
                move |_| r.next_u64()
            })
            .collect();
        let c: Vec<u64> = (0..4)
            .map({
                let mut r = StudyRng::new(3, &[10]);
                move |_| r.next_u64()
            })
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn normal_has_unit_variance() {
        let mut rng = StudyRng::new(11, &[]);
        let n = 20_000;
        let xs: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let mean = xs.iter().sum::<f64>() / f64::from(n);
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / f64::from(n - 1);
        assert!(mean.abs() < 0.03, "{mean}");
        assert!((var - 1.0).abs() < 0.05, "{var}");
    }
}
