//! The two one-dimensional samplers behind Marschner's importance sampling, each with a density
//! that is evaluated exactly: a windowed normal (for θ_h) and a periodic piecewise-linear
//! density over the azimuth φ ∈ [−π, π) (for N_p).

use std::f64::consts::{FRAC_1_SQRT_2, PI, TAU};
use tress_core::math::erfc;

#[inline]
fn norm_cdf(z: f64) -> f64 {
    0.5 * erfc(-z * FRAC_1_SQRT_2)
}

#[inline]
fn norm_pdf(z: f64) -> f64 {
    (-0.5 * z * z).exp() / TAU.sqrt()
}

/// The z with `norm_cdf(z) = p`: Abramowitz & Stegun 26.2.23 (|error| < 4.5e-4) polished by
/// Newton steps on `norm_cdf` itself, so that sampling inverts exactly the CDF the pdf is
/// normalised with.
fn norm_inv_cdf(p: f64) -> f64 {
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let tail = p.min(1.0 - p);
    let t = (-2.0 * tail.ln()).sqrt();
    let mag = t
        - (2.515_517 + t * (0.802_853 + t * 0.010_328))
            / (1.0 + t * (1.432_788 + t * (0.189_269 + t * 0.001_308)));
    let mut z = if p < 0.5 { -mag } else { mag };
    // Newton converges like |z|·e²/2: two steps suffice unless deep in the tail.
    for _ in 0..if mag > 6.0 { 3 } else { 2 } {
        z -= (norm_cdf(z) - p) / norm_pdf(z);
    }
    z
}

/// Φ(b) − Φ(a) for a ≤ b, taken in whichever tail keeps relative precision.
fn cdf_diff(a: f64, b: f64) -> f64 {
    if a + b > 0.0 {
        norm_cdf(-a) - norm_cdf(-b)
    } else {
        norm_cdf(b) - norm_cdf(a)
    }
}

/// ∫_a^b φ(z)(z − a) dz: the mass of a standard normal under a ramp rising from 0 at `a`.
fn ramp_mass(a: f64, b: f64) -> f64 {
    (norm_pdf(a) - norm_pdf(b) - a * cdf_diff(a, b)).max(0.0)
}

/// The z ∈ [a, b] with `ramp_mass(a, z) = target` (Newton safeguarded by bisection: the
/// derivative φ(z)(z − a) vanishes at `a`).
fn solve_ramp(a: f64, b: f64, target: f64) -> f64 {
    let (mut lo, mut hi) = (a, b);
    let mut z = 0.5 * (a + b);
    for _ in 0..100 {
        let g = ramp_mass(a, z) - target;
        if g > 0.0 {
            hi = z;
        } else {
            lo = z;
        }
        let d = norm_pdf(z) * (z - a);
        let newton = z - g / d;
        let next = if d > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - z).abs() <= 1e-12 * (1.0 + z.abs()) || hi - lo <= 1e-12 * (1.0 + z.abs()) {
            return next;
        }
        z = next;
    }
    z
}

/// The normal N(mean, sd²) on [lo, hi], multiplied by a window that is 1 inside and falls
/// linearly to 0 over a width `ramp` at both ends. Normalisation and inverse CDF are closed
/// form (∫ φ and ∫ zφ), so the density is exact.
///
/// For θ_h with θ_i = 2θ_h − θ_o, the window falls off like ψ = π/2 − |θ_i| toward the fiber axis,
/// which keeps the solid-angle density (∝ window / cos θ_i) finite at the poles.
#[derive(Clone, Copy, Debug)]
pub(super) struct WindowedNormal {
    pub mean: f64,
    pub sd: f64,
    pub lo: f64,
    pub hi: f64,
    /// Must satisfy 2·ramp < hi − lo.
    pub ramp: f64,
}

/// Φ(z), Φ(−z) and φ(z) at one point, from one erfc evaluation.
#[derive(Clone, Copy)]
struct Point {
    z: f64,
    cdf: f64,
    ccdf: f64,
    pdf: f64,
}

