//! The learned distribution of incident light: per cell of a [`Lattice`], a piecewise-constant
//! density over the whole sphere of directions, in equal-area bins.
//!
//! A record is one direction `wi` at a point with a non-negative value: an estimate of the
//! light arriving along `wi` divided by the density it was sampled with, so that a bin's sum
//! estimates the light arriving through the bin (or, for [`Target::Contribution`], what that
//! light contributes once scattered). Records are summed per finest-level cell and bin; coarser
//! levels sum their cells; a lookup takes the finest level whose cell holds `min_records`.
//! The density of a cell is its bins' sums normalised, with a share spread uniformly so that
//! a bin no record reached keeps some density.

use rustc_hash::FxHashMap;
use std::f32::consts::{PI, TAU};
use tress_core::math::{Vec2, Vec3};
use tress_learned_light::Lattice;

/// Equal-area bins over the sphere: `z_bins` bands of equal height in z (Archimedes: equal
/// area) times `phi_bins` equal sectors in azimuth, in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SphereBins {
    z_bins: u32,
    phi_bins: u32,
}

impl SphereBins {
    pub(crate) fn new(z_bins: u32, phi_bins: u32) -> Self {
        SphereBins { z_bins, phi_bins }
    }

    pub(crate) fn count(&self) -> usize {
        (self.z_bins * self.phi_bins) as usize
    }

    /// The bin of unit direction `d`.
    pub(crate) fn bin(&self, d: Vec3) -> usize {
        let z = ((d.z * 0.5 + 0.5) * self.z_bins as f32) as u32;
        let mut phi = d.y.atan2(d.x);
        if phi < 0.0 {
            phi += TAU;
        }
        let p = (phi * (self.phi_bins as f32 / TAU)) as u32;
        (z.min(self.z_bins - 1) * self.phi_bins + p.min(self.phi_bins - 1)) as usize
    }

    /// A uniformly distributed direction in bin `bin`, from `u` in [0, 1)².
    pub(crate) fn direction_in(&self, bin: usize, u: Vec2) -> Vec3 {
        let (iz, ip) = (bin as u32 / self.phi_bins, bin as u32 % self.phi_bins);
        let z = (-1.0 + 2.0 * (iz as f32 + u.x) / self.z_bins as f32).clamp(-1.0, 1.0);
        let phi = TAU * (ip as f32 + u.y) / self.phi_bins as f32;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let (sin, cos) = phi.sin_cos();
        Vec3::new(r * cos, r * sin, z)
    }

    /// Solid angle of one bin.
    fn bin_solid_angle(&self) -> f32 {
        4.0 * PI / self.count() as f32
    }
}

/// What the records estimate, and so what the guide's density follows.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
pub enum Target {
    /// The incident radiance's luminance (Müller et al. 2017): where light comes from.
    #[default]
    Radiance,
    /// The incident radiance's luminance times the fiber's scattering toward the cell's
    /// visitors: where the light that reaches the camera comes from, averaged over the
    /// fibers and viewing directions of the cell.
    Contribution,
}

/// One record before it is summed.
#[derive(Clone, Copy, Debug)]
struct Entry {
    /// Finest-level cell key (bin 0).
    cell: u64,
    bin: u16,
    value: f32,
}

/// Records of one training chunk, in the order they were made.
#[derive(Default)]
pub(crate) struct ChunkRecords {
    entries: Vec<Entry>,
    pub(crate) continuations: Vec<Continuation>,
}

/// A continuation drawn at a guided vertex of a training path, kept to choose the probability
/// of drawing from the guide in its cell ([`Guide::learn_probabilities`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Continuation {
    /// The vertex's finest-level cell.
    cell: [u32; 3],
    bin: u16,
    /// The square of the estimate the continuation made (the luminance of f·cos·L over its
    /// density q), times q: its share of a second moment under another density p is this
    /// over p (importance weights).
    moment: f32,
    /// The fiber's own density of the direction.
    fiber_pdf: f32,
}

impl Continuation {
    /// `estimate` is the luminance of the continuation's f·cos·L / `pdf`, drawn with `pdf`.
    pub(crate) fn new(
        lattice: &Lattice,
        bins: &SphereBins,
        p: Vec3,
        wi: Vec3,
        estimate: f32,
        pdf: f32,
        fiber_pdf: f32,
    ) -> Option<Self> {
        let moment = estimate * estimate * pdf;
        (moment.is_finite() && moment > 0.0 && fiber_pdf.is_finite() && p.is_finite()).then(|| {
            Continuation {
                cell: lattice.cell_of(p),
                bin: bins.bin(wi) as u16,
                moment,
                fiber_pdf,
            }
        })
    }
}

