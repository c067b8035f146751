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
//!
//! # Alpha and AOVs
//!
//! A render may record more than radiance ([`Outputs`]: alpha, depth, tangent, albedo,
//! variance). Each sample then adds a few more [`Quantity`] values — whether its camera ray hit
//! geometry, the distance, the fiber tangent and an albedo estimate at that hit, the squared
//! radiance — and every block holds one sum per quantity, joined exactly as the radiance is. So
//! the output channels ([`SampleSums::channels`]), computed from the pixels' totals, merge,
//! resume and tile bit for bit too.

use crate::accel::{Hit, HitKind};
use crate::camera::Camera;
use crate::film::{counts_hits, Aov, FilmSettings, Image, Outputs};
pub use crate::film::{quantities, quantity_count, Quantity};
use crate::integrator::{Integrator, WaveSample};
use crate::math::{Ray, Rgb, Vec3};
use crate::rng::{hash_words, pixel_position, Sampler};
use crate::scene::Scene;
use crate::shading::ShadingPoint;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Side of the square tiles the film is split into.
pub const TILE_SIZE: u32 = 16;

/// Camera samples handed to [`Integrator::li_wave`] at once: enough paths for a wavefront
/// integrator's batches of rays, few enough that a wave's state stays in the cache (at 64
/// spp, a wave is 16 pixels).
pub const WAVE: usize = 1024;

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
    /// Sums recording different outputs (alpha, AOVs).
    #[error("recorded outputs differ: {first} and {second}")]
    Outputs {
        /// Output channels of the sums held.
        first: String,
        /// Output channels of the sums appended.
        second: String,
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
    /// Wall-clock time of the integrator's per-film precomputation
    /// ([`Integrator::for_film`]), included in `wall`.
    pub precompute: Duration,
    /// What that precomputation built, for logs.
    pub precompute_note: Option<String>,
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
        self.precompute += other.precompute;
        if other.precompute_note.is_some() {
            self.precompute_note.clone_from(&other.precompute_note);
        }
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

/// What one camera sample contributes.
#[derive(Clone, Copy, Debug, Default)]
struct SampleRecord {
    /// Radiance; zero for a NaN or infinite sample.
    radiance: [f64; 3],
    /// Whether the camera ray hit geometry.
    hit: bool,
    /// Distance to the first hit.
    distance: f32,
    /// Fiber tangent at the first hit, when it is a fiber.
    tangent: Option<Vec3>,
    /// Albedo estimate of the first hit's material.
    albedo: Rgb,
}

impl SampleRecord {
    /// Writes the record's values of the quantities `outputs` record, in [`quantities`] order.
    fn write(&self, outputs: &Outputs, out: &mut Vec<f64>) {
        out.clear();
        out.extend(self.radiance);
        if counts_hits(outputs) {
            out.push(if self.hit { 1.0 } else { 0.0 });
        }
        if outputs.has(Aov::Depth) {
            out.push(if self.hit { self.distance as f64 } else { 0.0 });
        }
        if outputs.has(Aov::Tangent) {
            match self.tangent {
                Some(t) => out.extend([1.0, t.x as f64, t.y as f64, t.z as f64]),
                None => out.extend([0.0; 4]),
            }
        }
        if outputs.has(Aov::Albedo) {
            out.extend(self.albedo.to_array().map(f64::from));
        }
        if outputs.has(Aov::Variance) {
            out.extend(self.radiance.map(|v| v * v));
        }
    }
}

/// Seed word that separates the albedo estimate's random numbers from the integrator's, so
/// that recording the albedo leaves the radiance samples unchanged.
const ALBEDO_STREAM: u64 = 0xa1be_d0a1_be00_0001;

/// One-sample estimate of the directional albedo of `hit`'s material toward the camera: f·cos
/// θ / pdf of one direction its sampling routine draws (exact for diffuse surfaces, unbiased
/// for fibers), or zero when it draws nothing or something not finite.
fn albedo_estimate(
    scene: &Scene,
    hit: &Hit,
    ray: &Ray,
    pixel: (u32, u32),
    s: u64,
    seed: u64,
) -> Rgb {
    let sp = ShadingPoint::new(hit, ray, &scene.materials);
    let stream = hash_words(&[seed, ALBEDO_STREAM]);
    let mut sampler = Sampler::for_pixel_sample(pixel.0, pixel.1, s, stream);
    match sp.sample(sampler.next_4d()) {
        Some(sample) if sample.pdf > 0.0 => {
            let a = sample.f / sample.pdf;
            if a.is_finite() {
                a
            } else {
                Rgb::ZERO
            }
        }
        _ => Rgb::ZERO,
    }
}

/// The canonical block sums of one pixel, built by appending samples or blocks in index order;
/// sibling blocks are joined as soon as both are present, so the contents depend only on the
/// samples covered, never on how they were split. Each block holds one f64 sum per quantity.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockSums {
    /// Quantities per block.
    width: usize,
    /// The blocks, in index order.
    ranges: Vec<Range<u64>>,
    /// `width` sums per block, block by block.
    sums: Vec<f64>,
}

