//! Animal fur with a medulla: the double-cylinder model of Yan, Tseng, Jensen & Ramamoorthi 2015,
//! "Physically-accurate fur reflectance: modeling, measurement and rendering" (ACM TOG 34(6)),
//! with the five named lobes of Yan, Sun, Jensen & Ramamoorthi 2017, "An efficient and practical
//! near and far field fur reflectance model" (ACM TOG 36(4)).
//!
//! A fur fiber is a cortex (radius 1, index η, pigment σ_c per unit radius, under a tilted rough
//! cuticle) around a concentric medulla (radius κ) that scatters: σ_s, σ_a per unit radius and a
//! Henyey–Greenstein phase function of asymmetry g. Cortex and medulla share η, so a ray crosses
//! the medulla's boundary unbent. Human hair is the limit κ → 0, where this is Chiang et al.'s
//! model ([`crate::chiang`]) term for term.
//!
//! `eval = Σ_{p<3} M_p A_p N_p + M_3 A_3 / (2π) + E_s · D(ω_i)`:
//! - **Unscattered lobes R, TT, TRT and the residual** (p ≥ 3) are Chiang's — vMF longitudinal
//!   `M_p`, trimmed-logistic `N_p` about `Φ(p, h)`, cuticle tilt — with the medulla in the
//!   attenuation: every internal chord (all have the same impact parameter `sin γ_t`) crosses
//!   the cortex for `ℓ_c` and the medulla for `ℓ_m = 2√(κ² − sin²γ_t) / cos θ_t` when
//!   `|sin γ_t| < κ`, so its transmittance is `T = T_c T_m`, `T_c = e^{−σ_c ℓ_c}`,
//!   `T_m = e^{−(σ_s + σ_a) ℓ_m}`, and `A_0 = f`, `A_1 = (1−f)² T`, `A_2 = A_1 T f`,
//!   `A_3 = A_2 f T/(1 − f T)` as in Chiang.
//! - **Scattered lobes TTs, TRTs** (light scattered in the medulla and leaving without, or
//!   after, an internal reflection at the cuticle). The energy first scattered is, summed over
//!   the chords, `S = (1−f) √T_c (1−T_m) (σ_s/σ_t) / (1 − f T)` (light reaches the medulla
//!   after half a chord's cortex). Of it a fraction `ρ(σ_c) = E[w e^{−σ_c L}]` leaves the
//!   fiber (w: what the medulla's absorption leaves of a photon; L: its path through the
//!   cortex), so `E_s = S ρ(σ_c)`; `D` is the distribution of its exit directions. ρ and D are
//!   what the model precomputes.
//!
//! Without absorption (σ_c = σ_a = 0), ρ = 1 and `Σ_p A_p + S = 1` exactly (each chord's light is
//! reflected, transmitted or scattered), so the model conserves energy exactly: white furnace 1
//! for every θ_o and h, like Chiang's.
//!
//! # The precomputed scattering profiles
//! Yan et al. 2015 precompute the medulla's scattering profiles (their C_N, C_M) by simulating
//! light in the fiber, and 2017 keeps them as tables. Here tress simulates the whole double
//! cylinder in 3D itself (`Table::build`), for the parameters that shape the scattered light
//! (η, κ, σ_s, σ_a, g; not the cortex pigment, roughness or tilt): photons start at their first
//! scattering in the medulla — placed along the refracted chord (the k-th chord with probability
//! ∝ (f T_m)^{k−1}, at a depth ∝ e^{−σ_t s}) of a ray arriving along −ω_o at offset h — and walk
//! (free paths e^{−σ_s s}, absorption as a weight e^{−σ_a s}, HG scattering, Fresnel reflection
//! or refraction at the cuticle) until they leave; their exit direction is ω_i (light paths are
//! reversible). Each of 8 θ_o × 9 medulla offsets `u = sin γ_t / κ` (θ_o ≥ 0, u ≥ 0; the others
//! by the fiber's mirror symmetries) keeps the TTs and TRTs histograms over 16 bins of sin θ_i ×
//! 32 of φ (equal solid angles) and ρ at 9 cortex absorptions 0, ⅛, …, 16 (ln ρ interpolated
//! linearly in σ_c between them); `eval` interpolates the nodes bilinearly, and
//! sampling draws a node by its weight, a cell by its probability and a point uniformly in the
//! cell, so `pdf` is exactly the sampling density. The tables are built on every core with
//! fixed seeds (bit-identical for any thread count), with a progress bar on a terminal.
//!
//! # Where the tables are kept
//! [`crate::HairModel::build`] hands the model the run's `tress_core::prepare::Preparation`
//! ([`Fur::prepared`]), which keeps each table under its key — η, κ, σ_s, σ_a, g bit for bit,
//! not the pigment, roughness or tilt — so the materials, pigment variants, objects and study
//! jobs of one run that share a medulla share one build. When the front end gives the run a
//! table folder (`tress … --table-cache DIR`, by default `$XDG_CACHE_HOME/tress` or
//! `~/.cache/tress`; the Python functions' `table_cache`), the table is also stored there
//! (`tress_core::stored_table`: `fur-medulla-v<VERSION>-<hash of the key>.table`, written
//! atomically, its key echoed whole with the table's resolution, photon count, σ_c grid and
//! seed, and a checksum) and later runs read it back bit for bit, noting `fur-medulla table
//! read from …`; a file that is truncated, corrupt, of another version or of another key is
//! ignored with a warning note and the table built again. [`Fur::new`] builds a model's table
//! alone. Changing what the simulation computes or how a table is encoded means bumping the
//! stored version (`Table::VERSION`); a test pins a table's bytes to catch a change that
//! forgets to.
//!
//! # Simplifications (against the papers)
//! - The cortex pigment changes how much scattered light leaves (ρ), not where it goes: D is
//!   the colourless one (TRTs, which crosses more cortex, is a little too strong in dark fur),
//!   and the pigment is left out of the first chord's choice in the simulation. The cuticle of the simulation is smooth; its roughness and tilt
//!   act on the unscattered lobes only (the scattered ones are broad).
//! - One table per parameter set instead of Yan's tables over σ_s and g: exact for the
//!   parameters used, at a precomputation per model built (a few seconds of CPU).
//! - Far field in h like Chiang (N_p per h); no near-field integration over the fiber's width.
//!
//! | parameter | default | meaning |
//! |---|---|---|
//! | `beta_m`, `beta_n`, `alpha`, `eta`, `pigment` | as [`crate::chiang`] | cuticle roughness, tilt (degrees), index, cortex pigment |
//! | `medulla_ratio` | 0.5 | medulla radius κ over the fiber's, in [0, 0.95] (0: human hair) |
//! | `medulla_sigma_s` | 4 | medulla scattering coefficient per unit fiber radius, in [0, 20] |
//! | `medulla_sigma_a` | 0 | medulla absorption coefficient per unit fiber radius, in [0, 20] |
//! | `medulla_g` | 0 | Henyey–Greenstein asymmetry of the medulla, in [−0.9, 0.9] |
//!
//! RON: `Fur(medulla_ratio: 0.6, medulla_sigma_s: 6, pigment: Melanin(eumelanin: 0.8))`

use crate::pigment::Pigment;
use crate::{check_range, parallel_map, ModelParams, ParamError, TestInstance};
use serde::{Deserialize, Serialize};
use std::convert::Infallible;
use std::f64::consts::PI as PI64;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use tress_core::math::{luminance, Rgb, Vec3};
use tress_core::prepare::Preparation;
use tress_core::rng::Pcg32;
use tress_core::stored_table::StoredTable;
use tress_core::{Bcsdf, BcsdfSample};

/// Smallest accepted β_m, β_n (as Chiang's).
pub const BETA_MIN: f32 = crate::chiang::BETA_MIN;

