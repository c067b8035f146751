//! Statistical test support: χ² goodness of fit over the sphere, used to check every sampler in
//! tress (BCSDFs, environment maps) against its claimed pdf.

use crate::math::Vec3;
use crate::rng::Sampler;
use std::f64::consts::PI;

/// P(χ²_dof ≥ stat).
pub fn chi2_survival(stat: f64, dof: f64) -> f64 {
    if stat <= 0.0 {
        return 1.0;
    }
    statrs::function::gamma::gamma_ur(0.5 * dof, 0.5 * stat)
}

/// Per-test significance level for `tests` independent tests at family level `alpha` (Šidák).
pub fn sidak_alpha(alpha: f64, tests: usize) -> f64 {
    1.0 - (1.0 - alpha).powf(1.0 / tests as f64)
}

/// Outcome of a χ² goodness-of-fit test.
#[derive(Clone, Debug)]
pub struct Chi2Outcome {
    /// The χ² statistic, low-expectation cells pooled into one.
    pub statistic: f64,
    /// Degrees of freedom: cells used minus one (at least 1).
    pub dof: usize,
    /// Probability of a statistic this large if the sampler is right; 0 when samples fell in
    /// empty cells.
    pub p_value: f64,
    /// Samples that fell in cells whose expected count is (numerically) zero.
    pub samples_in_empty_cells: u64,
}

/// χ² test of observed against expected cell counts. Cells with expected count below
/// `min_expected` are pooled into one, as in Mitsuba's `ChiSquareTest`.
pub fn chi2_test(observed: &[f64], expected: &[f64], min_expected: f64) -> Chi2Outcome {
    assert_eq!(observed.len(), expected.len());
    let mut idx: Vec<usize> = (0..observed.len()).collect();
    idx.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]));
    let (mut pool_obs, mut pool_exp) = (0.0, 0.0);
    let mut stat = 0.0;
    let mut cells = 0usize;
    let mut empty_hits = 0u64;
    for &i in &idx {
        let (o, e) = (observed[i], expected[i]);
        if e <= 1e-12 * min_expected {
            if o > 0.0 {
                empty_hits += o as u64;
            }
            continue;
        }
        if e < min_expected {
            pool_obs += o;
            pool_exp += e;
            continue;
        }
        stat += (o - e) * (o - e) / e;
        cells += 1;
    }
    if pool_exp > 0.0 {
        stat += (pool_obs - pool_exp) * (pool_obs - pool_exp) / pool_exp;
        cells += 1;
    }
    let dof = cells.saturating_sub(1).max(1);
    let p_value = if empty_hits > 0 {
        0.0
    } else {
        chi2_survival(stat, dof as f64)
    };
    Chi2Outcome {
        statistic: stat,
        dof,
        p_value,
        samples_in_empty_cells: empty_hits,
    }
}

/// A cell whose pdf varies by more than this factor among its sub-cells' midpoints is
/// integrated again on a finer grid ([`SphereChi2::run`]).
const REFINE_RATIO: f64 = 4.0;
/// The finest sub-cells per side a cell's expected count is integrated with.
const MAX_SUB_CELLS: usize = 256;

/// A χ² test of a direction sampler against its solid-angle pdf over the whole sphere.
///
/// Cells are equal-area: `res_cos` bins in the cosine to `pole` and `res_phi` bins in azimuth.
/// Each cell's expected count integrates the pdf over `sub`×`sub` midpoint sub-cells, equal
/// in angle from the pole and in azimuth; where the pdf varies by more than a factor 4 among
/// them, and beside the poles, over 4× as many per side, again and again until it settles.
pub struct SphereChi2 {
    /// Axis the cosine bins are measured from (default +z).
    pub pole: Vec3,
    /// Number of bins in the cosine to `pole` (default 50).
    pub res_cos: usize,
    /// Number of bins in azimuth (default 100).
    pub res_phi: usize,
    /// Midpoint sub-cells per side when integrating a cell's expected count (default 4): equal
    /// steps in the angle from the pole and in azimuth.
    pub sub: usize,
    /// Directions drawn (default 1 000 000).
    pub samples: usize,
    /// Cells expecting fewer samples than this are pooled (default 5).
    pub min_expected: f64,
}

