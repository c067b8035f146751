//! Dual scattering (Zinke, Yuksel, Weber & Keyser 2008) for *any* [`Bcsdf`]: the per-θ tables,
//! built by deterministic quadrature of `eval_lobe`, and the shading function both
//! dual-scattering integrators share. The maths is in the book's chapter
//! docs/src/reference/hair-maths.md#dual-scattering; "(maths: …)" below names its sections.
//!
//! # What the tables measure
//! For a fixed direction `w_fix` at inclination θ (local fiber frame, φ = π/2, so
//! `w_fix = (sin θ, 0, cos θ)`), every quantity is an integral of `eval_lobe(w_fix, ω, h, t)`
//! over ω ∈ S² and h ∈ [−1, 1] (averaged: weight ½). The fixed direction is the **light
//! direction** ω_d and it sits in the `wo` slot: tress's models are energy conserving in that
//! slot (`∫ eval(wo, ωi) dωi = albedo(wo)`, the white furnace), and for reciprocal models
//! `eval(ω_d, ω)` is exactly the light arriving from ω_d and leaving toward ω. For
//! non-reciprocal models (Chiang/pbrt: A_p, h and the tilt attach to `wo`) it is the standard
//! approximation. By the fiber's rotational symmetry fixing φ = π/2 *is* the average over the
//! incident azimuth.
//!
//! * **Forward / backward.** Light travels along −ω_d; passing straight through the fiber it
//!   leaves toward φ = −π/2 (relative azimuth π). The forward half-space Ω_f is therefore
//!   `ω.z < 0` (|φ − π/2| > π/2), the backward half-space Ω_b is `ω.z > 0`.
//! * `ā_f = ∫_{Ω_f} eval dω`, `ā_b = ∫_{Ω_b} eval dω` (h-averaged): energy fractions, so
//!   `ā_f + ā_b` is the fiber's albedo for that light (1 for a white energy-conserving fiber).
//! * Per lobe t: `a_f^t`, `a_b^t` as above, and the energy-weighted mean α_t and **variance**
//!   β_t² of the longitudinal offset θ_h = (θ_fix + θ)/2 from the specular cone (θ = −θ_fix ⇔
//!   θ_h = 0), over the whole sphere — one α_t, β_t² per lobe, as in the paper's formulas.
//!   Using θ_h units throughout is self-consistent: a crossing that offsets θ_h by x deflects
//!   the light's inclination by 2x, and an inclination spread of variance V widens the θ_h of
//!   the next scattering by V/4, so n crossings add exactly n·β̄_f² to M^G's variance.
//! * `ᾱ_{f|b} = Σ_t a_{f|b}^t α_t / Σ_t a_{f|b}^t`, `β̄²_{f|b}` likewise with the weights on
//!   the variances (maths: the tables; notation).
//! * `Ā_b`, `Δ_b` (eqs. 14, 16), on the effective ā_f, ā_b of the next item.
//! * **Non-conserving models.** Marschner's model scatters ≈ 2× the incident energy (maths:
//!   Marschner's energy), so its ā_f exceeds 1 and `1/(1 − ā_f²)` passes its pole. Clamping ā_f
//!   to 0.99 alone (maths: sanity checks on the tables) is
//!   not enough: Marschner's blond then gets Ā_b ≈ 10³ (measured). The multiple-scattering
//!   terms therefore use `ā_{f|b} / max(1, ā_f + ā_b)` — the forward/backward *split* of the
//!   energy, which a fiber cannot exceed — and then clamp ā_f to [`A_F_MAX`]. For an
//!   energy-conserving model both steps are inert (the clamp only guards ā_b → 0).
//! * `σ_b` (eq. 17): the paper prints the denominator as `ā_b + ā_b³(2β̄_f + 3β̄_b)`, which adds
//!   radians to a pure number. We read eq. 17 as the ā-weighted mean of the standard deviations
//!   of the two back-scattering paths it sums, i.e. denominator `ā_b + ā_b³`:
//!   `σ_b = (1 + d_b ā_f²) · (√(2β̄_f² + β̄_b²) + ā_b² √(2β̄_f² + 3β̄_b²)) / (1 + ā_b²)`,
//!   which lies between the two paths' spreads (tested) and is finite for ā_b → 0. The
//!   tables store the d_b-free part σ_b0; [`DsGlobals::sigma_b2`] applies `(1 + d_b ā_f²)`.
//! * `N_t^G = a_f^t / (2π)`. For a model of Marschner's form `f = M_t(θ_h) N_t(φ) / cos²θ_d`
//!   with M_t a unit-area Gaussian *in θ_h*, the energy per radian of azimuth is
//!   `∫ f cos²θ dθ ≈ 2 N_t` on the specular cone (dθ = 2 dθ_h, cos θ = cos θ_d there), so the
//!   lobe's N_t is half its energy per radian, and the paper's `N^G = (1/π)∫_{Ω_f} N_t dφ` is
//!   `a_f^t / (2π)`. This makes `f_s_scatter` computable from the tables for any model.
//!
//! # Multiple scattering
//! [`MultipleScattering::Paper`] uses the closed forms above (T_f = d_f ā_f^n, Ā_b, Δ_b, σ_b).
//! [`MultipleScattering::FiberMedium`], the default, measures the scattered transmittance and
//! the back-scattering of the fibers by random walks in a homogeneous medium of them
//! ([`crate::fiber_medium`]): the closed forms treat a fiber as passing light straight on or
//! straight back, and make light hair 35–45 % too dark in red
//! (docs/src/research/dual-scattering-accuracy.md#as-first-built-the-papers-closed-forms).
//!
//! # Quadrature
//! Midpoint rule in θ ∈ [−π/2, π/2] (`theta_quad` nodes) and in φ over the whole circle
//! (`phi_quad` nodes, even, so both half-space boundaries fall between nodes); Gauss–Legendre
//! in h (`h_nodes`). The midpoint rule integrates a smooth lobe lying inside the interval (in φ:
//! any periodic integrand) with an error that decays like exp(−2π²σ²/Δ²) for a lobe of width σ
//! and node spacing Δ, so spacing ≈ lobe width already gives ~1e-8; only lobes cut by the
//! θ = ±π/2 ends fall back to O(Δ²). Near-field models (Chiang) have, for each h, an azimuthal
//! lobe as narrow as the azimuthal roughness (logistic scale 0.024 rad at β_n = 0.1); its
//! per-h error oscillates with h faster than any affordable h rule resolves, so `phi_quad` is
//! doubled (at most 3 times) until the half-space energies at θ ≈ 0 and θ ≈ 1.2 change by
//! < 1e-3. Models that ignore h, or are mirror symmetric in it, are detected and integrated
//! over one h / over [0, 1] (see `HDomain`). At the defaults, against a 128 (h) × 384 (θ) ×
//! 384 (φ) quadrature, every registered test model's tables are accurate to 1.5e-3 in ā
//! (Marschner; ≤ 4.5e-4 for the others), 1.5e-4 rad in α and 1 % in β².
//!
//! The table's θ nodes are cell centres `θ_k = −π/2 + (k + ½)·π/N` (never exactly along the
//! fiber); lookups interpolate linearly and clamp beyond the first/last node.
//!
//! # Shading
//! [`DualScatteringShading::eval`] is the paper's F (maths: the shading function F) in tress's
//! value convention (cos θ_i included: `L_o = ∫ L(ω_d) F dω_d`), with each term normalised to
//! the energy the paper assigns it (see `eval` for why the literal constants cannot be used
//! here). The tables are indexed by **θ of the light direction ω_d** (θ_i; maths: which
//! inclination indexes the tables), consistent with how they were built; the per-lobe α_t, β_t²
//! and N_t^G of `f_s_scatter` come from the same lookup.
//!
//! As specified, F is not normalised in tress's units: with M^G and the back-scattering
//! Gaussian unit-area in θ_h (dθ_i = 2 dθ_h) and f_back spread over the whole azimuth circle,
//! `d_b f_back_direct` alone returns up to 8·d_b·Ā_b of a uniform environment (less where the
//! Gaussian is cut at θ = ±π/2). Measured `∫ F dω_d` at θ_o = 0 (red channel, test
//! `default_tables_for_every_model`): white Chiang (β = 0.3) 2.98 with n = 0 and the light
//! visible (of which f_s: 1.00), 3.43 scattered only with n = 1; brown Chiang 0.43 (f_s: 0.40)
//! and 0.13.

use crate::fiber_medium::{BackScattering, FiberMedium};
use crate::ParamError;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;
use std::f64::consts::PI as PI64;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tress_core::limits::{Limits, ALLOW_SLOW_TABLES_VAR};
use tress_core::math::{erf, safe_asin, Rgb, Vec2, Vec3};
use tress_core::sampling::sample_uniform_sphere;
use tress_core::Bcsdf;

/// Upper clamp of ā_f wherever it enters T_f, Ā_b, Δ_b or σ_b (their 1/(1 − ā_f²) poles).
pub const A_F_MAX: f32 = 0.99;

/// Smallest variance (rad²) a Gaussian is evaluated with: lobes carrying no energy have zero
/// measured variance and would otherwise give 0·∞.
const MIN_VARIANCE: f32 = 1e-6;

/// Resolution of the tables and of the quadrature that fills them.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DualScatteringSettings {
    /// Table nodes over θ ∈ [−π/2, π/2] (cell centres).
    pub theta_nodes: usize,
    /// Gauss–Legendre nodes over h ∈ [−1, 1].
    pub h_nodes: usize,
    /// Midpoint nodes over the integrated direction's inclination.
    pub theta_quad: usize,
    /// Midpoint nodes over the integrated direction's azimuth (even); a minimum, doubled
    /// automatically for narrow azimuthal lobes (module docs, "Quadrature").
    pub phi_quad: usize,
    /// How light that crossed other fibers is modelled (module docs, "Multiple scattering").
    pub multiple_scattering: MultipleScattering,
    /// Random walks per θ node for [`MultipleScattering::FiberMedium`].
    pub walks: u32,
}

/// Where the multiple-scattering quantities of F come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
pub enum MultipleScattering {
    /// Zinke et al.'s closed forms: `T_f = d_f ā_f^n`, Ā_b, Δ_b, σ_b (eqs. 14–17).
    Paper,
    /// Random walks in a homogeneous medium of the fibers ([`crate::fiber_medium`]).
    FiberMedium,
}

impl Default for DualScatteringSettings {
    fn default() -> Self {
        DualScatteringSettings {
            theta_nodes: 64,
            h_nodes: 32,
            theta_quad: 64,
            phi_quad: 96,
            multiple_scattering: MultipleScattering::FiberMedium,
            walks: 4096,
        }
    }
}

impl DualScatteringSettings {
    fn validate(&self, limits: &Limits) -> Result<(), ParamError> {
        let check = |field: &'static str, v: usize, lo: usize| {
            if (lo..=4096).contains(&v) {
                Ok(())
            } else {
                Err(ParamError::new(
                    field,
                    v,
                    format!("must lie in [{lo}, 4096]"),
                ))
            }
        };
        check("theta_nodes", self.theta_nodes, 2)?;
        check("h_nodes", self.h_nodes, 1)?;
        check("theta_quad", self.theta_quad, 2)?;
        check("phi_quad", self.phi_quad, 2)?;
        if !(64..=1 << 24).contains(&self.walks) {
            return Err(ParamError::new(
                "walks",
                self.walks,
                "must lie in [64, 16777216]",
            ));
        }
        if !self.phi_quad.is_multiple_of(2) {
            return Err(ParamError::new(
                "phi_quad",
                self.phi_quad,
                "must be even (the half-space boundaries must fall between nodes)",
            ));
        }
        let work = self.work_over_default();
        if work > MAX_TABLE_WORK && !limits.slow_tables {
            return Err(ParamError::new(
                "tables",
                format!(
                    "(theta_nodes: {}, h_nodes: {}, theta_quad: {}, phi_quad: {}, walks: {})",
                    self.theta_nodes, self.h_nodes, self.theta_quad, self.phi_quad, self.walks
                ),
                format!(
                    "{work:.0}× the default tables' work, about {:.0} s per hair material on \
                     2 cores (over the {MAX_TABLE_WORK}× limit): lower them, or set \
                     {ALLOW_SLOW_TABLES_VAR}=1 to build them anyway",
                    work * DEFAULT_BUILD_SECONDS
                ),
            ));
        }
        Ok(())
    }

    /// The build's work relative to the defaults: quadrature nodes (θ × h × θ' × φ') plus the
    /// random walks (θ × walks; a walk costs about as much as 60 quadrature nodes).
    fn work_over_default(&self) -> f64 {
        let work = |s: &Self| {
            (s.theta_nodes * s.h_nodes * s.theta_quad * s.phi_quad) as f64
                + 60.0 * s.theta_nodes as f64 * f64::from(s.walks)
        };
        work(self) / work(&Self::default())
    }
}