impl ChunkRecords {
    /// Records `value` for direction `wi` at `p`; non-finite or negative values carry no
    /// estimate and are dropped.
    pub(crate) fn add(
        &mut self,
        lattice: &Lattice,
        bins: &SphereBins,
        p: Vec3,
        wi: Vec3,
        value: f32,
    ) {
        if !(value.is_finite() && value >= 0.0 && p.is_finite() && wi.is_finite()) {
            return;
        }
        self.entries.push(Entry {
            cell: lattice.key(0, lattice.cell_of(p), 0),
            bin: bins.bin(wi) as u16,
            value,
        });
    }
}

/// A cell's bins and how many records they sum.
#[derive(Clone, Debug)]
struct CellSums {
    bins: Box<[f32]>,
    count: u32,
}

impl CellSums {
    fn new(bins: usize) -> Self {
        CellSums {
            bins: vec![0.0; bins].into_boxed_slice(),
            count: 0,
        }
    }

    fn add(&mut self, other: &CellSums) {
        for (a, b) in self.bins.iter_mut().zip(other.bins.iter()) {
            *a += b;
        }
        self.count += other.count;
    }
}

/// The finest level's records, summed in a fixed order.
pub(crate) struct Records {
    bins: SphereBins,
    cells: FxHashMap<u64, CellSums>,
    pub(crate) count: u64,
}

impl Records {
    pub(crate) fn new(bins: SphereBins) -> Self {
        Records {
            bins,
            cells: FxHashMap::default(),
            count: 0,
        }
    }

    /// Adds a chunk's records, in their order: floating-point sums depend on it.
    pub(crate) fn merge(&mut self, chunk: &ChunkRecords) {
        let n = self.bins.count();
        for e in &chunk.entries {
            let cell = self.cells.entry(e.cell).or_insert_with(|| CellSums::new(n));
            cell.bins[e.bin as usize] += e.value;
            cell.count += 1;
        }
        self.count += chunk.entries.len() as u64;
    }
}

/// The guide a render samples directions from.
pub(crate) struct Guide {
    lattice: Lattice,
    bins: SphereBins,
    /// Every level's cells that hold enough records.
    cells: FxHashMap<u64, GuideCell>,
    min_records: u32,
    records: u64,
}

/// One cell's learned density, and how often continuations are drawn from it.
pub(crate) struct GuideCell {
    /// Cumulative distribution over the bins, ending at 1.
    cdf: Box<[f32]>,
    /// The probability of drawing a continuation from the guide rather than the fiber.
    pub(crate) probability: f32,
}

/// Candidate probabilities of drawing from the guide, as eighths of the largest allowed.
const PROBABILITY_STEPS: usize = 8;
/// Continuations a cell needs before its own probability is chosen; cells with fewer take the
/// one best over all continuations.
const MIN_CONTINUATIONS: u32 = 64;
/// How much smaller than the fiber's alone a mixture's predicted second moment must be for a
/// cell to guide.
const MIN_CELL_GAIN: f64 = 1.1;

/// Share of a cell's density spread uniformly over the sphere.
const UNIFORM_SHARE: f32 = 0.1;

/// Second moments of a cell's continuations under each candidate probability: of the
/// even-numbered continuations and of the odd-numbered ones.
#[derive(Default)]
struct CellMoments {
    sums: [[f64; PROBABILITY_STEPS + 1]; 2],
    count: u32,
}

impl CellMoments {
    fn add(&mut self, other: &CellMoments) {
        for (mine, theirs) in self.sums.iter_mut().zip(&other.sums) {
            for (a, b) in mine.iter_mut().zip(theirs) {
                *a += b;
            }
        }
        self.count += other.count;
    }

    /// The candidate the even-numbered continuations favour, if the odd-numbered ones find it
    /// [`MIN_CELL_GAIN`] times better than the fiber's sampling alone (guiding costs a lookup
    /// and the guide's density at every guided vertex); otherwise 0.
    fn choice(&self) -> usize {
        let [choose, judge] = &self.sums;
        let k = (0..=PROBABILITY_STEPS).fold(0, |b, k| if choose[k] < choose[b] { k } else { b });
        if judge[0] > MIN_CELL_GAIN * judge[k] {
            k
        } else {
            0
        }
    }
}