impl BlockSums {
    /// No samples yet, of `quantities` quantities per sample.
    pub fn new(quantities: usize) -> Self {
        BlockSums {
            width: quantities,
            ranges: Vec::new(),
            sums: Vec::new(),
        }
    }

    /// Removes all blocks, keeping the allocation for the next pixel.
    pub fn clear(&mut self) {
        self.ranges.clear();
        self.sums.clear();
    }

    /// The blocks in index order: the [`dyadic_cover`] of [`Self::range`].
    pub fn ranges(&self) -> &[Range<u64>] {
        &self.ranges
    }

    /// The sums of every block, block by block (quantities per block: the width given to
    /// [`Self::new`]).
    pub fn sums(&self) -> &[f64] {
        &self.sums
    }

    /// The sample range covered (empty at `0..0` before anything is appended).
    pub fn range(&self) -> Range<u64> {
        match (self.ranges.first(), self.ranges.last()) {
            (Some(first), Some(last)) => first.start..last.end,
            _ => 0..0,
        }
    }

    /// Appends the aligned block `block` whose samples sum to `sum` (one value per quantity);
    /// it must start where the previous block ended.
    pub fn push(&mut self, block: Range<u64>, sum: &[f64]) -> Result<(), SumsError> {
        if !is_aligned_block(&block) {
            return Err(SumsError::Unaligned(block));
        }
        if let Some(last) = self.ranges.last() {
            if block.start != last.end {
                return Err(SumsError::Gap {
                    before: self.range().start..last.end,
                    after: block,
                });
            }
        }
        assert_eq!(sum.len(), self.width, "one sum per quantity");
        self.push_unchecked(block, sum);
        Ok(())
    }

    fn push_unchecked(&mut self, block: Range<u64>, sum: &[f64]) {
        self.ranges.push(block);
        self.sums.extend_from_slice(sum);
        while let [.., left, right] = self.ranges.as_slice() {
            let len = left.end - left.start;
            let siblings = right.end - right.start == len && (left.start / len) % 2 == 0;
            if !siblings {
                break;
            }
            // Parent = left + right, quantity by quantity.
            let joined = left.start..right.end;
            let n = self.sums.len();
            let (lefts, rights) = self.sums[n - 2 * self.width..].split_at_mut(self.width);
            for (l, r) in lefts.iter_mut().zip(rights.iter()) {
                *l += *r;
            }
            self.sums.truncate(n - self.width);
            self.ranges.truncate(self.ranges.len() - 2);
            self.ranges.push(joined);
        }
    }

    /// The radiance: the RGB block sums added in order, divided by the sample count (black when
    /// there are no samples).
    pub fn mean(&self) -> Rgb {
        let range = self.range();
        let totals = totals(&self.sums, self.ranges.len(), self.width);
        mean_rgb(&totals, range.end - range.start)
    }
}

/// Per quantity, the sums of `blocks` blocks of `width` quantities added in block order.
fn totals(sums: &[f64], blocks: usize, width: usize) -> Vec<f64> {
    let mut total = vec![0.0f64; width];
    for block in sums[..blocks * width].chunks_exact(width.max(1)) {
        for (t, v) in total.iter_mut().zip(block) {
            *t += *v;
        }
    }
    total
}

/// The pixel's radiance from its totals (R, G, B first) and sample count.
fn mean_rgb(totals: &[f64], count: u64) -> Rgb {
    if count == 0 {
        return Rgb::ZERO;
    }
    let n = count as f64;
    Rgb::new(
        (totals[0] / n) as f32,
        (totals[1] / n) as f32,
        (totals[2] / n) as f32,
    )
}

/// The block sums of every pixel of a film window for one sample range. All pixels share the
/// block list (the [`dyadic_cover`] of `samples`) and the quantities (`quantities(&outputs)`);
/// `sums[(p · blocks.len() + k) · nq + q]` is quantity `q` of block `k` of pixel `p`
/// (row-major within the window), `nq` the number of quantities.
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
    /// What is recorded besides radiance; fixes the quantities summed ([`quantities`]).
    pub outputs: Outputs,
    /// Block sums in f64: `blocks.len()` blocks of every quantity per pixel, pixel by pixel.
    pub sums: Vec<f64>,
}

impl SampleSums {
    /// No samples yet: the empty range starting at `start`.
    pub fn empty(
        window: [u32; 4],
        full_width: u32,
        full_height: u32,
        start: u64,
        outputs: Outputs,
    ) -> Self {
        SampleSums {
            window,
            full_width,
            full_height,
            samples: start..start,
            blocks: Vec::new(),
            outputs,
            sums: Vec::new(),
        }
    }