impl Default for SphereChi2 {
    fn default() -> Self {
        SphereChi2 {
            pole: Vec3::Z,
            res_cos: 50,
            res_phi: 100,
            sub: 4,
            samples: 1_000_000,
            min_expected: 5.0,
        }
    }
}

impl SphereChi2 {
    fn basis(&self) -> crate::math::Frame {
        crate::math::Frame::from_z(self.pole.normalize())
    }

    fn cell_of(&self, frame: &crate::math::Frame, d: Vec3) -> usize {
        let l = frame.to_local(d);
        let c = l.z.clamp(-1.0, 1.0);
        let phi = l.y.atan2(l.x).rem_euclid(std::f32::consts::TAU);
        let ic = (((c + 1.0) * 0.5 * self.res_cos as f32) as usize).min(self.res_cos - 1);
        let ip =
            ((phi / std::f32::consts::TAU * self.res_phi as f32) as usize).min(self.res_phi - 1);
        ic * self.res_phi + ip
    }

    /// Runs the test. `sample` draws a direction (or `None`, a failed sample that counts as lost
    /// mass); `pdf` is the claimed density. Returns the outcome plus the histograms
    /// (observed, expected) for dumping on failure.
    pub fn run(
        &self,
        seed: u64,
        mut sample: impl FnMut(&mut Sampler) -> Option<Vec3>,
        pdf: impl Fn(Vec3) -> f64,
    ) -> (Chi2Outcome, Vec<f64>, Vec<f64>) {
        let frame = self.basis();
        let n_cells = self.res_cos * self.res_phi;
        let mut observed = vec![0.0f64; n_cells];
        let mut rng = Sampler::from_seed(seed);
        for _ in 0..self.samples {
            if let Some(d) = sample(&mut rng) {
                if d.is_finite() {
                    observed[self.cell_of(&frame, d.normalize())] += 1.0;
                }
            }
        }
        let mut expected = vec![0.0f64; n_cells];
        let dc = 2.0 / self.res_cos as f64;
        let dphi = 2.0 * PI / self.res_phi as f64;
        // The pdf over cell (ic, ip) by the midpoint rule on n × n sub-cells, with the least
        // and largest value met. Sub-cells are equal in angle from the pole, each weighted by
        // its exact area: equal steps in the cosine would span 20× more angle beside the poles
        // than at the equator (the first of 8 in a 50-row grid 5.7°), too coarse for a lobe
        // there.
        let integrate = |ic: usize, ip: usize, n: usize| {
            let theta_lo = (-1.0 + dc * (ic + 1) as f64).clamp(-1.0, 1.0).acos();
            let theta_hi = (-1.0 + dc * ic as f64).clamp(-1.0, 1.0).acos();
            let dtheta = (theta_hi - theta_lo) / n as f64;
            let (mut acc, mut lo, mut hi) = (0.0, f64::INFINITY, 0.0f64);
            for a in 0..n {
                let t0 = theta_lo + dtheta * a as f64;
                let area = (t0.cos() - (t0 + dtheta).cos()) * dphi / n as f64;
                let (s, c) = (t0 + 0.5 * dtheta).sin_cos();
                for b in 0..n {
                    let phi = dphi * (ip as f64 + (b as f64 + 0.5) / n as f64);
                    let local = Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32);
                    let v = pdf(frame.to_world(local));
                    (lo, hi) = (lo.min(v), hi.max(v));
                    acc += v * area;
                }
            }
            (acc, lo, hi)
        };
        for ic in 0..self.res_cos {
            for ip in 0..self.res_phi {
                let samples = self.samples as f64;
                let (acc, lo, hi) = integrate(ic, ip, self.sub);
                let mut count = acc * samples;
                // A cell across an edge of the pdf's support (GGX's microfacets end at the
                // horizon of their mean normal, where D is α²/π, not 0), a lobe sharper than
                // the sub-cells, or a cell touching a pole (its midpoints stay half a sub-cell
                // away from it, so a lobe peaking there goes unseen: a correct sampler failed)
                // is integrated 4× finer per side, again and again until two levels agree to a
                // twentieth of the count's Poisson deviation (what is left then adds at most
                // 1/400 to the cell's χ² term).
                let at_pole = ic == 0 || ic + 1 == self.res_cos;
                if hi > REFINE_RATIO * lo || at_pole {
                    let mut n = self.sub;
                    while n < MAX_SUB_CELLS {
                        n *= 4;
                        let finer = integrate(ic, ip, n).0 * samples;
                        let settled = (finer - count).abs() < 0.05 * finer.max(1.0).sqrt();
                        count = finer;
                        if settled {
                            break;
                        }
                    }
                }
                expected[ic * self.res_phi + ip] = count;
            }
        }
        (
            chi2_test(&observed, &expected, self.min_expected),
            observed,
            expected,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{sample_cosine_hemisphere, sample_uniform_sphere};

    #[test]
    fn chi2_survival_known_values() {
        // Reference values from mpmath.gammainc (regularised upper incomplete gamma).
        assert!((chi2_survival(3.841_458_820_694_124, 1.0) - 0.05).abs() < 1e-6);
        assert!((chi2_survival(18.307_038_053_275_146, 10.0) - 0.05).abs() < 1e-6);
        assert!((chi2_survival(100.0, 100.0) - 0.481_191_684_527_957).abs() < 1e-9);
        assert!((chi2_survival(1200.0, 1000.0) - 1.225_594_233_062_29e-5).abs() < 1e-10);
    }

    #[test]
    fn sphere_chi2_accepts_right_pdf_and_rejects_wrong_one() {
        let t = SphereChi2 {
            samples: 200_000,
            ..Default::default()
        };
        let (ok, _, _) = t.run(
            7,
            |s| Some(sample_uniform_sphere(s.next_2d())),
            |_| 1.0 / (4.0 * PI),
        );
        assert!(ok.p_value > 0.01, "{ok:?}");
        // Cosine-weighted samples claimed to be uniform must be rejected.
        let (bad, _, _) = t.run(
            7,
            |s| Some(sample_cosine_hemisphere(s.next_2d())),
            |_| 1.0 / (4.0 * PI),
        );
        assert!(bad.p_value < 1e-6, "{bad:?}");
        let (good_cos, _, _) = t.run(
            9,
            |s| Some(sample_cosine_hemisphere(s.next_2d())),
            |d| if d.z > 0.0 { d.z as f64 / PI } else { 0.0 },
        );
        assert!(good_cos.p_value > 0.01, "{good_cos:?}");
    }

    /// A sharp lobe beside the pole (cos²⁰⁰ about a direction 12° from it: 0.1 rad wide, less
    /// than the 5.7° the first of 8 equal-cosine sub-cells spans there) is accepted: the
    /// expected counts integrate it in equal angles.
    #[test]
    fn sphere_chi2_resolves_a_sharp_lobe_beside_the_pole() {
        let n = 200.0f32;
        let axis = Vec3::new(12f32.to_radians().sin(), 0.0, 12f32.to_radians().cos());
        let frame = crate::math::Frame::from_z(axis);
        let t = SphereChi2 {
            sub: 8,
            ..Default::default()
        };
        let (o, _, _) = t.run(
            3,
            |s| {
                let u = s.next_2d();
                let c = u.x.powf(1.0 / (n + 1.0));
                let r = (1.0 - c * c).max(0.0).sqrt();
                let (sp, cp) = (std::f32::consts::TAU * u.y).sin_cos();
                Some(frame.to_world(Vec3::new(r * cp, r * sp, c)))
            },
            |d| {
                let c = d.dot(axis).max(0.0) as f64;
                (n as f64 + 1.0) / (2.0 * PI) * c.powf(n as f64)
            },
        );
        assert!(o.p_value > 0.01, "{o:?}");
    }
}