/// Table settings beyond this many times the default tables' work are refused (a build of
/// `theta_nodes: 4096` ran for minutes without a word) unless the run's [`Limits`] allow slow
/// tables (the front ends' [`ALLOW_SLOW_TABLES_VAR`]).
pub const MAX_TABLE_WORK: f64 = 16.0;
/// Build time of the default tables on the 2-core development machine (for the estimate).
const DEFAULT_BUILD_SECONDS: f64 = 1.3;

/// The density factors d_f (forward) and d_b (backward), in [0, 1]: the paper's free
/// parameters, or scales of the measured terms (see [`DensityFactors::for_model`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DensityFactors {
    /// Forward density factor d_f, in [0, 1]: scales the forward-scattered light T_f.
    pub d_f: f32,
    /// Backward density factor d_b, in [0, 1]: scales the local back-scattering.
    pub d_b: f32,
}

impl Default for DensityFactors {
    /// 0.7 for both, as Zinke et al. suggest and every public implementation uses.
    fn default() -> Self {
        DensityFactors { d_f: 0.7, d_b: 0.7 }
    }
}

impl DensityFactors {
    /// The defaults for `model`: the paper's 0.7 for its closed forms; 1 (nothing removed)
    /// for the measured fiber medium, whose transport already accounts for the hair density.
    pub fn for_model(model: MultipleScattering) -> Self {
        match model {
            MultipleScattering::Paper => Self::default(),
            MultipleScattering::FiberMedium => DensityFactors { d_f: 1.0, d_b: 1.0 },
        }
    }
}

/// Why the tables could not be built.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum DualScatteringError {
    /// A table setting is out of range.
    #[error("dual-scattering settings")]
    Param(#[from] ParamError),
    /// The BCSDF returned NaN or infinity while the tables were being integrated.
    #[error(
        "the BCSDF returned a non-finite value (lobe {lobe}, light inclination θ = {theta} rad)"
    )]
    NonFinite {
        /// Name of the lobe ([`Bcsdf::lobe_names`]).
        lobe: &'static str,
        /// Light inclination at which it happened, in radians.
        theta: f32,
    },
}

/// The global (lobe-summed) quantities at one light inclination θ, per RGB channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DsGlobals {
    /// ā_f: energy scattered into the forward half-space, as measured.
    pub a_f: Rgb,
    /// ā_b: energy scattered into the backward half-space, as measured.
    pub a_b: Rgb,
    /// ā_f, ā_b as the multiple-scattering terms (T_f, Ā_b, Δ_b, σ_b) use them: scaled by
    /// 1/max(1, ā_f + ā_b), then ā_f clamped to [`A_F_MAX`] (module docs, "Non-conserving
    /// models"). Equal to the measured values for any model that conserves energy.
    pub a_f_eff: Rgb,
    /// ā_b scaled like `a_f_eff` (not clamped).
    pub a_b_eff: Rgb,
    /// ᾱ_f, ᾱ_b: lobe-weighted mean longitudinal shifts (rad, θ_h units).
    pub alpha_f: Rgb,
    /// ᾱ_b: the backward half-space's mean shift (rad, θ_h units).
    pub alpha_b: Rgb,
    /// β̄_f², β̄_b²: lobe-weighted longitudinal **variances** (rad², θ_h units).
    pub beta2_f: Rgb,
    /// β̄_b²: the backward half-space's variance (rad², θ_h units).
    pub beta2_b: Rgb,
    /// Ā_b (eq. 14): average back-scattering attenuation.
    pub big_a_b: Rgb,
    /// Δ_b (eq. 16): average longitudinal shift of back scattering (rad).
    pub delta_b: Rgb,
    /// σ_b without its `(1 + d_b ā_f²)` factor (eq. 17, module docs): a standard deviation.
    pub sigma_b0: Rgb,
}

impl DsGlobals {
    /// σ_b² (eq. 17) for the backward density factor `d_b`: a variance.
    pub fn sigma_b2(&self, d_b: f32) -> Rgb {
        let a_f = self.a_f_eff;
        let s = (Rgb::ONE + d_b * a_f * a_f) * self.sigma_b0;
        s * s
    }

    fn lerp(&self, o: &Self, t: f32) -> Self {
        DsGlobals {
            a_f: self.a_f.lerp(o.a_f, t),
            a_b: self.a_b.lerp(o.a_b, t),
            a_f_eff: self.a_f_eff.lerp(o.a_f_eff, t),
            a_b_eff: self.a_b_eff.lerp(o.a_b_eff, t),
            alpha_f: self.alpha_f.lerp(o.alpha_f, t),
            alpha_b: self.alpha_b.lerp(o.alpha_b, t),
            beta2_f: self.beta2_f.lerp(o.beta2_f, t),
            beta2_b: self.beta2_b.lerp(o.beta2_b, t),
            big_a_b: self.big_a_b.lerp(o.big_a_b, t),
            delta_b: self.delta_b.lerp(o.delta_b, t),
            sigma_b0: self.sigma_b0.lerp(o.sigma_b0, t),
        }
    }
}

/// One lobe's quantities at one light inclination θ, per RGB channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DsLobe {
    /// a_f^t, a_b^t: the lobe's energy in the forward / backward half-space.
    pub a_f: Rgb,
    /// a_b^t: the lobe's energy in the backward half-space.
    pub a_b: Rgb,
    /// α_t: energy-weighted mean of θ_h (rad); 0 where the lobe carries no energy.
    pub alpha: Rgb,
    /// β_t²: energy-weighted variance of θ_h (rad²); 0 where the lobe carries no energy.
    pub beta2: Rgb,
}

impl DsLobe {
    /// N_t^G, the mean of the lobe's azimuthal function over the forward half-circle
    /// (module docs): `a_f^t / (2π)`.
    pub fn n_g(&self) -> Rgb {
        self.a_f / (2.0 * PI)
    }

    fn lerp(&self, o: &Self, t: f32) -> Self {
        DsLobe {
            a_f: self.a_f.lerp(o.a_f, t),
            a_b: self.a_b.lerp(o.a_b, t),
            alpha: self.alpha.lerp(o.alpha, t),
            beta2: self.beta2.lerp(o.beta2, t),
        }
    }
}

/// The dual-scattering tables of one BCSDF (module docs).
#[derive(Clone, Debug)]
pub struct DualScatteringTables {
    settings: DualScatteringSettings,
    lobe_names: &'static [&'static str],
    globals: Vec<DsGlobals>,
    /// `theta_nodes × lobes`, node-major.
    lobes: Vec<DsLobe>,
    /// Each lobe's energy within a half-circle of relative azimuth centred on Δ_j
    /// (`AZIMUTH_NODES` nodes over [0, π]): `theta_nodes × lobes × AZIMUTH_NODES`.
    half_circle_energy: Vec<Rgb>,
    /// Measured multiple scattering ([`MultipleScattering::FiberMedium`]).
    medium: Option<FiberMedium>,
    /// See [`DualScatteringTables::settled_counts`].
    settled: SettledCounts,
    build_time: Duration,
}

/// Fiber counts past which F no longer changes measurably, so the density grid may stop
/// counting there ([`tress_core::accel::FiberDensity::fibers_crossed_up_to`]): most rays toward
/// a blocked light cross far more fibers than any light gets through, and the count is the
/// larger part of a dual-scattering sample's cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SettledCounts {
    /// Fibers crossed toward the light past which the scattered transmittance is at most
    /// [`NEGLIGIBLE_TRANSMITTANCE`] in every channel.
    pub toward_light: f32,
    /// Fibers behind the point past which the local back-scattering's energy is within
    /// [`SETTLED_BACK_SCATTERING`] (relative) of a half-space's.
    pub behind: f32,
}

/// Scattered transmittance treated as no light at all: a millionth of the light's radiance,
/// far below what a render resolves.
pub const NEGLIGIBLE_TRANSMITTANCE: f32 = 1e-6;
/// Relative change of the local back-scattering's energy treated as none.
pub const SETTLED_BACK_SCATTERING: f32 = 1e-5;

impl DualScatteringTables {
    /// Integrates `bcsdf` numerically (module docs); runs on all cores, deterministically.
    /// Settings whose work exceeds [`MAX_TABLE_WORK`] are refused unless `limits` allow slow
    /// tables.
    pub fn new(
        bcsdf: &dyn Bcsdf,
        settings: &DualScatteringSettings,
        limits: &Limits,
    ) -> Result<Self, DualScatteringError> {
        settings.validate(limits)?;
        Self::build(bcsdf, settings, h_domain(bcsdf))
    }

    fn build(
        bcsdf: &dyn Bcsdf,
        settings: &DualScatteringSettings,
        domain: HDomain,
    ) -> Result<Self, DualScatteringError> {
        let start = Instant::now();
        let n = settings.theta_nodes;
        let quad = Quadrature::new(settings, domain, refined_phi_quad(bcsdf, settings, domain)?);
        let per_node = crate::parallel_map(n, |k| quad.node(bcsdf, node_theta(k, n)));
        let lobe_names = bcsdf.lobe_names();
        let mut globals = Vec::with_capacity(n);
        let mut lobes = Vec::with_capacity(n * lobe_names.len());
        let mut half_circle_energy = Vec::with_capacity(n * lobe_names.len() * AZIMUTH_NODES);
        for m in per_node {
            let (g, l, w) = m?.finish();
            globals.push(g);
            lobes.extend(l);
            half_circle_energy.extend(w);
        }
        let medium = (settings.multiple_scattering == MultipleScattering::FiberMedium).then(|| {
            let albedo: Vec<Rgb> = globals.iter().map(|g| g.a_f + g.a_b).collect();
            FiberMedium::build(bcsdf, &albedo, |k| node_theta(k, n) as f32, settings.walks)
        });
        let settled = match &medium {
            Some(m) => SettledCounts {
                toward_light: m.transmittance_negligible_past(NEGLIGIBLE_TRANSMITTANCE),
                behind: m.back_scattering_settled_past(SETTLED_BACK_SCATTERING),
            },
            None => {
                // T_f = d_f·ā_f^n with d_f ≤ 1, and nothing reads the depth behind.
                let a_f = globals
                    .iter()
                    .map(|g| g.a_f_eff.max_element())
                    .fold(0.0f32, f32::max);
                let toward_light = if a_f < 1.0 {
                    // A hair past where ā_f^n meets the bound, for rounding.
                    (NEGLIGIBLE_TRANSMITTANCE.ln() / a_f.ln()).max(1.0) * 1.001
                } else {
                    f32::INFINITY
                };
                SettledCounts {
                    toward_light,
                    behind: f32::INFINITY,
                }
            }
        };
        let build_time = start.elapsed();
        let albedo_max = globals
            .iter()
            .map(|g| (g.a_f + g.a_b).max_element())
            .fold(0.0f32, f32::max);
        if albedo_max > 1.0 {
            tracing::warn!(
                "dual scattering: the fiber scatters up to {albedo_max:.3} of the incident energy \
                 (not energy conserving); T_f, Ā_b, Δ_b and σ_b use ā_f, ā_b scaled to a total of 1"
            );
        }
        tracing::info!(
            "dual-scattering tables for {} lobe(s), {} θ nodes, quadrature h {} ({:?}) × θ {} × φ {}: \
             built in {:.3} s; F settles past {} fibers toward the light and {} behind",
            lobe_names.len(),
            n,
            quad.h.len(),
            domain,
            settings.theta_quad,
            quad.phi.len(),
            build_time.as_secs_f64(),
            settled.toward_light,
            settled.behind
        );
        Ok(DualScatteringTables {
            settings: settings.clone(),
            lobe_names,
            globals,
            lobes,
            half_circle_energy,
            medium,
            settled,
            build_time,
        })
    }