impl Point {
    fn new(z: f64) -> Self {
        let tail = 0.5 * erfc(z.abs() * FRAC_1_SQRT_2);
        let (cdf, ccdf) = if z <= 0.0 {
            (tail, 1.0 - tail)
        } else {
            (1.0 - tail, tail)
        };
        Point {
            z,
            cdf,
            ccdf,
            pdf: norm_pdf(z),
        }
    }

    /// Φ(b.z) − Φ(self.z), in the tail that keeps relative precision (as [`cdf_diff`]).
    fn mass_to(&self, b: &Point) -> f64 {
        if self.z + b.z > 0.0 {
            self.ccdf - b.ccdf
        } else {
            b.cdf - self.cdf
        }
    }
}

impl WindowedNormal {
    /// Standardised break points zl < za < zb < zh and the three piece masses (in z units):
    /// ∫φ·(z − zl)/ρ, ∫φ, ∫φ·(zh − z)/ρ with ρ the ramp width in z.
    fn pieces(&self) -> ([Point; 4], [f64; 3]) {
        let at = |x: f64| Point::new((x - self.mean) / self.sd);
        let p = [
            at(self.lo),
            at(self.lo + self.ramp),
            at(self.hi - self.ramp),
            at(self.hi),
        ];
        let rho = self.ramp / self.sd;
        let masses = [
            (p[0].pdf - p[1].pdf - p[0].z * p[0].mass_to(&p[1])).max(0.0) / rho,
            p[1].mass_to(&p[2]),
            (p[3].pdf - p[2].pdf + p[3].z * p[2].mass_to(&p[3])).max(0.0) / rho,
        ];
        (p, masses)
    }

    /// The window at x: 1 inside, linear to 0 at lo and hi.
    #[cfg(test)]
    pub fn window(&self, x: f64) -> f64 {
        ((x - self.lo).min(self.hi - x) / self.ramp).clamp(0.0, 1.0)
    }

    /// The density at x without the window factor: φ(z) / (sd · Z). The full density is this
    /// times [`Self::window`]; 0 when the interval carries no representable mass.
    pub fn gauss_density(&self, x: f64) -> f64 {
        let (_, m) = self.pieces();
        let total = m[0] + m[1] + m[2];
        if total > 0.0 {
            norm_pdf((x - self.mean) / self.sd) / (self.sd * total)
        } else {
            0.0
        }
    }

    /// Inverse-CDF sample from `u` ∈ [0, 1).
    pub fn sample(&self, u: f64) -> Option<f64> {
        let ([pl, pa, pb, ph], m) = self.pieces();
        let total = m[0] + m[1] + m[2];
        if total.is_nan() || total <= 0.0 {
            return None;
        }
        let rho = self.ramp / self.sd;
        let t = u * total;
        let z = if t < m[0] {
            solve_ramp(pl.z, pa.z, t * rho)
        } else if t < m[0] + m[1] {
            let t = t - m[0];
            if pa.z + pb.z > 0.0 {
                // Mass of [z, zb] is m1 − t; invert in the mirrored (lower) tail.
                -norm_inv_cdf(pb.ccdf + (m[1] - t)).clamp(-pb.z, -pa.z)
            } else {
                norm_inv_cdf(pa.cdf + t).clamp(pa.z, pb.z)
            }
        } else {
            // Mass above z is total − t: the lower ramp of the mirrored normal.
            -solve_ramp(-ph.z, -pb.z, ((total - t) * rho).max(0.0))
        };
        Some((self.mean + self.sd * z).clamp(self.lo, self.hi))
    }
}

