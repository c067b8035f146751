//! A radiance cache: mean outgoing radiance per (cell, direction bin), at several cell sizes.
//!
//! A record is one unbiased estimate of the radiance leaving a point toward a direction (the
//! rest of a training path). Records are summed per chunk of training paths and the chunks'
//! sums merged in chunk order, so the cache does not depend on how threads shared the chunks.
//! Cells are cubes of a lattice
//! over the scene's bounds, `2^finest` along the longest side, halved per coarser level; a
//! lookup takes the finest level whose cell and bin hold enough records, which puts fine cells
//! where the training paths went often (the hair near its surface) and coarse ones elsewhere.

use crate::Lattice;
use rustc_hash::FxHashMap;
use tress_core::math::{Rgb, Vec3};

/// Sums of records.
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    rgb: [f64; 3],
    count: u32,
}

impl Sums {
    fn add(&mut self, other: &Sums) {
        for (a, b) in self.rgb.iter_mut().zip(other.rgb) {
            *a += b;
        }
        self.count += other.count;
    }
}

/// Records summed per cell and bin of one level — the finest until [`Records::coarsen`]: one
/// training chunk's, or all of them.
#[derive(Clone, Default)]
pub struct Records {
    cells: FxHashMap<u64, Sums>,
    /// The lattice level of `cells`' keys (0: the finest).
    level: u32,
    /// Records added (those dropped for carrying no estimate not counted).
    pub count: u64,
}

impl Records {
    /// Adds one record; non-finite or negative values are dropped (they carry no estimate).
    pub fn add(&mut self, lattice: &Lattice, p: Vec3, dir: Vec3, radiance: Rgb) {
        if !(radiance.is_finite() && radiance.min_element() >= 0.0 && p.is_finite()) {
            return;
        }
        let (c, bin) = lattice.locate(p, dir);
        let sums = self
            .cells
            .entry(lattice.key(self.level, c, bin))
            .or_default();
        sums.add(&Sums {
            rgb: radiance.to_array().map(f64::from),
            count: 1,
        });
        self.count += 1;
    }

    /// Adds a later chunk's records, at the coarser of the two levels. Floating-point sums
    /// depend on their order, so chunks must be merged in a fixed order for the cache to be
    /// the same on every run.
    pub fn merge(&mut self, later: &Records) {
        while self.level < later.level {
            self.coarsen_once();
        }
        // Keys in sorted order: a map's iteration order depends on its history.
        let mut keys: Vec<_> = later.cells.keys().copied().collect();
        keys.sort_unstable();
        for key in keys {
            self.cells
                .entry(Lattice::coarsen_key(key, self.level))
                .or_default()
                .add(&later.cells[&key]);
        }
        self.count += later.count;
    }

    /// Cells (cell and direction bin) that hold records.
    pub fn cells(&self) -> usize {
        self.cells.len()
    }

    /// The lattice level the records are summed at (0: the finest).
    pub fn level(&self) -> u32 {
        self.level
    }

    /// Merges every cell's sums into those of its cell one level coarser, which becomes the
    /// finest a cache built from them has: bounds their number (a quarter to an eighth as many
    /// cells where records are dense) at the cost of the finest lookups. `false`, changing
    /// nothing, at `lattice`'s coarsest level.
    pub fn coarsen(&mut self, lattice: &Lattice) -> bool {
        let coarser = self.level + 1 < lattice.levels();
        if coarser {
            self.coarsen_once();
        }
        coarser
    }

    fn coarsen_once(&mut self) {
        self.level += 1;
        // Keys in sorted order, as a cache sums its coarser levels, so that a coarsened level
        // is bit for bit the one a cache would have built.
        let mut keys: Vec<_> = self.cells.keys().copied().collect();
        keys.sort_unstable();
        let mut coarser = FxHashMap::<u64, Sums>::default();
        for key in keys {
            coarser
                .entry(Lattice::coarsen_key(key, self.level))
                .or_default()
                .add(&self.cells[&key]);
        }
        self.cells = coarser;
    }
}

/// A cell's mean radiance and how many records it averages.
#[derive(Clone, Copy, Debug)]
struct Cell {
    mean: Rgb,
    count: u32,
}

/// The cache a render looks radiance up in.
pub struct RadianceCache {
    lattice: Lattice,
    cells: FxHashMap<u64, Cell>,
    /// The finest level with cells: the records' level.
    first_level: u32,
    min_records: u32,
    records: u64,
}