/// Parameters of [`Fur`].
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
#[schemars(rename = "FurParams")]
pub struct Params {
    /// Longitudinal roughness β_m of the cuticle, in [10⁻³, 1] (default 0.3).
    pub beta_m: f32,
    /// Azimuthal roughness β_n of the cuticle, in [10⁻³, 1] (default 0.3).
    pub beta_n: f32,
    /// Cuticle scale tilt in degrees, in [−90, 90] (default 2).
    pub alpha: f32,
    /// Index of refraction of cortex and medulla, in (1, 3] (default 1.55).
    pub eta: f32,
    /// Absorption of the cortex (default eumelanin 1.3).
    pub pigment: Pigment,
    /// Medulla radius over the fiber's, κ, in [0, 0.95]; 0 is a fiber without medulla (human
    /// hair, Chiang's model) (default 0.5).
    pub medulla_ratio: f32,
    /// Medulla scattering coefficient σ_s per unit fiber radius, in [0, 20] (default 4).
    pub medulla_sigma_s: f32,
    /// Medulla absorption coefficient σ_a per unit fiber radius, in [0, 20] (default 0).
    pub medulla_sigma_a: f32,
    /// Henyey–Greenstein asymmetry g of the medulla's scattering, in [−0.9, 0.9] (default 0).
    pub medulla_g: f32,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            beta_m: 0.3,
            beta_n: 0.3,
            alpha: 2.0,
            eta: 1.55,
            pigment: Pigment::default(),
            medulla_ratio: 0.5,
            medulla_sigma_s: 4.0,
            medulla_sigma_a: 0.0,
            medulla_g: 0.0,
        }
    }
}

impl ModelParams for Params {
    fn pigment(&self) -> Option<(&Pigment, f32)> {
        Some((&self.pigment, self.beta_n))
    }

    fn pigment_mut(&mut self) -> Option<&mut Pigment> {
        Some(&mut self.pigment)
    }

    /// Scales the cuticle's β_m and β_n, within `BETA_MIN..=1`.
    fn scale_roughness(&mut self, scale: f32) {
        self.beta_m = (self.beta_m * scale).clamp(BETA_MIN, 1.0);
        self.beta_n = (self.beta_n * scale).clamp(BETA_MIN, 1.0);
    }
}

/// Lobe indices: the unscattered R, TT, TRT, residual, then the scattered TTs, TRTs.
const RESIDUAL: usize = 3;
const SCATTERED: usize = 4;
const LOBE_NAMES: [&str; 6] = ["R", "TT", "TRT", "residual", "TTs", "TRTs"];

/// The fur BCSDF (module docs).
#[derive(Debug, Clone)]
pub struct Fur {
    eta: f64,
    sigma_c: [f64; 3],
    kappa: f64,
    sigma_s: f64,
    sigma_t: f64,
    /// Longitudinal variance of lobe p (R, TT, TRT, residual).
    v: [f64; 4],
    /// `−ln v − ln(1 − e^{−2/v})` of lobe p.
    ln_norm: [f64; 4],
    /// sin and cos of lobe p's rotation of θ_o by the cuticle tilt.
    tilt: [(f64, f64); 4],
    /// Logistic scale, its `CDF(−π)` and `CDF(π) − CDF(−π)`.
    s: f64,
    cdf_lo: f64,
    cdf_range: f64,
    /// The scattering profiles; `None` when the medulla cannot scatter (κ = 0 or σ_s = 0).
    table: Option<Arc<Table>>,
    /// Each table node's escaping fraction ρ(σ_c) for this cortex's σ_c, per channel: fixed
    /// per model, so `eval` only interpolates it.
    escape: Vec<[f64; 3]>,
}

/// Everything that depends on (wo, h) only.
struct Geometry {
    /// wo's direction in the normal plane, normalised, the reference of azimuths.
    normal_o: (f64, f64),
    /// sin θ_o' and |cos θ_o'| seen by each unscattered lobe (tilted).
    sin_o: [f64; 4],
    cos_o: [f64; 4],
    /// Exit azimuth Φ(p, h) of R, TT, TRT.
    phi_exit: [f64; 3],
    /// Energy of each lobe group: A_0..A_3, then E_s (both scattered lobes), per channel.
    energy: [Rgb; 5],
    /// Probability of sampling each of the five.
    lobe_pdf: [f64; 5],
    /// The table nodes and their weights, with the mirror flags (module docs).
    nodes: Nodes,
}