impl Guide {
    /// The densities of every level's cells that hold at least `min_records` records.
    /// Each draws from the guide with `probability` until [`Guide::learn_probabilities`].
    pub(crate) fn new(
        lattice: Lattice,
        records: &Records,
        min_records: u32,
        probability: f32,
    ) -> Self {
        let n = records.bins.count();
        let mut cells = FxHashMap::default();
        let mut finer: FxHashMap<u64, CellSums> = records.cells.clone();
        for level in 0..lattice.levels() {
            let mut keys: Vec<u64> = finer.keys().copied().collect();
            keys.sort_unstable();
            for &key in &keys {
                let sums = &finer[&key];
                if sums.count >= min_records {
                    if let Some(cdf) = cdf(&sums.bins) {
                        cells.insert(key, GuideCell { cdf, probability });
                    }
                }
            }
            if level + 1 == lattice.levels() {
                break;
            }
            let mut coarser: FxHashMap<u64, CellSums> = FxHashMap::default();
            for key in keys {
                let (_, c, _) = Lattice::split_key(key);
                coarser
                    .entry(lattice.key(level + 1, c, 0))
                    .or_insert_with(|| CellSums::new(n))
                    .add(&finer[&key]);
            }
            finer = coarser;
        }
        Guide {
            lattice,
            bins: records.bins,
            cells,
            min_records,
            records: records.count,
        }
    }

    /// The finest cell around `p` that holds enough records.
    pub(crate) fn find(&self, p: Vec3) -> Option<&GuideCell> {
        self.find_cell(self.lattice.cell_of(p))
            .map(|(_, cell)| cell)
    }

    /// The finest cell holding enough records among those around finest cell `c`, with its key.
    fn find_cell(&self, c: [u32; 3]) -> Option<(u64, &GuideCell)> {
        (0..self.lattice.levels()).find_map(|level| {
            let key = self.lattice.key(level, c, 0);
            self.cells.get(&key).map(|cell| (key, cell))
        })
    }

    /// A direction drawn from a cell's distribution and its solid-angle density.
    pub(crate) fn sample(&self, cell: &GuideCell, u: [f32; 3]) -> (Vec3, f32) {
        let cdf = &cell.cdf;
        let bin = cdf.partition_point(|&c| c <= u[0]).min(cdf.len() - 1);
        let wi = self.bins.direction_in(bin, Vec2::new(u[1], u[2]));
        // The density of the bin the direction is found in: where rounding puts a direction
        // drawn at a bin's edge into its neighbour, sampling and `pdf` still agree.
        (wi, self.pdf(cell, wi))
    }

    /// The solid-angle density of a cell's distribution at `wi`.
    pub(crate) fn pdf(&self, cell: &GuideCell, wi: Vec3) -> f32 {
        self.bin_pdf(&cell.cdf, self.bins.bin(wi))
    }

    /// Chooses each cell's probability of drawing from the guide among eighths of `largest`:
    /// the one that minimises the second moment of the continuations' estimates in the cell
    /// had they been drawn from that mixture, estimated from `continuations` (drawn from other
    /// densities) by importance weights, if it is [`MIN_CELL_GAIN`] times smaller than the
    /// fiber's sampling alone gives (half the continuations choose, the other half judge).
    /// Where the guide does not follow the light that much better than the fiber's own sampling
    /// does, it is 0 and the cell's vertices are the path tracer's. Returns the predicted gain:
    /// the second moment with the fiber's sampling alone over the one with the chosen
    /// probabilities, of the judging half of the continuations.
    pub(crate) fn learn_probabilities(
        &mut self,
        continuations: &[Continuation],
        largest: f32,
    ) -> f64 {
        let candidates: [f32; PROBABILITY_STEPS + 1] =
            std::array::from_fn(|k| largest * k as f32 / PROBABILITY_STEPS as f32);
        // Per cell, the second moment under each candidate of the even-numbered continuations,
        // which choose the candidate, and of the odd-numbered ones, which judge it: chosen and
        // judged by the same samples, the smallest of nine noisy sums promises gains the next
        // samples do not see.
        let mut moments: FxHashMap<u64, CellMoments> = FxHashMap::default();
        for (i, c) in continuations.iter().enumerate() {
            let Some((key, cell)) = self.find_cell(c.cell) else {
                continue;
            };
            let guide_pdf = self.bin_pdf(&cell.cdf, c.bin as usize);
            let m = moments.entry(key).or_default();
            let sums = &mut m.sums[i % 2];
            for (sum, &a) in sums.iter_mut().zip(&candidates) {
                let density = a * guide_pdf + (1.0 - a) * c.fiber_pdf;
                // A direction the mixture could not draw makes that candidate's estimator
                // miss light: never chosen.
                *sum += if density > 0.0 {
                    c.moment as f64 / density as f64
                } else {
                    f64::INFINITY
                };
            }
            m.count += 1;
        }
        let mut keys: Vec<u64> = moments.keys().copied().collect();
        keys.sort_unstable();
        let mut overall = CellMoments::default();
        for key in &keys {
            overall.add(&moments[key]);
        }
        let fallback = overall.choice();
        let (mut unguided, mut guided) = (0.0f64, 0.0f64);
        let choice = |m: &CellMoments| {
            if m.count >= MIN_CONTINUATIONS {
                m.choice()
            } else {
                fallback
            }
        };
        for key in &keys {
            let m = &moments[key];
            unguided += m.sums[1][0];
            guided += m.sums[1][choice(m)];
        }
        for (key, cell) in self.cells.iter_mut() {
            cell.probability = candidates[moments.get(key).map_or(fallback, choice)];
        }
        if guided > 0.0 {
            unguided / guided
        } else {
            1.0
        }
    }