/// A periodic piecewise-linear density on φ ∈ [−π, π): node `k` sits at φ_k = −π + kΔ,
/// Δ = 2π/n, and the density interpolates linearly between neighbouring nodes (node n ≡ node 0).
/// Continuous in φ, so a χ² histogram's sub-cell quadrature of it is accurate.
#[derive(Clone, Debug)]
pub(super) struct AzimuthPdf {
    nodes: Vec<f64>,
    /// Cumulative cell masses (unnormalised), n + 1 entries.
    cdf: Vec<f64>,
}

impl AzimuthPdf {
    /// From non-negative node values; an all-zero (or non-finite) row becomes uniform.
    pub fn new(mut nodes: Vec<f64>) -> Self {
        let ok = nodes.iter().all(|v| v.is_finite() && *v >= 0.0);
        if !ok || nodes.iter().sum::<f64>() <= 0.0 {
            nodes.iter_mut().for_each(|v| *v = 1.0);
        }
        let n = nodes.len();
        let delta = TAU / n as f64;
        let mut cdf = Vec::with_capacity(n + 1);
        cdf.push(0.0);
        for k in 0..n {
            let m = 0.5 * delta * (nodes[k] + nodes[(k + 1) % n]);
            cdf.push(cdf[k] + m);
        }
        AzimuthPdf { nodes, cdf }
    }

    fn delta(&self) -> f64 {
        TAU / self.nodes.len() as f64
    }

    /// The normalising integral ∫_{−π}^{π} of the interpolant.
    pub fn total(&self) -> f64 {
        self.cdf[self.nodes.len()]
    }