    /// The settings the tables were built with.
    pub fn settings(&self) -> &DualScatteringSettings {
        &self.settings
    }

    /// The BCSDF's lobe names; lobe indices follow this order.
    pub fn lobe_names(&self) -> &'static [&'static str] {
        self.lobe_names
    }

    /// Wall-clock time the quadrature took.
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// The inclinations of the table nodes, ascending.
    pub fn node_thetas(&self) -> impl Iterator<Item = f32> + '_ {
        let n = self.globals.len();
        (0..n).map(move |k| node_theta(k, n) as f32)
    }

    /// Global quantities at light inclination `theta` (rad), linearly interpolated.
    pub fn globals(&self, theta: f32) -> DsGlobals {
        let (i, t) = self.locate(theta);
        self.globals[i].lerp(&self.globals[i + 1], t)
    }

    /// Lobe `lobe`'s quantities at light inclination `theta`; zero for an index past the last
    /// lobe (like `Bcsdf::eval_lobe`).
    pub fn lobe(&self, theta: f32, lobe: usize) -> DsLobe {
        let nl = self.lobe_names.len();
        if lobe >= nl {
            return DsLobe::default();
        }
        let (i, t) = self.locate(theta);
        self.lobes[i * nl + lobe].lerp(&self.lobes[(i + 1) * nl + lobe], t)
    }

    /// N_t^G(θ, Δ): lobe `lobe`'s response, per radian of azimuth, to light from inclination
    /// `theta` that arrives spread uniformly (density 1/π) over the half-circle of azimuths
    /// around its direction (forward-scattered light), seen at relative azimuth `delta` ∈ [0, π]
    /// from the light's direction (0: back toward the light's side, π: straight through): the
    /// lobe's energy within the half-circle of relative azimuths `[Δ − π/2, Δ + π/2]`, over π.
    /// Over all Δ it carries the lobe's whole energy. The paper's `N^G` ([`DsLobe::n_g`]) is
    /// the forward half's energy over 2π at every Δ, which assumes the viewer looks toward the
    /// light through the hair: light that crossed fibers on the viewer's side is returned by
    /// the back lobes (R, TRT) and, for blond fibers, is 9× weaker than that. Zero past the
    /// last lobe.
    pub fn scattered_azimuthal(&self, theta: f32, lobe: usize, delta: f32) -> Rgb {
        let nl = self.lobe_names.len();
        if lobe >= nl {
            return Rgb::ZERO;
        }
        let (i, t) = self.locate(theta);
        let u = (delta / PI).clamp(0.0, 1.0) * (AZIMUTH_NODES - 1) as f32;
        // NaN maps to the first node rather than out of bounds.
        let u = if u.is_nan() { 0.0 } else { u };
        let j = (u as usize).min(AZIMUTH_NODES - 2);
        let s = u - j as f32;
        let at = |node: usize| {
            let row = &self.half_circle_energy[(node * nl + lobe) * AZIMUTH_NODES..];
            row[j].lerp(row[j + 1], s)
        };
        at(i).lerp(at(i + 1), t) / PI
    }

    /// Light returned by the hair behind a fiber met by light from inclination `theta`: the
    /// local term f_back. `behind` is the fibers (expected) behind it, away from the light
    /// (the fiber medium's layer; the paper assumes a half-space); `d_b` enters the paper's
    /// σ_b only.
    pub fn back_scattering(&self, theta: f32, d_b: f32, behind: f32) -> BackScattering {
        match &self.medium {
            Some(m) => {
                let (i, t) = self.locate(theta);
                m.back_scattering(i, t, behind)
            }
            None => {
                let g = self.globals(theta);
                BackScattering {
                    energy: g.big_a_b,
                    mean: g.delta_b,
                    variance: g.sigma_b2(d_b),
                }
            }
        }
    }

    /// The fiber counts past which F no longer changes measurably.
    pub fn settled_counts(&self) -> SettledCounts {
        self.settled
    }

    /// The random-walk tables, for [`MultipleScattering::FiberMedium`].
    pub fn fiber_medium(&self) -> Option<&FiberMedium> {
        self.medium.as_ref()
    }

    /// The multiple-scattering model the tables were built for.
    pub fn multiple_scattering(&self) -> MultipleScattering {
        self.settings.multiple_scattering
    }

    /// Lower node index and interpolation weight, clamped to the end nodes.
    fn locate(&self, theta: f32) -> (usize, f32) {
        let n = self.globals.len();
        let u = (theta + 0.5 * PI) * (n as f32 / PI) - 0.5;
        // NaN maps to the first node rather than out of bounds.
        let u = if u.is_nan() {
            0.0
        } else {
            u.clamp(0.0, (n - 1) as f32)
        };
        let i = (u as usize).min(n - 2);
        (i, u - i as f32)
    }
}

/// Which part of the h range the quadrature must cover.
#[derive(Clone, Copy, Debug, PartialEq)]
enum HDomain {
    /// The model ignores h (far-field models such as Marschner's and d'Eon's integrate it
    /// analytically): one node suffices.
    Ignored,
    /// Mirror symmetry of a circular fiber, `f(h, Δφ) = f(−h, −Δφ)` (maths: symmetry): the
    /// mirror Δφ → −Δφ keeps both half-spaces and θ, so every moment of −h equals that of h and
    /// h ∈ [0, 1] suffices.
    Mirror,
    Full,
}

/// Probes `bcsdf` at 256 fixed pseudo-random direction pairs (the fixed direction in the
/// tables' position, φ = π/2) for the symmetries of [`HDomain`]. A model lacking a symmetry
/// violates it almost everywhere, so agreement on all probes is conclusive in practice;
/// independence of h is checked bit for bit, the mirror to a relative 1e-3 (it maps φ through
/// a different rounding).
fn h_domain(bcsdf: &dyn Bcsdf) -> HDomain {
    let mut rng = tress_core::rng::Sampler::from_seed(0xD5A1);
    let probes: Vec<(Vec3, Vec3)> = (0..256)
        .map(|_| {
            let u = rng.next_4d();
            let theta = PI * (u[0] - 0.5);
            let wo = Vec3::new(theta.sin(), 0.0, theta.cos());
            (wo, sample_uniform_sphere(Vec2::new(u[1], u[2])))
        })
        .collect();
    let lobes = 0..bcsdf.lobe_names().len();
    let ignored = probes.iter().all(|&(wo, wi)| {
        lobes.clone().all(|t| {
            let f0 = bcsdf.eval_lobe(wo, wi, -0.9, t);
            [-0.3, 0.2, 0.8]
                .into_iter()
                .all(|h| bcsdf.eval_lobe(wo, wi, h, t) == f0)
        })
    });
    if ignored {
        return HDomain::Ignored;
    }
    let mirror = probes.iter().all(|&(wo, wi)| {
        let wi_m = Vec3::new(wi.x, -wi.y, wi.z);
        lobes.clone().all(|t| {
            [0.15, 0.5, 0.85].into_iter().all(|h| {
                let a = bcsdf.eval_lobe(wo, wi, h, t);
                let b = bcsdf.eval_lobe(wo, wi_m, -h, t);
                (a - b)
                    .abs()
                    .cmple(1e-3 * a.abs().max(b.abs()) + Rgb::splat(1e-6))
                    .all()
            })
        })
    });
    if mirror {
        HDomain::Mirror
    } else {
        HDomain::Full
    }
}

/// Largest automatic refinement of `phi_quad` (module docs, "Quadrature").
const MAX_PHI_DOUBLINGS: u32 = 3;

/// `phi_quad`, doubled until the half-space energies at two pilot inclinations (the nodes
/// nearest θ = 0 and θ = 1.2 rad, where the per-h errors average out differently) change by
/// less than 1e-3, at most [`MAX_PHI_DOUBLINGS`] times.
fn refined_phi_quad(
    bcsdf: &dyn Bcsdf,
    settings: &DualScatteringSettings,
    domain: HDomain,
) -> Result<usize, DualScatteringError> {
    let n = settings.theta_nodes;
    let nearest = |theta: f64| (((theta / PI64 + 0.5) * n as f64) as usize).min(n - 1);
    let pilots = [nearest(0.0), nearest(1.2)].map(|k| node_theta(k, n));
    let energies = |phi_quad: usize| -> Result<Vec<DVec3>, DualScatteringError> {
        let quad = Quadrature::new(settings, domain, phi_quad);
        let mut e = Vec::new();
        for theta in pilots {
            let m = quad.node(bcsdf, theta)?;
            e.push(m.lobes.iter().map(|l| l.e_f).sum());
            e.push(m.lobes.iter().map(|l| l.e_b).sum());
        }
        Ok(e)
    };
    let mut phi_quad = settings.phi_quad;
    let mut coarse = energies(phi_quad)?;
    for _ in 0..MAX_PHI_DOUBLINGS {
        let fine = energies(2 * phi_quad)?;
        let change = coarse
            .iter()
            .zip(&fine)
            .map(|(c, f)| (*c - *f).abs().max_element())
            .fold(0.0, f64::max);
        if change < 1e-3 {
            break;
        }
        phi_quad *= 2;
        coarse = fine;
    }
    Ok(phi_quad)
}

/// θ of table node `k` of `n` (cell centres).
fn node_theta(k: usize, n: usize) -> f64 {
    -0.5 * PI64 + (k as f64 + 0.5) * PI64 / n as f64
}

/// Nodes and weights of the (h, θ, φ) quadrature.
struct Quadrature {
    /// (h, weight): the weights average over [−1, 1] (module docs of [`HDomain`]).
    h: Vec<(f32, f64)>,
    /// (sin θ, cos θ, θ, cos θ·Δθ·Δφ): the solid-angle weight of one (θ, φ) cell.
    theta: Vec<(f64, f64, f64, f64)>,
    /// (cos φ, sin φ); the first half (φ < 0) is the forward half-space.
    phi: Vec<(f64, f64)>,
}

impl Quadrature {
    fn new(s: &DualScatteringSettings, domain: HDomain, phi_quad: usize) -> Self {
        let d_theta = PI64 / s.theta_quad as f64;
        let d_phi = 2.0 * PI64 / phi_quad as f64;
        // (h, weight): the weights average over [−1, 1].
        let h = match domain {
            HDomain::Ignored => vec![(0.0, 1.0)],
            // Gauss–Legendre on [0, 1] with the node density of the full rule.
            HDomain::Mirror => gauss_legendre(s.h_nodes.div_ceil(2))
                .into_iter()
                .map(|(x, w)| (0.5 * (x + 1.0) as f32, 0.5 * w))
                .collect(),
            HDomain::Full => gauss_legendre(s.h_nodes)
                .into_iter()
                .map(|(x, w)| (x as f32, 0.5 * w))
                .collect(),
        };
        Quadrature {
            h,
            theta: (0..s.theta_quad)
                .map(|j| {
                    let t = -0.5 * PI64 + (j as f64 + 0.5) * d_theta;
                    (t.sin(), t.cos(), t, t.cos() * d_theta * d_phi)
                })
                .collect(),
            phi: (0..phi_quad)
                .map(|k| {
                    let p = -PI64 + (k as f64 + 0.5) * d_phi;
                    (p.cos(), p.sin())
                })
                .collect(),
        }
    }