    /// The share of cells that draw from the guide, and their mean probability of doing so.
    pub(crate) fn probabilities(&self) -> (f64, f64) {
        let guiding: Vec<f32> = self
            .cells
            .values()
            .map(|c| c.probability)
            .filter(|&p| p > 0.0)
            .collect();
        let share = guiding.len() as f64 / self.cells.len().max(1) as f64;
        let mean = guiding.iter().map(|&p| p as f64).sum::<f64>() / guiding.len().max(1) as f64;
        (share, mean)
    }

    fn bin_pdf(&self, cdf: &[f32], bin: usize) -> f32 {
        let below = if bin == 0 { 0.0 } else { cdf[bin - 1] };
        (cdf[bin] - below) / self.bins.bin_solid_angle()
    }

    /// One line for logs.
    pub(crate) fn describe(&self) -> String {
        format!(
            "guide: {} records, {} cells with at least {} ({} levels, {} to {} cells along \
             the longest side, {} direction bins)",
            self.records,
            self.cells.len(),
            self.min_records,
            self.lattice.levels(),
            1u32 << self.lattice.finest(),
            1u32 << (self.lattice.finest() + 1 - self.lattice.levels()),
            self.bins.count()
        )
    }

    /// Bytes the guide's cells hold.
    pub(crate) fn bytes(&self) -> usize {
        self.cells.len() * (self.bins.count() * 4 + 32)
    }
}