impl Fur {
    /// Validates `p`, then builds the medulla's scattering profiles, for this model alone
    /// ([`Fur::prepared`] shares them through a run).
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        Self::prepared(p, &Preparation::new())
    }

    /// Validates `p`, then takes the medulla's scattering profiles from the run's `prep`: built
    /// once per [`TableKey`] in a run, and read from (or stored in) its table folder if it has
    /// one (module docs).
    pub fn prepared(p: &Params, prep: &Preparation) -> Result<Self, ParamError> {
        check_range("beta_m", p.beta_m, BETA_MIN, 1.0)?;
        check_range("beta_n", p.beta_n, BETA_MIN, 1.0)?;
        check_range("alpha", p.alpha, -90.0, 90.0)?;
        if !(p.eta.is_finite() && p.eta > 1.0 && p.eta <= 3.0) {
            return Err(ParamError::new("eta", p.eta, "must lie in (1, 3]"));
        }
        check_range("medulla_ratio", p.medulla_ratio, 0.0, 0.95)?;
        check_range("medulla_sigma_s", p.medulla_sigma_s, 0.0, 20.0)?;
        check_range("medulla_sigma_a", p.medulla_sigma_a, 0.0, 20.0)?;
        check_range("medulla_g", p.medulla_g, -0.9, 0.9)?;
        let sigma_c = p.pigment.sigma_a(p.beta_n)?;

        let bm = p.beta_m as f64;
        let v0 = (0.726 * bm + 0.812 * bm * bm + 3.7 * bm.powi(20)).powi(2);
        let v = [v0, 0.25 * v0, 4.0 * v0, 4.0 * v0];
        let bn = p.beta_n as f64;
        let s = (PI64 / 8.0).sqrt() * (0.265 * bn + 1.194 * bn * bn + 5.372 * bn.powi(22));
        let a = (p.alpha as f64).to_radians();
        let tilt = [-2.0 * a, a, 4.0 * a, 0.0].map(|t: f64| (t.sin(), t.cos()));

        let key = TableKey::new(p);
        let table = if key.kappa > 0.0 && key.sigma_s > 0.0 {
            let built = prep.get_or_build_stored(key, || Ok::<_, Infallible>(Table::build(&key)));
            Some(built.unwrap_or_else(|never| match never {}))
        } else {
            None
        };
        let sigma_c = [sigma_c.x, sigma_c.y, sigma_c.z].map(f64::from);
        let escape = table.as_ref().map_or(Vec::new(), |t| {
            t.nodes
                .iter()
                .map(|n| sigma_c.map(|s| n.escape_at(s)))
                .collect()
        });
        Ok(Fur {
            eta: p.eta as f64,
            sigma_c,
            kappa: p.medulla_ratio as f64,
            sigma_s: p.medulla_sigma_s as f64,
            sigma_t: (p.medulla_sigma_s + p.medulla_sigma_a) as f64,
            v,
            ln_norm: v.map(|v| -v.ln() - (-(-2.0 / v).exp_m1()).ln()),
            tilt,
            s,
            cdf_lo: 1.0 / (1.0 + (PI64 / s).exp()),
            cdf_range: (PI64 / (2.0 * s)).tanh(),
            table,
            escape,
        })
    }

    fn geometry(&self, wo: Vec3, h: f32) -> Geometry {
        let h = (h as f64).clamp(-1.0, 1.0);
        let sin_o = (wo.x as f64).clamp(-1.0, 1.0);
        let cos_o = ((1.0 - sin_o) * (1.0 + sin_o)).max(0.0).sqrt();
        let eta = self.eta;
        // η cos θ_t = √(η² − sin²θ_o); sin γ_t = h / η' without dividing by cos θ_o.
        let root = (eta * eta - sin_o * sin_o).sqrt();
        let sin_gt = h * cos_o / root;
        let cos_gt = (1.0 - sin_gt * sin_gt).max(0.0).sqrt();
        let (gamma_t, gamma_o) = (sin_gt.asin(), h.asin());
        // 3D lengths of one chord and of its part in the medulla (÷ cos θ_t = × η / root).
        let to_3d = eta / root;
        let chord = 2.0 * cos_gt * to_3d;
        let u = if self.kappa > 0.0 {
            sin_gt / self.kappa
        } else {
            1.0
        };
        let medulla = if u.abs() < 1.0 {
            2.0 * self.kappa * (1.0 - u * u).sqrt() * to_3d
        } else {
            0.0
        };
        let f = fresnel_dielectric(cos_o * (1.0 - h * h).max(0.0).sqrt(), eta);
        let t_m = (-self.sigma_t * medulla).exp();
        let albedo = if self.sigma_t > 0.0 {
            self.sigma_s / self.sigma_t
        } else {
            0.0
        };
        let nodes = self
            .table
            .as_ref()
            .map_or(Nodes::NONE, |t| t.nodes(sin_o, u));
        let mut escape = [0.0; 3];
        if self.table.is_some() {
            for (&i, &w) in nodes.index.iter().zip(&nodes.weight) {
                for (e, n) in escape.iter_mut().zip(self.escape[i]) {
                    *e += w * n;
                }
            }
        }
        let mut energy = [Rgb::ZERO; 5];
        for c in 0..3 {
            let t_c = (-self.sigma_c[c] * (chord - medulla)).exp();
            let t = t_c * t_m;
            let a1 = (1.0 - f) * (1.0 - f) * t;
            let a2 = a1 * t * f;
            // 1 − fT = 0 only when f = 1 (h = ±1), where a2 = 0 and nothing enters.
            let denom = (1.0 - f * t).max(f64::MIN_POSITIVE);
            let a3 = a2 * f * t / denom;
            let scattered = (1.0 - f) * t_c.sqrt() * (1.0 - t_m) * albedo / denom * escape[c];
            for (e, v) in energy.iter_mut().zip([f, a1, a2, a3, scattered]) {
                e[c] = v as f32;
            }
        }
        let lum = energy.map(|e| luminance(e) as f64);
        let total: f64 = lum.iter().sum();
        let lobe_pdf = if total > 0.0 {
            lum.map(|l| l / total)
        } else {
            [0.0; 5]
        };
        let mut sin_t = [0.0; 4];
        let mut cos_t = [0.0; 4];
        for p in 0..4 {
            let (ts, tc) = self.tilt[p];
            sin_t[p] = sin_o * tc + cos_o * ts;
            cos_t[p] = (cos_o * tc - sin_o * ts).abs();
        }
        Geometry {
            normal_o: normal_plane_direction(wo),
            sin_o: sin_t,
            cos_o: cos_t,
            phi_exit: [0.0, 1.0, 2.0].map(|p| 2.0 * p * gamma_t - 2.0 * gamma_o + p * PI64),
            energy,
            lobe_pdf,
            nodes,
        }
    }

    /// (sin θ_i, cos θ_i, φ_i − φ_o) of `wi`.
    fn angles(g: &Geometry, wi: Vec3) -> (f64, f64, f64) {
        let sin_i = (wi.x as f64).clamp(-1.0, 1.0);
        let cos_i = ((1.0 - sin_i) * (1.0 + sin_i)).max(0.0).sqrt();
        let (y, z) = g.normal_o;
        let (wy, wz) = (wi.y as f64, wi.z as f64);
        (sin_i, cos_i, (y * wz - z * wy).atan2(y * wy + z * wz))
    }

    /// The six lobes' values (M_p N_p per unit energy; for TTs and TRTs the density D of each)
    /// at the angles of wi.
    fn shapes(&self, g: &Geometry, (sin_i, cos_i, phi): (f64, f64, f64)) -> [f64; 6] {
        let mut out = [0.0; 6];
        for (p, value) in out.iter_mut().enumerate().take(4) {
            let m = vmf(
                self.v[p],
                self.ln_norm[p],
                sin_i,
                cos_i,
                g.sin_o[p],
                g.cos_o[p],
            );
            let n = if p < RESIDUAL {
                self.logistic(wrap_pi(phi - g.phi_exit[p]))
            } else {
                1.0 / (2.0 * PI64)
            };
            *value = m * n;
        }
        if let Some(t) = &self.table {
            let [tts, trts] = t.density(&g.nodes, sin_i, phi);
            out[SCATTERED] = tts;
            out[SCATTERED + 1] = trts;
        }
        out
    }

    /// (eval, pdf) from the lobe shapes.
    fn combine(g: &Geometry, shapes: &[f64; 6]) -> (Rgb, f32) {
        let mut f = Rgb::ZERO;
        let mut pdf = 0.0;
        for (p, &shape) in shapes.iter().enumerate() {
            let group = p.min(SCATTERED);
            f += g.energy[group] * shape as f32;
            pdf += g.lobe_pdf[group] * shape;
        }
        (f, pdf as f32)
    }

    fn eval_pdf_at(&self, g: &Geometry, wi: Vec3) -> (Rgb, f32) {
        Self::combine(g, &self.shapes(g, Self::angles(g, wi)))
    }

    /// The trimmed logistic at x ∈ [−π, π].
    fn logistic(&self, x: f64) -> f64 {
        let e = (-x.abs() / self.s).exp();
        e / (self.s * (1.0 + e) * (1.0 + e) * self.cdf_range)
    }

    /// Draws a lobe group, then a direction from it: the geometry, the group and wi.
    fn draw(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<(Geometry, usize, Vec3)> {
        let g = self.geometry(wo, h);
        let u0 = u[0] as f64;
        let mut cdf = 0.0;
        let mut chosen = None;
        for (p, &prob) in g.lobe_pdf.iter().enumerate() {
            if prob > 0.0 && u0 < cdf + prob {
                chosen = Some((p, ((u0 - cdf) / prob).clamp(0.0, 1.0)));
                break;
            }
            cdf += prob;
        }
        // Rounding may leave u[0] above the total: take the last group that can occur.
        let (p, u_rest) = match chosen {
            Some(c) => c,
            None => (g.lobe_pdf.iter().rposition(|&q| q > 0.0)?, 1.0),
        };
        let (sin_i, phi) = if p == SCATTERED {
            self.table
                .as_ref()?
                .sample(&g.nodes, u_rest, [u[1], u[2], u[3]].map(f64::from))?
        } else {
            self.sample_unscattered(&g, p, [u[1], u[2], u[3]].map(f64::from))
        };
        let cos_i = ((1.0 - sin_i) * (1.0 + sin_i)).max(0.0).sqrt();
        let (y, z) = g.normal_o;
        let (sd, cd) = phi.sin_cos();
        let wi = Vec3::new(
            sin_i as f32,
            (cos_i * (y * cd - z * sd)) as f32,
            (cos_i * (z * cd + y * sd)) as f32,
        );
        Some((g, p, wi))
    }

    /// θ_i from lobe p's vMF about its mirror direction (u[0], u[1]) and φ from its logistic
    /// about Φ(p, h) or uniform for the residual (u[2]): (sin θ_i, φ_i − φ_o).
    fn sample_unscattered(&self, g: &Geometry, p: usize, u: [f64; 3]) -> (f64, f64) {
        const U_MIN: f64 = 1.0 / (1u64 << 24) as f64;
        let v = self.v[p];
        // cos θ* = 1 + v ln(u + (1 − u) e^{−2/v}).
        let w = (-v * (-(1.0 - u[0].max(U_MIN)) * (-(-2.0 / v).exp_m1())).ln_1p()).min(2.0);
        let cos_star = 1.0 - w;
        let sin_star = (w * (2.0 - w)).max(0.0).sqrt();
        let sin_i = (-cos_star * g.sin_o[p] + sin_star * (2.0 * PI64 * u[1]).cos() * g.cos_o[p])
            .clamp(-1.0, 1.0);
        let phi = if p < RESIDUAL {
            let q = u[2].max(U_MIN) * self.cdf_range + self.cdf_lo;
            g.phi_exit[p] + (self.s * (q / (1.0 - q)).ln()).clamp(-PI64, PI64)
        } else {
            2.0 * PI64 * u[2] - PI64
        };
        (sin_i, phi)
    }
}

impl Bcsdf for Fur {
    fn eval(&self, wo: Vec3, wi: Vec3, h: f32) -> Rgb {
        self.eval_pdf_at(&self.geometry(wo, h), wi).0
    }