    /// Number of pixels in the window.
    pub fn pixel_count(&self) -> usize {
        let [x0, y0, x1, y1] = self.window;
        (x1 - x0) as usize * (y1 - y0) as usize
    }

    /// Number of quantities summed per block.
    pub fn quantity_count(&self) -> usize {
        quantity_count(&self.outputs)
    }

    /// The block sums of pixel `p` (row-major index within the window): every quantity of
    /// block 0, then of block 1, …
    pub fn pixel(&self, p: usize) -> &[f64] {
        let n = self.blocks.len() * self.quantity_count();
        &self.sums[p * n..(p + 1) * n]
    }

    /// The radiance image: every pixel's RGB block sums added in order and divided by the
    /// sample count.
    pub fn image(&self) -> Image {
        let mut image = Image::window(self.window, self.full_width, self.full_height);
        let count = self.samples.end - self.samples.start;
        let (nb, nq) = (self.blocks.len(), self.quantity_count());
        for (p, px) in image.pixels.iter_mut().enumerate() {
            *px = mean_rgb(&totals(self.pixel(p), nb, nq), count);
        }
        image
    }

    /// Every output channel, named and ordered as [`Outputs::channel_names`]: the radiance,
    /// alpha and the AOVs, each a value per pixel of the window (row-major), all computed from
    /// the pixels' totals (see [`Aov`] for what each holds).
    pub fn channels(&self) -> Vec<(&'static str, Vec<f32>)> {
        let names = self.outputs.channel_names();
        let quantities = quantities(&self.outputs);
        let at = |q: Quantity| quantities.iter().position(|&x| x == q);
        let (nb, nq) = (self.blocks.len(), quantities.len());
        let count = self.samples.end - self.samples.start;
        let n = count as f64;
        let mut values: Vec<Vec<f32>> = vec![Vec::with_capacity(self.pixel_count()); names.len()];
        let mut row = Vec::with_capacity(names.len());
        for p in 0..self.pixel_count() {
            let t = totals(self.pixel(p), nb, nq);
            let get = |q: Quantity| at(q).map_or(0.0, |i| t[i]);
            row.clear();
            row.extend(mean_rgb(&t, count).to_array());
            // Averages over the samples that hit (or saw a fiber); `none` where there are none.
            let over = |sum: f64, hits: f64, none: f32| {
                if hits > 0.0 {
                    (sum / hits) as f32
                } else {
                    none
                }
            };
            if self.outputs.alpha {
                row.push(if count > 0 {
                    (get(Quantity::Hits) / n) as f32
                } else {
                    0.0
                });
            }
            for aov in &self.outputs.aovs {
                match aov {
                    Aov::Depth => row.push(over(
                        get(Quantity::Distance),
                        get(Quantity::Hits),
                        f32::INFINITY,
                    )),
                    Aov::Tangent => {
                        let fibers = get(Quantity::FiberHits);
                        for q in [Quantity::TangentX, Quantity::TangentY, Quantity::TangentZ] {
                            row.push(over(get(q), fibers, 0.0));
                        }
                    }
                    Aov::Albedo => {
                        let hits = get(Quantity::Hits);
                        for q in [Quantity::AlbedoR, Quantity::AlbedoG, Quantity::AlbedoB] {
                            row.push(over(get(q), hits, 0.0));
                        }
                    }
                    Aov::Variance => {
                        let pairs = [
                            (Quantity::R, Quantity::R2),
                            (Quantity::G, Quantity::G2),
                            (Quantity::B, Quantity::B2),
                        ];
                        for (q, q2) in pairs {
                            row.push(if count >= 2 {
                                let (s, s2) = (get(q), get(q2));
                                // Rounding can leave a constant pixel a hair below zero.
                                ((s2 - s * s / n) / (n * (n - 1.0))).max(0.0) as f32
                            } else {
                                f32::INFINITY
                            });
                        }
                    }
                }
            }
            debug_assert_eq!(row.len(), names.len());
            for (column, v) in values.iter_mut().zip(&row) {
                column.push(*v);
            }
        }
        names.into_iter().zip(values).collect()
    }

