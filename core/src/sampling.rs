//! Warps from the unit square, MIS heuristics and piecewise-constant distributions.

use crate::math::{Vec2, Vec3};
use std::f32::consts::{FRAC_PI_4, PI};

/// 1/(4π): the pdf of a uniform direction on the sphere.
pub const INV_4PI: f32 = 1.0 / (4.0 * PI);

/// Uniform direction on the unit sphere; pdf 1/(4π).
#[inline]
pub fn sample_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.y).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// Uniform point on the unit disk (Shirley–Chiu concentric map).
#[inline]
pub fn sample_uniform_disk_concentric(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, FRAC_PI_4 * (o.y / o.x))
    } else {
        (o.y, std::f32::consts::FRAC_PI_2 - FRAC_PI_4 * (o.x / o.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// Cosine-weighted direction on the +z hemisphere; pdf cos θ / π.
#[inline]
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = sample_uniform_disk_concentric(u);
    Vec3::new(d.x, d.y, (1.0 - d.length_squared()).max(0.0).sqrt())
}

/// Uniform direction in the cone of half-angle acos(`cos_max`) around +z; pdf 1/(2π(1−cos_max)).
#[inline]
pub fn sample_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_t = 1.0 - u.x * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.y).sin_cos();
    Vec3::new(sin_t * c, sin_t * s, cos_t)
}

/// Solid-angle pdf of [`sample_uniform_cone`]: 1/(2π(1−cos_max)).
#[inline]
pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// Power heuristic (β = 2) weight of strategy `f` against `g`, one sample each.
#[inline]
pub fn power_heuristic(pdf_f: f32, pdf_g: f32) -> f32 {
    let f2 = pdf_f * pdf_f;
    let g2 = pdf_g * pdf_g;
    if f2.is_infinite() {
        return 1.0;
    }
    if f2 + g2 == 0.0 {
        0.0
    } else {
        f2 / (f2 + g2)
    }
}

/// A piecewise-constant density on [0, 1) with `n` equal cells, sampled in O(1) with Vose's
/// alias method: one table entry per draw instead of a binary search through the CDF, whose
/// cache misses made environment sampling a visible share of a render's profile. The draw is
/// not monotone in `u` (no stratification is lost: tress draws independent numbers).
#[derive(Clone, Debug)]
pub struct Distribution1D {
    func: Vec<f32>,
    /// Per cell: the probability of keeping the cell, and the cell taken otherwise.
    alias: Vec<(f32, u32)>,
    integral: f32,
}