    fn sample(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<BcsdfSample> {
        let (g, _, wi) = self.draw(wo, h, u)?;
        // Evaluated at the direction's vector, so that a point drawn next to a table cell's edge
        // gets the value and density of the cell the vector falls in.
        let (f, pdf) = self.eval_pdf_at(&g, wi);
        (pdf > 0.0 && pdf.is_finite()).then_some(BcsdfSample { wi, f, pdf })
    }

    // Every group's shape is sampled exactly (vMF × logistic, or the table's mixture of cells),
    // so a sample of group p weighs its energy over the probability of choosing it.
    fn sample_weight(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<(Vec3, Rgb)> {
        let (g, p, wi) = self.draw(wo, h, u)?;
        let weight = g.energy[p] / g.lobe_pdf[p] as f32;
        weight.is_finite().then_some((wi, weight))
    }

    fn pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> f32 {
        self.eval_pdf_at(&self.geometry(wo, h), wi).1
    }

    fn eval_pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> (Rgb, f32) {
        self.eval_pdf_at(&self.geometry(wo, h), wi)
    }

    fn lobe_names(&self) -> &'static [&'static str] {
        &LOBE_NAMES
    }

    fn eval_lobe(&self, wo: Vec3, wi: Vec3, h: f32, p: usize) -> Rgb {
        if p >= LOBE_NAMES.len() {
            return Rgb::ZERO;
        }
        let g = self.geometry(wo, h);
        let shapes = self.shapes(&g, Self::angles(&g, wi));
        g.energy[p.min(SCATTERED)] * shapes[p] as f32
    }

    fn eval_lobes_batch(&self, wo: Vec3, h: f32, wis: &[Vec3], out: &mut [Rgb]) {
        let g = self.geometry(wo, h);
        for (&wi, row) in wis.iter().zip(out.chunks_exact_mut(LOBE_NAMES.len())) {
            let shapes = self.shapes(&g, Self::angles(&g, wi));
            for (p, v) in row.iter_mut().enumerate() {
                *v = g.energy[p.min(SCATTERED)] * shapes[p] as f32;
            }
        }
    }
}

/// The vMF longitudinal lobe, normalised so that ∫ M cos θ_i dθ_i = 1, in Chiang's
/// overflow-free form `exp(ln_norm − |u − m|²/(2v)) · I₀(a) e^{−a}`, `a = cos θ_i cos θ_o / v`.
fn vmf(v: f64, ln_norm: f64, sin_i: f64, cos_i: f64, sin_o: f64, cos_o: f64) -> f64 {
    let ds = sin_i + sin_o;
    let dc = cos_i - cos_o;
    (ln_norm - (ds * ds + dc * dc) / (2.0 * v)).exp() * i0_scaled(cos_i * cos_o / v)
}

/// `I₀(x) e^{−x}` for x ≥ 0 (Abramowitz & Stegun 9.8.1 and 9.8.2, relative error < 2·10⁻⁷).
#[allow(clippy::excessive_precision)] // the published coefficients, digit for digit
fn i0_scaled(x: f64) -> f64 {
    if x <= 3.75 {
        let t = (x / 3.75) * (x / 3.75);
        let p = 1.0
            + t * (3.5156229
                + t * (3.0899424
                    + t * (1.2067492 + t * (0.2659732 + t * (0.0360768 + t * 0.0045813)))));
        p * (-x).exp()
    } else {
        let t = 3.75 / x;
        let p = 0.39894228
            + t * (0.01328592
                + t * (0.00225319
                    + t * (-0.00157565
                        + t * (0.00916281
                            + t * (-0.02057706
                                + t * (0.02635537 + t * (-0.01647633 + t * 0.00392377)))))));
        p / x.sqrt()
    }
}

/// `w`'s direction in the normal plane, normalised; (1, 0) along the fiber, where φ is
/// undefined and taken as 0.
fn normal_plane_direction(w: Vec3) -> (f64, f64) {
    let (y, z) = (w.y as f64, w.z as f64);
    let r = (y * y + z * z).sqrt();
    if r > 0.0 {
        (y / r, z / r)
    } else {
        (1.0, 0.0)
    }
}

fn wrap_pi(x: f64) -> f64 {
    x - 2.0 * PI64 * (x / (2.0 * PI64)).round()
}

/// Unpolarised Fresnel reflectance at incidence cosine `cos_i` from the side of index 1 onto
/// index `eta` (`eta` < 1 from inside; total internal reflection gives 1).
fn fresnel_dielectric(cos_i: f64, eta: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let r_par = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (r_perp * r_perp + r_par * r_par)
}

// ------------------------------------------------------------------------------------------
// The precomputed scattering profiles.

/// Nodes in θ_o (0°, 12°, …, 84°) and in u = sin γ_t / κ (0, 1/8, …, 1).
const N_THETA: usize = 8;
const THETA_STEP_DEG: f64 = 12.0;
const N_U: usize = 9;
/// Exit-direction cells: sin θ_i in 16 equal bins, φ_i − φ_o in 32.
const N_SIN: usize = 16;
const N_PHI: usize = 32;
const CELLS: usize = N_SIN * N_PHI;
/// Photons simulated per node: the histograms' cells get ~16 each on average (a smooth
/// enough profile for a broad lobe once interpolated between nodes, for a few seconds of CPU
/// per model).
const PHOTONS: u32 = 1 << 14;
const CELL_AREA: f64 = (2.0 / N_SIN as f64) * (2.0 * PI64 / N_PHI as f64);
/// The seed of every node's photon streams (each node its own stream).
const SEED: u64 = 0xf0_2015;

/// The parameters the table depends on (module docs), compared bit for bit (−0 is made +0);
/// the table's resolution and photon counts are constants of the build, in its stored key.
#[derive(Clone, Copy, Debug)]
struct TableKey {
    eta: f32,
    kappa: f32,
    sigma_s: f32,
    sigma_a: f32,
    g: f32,
}

impl TableKey {
    fn new(p: &Params) -> Self {
        // + 0.0 turns −0 into +0, which build the same table.
        TableKey {
            eta: p.eta + 0.0,
            kappa: p.medulla_ratio + 0.0,
            sigma_s: p.medulla_sigma_s + 0.0,
            sigma_a: p.medulla_sigma_a + 0.0,
            g: p.medulla_g + 0.0,
        }
    }

    fn bits(&self) -> [u32; 5] {
        [self.eta, self.kappa, self.sigma_s, self.sigma_a, self.g].map(f32::to_bits)
    }
}

impl PartialEq for TableKey {
    fn eq(&self, other: &Self) -> bool {
        self.bits() == other.bits()
    }
}

impl Eq for TableKey {}

impl std::hash::Hash for TableKey {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.bits().hash(state);
    }
}

/// One node's profile: TTs cells then TRTs cells as probabilities (summing to 1 over both),
/// their cumulative sums for sampling, and the escaping fraction through a cortex of each
/// absorption of [`SIGMA_GRID`].
#[derive(Debug)]
struct Node {
    prob: Vec<f32>,
    cdf: Vec<f32>,
    escape: [f32; SIGMA_GRID.len()],
}

/// Cortex absorptions σ_c (per unit radius) at which each node keeps the fraction of first
/// scattered light that leaves the fiber, `E[w e^{−σ_c L}]` over photons of weight w (medulla
/// absorption) and cortex path L: the exact mean, where `e^{−σ_c E[L]}` would be too dark
/// (Jensen's inequality). In between, ln of it is interpolated linearly in σ_c (it is smooth
/// and convex in σ_c); past the last, extrapolated along the last interval.
const SIGMA_GRID: [f64; 9] = [0.0, 0.125, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0];

/// The scattering profiles of one parameter set (module docs).
#[derive(Debug)]
struct Table {
    nodes: Vec<Node>,
}

/// The table's sizes, as stored: nodes in θ_o and u, cells in sin θ_i and φ, cortex
/// absorptions.
const STORED_SIZES: [u32; 5] = [
    N_THETA as u32,
    N_U as u32,
    N_SIN as u32,
    N_PHI as u32,
    SIGMA_GRID.len() as u32,
];

/// Kept on disk as its key (η, κ, σ_s, σ_a, g, then the resolution, photon count and σ_c grid,
/// and the simulation's seed) and, per node, the TTs and TRTs cell probabilities and the
/// escaping fractions, all as f32 bits; the cumulative sums are recomputed (the same bits).
impl StoredTable for Table {
    type Key = TableKey;
    const KIND: &'static str = "fur-medulla";
    const VERSION: u32 = 1;

    fn key_bytes(key: &TableKey) -> Vec<u8> {
        let mut out = Vec::new();
        key.bits().iter().for_each(|b| out.extend(b.to_le_bytes()));
        STORED_SIZES
            .iter()
            .chain(&[PHOTONS])
            .for_each(|v| out.extend(v.to_le_bytes()));
        [THETA_STEP_DEG.to_bits(), SEED]
            .iter()
            .chain(&SIGMA_GRID.map(f64::to_bits))
            .for_each(|v| out.extend(v.to_le_bytes()));
        out
    }

