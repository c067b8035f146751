//! Random numbers: PCG32 (O'Neill 2014), and the per-pixel-sample [`Sampler`] of padded,
//! Owen-scrambled Sobol points.
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
pub const fn mix64(mut z: u64) -> u64 {
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
///
/// A pixel sample's numbers are padded, Owen-scrambled Sobol points (Burley 2020): each draw
/// (`next_1d`, `next_2d`, `next_4d`) is one *dimension* of the sample, and over a pixel's
/// samples every dimension is a scrambled Sobol sequence — the first 2^k samples of a pixel
/// place one point in each of 2^k equal intervals of a 1-D draw, in each elementary rectangle
/// of a 2-D one — with the sample index shuffled per dimension so that dimensions are
/// independent of each other. Each number alone is uniform, so estimators stay unbiased, and a
/// pixel's light, BCSDF and lens samples cover their domains evenly. How much noise that takes
/// out depends on how alike the integrands of a pixel's samples are: on hair, whose samples
/// hit different fibers, 7–16 % of dual-mis's variance
/// (docs/src/research/dual-scattering-speed.md#why-not-under-an-environment). Only a sample's first [`STRATIFIED_DRAWS`] draws are stratified — the lens
/// and the first two bounces' light, BCSDF and light-choice numbers, where stratification
/// pays — and the rest come from a PCG32 stream of the sample: a scrambled Sobol draw costs
/// about 15 ns against a PCG draw's 3, which a long path (light hair: tens of bounces, four
/// draws each) would pay at every bounce. Free-standing samplers ([`Sampler::from_seed`]) are
/// independent PCG32 streams.
#[derive(Clone, Debug)]
pub struct Sampler {
    source: Source,
}

#[derive(Clone, Debug)]
enum Source {
    Independent(Pcg32),
    Stratified {
        sequence: PixelSequence,
        /// The draws after the first [`STRATIFIED_DRAWS`].
        tail: Pcg32,
    },
}

/// Draws of a pixel sample that are stratified over the pixel's samples; later ones are
/// independent.
pub const STRATIFIED_DRAWS: u64 = 8;

/// Each stratified draw's key, hashed into its scrambling seeds.
const DIMENSION_KEYS: [u64; STRATIFIED_DRAWS as usize] = {
    let mut keys = [0; STRATIFIED_DRAWS as usize];
    let mut d = 0;
    while d < keys.len() {
        keys[d] = mix64(d as u64);
        d += 1;
    }
    keys
};

/// Where one pixel sample stands in its pixel's padded Sobol sequence.
#[derive(Clone, Debug)]
struct PixelSequence {
    /// Hash of the pixel, the seed and the index's high word.
    pixel: u64,
    /// The sample's index within its pixel (low 32 bits).
    index: u32,
    /// Draws taken so far.
    dimension: u64,
}

impl PixelSequence {
    /// The next draw: the sample's point of an N-D (N ≤ 4) Sobol sequence, with the index
    /// shuffled and each coordinate Owen-scrambled by seeds of this pixel and dimension.
    #[inline]
    fn next_point<const N: usize>(&mut self) -> [f32; N] {
        let h = mix64(self.pixel ^ DIMENSION_KEYS[self.dimension as usize]);
        self.dimension += 1;
        // Owen-scrambling the index permutes every aligned block of 2^k indices within
        // itself, so the first 2^k samples of a pixel are still a Sobol net in every draw.
        let j = owen_scramble(self.index, h as u32);
        let first_seeds = mix64(h);
        let seed = |d: usize| {
            let word = if d < 2 {
                first_seeds
            } else {
                mix64(first_seeds)
            };
            (word >> (32 * (d % 2))) as u32
        };
        std::array::from_fn(|d| to_unit(owen_scramble(sobol(d, j), seed(d))))
    }
}

impl Sampler {
    /// The numbers of sample `sample_index` of pixel (`x`, `y`) under `seed`: stratified over
    /// the pixel's samples (see [`Sampler`]).
    pub fn for_pixel_sample(x: u32, y: u32, sample_index: u64, seed: u64) -> Self {
        let pixel = hash_words(&[x as u64, y as u64, seed, sample_index >> 32]);
        Sampler {
            source: Source::Stratified {
                sequence: PixelSequence {
                    pixel,
                    index: sample_index as u32,
                    dimension: 0,
                },
                tail: Pcg32::new(mix64(pixel ^ sample_index), pixel),
            },
        }
    }

    /// A free-standing sampler of independent numbers (tests, precomputation).
    pub fn from_seed(seed: u64) -> Self {
        Sampler {
            source: Source::Independent(Pcg32::new(mix64(seed), seed)),
        }
    }

    /// Where the next draw comes from: the pixel's stratified sequence for a sample's first
    /// [`STRATIFIED_DRAWS`] draws, an independent stream otherwise.
    #[inline]
    fn next_source(&mut self) -> Result<&mut PixelSequence, &mut Pcg32> {
        match &mut self.source {
            Source::Stratified { sequence, .. } if sequence.dimension < STRATIFIED_DRAWS => {
                Ok(sequence)
            }
            Source::Independent(rng) | Source::Stratified { tail: rng, .. } => Err(rng),
        }
    }

    /// Next uniform number in [0, 1).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        match self.next_source() {
            Ok(sequence) => sequence.next_point::<1>()[0],
            Err(rng) => rng.next_f32(),
        }
    }

    /// Next two uniform numbers, a point in [0, 1)².
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        match self.next_source() {
            Ok(sequence) => Vec2::from_array(sequence.next_point()),
            Err(rng) => Vec2::new(rng.next_f32(), rng.next_f32()),
        }
    }

    /// Next four uniform numbers in [0, 1), as [`crate::Bcsdf::sample`] takes them: one 4-D
    /// Sobol point, so lobe choice and both angles are stratified jointly.
    #[inline]
    pub fn next_4d(&mut self) -> [f32; 4] {
        match self.next_source() {
            Ok(sequence) => sequence.next_point(),
            Err(rng) => std::array::from_fn(|_| rng.next_f32()),
        }
    }
}