impl Distribution1D {
    /// From non-negative cell values. An all-zero function becomes uniform so sampling never fails.
    pub fn new(func: &[f32]) -> Self {
        let mut func: Vec<f32> = func
            .iter()
            .map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 })
            .collect();
        if func.is_empty() {
            func.push(1.0);
        }
        let n = func.len();
        let sum: f64 = func.iter().map(|&v| v as f64).sum();
        let integral = sum / n as f64;
        if sum == 0.0 {
            func.iter_mut().for_each(|v| *v = 1.0);
        }
        let alias = alias_table(&func);
        Distribution1D {
            func,
            alias,
            integral: integral as f32,
        }
    }

    /// Number of cells (at least 1: an empty input becomes one cell).
    pub fn len(&self) -> usize {
        self.func.len()
    }

    /// Whether there are no cells; never true, since an empty input becomes one cell.
    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// ∫ func over [0, 1) (0 if the input was all zero).
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// Returns (x ∈ [0,1), density at x, cell index). `u` picks a table entry; what is left of
    /// it decides between the entry's cell and its alias, and what is left then places x
    /// uniformly in the chosen cell (about 24 − log₂ n bits of resolution).
    pub fn sample_continuous(&self, u: f32) -> (f32, f32, usize) {
        let n = self.func.len();
        let (i, du) = self.sample_cell(u);
        // Keep x inside cell i where rounding of i + du would reach the next cell.
        let x = ((i as f32 + du.clamp(0.0, 1.0)) / n as f32)
            .clamp(i as f32 / n as f32, 1.0 - f32::EPSILON);
        let x = if (x * n as f32) as usize > i {
            f32::from_bits(x.to_bits() - 1)
        } else {
            x
        };
        (x, self.pdf_cell(i), i)
    }

    /// A cell drawn ∝ its value, and what is left of `u` as a uniform number in [0, 1] (about
    /// 24 − log₂ n bits, fewer where the entry's choice is lopsided), from one table entry.
    pub fn sample_cell(&self, u: f32) -> (usize, f32) {
        let n = self.func.len();
        let scaled = u.clamp(0.0, 1.0) * n as f32;
        let entry = (scaled as usize).min(n - 1);
        let rest = (scaled - entry as f32).clamp(0.0, 1.0);
        self.choose(entry, rest)
    }

    /// Entry `entry` of the alias table: the probability of keeping cell `entry`, and the cell
    /// taken otherwise (see [`alias_choose`]). Tables too large for the cache copy these into
    /// records of their own, beside what a draw reads next.
    pub fn alias_entry(&self, entry: usize) -> (f32, u32) {
        self.alias[entry]
    }

    /// Entry `entry`'s cell or its alias, by `u` ∈ [0, 1]; and `u` rescaled to [0, 1].
    fn choose(&self, entry: usize, u: f32) -> (usize, f32) {
        let (keep, other) = self.alias[entry];
        alias_choose(keep, other, entry, u)
    }

    /// Density (w.r.t. x ∈ [0,1)) of cell `i`.
    pub fn pdf_cell(&self, i: usize) -> f32 {
        if self.integral > 0.0 {
            self.func[i] / self.integral
        } else {
            1.0
        }
    }

    /// Density at x ∈ [0, 1).
    pub fn pdf(&self, x: f32) -> f32 {
        let i = ((x * self.func.len() as f32) as usize).min(self.func.len() - 1);
        self.pdf_cell(i)
    }
}

/// The choice of an alias table's entry `entry` = (`keep`, `other`) by `u` ∈ [0, 1]: the
/// entry's own cell or `other`, and `u` rescaled to [0, 1].
#[inline]
pub fn alias_choose(keep: f32, other: u32, entry: usize, u: f32) -> (usize, f32) {
    let (i, du) = if u < keep {
        (entry, u / keep)
    } else {
        (other as usize, (u - keep) / (1.0 - keep))
    };
    (i, du.clamp(0.0, 1.0))
}

/// Vose's alias table of non-negative weights with a positive sum: entry i keeps cell i with
/// probability `keep`, else gives the alias. Cells of weight 0 are never produced (their
/// `keep` is 0 and no alias points at them).
fn alias_table(weights: &[f32]) -> Vec<(f32, u32)> {
    let n = weights.len();
    let sum: f64 = weights.iter().map(|&w| w as f64).sum();
    let mut scaled: Vec<f64> = weights.iter().map(|&w| w as f64 * n as f64 / sum).collect();
    let mut table = vec![(1.0f32, 0u32); n];
    for (i, t) in table.iter_mut().enumerate() {
        t.1 = i as u32;
    }
    let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| scaled[i] < 1.0);
    while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
        small.pop();
        table[s] = (scaled[s] as f32, l as u32);
        scaled[l] -= 1.0 - scaled[s];
        if scaled[l] < 1.0 {
            large.pop();
            small.push(l);
        }
    }
    // Whatever remains is 1 up to rounding: such entries keep their own cell, unless the
    // cell has no weight at all (rounding left a zero-weight cell without a partner).
    for &i in small.iter().chain(&large) {
        table[i].0 = if weights[i] > 0.0 { 1.0 } else { 0.0 };
        if weights[i] == 0.0 {
            table[i].1 = weights.iter().position(|&w| w > 0.0).unwrap_or(i) as u32;
        }
    }
    table
}