    fn encode(&self, out: &mut Vec<u8>) {
        STORED_SIZES
            .iter()
            .for_each(|v| out.extend(v.to_le_bytes()));
        for n in &self.nodes {
            n.prob
                .iter()
                .chain(&n.escape)
                .for_each(|v| out.extend(v.to_bits().to_le_bytes()));
        }
    }

    fn decode(bytes: &[u8]) -> Result<Self, String> {
        let words: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let per_node = 2 * CELLS + SIGMA_GRID.len();
        let want = STORED_SIZES.len() + N_THETA * N_U * per_node;
        if bytes.len() != 4 * want {
            return Err(format!("{} bytes of table, not {}", bytes.len(), 4 * want));
        }
        let (sizes, values) = words.split_at(STORED_SIZES.len());
        if sizes != STORED_SIZES {
            return Err(format!("sizes {sizes:?}, not {STORED_SIZES:?}"));
        }
        let values: Vec<f32> = values.iter().map(|&b| f32::from_bits(b)).collect();
        if let Some(v) = values.iter().find(|v| !(0.0..=1.0).contains(*v)) {
            return Err(format!("a probability or fraction of {v}, outside [0, 1]"));
        }
        let nodes = values
            .chunks_exact(per_node)
            .map(|node| {
                let (prob, escape) = node.split_at(2 * CELLS);
                let mut e = [0.0; SIGMA_GRID.len()];
                e.copy_from_slice(escape);
                Node::new(prob.to_vec(), e)
            })
            .collect();
        Ok(Table { nodes })
    }
}

/// Up to four table nodes with their bilinear weights, and the mirror flags of the query.
struct Nodes {
    index: [usize; 4],
    weight: [f64; 4],
    flip_theta: bool,
    flip_phi: bool,
}

impl Nodes {
    const NONE: Nodes = Nodes {
        index: [0; 4],
        weight: [0.0; 4],
        flip_theta: false,
        flip_phi: false,
    };
}

impl Table {
    /// Simulates every node (module docs), on every core, with a progress bar on a terminal.
    fn build(key: &TableKey) -> Table {
        let bar = progress_bar((N_THETA * N_U) as u64);
        let done = AtomicU64::new(0);
        let nodes = parallel_map(N_THETA * N_U, |n| {
            let node = simulate_node(key, n / N_U, n % N_U);
            bar.set_position(done.fetch_add(1, Ordering::Relaxed) + 1);
            node
        });
        bar.finish_and_clear();
        Table { nodes }
    }

    /// The nodes around (|θ_o|, |u|) with bilinear weights.
    fn nodes(&self, sin_o: f64, u: f64) -> Nodes {
        let t = (sin_o.abs().asin().to_degrees() / THETA_STEP_DEG).min((N_THETA - 1) as f64);
        let x = u.abs().min(1.0) * (N_U - 1) as f64;
        let (t0, x0) = ((t as usize).min(N_THETA - 2), (x as usize).min(N_U - 2));
        let (ft, fx) = (t - t0 as f64, x - x0 as f64);
        Nodes {
            index: [
                t0 * N_U + x0,
                t0 * N_U + x0 + 1,
                (t0 + 1) * N_U + x0,
                (t0 + 1) * N_U + x0 + 1,
            ],
            weight: [
                (1.0 - ft) * (1.0 - fx),
                (1.0 - ft) * fx,
                ft * (1.0 - fx),
                ft * fx,
            ],
            flip_theta: sin_o < 0.0,
            flip_phi: u < 0.0,
        }
    }

    /// The table's cell of (sin θ_i, φ), in the mirrored frame of the query.
    fn cell(n: &Nodes, sin_i: f64, phi: f64) -> usize {
        let j = (((sin_i + 1.0) * 0.5 * N_SIN as f64) as usize).min(N_SIN - 1);
        let k = (((wrap_pi(phi) + PI64) / (2.0 * PI64) * N_PHI as f64) as usize).min(N_PHI - 1);
        let j = if n.flip_theta { N_SIN - 1 - j } else { j };
        let k = if n.flip_phi { N_PHI - 1 - k } else { k };
        j * N_PHI + k
    }

    /// Solid-angle densities of TTs and TRTs at (sin θ_i, φ).
    fn density(&self, n: &Nodes, sin_i: f64, phi: f64) -> [f64; 2] {
        let c = Self::cell(n, sin_i, phi);
        let mut d = [0.0; 2];
        for (&i, &w) in n.index.iter().zip(&n.weight) {
            if w > 0.0 {
                let prob = &self.nodes[i].prob;
                d[0] += w * prob[c] as f64;
                d[1] += w * prob[CELLS + c] as f64;
            }
        }
        d.map(|x| x / CELL_AREA)
    }

    /// Draws a node by its weight (`u_node`), a cell by its probability (u[0]) and a point
    /// uniformly in it (u[1], u[2]): (sin θ_i, φ).
    fn sample(&self, n: &Nodes, u_node: f64, u: [f64; 3]) -> Option<(f64, f64)> {
        let mut acc = 0.0;
        let mut node = None;
        for (&i, &w) in n.index.iter().zip(&n.weight) {
            if w > 0.0 {
                node = Some(i);
                acc += w;
                if u_node < acc {
                    break;
                }
            }
        }
        let cdf = &self.nodes[node?].cdf;
        let target = (u[0] as f32) * cdf[cdf.len() - 1];
        let mut c = cdf.partition_point(|&x| x <= target).min(cdf.len() - 1);
        // u[0] rounding to the total lands past the last cell: step back to one that can occur.
        while c > 0 && cdf[c] == cdf[c - 1] {
            c -= 1;
        }
        let c = c % CELLS;
        let (j, k) = (c / N_PHI, c % N_PHI);
        let mut sin_i = -1.0 + (j as f64 + u[1]) * 2.0 / N_SIN as f64;
        let mut phi = -PI64 + (k as f64 + u[2]) * 2.0 * PI64 / N_PHI as f64;
        if n.flip_theta {
            sin_i = -sin_i;
        }
        if n.flip_phi {
            phi = -phi;
        }
        Some((sin_i.clamp(-1.0, 1.0), phi))
    }
}

impl Node {
    /// The escaping fraction through a cortex of absorption `sigma` ([`SIGMA_GRID`]).
    fn escape_at(&self, sigma: f64) -> f64 {
        let last = SIGMA_GRID.len() - 1;
        let k = SIGMA_GRID[1..last].partition_point(|&s| s <= sigma);
        let t = (sigma - SIGMA_GRID[k]) / (SIGMA_GRID[k + 1] - SIGMA_GRID[k]);
        let (a, b) = (self.escape[k] as f64, self.escape[k + 1] as f64);
        if a > 0.0 && b > 0.0 {
            (a.ln() + t * (b.ln() - a.ln())).exp()
        } else {
            (a + t * (b - a)).max(0.0)
        }
    }

    /// A node from its cell probabilities (summing to 1) and escaping fractions.
    fn new(prob: Vec<f32>, escape: [f32; SIGMA_GRID.len()]) -> Node {
        let cdf: Vec<f32> = prob
            .iter()
            .scan(0.0f32, |s, &p| {
                *s += p;
                Some(*s)
            })
            .collect();
        Node { prob, cdf, escape }
    }
}

/// A progress bar on stderr for the table build, hidden unless stderr is a terminal.
fn progress_bar(total: u64) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} fur medulla table [{elapsed_precise}] {wide_bar} {pos}/{len} ETA {eta}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar
}

type V3 = [f64; 3];

fn add(a: V3, b: V3, s: f64) -> V3 {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Distance along `d` from `p` to the cylinder of radius `r` about the x axis, leaving it
/// (the larger root): `None` if the line misses it or runs along the axis.
fn exit_distance(p: V3, d: V3, r: f64) -> Option<(f64, f64)> {
    let a = d[1] * d[1] + d[2] * d[2];
    if a < 1e-14 {
        return None;
    }
    let b = p[1] * d[1] + p[2] * d[2];
    let c = p[1] * p[1] + p[2] * p[2] - r * r;
    let disc = b * b - a * c;
    if disc <= 0.0 {
        return None;
    }
    let q = disc.sqrt();
    Some(((-b - q) / a, (-b + q) / a))
}

/// The outward normal of the unit cylinder at `p`.
fn normal_at(p: V3) -> V3 {
    let r = (p[1] * p[1] + p[2] * p[2]).sqrt();
    [0.0, p[1] / r, p[2] / r]
}

/// `d` turned by the Henyey–Greenstein phase function of asymmetry `g`.
fn scatter_hg(d: V3, g: f64, u1: f64, u2: f64) -> V3 {
    let cos = if g.abs() < 1e-3 {
        1.0 - 2.0 * u1
    } else {
        let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u1);
        ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
    };
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let (sp, cp) = (2.0 * PI64 * u2).sin_cos();
    // An orthonormal basis around d (Duff et al. 2017).
    let sign = 1f64.copysign(d[2]);
    let a = -1.0 / (sign + d[2]);
    let b = d[0] * d[1] * a;
    let t1 = [1.0 + sign * d[0] * d[0] * a, sign * b, -sign * d[0]];
    let t2 = [b, sign + d[1] * d[1] * a, -d[1]];
    let mut out = [0.0; 3];
    for i in 0..3 {
        out[i] = sin * cp * t1[i] + sin * sp * t2[i] + cos * d[i];
    }
    out
}

