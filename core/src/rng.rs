//! Random numbers: PCG32 (O'Neill 2014) and the per-pixel-sample [`Sampler`].
//!
//! Determinism rule: the random stream of a pixel sample is a function of (pixel, sample index,
//! seed) only — never of the thread, the tile or the crop window — so images are bit-identical
//! for any thread count and crop, and sample ranges rendered apart can be merged exactly.

use glam::Vec2;

/// PCG-XSH-RR 32-bit generator with 64-bit state.
#[derive(Clone, Debug)]
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

const PCG_MULT: u64 = 6364136223846793005;

impl Pcg32 {
    /// Generator on stream `stream` starting from `seed`.
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut rng = Pcg32 {
            state: 0,
            inc: (stream << 1) | 1,
        };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(seed);
        rng.next_u32();
        rng
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(PCG_MULT).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in [0, 1): the top 24 bits, so the result is exactly representable and < 1.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
}

/// SplitMix64 finaliser: a bijective 64-bit mix with full avalanche.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d049bb133111eb);
    z ^ (z >> 31)
}

/// Hash of several words (order-sensitive).
pub fn hash_words(words: &[u64]) -> u64 {
    words
        .iter()
        .fold(0x9e3779b97f4a7c15u64, |h, &w| mix64(h ^ mix64(w)))
}

/// The random numbers of one pixel sample.
#[derive(Clone, Debug)]
pub struct Sampler {
    rng: Pcg32,
}

impl Sampler {
    /// The stream for sample `sample_index` of pixel (`x`, `y`) under `seed`.
    pub fn for_pixel_sample(x: u32, y: u32, sample_index: u64, seed: u64) -> Self {
        let pixel_stream = hash_words(&[x as u64, y as u64, seed]);
        let start = hash_words(&[pixel_stream, sample_index]);
        Sampler {
            rng: Pcg32::new(start, pixel_stream),
        }
    }

    /// A free-standing sampler (tests, precomputation).
    pub fn from_seed(seed: u64) -> Self {
        Sampler {
            rng: Pcg32::new(mix64(seed), seed),
        }
    }

    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        self.rng.next_f32()
    }

    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        Vec2::new(self.rng.next_f32(), self.rng.next_f32())
    }

    #[inline]
    pub fn next_4d(&mut self) -> [f32; 4] {
        [
            self.next_1d(),
            self.next_1d(),
            self.next_1d(),
            self.next_1d(),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pcg_is_uniform_enough() {
        let mut s = Sampler::from_seed(3);
        let n = 200_000;
        let mut bins = [0u32; 10];
        let mut sum = 0.0f64;
        for _ in 0..n {
            let u = s.next_1d();
            assert!((0.0..1.0).contains(&u));
            bins[(u * 10.0) as usize] += 1;
            sum += u as f64;
        }
        assert!((sum / n as f64 - 0.5).abs() < 0.005);
        for b in bins {
            assert!((b as f64 / n as f64 - 0.1).abs() < 0.005, "bins {bins:?}");
        }
    }

    #[test]
    fn pixel_streams_differ_and_repeat() {
        let a: Vec<f32> = (0..8)
            .map({
                let mut s = Sampler::for_pixel_sample(1, 2, 3, 4);
                move |_| s.next_1d()
            })
            .collect();
        let b: Vec<f32> = (0..8)
            .map({
                let mut s = Sampler::for_pixel_sample(1, 2, 3, 4);
                move |_| s.next_1d()
            })
            .collect();
        let c: Vec<f32> = (0..8)
            .map({
                let mut s = Sampler::for_pixel_sample(2, 1, 3, 4);
                move |_| s.next_1d()
            })
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
