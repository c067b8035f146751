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

    /// Next uniformly distributed 32-bit word.
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

    /// Next uniform number in [0, 1).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        self.rng.next_f32()
    }

    /// Next two uniform numbers, a point in [0, 1)².
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        Vec2::new(self.rng.next_f32(), self.rng.next_f32())
    }

    /// Next four uniform numbers in [0, 1), as [`crate::Bcsdf::sample`] takes them.
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

/// Where in pixel (`x`, `y`) sample `sample_index` looks, in [0, 1)²: the 2-D Sobol sequence
/// (a (0, 2)-sequence: the first 2^k samples of a pixel fall one in each of any 2^k equal
/// elementary rectangles), Owen-scrambled per pixel and seed. Each point alone is uniform, so
/// estimates stay unbiased, and pixels stay independent; but a pixel's samples cover it evenly,
/// which takes out most of the variance of which fibers a pixel's rays hit — the dominant noise
/// of hair once the shading itself is smooth (dual scattering). Depends only on the sample's
/// index, so sample ranges rendered apart (`--spp-offset`, farms) add up exactly as before.
pub fn pixel_position(x: u32, y: u32, sample_index: u64, seed: u64) -> Vec2 {
    let h = hash_words(&[x as u64, y as u64, seed, 0x0070_6978_656c]);
    // Sobol's first two dimensions for a 32-bit index: its bit reversal, and the Pascal-matrix
    // dimension.
    let i = sample_index as u32;
    let first = i.reverse_bits();
    let mut second = 0u32;
    let mut v = 1u32 << 31;
    let mut bits = i;
    while bits != 0 {
        if bits & 1 != 0 {
            second ^= v;
        }
        bits >>= 1;
        v ^= v >> 1;
    }
    let to_unit = |u: u32| (u >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
    Vec2::new(
        to_unit(owen_scramble(first, h as u32)),
        to_unit(owen_scramble(second, (h >> 32) as u32)),
    )
}

/// Nested uniform (Owen) scrambling of a 32-bit fixed-point number: Laine and Karras's hash
/// permutes each bit depending on the bits above it (applied to the bit-reversed value).
fn owen_scramble(v: u32, seed: u32) -> u32 {
    let mut x = v.reverse_bits();
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x.reverse_bits()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first 2^k positions of a pixel fill every cell of every 2^a × 2^(k−a) grid exactly
    /// once, for any pixel and seed; across pixels the positions are uniform.
    #[test]
    fn pixel_positions_are_stratified_and_uniform() {
        for (x, y, seed) in [(0, 0, 1), (17, 3, 1), (17, 3, 2)] {
            for k in [4u32, 6] {
                let n = 1u64 << k;
                let points: Vec<Vec2> = (0..n).map(|i| pixel_position(x, y, i, seed)).collect();
                for a in 0..=k {
                    let (cols, rows) = (1u32 << a, 1u32 << (k - a));
                    let mut seen = vec![false; n as usize];
                    for p in &points {
                        assert!((0.0..1.0).contains(&p.x) && (0.0..1.0).contains(&p.y));
                        let cell = (p.x * cols as f32) as u32 + cols * (p.y * rows as f32) as u32;
                        assert!(
                            !seen[cell as usize],
                            "pixel ({x},{y}) seed {seed}: {cols}x{rows}"
                        );
                        seen[cell as usize] = true;
                    }
                }
            }
        }
        // The same sample index in 10^4 pixels: uniform over the unit square (4×4 cells).
        let mut cells = [0u32; 16];
        for p in 0..10_000u32 {
            let q = pixel_position(p % 100, p / 100, 5, 9);
            cells[(q.x * 4.0) as usize + 4 * (q.y * 4.0) as usize] += 1;
        }
        for c in cells {
            assert!((c as f32 - 625.0).abs() < 4.0 * 25.0, "{cells:?}");
        }
    }

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
