//! THE render loop: rayon over fixed tiles, per-pixel-sample seeding, box filter, statistics,
//! and the exact per-pixel sample sums that let renders of sample ranges, waves and tiles be
//! merged bit for bit.
//!
//! Every pixel sample takes its position in the pixel from `rng::pixel_position(x, y, index,
//! seed)` (stratified across a pixel's samples) and its other random numbers from
//! `Sampler::for_pixel_sample(x, y, index, seed)`, so a sample's radiance depends only on the
//! scene, the pixel, the sample index and the seed, never on threads, tiles, crops or which
//! process rendered it.
//!
//! # Exact accumulation: aligned dyadic blocks
//!
//! Floating-point addition is not associative, so "the sum of samples 0..n" depends on how it is
//! bracketed, and a plain running sum cannot be continued by another process. tress fixes one
//! bracketing that every split of the sample range reproduces. An *aligned block* is a range of
//! sample indices `[k·2^l, (k+1)·2^l)`; its sum is the sum of its left half plus the sum of its
//! right half, in f64 (a one-sample block is the sample's radiance, or 0 when that is NaN or
//! infinite). A range `[a, b)` is covered by its maximal aligned blocks ([`dyadic_cover`]: at most
//! two per bit of `b`), and a pixel stores one RGB sum per block. Its value is the block sums
//! added in index order, divided by `b − a`, rounded to f32.
//!
//! Appending the blocks of `[b, c)` to those of `[a, b)` and joining every pair of sibling blocks
//! into their parent (left + right) yields exactly the blocks of `[a, c)` with exactly their
//! defined sums ([`BlockSums`]), because that join *is* the definition of a block's sum. So a
//! render of `[0, a)` merged with one of `[a, b)` equals the render of `[0, b)` bit for bit, a
//! render in waves equals one without, and all of it holds for any thread count, crop or tiling.
//! Within a block the tree is pairwise summation, whose rounding error grows with log n rather
//! than n.

use crate::film::{FilmSettings, Image};
use crate::integrator::Integrator;
use crate::math::Rgb;
use crate::rng::{pixel_position, Sampler};
use crate::scene::{rays_traced_on_this_thread, Scene};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Side of the square tiles the film is split into.
pub const TILE_SIZE: u32 = 16;

/// Why sample sums cannot be joined.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SumsError {
    /// A block of samples that is not an aligned power-of-two range.
    #[error("samples [{}, {}) are not an aligned power-of-two block", .0.start, .0.end)]
    Unaligned(Range<u64>),
    /// Samples that do not start where the earlier ones end.
    #[error(
        "samples [{}, {}) do not follow samples [{}, {})",
        after.start, after.end, before.start, before.end
    )]
    Gap {
        /// The samples held so far.
        before: Range<u64>,
        /// The samples that should follow them.
        after: Range<u64>,
    },
    /// Sums of different pixel windows or films.
    #[error(
        "pixel windows differ: {:?} of {}x{} and {:?} of {}x{}",
        first.0, first.1, first.2, second.0, second.1, second.2
    )]
    Windows {
        /// Window and film size of the sums held.
        first: ([u32; 4], u32, u32),
        /// Window and film size of the sums appended.
        second: ([u32; 4], u32, u32),
    },
}

/// What a render cost.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    /// Wall-clock time taken (summed over waves by [`RenderStats::add`]).
    pub wall: Duration,
    /// Camera samples taken.
    pub samples: u64,
    /// Rays traced (closest-hit and shadow).
    pub rays: u64,
    /// Samples whose radiance was NaN or infinite; they were dropped (counted as black).
    pub nonfinite_samples: u64,
}

impl RenderStats {
    /// Camera samples per second of wall-clock time.
    pub fn samples_per_second(&self) -> f64 {
        self.samples as f64 / self.wall.as_secs_f64().max(1e-9)
    }

    /// Rays traced per second of wall-clock time.
    pub fn rays_per_second(&self) -> f64 {
        self.rays as f64 / self.wall.as_secs_f64().max(1e-9)
    }

    /// Adds the costs of another render (a later wave).
    pub fn add(&mut self, other: &RenderStats) {
        self.wall += other.wall;
        self.samples += other.samples;
        self.rays += other.rays;
        self.nonfinite_samples += other.nonfinite_samples;
    }
}