    /// Energy moments of every lobe for the light at inclination `theta_fix`.
    fn node(&self, bcsdf: &dyn Bcsdf, theta_fix: f64) -> Result<NodeMoments, DualScatteringError> {
        let names = bcsdf.lobe_names();
        let w_fix = Vec3::new(theta_fix.sin() as f32, 0.0, theta_fix.cos() as f32);
        let half = self.phi.len() / 2;
        let mut lobes = vec![LobeMoments::default(); names.len()];
        // Energy per lobe and φ node (lobe-major), for the half-circle windows.
        let mut per_phi = vec![DVec3::ZERO; names.len() * self.phi.len()];
        // One ring of directions (fixed θ, every φ) per batch of the model's evaluation.
        let mut wis = vec![Vec3::ZERO; self.phi.len()];
        let mut values = vec![Rgb::ZERO; self.phi.len() * names.len()];
        for &(h, wh) in &self.h {
            for &(sin_t, cos_t, theta, w_cell) in &self.theta {
                let theta_h = 0.5 * (theta_fix + theta);
                let w = wh * w_cell;
                for (wi, &(cos_p, sin_p)) in wis.iter_mut().zip(&self.phi) {
                    *wi = Vec3::new(sin_t as f32, (cos_t * cos_p) as f32, (cos_t * sin_p) as f32);
                }
                bcsdf.eval_lobes_batch(w_fix, h, &wis, &mut values);
                for (k, row) in values.chunks_exact(names.len()).enumerate() {
                    let forward = k < half;
                    for (l, (m, value)) in lobes.iter_mut().zip(row).enumerate() {
                        let v = value.as_dvec3() * w;
                        per_phi[l * self.phi.len() + k] += v;
                        if forward {
                            m.e_f += v;
                        } else {
                            m.e_b += v;
                        }
                        m.m1 += v * theta_h;
                        m.m2 += v * (theta_h * theta_h);
                    }
                }
            }
        }
        for (m, &lobe) in lobes.iter().zip(names) {
            if !(m.e_f + m.e_b + m.m1 + m.m2).is_finite() {
                return Err(DualScatteringError::NonFinite {
                    lobe,
                    theta: theta_fix as f32,
                });
            }
        }
        let windows = per_phi
            .chunks_exact(self.phi.len())
            .flat_map(|energy| {
                (0..AZIMUTH_NODES).map(move |j| {
                    let delta = PI64 * j as f64 / (AZIMUTH_NODES - 1) as f64;
                    // Averaged over ±Δ: the h-averaged lobes are symmetric in azimuth, but a
                    // mirror-symmetric model integrated over h ∈ [0, 1] only is not.
                    0.5 * (self.half_circle(energy, delta) + self.half_circle(energy, -delta))
                })
            })
            .collect();
        Ok(NodeMoments { lobes, windows })
    }

    /// The energy of φ cells (`energy[k]` in the cell around `self.phi[k]`) within the
    /// half-circle of azimuths relative to the fixed direction centred on `delta`. The fixed
    /// direction lies at φ = π/2, so that half-circle is φ ∈ [Δ, Δ + π]; partly covered cells
    /// count in proportion.
    fn half_circle(&self, energy: &[DVec3], delta: f64) -> DVec3 {
        let d_phi = 2.0 * PI64 / self.phi.len() as f64;
        let mut sum = DVec3::ZERO;
        for (k, &e) in energy.iter().enumerate() {
            let a = -PI64 + k as f64 * d_phi;
            let covered: f64 = [-2.0, 0.0, 2.0]
                .iter()
                .map(|turns| {
                    let lo = delta + turns * PI64;
                    ((a + d_phi).min(lo + PI64) - a.max(lo)).max(0.0)
                })
                .sum();
            sum += e * (covered / d_phi);
        }
        sum
    }
}

/// Relative azimuths Δ ∈ [0, π] (uniform, both ends included) at which the half-circle
/// energies of forward-scattered light are tabulated.
const AZIMUTH_NODES: usize = 33;

#[derive(Clone, Copy, Default)]
struct LobeMoments {
    /// Energy in the forward / backward half-space.
    e_f: DVec3,
    e_b: DVec3,
    /// Σ energy·θ_h and Σ energy·θ_h² over the sphere.
    m1: DVec3,
    m2: DVec3,
}

struct NodeMoments {
    lobes: Vec<LobeMoments>,
    /// Half-circle energies, `lobes × AZIMUTH_NODES` ([`DualScatteringTables::scattered_azimuthal`]).
    windows: Vec<DVec3>,
}

/// `num / den` per channel, 0 where `den` carries no energy.
fn ratio(num: DVec3, den: DVec3) -> DVec3 {
    let f = |n: f64, d: f64| if d > 1e-30 { n / d } else { 0.0 };
    DVec3::new(f(num.x, den.x), f(num.y, den.y), f(num.z, den.z))
}

impl NodeMoments {
    /// Per-lobe statistics and the global quantities (maths: the tables).
    fn finish(self) -> (DsGlobals, Vec<DsLobe>, Vec<Rgb>) {
        let mut a_f = DVec3::ZERO;
        let mut a_b = DVec3::ZERO;
        let (mut alpha_f, mut alpha_b) = (DVec3::ZERO, DVec3::ZERO);
        let (mut beta2_f, mut beta2_b) = (DVec3::ZERO, DVec3::ZERO);
        let lobes: Vec<DsLobe> = self
            .lobes
            .iter()
            .map(|m| {
                let e = m.e_f + m.e_b;
                let alpha = ratio(m.m1, e);
                let beta2 = (ratio(m.m2, e) - alpha * alpha).max(DVec3::ZERO);
                a_f += m.e_f;
                a_b += m.e_b;
                alpha_f += m.e_f * alpha;
                alpha_b += m.e_b * alpha;
                beta2_f += m.e_f * beta2;
                beta2_b += m.e_b * beta2;
                DsLobe {
                    a_f: m.e_f.as_vec3(),
                    a_b: m.e_b.as_vec3(),
                    alpha: alpha.as_vec3(),
                    beta2: beta2.as_vec3(),
                }
            })
            .collect();
        let alpha_f = ratio(alpha_f, a_f);
        let alpha_b = ratio(alpha_b, a_b);
        let beta2_f = ratio(beta2_f, a_f);
        let beta2_b = ratio(beta2_b, a_b);

        // Eqs. 14, 16, 17 per channel, on energy fractions of at most 1 in total, with ā_f
        // clamped away from the pole at 1.
        let scale = DVec3::ONE / (a_f + a_b).max(DVec3::ONE);
        let af = (a_f * scale).min(DVec3::splat(A_F_MAX as f64));
        let ab = a_b * scale;
        let af2 = af * af;
        let ab2 = ab * ab;
        let one = DVec3::ONE;
        let q = one - af2;
        let big_a_b = ab * af2 / q + ab2 * ab * af2 / (q * q * q);
        let delta_b = alpha_b * (one - 2.0 * ab2 / (q * q))
            + alpha_f * (2.0 * q * q + 4.0 * af2 * ab2) / (q * q * q);
        let s1 = (2.0 * beta2_f + beta2_b).map(f64::sqrt);
        let s3 = (2.0 * beta2_f + 3.0 * beta2_b).map(f64::sqrt);
        let sigma_b0 = (s1 + ab2 * s3) / (one + ab2);

        let globals = DsGlobals {
            a_f: a_f.as_vec3(),
            a_b: a_b.as_vec3(),
            a_f_eff: af.as_vec3(),
            a_b_eff: ab.as_vec3(),
            alpha_f: alpha_f.as_vec3(),
            alpha_b: alpha_b.as_vec3(),
            beta2_f: beta2_f.as_vec3(),
            beta2_b: beta2_b.as_vec3(),
            big_a_b: big_a_b.as_vec3(),
            delta_b: delta_b.as_vec3(),
            sigma_b0: sigma_b0.as_vec3(),
        };
        (
            globals,
            lobes,
            self.windows.iter().map(|w| w.as_vec3()).collect(),
        )
    }
}

/// Gauss–Legendre nodes and weights on [−1, 1] (Newton iteration on P_n).
pub(crate) fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            // Tricomi's initial guess for the i-th root, descending from +1.
            let mut x = (PI64 * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let k = k as f64;
                    (p0, p1) = (p1, ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k);
                }
                // P_n = p1, P_{n−1} = p0 (also for n = 1, where the loop is empty).
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-15 {
                    break;
                }
            }
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

/// What identifies a BCSDF to a run's table cache (`tress_core::prepare::Preparation`, keyed
/// by this and the settings, compared by value; a model's `Debug` text could leave out a
/// parameter and hand it another model's tables): every lobe's value and the total, all channels
/// bit for bit, at 64 fixed random (ω_o, ω_i, h). Equal parameters give equal values; any
/// parameter that changes the scattering, and so the tables, changes some of them.
pub fn fingerprint(bcsdf: &dyn Bcsdf) -> Vec<u32> {
    let mut rng = tress_core::rng::Pcg32::new(0xf1_9e7, 0);
    let mut next = || rng.next_f32();
    let lobes = bcsdf.lobe_names().len();
    let mut key = Vec::new();
    for _ in 0..64 {
        let wo = sample_uniform_sphere(Vec2::new(next(), next()));
        let wi = sample_uniform_sphere(Vec2::new(next(), next()));
        let h = 2.0 * next() - 1.0;
        key.extend(bcsdf.eval(wo, wi, h).to_array().map(f32::to_bits));
        for p in 0..lobes {
            key.extend(bcsdf.eval_lobe(wo, wi, h, p).to_array().map(f32::to_bits));
        }
    }
    key
}

/// Longitudinal density of a lobe whose θ_h ~ N(mean, var) (θ_i = 2θ_h − θ_o), expressed as
/// a truncated Gaussian in s = sin θ_i on [−1, 1] with the matching centre and width (its
/// linearisation at the centre). Since dω = ds dφ, a term `E·p(s)·p(φ)` carries exactly the
/// energy E and has no 1/cos θ_i pole (which would give the estimators infinite variance).
fn longitudinal_density(s: f32, theta_o: f32, mean: Rgb, var: Rgb) -> Rgb {
    Rgb::from_array(std::array::from_fn(|c| {
        let centre = (2.0 * mean[c] - theta_o).clamp(-PI / 2.0, PI / 2.0);
        let sd_theta = 2.0 * var[c].max(MIN_VARIANCE).sqrt();
        let sd = (sd_theta * centre.cos())
            .max(0.5 * sd_theta * sd_theta)
            .max(1e-3);
        let mu = centre.sin();
        let x = s - mu;
        let z = x * x / (2.0 * sd * sd);
        // exp(−z) < 1e-17: below anything a render shows, and below the f32 precision of the
        // lobes it is added to.
        if z > 40.0 {
            return 0.0;
        }
        // The share of the Gaussian inside [−1, 1]: 1 to f32 precision more than 6 sd inside.
        let inside = if (1.0 - mu.abs()) > 6.0 * sd {
            1.0
        } else {
            let k = std::f32::consts::SQRT_2 * sd;
            (0.5 * (erf(f64::from((1.0 - mu) / k)) - erf(f64::from((-1.0 - mu) / k))) as f32)
                .max(1e-6)
        };
        (-z).exp() / ((2.0 * PI).sqrt() * sd * inside)
    }))
}

/// The forward-scattering state of the light after crossing `n` fibers (maths: the
/// decomposition).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForwardScattering {
    /// T_f = d_f · ā_f(θ)^n, with the effective ā_f ([`DsGlobals::a_f_eff`]).
    pub t_f: Rgb,
    /// σ̄_f² = n · β̄_f²(θ): a variance (rad², θ_h units).
    pub sigma2_f: Rgb,
}

/// The dual-scattering shading function F of one hair material (maths: the shading function
/// F), shared by both dual-scattering integrators.
#[derive(Clone, Debug)]
pub struct DualScatteringShading {
    bcsdf: Arc<dyn Bcsdf>,
    tables: Arc<DualScatteringTables>,
    factors: DensityFactors,
}

impl DualScatteringShading {
    /// `tables` must have been built from `bcsdf`; `factors` must lie in [0, 1].
    pub fn new(
        bcsdf: Arc<dyn Bcsdf>,
        tables: Arc<DualScatteringTables>,
        factors: DensityFactors,
    ) -> Result<Self, ParamError> {
        crate::check_range("d_f", factors.d_f, 0.0, 1.0)?;
        crate::check_range("d_b", factors.d_b, 0.0, 1.0)?;
        Ok(DualScatteringShading {
            bcsdf,
            tables,
            factors,
        })
    }

    /// The hair model the tables were built from.
    pub fn bcsdf(&self) -> &dyn Bcsdf {
        self.bcsdf.as_ref()
    }

    /// The precomputed dual-scattering tables.
    pub fn tables(&self) -> &DualScatteringTables {
        &self.tables
    }

    /// The density factors d_f and d_b in use.
    pub fn factors(&self) -> DensityFactors {
        self.factors
    }

