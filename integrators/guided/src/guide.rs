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
    /// Cumulative distribution over the bins of each cell (every level's), ending at 1.
    cells: FxHashMap<u64, Box<[f32]>>,
    min_records: u32,
    records: u64,
}

/// Share of a cell's density spread uniformly over the sphere.
const UNIFORM_SHARE: f32 = 0.1;

impl Guide {
    /// The densities of every level's cells that hold at least `min_records` records.
    pub(crate) fn new(lattice: Lattice, records: &Records, min_records: u32) -> Self {
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
                        cells.insert(key, cdf);
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

    /// The distribution of the finest cell around `p` that holds enough records.
    pub(crate) fn find(&self, p: Vec3) -> Option<&[f32]> {
        let c = self.lattice.cell_of(p);
        (0..self.lattice.levels()).find_map(|level| {
            self.cells
                .get(&self.lattice.key(level, c, 0))
                .map(|cdf| &cdf[..])
        })
    }

    /// A direction drawn from a cell's distribution and its solid-angle density.
    pub(crate) fn sample(&self, cdf: &[f32], u: [f32; 3]) -> (Vec3, f32) {
        let bin = cdf.partition_point(|&c| c <= u[0]).min(cdf.len() - 1);
        let wi = self.bins.direction_in(bin, Vec2::new(u[1], u[2]));
        // The density of the bin the direction is found in: where rounding puts a direction
        // drawn at a bin's edge into its neighbour, sampling and `pdf` still agree.
        (wi, self.pdf(cdf, wi))
    }

    /// The solid-angle density of a cell's distribution at `wi`.
    pub(crate) fn pdf(&self, cdf: &[f32], wi: Vec3) -> f32 {
        self.bin_pdf(cdf, self.bins.bin(wi))
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
        let guide = Guide::new(lattice, &records, 100);
        let cdf = guide
            .find(Vec3::splat(0.2))
            .expect("a cell with 400 records");
        // The integral over the sphere, by midpoint sums over each bin.
        let integral: f32 = (0..bins.count())
            .map(|b| {
                guide.pdf(cdf, bins.direction_in(b, Vec2::splat(0.5))) * bins.bin_solid_angle()
            })
            .sum();
        assert!((integral - 1.0).abs() < 1e-5, "{integral}");
        let n = 200_000;
        let mut counts = vec![0u32; bins.count()];
        let mut rng = tress_core::Sampler::from_seed(5);
        for _ in 0..n {
            let u = rng.next_4d();
            let (wi, pdf) = guide.sample(cdf, [u[0], u[1], u[2]]);
            assert_eq!(pdf, guide.pdf(cdf, wi));
            counts[bins.bin(wi)] += 1;
        }
        for (b, &c) in counts.iter().enumerate() {
            let p = guide.pdf(cdf, bins.direction_in(b, Vec2::splat(0.5))) * bins.bin_solid_angle();
            let expected = p as f64 * n as f64;
            let sd = (expected * (1.0 - p as f64)).sqrt();
            assert!(
                (c as f64 - expected).abs() < 5.0 * sd + 1.0,
                "bin {b}: {c} vs {expected}"
            );
        }
        // Too few records in the cell and the whole box: no guide.
        assert!(Guide::new(lattice, &records, 401)
            .find(Vec3::splat(0.2))
            .is_none());
    }
}
