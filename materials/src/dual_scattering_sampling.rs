//! Importance sampling of the dual-scattering shading function F (for the `dual-mis`
//! integrator), with a pdf that is exactly the density of the sampler.
//!
//! F is a sum of terms with known shapes (docs/src/reference/hair-maths.md#sampling-f), so
//! directions are drawn from a mixture whose weights follow the terms' attenuations at the
//! specular cone of `wo`:
//! - the BCSDF's own importance sampling (the direct single-scattering term f_s; for the
//!   registered models this is d'Eon et al. 2013-style lobe / longitudinal / azimuthal
//!   sampling with an exact pdf);
//! - the back-scattering lobe: longitudinal offset around Δ_b with spread σ_b, azimuth uniform
//!   over the backward half-circle (the light's side, local z > 0), where f_back lives;
//! - the forward-scattered term at three spreads β̄_f²·(1 + n) for n ∈ {2, 8, 32} fibers
//!   crossed (σ̄_f² = n β̄_f² grows with depth, which is unknown until a direction is chosen),
//!   any azimuth;
//! - a defensive uniform-sphere component, so every direction has density.
//!
//! The longitudinal components are logistic distributions in s = sin θ_i, truncated to
//! [−1, 1]: their CDF inverts in closed form and, since dω = ds dφ, their solid-angle density
//! `p(s)/2π` has no 1/cos θ singularity at the poles. A component centred where F's
//! Gaussian in θ_h peaks (θ_i = 2θ_h − θ_o) with the matching width in s is a close proposal.

use crate::dual_scattering::{DualScatteringShading, MultipleScattering};
use std::f32::consts::{FRAC_PI_2, PI, TAU};
use tress_core::luminance;
use tress_core::math::{fiber_direction, safe_asin, safe_sqrt, Vec3};

/// Probability of the defensive uniform component.
const UNIFORM_WEIGHT: f32 = 0.1;
/// Fibers-crossed values whose forward spreads the mixture covers.
const FORWARD_DEPTHS: [f32; 3] = [2.0, 8.0, 32.0];
/// Fibers crossed at which the mixture weighs the multiple-scattering terms.
const PROPOSAL_DEPTH: f32 = 2.0;
/// Smallest logistic scale in s, so narrow lobes stay finite.
const MIN_SCALE: f32 = 0.01;

/// A logistic distribution in s = sin θ_i truncated to [−1, 1].
#[derive(Clone, Copy, Debug)]
struct TruncatedLogistic {
    mu: f32,
    scale: f32,
    cdf_lo: f32,
    cdf_hi: f32,
}

impl TruncatedLogistic {
    /// Centred on inclination `theta_i` (rad), with standard deviation `sd_theta` (rad) in θ.
    fn new(theta_i: f32, sd_theta: f32) -> Self {
        let theta_i = theta_i.clamp(-std::f32::consts::FRAC_PI_2, std::f32::consts::FRAC_PI_2);
        let mu = theta_i.sin();
        // ds = cos θ dθ; a logistic of scale k has standard deviation kπ/√3.
        let sd_s = (sd_theta * theta_i.cos()).max(sd_theta * sd_theta * 0.5);
        let scale = (sd_s * 3f32.sqrt() / PI).max(MIN_SCALE);
        let cdf = |x: f32| 1.0 / (1.0 + (-(x - mu) / scale).exp());
        TruncatedLogistic {
            mu,
            scale,
            cdf_lo: cdf(-1.0),
            cdf_hi: cdf(1.0),
        }
    }

    fn sample(&self, u: f32) -> f32 {
        let p = (self.cdf_lo + u * (self.cdf_hi - self.cdf_lo)).clamp(1e-7, 1.0 - 1e-7);
        (self.mu + self.scale * (p / (1.0 - p)).ln()).clamp(-1.0, 1.0)
    }

    fn pdf(&self, s: f32) -> f32 {
        if !(-1.0..=1.0).contains(&s) {
            return 0.0;
        }
        let z = (-(s - self.mu).abs() / self.scale).exp();
        z / (self.scale * (1.0 + z) * (1.0 + z)) / (self.cdf_hi - self.cdf_lo).max(1e-12)
    }
}

/// The mixture for one `wo`: component probabilities and the longitudinal proposals.
struct Mixture {
    /// [BCSDF, back, forward × 3, uniform]
    weights: [f32; 6],
    back: TruncatedLogistic,
    forward: [TruncatedLogistic; 3],
}