impl RadianceCache {
    /// The cells of `records`' level and every coarser one; a lookup uses a cell only when
    /// it averages at least `min_records` records. Borrows the records (training goes on from
    /// them) and holds the sums of two levels at a time while it builds.
    pub fn new(lattice: Lattice, records: &Records, min_records: u32) -> Self {
        let mut cells = FxHashMap::default();
        let mut add_level = |sums: &FxHashMap<u64, Sums>| {
            cells.extend(sums.iter().filter(|(_, s)| s.count > 0).map(|(&key, s)| {
                let mean = Vec3::from_array(s.rgb.map(|v| (v / s.count as f64) as f32));
                let count = s.count;
                (key, Cell { mean, count })
            }));
        };
        add_level(&records.cells);
        let mut finer: Option<FxHashMap<u64, Sums>> = None;
        for level in records.level + 1..lattice.levels() {
            let from = finer.as_ref().unwrap_or(&records.cells);
            let mut coarser = FxHashMap::default();
            // Keys in sorted order: a sum's rounding depends on the order of its terms.
            let mut keys: Vec<_> = from.keys().copied().collect();
            keys.sort_unstable();
            for key in keys {
                coarser
                    .entry(Lattice::coarsen_key(key, level))
                    .or_insert_with(Sums::default)
                    .add(&from[&key]);
            }
            add_level(&coarser);
            finer = Some(coarser);
        }
        RadianceCache {
            lattice,
            cells,
            first_level: records.level,
            min_records,
            records: records.count,
        }
    }

    /// The radiance leaving `p` toward `dir`, from the finest level whose cell around `p` holds
    /// enough records: the records of that cell and its neighbours, weighted by a tent around
    /// `p` one cell wide (trilinear interpolation of the cells' means, weighted by their
    /// counts), so that neighbouring points see a smooth average rather than the steps and the
    /// independent noise of single cells. `None` where no level has enough.
    pub fn lookup(&self, p: Vec3, dir: Vec3) -> Option<Rgb> {
        let p = self.lattice.clamp(p);
        let (c, bin) = self.lattice.locate(p, dir);
        let level = (self.first_level..self.lattice.levels()).find(|&level| {
            self.cells
                .get(&self.lattice.key(level, c, bin))
                .is_some_and(|cell| cell.count >= self.min_records)
        })?;
        // Position in cells of this level, relative to the centres of the cells below it.
        let side = self.lattice.cell_side(level);
        let u = (p - self.lattice.origin()) / side - Vec3::splat(0.5);
        let base = u.floor();
        let t = u - base;
        let mut sum = Rgb::ZERO;
        let mut weight = 0.0;
        for corner in 0..8u32 {
            let offset = Vec3::new(
                (corner & 1) as f32,
                ((corner >> 1) & 1) as f32,
                (corner >> 2) as f32,
            );
            let at = base + offset;
            let cells_per_side = (1u32 << (self.lattice.finest() - level)) as f32;
            if at.min_element() < 0.0 || at.max_element() >= cells_per_side {
                continue;
            }
            let w = Vec3::ONE - (t - offset).abs();
            let w = w.x * w.y * w.z;
            let key =
                self.lattice
                    .key_at_level(level, [at.x as u32, at.y as u32, at.z as u32], bin);
            if let Some(cell) = self.cells.get(&key) {
                sum += cell.mean * (w * cell.count as f32);
                weight += w * cell.count as f32;
            }
        }
        (weight > 0.0).then(|| sum / weight)
    }

