//! Cubic cells over the scene's bounds at several sizes, and octahedral direction bins.

use tress_core::math::{Aabb, Vec3};

/// How positions and directions are quantised: cubes of a lattice over the scene's bounds,
/// `2^finest` along the longest side at level 0 and half as many per side at each coarser
/// level; directions in `bins × bins` bins of the octahedral map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lattice {
    origin: Vec3,
    /// Side of a finest-level cell.
    cell: f32,
    /// Cells per side at the finest level, as a power of two.
    finest: u32,
    /// Levels, finest first.
    levels: u32,
    /// Direction bins per side of the octahedral map.
    bins: u32,
}

impl Lattice {
    /// Levels a key can name: the level takes its top 4 bits.
    pub const MAX_LEVELS: u32 = 16;

    /// A lattice over `bounds` with `2^finest` cells along their longest side, `levels`
    /// levels and `bins × bins` direction bins.
    pub fn new(bounds: Aabb, finest: u32, levels: u32, bins: u32) -> Self {
        let extent = (bounds.max - bounds.min)
            .max_element()
            .max(f32::MIN_POSITIVE);
        Lattice {
            origin: bounds.min,
            cell: extent / (1u32 << finest) as f32,
            finest,
            levels,
            bins,
        }
    }

    /// Levels, finest (0) first.
    pub fn levels(&self) -> u32 {
        self.levels
    }

    /// Cells per side at the finest level, as a power of two.
    pub fn finest(&self) -> u32 {
        self.finest
    }

    /// Direction bins per side of the octahedral map.
    pub fn bins(&self) -> u32 {
        self.bins
    }

    /// `p` moved into the lattice's box.
    pub fn clamp(&self, p: Vec3) -> Vec3 {
        let extent = self.cell * (1u32 << self.finest) as f32;
        p.clamp(self.origin, self.origin + Vec3::splat(extent))
    }

    /// The finest level's cell coordinates of `p`, clamped to the lattice.
    pub fn cell_of(&self, p: Vec3) -> [u32; 3] {
        let max = ((1u32 << self.finest) - 1) as f32;
        let c = ((p - self.origin) / self.cell).clamp(Vec3::ZERO, Vec3::splat(max));
        [c.x as u32, c.y as u32, c.z as u32]
    }

    /// The finest level's cell coordinates of `p` (clamped to the lattice) and the direction
    /// bin of `dir`.
    pub fn locate(&self, p: Vec3, dir: Vec3) -> ([u32; 3], u32) {
        (self.cell_of(p), self.direction_bin(dir))
    }

    /// Octahedral map of a unit direction onto [0, 1)², quantised to `bins × bins`.
    pub fn direction_bin(&self, d: Vec3) -> u32 {
        let l1 = d.x.abs() + d.y.abs() + d.z.abs();
        let (mut u, mut v) = (d.x / l1, d.y / l1);
        if d.z < 0.0 {
            (u, v) = ((1.0 - v.abs()) * u.signum(), (1.0 - u.abs()) * v.signum());
        }
        let n = self.bins as f32;
        let q = |x: f32| (((x * 0.5 + 0.5) * n) as u32).min(self.bins - 1);
        q(u) * self.bins + q(v)
    }

    /// The key of level `level`'s cell containing finest-level cell `c`, bin `bin`.
    pub fn key(&self, level: u32, c: [u32; 3], bin: u32) -> u64 {
        self.key_at_level(level, c.map(|v| v >> level), bin)
    }

    /// The key of level `level`'s cell `c` (in that level's cells), bin `bin`.
    pub fn key_at_level(&self, level: u32, c: [u32; 3], bin: u32) -> u64 {
        pack(level, c, bin)
    }

    /// The key of the level-`level` cell holding the cell `key` names (of a level no coarser),
    /// same bin.
    pub fn coarsen_key(key: u64, level: u32) -> u64 {
        let (_, c, bin) = Self::split_key(key);
        pack(level, c.map(|v| v >> level), bin)
    }

    /// The finest-level cell a key names (its level, cell and bin), as coordinates of the
    /// cell's first finest-level cell.
    pub fn split_key(key: u64) -> (u32, [u32; 3], u32) {
        let level = (key >> 60) as u32;
        let bin = ((key >> 48) & 0xfff) as u32;
        let c =
            [key & 0xffff, (key >> 16) & 0xffff, (key >> 32) & 0xffff].map(|v| (v as u32) << level);
        (level, c, bin)
    }

    /// Side of a cell of level `level`.
    pub fn cell_side(&self, level: u32) -> f32 {
        self.cell * (1u32 << level) as f32
    }

    /// The lattice's origin (the minimum corner of its box).
    pub fn origin(&self) -> Vec3 {
        self.origin
    }
}

/// A key from its level, the cell's coordinates in that level's cells and the bin.
fn pack(level: u32, c: [u32; 3], bin: u32) -> u64 {
    let [x, y, z] = c.map(u64::from);
    (level as u64) << 60 | (bin as u64) << 48 | z << 32 | y << 16 | x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::unit_box;

    /// Directions spread over the sphere (a Fibonacci lattice).
    fn directions(n: usize) -> impl Iterator<Item = Vec3> {
        (0..n).map(move |i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let phi = i as f32 * 2.399_963;
            let r = (1.0 - z * z).sqrt();
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
    }

    #[test]
    fn direction_bins_cover_the_sphere_evenly() {
        let lattice = Lattice::new(unit_box(), 3, 1, 4);
        let mut counts = [0u32; 16];
        let n = 16_000;
        for d in directions(n) {
            counts[lattice.direction_bin(d) as usize] += 1;
        }
        // The octahedral map's bins are not equal-area, but none is empty or more than three
        // times another.
        let (min, max) = (counts.iter().min().unwrap(), counts.iter().max().unwrap());
        assert!(*min > 0 && *max < 3 * min, "{counts:?}");
        // Opposite directions never share a bin.
        for d in directions(500) {
            assert_ne!(lattice.direction_bin(d), lattice.direction_bin(-d), "{d}");
        }
    }

    #[test]
    fn keys_split_back_into_level_cell_and_bin() {
        let lattice = Lattice::new(unit_box(), 6, 4, 4);
        for (level, c, bin) in [(0, [3, 5, 63], 7), (2, [8, 0, 60], 15), (3, [0, 0, 0], 0)] {
            let key = lattice.key(level, c, bin);
            let (l, first, b) = Lattice::split_key(key);
            assert_eq!((l, b), (level, bin));
            assert_eq!(first, c.map(|v| v >> level << level));
            assert_eq!(Lattice::coarsen_key(key, level), key);
            assert_eq!(
                Lattice::coarsen_key(lattice.key(0, c, bin), level),
                key,
                "a finest cell's key coarsened is its level-{level} cell's"
            );
        }
    }
}