    /// T_f and σ̄_f² for light arriving from local direction `wi` through `n` fibers
    /// (constant-θ approximation: every crossing at the light's inclination). Negative or NaN
    /// `n` counts as 0.
    ///
    /// With the paper's closed forms `T_f = d_f ā_f^n`. With the fiber medium `T_f` is the
    /// scattered transmittance T_s(n) of a layer n fibers deep, divided by `1 − e^{−n}`, the
    /// chance that the shadow ray is blocked: F adds the scattered light only when it is, and
    /// the scattered light reaches a point whether or not its own line to the light is blocked,
    /// so this keeps its expectation over the Poisson crossings the grid's mean n stands for.
    pub fn forward(&self, wi: Vec3, n: f32) -> ForwardScattering {
        let n = if n > 0.0 { n } else { 0.0 };
        let theta = safe_asin(wi.x);
        let g = self.tables.globals(theta);
        let t_f = match &self.tables.medium {
            Some(m) => {
                let (i, t) = self.tables.locate(theta);
                let blocked = -(-n).exp_m1();
                // n → 0: T_s(n) ≈ T_s'(0)·n, and so is the blocking chance.
                let n = n.max(1e-4);
                m.scattered_transmittance(i, t, n) / blocked.max(-(-1e-4f32).exp_m1())
            }
            None => {
                let a_f = g.a_f_eff;
                Rgb::new(a_f.x.powf(n), a_f.y.powf(n), a_f.z.powf(n))
            }
        };
        ForwardScattering {
            t_f: self.factors.d_f * t_f,
            sigma2_f: n * g.beta2_f,
        }
    }

    /// The inclination at which F's lobes (their shapes and energies, tabulated per light
    /// inclination) are read for light at `theta_i` seen at `theta_o`. The fiber medium's are
    /// read at θ_o, i.e. for the reciprocal path (light from ω_o, seen from ω_i): they then do
    /// not vary with θ_i, so each term is a normalised density over ω_i and its integral over
    /// the light's directions is exactly its tabulated energy. Read at θ_i instead, the
    /// back-scattering lobe's centre moves with θ_i (its mean θ_h grows with the light's
    /// inclination) and the density over ω_i integrated to up to 1.5× its energy: a
    /// half-space of white fibers returned 1.36 of the light. The paper's forms keep θ_i.
    pub(crate) fn shape_theta(&self, theta_i: f32, theta_o: f32) -> f32 {
        match self.tables.multiple_scattering() {
            MultipleScattering::Paper => theta_i,
            MultipleScattering::FiberMedium => theta_o,
        }
    }

    /// Whether [`Self::eval_layered`] uses the depth of hair behind the shading point.
    pub fn uses_depth_behind(&self) -> bool {
        self.tables.medium.is_some()
    }

    /// F(wo, wi) for light from local direction `wi` (ω_d) seen from `wo`, at offset `h`, where
    /// the light crossed `n` fibers and reaches the point unscattered with fraction
    /// `direct_fraction` ∈ [0, 1] (1: unoccluded shadow ray):
    ///
    /// `F = direct·(f_s + d_b f_back_direct cos θ_i)
    ///    + max(T_f − direct, 0)·d_f·(f_s_scatter + d_b f_back_scatter)·cos θ_i`.
    ///
    /// `f_s = bcsdf.eval(wo, wi, h)` (cos θ_i included, tress's convention), so
    /// `L_o = ∫ L(ω_d) F dω_d`. d_f appears both inside T_f and as the factor of the scattered
    /// term, as in the paper's pseudo-code. The clamp at 0 is ours: with
    /// n = 0 the paper's T_f = d_f < 1 = direct would make the scattered term negative; with it
    /// F at n = 0, direct = 1 is exactly `f_s + d_b f_back_direct cos θ_i` (maths:
    /// dual-scattering limits).
    ///
    /// **Normalisation.** The paper's constants (`2Ā_b g/(π cos²θ_d)` for f_back, `π` before
    /// f_back_scatter, Gaussians of unit area in θ_h) were written for Marschner's lobes, which
    /// return about twice the incident energy (maths: Marschner's energy). Taken literally
    /// with tress's energy-conserving models, F returns ≈3× the light a white fiber receives
    /// (measured: ∫F dω_d = 2.98 for a white Chiang fiber at n = 0). Here every term is a
    /// proper density carrying the energy the paper assigns it: the longitudinal Gaussian in
    /// θ_h becomes a truncated Gaussian in sin θ_i with the same centre and width (Zinke's
    /// `1/cos²θ_d` times tress's cos θ_i only normalises on the specular cone, and loses up to
    /// a third of a broad lobe's energy away from it; a density in θ_i would need a 1/cos θ_i
    /// factor that gives every estimator infinite variance), and f_back is confined to the backward half-space
    /// (`wi.z > 0`, the light's side) with azimuthal density 1/π. So
    /// `∫ d_b f_back_direct cos θ_i dω = d_b Ā_b` and `∫ f_s_scatter cos θ_i dω = ā_f`
    /// (N^G = a_f^t/2π over the whole circle).
    ///
    /// **Fiber medium.** With [`MultipleScattering::FiberMedium`] tables the closed forms give
    /// way to the measured light ([`crate::fiber_medium`]):
    /// `F = direct·(f_s + d_b f_back) + (1 − direct)·T_f·(f_s_scatter + d_b f_back_scatter)`,
    /// with T_f the layer's scattered transmittance given a blocked shadow ray
    /// ([`Self::forward`]) and f_back the measured back-scattering of the `behind` fibers. Two
    /// things differ from the paper's terms, both so that no term returns more than its energy
    /// (a white furnace): the lobes' shapes are read at θ_o, for the reciprocal path, so each
    /// is a normalised density over ω_d; and f_s_scatter's azimuthal factor is
    /// [`DualScatteringTables::scattered_azimuthal`], the response at ω_o's azimuth to light
    /// spread over the half-circle around ω_d, instead of the paper's constant N^G (the
    /// forward half's energy at every azimuth). Measured, white Chiang fibers (β = 0.3) in a
    /// furnace, path tracer 1.00: a slab 85 fibers deep seen from above returned 1.12 before
    /// and 0.83 after, the hair ball of the tests 1.19 and 0.92.
    pub fn eval(&self, wo: Vec3, wi: Vec3, h: f32, n: f32, direct_fraction: f32) -> Rgb {
        self.eval_layered(wo, wi, h, n, f32::INFINITY, direct_fraction)
    }

    /// [`Self::eval`] where `behind` fibers (expected) lie behind the shading point, away from
    /// the light: the depth of hair that can return light to it (the fiber medium's local term;
    /// the paper's ignores it).
    pub fn eval_layered(
        &self,
        wo: Vec3,
        wi: Vec3,
        h: f32,
        n: f32,
        behind: f32,
        direct_fraction: f32,
    ) -> Rgb {
        let direct = if direct_fraction.is_nan() {
            0.0
        } else {
            direct_fraction.clamp(0.0, 1.0)
        };
        let DensityFactors { d_f, d_b } = self.factors;
        let theta_i = safe_asin(wi.x);
        let theta_o = safe_asin(wo.x);
        let medium = self.tables.multiple_scattering() == MultipleScattering::FiberMedium;
        let shape_theta = self.shape_theta(theta_i, theta_o);
        let b = self.tables.back_scattering(shape_theta, d_b, behind);
        let backward = wi.z > 0.0;
        // Longitudinal density in sin θ_i of a Gaussian in θ_h (see `longitudinal_density`).
        let lobe = |mean: Rgb, var: Rgb| longitudinal_density(wi.x, theta_o, mean, var);
        let back = |extra_var: Rgb| {
            if backward {
                b.energy * lobe(b.mean, b.variance + extra_var) / PI
            } else {
                Rgb::ZERO
            }
        };

        let mut f = Rgb::ZERO;
        if direct > 0.0 {
            f += direct * (self.bcsdf.eval(wo, wi, h) + d_b * back(Rgb::ZERO));
        }
        let fwd = self.forward(wi, n);
        let w_scatter = match self.tables.multiple_scattering() {
            // The paper's d_f stands both in T_f and before the scattered term.
            MultipleScattering::Paper => (fwd.t_f - Rgb::splat(direct)).max(Rgb::ZERO) * d_f,
            MultipleScattering::FiberMedium => fwd.t_f * (1.0 - direct),
        };
        if w_scatter.max_element() > 0.0 {
            let delta = relative_azimuth(wo, wi);
            let mut f_s_scatter = Rgb::ZERO;
            for t in 0..self.tables.lobe_names().len() {
                let l = self.tables.lobe(shape_theta, t);
                let n_g = if medium {
                    self.tables.scattered_azimuthal(shape_theta, t, delta)
                } else {
                    l.n_g()
                };
                f_s_scatter += lobe(l.alpha, l.beta2 + fwd.sigma2_f) * n_g;
            }
            f += w_scatter * (f_s_scatter + d_b * back(fwd.sigma2_f));
        }
        f
    }
}