    /// One line for logs.
    pub fn describe(&self) -> String {
        format!(
            "radiance cache: {} records in {} cells of {} levels ({} to {} cells along the \
             longest side, {} direction bins)",
            self.records,
            self.cells.len(),
            self.lattice.levels() - self.first_level,
            1u32 << (self.lattice.finest() - self.first_level),
            1u32 << (self.lattice.finest() + 1 - self.lattice.levels()),
            self.lattice.bins() * self.lattice.bins()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::unit_box;

    #[test]
    fn a_lookup_takes_the_finest_level_with_enough_records() {
        // Four levels over the unit box: 8, 4, 2, 1 cells per side.
        let lattice = Lattice::new(unit_box(), 3, 4, 1);
        let mut records = Records::default();
        // Three records in the finest cell at the origin, five in the rest of its level-1
        // cell, and far away one record of another value.
        for _ in 0..3 {
            records.add(&lattice, Vec3::splat(0.01), Vec3::Z, Rgb::splat(1.0));
        }
        for _ in 0..5 {
            records.add(&lattice, Vec3::splat(0.2), Vec3::Z, Rgb::splat(3.0));
        }
        records.add(&lattice, Vec3::splat(0.9), Vec3::Z, Rgb::splat(100.0));
        let at = |min_records| RadianceCache::new(lattice, &records, min_records);
        // The centre of the finest cell at the origin.
        let origin = Vec3::splat(0.0625);
        assert_eq!(at(3).lookup(origin, Vec3::Z), Some(Rgb::splat(1.0)));
        // Not enough in the finest cell: its parent's mean, (3·1 + 5·3) / 8.
        assert_eq!(at(4).lookup(origin, Vec3::Z), Some(Rgb::splat(2.25)));
        // Only the whole box has nine.
        assert_eq!(at(9).lookup(origin, Vec3::Z), Some(Rgb::splat(118.0 / 9.0)));
        assert_eq!(at(10).lookup(origin, Vec3::Z), None);
        // Points outside the lattice are clamped into it.
        assert_eq!(
            at(3).lookup(Vec3::splat(-5.0), Vec3::Z),
            Some(Rgb::splat(1.0))
        );
    }

    #[test]
    fn lookups_interpolate_between_cell_centres() {
        // Two cells side by side along x, equally many records of 1 and of 3.
        let lattice = Lattice::new(unit_box(), 1, 1, 1);
        let mut records = Records::default();
        for _ in 0..4 {
            records.add(&lattice, Vec3::new(0.1, 0.1, 0.1), Vec3::Z, Rgb::splat(1.0));
            records.add(&lattice, Vec3::new(0.9, 0.1, 0.1), Vec3::Z, Rgb::splat(3.0));
        }
        let cache = RadianceCache::new(lattice, &records, 1);
        let at = |x: f32| cache.lookup(Vec3::new(x, 0.25, 0.25), Vec3::Z).unwrap().x;
        assert_eq!(at(0.25), 1.0);
        assert_eq!(at(0.5), 2.0);
        assert!((at(0.625) - 2.5).abs() < 1e-6);
        assert_eq!(at(0.75), 3.0);
        // Beyond the outermost centres there is nothing to interpolate toward.
        assert_eq!(at(0.95), 3.0);
    }

    #[test]
    fn records_that_carry_no_estimate_are_dropped() {
        let lattice = Lattice::new(unit_box(), 1, 1, 1);
        let mut records = Records::default();
        records.add(&lattice, Vec3::ZERO, Vec3::Z, Rgb::new(f32::NAN, 0.0, 0.0));
        records.add(&lattice, Vec3::ZERO, Vec3::Z, Rgb::new(-1.0, 0.0, 0.0));
        records.add(&lattice, Vec3::NAN, Vec3::Z, Rgb::ONE);
        assert_eq!(records.count, 0);
        let cache = RadianceCache::new(lattice, &records, 1);
        assert_eq!(cache.lookup(Vec3::ZERO, Vec3::Z), None);
    }

    /// Records of fixed pseudo-random points, directions and values over the unit box.
    fn scattered(lattice: &Lattice, n: u32) -> Records {
        let mut records = Records::default();
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for _ in 0..n {
            let p = Vec3::new(next(), next(), next());
            let dir = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize();
            records.add(lattice, p, dir, Rgb::new(next(), next(), 4.0 * next()));
        }
        records
    }

    #[test]
    fn coarsening_drops_only_the_finest_level() {
        let lattice = Lattice::new(unit_box(), 4, 5, 2);
        let fine = scattered(&lattice, 20_000);
        let mut coarse = fine.clone();
        assert!(coarse.coarsen(&lattice));
        assert_eq!(coarse.level(), 1);
        assert_eq!(coarse.count, fine.count);
        // 16³ cells of 4 bins at most, 8³ after: 20 000 records fill most of both.
        assert!(fine.cells() > 4 * coarse.cells(), "{}", fine.cells());
        // With more records a cell than any finest cell holds (1.2 on average), both caches
        // read level 1 (9.8 on average) or coarser, and the coarsened records sum it in the order a cache does: bit for bit.
        let (a, b) = (
            RadianceCache::new(lattice, &fine, 12),
            RadianceCache::new(lattice, &coarse, 12),
        );
        for r in scattered(&lattice, 500).cells.keys() {
            let (_, c, bin) = Lattice::split_key(*r);
            let p = (Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) + 0.3) / 16.0;
            let dir = [Vec3::X, -Vec3::Y, Vec3::Z, -Vec3::Z][bin as usize];
            assert_eq!(a.lookup(p, dir), b.lookup(p, dir), "at {p}");
            assert!(b.lookup(p, dir).is_some());
        }
        // Down to the coarsest level, and no further.
        while coarse.coarsen(&lattice) {}
        assert_eq!(coarse.level(), 4);
        assert!(coarse.cells() <= 4);
        assert!(RadianceCache::new(lattice, &coarse, 1)
            .lookup(Vec3::splat(0.5), Vec3::Z)
            .is_some());
    }

    #[test]
    fn finer_records_merge_into_coarsened_ones() {
        let lattice = Lattice::new(unit_box(), 3, 4, 1);
        let mut all = Records::default();
        all.add(&lattice, Vec3::splat(0.01), Vec3::Z, Rgb::splat(1.0));
        assert!(all.coarsen(&lattice));
        let mut later = Records::default();
        later.add(&lattice, Vec3::splat(0.2), Vec3::Z, Rgb::splat(3.0));
        all.merge(&later);
        assert_eq!((all.level(), all.cells(), all.count), (1, 1, 2));
        // And coarsened records merged into finer ones coarsen those first.
        let mut fine = later.clone();
        fine.merge(&all);
        assert_eq!((fine.level(), fine.cells(), fine.count), (1, 1, 3));
        let cache = RadianceCache::new(lattice, &fine, 3);
        let mean = cache.lookup(Vec3::splat(0.125), Vec3::Z).unwrap();
        assert!(
            (mean - Rgb::splat(7.0 / 3.0)).abs().max_element() < 1e-6,
            "{mean}"
        );
    }
}