    /// Appends the sums of the samples that follow (same window, film and outputs), exactly.
    pub fn append(&mut self, later: &SampleSums) -> Result<(), SumsError> {
        if later.window != self.window
            || (later.full_width, later.full_height) != (self.full_width, self.full_height)
        {
            return Err(SumsError::Windows {
                first: (self.window, self.full_width, self.full_height),
                second: (later.window, later.full_width, later.full_height),
            });
        }
        if later.outputs != self.outputs {
            return Err(SumsError::Outputs {
                first: self.outputs.channel_names().join(", "),
                second: later.outputs.channel_names().join(", "),
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
        let nq = self.quantity_count();
        let mut sums = Vec::with_capacity(self.pixel_count() * blocks.len() * nq);
        let mut acc = BlockSums::new(nq);
        for p in 0..self.pixel_count() {
            acc.clear();
            let own = self.blocks.iter().zip(self.pixel(p).chunks_exact(nq));
            let theirs = later.blocks.iter().zip(later.pixel(p).chunks_exact(nq));
            for (block, sum) in own.chain(theirs) {
                acc.push(block.clone(), sum)?;
            }
            debug_assert_eq!(acc.ranges(), blocks.as_slice());
            sums.extend_from_slice(acc.sums());
        }
        self.samples = samples;
        self.blocks = blocks;
        self.sums = sums;
        Ok(())
    }
}

struct TileResult {
    sums: Vec<f64>,
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

/// Renders the radiance of the sample indices `samples` of every pixel of the film window
/// ([`render_outputs`] recording nothing else).
pub fn render_samples(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    samples: Range<u64>,
    cancel: &AtomicBool,
    progress: &(dyn Fn(u64) + Sync),
) -> Option<SampleRender> {
    render_outputs(
        scene,
        integrator,
        film,
        &Outputs::default(),
        samples,
        cancel,
        progress,
    )
}

/// The camera ray of sample `sample_index` of pixel (x, y), and the sampler the integrator
/// continues it with: the pixel position from `rng::pixel_position`, the lens sample as the
/// sampler's first draw.
pub fn camera_sample(
    camera: &Camera,
    film: &FilmSettings,
    x: u32,
    y: u32,
    sample_index: u64,
) -> (Ray, Sampler) {
    let mut sampler = Sampler::for_pixel_sample(x, y, sample_index, film.seed);
    let jitter = pixel_position(x, y, sample_index, film.seed);
    let lens = sampler.next_2d();
    let ray = camera.generate_ray(
        x as f32 + jitter.x,
        y as f32 + jitter.y,
        film.width,
        film.height,
        lens,
    );
    (ray, sampler)
}

/// Renders the sample indices `samples` of every pixel of the film window (`film.spp` is not
/// used), recording `outputs` besides the radiance, and returns their exact block sums.
/// Returns `None` as soon as `cancel` is set: workers check it before every sample.
///
/// Alpha and the AOVs of the first hit cost one extra query of each camera ray: an any-hit
/// (occlusion) query for alpha alone, a closest-hit query for the AOVs. It is counted in the
/// ray statistics, draws no random numbers from the integrator's stream, and so leaves the
/// radiance samples bit for bit unchanged.
pub fn render_outputs(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    outputs: &Outputs,
    samples: Range<u64>,
    cancel: &AtomicBool,
    progress: &(dyn Fn(u64) + Sync),
) -> Option<SampleRender> {
    // Each segment is prepared for (and what was prepared let go) in turn; the segments' sums
    // append exactly, so the image is the same as one range's.
    let mut segments = integrator.sample_segments(samples.clone()).into_iter();
    let first = segments.next().unwrap_or(samples);
    let mut done = render_segment(scene, integrator, film, outputs, first, cancel, progress)?;
    for segment in segments {
        let later = render_segment(scene, integrator, film, outputs, segment, cancel, progress)?;
        done.sums
            .append(&later.sums)
            .expect("an integrator's sample segments follow each other");
        done.stats.add(&later.stats);
    }
    Some(done)
}

/// [`render_outputs`] of one sample segment, prepared for as a whole.
fn render_segment(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    outputs: &Outputs,
    samples: Range<u64>,
    cancel: &AtomicBool,
    progress: &(dyn Fn(u64) + Sync),
) -> Option<SampleRender> {
    let start = Instant::now();
    let prepared = integrator.for_film(scene, film, samples.clone(), cancel, &|_| {});
    let integrator = prepared
        .as_ref()
        .map_or(integrator, |p| p.integrator.as_ref());
    // Nothing to report for integrators without a per-film precomputation.
    let precompute = if prepared.is_some() {
        start.elapsed()
    } else {
        Duration::ZERO
    };
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
            let rays_before = scene.rays_traced_on_this_thread();
            let job = TileJob {
                scene,
                integrator,
                film,
                outputs,
                samples: &samples,
                blocks: &blocks,
                cancel,
            };
            let (sums, nonfinite) = job.render(tile)?;
            let [tx0, ty0, tx1, ty1] = tile;
            progress(((tx1 - tx0) * (ty1 - ty0)) as u64 * per_pixel);
            Some(TileResult {
                sums,
                rays: scene.rays_traced_on_this_thread() - rays_before,
                nonfinite,
            })
        })
        .collect::<Option<Vec<_>>>()?;

    let per_block = blocks.len() * quantity_count(outputs);
    let width = (x1 - x0) as usize;
    let pixels = width * (y1 - y0) as usize;
    let mut sums = vec![0.0f64; pixels * per_block];
    let mut stats = RenderStats::default();
    for (tile, result) in tiles.iter().zip(&results) {
        let [tx0, ty0, tx1, _] = *tile;
        let tw = (tx1 - tx0) as usize;
        for (i, pixel) in result.sums.chunks_exact(per_block.max(1)).enumerate() {
            let (px, py) = (tx0 as usize + i % tw, ty0 as usize + i / tw);
            let p = (py - y0 as usize) * width + (px - x0 as usize);
            sums[p * per_block..(p + 1) * per_block].copy_from_slice(pixel);
        }
        stats.rays += result.rays;
        stats.nonfinite_samples += result.nonfinite;
    }
    stats.samples = pixels as u64 * per_pixel;
    stats.wall = start.elapsed();
    stats.precompute = precompute;
    stats.precompute_note = prepared.map(|p| p.note);
    Some(SampleRender {
        sums: SampleSums {
            window,
            full_width: film.width,
            full_height: film.height,
            samples,
            blocks,
            outputs: outputs.clone(),
            sums,
        },
        stats,
    })
}

/// Everything a worker needs to render tiles.
struct TileJob<'a> {
    scene: &'a Scene,
    integrator: &'a dyn Integrator,
    film: &'a FilmSettings,
    outputs: &'a Outputs,
    samples: &'a Range<u64>,
    blocks: &'a [Range<u64>],
    cancel: &'a AtomicBool,
}

impl TileJob<'_> {
    /// The block sums of every pixel of `tile`, row by row, and the count of samples that were
    /// NaN or infinite; `None` when cancelled.
    fn render(&self, tile: [u32; 4]) -> Option<(Vec<f64>, u64)> {
        let (scene, film, outputs) = (self.scene, self.film, self.outputs);
        let [tx0, ty0, tx1, ty1] = tile;
        let nq = quantity_count(outputs);
        let mut sums =
            Vec::with_capacity(((tx1 - tx0) * (ty1 - ty0)) as usize * self.blocks.len() * nq);
        let mut nonfinite = 0;
        let mut acc = BlockSums::new(nq);
        let mut values = Vec::with_capacity(nq);
        // Depth, tangent and albedo need the hit itself; alpha alone only whether there is one.
        let closest_hit = [Aov::Depth, Aov::Tangent, Aov::Albedo]
            .iter()
            .any(|&a| outputs.has(a));
        // Samples go to the integrator in waves of up to `WAVE` (pixel after pixel, in
        // sample order), and their values into each pixel's block sums in the same order.
        let mut wave: Vec<WaveSample> = Vec::with_capacity(WAVE);
        let mut records: Vec<SampleRecord> = Vec::with_capacity(WAVE);
        let samples_per_pixel = (self.samples.end - self.samples.start) as usize;
        let pixels = (tx0..tx1).len() * (ty0..ty1).len();
        let total = pixels * samples_per_pixel;
        let mut next = 0;
        while next < total {
            if self.cancel.load(Ordering::Relaxed) {
                return None;
            }
            let end = (next + WAVE).min(total);
            wave.clear();
            records.clear();
            for k in next..end {
                let (pixel, s) = (k / samples_per_pixel, k % samples_per_pixel);
                let (x, y) = (
                    tx0 + (pixel % (tx1 - tx0) as usize) as u32,
                    ty0 + (pixel / (tx1 - tx0) as usize) as u32,
                );
                let s = self.samples.start + s as u64;
                let (ray, sampler) = camera_sample(&scene.camera, film, x, y, s);
                let mut record = SampleRecord::default();
                if closest_hit {
                    if let Some(hit) = scene.intersect(&ray) {
                        record.hit = true;
                        record.distance = hit.t;
                        if let HitKind::Fiber { tangent, .. } = hit.kind {
                            record.tangent = Some(tangent);
                        }
                        if outputs.has(Aov::Albedo) {
                            record.albedo =
                                albedo_estimate(scene, &hit, &ray, (x, y), s, film.seed);
                        }
                    }
                } else if outputs.alpha {
                    // Alpha needs no hit record: an any-hit query stops at the first fiber.
                    record.hit = scene.occluded(&ray);
                }
                records.push(record);
                wave.push(WaveSample {
                    ray,
                    sampler,
                    sample_index: s,
                    radiance: Rgb::ZERO,
                });
            }
            self.integrator.li_wave(scene, &mut wave);
            for (k, (w, record)) in (next..end).zip(wave.iter().zip(&mut records)) {
                let l = w.radiance;
                if l.is_finite() {
                    record.radiance = [l.x as f64, l.y as f64, l.z as f64];
                } else {
                    nonfinite += 1;
                }
                record.write(outputs, &mut values);
                acc.push_unchecked(w.sample_index..w.sample_index + 1, &values);
                if (k + 1) % samples_per_pixel == 0 {
                    debug_assert_eq!(acc.ranges(), self.blocks);
                    sums.extend_from_slice(acc.sums());
                    acc.clear();
                }
            }
            next = end;
        }
        Some((sums, nonfinite))
    }
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