/// Azimuth between `a` and `b` about the fiber (the local x axis), in [0, π]; π/2 where
/// either runs along the fiber and has no azimuth.
fn relative_azimuth(a: Vec3, b: Vec3) -> f32 {
    let (pa, pb) = (Vec2::new(a.y, a.z), Vec2::new(b.y, b.z));
    let norms = (pa.length_squared() * pb.length_squared()).sqrt();
    // Also catches NaN.
    if norms.is_nan() || norms <= 1e-12 {
        return 0.5 * PI;
    }
    (pa.dot(pb) / norms).clamp(-1.0, 1.0).acos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pigment::Pigment;
    use crate::{chiang, deon, lambertian_fiber, HairModel};
    use tress_core::rng::Sampler;

    /// Coarse but complete tables, for the range checks.
    fn coarse() -> DualScatteringSettings {
        DualScatteringSettings {
            theta_nodes: 12,
            h_nodes: 12,
            theta_quad: 48,
            phi_quad: 64,
            walks: 1024,
            ..Default::default()
        }
    }

    fn tables(b: &dyn Bcsdf, s: &DualScatteringSettings) -> Arc<DualScatteringTables> {
        crate::test_util::shared_tables(b, s)
    }

    fn all_models() -> Vec<(String, Arc<dyn Bcsdf>, bool)> {
        HairModel::test_instances()
            .into_iter()
            .map(|t| {
                (
                    t.name,
                    t.params.build(crate::test_util::shared_prep()).unwrap(),
                    t.white_furnace,
                )
            })
            .collect()
    }

    fn model(name: &str) -> Arc<dyn Bcsdf> {
        let inst = HairModel::test_instances()
            .into_iter()
            .find(|t| t.name == name)
            .unwrap_or_else(|| panic!("no test instance {name}"));
        inst.params.build(crate::test_util::shared_prep()).unwrap()
    }

    fn lambertian(albedo: (f32, f32, f32)) -> Arc<dyn Bcsdf> {
        Arc::new(
            lambertian_fiber::LambertianFiber::new(&lambertian_fiber::Params { albedo }).unwrap(),
        )
    }

    fn chiang_with(sigma_a: f32) -> Arc<dyn Bcsdf> {
        Arc::new(
            chiang::Chiang::new(&chiang::Params {
                pigment: Pigment::SigmaA((sigma_a, sigma_a, sigma_a)),
                ..Default::default()
            })
            .unwrap(),
        )
    }

    fn channels(v: Rgb) -> [f32; 3] {
        v.to_array()
    }

    fn random_pair(rng: &mut Sampler) -> (Vec3, Vec3, f32) {
        let u = rng.next_4d();
        (
            sample_uniform_sphere(Vec2::new(u[0], u[1])),
            sample_uniform_sphere(Vec2::new(u[2], u[3])),
            2.0 * rng.next_1d() - 1.0,
        )
    }

    /// White fibers filling the half-space below a fiber seen from above, in a white furnace:
    /// every direction of the upper half reaches the fiber directly, the lower half is hair
    /// (n, behind → ∞). ∫ F dω_d is what the fiber returns; the exact answer is 1 and dual
    /// scattering must not exceed it. (With the lobes read at θ_i it returned 1.36 at θ_o = 0.)
    #[test]
    fn a_white_half_space_returns_at_most_the_furnace() {
        let shading = DualScatteringShading::new(
            chiang_with(0.0),
            tables(chiang_with(0.0).as_ref(), &coarse()),
            DensityFactors { d_f: 1.0, d_b: 1.0 },
        )
        .unwrap();
        let (ns, nphi) = (160, 160);
        for theta_o in [0.0f32, 0.5, 1.0] {
            let wo = Vec3::new(theta_o.sin(), 0.0, theta_o.cos());
            let mut total = 0.0f64;
            for i in 0..ns {
                for j in 0..nphi {
                    let s = -1.0 + 2.0 * (i as f32 + 0.5) / ns as f32;
                    let phi = -PI + 2.0 * PI * (j as f32 + 0.5) / nphi as f32;
                    let c = (1.0 - s * s).sqrt();
                    let wi = Vec3::new(s, c * phi.cos(), c * phi.sin());
                    let (n, direct) = if wi.z > 0.0 { (0.0, 1.0) } else { (1e4, 0.0) };
                    let f: f64 = [-0.75f32, -0.25, 0.25, 0.75]
                        .iter()
                        .map(|&h| f64::from(shading.eval_layered(wo, wi, h, n, 1e4, direct).x))
                        .sum::<f64>()
                        / 4.0;
                    total += f * (2.0 / ns as f64) * (2.0 * std::f64::consts::PI / nphi as f64);
                }
            }
            eprintln!("θ_o {theta_o}: ∫F = {total:.4}");
            assert!(
                total > 0.85 && total <= 1.0,
                "θ_o {theta_o}: a white half-space returns {total}"
            );
        }
    }

    /// The tables' batched evaluation gives exactly `eval_lobe`, bit for bit, for every model
    /// (the models that override it share per-`(wo, h)` work; nothing may change a value).
    #[test]
    fn batched_lobe_evaluation_is_eval_lobe_bit_for_bit() {
        let mut rng = Sampler::from_seed(5);
        for (name, b, _) in all_models() {
            let lobes = b.lobe_names().len();
            for _ in 0..20 {
                let (wo, _, h) = random_pair(&mut rng);
                let wis: Vec<Vec3> = (0..17).map(|_| random_pair(&mut rng).1).collect();
                let mut out = vec![Rgb::splat(f32::NAN); wis.len() * lobes];
                b.eval_lobes_batch(wo, h, &wis, &mut out);
                for (i, &wi) in wis.iter().enumerate() {
                    for p in 0..lobes {
                        let want = b.eval_lobe(wo, wi, h, p).to_array().map(f32::to_bits);
                        let got = out[i * lobes + p].to_array().map(f32::to_bits);
                        assert_eq!(got, want, "{name}: lobe {p}, wo {wo}, wi {wi}, h {h}");
                    }
                }
            }
        }
    }

    #[test]
    fn gauss_legendre_is_exact_to_degree_2n_minus_1() {
        for n in [1, 2, 5, 12, 32] {
            let q = gauss_legendre(n);
            for deg in 0..2 * n {
                let exact = if deg % 2 == 1 {
                    0.0
                } else {
                    2.0 / (deg as f64 + 1.0)
                };
                let got: f64 = q.iter().map(|&(x, w)| w * x.powi(deg as i32)).sum();
                assert!(
                    (got - exact).abs() < 1e-12,
                    "n {n} degree {deg}: {got} vs {exact}"
                );
            }
        }
    }

    #[test]
    fn slow_tables_are_refused_unless_the_limits_allow_them() {
        let slow = DualScatteringSettings {
            theta_nodes: 4096,
            ..Default::default()
        };
        let e = slow.validate(&Limits::default()).unwrap_err();
        assert_eq!(e.field, "tables");
        assert!(e.reason.contains(ALLOW_SLOW_TABLES_VAR), "{e}");
        let allowed = Limits {
            slow_tables: true,
            ..Limits::default()
        };
        slow.validate(&allowed).unwrap();
        DualScatteringSettings::default()
            .validate(&Limits::default())
            .unwrap();
    }

    #[test]
    fn invalid_settings_are_rejected_with_the_field_name() {
        let b = lambertian((1.0, 1.0, 1.0));
        for (s, field) in [
            (
                DualScatteringSettings {
                    phi_quad: 33,
                    ..coarse()
                },
                "phi_quad",
            ),
            (
                DualScatteringSettings {
                    theta_nodes: 1,
                    ..coarse()
                },
                "theta_nodes",
            ),
            (
                DualScatteringSettings {
                    h_nodes: 0,
                    ..coarse()
                },
                "h_nodes",
            ),
            (
                DualScatteringSettings {
                    theta_quad: 100_000,
                    ..coarse()
                },
                "theta_quad",
            ),
        ] {
            match DualScatteringTables::new(b.as_ref(), &s, &Limits::default()) {
                Err(DualScatteringError::Param(e)) => assert_eq!(e.field, field),
                other => panic!("{field}: expected a parameter error, got {other:?}"),
            }
        }
        let t = tables(b.as_ref(), &coarse());
        let bad = DensityFactors { d_f: 1.5, d_b: 0.7 };
        assert_eq!(
            DualScatteringShading::new(b, t, bad).unwrap_err().field,
            "d_f"
        );
    }

    /// A Lambertian fiber scatters uniformly in azimuth with a cos θ profile: ā_f = ā_b = ½·albedo,
    /// α = θ/2 (θ_h of a θ_i symmetric about 0), β² = var(θ_i)/4 = π²/48 − 1/8, and eqs. 14, 16,
    /// 17 evaluated by hand.
    #[test]
    fn lambertian_fiber_matches_the_analytic_oracle() {
        let t = tables(lambertian((1.0, 1.0, 1.0)).as_ref(), &coarse());
        let beta2 = PI * PI / 48.0 - 0.125;
        let big_a_b = 0.5 * 0.25 / 0.75 + 0.125 * 0.25 / (0.75f32 * 0.75 * 0.75);
        let delta_factor = (1.0 - 2.0 * 0.25 / 0.5625) + (2.0 * 0.5625 + 4.0 * 0.0625) / 0.421875;
        let sigma_b0 = ((3.0 * beta2).sqrt() + 0.25 * (5.0 * beta2).sqrt()) / 1.25;
        let thetas: Vec<f32> = t.node_thetas().collect();
        for th in thetas {
            let g = t.globals(th);
            let close = |what: &str, got: Rgb, want: f32, tol: f32| {
                for c in channels(got) {
                    assert!((c - want).abs() <= tol, "θ {th}: {what} {c} vs {want}");
                }
            };
            close("ā_f", g.a_f, 0.5, 1e-6);
            close("ā_b", g.a_b, 0.5, 1e-6);
            close("ᾱ_f", g.alpha_f, th / 2.0, 1e-5);
            close("ᾱ_b", g.alpha_b, th / 2.0, 1e-5);
            close("β̄_f²", g.beta2_f, beta2, 1e-5);
            close("β̄_b²", g.beta2_b, beta2, 1e-5);
            close("Ā_b", g.big_a_b, big_a_b, 1e-5);
            close("Δ_b", g.delta_b, delta_factor * th / 2.0, 1e-4);
            close("σ_b0", g.sigma_b0, sigma_b0, 1e-5);
            close("N^G", t.lobe(th, 0).n_g(), 0.5 / (2.0 * PI), 1e-6);
        }
        // A coloured fiber splits each channel's albedo in half.
        let brown = tables(lambertian((0.5, 0.3, 0.1)).as_ref(), &coarse());
        let g = brown.globals(0.3);
        assert!((g.a_f - Rgb::new(0.25, 0.15, 0.05)).abs().max_element() < 1e-6);
        assert!((g.a_b - g.a_f).abs().max_element() < 1e-6);
    }

    #[test]
    fn lookups_interpolate_linearly_and_clamp_at_the_ends() {
        let t = tables(model("Chiang/brown").as_ref(), &coarse());
        let nodes: Vec<f32> = t.node_thetas().collect();
        for (k, &th) in nodes.iter().enumerate() {
            let d = t.globals(th).a_f - t.globals[k].a_f;
            assert!(d.abs().max_element() < 1e-6, "node {k}: {d}");
        }
        let mid = 0.5 * (nodes[3] + nodes[4]);
        let want = 0.5 * (t.globals[3].big_a_b + t.globals[4].big_a_b);
        assert!((t.globals(mid).big_a_b - want).abs().max_element() < 1e-6);
        assert_eq!(t.globals(-1.6), t.globals[0]);
        assert_eq!(t.globals(1.6), *t.globals.last().unwrap());
        assert_eq!(t.globals(f32::NAN), t.globals[0]);
        assert_eq!(t.lobe(0.1, 99), DsLobe::default());
    }

    /// The ranges of the maths' sanity checks on every registered model (coarse tables).
    #[test]
    fn tables_lie_in_the_sanity_ranges_for_every_model() {
        for (name, b, _) in all_models() {
            let t = tables(b.as_ref(), &coarse());
            let nl = t.lobe_names().len();
            for th in t.node_thetas().collect::<Vec<_>>() {
                let g = t.globals(th);
                let lobes: Vec<DsLobe> = (0..nl).map(|l| t.lobe(th, l)).collect();
                let ctx = format!("{name} θ {th:.3}");
                for c in 0..3 {
                    let (af, ab) = (g.a_f[c], g.a_b[c]);
                    assert!(af >= 0.0 && ab >= 0.0, "{ctx}: ā_f {af}, ā_b {ab}");
                    let (afe, abe) = (g.a_f_eff[c], g.a_b_eff[c]);
                    assert!(
                        afe <= A_F_MAX && afe + abe <= 1.0 + 1e-6,
                        "{ctx}: effective {afe} {abe}"
                    );
                    assert!(
                        g.big_a_b[c] >= 0.0 && g.big_a_b[c].is_finite(),
                        "{ctx}: Ā_b {}",
                        g.big_a_b[c]
                    );
                    assert!(g.delta_b[c].is_finite(), "{ctx}: Δ_b");
                    assert!(
                        g.sigma_b2(0.7)[c] > 0.0,
                        "{ctx}: σ_b² {}",
                        g.sigma_b2(0.7)[c]
                    );
                    // Eq. 17 as read here: σ_b0 lies between the two back-scattering paths' spreads.
                    let s1 = (2.0 * g.beta2_f[c] + g.beta2_b[c]).sqrt();
                    let s3 = (2.0 * g.beta2_f[c] + 3.0 * g.beta2_b[c]).sqrt();
                    assert!(
                        g.sigma_b0[c] >= s1 * (1.0 - 1e-5) && g.sigma_b0[c] <= s3 * (1.0 + 1e-5),
                        "{ctx}: σ_b0"
                    );
                    // Lobe-weighted means and variances lie within the lobes' range.
                    for (half, mean, var, energy) in [
                        (
                            "f",
                            g.alpha_f[c],
                            g.beta2_f[c],
                            lobes.iter().map(|l| l.a_f[c]).collect::<Vec<_>>(),
                        ),
                        (
                            "b",
                            g.alpha_b[c],
                            g.beta2_b[c],
                            lobes.iter().map(|l| l.a_b[c]).collect::<Vec<_>>(),
                        ),
                    ] {
                        let used: Vec<&DsLobe> = lobes
                            .iter()
                            .zip(&energy)
                            .filter(|(_, &e)| e > 0.0)
                            .map(|(l, _)| l)
                            .collect();
                        assert!(!used.is_empty(), "{ctx}: no lobe scatters into half {half}");
                        let (lo, hi) = used.iter().fold((f32::MAX, f32::MIN), |(lo, hi), l| {
                            (lo.min(l.alpha[c]), hi.max(l.alpha[c]))
                        });
                        assert!(
                            mean >= lo - 1e-5 && mean <= hi + 1e-5,
                            "{ctx}: ᾱ_{half} {mean} ∉ [{lo}, {hi}]"
                        );
                        let (lo, hi) = used.iter().fold((f32::MAX, f32::MIN), |(lo, hi), l| {
                            (lo.min(l.beta2[c]), hi.max(l.beta2[c]))
                        });
                        assert!(
                            var >= lo - 1e-6 && var <= hi + 1e-6,
                            "{ctx}: β̄²_{half} {var} ∉ [{lo}, {hi}]"
                        );
                        assert!(var > 0.0, "{ctx}: β̄²_{half} = {var}");
                    }
                    for (l, lobe) in lobes.iter().enumerate() {
                        if lobe.a_f[c] + lobe.a_b[c] > 1e-6 {
                            assert!(lobe.beta2[c] > 0.0, "{ctx}: lobe {l} β² {}", lobe.beta2[c]);
                        }
                    }
                }
            }
        }
    }

    /// White energy-conserving fibers: the quadrature must put all the energy somewhere.
    #[test]
    fn white_fibers_scatter_all_energy() {
        // ā_f and ā_b come from the quadrature alone: the fiber medium's random walks, which
        // white fibers make long, would not change them.
        let s = DualScatteringSettings {
            theta_nodes: 4,
            multiple_scattering: MultipleScattering::Paper,
            ..Default::default()
        };
        let mut checked = 0;
        for (name, b, white) in all_models() {
            if !white {
                continue;
            }
            checked += 1;
            let t = tables(b.as_ref(), &s);
            for g in &t.globals {
                let total = g.a_f + g.a_b;
                assert!(
                    (total - Rgb::ONE).abs().max_element() < 0.01,
                    "{name}: ā_f + ā_b = {total}"
                );
            }
        }
        assert!(checked >= 3, "only {checked} white test instances");
    }

    /// Monte Carlo estimates of (ā_f, ā_b) at inclination θ with their standard errors:
    /// h uniform, ω uniform on the sphere, estimator eval·4π split by the half-space.
    fn monte_carlo(b: &dyn Bcsdf, theta: f32, samples: usize, seed: u64) -> [(Rgb, Rgb); 2] {
        let mut rng = Sampler::from_seed(seed);
        let w_fix = Vec3::new(theta.sin(), 0.0, theta.cos());
        let mut sum = [DVec3::ZERO; 2];
        let mut sum2 = [DVec3::ZERO; 2];
        for _ in 0..samples {
            let wi = sample_uniform_sphere(rng.next_2d());
            let h = 2.0 * rng.next_1d() - 1.0;
            let x = b.eval(w_fix, wi, h).as_dvec3() * (4.0 * PI64);
            let half = if wi.z < 0.0 { 0 } else { 1 };
            sum[half] += x;
            sum2[half] += x * x;
        }
        let n = samples as f64;
        [0, 1].map(|k| {
            let mean = sum[k] / n;
            let var = (sum2[k] / n - mean * mean) / (n - 1.0);
            (mean.as_vec3(), var.map(f64::sqrt).as_vec3())
        })
    }

    #[test]
    fn fractions_match_brute_force_monte_carlo() {
        let s = DualScatteringSettings {
            theta_nodes: 8,
            ..Default::default()
        };
        for name in [
            "Chiang/brown",
            "Chiang/blond",
            "DEon/blond",
            "Marschner/brown",
        ] {
            let b = model(name);
            let t = tables(b.as_ref(), &s);
            let nodes: Vec<f32> = t.node_thetas().collect();
            for (i, th) in [nodes[1], nodes[4], nodes[6]].into_iter().enumerate() {
                let g = t.globals(th);
                let mc = monte_carlo(b.as_ref(), th, 1 << 18, 17 + i as u64);
                for ((what, quad), (mean, se)) in
                    [("ā_f", g.a_f), ("ā_b", g.a_b)].into_iter().zip(mc)
                {
                    // 4.5 standard errors (72 comparisons at α = 0.01, Šidák) plus the
                    // quadrature's own error, ≤ 1e-3 against a 4× finer quadrature.
                    let tol = 4.5 * se + Rgb::splat(1e-3);
                    assert!(
                        (quad - mean).abs().cmple(tol).all(),
                        "{name} θ {th:.3}: {what} quadrature {quad} vs Monte Carlo {mean} ± {se}"
                    );
                }
            }
        }
    }

    /// The transmission lobe must land in the forward half-space (φ_i ≈ φ_o + π = −π/2).
    #[test]
    fn tt_lobe_lands_in_the_forward_half() {
        let mut checked = 0;
        for (name, b, _) in all_models() {
            let Some(tt) = b.lobe_names().iter().position(|&n| n == "TT") else {
                continue;
            };
            let r = b.lobe_names().iter().position(|&n| n == "R");
            let t = tables(b.as_ref(), &coarse());
            for th in t
                .node_thetas()
                .filter(|th| th.abs() < 1.0)
                .collect::<Vec<_>>()
            {
                let l = t.lobe(th, tt);
                let share = l.a_f / (l.a_f + l.a_b);
                assert!(
                    share.min_element() > 0.6,
                    "{name} θ {th:.3}: TT forward share {share}"
                );
                if let Some(r) = r {
                    let l = t.lobe(th, r);
                    let r_share = l.a_f / (l.a_f + l.a_b);
                    assert!(
                        share.cmpgt(r_share).all(),
                        "{name} θ {th:.3}: TT {share} vs R {r_share}"
                    );
                }
            }
            checked += 1;
        }
        assert!(checked > 0, "no registered model has a TT lobe");
    }

    #[test]
    fn blond_fibers_scatter_mostly_forward() {
        let mut checked = 0;
        for (name, b, _) in all_models() {
            if !name.ends_with("/blond") {
                continue;
            }
            checked += 1;
            let t = tables(b.as_ref(), &coarse());
            for th in [-0.5f32, 0.0, 0.5] {
                let g = t.globals(th);
                assert!(
                    g.a_f.cmpgt(4.0 * g.a_b).all(),
                    "{name} θ {th}: ā_f {} ā_b {}",
                    g.a_f,
                    g.a_b
                );
            }
            // ā_b rises toward grazing inclinations (maths: sanity checks on the tables).
            assert!(t.globals(1.3).a_b.cmpgt(t.globals(0.0).a_b).all(), "{name}");
        }
        assert!(checked >= 2, "only {checked} blond test instances");
    }

    /// Maths, dual-scattering limits:
    /// opaque fibers only reflect (Fresnel), so ā_f is the R lobe's forward part and the
    /// multiple back-scattering vanishes.
    #[test]
    fn opaque_fibers_have_no_transmission_and_no_multiple_back_scattering() {
        let b = chiang_with(100.0);
        let t = tables(b.as_ref(), &coarse());
        let r = b.lobe_names().iter().position(|&n| n == "R").unwrap();
        for th in t.node_thetas().collect::<Vec<_>>() {
            let g = t.globals(th);
            assert!(
                (g.a_f - t.lobe(th, r).a_f).abs().max_element() < 1e-6,
                "θ {th}: {}",
                g.a_f
            );
            for l in (0..b.lobe_names().len()).filter(|&l| l != r) {
                let e = t.lobe(th, l).a_f + t.lobe(th, l).a_b;
                assert!(e.max_element() < 1e-6, "θ {th}: lobe {l} carries {e}");
            }
            // Away from grazing, Fresnel reflection is weak: ā_f small, Ā_b ≈ 0.
            if th.abs() < 1.0 {
                assert!(g.a_f.max_element() < 0.1, "θ {th}: ā_f {}", g.a_f);
                assert!(g.big_a_b.max_element() < 1e-3, "θ {th}: Ā_b {}", g.big_a_b);
            }
        }
        // The same fiber, transparent: transmission dominates and Ā_b is substantial.
        let clear = tables(chiang_with(0.0).as_ref(), &coarse());
        let g = clear.globals(0.0);
        assert!(
            g.a_f.min_element() > 0.6 && g.big_a_b.min_element() > 0.1,
            "{g:?}"
        );
    }

    fn shading_with(
        model: MultipleScattering,
        b: Arc<dyn Bcsdf>,
        factors: DensityFactors,
    ) -> DualScatteringShading {
        let settings = DualScatteringSettings {
            multiple_scattering: model,
            ..coarse()
        };
        let t = tables(b.as_ref(), &settings);
        DualScatteringShading::new(b, t, factors).unwrap()
    }

    /// The paper's closed forms, whose formulas several tests write out independently.
    fn shading(b: Arc<dyn Bcsdf>, factors: DensityFactors) -> DualScatteringShading {
        shading_with(MultipleScattering::Paper, b, factors)
    }

    /// Maths, dual-scattering limits:
    /// with no fibers in the way and the light fully visible, F is the single-fiber BCSDF
    /// plus the local back-scattering term, exactly.
    #[test]
    fn with_no_fibers_crossed_f_is_single_scattering_plus_local_back_scattering() {
        let mut rng = Sampler::from_seed(3);
        for name in [
            "Chiang/brown",
            "Marschner/blond",
            "DEon/blond",
            "LambertianFiber/brown",
        ] {
            let b = model(name);
            let ds = shading(b.clone(), DensityFactors::default());
            let no_back = shading(b.clone(), DensityFactors { d_f: 0.7, d_b: 0.0 });
            for _ in 0..200 {
                let (wo, wi, h) = random_pair(&mut rng);
                let fs = b.eval(wo, wi, h);
                assert_eq!(no_back.eval(wo, wi, h, 0.0, 1.0), fs, "{name}");
                // f_back_direct from the tables, written out independently of `eval`.
                let (ti, to) = (wi.x.asin(), wo.x.asin());
                let g = ds.tables().globals(ti);
                let v = g.sigma_b2(0.7);
                // Backward half-space only, longitudinal density in sin θ_i (see `eval`).
                let backward = if wi.z > 0.0 { 1.0 } else { 0.0 };
                let p_s = longitudinal_density(wi.x, to, g.delta_b, v);
                let f_back = backward * g.big_a_b * p_s / PI;
                let want = fs + 0.7 * f_back;
                let got = ds.eval(wo, wi, h, 0.0, 1.0);
                assert!(
                    (got - want)
                        .abs()
                        .cmple(1e-5 * want.abs() + Rgb::splat(1e-7))
                        .all(),
                    "{name}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn transmittance_decreases_and_spread_grows_linearly_with_fibers_crossed() {
        for (name, b, _) in all_models() {
            let ds = shading(b, DensityFactors::default());
            for wi in [
                Vec3::new(0.0, 0.6, 0.8),
                Vec3::new(0.7, 0.0, -0.714).normalize(),
            ] {
                let one = ds.forward(wi, 1.0);
                let mut prev = ds.forward(wi, 0.0);
                assert_eq!(prev.t_f, Rgb::splat(0.7), "{name}: T_f(0) = d_f");
                assert_eq!(prev.sigma2_f, Rgb::ZERO);
                for k in 1..=40 {
                    let n = 0.5 * k as f32;
                    let f = ds.forward(wi, n);
                    assert!(
                        f.t_f.cmplt(prev.t_f).all(),
                        "{name} n {n}: {} !< {}",
                        f.t_f,
                        prev.t_f
                    );
                    let lin = n * one.sigma2_f;
                    assert!(
                        (f.sigma2_f - lin).abs().cmple(1e-6 * lin).all(),
                        "{name} n {n}"
                    );
                    prev = f;
                }
            }
        }
    }

    /// Past the settled counts, F's forward light is negligible and its back-scattering a
    /// half-space's, for every model and light inclination; and for absorbing fibers the counts
    /// are short enough to spare the grid most of a ray through a groom.
    #[test]
    fn f_does_not_change_past_the_settled_counts() {
        let models = [MultipleScattering::Paper, MultipleScattering::FiberMedium];
        for ((name, b, _), model) in all_models()
            .into_iter()
            .flat_map(|m| models.map(|model| (m.clone(), model)))
        {
            let ds = shading_with(model, b, DensityFactors { d_f: 1.0, d_b: 1.0 });
            let settled = ds.tables().settled_counts();
            let blocked = -(-settled.toward_light).exp_m1();
            for k in 0..=16 {
                let theta = -0.5 * PI + PI * k as f32 / 16.0;
                let wi = Vec3::new(theta.sin(), 0.0, theta.cos());
                for scale in [1.0, 1.3, 2.0, 4.0, 64.0] {
                    let n = settled.toward_light * scale;
                    let t_f = ds.forward(wi, n).t_f.max_element();
                    assert!(
                        t_f <= NEGLIGIBLE_TRANSMITTANCE / blocked,
                        "{name} {model:?} θ {theta} n {n}: T_f {t_f}"
                    );
                }
                let half_space = ds
                    .tables()
                    .back_scattering(theta, 1.0, f32::INFINITY)
                    .energy;
                for scale in [1.0, 1.3, 2.0, 4.0, 64.0] {
                    let behind = settled.behind * scale;
                    let energy = ds.tables().back_scattering(theta, 1.0, behind).energy;
                    assert!(
                        (energy - half_space)
                            .abs()
                            .cmple(half_space * SETTLED_BACK_SCATTERING * 1.001)
                            .all(),
                        "{name} {model:?} θ {theta} behind {behind}: {energy} vs {half_space}"
                    );
                }
            }
        }
        let blond = shading_with(
            MultipleScattering::FiberMedium,
            model("Chiang/blond"),
            DensityFactors::default(),
        );
        let settled = blond.tables().settled_counts();
        assert!(
            settled.toward_light <= 128.0 && settled.behind <= 64.0,
            "{settled:?}"
        );
    }

    /// F is finite and non-negative for every model, with and without fibers in the way.
    #[test]
    fn shading_is_finite_and_non_negative_for_every_model() {
        let mut rng = Sampler::from_seed(11);
        let models = [MultipleScattering::Paper, MultipleScattering::FiberMedium];
        for ((name, b, _), model) in all_models()
            .into_iter()
            .flat_map(|m| models.map(|model| (m.clone(), model)))
        {
            let ds = shading_with(model, b, DensityFactors::for_model(model));
            for i in 0..300 {
                let (wo, wi, h) = random_pair(&mut rng);
                let n = (i % 7) as f32 * 1.5;
                let direct = if i % 3 == 0 { 1.0 } else { 0.0 };
                let f = ds.eval(wo, wi, h, n, direct);
                assert!(
                    f.is_finite() && f.min_element() >= 0.0,
                    "{name} ({model:?}) n {n}: F = {f}"
                );
            }
            // Along the fiber and with nonsense inputs.
            let f = ds.eval(Vec3::X, -Vec3::X, 1.0, f32::NAN, f32::NAN);
            assert!(
                f.is_finite() && f.min_element() >= 0.0,
                "{name} ({model:?}): F = {f}"
            );
        }
    }

    #[test]
    fn tables_are_shared_by_fingerprint_and_settings_by_value() {
        use tress_core::prepare::Preparation;
        type Key = (Vec<u32>, DualScatteringSettings);
        let prep = Preparation::new();
        let get = |b: &dyn Bcsdf, s: &DualScatteringSettings| {
            prep.get_or_build((fingerprint(b), s.clone()), || {
                DualScatteringTables::new(b, s, &Limits::default())
            })
            .unwrap()
        };
        let a = model("DEon/brown");
        let same = model("DEon/brown");
        let other = model("DEon/blond");
        let t1 = get(a.as_ref(), &coarse());
        let t2 = get(same.as_ref(), &coarse());
        assert!(Arc::ptr_eq(&t1, &t2));
        let t3 = get(other.as_ref(), &coarse());
        assert!(!Arc::ptr_eq(&t1, &t3));
        let finer = DualScatteringSettings {
            theta_nodes: 16,
            ..coarse()
        };
        get(a.as_ref(), &finer);
        assert_eq!(prep.count::<Key, DualScatteringTables>(), 3);
        // Models whose `Debug` text is the same but whose scattering differs get their own
        // tables (the key was the `Debug` text).
        let t4 = get(&Opaque(model("DEon/brown")), &coarse());
        let t5 = get(&Opaque(model("DEon/blond")), &coarse());
        assert!(!Arc::ptr_eq(&t4, &t5));
        // An opaque model is the same model: it shares the tables of its value.
        assert!(Arc::ptr_eq(&t1, &t4));
        assert_eq!(prep.count::<Key, DualScatteringTables>(), 3);
    }

    /// A model whose `Debug` says nothing of its parameters.
    struct Opaque(Arc<dyn Bcsdf>);

    impl std::fmt::Debug for Opaque {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("Opaque")
        }
    }

    impl Bcsdf for Opaque {
        fn eval(&self, wo: Vec3, wi: Vec3, h: f32) -> Rgb {
            self.0.eval(wo, wi, h)
        }
        fn sample(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<tress_core::BcsdfSample> {
            self.0.sample(wo, h, u)
        }
        fn pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> f32 {
            self.0.pdf(wo, wi, h)
        }
        fn lobe_names(&self) -> &'static [&'static str] {
            self.0.lobe_names()
        }
        fn eval_lobe(&self, wo: Vec3, wi: Vec3, h: f32, p: usize) -> Rgb {
            self.0.eval_lobe(wo, wi, h, p)
        }
    }

    /// A fiber that prefers one side: breaks the mirror symmetry h → −h, Δφ → −Δφ.
    #[derive(Debug)]
    struct Skewed(Arc<dyn Bcsdf>);

    impl Bcsdf for Skewed {
        fn eval(&self, wo: Vec3, wi: Vec3, h: f32) -> Rgb {
            self.0.eval(wo, wi, h) * (1.0 + 0.5 * h)
        }
        fn sample(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<tress_core::BcsdfSample> {
            self.0.sample(wo, h, u)
        }
        fn pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> f32 {
            self.0.pdf(wo, wi, h)
        }
    }

    #[test]
    fn h_symmetries_are_detected() {
        assert_eq!(h_domain(model("Chiang/brown").as_ref()), HDomain::Mirror);
        assert_eq!(
            h_domain(lambertian((0.5, 0.5, 0.5)).as_ref()),
            HDomain::Ignored
        );
        let d = deon::DEon::new(&deon::Params::default()).unwrap();
        assert_eq!(h_domain(&d), HDomain::Ignored, "d'Eon's model ignores h");
        assert_eq!(h_domain(&Skewed(model("Chiang/brown"))), HDomain::Full);
        assert_eq!(
            h_domain(&Skewed(lambertian((0.5, 0.5, 0.5)))),
            HDomain::Full
        );
    }

    /// Integrating h over [0, 1] under the mirror symmetry gives the tables of the full range,
    /// up to the two rules' quadrature error.
    #[test]
    fn mirror_symmetric_tables_equal_full_range_tables() {
        let b = model("Chiang/blond");
        let s = DualScatteringSettings {
            theta_nodes: 4,
            h_nodes: 48,
            ..coarse()
        };
        let mirror = DualScatteringTables::build(b.as_ref(), &s, HDomain::Mirror).unwrap();
        let full = DualScatteringTables::build(b.as_ref(), &s, HDomain::Full).unwrap();
        for (m, f) in mirror.globals.iter().zip(&full.globals) {
            for (what, x, y, tol) in [
                ("ā_f", m.a_f, f.a_f, 2e-4),
                ("ā_b", m.a_b, f.a_b, 2e-4),
                ("ᾱ_f", m.alpha_f, f.alpha_f, 5e-5),
                ("ᾱ_b", m.alpha_b, f.alpha_b, 5e-5),
                ("β̄²_f", m.beta2_f, f.beta2_f, 1e-5),
                ("β̄²_b", m.beta2_b, f.beta2_b, 1e-5),
            ] {
                assert!(
                    (x - y).abs().max_element() < tol,
                    "{what}: mirror {x} vs full {y}"
                );
            }
        }
    }

    /// Default-resolution tables for every model: build times and the figures of the report
    /// (run with `--ignored --nocapture`), and the white-furnace and range checks at full accuracy.
    #[test]
    #[ignore]
    fn default_tables_for_every_model() {
        for theta_nodes in [64, 128] {
            let s = DualScatteringSettings {
                theta_nodes,
                ..Default::default()
            };
            for (name, b, white) in all_models() {
                let t = DualScatteringTables::new(b.as_ref(), &s, &Limits::default()).unwrap();
                println!(
                    "{name:30} {theta_nodes:4} nodes: {:6.2} s",
                    t.build_time().as_secs_f64()
                );
                for th in [0.0f32, 0.6, 1.2] {
                    let g = t.globals(th);
                    println!(
                        "  θ {th:3.1}: ā_f {:.3?} ā_b {:.3?} ᾱ_f {:.3?} ᾱ_b {:.3?} β̄²_f {:.4?} β̄²_b {:.4?} Ā_b {:.3?} Δ_b {:.3?} σ_b² {:.4?}",
                        g.a_f.to_array(), g.a_b.to_array(), g.alpha_f.to_array(), g.alpha_b.to_array(),
                        g.beta2_f.to_array(), g.beta2_b.to_array(), g.big_a_b.to_array(),
                        g.delta_b.to_array(), g.sigma_b2(0.7).to_array()
                    );
                    if white {
                        assert!(
                            (g.a_f + g.a_b - Rgb::ONE).abs().max_element() < 0.005,
                            "{name}"
                        );
                    }
                    assert!(
                        g.big_a_b.is_finite() && g.sigma_b2(0.7).min_element() > 0.0,
                        "{name}"
                    );
                    if theta_nodes == 64 {
                        let ds = DualScatteringShading::new(
                            b.clone(),
                            Arc::new(t.clone()),
                            DensityFactors::default(),
                        )
                        .unwrap();
                        let wo = Vec3::new(th.sin(), 0.0, th.cos());
                        println!(
                            "        ∫F dω_d: n = 0, direct {:.3?}; scattered only, n = 1 {:.3?}, n = 4 {:.3?}",
                            returned_energy(&ds, wo, 0.0, 1.0),
                            returned_energy(&ds, wo, 1.0, 0.0),
                            returned_energy(&ds, wo, 4.0, 0.0)
                        );
                    }
                }
            }
        }
    }

    /// `∫ F(wo, ω_d) dω_d`, h averaged: the radiance F returns toward `wo` under a uniform
    /// environment of radiance 1 (midpoint rule, 128 × 256 directions, 8 Gauss–Legendre h).
    fn returned_energy(ds: &DualScatteringShading, wo: Vec3, n: f32, direct: f32) -> [f32; 3] {
        let (nt, np) = (128, 256);
        let cell = PI / nt as f32 * 2.0 * PI / np as f32;
        let mut sum = Rgb::ZERO;
        for (h, wh) in gauss_legendre(8) {
            for j in 0..nt {
                let t = -0.5 * PI + (j as f32 + 0.5) * PI / nt as f32;
                for k in 0..np {
                    let p = (k as f32 + 0.5) * 2.0 * PI / np as f32;
                    let wi = Vec3::new(t.sin(), t.cos() * p.cos(), t.cos() * p.sin());
                    sum +=
                        ds.eval(wo, wi, h as f32, n, direct) * (0.5 * wh as f32 * t.cos() * cell);
                }
            }
        }
        sum.to_array()
    }

    /// The normalisation of `eval`: with the light visible and no fibers crossed, a white
    /// fiber's F returns its albedo (1) plus d_b·Ā_b of local back-scattering; with all the light
    /// scattered (direct = 0), d_f·T_f·(ā_f + d_b Ā_b) — not the ≈3× of the literal constants.
    #[test]
    fn f_returns_the_energy_each_term_is_assigned() {
        let b = model("Chiang/white_default");
        let ds = shading(b.clone(), DensityFactors::default());
        let wo = Vec3::new(0.0, 0.0, 1.0);
        let theta_i = 0.0; // light on the specular cone of wo
        let g = ds.tables().globals(theta_i);
        let energy = |n: f32, direct: f32| {
            // ∫ F dω_d by midpoint quadrature over (sin θ, φ): dω = ds dφ.
            let (ns, np) = (400, 400);
            let mut sum = Rgb::ZERO;
            for i in 0..ns {
                let sn = -1.0 + (i as f32 + 0.5) * 2.0 / ns as f32;
                for j in 0..np {
                    let phi = (j as f32 + 0.5) * 2.0 * PI / np as f32;
                    let wi = tress_core::math::fiber_direction(sn, (1.0 - sn * sn).sqrt(), phi);
                    let hs = [-0.75f32, -0.25, 0.25, 0.75];
                    sum += hs
                        .iter()
                        .map(|&h| ds.eval(wo, wi, h, n, direct))
                        .sum::<Rgb>()
                        / hs.len() as f32;
                }
            }
            sum.x * (2.0 / ns as f32) * (2.0 * PI / np as f32)
        };
        let direct = energy(0.0, 1.0);
        let want_direct = 1.0 + 0.7 * g.big_a_b.x;
        assert!(
            (direct - want_direct).abs() < 0.03 * want_direct,
            "{direct} vs {want_direct}"
        );
        let n = 3.0;
        let scattered = energy(n, 0.0);
        let t_f = ds.forward(Vec3::new(0.0, 0.0, -1.0), n).t_f.x;
        let want = t_f * 0.7 * (g.a_f.x + 0.7 * g.big_a_b.x);
        assert!(
            (scattered - want).abs() < 0.05 * want,
            "{scattered} vs {want}"
        );
    }
}