/// The fiber's interior as the simulation sees it: index, medulla radius, coefficients, HG g.
struct Medium {
    eta: f64,
    kappa: f64,
    sigma_s: f64,
    sigma_a: f64,
    g: f64,
}

/// A photon that left the fiber: its direction, weight (medulla absorption), cortex path and
/// internal reflections on the way.
struct Exit {
    dir: V3,
    weight: f64,
    cortex: f64,
    reflections: u32,
}

impl Medium {
    fn new(key: &TableKey) -> Self {
        Medium {
            eta: key.eta as f64,
            kappa: key.kappa as f64,
            sigma_s: key.sigma_s as f64,
            sigma_a: key.sigma_a as f64,
            g: key.g as f64,
        }
    }

    /// Follows a photon at `p` inside the fiber going along `d` (in the medulla or the cortex)
    /// until it leaves; `None` if the medulla absorbs it (Russian roulette) or it runs along
    /// the axis (probability ~10⁻¹⁴) or past the cap of events.
    fn walk(
        &self,
        mut p: V3,
        mut d: V3,
        mut in_medulla: bool,
        next: &mut impl FnMut() -> f64,
    ) -> Option<Exit> {
        let (kappa, eta) = (self.kappa, self.eta);
        let (mut weight, mut cortex, mut reflections) = (1.0f64, 0.0f64, 0u32);
        for _ in 0..100_000 {
            if in_medulla {
                let (_, to_edge) = exit_distance(p, d, kappa)?;
                let free = -(1.0 - next()).ln() / self.sigma_s;
                if free < to_edge {
                    p = add(p, d, free);
                    weight *= (-self.sigma_a * free).exp();
                    d = scatter_hg(d, self.g, next(), next());
                    // Russian roulette keeps long absorbing walks short without bias.
                    if weight < 0.05 {
                        if next() < 0.5 {
                            return None;
                        }
                        weight *= 2.0;
                    }
                    continue;
                }
                p = add(p, d, to_edge);
                weight *= (-self.sigma_a * to_edge).exp();
                in_medulla = false;
            }
            // In the cortex: to the medulla if the line enters it ahead, else to the cuticle.
            if let Some((enter, _)) = exit_distance(p, d, kappa).filter(|&(e, _)| e > 1e-9) {
                p = add(p, d, enter);
                cortex += enter;
                in_medulla = true;
                continue;
            }
            let (_, out) = exit_distance(p, d, 1.0)?;
            p = add(p, d, out);
            cortex += out;
            let n = normal_at(p);
            let cos = dot(d, n);
            if next() < fresnel_dielectric(cos, 1.0 / eta) {
                d = add(d, n, -2.0 * cos);
                reflections += 1;
                continue;
            }
            let cos_out = (1.0 - eta * eta * (1.0 - cos * cos)).max(0.0).sqrt();
            let out_dir = add(d.map(|x| x * eta), n, cos_out - eta * cos);
            let len = dot(out_dir, out_dir).sqrt();
            return Some(Exit {
                dir: out_dir.map(|x| x / len),
                weight,
                cortex,
                reflections,
            });
        }
        None
    }
}

/// A ray along −ω_o (θ_o = `theta`, φ_o = π/2) entering the fiber at offset `h`: the entry
/// point, the refracted direction and the Fresnel reflectance.
fn entry(eta: f64, theta: f64, h: f64) -> (V3, V3, f64) {
    let (sin_o, cos_o) = theta.sin_cos();
    let d_in = [-sin_o, 0.0, -cos_o];
    let p_in = [0.0, h, (1.0 - h * h).sqrt()];
    let n_in = normal_at(p_in);
    let cos_in = -dot(d_in, n_in);
    let cos_t = (1.0 - (1.0 - cos_in * cos_in) / (eta * eta)).sqrt();
    let d_t = add(d_in, n_in, cos_in - eta * cos_t).map(|x| x / eta);
    (p_in, d_t, fresnel_dielectric(cos_in, eta))
}

/// Simulates node (θ_o index, u index): the histograms of TTs and TRTs exit directions of photons
/// starting at their first scattering in the medulla (module docs), and the fractions that
/// leave through a cortex of each absorption of [`SIGMA_GRID`].
fn simulate_node(key: &TableKey, ti: usize, ui: usize) -> Node {
    let medium = Medium::new(key);
    let (eta, kappa) = (medium.eta, medium.kappa);
    let sigma_t = medium.sigma_s + medium.sigma_a;
    let theta = (ti as f64 * THETA_STEP_DEG).to_radians();
    let (sin_o, cos_o) = theta.sin_cos();
    let eta_p = (eta * eta - sin_o * sin_o).sqrt() / cos_o;
    let u = ui as f64 / (N_U - 1) as f64;
    // Offsets beyond the reach of refraction (u κ η' > 1) are simulated at the grazing limit,
    // which interpolation toward them approaches; u = 1 just inside the tangent.
    let h = (u.min(1.0 - 1e-6) * kappa * eta_p).min(1.0 - 1e-6);

    let mut rng = Pcg32::new(SEED, (ti * N_U + ui) as u64);
    let mut next = || rng.next_f32() as f64;
    let mut hist = vec![0.0f64; 2 * CELLS];
    let mut escaped = [0.0f64; SIGMA_GRID.len()];

    let (p_in, d_t, f) = entry(eta, theta, h);

    for _ in 0..PHOTONS {
        // The chord of the first scattering: after k internal reflections with probability
        // ∝ (f T_m)^k (the chords are rotated copies, all crossing the medulla alike).
        let (mut p, mut d) = (p_in, d_t);
        let Some((m_in, m_out)) = exit_distance(p, d, kappa) else {
            break;
        };
        let t_m = (-sigma_t * (m_out - m_in)).exp();
        let q = f * t_m;
        let mut k = 0;
        while next() < q && k < 64 {
            k += 1;
        }
        for _ in 0..k {
            let (_, out) = exit_distance(p, d, 1.0).expect("a chord inside the fiber ends");
            p = add(p, d, out);
            let n = normal_at(p);
            d = add(d, n, -2.0 * dot(d, n));
        }
        let (m_in, m_out) = exit_distance(p, d, kappa).expect("every chord crosses the medulla");
        // Depth in the medulla ∝ e^{−σ_t s} on [0, ℓ_m].
        let depth = -(-next() * (-(-sigma_t * (m_out - m_in)).exp_m1())).ln_1p() / sigma_t;
        p = add(p, d, m_in + depth.min(m_out - m_in));
        d = scatter_hg(d, medium.g, next(), next());

        if let Some(exit) = medium.walk(p, d, true, &mut next) {
            let w = exit.dir;
            let c = Table::cell(&Nodes::NONE, w[0], w[2].atan2(w[1]) - PI64 / 2.0);
            hist[if exit.reflections == 0 { c } else { CELLS + c }] += exit.weight;
            for (e, sigma) in escaped.iter_mut().zip(SIGMA_GRID) {
                *e += exit.weight * (-sigma * exit.cortex).exp();
            }
        }
    }
    let total: f64 = hist.iter().sum();
    let prob: Vec<f32> = if total > 0.0 {
        hist.iter().map(|&x| (x / total) as f32).collect()
    } else {
        // No photon left (impossible for the accepted parameters): an even profile.
        vec![1.0 / (2 * CELLS) as f32; 2 * CELLS]
    };
    Node::new(prob, escaped.map(|e| (e / PHOTONS as f64).min(1.0) as f32))
}