/// A rendered image and its statistics.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// The rendered pixels of the film window.
    pub image: Image,
    /// Time, samples and rays the render took.
    pub stats: RenderStats,
}

/// The exact per-pixel sums of a sample range, and what rendering them cost.
#[derive(Clone, Debug)]
pub struct SampleRender {
    /// Per-pixel block sums of the sample range, mergeable with neighbouring ranges.
    pub sums: SampleSums,
    /// Time, samples and rays rendering the range took.
    pub stats: RenderStats,
}

/// The maximal aligned dyadic blocks covering `samples`, in index order (see the module notes).
pub fn dyadic_cover(samples: Range<u64>) -> Vec<Range<u64>> {
    let mut blocks = Vec::new();
    let mut a = samples.start;
    while a < samples.end {
        // The largest block starting at `a` is limited by the alignment of `a` and by the end.
        let mut len = if a == 0 {
            1u64 << 63
        } else {
            1u64 << a.trailing_zeros()
        };
        while len > samples.end - a {
            len >>= 1;
        }
        blocks.push(a..a + len);
        a += len;
    }
    blocks
}

fn is_aligned_block(b: &Range<u64>) -> bool {
    let len = b.end.wrapping_sub(b.start);
    b.start < b.end && len.is_power_of_two() && b.start.is_multiple_of(len)
}

fn add3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// The canonical block sums of one pixel, built by appending samples or blocks in index order;
/// sibling blocks are joined as soon as both are present, so the contents depend only on the
/// samples covered, never on how they were split.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BlockSums {
    blocks: Vec<(Range<u64>, [f64; 3])>,
}

impl BlockSums {
    /// No samples yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Removes all blocks, keeping the allocation for the next pixel.
    pub fn clear(&mut self) {
        self.blocks.clear();
    }

    /// The blocks and their RGB sums, in index order: the [`dyadic_cover`] of [`Self::range`].
    pub fn blocks(&self) -> &[(Range<u64>, [f64; 3])] {
        &self.blocks
    }

    /// The sample range covered (empty at `0..0` before anything is appended).
    pub fn range(&self) -> Range<u64> {
        match (self.blocks.first(), self.blocks.last()) {
            (Some(first), Some(last)) => first.0.start..last.0.end,
            _ => 0..0,
        }
    }

    /// Appends the aligned block `block` whose samples sum to `sum`; it must start where the
    /// previous block ended.
    pub fn push(&mut self, block: Range<u64>, sum: [f64; 3]) -> Result<(), SumsError> {
        if !is_aligned_block(&block) {
            return Err(SumsError::Unaligned(block));
        }
        if let Some((last, _)) = self.blocks.last() {
            if block.start != last.end {
                return Err(SumsError::Gap {
                    before: self.range().start..last.end,
                    after: block,
                });
            }
        }
        self.push_unchecked(block, sum);
        Ok(())
    }

    fn push_unchecked(&mut self, block: Range<u64>, sum: [f64; 3]) {
        self.blocks.push((block, sum));
        while let [.., (left, l), (right, r)] = self.blocks.as_slice() {
            let len = left.end - left.start;
            let siblings = right.end - right.start == len && (left.start / len) % 2 == 0;
            if !siblings {
                break;
            }
            let joined = (left.start..right.end, add3(*l, *r));
            self.blocks.truncate(self.blocks.len() - 2);
            self.blocks.push(joined);
        }
    }

    /// The pixel value: the block sums added in order, divided by the sample count (black when
    /// there are no samples).
    pub fn mean(&self) -> Rgb {
        mean_of(
            self.blocks.iter().map(|(_, s)| *s),
            self.range().end - self.range().start,
        )
    }
}

fn mean_of(sums: impl Iterator<Item = [f64; 3]>, count: u64) -> Rgb {
    if count == 0 {
        return Rgb::ZERO;
    }
    let total = sums.fold([0.0f64; 3], add3);
    let n = count as f64;
    Rgb::new(
        (total[0] / n) as f32,
        (total[1] / n) as f32,
        (total[2] / n) as f32,
    )
}

