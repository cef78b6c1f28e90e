//! The small random number generator every layer may use: reproducible streams for sampling,
//! for generated test meshes and for benchmark rays.

/// SplitMix64 (Steele, Lea and Flood 2014): a tiny generator whose every seed gives a good
/// stream. Used to seed per-pixel streams and to make deterministic test data.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator started from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.0)
    }

    /// A uniform float in `[0, 1)` (24 random bits).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }
}

/// The SplitMix64 finalizer: a good 64-bit hash, used to derive independent seeds
/// (for example one per pixel, so an image does not depend on the thread count).
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