    fn flat_bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|s| s.to_bits()).collect()
    }

    fn add3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
    }

    fn rgb_blocks(acc: &BlockSums) -> Vec<[f64; 3]> {
        acc.sums()
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect()
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
        let mut one_by_one = BlockSums::new(3);
        for s in whole.clone() {
            one_by_one.push(s..s + 1, &value(s)).unwrap();
        }
        let expected: Vec<[f64; 3]> = dyadic_cover(whole.clone())
            .into_iter()
            .map(tree_sum)
            .collect();
        assert_eq!(one_by_one.ranges(), dyadic_cover(whole.clone()).as_slice());
        assert_eq!(bits(&rgb_blocks(&one_by_one)), bits(&expected));
        // Split the range at arbitrary points; each piece is summed alone, then appended.
        let mut rng = Sampler::from_seed(99);
        for _ in 0..200 {
            let mut cuts: Vec<u64> = (0..4)
                .map(|_| (rng.next_1d() * whole.end as f32) as u64)
                .collect();
            cuts.extend([0, whole.end]);
            cuts.sort();
            let mut merged = BlockSums::new(3);
            for w in cuts.windows(2) {
                let mut piece = BlockSums::new(3);
                for s in w[0]..w[1] {
                    piece.push(s..s + 1, &value(s)).unwrap();
                }
                for (b, s) in piece.ranges().iter().zip(piece.sums().chunks_exact(3)) {
                    merged.push(b.clone(), s).unwrap();
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
        let mut acc = BlockSums::new(3);
        assert!(acc
            .push(3..5, &[0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("aligned"));
        assert!(acc.push(4..4, &[0.0; 3]).is_err());
        acc.push(4..8, &[1.0; 3]).unwrap();
        assert!(acc
            .push(9..10, &[0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("follow"));
        assert!(acc.push(0..4, &[0.0; 3]).is_err());
        assert_eq!(acc.range(), 4..8);
        assert_eq!(acc.mean(), Rgb::splat(0.25));
        assert_eq!(BlockSums::new(3).mean(), Rgb::ZERO);
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
            let mut acc = SampleSums::empty(f.window(), 37, 21, 0, Outputs::default());
            for w in cuts.windows(2) {
                acc.append(&run(&f, w[0]..w[1])).unwrap();
            }
            assert_eq!(flat_bits(&acc.sums), flat_bits(&whole.sums), "{cuts:?}");
            assert_eq!(acc.blocks, whole.blocks);
        }
        // Crops see the same sums as the full film.
        let c = run(&film(Some([5, 3, 30, 19])), 0..13);
        for y in 3..19usize {
            for x in 5..30usize {
                let pc = (y - 3) * 25 + (x - 5);
                let pf = y * 37 + x;
                assert_eq!(flat_bits(c.pixel(pc)), flat_bits(whole.pixel(pf)));
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

    /// Geometry with a known first hit per direction: nothing to the left (x < 0); to the
    /// right a fiber above the horizon (y > 0) and a surface below, at distance 1 + x.
    struct Quadrants;

    impl Quadrants {
        fn tangent(ray: &Ray) -> Vec3 {
            Vec3::new(ray.dir.y, 1.0, 0.5).normalize()
        }
    }

    impl Accel for Quadrants {
        fn intersect(&self, ray: &Ray) -> Option<Hit> {
            if ray.dir.x <= 0.0 {
                return None;
            }
            let t = 1.0 + ray.dir.x;
            let kind = if ray.dir.y > 0.0 {
                HitKind::Fiber {
                    tangent: Self::tangent(ray),
                    h: 0.0,
                    radius: 0.01,
                    strand: 0,
                    v: 0.5,
                    orientation: Vec3::Z,
                }
            } else {
                HitKind::Surface { normal: -ray.dir }
            };
            Some(Hit {
                t,
                p: ray.at(t),
                prim: crate::accel::PrimId { geom: 0, prim: 0 },
                material: 0,
                kind,
            })
        }
        fn occluded(&self, ray: &Ray) -> bool {
            ray.dir.x > 0.0
        }
        fn occluded_by_surfaces(&self, _: &Ray) -> bool {
            false
        }
        fn bounds(&self) -> Aabb {
            Aabb::EMPTY
        }
    }

    const ALBEDO: Rgb = Rgb::new(0.25, 0.5, 0.75);

    /// The quadrants, with a diffuse material (the fibers, wearing it, shade black).
    fn quadrants() -> Scene {
        Scene::new(
            Camera::perspective(Vec3::Z, Vec3::ZERO, Vec3::Y, 40.0, 0.0, None),
            Box::new(Quadrants),
            vec![crate::Material::Diffuse { albedo: ALBEDO }],
            Vec::new().into(),
        )
    }

    fn everything() -> Outputs {
        Outputs {
            alpha: true,
            aovs: Aov::ALL.into_iter().collect(),
        }
    }

    fn run_outputs(
        scene: &Scene,
        film: &FilmSettings,
        outputs: &Outputs,
        samples: Range<u64>,
    ) -> SampleRender {
        let never = AtomicBool::new(false);
        render_outputs(scene, &Noise, film, outputs, samples, &never, &|_| {}).unwrap()
    }

    fn channel_bits(sums: &SampleSums) -> Vec<(&'static str, Vec<u32>)> {
        sums.channels()
            .into_iter()
            .map(|(n, v)| (n, v.iter().map(|x| x.to_bits()).collect()))
            .collect()
    }

    #[test]
    fn quantities_match_what_samples_write() {
        for bits in 0..32u32 {
            let mut outputs = Outputs {
                alpha: bits & 1 != 0,
                ..Default::default()
            };
            for (i, aov) in Aov::ALL.into_iter().enumerate() {
                if bits & (2 << i) != 0 {
                    outputs.aovs.insert(aov);
                }
            }
            let q = quantities(&outputs);
            assert_eq!(q.len(), quantity_count(&outputs), "{outputs:?}");
            let mut written = Vec::new();
            SampleRecord::default().write(&outputs, &mut written);
            assert_eq!(written.len(), q.len(), "{outputs:?}");
            let names: std::collections::HashSet<&str> = q.iter().map(|q| q.name()).collect();
            assert_eq!(names.len(), q.len(), "names are unique");
        }
        assert_eq!(
            quantities(&Outputs::default()),
            [Quantity::R, Quantity::G, Quantity::B]
        );
    }

    /// Every output channel against its definition, computed sample by sample here; the
    /// radiance stays bit for bit what a render of radiance alone gives.
    #[test]
    fn output_channels_follow_their_definitions() {
        let scene = quadrants();
        let f = film(None);
        let all = run_outputs(&scene, &f, &everything(), 0..13);
        let plain = run_outputs(&scene, &f, &Outputs::default(), 0..13);
        let channels = all.sums.channels();
        let names: Vec<&str> = channels.iter().map(|c| c.0).collect();
        assert_eq!(names, everything().channel_names());
        assert_eq!(channel_bits(&plain.sums)[..], channel_bits(&all.sums)[..3]);
        // One occlusion or hit query per sample, counted; the integrator traces nothing here.
        assert_eq!(plain.stats.rays, 0);
        assert_eq!(all.stats.rays, 37 * 21 * 13);
        let value = |name: &str, p: usize| channels.iter().find(|c| c.0 == name).unwrap().1[p];
        let (mut saw_partial, mut saw_fiber) = (false, false);
        for y in 0..21u32 {
            for x in 0..37u32 {
                let p = (y * 37 + x) as usize;
                let (mut hits, mut fibers, mut distance) = (0.0f64, 0.0f64, 0.0f64);
                let (mut tangent, mut albedo) = ([0.0f64; 3], [0.0f64; 3]);
                let (mut sum, mut squares) = ([0.0f64; 3], [0.0f64; 3]);
                for s in 0..13 {
                    let (ray, mut sampler) = camera_sample(&scene.camera, &f, x, y, s);
                    let l = Noise.li(&ray, &scene, &mut sampler);
                    if l.is_finite() {
                        for c in 0..3 {
                            sum[c] += l[c] as f64;
                            squares[c] += (l[c] as f64).powi(2);
                        }
                    }
                    if ray.dir.x > 0.0 {
                        hits += 1.0;
                        distance += (1.0 + ray.dir.x) as f64;
                        if ray.dir.y > 0.0 {
                            fibers += 1.0;
                            let t = Quadrants::tangent(&ray);
                            for c in 0..3 {
                                tangent[c] += t[c] as f64;
                            }
                        } else {
                            for c in 0..3 {
                                albedo[c] += ALBEDO[c] as f64;
                            }
                        }
                    }
                }
                let close = |got: f32, want: f64, what: &str| {
                    let tolerance = 1e-5 * want.abs().max(1e-3);
                    assert!(
                        (got as f64 - want).abs() <= tolerance,
                        "{what} at ({x}, {y}): {got} vs {want}"
                    );
                };
                assert_eq!(value("A", p), (hits / 13.0) as f32, "alpha at ({x}, {y})");
                saw_partial |= hits > 0.0 && hits < 13.0;
                saw_fiber |= fibers > 0.0;
                if hits == 0.0 {
                    assert_eq!(value("depth.Z", p), f32::INFINITY);
                    assert_eq!(value("albedo.G", p), 0.0);
                } else {
                    close(value("depth.Z", p), distance / hits, "depth");
                    for (c, name) in ["albedo.R", "albedo.G", "albedo.B"].iter().enumerate() {
                        close(value(name, p), albedo[c] / hits, name);
                    }
                }
                for (c, name) in ["tangent.X", "tangent.Y", "tangent.Z"].iter().enumerate() {
                    let want = if fibers > 0.0 {
                        tangent[c] / fibers
                    } else {
                        0.0
                    };
                    close(value(name, p), want, name);
                }
                for (c, name) in ["variance.R", "variance.G", "variance.B"]
                    .iter()
                    .enumerate()
                {
                    let (n, mean) = (13.0, sum[c] / 13.0);
                    let want = (squares[c] / n - mean * mean) * n / (n - 1.0) / n;
                    let got = value(name, p) as f64;
                    assert!(
                        (got - want).abs() <= 1e-4 * want.max(1e-6),
                        "{name} at ({x}, {y}): {got} vs {want}"
                    );
                }
            }
        }
        assert!(
            saw_partial && saw_fiber,
            "the film must straddle the quadrants"
        );
        // Below two samples the variance is unknown.
        let one = run_outputs(&scene, &f, &everything(), 0..1).sums.channels();
        let variance = &one.iter().find(|c| c.0 == "variance.G").unwrap().1;
        assert!(variance.iter().all(|v| *v == f32::INFINITY));
    }

    /// Alpha and the AOVs merge, resume and crop as exactly as the radiance does, and do not
    /// depend on the thread count.
    #[test]
    fn output_channels_are_exact_for_any_split_crop_and_thread_count() {
        let scene = quadrants();
        let f = film(None);
        let outputs = everything();
        let whole = run_outputs(&scene, &f, &outputs, 0..13).sums;
        for cuts in [vec![0, 1, 2, 4, 8, 13], vec![0, 5, 13]] {
            let mut acc = SampleSums::empty(f.window(), 37, 21, 0, outputs.clone());
            for w in cuts.windows(2) {
                acc.append(&run_outputs(&scene, &f, &outputs, w[0]..w[1]).sums)
                    .unwrap();
            }
            assert_eq!(flat_bits(&acc.sums), flat_bits(&whole.sums), "{cuts:?}");
            assert_eq!(channel_bits(&acc), channel_bits(&whole), "{cuts:?}");
        }
        let crop = run_outputs(&scene, &film(Some([5, 3, 30, 19])), &outputs, 0..13).sums;
        let (cropped, full) = (crop.channels(), whole.channels());
        for ((name, c), (_, w)) in cropped.iter().zip(&full) {
            for y in 3..19usize {
                for x in 5..30usize {
                    let (pc, pf) = ((y - 3) * 25 + (x - 5), y * 37 + x);
                    assert_eq!(c[pc].to_bits(), w[pf].to_bits(), "{name} at ({x}, {y})");
                }
            }
        }
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let other = pool.install(|| run_outputs(&scene, &f, &outputs, 0..13).sums);
            assert_eq!(
                flat_bits(&other.sums),
                flat_bits(&whole.sums),
                "{threads} threads"
            );
        }
        // Sums of other outputs do not join.
        let mut radiance = run_outputs(&scene, &f, &Outputs::default(), 0..4).sums;
        let later = run_outputs(&scene, &f, &outputs, 4..6).sums;
        let msg = radiance.append(&later).unwrap_err().to_string();
        assert!(
            msg.contains("outputs differ") && msg.contains("depth.Z"),
            "{msg}"
        );
        // Alpha alone takes the any-hit query and gives the same alpha.
        let alpha_only = Outputs {
            alpha: true,
            ..Default::default()
        };
        let a = run_outputs(&scene, &f, &alpha_only, 0..13).sums.channels();
        assert_eq!(a[3].0, "A");
        assert_eq!(a[3].1, full[3].1);
    }

    #[test]
    fn memory_estimate_counts_the_recorded_quantities() {
        let f = film(None);
        let plain = f.memory_bytes();
        assert_eq!(
            plain,
            2 * 37 * 21 * (24 * 4 + 12),
            "13 spp: 4 blocks of RGB"
        );
        let all = f.memory_bytes_for(&everything());
        let channels = everything().channel_names().len() as u64;
        assert_eq!(all, 2 * 37 * 21 * (8 * 15 * 4 + 4 * channels));
    }
}