/// The block sums of every pixel of a film window for one sample range. All pixels share the
/// block list (the [`dyadic_cover`] of `samples`); `sums[p * blocks.len() + k]` is block `k` of
/// pixel `p` (row-major within the window).
#[derive(Clone, Debug, PartialEq)]
pub struct SampleSums {
    /// Pixel window `[x0, y0, x1, y1)`.
    pub window: [u32; 4],
    /// Width of the whole film in pixels.
    pub full_width: u32,
    /// Height of the whole film in pixels.
    pub full_height: u32,
    /// Sample indices `[a, b)` summed.
    pub samples: Range<u64>,
    /// The aligned blocks covering `samples` (its [`dyadic_cover`]), shared by all pixels.
    pub blocks: Vec<Range<u64>>,
    /// RGB block sums in f64, `blocks.len()` per pixel, pixel by pixel.
    pub sums: Vec<[f64; 3]>,
}

impl SampleSums {
    /// No samples yet: the empty range starting at `start`.
    pub fn empty(window: [u32; 4], full_width: u32, full_height: u32, start: u64) -> Self {
        SampleSums {
            window,
            full_width,
            full_height,
            samples: start..start,
            blocks: Vec::new(),
            sums: Vec::new(),
        }
    }

    /// Number of pixels in the window.
    pub fn pixel_count(&self) -> usize {
        let [x0, y0, x1, y1] = self.window;
        (x1 - x0) as usize * (y1 - y0) as usize
    }

    /// The block sums of pixel `p` (row-major index within the window).
    pub fn pixel(&self, p: usize) -> &[[f64; 3]] {
        let nb = self.blocks.len();
        &self.sums[p * nb..(p + 1) * nb]
    }

    /// The image: every pixel's block sums added in order and divided by the sample count.
    pub fn image(&self) -> Image {
        let mut image = Image::window(self.window, self.full_width, self.full_height);
        let count = self.samples.end - self.samples.start;
        for (p, px) in image.pixels.iter_mut().enumerate() {
            *px = mean_of(self.pixel(p).iter().copied(), count);
        }
        image
    }

    /// Appends the sums of the samples that follow (same window and film), exactly.
    pub fn append(&mut self, later: &SampleSums) -> Result<(), SumsError> {
        if later.window != self.window
            || (later.full_width, later.full_height) != (self.full_width, self.full_height)
        {
            return Err(SumsError::Windows {
                first: (self.window, self.full_width, self.full_height),
                second: (later.window, later.full_width, later.full_height),
            });
        }
        if later.samples.start != self.samples.end {
            return Err(SumsError::Gap {
                before: self.samples.clone(),
                after: later.samples.clone(),
            });
        }
        if later.samples.is_empty() {
            return Ok(());
        }
        let samples = self.samples.start..later.samples.end;
        let blocks = dyadic_cover(samples.clone());
        let mut sums = Vec::with_capacity(self.pixel_count() * blocks.len());
        let mut acc = BlockSums::new();
        for p in 0..self.pixel_count() {
            acc.clear();
            let own = self.blocks.iter().zip(self.pixel(p));
            for (block, sum) in own.chain(later.blocks.iter().zip(later.pixel(p))) {
                acc.push(block.clone(), *sum)?;
            }
            debug_assert!(acc.blocks().iter().map(|b| &b.0).eq(blocks.iter()));
            sums.extend(acc.blocks().iter().map(|b| b.1));
        }
        self.samples = samples;
        self.blocks = blocks;
        self.sums = sums;
        Ok(())
    }
}

struct TileResult {
    sums: Vec<[f64; 3]>,
    rays: u64,
    nonfinite: u64,
}