    /// φ ∈ [−π, π) from `u` ∈ [0, 1).
    pub fn sample(&self, u: f64) -> f64 {
        let n = self.nodes.len();
        let target = u * self.total();
        let k = self.cdf.partition_point(|&c| c <= target).clamp(1, n) - 1;
        let width = self.cdf[k + 1] - self.cdf[k];
        let r = if width > 0.0 {
            ((target - self.cdf[k]) / width).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let (v0, v1) = (self.nodes[k], self.nodes[(k + 1) % n]);
        // Solve ∫_0^t (v0 + (v1 − v0)s) ds = r (v0 + v1)/2 for t, in the cancellation-free form.
        let denom = v0 + (v0 * v0 + r * (v1 * v1 - v0 * v0)).max(0.0).sqrt();
        let t = if denom > 0.0 {
            (r * (v0 + v1) / denom).clamp(0.0, 1.0)
        } else {
            r
        };
        (-PI + (k as f64 + t) * self.delta()).min(PI)
    }

    /// The density at φ (any real; wrapped into [−π, π)).
    pub fn pdf(&self, phi: f64) -> f64 {
        let n = self.nodes.len();
        let x = (phi + PI).rem_euclid(TAU) / self.delta();
        let k = (x as usize).min(n - 1);
        let t = (x - k as f64).clamp(0.0, 1.0);
        let (v0, v1) = (self.nodes[k], self.nodes[(k + 1) % n]);
        (v0 + (v1 - v0) * t) / self.total()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tress_core::stats::chi2_test;
    use tress_core::Sampler;

    #[test]
    fn normal_cdf_and_inverse_agree() {
        // Φ(−1.96) = 0.0249979, Φ(−5) = 2.8665e-7 (tables), Φ(−20) = 2.7536e-89.
        assert!((norm_cdf(-1.959_963_984_540_054) - 0.025).abs() < 1e-8);
        assert!((norm_cdf(-5.0) / 2.866_515_718_791_939e-7 - 1.0).abs() < 1e-6);
        assert!((norm_cdf(-20.0) / 2.753_624_118_606_233e-89 - 1.0).abs() < 1e-6);
        for p in [
            1e-280,
            1e-30,
            1e-5,
            0.01,
            0.3,
            0.5,
            0.77,
            0.999,
            1.0 - 1e-12,
        ] {
            let z = norm_inv_cdf(p);
            assert!((norm_cdf(z) / p - 1.0).abs() < 1e-10, "p={p}: z={z}");
        }
    }

    fn chi2_of(sample: impl Fn(f64) -> f64, pdf: impl Fn(f64) -> f64, lo: f64, hi: f64) -> f64 {
        let bins = 200;
        let n = 200_000;
        let mut rng = Sampler::from_seed(99);
        let mut obs = vec![0.0; bins];
        for _ in 0..n {
            let x = sample(rng.next_1d() as f64);
            assert!((lo..=hi).contains(&x), "sample {x} outside [{lo}, {hi}]");
            obs[(((x - lo) / (hi - lo) * bins as f64) as usize).min(bins - 1)] += 1.0;
        }
        let w = (hi - lo) / bins as f64;
        let exp: Vec<f64> = (0..bins)
            .map(|b| {
                // 64-point midpoint rule per bin.
                (0..64)
                    .map(|s| pdf(lo + w * (b as f64 + (s as f64 + 0.5) / 64.0)))
                    .sum::<f64>()
                    * w
                    / 64.0
                    * n as f64
            })
            .collect();
        let total: f64 = exp.iter().sum::<f64>() / n as f64;
        assert!(
            (total - 1.0).abs() < 1e-3,
            "[{lo}, {hi}]: pdf integrates to {total}"
        );
        chi2_test(&obs, &exp, 5.0).p_value
    }

    #[test]
    fn windowed_normal_sampler_matches_its_density() {
        // Centred, one-sided, mirrored, narrow and deep-tail configurations; θ_h intervals of
        // width π/2 with 15° ramps as used by the model.
        let r = 15f64.to_radians();
        let w = std::f64::consts::FRAC_PI_2;
        for (mean, sd, lo) in [
            (0.0, 0.3, -0.7),
            (-0.13, 0.13, -0.13),
            (0.2, 0.05, -w),
            (-0.1, 0.3, 0.1),
            (0.5, 0.02, -0.4),
            (0.5, 0.02, 0.45),
            (-0.3, 0.05, -0.1),
            (0.0, 0.009, -0.8),
        ] {
            let d = WindowedNormal {
                mean,
                sd,
                lo,
                hi: lo + w,
                ramp: r,
            };
            let p = chi2_of(
                |u| d.sample(u).unwrap(),
                |x| d.gauss_density(x) * d.window(x),
                lo,
                lo + w,
            );
            assert!(p > 1e-3, "{d:?}: χ² p = {p}");
        }
    }

    #[test]
    fn ramp_mass_matches_quadrature() {
        for (a, b) in [
            (-1.0, 0.5),
            (-12.0, -10.0),
            (3.0, 9.0),
            (-0.2, 0.1),
            (20.0, 25.0),
        ] {
            let n = 100_000;
            let h = (b - a) / n as f64;
            let q: f64 = (0..n)
                .map(|k| {
                    let z = a + h * (k as f64 + 0.5);
                    norm_pdf(z) * (z - a) * h
                })
                .sum();
            assert!(
                (ramp_mass(a, b) / q - 1.0).abs() < 1e-4,
                "[{a}, {b}]: {} vs {q}",
                ramp_mass(a, b)
            );
        }
    }

    #[test]
    fn azimuth_pdf_sampler_matches_its_pdf() {
        let mut rng = Sampler::from_seed(5);
        // Spiky values with exact zeros, as in the TT/TRT tables.
        let nodes: Vec<f64> = (0..37)
            .map(|k| {
                if k % 7 == 3 {
                    0.0
                } else {
                    (rng.next_1d() as f64).powi(3) * 10.0
                }
            })
            .collect();
        let d = AzimuthPdf::new(nodes);
        let p = chi2_of(|u| d.sample(u), |x| d.pdf(x), -PI, PI);
        assert!(p > 1e-3, "χ² p = {p}");
        // A wrong density must be rejected (the test can fail).
        let uniform = chi2_of(|u| d.sample(u), |_| 1.0 / TAU, -PI, PI);
        assert!(uniform < 1e-6);
    }
}
