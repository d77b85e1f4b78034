//! Deterministic noise for tests (xorshift64), so tests need no RNG crate and every run sees the
//! same samples.

use glam::Vec3;

/// A xorshift64 generator seeded by its field (use a non-zero seed).
pub(crate) struct Noise(pub u64);

impl Noise {
    /// The next sample, uniform in [−1, 1].
    pub fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 % 2_000_001) as f32 / 1_000_000.0 - 1.0
    }

    /// Three samples as a vector, each in [−1, 1].
    pub fn vec(&mut self) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next())
    }
}