/// Renders the film window of `film` with `integrator` (all `film.spp` samples), calling
/// `progress` with the number of samples finished after each tile (from worker threads).
pub fn render(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> RenderOutput {
    let never = AtomicBool::new(false);
    let done = render_samples(
        scene,
        integrator,
        film,
        0..film.spp as u64,
        &never,
        progress,
    )
    .expect("a render that is never cancelled finishes");
    RenderOutput {
        image: done.sums.image(),
        stats: done.stats,
    }
}

/// Renders the sample indices `samples` of every pixel of the film window (`film.spp` is not
/// used), returning their exact block sums. Returns `None` as soon as `cancel` is set: workers
/// check it before every sample.
pub fn render_samples(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    samples: Range<u64>,
    cancel: &AtomicBool,
    progress: &(dyn Fn(u64) + Sync),
) -> Option<SampleRender> {
    let start = Instant::now();
    let window = film.window();
    let [x0, y0, x1, y1] = window;
    let tiles: Vec<[u32; 4]> = (y0..y1)
        .step_by(TILE_SIZE as usize)
        .flat_map(|ty| {
            (x0..x1)
                .step_by(TILE_SIZE as usize)
                .map(move |tx| [tx, ty, (tx + TILE_SIZE).min(x1), (ty + TILE_SIZE).min(y1)])
        })
        .collect();
    let blocks = dyadic_cover(samples.clone());
    let per_pixel = samples.end - samples.start;

    let results: Vec<TileResult> = tiles
        .par_iter()
        .map(|&tile| {
            let rays_before = rays_traced_on_this_thread();
            let (sums, nonfinite) =
                render_tile(scene, integrator, film, tile, &samples, &blocks, cancel)?;
            let [tx0, ty0, tx1, ty1] = tile;
            progress(((tx1 - tx0) * (ty1 - ty0)) as u64 * per_pixel);
            Some(TileResult {
                sums,
                rays: rays_traced_on_this_thread() - rays_before,
                nonfinite,
            })
        })
        .collect::<Option<Vec<_>>>()?;

    let nb = blocks.len();
    let width = (x1 - x0) as usize;
    let pixels = width * (y1 - y0) as usize;
    let mut sums = vec![[0.0f64; 3]; pixels * nb];
    let mut stats = RenderStats::default();
    for (tile, result) in tiles.iter().zip(&results) {
        let [tx0, ty0, tx1, _] = *tile;
        let tw = (tx1 - tx0) as usize;
        for (i, pixel) in result.sums.chunks_exact(nb.max(1)).enumerate() {
            let (px, py) = (tx0 as usize + i % tw, ty0 as usize + i / tw);
            let p = (py - y0 as usize) * width + (px - x0 as usize);
            sums[p * nb..(p + 1) * nb].copy_from_slice(pixel);
        }
        stats.rays += result.rays;
        stats.nonfinite_samples += result.nonfinite;
    }
    stats.samples = pixels as u64 * per_pixel;
    stats.wall = start.elapsed();
    Some(SampleRender {
        sums: SampleSums {
            window,
            full_width: film.width,
            full_height: film.height,
            samples,
            blocks,
            sums,
        },
        stats,
    })
}

fn render_tile(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    tile: [u32; 4],
    samples: &Range<u64>,
    blocks: &[Range<u64>],
    cancel: &AtomicBool,
) -> Option<(Vec<[f64; 3]>, u64)> {
    let [tx0, ty0, tx1, ty1] = tile;
    let mut sums = Vec::with_capacity(((tx1 - tx0) * (ty1 - ty0)) as usize * blocks.len());
    let mut nonfinite = 0;
    let mut acc = BlockSums::new();
    for y in ty0..ty1 {
        for x in tx0..tx1 {
            acc.clear();
            for s in samples.clone() {
                if cancel.load(Ordering::Relaxed) {
                    return None;
                }
                let mut sampler = Sampler::for_pixel_sample(x, y, s, film.seed);
                let jitter = pixel_position(x, y, s, film.seed);
                let lens = sampler.next_2d();
                let ray = scene.camera.generate_ray(
                    x as f32 + jitter.x,
                    y as f32 + jitter.y,
                    film.width,
                    film.height,
                    lens,
                );
                let l = integrator.li(&ray, scene, &mut sampler);
                let value = if l.is_finite() {
                    [l.x as f64, l.y as f64, l.z as f64]
                } else {
                    nonfinite += 1;
                    [0.0; 3]
                };
                acc.push_unchecked(s..s + 1, value);
            }
            debug_assert!(acc.blocks().iter().map(|b| &b.0).eq(blocks.iter()));
            sums.extend(acc.blocks().iter().map(|b| b.1));
        }
    }
    Some((sums, nonfinite))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::{Accel, Hit};
    use crate::camera::Camera;
    use crate::math::{Aabb, Ray, Vec3};

    /// Deterministic, wide-ranging test values (rounding differences would show).
    fn value(i: u64) -> [f64; 3] {
        let mut s = Sampler::from_seed(i);
        let u = s.next_1d() as f64;
        [(20.0 * u).exp(), u * 1e-3, 1.0 / (u + 1e-3)]
    }

    fn bits(v: &[[f64; 3]]) -> Vec<[u64; 3]> {
        v.iter().map(|s| s.map(f64::to_bits)).collect()
    }

    /// The definition: an aligned block's sum is its halves' sums added.
    fn tree_sum(b: Range<u64>) -> [f64; 3] {
        if b.end - b.start == 1 {
            return value(b.start);
        }
        let mid = b.start + (b.end - b.start) / 2;
        add3(tree_sum(b.start..mid), tree_sum(mid..b.end))
    }

    #[test]
    fn cover_is_maximal_aligned_and_contiguous() {
        assert_eq!(dyadic_cover(0..0), Vec::<Range<u64>>::new());
        assert_eq!(dyadic_cover(0..64), vec![0..64]);
        assert_eq!(dyadic_cover(0..7), vec![0..4, 4..6, 6..7]);
        assert_eq!(dyadic_cover(3..17), vec![3..4, 4..8, 8..16, 16..17]);
        assert_eq!(dyadic_cover(0..u64::MAX).len(), 64);
        for a in 0..40u64 {
            for b in a..80 {
                let c = dyadic_cover(a..b);
                assert!(c.iter().all(is_aligned_block), "{a}..{b}: {c:?}");
                assert!(c.windows(2).all(|w| w[0].end == w[1].start));
                assert_eq!(c.first().map_or(b, |f| f.start), a);
                assert_eq!(c.last().map_or(a, |l| l.end), b);
                // Maximal: no block's parent fits inside the range.
                for blk in &c {
                    let len = blk.end - blk.start;
                    let parent = (blk.start / (2 * len)) * 2 * len;
                    assert!(parent < a || parent + 2 * len > b, "{a}..{b}: {blk:?}");
                }
            }
        }
    }

    #[test]
    fn any_split_gives_the_same_bits_as_the_definition() {
        let whole = 0..203u64;
        let mut one_by_one = BlockSums::new();
        for s in whole.clone() {
            one_by_one.push(s..s + 1, value(s)).unwrap();
        }
        let expected: Vec<[f64; 3]> = dyadic_cover(whole.clone())
            .into_iter()
            .map(tree_sum)
            .collect();
        let got: Vec<[f64; 3]> = one_by_one.blocks().iter().map(|b| b.1).collect();
        assert_eq!(bits(&got), bits(&expected));
        // Split the range at arbitrary points; each piece is summed alone, then appended.
        let mut rng = Sampler::from_seed(99);
        for _ in 0..200 {
            let mut cuts: Vec<u64> = (0..4)
                .map(|_| (rng.next_1d() * whole.end as f32) as u64)
                .collect();
            cuts.extend([0, whole.end]);
            cuts.sort();
            let mut merged = BlockSums::new();
            for w in cuts.windows(2) {
                let mut piece = BlockSums::new();
                for s in w[0]..w[1] {
                    piece.push(s..s + 1, value(s)).unwrap();
                }
                for (b, s) in piece.blocks() {
                    merged.push(b.clone(), *s).unwrap();
                }
            }
            assert_eq!(merged, one_by_one, "cuts {cuts:?}");
            assert_eq!(
                merged.mean().to_array().map(f32::to_bits),
                one_by_one.mean().to_array().map(f32::to_bits)
            );
        }
        // A plain running sum would not have been associative: the test can fail.
        let seq = (0..203).map(value).fold([0.0; 3], add3);
        let split = add3(
            (0..100).map(value).fold([0.0; 3], add3),
            (100..203).map(value).fold([0.0; 3], add3),
        );
        assert_ne!(bits(&[seq]), bits(&[split]));
    }

    #[test]
    fn bad_blocks_are_refused() {
        let mut acc = BlockSums::new();
        assert!(acc
            .push(3..5, [0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("aligned"));
        assert!(acc.push(4..4, [0.0; 3]).is_err());
        acc.push(4..8, [1.0; 3]).unwrap();
        assert!(acc
            .push(9..10, [0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("follow"));
        assert!(acc.push(0..4, [0.0; 3]).is_err());
        assert_eq!(acc.range(), 4..8);
        assert_eq!(acc.mean(), Rgb::splat(0.25));
        assert_eq!(BlockSums::new().mean(), Rgb::ZERO);
    }

    struct Empty;

    impl Accel for Empty {
        fn intersect(&self, _: &Ray) -> Option<Hit> {
            None
        }
        fn occluded(&self, _: &Ray) -> bool {
            false
        }
        fn occluded_by_surfaces(&self, _: &Ray) -> bool {
            false
        }
        fn bounds(&self) -> Aabb {
            Aabb::EMPTY
        }
    }

    /// Radiance from the ray and the sampler, with a heavy tail and an occasional NaN.
    #[derive(Debug)]
    struct Noise;

    impl Integrator for Noise {
        fn li(&self, ray: &Ray, _: &Scene, sampler: &mut Sampler) -> Rgb {
            let u = sampler.next_1d();
            if u < 0.01 {
                return Rgb::splat(f32::NAN);
            }
            Rgb::new((12.0 * u).exp(), ray.dir.x.abs(), 1.0 / u)
        }
    }

    fn scene() -> Scene {
        Scene::new(
            Camera::perspective(Vec3::Z, Vec3::ZERO, Vec3::Y, 40.0, 0.0, None),
            Box::new(Empty),
            Vec::new(),
            Vec::new().into(),
        )
    }

    fn film(crop: Option<[u32; 4]>) -> FilmSettings {
        FilmSettings {
            width: 37,
            height: 21,
            spp: 13,
            seed: 4,
            crop,
        }
    }

    fn run(film: &FilmSettings, samples: Range<u64>) -> SampleSums {
        let never = AtomicBool::new(false);
        render_samples(&scene(), &Noise, film, samples, &never, &|_| {})
            .unwrap()
            .sums
    }

    #[test]
    fn ranges_and_waves_merge_into_the_single_render() {
        let f = film(None);
        let whole = run(&f, 0..13);
        assert_eq!(whole.blocks, vec![0..8, 8..12, 12..13]);
        let full = render(&scene(), &Noise, &f, &|_| {});
        assert_eq!(full.image, whole.image());
        assert!(full.stats.nonfinite_samples > 0);
        for cuts in [vec![0, 1, 2, 4, 8, 13], vec![0, 5, 13], vec![0, 12, 13]] {
            let mut acc = SampleSums::empty(f.window(), 37, 21, 0);
            for w in cuts.windows(2) {
                acc.append(&run(&f, w[0]..w[1])).unwrap();
            }
            assert_eq!(bits(&acc.sums), bits(&whole.sums), "{cuts:?}");
            assert_eq!(acc.blocks, whole.blocks);
        }
        // Crops see the same sums as the full film.
        let c = run(&film(Some([5, 3, 30, 19])), 0..13);
        let nb = whole.blocks.len();
        for y in 3..19usize {
            for x in 5..30usize {
                let pc = (y - 3) * 25 + (x - 5);
                let pf = y * 37 + x;
                assert_eq!(bits(c.pixel(pc)), bits(&whole.sums[pf * nb..(pf + 1) * nb]));
            }
        }
    }

    #[test]
    fn mismatched_appends_are_refused_and_cancel_stops() {
        let f = film(None);
        let mut a = run(&f, 0..4);
        let gap = run(&f, 5..6);
        assert!(a
            .append(&gap)
            .unwrap_err()
            .to_string()
            .contains("do not follow"));
        let other = run(&film(Some([0, 0, 8, 8])), 4..5);
        assert!(a
            .append(&other)
            .unwrap_err()
            .to_string()
            .contains("windows differ"));
        let cancelled = AtomicBool::new(true);
        assert!(render_samples(&scene(), &Noise, &f, 0..4, &cancelled, &|_| {}).is_none());
    }
}