/// The cumulative distribution of `sums` with [`UNIFORM_SHARE`] of it spread uniformly;
/// `None` when the sums carry nothing.
fn cdf(sums: &[f32]) -> Option<Box<[f32]>> {
    let total: f64 = sums.iter().map(|&v| v as f64).sum();
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let n = sums.len() as f64;
    let share = UNIFORM_SHARE as f64;
    let mut acc = 0.0f64;
    let mut cdf: Box<[f32]> = sums
        .iter()
        .map(|&v| {
            acc += (1.0 - share) * v as f64 / total + share / n;
            acc as f32
        })
        .collect();
    // The last entry is 1 exactly, so that every u in [0, 1) finds a bin.
    *cdf.last_mut().expect("at least one bin") = 1.0;
    Some(cdf)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tress_core::math::Aabb;

    #[test]
    fn sphere_bins_are_found_by_the_directions_they_draw() {
        let bins = SphereBins::new(6, 12);
        for bin in 0..bins.count() {
            for u in [
                Vec2::new(0.01, 0.01),
                Vec2::new(0.5, 0.5),
                Vec2::new(0.99, 0.98),
            ] {
                let d = bins.direction_in(bin, u);
                assert!((d.length() - 1.0).abs() < 1e-5);
                assert_eq!(bins.bin(d), bin, "{d} u {u}");
            }
        }
    }

    /// The density integrates to 1 over the sphere and sampling follows it (every bin drawn
    /// as often as its probability says, within 5 standard deviations).
    #[test]
    fn cell_density_integrates_to_one_and_sampling_follows_it() {
        let unit = Aabb {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        let lattice = Lattice::new(unit, 1, 2, 1);
        let bins = SphereBins::new(4, 8);
        let mut chunk = ChunkRecords::default();
        for i in 0..400 {
            let d = bins.direction_in(i % 7, Vec2::new(0.3, 0.6));
            chunk.add(&lattice, &bins, Vec3::splat(0.2), d, (i % 7) as f32 + 1.0);
        }
        let mut records = Records::new(bins);
        records.merge(&chunk);
        let guide = Guide::new(lattice, &records, 100, 0.5);
        let cell = guide
            .find(Vec3::splat(0.2))
            .expect("a cell with 400 records");
        // The integral over the sphere, by midpoint sums over each bin.
        let integral: f32 = (0..bins.count())
            .map(|b| {
                guide.pdf(cell, bins.direction_in(b, Vec2::splat(0.5))) * bins.bin_solid_angle()
            })
            .sum();
        assert!((integral - 1.0).abs() < 1e-5, "{integral}");
        let n = 200_000;
        let mut counts = vec![0u32; bins.count()];
        let mut rng = tress_core::Sampler::from_seed(5);
        for _ in 0..n {
            let u = rng.next_4d();
            let (wi, pdf) = guide.sample(cell, [u[0], u[1], u[2]]);
            assert_eq!(pdf, guide.pdf(cell, wi));
            counts[bins.bin(wi)] += 1;
        }
        for (b, &c) in counts.iter().enumerate() {
            let p =
                guide.pdf(cell, bins.direction_in(b, Vec2::splat(0.5))) * bins.bin_solid_angle();
            let expected = p as f64 * n as f64;
            let sd = (expected * (1.0 - p as f64)).sqrt();
            assert!(
                (c as f64 - expected).abs() < 5.0 * sd + 1.0,
                "bin {b}: {c} vs {expected}"
            );
        }
        // Too few records in the cell and the whole box: no guide.
        assert!(Guide::new(lattice, &records, 401, 0.5)
            .find(Vec3::splat(0.2))
            .is_none());
    }

    /// A cell whose continuations carry light only where the guide is dense and the fiber's
    /// density is low learns to draw from the guide as often as allowed; one where the fiber's
    /// density already follows the light learns not to guide at all.
    #[test]
    fn cells_learn_to_guide_only_where_the_guide_follows_the_light_better() {
        let unit = Aabb {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        let lattice = Lattice::new(unit, 1, 1, 1);
        let bins = SphereBins::new(2, 2);
        let lit = bins.direction_in(0, Vec2::splat(0.5));
        let dark = bins.direction_in(3, Vec2::splat(0.5));
        let (guided_at, unguided_at) = (Vec3::splat(0.25), Vec3::splat(0.75));
        // Both cells' guides see the light arrive through bin 0.
        let mut chunk = ChunkRecords::default();
        for p in [guided_at, unguided_at] {
            for _ in 0..100 {
                chunk.add(&lattice, &bins, p, lit, 1.0);
            }
        }
        let mut records = Records::new(bins);
        records.merge(&chunk);
        let mut guide = Guide::new(lattice, &records, 100, 0.5);
        let uniform = 1.0 / (4.0 * PI);
        let mut continuations = Vec::new();
        for i in 0..200 {
            // Fiber-sampled directions (uniform density), light only in bin 0: the guide,
            // dense there, would have done better.
            let wi = if i % 4 == 0 { lit } else { dark };
            let estimate = if i % 4 == 0 { 4.0 } else { 0.0 };
            continuations.extend(Continuation::new(
                &lattice, &bins, guided_at, wi, estimate, uniform, uniform,
            ));
            // The fiber's own density already puts its samples where the light is, and the
            // light comes from every direction: the guide, dense in bin 0 only, can only add
            // variance.
            let wi = bins.direction_in(i % 4, Vec2::splat(0.5));
            continuations.extend(Continuation::new(
                &lattice,
                &bins,
                unguided_at,
                wi,
                1.0,
                uniform,
                uniform,
            ));
        }
        let gain = guide.learn_probabilities(&continuations, 0.5);
        assert_eq!(guide.find(guided_at).unwrap().probability, 0.5);
        assert_eq!(guide.find(unguided_at).unwrap().probability, 0.0);
        assert!(gain > 1.05, "{gain}");
        // Nothing to learn from: every cell takes the fallback, which is not to guide.
        let mut idle = Guide::new(lattice, &records, 100, 0.5);
        assert_eq!(idle.learn_probabilities(&[], 0.5), 1.0);
        assert_eq!(idle.probabilities().0, 0.0);
    }
}