/// Parameter sets the statistical tests run on this model ([`crate::HairModel::test_instances`]).
pub fn test_instances() -> Vec<TestInstance<Params>> {
    let white = |name: &str, p: Params| TestInstance {
        name: name.into(),
        params: Params {
            pigment: Pigment::SigmaA((0.0, 0.0, 0.0)),
            medulla_sigma_a: 0.0,
            ..p
        },
        white_furnace: true,
    };
    vec![
        white("white_default", Params::default()),
        white(
            "white_thick_forward",
            Params {
                beta_m: 0.2,
                beta_n: 0.4,
                medulla_ratio: 0.8,
                medulla_sigma_s: 8.0,
                medulla_g: 0.6,
                ..Params::default()
            },
        ),
        TestInstance {
            name: "brown_absorbing_medulla".into(),
            params: Params {
                medulla_sigma_a: 1.0,
                ..Params::default()
            },
            white_furnace: false,
        },
        TestInstance {
            name: "light_thin_medulla".into(),
            params: Params {
                medulla_ratio: 0.2,
                pigment: Pigment::Melanin {
                    eumelanin: 0.3,
                    pheomelanin: 0.2,
                    tint: crate::pigment::NO_TINT,
                },
                ..Params::default()
            },
            white_furnace: false,
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::assert_rejected;
    use tress_core::sampling::sample_uniform_sphere;
    use tress_core::Sampler;

    fn chiang_params(p: &Params) -> crate::chiang::Params {
        crate::chiang::Params {
            beta_m: p.beta_m,
            beta_n: p.beta_n,
            alpha: p.alpha,
            eta: p.eta,
            pigment: p.pigment.clone(),
        }
    }

    #[test]
    fn rejects_bad_parameters_naming_the_field() {
        assert_rejected(
            Fur::new,
            &[
                (|p: &mut Params| p.beta_m = 0.0, "beta_m"),
                (|p| p.beta_n = 1.5, "beta_n"),
                (|p| p.alpha = 91.0, "alpha"),
                (|p| p.eta = 1.0, "eta"),
                (|p| p.medulla_ratio = 0.99, "medulla_ratio"),
                (|p| p.medulla_ratio = f32::NAN, "medulla_ratio"),
                (|p| p.medulla_sigma_s = -1.0, "medulla_sigma_s"),
                (|p| p.medulla_sigma_a = 25.0, "medulla_sigma_a"),
                (|p| p.medulla_g = 0.95, "medulla_g"),
                (|p| p.pigment = Pigment::SigmaA((0.1, -1.0, 0.1)), "sigma_a"),
            ],
        );
    }

    /// Without a medulla (κ = 0) the model is Chiang's term for term: the same values and
    /// densities up to f32 rounding (this model computes in f64, Chiang's in f32 lanes).
    #[test]
    fn without_medulla_it_is_chiangs_model() {
        for p in [
            Params {
                medulla_ratio: 0.0,
                ..Params::default()
            },
            Params {
                medulla_ratio: 0.0,
                beta_m: 0.15,
                beta_n: 0.6,
                alpha: -3.0,
                eta: 1.6,
                pigment: Pigment::Melanin {
                    eumelanin: 0.4,
                    pheomelanin: 0.3,
                    tint: crate::pigment::NO_TINT,
                },
                ..Params::default()
            },
        ] {
            let fur = Fur::new(&p).unwrap();
            assert!(fur.table.is_none());
            let chiang = crate::chiang::Chiang::new(&chiang_params(&p)).unwrap();
            let mut rng = Sampler::from_seed(43);
            for _ in 0..20_000 {
                let wo = sample_uniform_sphere(rng.next_2d());
                let wi = sample_uniform_sphere(rng.next_2d());
                let h = 2.0 * rng.next_1d() - 1.0;
                let (f, pdf) = fur.eval_pdf(wo, wi, h);
                let (fc, pdfc) = chiang.eval_pdf(wo, wi, h);
                let close = |a: f32, b: f32| (a - b).abs() <= 2e-4 * b.abs() + 1e-7;
                assert!(
                    (0..3).all(|c| close(f[c], fc[c])) && close(pdf, pdfc),
                    "wo {wo} wi {wi} h {h}: fur ({f}, {pdf}) vs Chiang ({fc}, {pdfc})"
                );
            }
        }
    }

    /// A vanishing medulla approaches the plain fiber: with κ = 10⁻³ the L1 distance
    /// ∫ |f_fur − f_Chiang| dω is at most what the medulla can take from or give to the lobes.
    /// A chord crosses at most ℓ = 2κ/cos θ_t of medulla, so each pass keeps T_m ≥ e^{−σ_t ℓ}:
    /// TT changes by at most ε = 1 − e^{−σ_t ℓ}, TRT by 2ε, the residual by a further ε per
    /// pass, and the scattered lobes carry what the others lose — under 2·(4ε) in all, checked
    /// against a Monte Carlo estimate whose standard error is a small part of it.
    #[test]
    fn a_vanishing_medulla_approaches_the_plain_fiber() {
        let p = Params {
            medulla_ratio: 1e-3,
            pigment: Pigment::SigmaA((0.0, 0.0, 0.0)),
            ..Params::default()
        };
        let fur = Fur::new(&p).unwrap();
        let chiang = crate::chiang::Chiang::new(&chiang_params(&p)).unwrap();
        for (theta_deg, h) in [(0.0f32, 0.0f32), (30.0, 0.5), (60.0, -0.3)] {
            let t = theta_deg.to_radians();
            let wo = Vec3::new(t.sin(), 0.0, t.cos());
            let cos_t = ((p.eta * p.eta - t.sin().powi(2)).sqrt() / p.eta) as f64;
            let eps = 1.0 - (-(p.medulla_sigma_s as f64) * 2e-3 / cos_t).exp();
            let mut rng = Sampler::from_seed(7);
            let n = 200_000;
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for _ in 0..n {
                let wi = sample_uniform_sphere(rng.next_2d());
                let d =
                    ((fur.eval(wo, wi, h) - chiang.eval(wo, wi, h)).abs().x as f64) * 4.0 * PI64;
                sum += d;
                sum2 += d * d;
            }
            let mean = sum / n as f64;
            let se = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
            println!(
                "θ_o {theta_deg}° h {h}: L1 {mean:.2e} ± {se:.1e}, bound {:.2e}",
                8.0 * eps
            );
            assert!(se < 2.0 * eps, "too noisy to test");
            assert!(
                mean < 8.0 * eps,
                "θ_o {theta_deg}° h {h}: L1 {mean} ≥ {}",
                8.0 * eps
            );
        }
    }

    /// Every number of a table, bit for bit.
    fn table_bits(t: &Table) -> Vec<u32> {
        t.nodes
            .iter()
            .flat_map(|n| n.prob.iter().chain(&n.cdf).chain(&n.escape))
            .map(|v| v.to_bits())
            .collect()
    }

    fn medulla(sigma_s: f32) -> Params {
        Params {
            medulla_ratio: 0.4,
            medulla_sigma_s: sigma_s,
            medulla_sigma_a: 0.25,
            medulla_g: -0.2,
            ..Params::default()
        }
    }

    /// The table a model took from `prep`.
    fn table_of(p: &Params, prep: &Preparation) -> Arc<Table> {
        Fur::prepared(p, prep)
            .unwrap()
            .table
            .expect("a scattering medulla")
    }

    #[test]
    fn a_run_builds_each_table_once_whatever_the_pigment_roughness_and_tilt() {
        let prep = Preparation::new();
        let a = table_of(&medulla(3.0), &prep);
        let other_cortex = Params {
            beta_m: 0.2,
            beta_n: 0.5,
            alpha: -3.0,
            pigment: Pigment::Melanin {
                eumelanin: 0.3,
                pheomelanin: 0.8,
                tint: crate::pigment::NO_TINT,
            },
            ..medulla(3.0)
        };
        let b = table_of(&other_cortex, &prep);
        assert!(Arc::ptr_eq(&a, &b));
        assert_eq!(prep.count::<TableKey, Table>(), 1);
        // −0 is +0; any parameter of the medulla is another table.
        let negative_zero = Params {
            medulla_sigma_a: -0.0,
            ..medulla(3.0)
        };
        table_of(
            &Params {
                medulla_sigma_a: 0.0,
                ..medulla(3.0)
            },
            &prep,
        );
        table_of(&negative_zero, &prep);
        assert_eq!(prep.count::<TableKey, Table>(), 2);
        for edit in [
            |p: &mut Params| p.eta = 1.6,
            |p: &mut Params| p.medulla_ratio = 0.5,
            |p: &mut Params| p.medulla_sigma_s = 3.5,
            |p: &mut Params| p.medulla_sigma_a = 0.5,
            |p: &mut Params| p.medulla_g = 0.2,
        ] {
            let mut p = medulla(3.0);
            edit(&mut p);
            assert!(TableKey::new(&p) != TableKey::new(&medulla(3.0)));
        }
        // A model without a scattering medulla asks for no table.
        Fur::prepared(
            &Params {
                medulla_ratio: 0.0,
                ..medulla(3.0)
            },
            &prep,
        )
        .unwrap();
        Fur::prepared(&medulla(0.0), &prep).unwrap();
        assert_eq!(prep.count::<TableKey, Table>(), 2);
    }

    /// A table stored in the run's folder is read back by the next run bit for bit; a file that
    /// is truncated, of another version or of another key is ignored with a warning and the
    /// table built again, equal to a fresh build, and stored over it.
    #[test]
    fn stored_tables_read_back_bit_for_bit_and_bad_files_are_rebuilt() {
        let dir = tempfile::tempdir().unwrap();
        let run = || Preparation::new().with_table_dir(Some(dir.path().to_owned()));
        let p = medulla(2.5);
        let key = TableKey::new(&p);
        let fresh = table_bits(&Table::build(&key));

        let first = run();
        assert_eq!(table_bits(&table_of(&p, &first)), fresh);
        let notes = first.take_notes();
        assert!(
            notes[0].starts_with("fur-medulla table built in"),
            "{notes:?}"
        );
        let path = tress_core::stored_table::path::<Table>(dir.path(), &Table::key_bytes(&key));
        let stored = std::fs::read(&path).unwrap();

        let second = run();
        assert_eq!(table_bits(&table_of(&p, &second)), fresh);
        let notes = second.take_notes();
        assert_eq!(
            notes,
            [format!("fur-medulla table read from {}", path.display())]
        );

        // The checksum covers everything before it: an edited field gets a new one, so that
        // the field itself is what the reader refuses.
        let resum = |mut bytes: Vec<u8>| {
            let body = bytes.len() - 8;
            let sum = tress_core::stored_table::fnv1a64(&bytes[..body]);
            bytes[body..].copy_from_slice(&sum.to_le_bytes());
            bytes
        };
        let version_at = 8 + 4 + 4 + Table::KIND.len();
        let key_at = version_at + 4 + 4;
        let mut other_version = stored.clone();
        other_version[version_at] += 1;
        let mut other_key = stored.clone();
        other_key[key_at] ^= 1; // η's lowest bit
        for (bad, why) in [
            (stored[..stored.len() / 2].to_vec(), "truncated"),
            (
                resum(other_version),
                "version 2, this build reads version 1",
            ),
            (resum(other_key), "key differs"),
        ] {
            tress_core::output_file::write_bytes(&path, &Default::default(), &bad).unwrap();
            let again = run();
            assert_eq!(table_bits(&table_of(&p, &again)), fresh, "{why}");
            let notes = again.take_notes();
            assert!(
                notes[0].starts_with("warning: ignoring") && notes[0].contains(why),
                "{notes:?}"
            );
            assert!(
                notes[1].starts_with("fur-medulla table built in"),
                "{notes:?}"
            );
            assert_eq!(std::fs::read(&path).unwrap(), stored, "{why}: stored again");
        }
    }

    #[test]
    fn the_table_is_deterministic_and_its_escape_falls_with_absorption() {
        let key = TableKey::new(&Params {
            medulla_ratio: 0.3,
            medulla_sigma_s: 2.0,
            medulla_sigma_a: 0.5,
            medulla_g: 0.3,
            ..Params::default()
        });
        let start = std::time::Instant::now();
        let a = Table::build(&key);
        println!("table built in {:.2} s", start.elapsed().as_secs_f64());
        let b = Table::build(&key);
        assert_eq!(table_bits(&a), table_bits(&b));
        // The bytes this table is stored as, pinned: a change to the simulation or to the
        // encoding changes them, and must bump `Table::VERSION`, so that no run reads a table
        // an older build stored (then pin the new value here).
        let mut bytes = Vec::new();
        a.encode(&mut bytes);
        let sum = tress_core::stored_table::fnv1a64(&bytes);
        assert_eq!(
            (Table::VERSION, sum),
            (1, 0x70ca_9045_1ee4_2791),
            "the stored table changed ({sum:#018x}): bump Table::VERSION"
        );
        for n in &a.nodes {
            assert!(
                n.escape[0] > 0.0 && n.escape[0] < 1.0,
                "an absorbing medulla keeps some light"
            );
            assert!(n.escape.windows(2).all(|e| e[1] <= e[0]), "{:?}", n.escape);
        }
    }
    /// Yan et al. 2015 validate their rendering model against full 3D light transport in the
    /// double cylinder; so does this test, for the energy the model returns. A brute-force
    /// simulation of the fiber (Fresnel at the cuticle, cortex absorption per photon path,
    /// the medulla's walk) gives the directional albedo at (θ_o, h); the model's is the sum of
    /// its lobe energies `Σ A_p + E_s`. Without absorption both are 1 (to f32 rounding). With
    /// it they differ by the simulation's noise (4 s.e.) and by the error of the table's ρ: its
    /// nodes' own Monte Carlo estimates (2¹⁴ photons: ≲ 1 % relative s.e. for ρ ≥ 0.1), their
    /// interpolation between nodes and absorptions, and the colourless choice of the first
    /// chord — held to 2 % of the scattered energy. (With ρ taken as e^{−σ_c E[L]} instead,
    /// brown's blue channel came out 18 % of its albedo too dark.)
    #[test]
    fn the_lobe_energies_match_a_full_simulation_of_the_double_cylinder() {
        const N: usize = 100_000;
        for (name, pigment, sigma_a) in [
            ("white", Pigment::SigmaA((0.0, 0.0, 0.0)), 0.0f32),
            ("light", Pigment::SigmaA((0.1, 0.2, 0.4)), 0.5),
            ("brown", Pigment::default(), 1.0),
        ] {
            let p = Params {
                pigment,
                medulla_sigma_a: sigma_a,
                ..Params::default()
            };
            let fur = Fur::new(&p).unwrap();
            let medium = Medium::new(&TableKey::new(&p));
            for (i, (theta_deg, h)) in [(0.0f64, 0.1f64), (30.0, -0.4), (60.0, 0.7)]
                .into_iter()
                .enumerate()
            {
                let theta = theta_deg.to_radians();
                let (p_in, d_t, f) = entry(medium.eta, theta, h);
                let mut rng = Pcg32::new(99, i as u64);
                let mut next = || rng.next_f32() as f64;
                let mut sum = [0.0f64; 3];
                let mut sum2 = [0.0f64; 3];
                for _ in 0..N {
                    let w: [f64; 3] = if next() < f {
                        [1.0; 3]
                    } else if let Some(exit) = medium.walk(p_in, d_t, false, &mut next) {
                        fur.sigma_c.map(|s| exit.weight * (-s * exit.cortex).exp())
                    } else {
                        [0.0; 3]
                    };
                    for c in 0..3 {
                        sum[c] += w[c];
                        sum2[c] += w[c] * w[c];
                    }
                }
                let wo = Vec3::new(theta.sin() as f32, 0.0, theta.cos() as f32);
                let g = fur.geometry(wo, h as f32);
                for c in 0..3 {
                    let mean = sum[c] / N as f64;
                    let se = ((sum2[c] / N as f64 - mean * mean) / N as f64).sqrt();
                    let model: f64 = g.energy.iter().map(|e| e[c] as f64).sum();
                    let scattered = g.energy[SCATTERED][c] as f64;
                    println!(
                        "{name} θ_o {theta_deg}° h {h} channel {c}: model {model:.4} \
                         (scattered {scattered:.4}), simulation {mean:.4} ± {se:.4}"
                    );
                    // 10⁻⁵: the model's f32 lobe energies.
                    let table = if name == "white" {
                        0.0
                    } else {
                        0.02 * scattered
                    };
                    let allowed = 4.0 * se + 1e-5 + table;
                    assert!(
                        (model - mean).abs() < allowed,
                        "{name} θ_o {theta_deg}° h {h} channel {c}: model {model} vs {mean} ± {se}"
                    );
                }
            }
        }
    }
}