/// Asks the processor to bring the cache line holding `value` into its caches, so that a read
/// issued later finds it there: integrators that shade many paths together issue the reads of
/// the next ones' tables early, while the current ones compute. Changes no result.
#[inline]
pub fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint that never faults, of an address that is a valid reference;
    // SSE, which it needs, is part of x86-64's baseline.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
            (value as *const T).cast(),
        );
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Sampler;

    #[test]
    fn distribution1d_samples_proportionally() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0]);
        let mut s = Sampler::from_seed(1);
        let mut counts = [0u32; 3];
        let n = 100_000;
        for _ in 0..n {
            let (x, pdf, i) = d.sample_continuous(s.next_1d());
            assert!((d.pdf(x) - pdf).abs() < 1e-6);
            counts[i] += 1;
        }
        assert_eq!(counts[1], 0);
        assert!((counts[2] as f64 / n as f64 - 0.75).abs() < 0.01);
    }

    /// Cell frequencies match func / Σ func (χ² over 64 cells of a ragged function with zero
    /// cells and a dominant one) and positions are uniform within cells (χ² over 8 sub-bins).
    #[test]
    fn alias_sampling_matches_the_density() {
        let func: Vec<f32> = (0..64)
            .map(|i| match i {
                7 | 20 | 21 => 0.0,
                40 => 50.0,
                _ => ((i * 37) % 11) as f32 + 0.25,
            })
            .collect();
        let d = Distribution1D::new(&func);
        let total: f64 = func.iter().map(|&f| f as f64).sum();
        let mut s = Sampler::from_seed(7);
        let n = 400_000;
        let mut cells = vec![0u32; 64];
        let mut sub = [0u32; 8];
        for _ in 0..n {
            let (x, pdf, i) = d.sample_continuous(s.next_1d());
            assert_eq!(pdf, d.pdf(x));
            assert_eq!(i, (x * 64.0) as usize);
            cells[i] += 1;
            sub[((x * 64.0).fract() * 8.0) as usize] += 1;
        }
        let mut chi2 = 0.0;
        let mut dof = 0;
        for (c, &f) in cells.iter().zip(&func) {
            let expected = n as f64 * f as f64 / total;
            if f == 0.0 {
                assert_eq!(*c, 0, "a zero cell was sampled");
                continue;
            }
            chi2 += (*c as f64 - expected).powi(2) / expected;
            dof += 1;
        }
        // 60 cells → 59 dof: the 0.1 % critical value is about 98.
        assert!(chi2 < 98.0, "cell χ² {chi2} over {} dof", dof - 1);
        let expected = n as f64 / 8.0;
        let chi2: f64 = sub
            .iter()
            .map(|&c| (c as f64 - expected).powi(2) / expected)
            .sum();
        assert!(chi2 < 24.3, "within-cell χ² {chi2} over 7 dof");
    }

    #[test]
    fn alias_table_of_uniform_and_single_spike() {
        let d = Distribution1D::new(&[0.0, 0.0, 2.0, 0.0]);
        for k in 0..1000 {
            let (_, _, i) = d.sample_continuous(k as f32 / 1000.0);
            assert_eq!(i, 2);
        }
        let d = Distribution1D::new(&[0.0; 5]);
        assert_eq!(d.integral(), 0.0);
        let (x, pdf, _) = d.sample_continuous(0.999_999_9);
        assert!(x < 1.0 && pdf == 1.0);
    }

    #[test]
    fn power_heuristic_limits() {
        assert_eq!(power_heuristic(1.0, 0.0), 1.0);
        assert_eq!(power_heuristic(0.0, 0.0), 0.0);
        assert_eq!(power_heuristic(f32::INFINITY, 1.0), 1.0);
        assert!((power_heuristic(1.0, 1.0) - 0.5).abs() < 1e-7);
    }
}