impl DualScatteringShading {
    fn mixture(&self, wo: Vec3) -> Mixture {
        let theta_o = safe_asin(wo.x);
        // The tables are indexed by the light's inclination; light on the specular cone of wo.
        let g = self.tables().globals(-theta_o);
        let d = self.factors();
        let e_direct = luminance(g.a_f + g.a_b).max(1e-4);
        // F's back-scattering lobe, as F reads it for light on the specular cone.
        let b = self.tables().back_scattering(
            self.shape_theta(-theta_o, theta_o),
            d.d_b,
            f32::INFINITY,
        );
        let (e_back, back_mean, back_var) =
            (d.d_b * luminance(b.energy).max(0.0), b.mean, b.variance);
        let e_forward = match self.tables().multiple_scattering() {
            MultipleScattering::Paper => d.d_f * d.d_f * luminance(g.a_f_eff).max(0.0),
            // The scattered light a few fibers deep, from the light on the specular cone.
            MultipleScattering::FiberMedium => {
                let light = fiber_direction((-theta_o).sin(), theta_o.cos(), -FRAC_PI_2);
                luminance(g.a_f_eff * self.forward(light, PROPOSAL_DEPTH).t_f).max(0.0)
            }
        };
        let total = e_direct + e_back + e_forward;
        let scale = (1.0 - UNIFORM_WEIGHT) / total;
        let f = e_forward * scale / FORWARD_DEPTHS.len() as f32;
        let weights = [e_direct * scale, e_back * scale, f, f, f, UNIFORM_WEIGHT];
        let lum = |v: tress_core::Rgb| luminance(v).max(0.0);
        // θ_h ~ N(μ, v) ⇒ θ_i = 2θ_h − θ_o has mean 2μ − θ_o and standard deviation 2√v.
        let back =
            TruncatedLogistic::new(2.0 * lum(back_mean) - theta_o, 2.0 * lum(back_var).sqrt());
        let forward = FORWARD_DEPTHS.map(|n| {
            let v = lum(g.beta2_f) * (1.0 + n);
            TruncatedLogistic::new(2.0 * lum(g.alpha_f) - theta_o, 2.0 * v.sqrt())
        });
        Mixture {
            weights,
            back,
            forward,
        }
    }

    /// The direction sampler for shading from `wo`: build it once per shading point when
    /// drawing several directions or evaluating several pdfs there.
    pub fn direction_sampler(&self, wo: Vec3) -> DirectionSampler<'_> {
        DirectionSampler {
            shading: self,
            wo,
            mixture: self.mixture(wo),
        }
    }

    /// Draws a light direction ω_d (local frame) for shading from `wo` at offset `h`, with its
    /// solid-angle pdf ([`DualScatteringShading::direction_pdf`]).
    pub fn sample_direction(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<(Vec3, f32)> {
        self.direction_sampler(wo).sample(h, u)
    }

    /// Solid-angle density of [`DualScatteringShading::sample_direction`].
    pub fn direction_pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> f32 {
        self.direction_sampler(wo).pdf(wi, h)
    }
}

/// Samples light directions for one `wo` ([`DualScatteringShading::direction_sampler`]).
pub struct DirectionSampler<'a> {
    shading: &'a DualScatteringShading,
    wo: Vec3,
    mixture: Mixture,
}