/// A 32-bit fixed-point number in [0, 1) as f32: its top 24 bits, exactly representable and
/// below 1.
#[inline]
fn to_unit(u: u32) -> f32 {
    (u >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// Direction numbers of Sobol's first four dimensions (Joe and Kuo's primitive polynomials
/// and initial numbers: x, x + 1, x² + x + 1, x³ + x + 1), one per index bit.
const SOBOL_DIRECTIONS: [[u32; 32]; 4] = [
    sobol_directions(0, 0, &[]),
    sobol_directions(1, 0, &[1]),
    sobol_directions(2, 1, &[1, 3]),
    sobol_directions(3, 1, &[1, 3, 1]),
];

/// Direction numbers of a dimension whose primitive polynomial has degree `degree` and inner
/// coefficients `a` (bit i−1 … 0 for x^(degree−1) … x), with initial odd numbers `m`; degree 0
/// is the van der Corput dimension.
const fn sobol_directions(degree: usize, a: u32, m: &[u32]) -> [u32; 32] {
    let mut v = [0u32; 32];
    let mut k = 0;
    while k < 32 {
        v[k] = if degree == 0 {
            1 << (31 - k)
        } else if k < degree {
            m[k] << (31 - k)
        } else {
            let mut x = v[k - degree] ^ (v[k - degree] >> degree);
            let mut i = 1;
            while i < degree {
                if (a >> (degree - 1 - i)) & 1 == 1 {
                    x ^= v[k - i];
                }
                i += 1;
            }
            x
        };
        k += 1;
    }
    v
}

/// Per dimension and index byte, the XOR of the direction numbers that byte's bits select:
/// a Sobol coordinate is then four table reads instead of a loop over the index's bits (a
/// shuffled index has all 32 of them).
const SOBOL_BYTE_TABLES: [[[u32; 256]; 4]; 4] = {
    let mut tables = [[[0u32; 256]; 4]; 4];
    let mut d = 0;
    while d < 4 {
        let mut byte = 0;
        while byte < 4 {
            let mut value = 0;
            while value < 256 {
                let mut x = 0;
                let mut bit = 0;
                while bit < 8 {
                    if (value >> bit) & 1 == 1 {
                        x ^= SOBOL_DIRECTIONS[d][8 * byte + bit];
                    }
                    bit += 1;
                }
                tables[d][byte][value] = x;
                value += 1;
            }
            byte += 1;
        }
        d += 1;
    }
    tables
};

/// Coordinate `dimension` (0–3) of the `index`-th Sobol point, as 32-bit fixed point.
#[inline]
fn sobol(dimension: usize, index: u32) -> u32 {
    let tables = &SOBOL_BYTE_TABLES[dimension];
    let [b0, b1, b2, b3] = index.to_le_bytes();
    tables[0][b0 as usize]
        ^ tables[1][b1 as usize]
        ^ tables[2][b2 as usize]
        ^ tables[3][b3 as usize]
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
    let i = sample_index as u32;
    Vec2::new(
        to_unit(owen_scramble(sobol(0, i), h as u32)),
        to_unit(owen_scramble(sobol(1, i), (h >> 32) as u32)),
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

    /// One sample's numbers for each of the first `n` samples of a pixel: `take` maps a fresh
    /// sampler to them.
    fn pixel_draws<const D: usize>(
        (x, y, seed): (u32, u32, u64),
        n: u64,
        take: impl Fn(&mut Sampler) -> [f32; D],
    ) -> Vec<[f32; D]> {
        (0..n)
            .map(|i| take(&mut Sampler::for_pixel_sample(x, y, i, seed)))
            .collect()
    }

    /// True when `points` (2^k of them) fill each of the 2^k cells of the grid with `cells[d]`
    /// divisions along coordinate d exactly once.
    fn one_per_cell<const D: usize>(points: &[[f32; D]], cells: [u32; D]) -> bool {
        let mut seen = vec![false; points.len()];
        points.iter().all(|p| {
            let mut cell = 0usize;
            for d in 0..D {
                assert!((0.0..1.0).contains(&p[d]));
                cell = cell * cells[d] as usize + (p[d] * cells[d] as f32) as usize;
            }
            !std::mem::replace(&mut seen[cell], true)
        })
    }

    /// Over a pixel's first 2^k samples, each of a sample's first [`STRATIFIED_DRAWS`] draws is
    /// stratified: 1-D draws one per 1/2^k interval, 2-D draws one per elementary rectangle
    /// (Sobol's first two dimensions are a (0, 2)-sequence), and every coordinate of a 4-D draw
    /// one per interval, the four jointly one per half-cube for 16 samples (Sobol's property A,
    /// which the direction numbers of its dimensions 3 and 4 give; a wrong recurrence breaks
    /// it). The last of them is as stratified as the first.
    #[test]
    fn the_first_draws_of_pixel_samples_are_stratified() {
        for pixel in [(0, 0, 1), (17, 3, 1), (17, 3, 2)] {
            for k in [4u32, 6] {
                let n = 1u64 << k;
                for skip in [0, 1, STRATIFIED_DRAWS - 1] {
                    let ones = pixel_draws(pixel, n, |s| {
                        for _ in 0..skip {
                            s.next_2d();
                        }
                        [s.next_1d()]
                    });
                    assert!(one_per_cell(&ones, [n as u32]), "{pixel:?} 1-D, k = {k}");
                    let twos = pixel_draws(pixel, n, |s| {
                        for _ in 0..skip {
                            s.next_1d();
                        }
                        s.next_2d().to_array()
                    });
                    for a in 0..=k {
                        assert!(
                            one_per_cell(&twos, [1 << a, 1 << (k - a)]),
                            "{pixel:?} 2-D, {}x{}",
                            1 << a,
                            1 << (k - a)
                        );
                    }
                    let fours = pixel_draws(pixel, n, |s| {
                        for _ in 0..skip {
                            s.next_4d();
                        }
                        s.next_4d()
                    });
                    for d in 0..4 {
                        let coordinate: Vec<[f32; 1]> = fours.iter().map(|p| [p[d]]).collect();
                        assert!(one_per_cell(&coordinate, [n as u32]), "4-D coordinate {d}");
                    }
                    assert!(one_per_cell(&fours[..16], [2; 4]), "{pixel:?} property A");
                }
            }
        }
    }

    /// Across pixels a draw is uniform, and consecutive draws of a sample are independent
    /// (their correlation over 10^4 pixels is within noise of zero): at the start, across the
    /// switch from stratified draws to the sample's PCG stream, and within that stream.
    #[test]
    fn pixel_sample_draws_are_uniform_and_independent() {
        let n = 10_000u32;
        for skip in [0, STRATIFIED_DRAWS - 1, STRATIFIED_DRAWS] {
            let mut cells = [0u32; 16];
            let (mut sum_xy, mut sum_x, mut sum_y, mut sum_xx, mut sum_yy) =
                (0.0, 0.0, 0.0, 0.0, 0.0);
            for p in 0..n {
                let mut s = Sampler::for_pixel_sample(p % 100, p / 100, 3, 9);
                for _ in 0..skip {
                    s.next_1d();
                }
                let first = s.next_2d();
                let second = s.next_1d() as f64;
                cells[(first.x * 4.0) as usize + 4 * (first.y * 4.0) as usize] += 1;
                let x = first.x as f64;
                sum_x += x;
                sum_y += second;
                sum_xy += x * second;
                sum_xx += x * x;
                sum_yy += second * second;
            }
            let expected = n as f32 / 16.0;
            for c in cells {
                assert!(
                    (c as f32 - expected).abs() < 4.0 * expected.sqrt(),
                    "after {skip} draws: {cells:?}"
                );
            }
            let nf = n as f64;
            let cov = sum_xy / nf - sum_x / nf * sum_y / nf;
            let var_x = sum_xx / nf - (sum_x / nf).powi(2);
            let var_y = sum_yy / nf - (sum_y / nf).powi(2);
            let correlation = cov / (var_x * var_y).sqrt();
            // One standard error of a correlation over n independent pairs is 1/√n = 0.01.
            assert!(
                correlation.abs() < 0.04,
                "after {skip} draws: correlation {correlation}"
            );
        }
    }

    /// The byte tables give every Sobol coordinate its definition: the XOR of the direction
    /// numbers of the index's set bits.
    #[test]
    fn sobol_coordinates_are_the_xor_of_their_direction_numbers() {
        let mut rng = Pcg32::new(8, 8);
        let indices = (0..64)
            .chain([u32::MAX, 1 << 31])
            .chain((0..1000).map(|_| rng.next_u32()));
        for index in indices {
            for (d, directions) in SOBOL_DIRECTIONS.iter().enumerate() {
                let by_bits = (0..32)
                    .filter(|k| (index >> k) & 1 == 1)
                    .fold(0, |x, k| x ^ directions[k]);
                assert_eq!(sobol(d, index), by_bits, "dimension {d}, index {index}");
            }
        }
        // Dimension 0 is the van der Corput sequence: the index's bits reversed.
        assert_eq!(sobol(0, 0x1234_5678), 0x1234_5678u32.reverse_bits());
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
