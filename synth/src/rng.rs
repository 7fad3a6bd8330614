//! Deterministic randomness that does not depend on the thread count.
//!
//! Every random stream is keyed by a hash of *what* it is for — `(seed, frame, pixel, purpose)` —
//! never drawn from a shared generator, so rendering the same frame with 1 or 16 threads, or one
//! pixel alone (as the tests do), gives bit-identical results.

use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;

/// The purposes a stream can be keyed by; distinct values keep streams independent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
pub enum Stream {
    /// Scene layout, materials and lights.
    Scene = 1,
    /// Path sampling of one pixel.
    Pixel = 2,
    /// Sensor noise of one pixel.
    Sensor = 3,
    /// Perturbation of one frame.
    Perturbation = 4,
    /// Motion and drift of a sequence.
    Sequence = 5,
    /// Sensor and scene settings of one shard of a dataset family.
    Family = 6,
}

/// SplitMix64 finaliser: a strong 64-bit mixing function.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hash of a key tuple (order matters).
#[inline]
pub fn hash_key(seed: u64, stream: Stream, a: u64, b: u64) -> u64 {
    let mut h = mix64(seed ^ 0x9e37_79b9_7f4a_7c15);
    h = mix64(h ^ (stream as u64).wrapping_mul(0xd1b5_4a32_d192_ed03));
    h = mix64(h ^ a.wrapping_mul(0x8cb9_2ba7_2f3d_8dd7));
    mix64(h ^ b.wrapping_mul(0xa076_1d64_78bd_642f))
}

/// A seeded `rand` generator for the key (used where `rand_distr` distributions are needed).
pub fn keyed_rng(seed: u64, stream: Stream, a: u64, b: u64) -> Pcg64Mcg {
    Pcg64Mcg::seed_from_u64(hash_key(seed, stream, a, b))
}

/// A tiny, fast SplitMix64 generator for the inner rendering loop.
#[derive(Debug, Clone)]
pub struct FastRng {
    state: u64,
}

impl FastRng {
    pub fn new(key: u64) -> Self {
        FastRng { state: key }
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        mix64(self.state)
    }

    /// Uniform in `[0, 1)` with 53 random bits.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_differ_and_repeat() {
        assert_eq!(
            hash_key(1, Stream::Pixel, 2, 3),
            hash_key(1, Stream::Pixel, 2, 3)
        );
        assert_ne!(
            hash_key(1, Stream::Pixel, 2, 3),
            hash_key(1, Stream::Sensor, 2, 3)
        );
        assert_ne!(
            hash_key(1, Stream::Pixel, 2, 3),
            hash_key(1, Stream::Pixel, 3, 2)
        );
        let mut r = FastRng::new(7);
        let mean = (0..100_000).map(|_| r.uniform()).sum::<f64>() / 1e5;
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
    }
}