impl DirectionSampler<'_> {
    /// A light direction ω_d (local frame) at offset `h`, with its solid-angle pdf.
    pub fn sample(&self, h: f32, u: [f32; 4]) -> Option<(Vec3, f32)> {
        let (m, wo) = (&self.mixture, self.wo);
        // Pick the component with u[0], then reuse its position within the component's bin.
        let mut acc = 0.0;
        let mut chosen = m.weights.len() - 1;
        for (i, w) in m.weights.iter().enumerate() {
            if u[0] < acc + w {
                chosen = i;
                break;
            }
            acc += w;
        }
        let wi = match chosen {
            0 => {
                self.shading
                    .bcsdf()
                    .sample(
                        wo,
                        h,
                        [
                            u[1],
                            u[2],
                            u[3],
                            ((u[0] - acc) / m.weights[0]).clamp(0.0, 0.999_999),
                        ],
                    )?
                    .wi
            }
            _ => {
                let (s, phi) = match chosen {
                    1 => (m.back.sample(u[1]), PI * u[2]),
                    2..=4 => (m.forward[chosen - 2].sample(u[1]), TAU * u[2]),
                    _ => (2.0 * u[1] - 1.0, TAU * u[2]),
                };
                fiber_direction(s, safe_sqrt(1.0 - s * s), phi)
            }
        };
        let pdf = self.pdf(wi, h);
        (pdf > 0.0 && pdf.is_finite()).then_some((wi, pdf))
    }

    /// Solid-angle density of [`Self::sample`] at `wi`.
    pub fn pdf(&self, wi: Vec3, h: f32) -> f32 {
        let m = &self.mixture;
        let s = wi.x.clamp(-1.0, 1.0);
        let inv_2pi = 1.0 / TAU;
        let mut pdf = m.weights[0] * self.shading.bcsdf().pdf(self.wo, wi, h);
        if wi.z > 0.0 {
            pdf += m.weights[1] * m.back.pdf(s) / PI;
        }
        for (k, c) in m.forward.iter().enumerate() {
            pdf += m.weights[2 + k] * c.pdf(s) * inv_2pi;
        }
        pdf + m.weights[5] / (4.0 * PI)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dual_scattering::{DensityFactors, DualScatteringSettings};
    use crate::HairModel;
    use std::sync::Arc;
    use tress_core::stats::{sidak_alpha, SphereChi2};

    fn shading(name: &str) -> DualScatteringShading {
        let inst = HairModel::test_instances()
            .into_iter()
            .find(|t| t.name == name)
            .unwrap();
        let b = inst.params.build(crate::test_util::shared_prep()).unwrap();
        let settings = DualScatteringSettings {
            theta_nodes: 32,
            ..Default::default()
        };
        let t = crate::test_util::shared_tables(b.as_ref(), &settings);
        DualScatteringShading::new(Arc::clone(&b), t, DensityFactors::default()).unwrap()
    }

    const CASES: [(&str, f32, f32); 4] = [
        ("Chiang/brown", 0.3, 0.4),
        ("Chiang/blond", -1.1, -0.7),
        ("DEon/blond", 0.9, 0.2),
        ("Marschner/brown", -0.2, 0.0),
    ];

    /// χ² of `sample_direction` against `direction_pdf` over the sphere (pole on the tangent).
    #[test]
    fn sampler_matches_pdf() {
        let alpha = sidak_alpha(0.01, CASES.len());
        for (name, theta_o, h) in CASES {
            let ds = shading(name);
            let wo = fiber_direction(theta_o.sin(), theta_o.cos(), std::f32::consts::FRAC_PI_2);
            let test = SphereChi2 {
                pole: Vec3::X,
                sub: 8,
                samples: 400_000,
                ..Default::default()
            };
            let (out, _, _) = test.run(
                7,
                |s| ds.sample_direction(wo, h, s.next_4d()).map(|(wi, _)| wi),
                |wi| ds.direction_pdf(wo, wi, h) as f64,
            );
            eprintln!(
                "{name} θ_o = {theta_o}: χ² {:.1} dof {} p = {:.3}",
                out.statistic, out.dof, out.p_value
            );
            assert!(
                out.p_value > alpha,
                "{name} θ_o = {theta_o}, h = {h}: {out:?}"
            );
        }
    }

    /// The pdf returned with a sample is the one `direction_pdf` gives, and it integrates to
    /// at most 1 (samples the BCSDF rejects are lost mass).
    #[test]
    fn sample_pdf_is_consistent_and_normalised() {
        for (name, theta_o, h) in CASES {
            let ds = shading(name);
            let wo = fiber_direction(theta_o.sin(), theta_o.cos(), std::f32::consts::FRAC_PI_2);
            let mut rng = tress_core::Sampler::from_seed(5);
            for _ in 0..2000 {
                if let Some((wi, pdf)) = ds.sample_direction(wo, h, rng.next_4d()) {
                    let p = ds.direction_pdf(wo, wi, h);
                    assert!((p - pdf).abs() <= 1e-4 * p, "{name}: {pdf} vs {p}");
                }
            }
            // ∫ pdf dω by quadrature over (sin θ, φ).
            let (ns, np) = (600, 400);
            let mut sum = 0.0f64;
            for i in 0..ns {
                let s = -1.0 + (i as f32 + 0.5) * 2.0 / ns as f32;
                for j in 0..np {
                    let phi = (j as f32 + 0.5) * TAU / np as f32;
                    sum += ds.direction_pdf(wo, fiber_direction(s, safe_sqrt(1.0 - s * s), phi), h)
                        as f64;
                }
            }
            let integral = sum * (2.0 / ns as f64) * (TAU as f64 / np as f64);
            assert!((integral - 1.0).abs() < 0.01, "{name}: ∫ pdf = {integral}");
        }
    }
}
