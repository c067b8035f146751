//! Marschner et al. 2003, "Light Scattering from Human Hair Fibers" (SIGGRAPH), in the form
//! Zinke et al. 2008 built dual scattering on, with an importance sampler whose pdf is exact.
//!
//! `S(ω_i, ω_o) = Σ_{p ∈ R, TT, TRT} M_p(θ_h) · N_p(η'(θ_d), φ) / cos²θ_d`, with
//! θ_h = (θ_i + θ_o)/2, θ_d = (θ_o − θ_i)/2 and [`Bcsdf::eval`] returning `S · cos θ_i`.
//! - M_p: unit-area Gaussian in θ_h, mean α_p, *variance* β_p² (α_TT = −α_R/2, α_TRT = −3α_R/2,
//!   β_TT = β_R/2, β_TRT = 2β_R).
//! - N_p: sum over the roots h of Marschner's cubic Φ̂(p, γ) ≡ φ of A(p, h)/|2 dΦ̂/dh|, with
//!   Bravais indices η', η'' at θ_d, the polarisation-averaged Fresnel ½(F_⊥(η') + F_∥(η'')), and
//!   absorption along the corrected chord 2 cos γ_t / cos θ_t (sin θ_t = sin θ_d / η).
//! - TRT: the effective index η*(φ_h) of an elliptical fiber (TRT only) and the caustic replaced
//!   by two Gaussian glints, faded out as η' passes 2 (Marschner §4.3).
//!
//! **Conventions.** φ is the relative azimuth φ_i − φ_o wrapped to [−π, π]; for circular fibers
//! every N_p is even in φ, so Marschner's φ_r − φ_i gives the same values. The eccentric index uses
//! cos 2φ_h = cos(φ_i + φ_o) measured in the local fiber frame: lacking a per-fiber orientation,
//! the cross-section's axes are taken along the frame's y (width) and z axes. The model integrates
//! over the offset h analytically (the roots), so `eval`, `sample` and `pdf` **ignore the hit's
//! `h`**.
//!
//! **Not energy conserving.** With σ_a = 0 the white-furnace integral ∫ S cos θ_i dω_i is ≈ 2 at
//! normal incidence (≈ 1.96 at θ_o = 0, 1.62 at 80°, 2.47 at 89° for β_R = 5°; the book,
//! docs/src/reference/hair-maths.md#marschners-energy):
//! M_p is unit-area in θ_h but the integral runs over θ_i = 2θ_h − θ_o, so dθ_i = 2 dθ_h doubles
//! it; 1/cos²θ_d and the truncation of θ_i to [−π/2, π/2] add the θ_o dependence, and the glints
//! add energy on top. Every test instance is therefore flagged `white_furnace: false`.
//!
//! **Sampling** (exact pdf, for MIS). The lobe is chosen with probability ∝ its albedo
//! E_p(θ_o) = ∫ cos²θ_i M_p ∫N_p dφ / cos²θ_d dθ_i, tabulated over θ_o (a function of ω_o only).
//! θ_h is drawn from M_p's Gaussian on the range that keeps θ_i ∈ [−π/2, π/2], multiplied by a
//! window that ramps linearly to 0 over the last 30° of θ_i before the fiber axis (closed-form
//! normalisation and inverse CDF). φ is drawn from a periodic piecewise-linear table of N_p over
//! (|θ_d|, φ) built in `new`, from one of the two θ_d rows around |θ_d| picked with the
//! interpolation weights. The pdf is the same mixture,
//! `Σ_p P_p · q_p(θ_h) · ½ · Σ_rows w · n_row(φ) · window / cos θ_i` per unit solid angle
//! (½ = |dθ_h/dθ_i|). Without the window that density would grow like 1/cos θ_i toward the axis
//! (integrable, but no fixed quadrature or χ² binning of it converges); with it the pdf is finite
//! and continuous, and f/pdf still vanishes at the axis (f carries cos θ_i, the window ψ). Table
//! rows carry a floor of 1 % of their mean so that every direction with f > 0 can be sampled. The
//! elliptical TRT lobe is tabulated with η*(φ_h) for ω_o at φ_o = π/2, where the fiber frame puts
//! it; for other φ_o the pdf stays exact, only less well matched.
//!
//! | parameter | default | meaning |
//! |---|---|---|
//! | `alpha_r` | −7.5 | R lobe shift α_R in degrees, [−20, 20] (cuticle tilt; negative = toward the root) |
//! | `beta_r` | 7.5 | R lobe width β_R in degrees (standard deviation), [1, 30] |
//! | `eta` | 1.55 | index of refraction, [1.2, 3] |
//! | `pigment` | `Melanin(eumelanin: 1.3)` | σ_a per unit radius ([`Pigment`]; `Color` uses Chiang's fit at β_n = 0.3, as this model has no azimuthal roughness) |
//! | `eccentricity` | 1 | cross-section axis ratio a, [0.5, 1]; must keep η*_1 = 2(η−1)a² − η + 2 ≥ 1.2 |
//! | `glint` | 2.5 | glint scale k_G, [0, 10] |
//! | `caustic_width` | 15 | glint azimuthal width w_c in degrees, [1, 60] |
//! | `caustic_fade` | 0.3 | range Δη' over which the glint fades out above η' = 2, [0.05, 2] |
//! | `caustic_limit` | 0.5 | maximum glint h-width Δh_M, [0, 1] |
//!
//! RON (scene files, newtype variants unwrapped):
//! `Marschner(alpha_r: -7.5, beta_r: 7.5, pigment: Melanin(eumelanin: 0.4), eccentricity: 0.9)`

mod azimuthal;
mod sampling;

use crate::pigment::Pigment;
use crate::{check_range, ModelParams, ParamError, TestInstance};
use azimuthal::{wrap_pi, FresnelMode, Glint, Slice};
use sampling::{AzimuthPdf, WindowedNormal};
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use tress_core::math::{fiber_direction, Rgb, Vec3};
use tress_core::{Bcsdf, BcsdfSample};

/// θ_d rows of the sampling tables over [0, π/2].
const ROWS: usize = 64;
/// φ nodes per row over [−π, π) (even, so the rows can be mirrored).
const NODES: usize = 256;
/// θ_o nodes of the lobe-selection table over [−π/2, π/2].
const LOBE_ROWS: usize = 129;
/// θ_i quadrature nodes per lobe-selection entry.
const LOBE_QUAD: usize = 1024;
/// Sub-samples of N_p averaged around each node (smooths the near-singular TRT peaks).
const SUB: usize = 8;
/// Defensive floor of each table row, as a fraction of the row mean.
const FLOOR: f64 = 0.01;
/// Width in θ_h of the ramps that window M_p's Gaussian toward θ_i = ±π/2 when sampling: the
/// window is ψ/(2·RAMP) for ψ = π/2 − |θ_i| < 2·RAMP (i.e. |θ_i| > 60°), so the solid-angle pdf
/// stays finite along the fiber axis.
const RAMP: f64 = 15.0 * PI / 180.0;
/// Lowest effective TRT index accepted; the root solver relies on η' ≥ 1.2.
const MIN_ETA: f64 = 1.2;
/// β_n at which a `Pigment::Color` is converted (Chiang's fit needs one).
pub(crate) const COLOR_BETA_N: f32 = 0.3;

/// Parameters of [`Marschner`] (module docs).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
#[schemars(rename = "MarschnerParams")]
pub struct Params {
    /// α_R in degrees.
    pub alpha_r: f32,
    /// β_R in degrees (standard deviation).
    pub beta_r: f32,
    /// Index of refraction, in [1.2, 3] (default 1.55).
    pub eta: f32,
    /// Absorption σ_a per unit radius (default eumelanin 1.3).
    pub pigment: Pigment,
    /// Cross-section axis ratio a ≤ 1 (1 = circular).
    pub eccentricity: f32,
    /// k_G.
    pub glint: f32,
    /// w_c in degrees.
    pub caustic_width: f32,
    /// Δη'.
    pub caustic_fade: f32,
    /// Δh_M.
    pub caustic_limit: f32,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            alpha_r: -7.5,
            beta_r: 7.5,
            eta: 1.55,
            pigment: Pigment::default(),
            eccentricity: 1.0,
            glint: 2.5,
            caustic_width: 15.0,
            caustic_fade: 0.3,
            caustic_limit: 0.5,
        }
    }
}

impl ModelParams for Params {
    /// The pigment, converted at β_n = 0.3 (`COLOR_BETA_N`: the model has no azimuthal
    /// roughness).
    fn pigment(&self) -> Option<(&Pigment, f32)> {
        Some((&self.pigment, COLOR_BETA_N))
    }

    fn pigment_mut(&mut self) -> Option<&mut Pigment> {
        Some(&mut self.pigment)
    }

    /// Scales β_R, within [1°, 30°]: the only lobe width a strand's roughness sets.
    fn scale_roughness(&mut self, scale: f32) {
        self.beta_r = (self.beta_r * scale).clamp(1.0, 30.0);
    }
}

/// Marschner's BCSDF with its sampling tables (module docs).
pub struct Marschner {
    params: Params,
    alpha: [f64; 3],
    /// β_p², the Gaussian variances.
    var: [f64; 3],
    eta: f64,
    /// η*_1, η*_2 (both = η for a circular fiber).
    eta_star: [f64; 2],
    sigma_a: [f64; 3],
    /// `None` only in the test configuration that reproduces the caustic-free energy oracle.
    glint: Option<Glint>,
    /// Bravais polarisation average (Marschner); unpolarised 3D Fresnel only for the test oracle.
    fresnel: FresnelMode,
    /// Per lobe, per θ_d row: the azimuthal sampling density.
    rows: [Vec<AzimuthPdf>; 3],
    /// Per θ_o node: the lobe-selection probabilities.
    lobe_table: Vec<[f64; 3]>,
}

impl std::fmt::Debug for Marschner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Marschner")
            .field("params", &self.params)
            .finish_non_exhaustive()
    }
}

/// The angles of one (ω_o, ω_i) pair.
struct Angles {
    theta_o: f64,
    /// ψ_i = π/2 − |θ_i|, the angle of ω_i to the fiber axis (accurate near the axis).
    psi_i: f64,
    cos_i: f64,
    theta_h: f64,
    theta_d: f64,
    /// φ_i − φ_o in [−π, π].
    phi: f64,
    /// cos 2φ_h = cos(φ_i + φ_o).
    cos_2phi_h: f64,
}

/// (θ, φ) of a direction in the fiber frame; θ from atan2 so that it stays accurate near the axis.
fn spherical(w: Vec3) -> (f64, f64) {
    let (x, y, z) = (w.x as f64, w.y as f64, w.z as f64);
    (x.atan2(y.hypot(z)), z.atan2(y))
}

impl Angles {
    fn new(wo: Vec3, wi: Vec3) -> Self {
        let [xo, yo, zo] = wo.to_array().map(f64::from);
        let [xi, yi, zi] = wi.to_array().map(f64::from);
        let (ro, ri) = (yo.hypot(zo), yi.hypot(zi));
        let theta_o = xo.atan2(ro);
        let psi_i = ri.atan2(xi.abs());
        let theta_i = (FRAC_PI_2 - psi_i).copysign(xi);
        // φ_i − φ_o and cos(φ_i + φ_o) from products, without the two azimuths themselves; a
        // direction on the axis has φ = 0 (atan2(0, 0)).
        let cos_2phi_h = match (ro > 0.0, ri > 0.0) {
            (true, true) => (yi * yo - zi * zo) / (ri * ro),
            (true, false) => yo / ro,
            (false, true) => yi / ri,
            (false, false) => 1.0,
        };
        Angles {
            theta_o,
            psi_i,
            cos_i: psi_i.sin(),
            theta_h: 0.5 * (theta_i + theta_o),
            theta_d: 0.5 * (theta_o - theta_i),
            phi: (zi * yo - yi * zo).atan2(yi * yo + zi * zo),
            cos_2phi_h,
        }
    }
}

/// Unit-area Gaussian with variance `v`.
#[inline]
fn gaussian(x: f64, v: f64) -> f64 {
    (-0.5 * x * x / v).exp() / (TAU * v).sqrt()
}

impl Marschner {
    /// Validates `p` and builds the lobe-albedo and azimuthal sampling tables.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        let mut m = Self::unbuilt(p)?;
        m.build_tables();
        Ok(m)
    }

    /// Validated parameters, tables not yet built.
    fn unbuilt(p: &Params) -> Result<Self, ParamError> {
        check_range("alpha_r", p.alpha_r, -20.0, 20.0)?;
        check_range("beta_r", p.beta_r, 1.0, 30.0)?;
        check_range("eta", p.eta, 1.2, 3.0)?;
        check_range("eccentricity", p.eccentricity, 0.5, 1.0)?;
        check_range("glint", p.glint, 0.0, 10.0)?;
        check_range("caustic_width", p.caustic_width, 1.0, 60.0)?;
        check_range("caustic_fade", p.caustic_fade, 0.05, 2.0)?;
        check_range("caustic_limit", p.caustic_limit, 0.0, 1.0)?;
        let eta = p.eta as f64;
        let a2 = (p.eccentricity as f64).powi(2);
        let eta_star = [
            2.0 * (eta - 1.0) * a2 - eta + 2.0,
            2.0 * (eta - 1.0) / a2 - eta + 2.0,
        ];
        if eta_star[0] < MIN_ETA {
            return Err(ParamError::new(
                "eccentricity",
                p.eccentricity,
                format!(
                    "with eta = {} the effective TRT index η* = 2(η−1)a² − η + 2 = {:.3} is below {MIN_ETA}",
                    p.eta, eta_star[0]
                ),
            ));
        }
        let sigma = p.pigment.sigma_a(COLOR_BETA_N)?;
        let alpha_r = (p.alpha_r as f64).to_radians();
        let beta_r = (p.beta_r as f64).to_radians();
        Ok(Marschner {
            params: p.clone(),
            alpha: [alpha_r, -0.5 * alpha_r, -1.5 * alpha_r],
            var: [beta_r, 0.5 * beta_r, 2.0 * beta_r].map(|b| b * b),
            eta,
            eta_star,
            sigma_a: [sigma.x, sigma.y, sigma.z].map(f64::from),
            glint: Some(Glint {
                k_g: p.glint as f64,
                width: (p.caustic_width as f64).to_radians(),
                fade: p.caustic_fade as f64,
                limit: p.caustic_limit as f64,
            }),
            fresnel: FresnelMode::Bravais,
            rows: Default::default(),
            lobe_table: Vec::new(),
        })
    }

    /// η*(φ_h) of an elliptical fiber (Marschner eq. for the TRT lobe).
    fn eta_trt(&self, cos_2phi_h: f64) -> f64 {
        let [e1, e2] = self.eta_star;
        0.5 * ((e1 + e2) + cos_2phi_h * (e1 - e2))
    }

    fn slice(&self, eta: f64, theta_d: f64) -> Slice {
        let (s, c) = theta_d.sin_cos();
        Slice::new(eta, s, c, self.fresnel)
    }

    /// N_p per channel; `trt` is the slice at the TRT index.
    fn n_p(&self, p: usize, slice: &Slice, trt: &Slice, phi: f64) -> [f64; 3] {
        match (p, &self.glint) {
            (2, Some(g)) => trt.n_trt(phi, &self.sigma_a, g),
            (2, None) => trt.n_roots(2, phi, &self.sigma_a),
            _ => slice.n_roots(p as u32, phi, &self.sigma_a),
        }
    }

    /// S(ω_i, ω_o) per channel.
    fn s(&self, a: &Angles) -> [f64; 3] {
        self.s_lobes(a, 0..3)
    }

    /// S restricted to the lobes `lobes` (0 R, 1 TT, 2 TRT).
    fn s_lobes(&self, a: &Angles, lobes: std::ops::Range<usize>) -> [f64; 3] {
        let slice = self.slice(self.eta, a.theta_d);
        let trt = if self.eta_star[0] == self.eta_star[1] {
            slice
        } else {
            self.slice(self.eta_trt(a.cos_2phi_h), a.theta_d)
        };
        let cos_d = a.theta_d.cos().max(1e-5);
        let mut out = [0.0; 3];
        for p in lobes {
            let m = gaussian(a.theta_h - self.alpha[p], self.var[p]);
            let n = self.n_p(p, &slice, &trt, a.phi);
            for (o, v) in out.iter_mut().zip(n) {
                *o += m * v;
            }
        }
        out.map(|v| v / (cos_d * cos_d))
    }

    fn build_tables(&mut self) {
        let delta = TAU / NODES as f64;
        let eccentric = self.eta_star[0] != self.eta_star[1];
        let mut rows: [Vec<AzimuthPdf>; 3] = Default::default();
        let mut energy: [Vec<f64>; 3] = Default::default();
        for j in 0..ROWS {
            let theta_d = FRAC_PI_2 * j as f64 / (ROWS - 1) as f64;
            let slice = self.slice(self.eta, theta_d);
            for p in 0..3 {
                let mut v = vec![0.0; NODES];
                // Every N_p tabulated here is even in φ: fill half, mirror.
                for k in 0..=NODES / 2 {
                    let phi_k = -PI + k as f64 * delta;
                    let sum: f64 = (0..SUB)
                        .map(|s| {
                            let phi =
                                wrap_pi(phi_k + delta * ((s as f64 + 0.5) / SUB as f64 - 0.5));
                            // The frame puts ω_o at φ_o = π/2, so cos 2φ_h = cos(φ + π) = −cos φ:
                            // the eccentric TRT index is a function of the tabulated φ.
                            let trt = if eccentric {
                                self.slice(self.eta_trt(-phi.cos()), theta_d)
                            } else {
                                slice
                            };
                            let n = self.n_p(p, &slice, &trt, phi);
                            (n[0] + n[1] + n[2]) / 3.0
                        })
                        .sum();
                    v[k] = sum / SUB as f64;
                    if k > 0 && k < NODES / 2 {
                        v[NODES - k] = v[k];
                    }
                }
                let integral = delta * v.iter().sum::<f64>();
                let floor = FLOOR * integral / TAU;
                v.iter_mut().for_each(|x| *x = x.max(floor));
                energy[p].push(integral);
                rows[p].push(AzimuthPdf::new(v));
            }
        }
        self.rows = rows;
        // Lobe albedos E_p(θ_o) = ∫ cos²θ_i M_p(θ_h) ∫N_p dφ / cos²θ_d dθ_i (channel mean, glints
        // included): selecting lobes in proportion to them is what one-sample MIS over lobes
        // wants.
        let dti = PI / LOBE_QUAD as f64;
        self.lobe_table = (0..LOBE_ROWS)
            .map(|r| {
                let theta_o = -FRAC_PI_2 + PI * r as f64 / (LOBE_ROWS - 1) as f64;
                let mut e = [0.0; 3];
                for k in 0..LOBE_QUAD {
                    let theta_i = -FRAC_PI_2 + dti * (k as f64 + 0.5);
                    let (theta_h, theta_d) = (0.5 * (theta_i + theta_o), 0.5 * (theta_o - theta_i));
                    let (j, w) = Self::row_mix(theta_d);
                    let cos_d = theta_d.cos().max(1e-5);
                    let common = (theta_i.cos() / cos_d).powi(2) * dti;
                    for (p, ep) in e.iter_mut().enumerate() {
                        let n = (1.0 - w) * energy[p][j] + w * energy[p][j + 1];
                        *ep += common * gaussian(theta_h - self.alpha[p], self.var[p]) * n;
                    }
                }
                let total = e[0] + e[1] + e[2];
                if total > 0.0 {
                    e.map(|x| x / total)
                } else {
                    // Every lobe underflowed (extreme tilt and width): any fixed choice is exact.
                    [1.0 / 3.0; 3]
                }
            })
            .collect();
    }

    /// The two table rows around |θ_d| and the weight of the upper one.
    fn row_mix(theta_d: f64) -> (usize, f64) {
        let x = (theta_d.abs() / FRAC_PI_2 * (ROWS - 1) as f64).clamp(0.0, (ROWS - 1) as f64);
        let j = (x as usize).min(ROWS - 2);
        (j, x - j as f64)
    }

    /// Lobe-selection probabilities, interpolated in θ_o (a function of ω_o only).
    fn lobe_probs(&self, theta_o: f64) -> [f64; 3] {
        let x = ((theta_o + FRAC_PI_2) / PI * (LOBE_ROWS - 1) as f64)
            .clamp(0.0, (LOBE_ROWS - 1) as f64);
        let r = (x as usize).min(LOBE_ROWS - 2);
        let w = x - r as f64;
        let (a, b) = (self.lobe_table[r], self.lobe_table[r + 1]);
        std::array::from_fn(|p| (1.0 - w) * a[p] + w * b[p])
    }

    /// The distribution of θ_h for lobe p: M_p's Gaussian on the θ_h range that keeps
    /// θ_i ∈ [−π/2, π/2], windowed toward both ends (see [`RAMP`]).
    fn theta_h_dist(&self, p: usize, theta_o: f64) -> WindowedNormal {
        WindowedNormal {
            mean: self.alpha[p],
            sd: self.var[p].sqrt(),
            lo: 0.5 * (theta_o - FRAC_PI_2),
            hi: 0.5 * (theta_o + FRAC_PI_2),
            ramp: RAMP,
        }
    }

    fn pdf_angles(&self, a: &Angles) -> f64 {
        let probs = self.lobe_probs(a.theta_o);
        let (j, w) = Self::row_mix(a.theta_d);
        let mut sum = 0.0;
        for (p, &prob) in probs.iter().enumerate() {
            if prob == 0.0 {
                continue;
            }
            let q = self.theta_h_dist(p, a.theta_o).gauss_density(a.theta_h);
            let rows = &self.rows[p];
            let n = (1.0 - w) * rows[j].pdf(a.phi) + w * rows[j + 1].pdf(a.phi);
            sum += prob * q * n;
        }
        // The window (the same for every lobe: it depends on θ_i only) over cos θ_i, the
        // dθ_i dφ → dω conversion; finite as ψ → 0. ½ = |dθ_h/dθ_i|.
        let psi = a.psi_i;
        let window_over_cos = if psi >= 2.0 * RAMP {
            1.0 / a.cos_i
        } else if psi > 1e-8 {
            psi / psi.sin() / (2.0 * RAMP)
        } else {
            1.0 / (2.0 * RAMP)
        };
        0.5 * sum * window_over_cos
    }
}

impl Bcsdf for Marschner {
    fn eval(&self, wo: Vec3, wi: Vec3, _h: f32) -> Rgb {
        let a = Angles::new(wo, wi);
        let s = self.s(&a);
        Rgb::from_array(s.map(|v| (v * a.cos_i) as f32))
    }

    fn lobe_names(&self) -> &'static [&'static str] {
        &["R", "TT", "TRT"]
    }

    fn eval_lobe(&self, wo: Vec3, wi: Vec3, _h: f32, p: usize) -> Rgb {
        if p >= 3 {
            return Rgb::ZERO;
        }
        let a = Angles::new(wo, wi);
        Rgb::from_array(self.s_lobes(&a, p..p + 1).map(|v| (v * a.cos_i) as f32))
    }

    fn sample(&self, wo: Vec3, _h: f32, u: [f32; 4]) -> Option<BcsdfSample> {
        let (theta_o, phi_o) = spherical(wo);
        let probs = self.lobe_probs(theta_o);
        let u0 = u[0] as f64;
        let p = if u0 < probs[0] {
            0
        } else if u0 < probs[0] + probs[1] || probs[2] == 0.0 {
            1
        } else {
            2
        };
        let theta_h = self.theta_h_dist(p, theta_o).sample(u[1] as f64)?;
        let theta_i = (2.0 * theta_h - theta_o).clamp(-FRAC_PI_2, FRAC_PI_2);
        let (j, w) = Self::row_mix(theta_o - theta_h);
        let row = if (u[2] as f64) < w { j + 1 } else { j };
        let phi = self.rows[p][row].sample(u[3] as f64);
        let (sin_i, cos_i) = theta_i.sin_cos();
        let wi = fiber_direction(sin_i as f32, cos_i as f32, (phi_o + phi) as f32);
        // Value and density from the same code path as eval/pdf.
        let a = Angles::new(wo, wi);
        let pdf = self.pdf_angles(&a) as f32;
        let s = self.s(&a);
        (pdf > 0.0 && pdf.is_finite()).then(|| BcsdfSample {
            wi,
            f: Rgb::from_array(s.map(|v| (v * a.cos_i) as f32)),
            pdf,
        })
    }

    fn pdf(&self, wo: Vec3, wi: Vec3, _h: f32) -> f32 {
        self.pdf_angles(&Angles::new(wo, wi)) as f32
    }
}

/// Parameter sets the statistical tests run on this model ([`crate::HairModel::test_instances`]).
pub fn test_instances() -> Vec<TestInstance<Params>> {
    let with = |name: &str, params: Params| TestInstance {
        name: name.into(),
        params,
        white_furnace: false,
    };
    vec![
        with("brown", Params::default()),
        with(
            "blond",
            Params {
                pigment: Pigment::SigmaA((0.06, 0.10, 0.20)),
                ..Params::default()
            },
        ),
        with(
            "dark",
            Params {
                pigment: Pigment::Melanin {
                    eumelanin: 8.0,
                    pheomelanin: 0.0,
                    tint: crate::pigment::NO_TINT,
                },
                ..Params::default()
            },
        ),
        with(
            "clear",
            Params {
                pigment: Pigment::SigmaA((0.0, 0.0, 0.0)),
                ..Params::default()
            },
        ),
        with(
            "eccentric",
            Params {
                pigment: Pigment::SigmaA((0.06, 0.10, 0.20)),
                eccentricity: 0.9,
                ..Params::default()
            },
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use tress_core::math::luminance;
    use tress_core::sampling::sample_uniform_sphere;
    use tress_core::stats::{sidak_alpha, SphereChi2};
    use tress_core::Sampler;

    fn build(p: &Params) -> Marschner {
        Marschner::new(p).unwrap()
    }

    fn dir(theta: f64, phi: f64) -> Vec3 {
        fiber_direction(theta.sin() as f32, theta.cos() as f32, phi as f32)
    }

    /// The configuration of the oracle in docs/src/reference/hair-maths.md#marschners-energy:
    /// α = 0, σ_a = 0, no caustic treatment and
    /// unpolarised Fresnel. "Polarisation ignored" there means the exact dielectric Fresnel with η
    /// at the 3D incidence angle (cos θ_d cos γ), not Fresnel with η' in the cross-section: only the
    /// former reproduces its Σ_p ½∫A_p dh = 0.992 / 0.986 / 0.886 at θ_d = 0/45/80° (η' gives
    /// 0.992 / 0.984 / 0.865). Only `eval` is used, so no tables are built.
    fn oracle_config(beta_r: f32) -> Marschner {
        let mut m = Marschner::unbuilt(&Params {
            alpha_r: 0.0,
            beta_r,
            pigment: Pigment::SigmaA((0.0, 0.0, 0.0)),
            ..Params::default()
        })
        .unwrap();
        m.glint = None;
        m.fresnel = FresnelMode::Unpolarised3d;
        m
    }

    /// Independent reference for E(θ_o): the azimuth integrated analytically (∫N_p dφ = ½∫A_p dh)
    /// with a textbook unpolarised Fresnel written here, then a θ_i quadrature.
    fn energy_by_h(beta_r: f64, theta_o: f64) -> f64 {
        let eta: f64 = 1.55;
        let fresnel = |n: f64, cos_i: f64| {
            let sin_t2 = (1.0 - cos_i * cos_i) / (n * n);
            if sin_t2 >= 1.0 {
                return 1.0;
            }
            let cos_t = (1.0 - sin_t2).sqrt();
            let rs = (cos_i - n * cos_t) / (cos_i + n * cos_t);
            let rp = (n * cos_i - cos_t) / (n * cos_i + cos_t);
            0.5 * (rs * rs + rp * rp)
        };
        let beta = [beta_r, beta_r / 2.0, beta_r * 2.0];
        let (nt, nh) = (2000, 300);
        let mut e = 0.0;
        for k in 0..nt {
            let ti = -FRAC_PI_2 + PI * (k as f64 + 0.5) / nt as f64;
            let (th, td) = (0.5 * (ti + theta_o), 0.5 * (theta_o - ti));
            let ep = (eta * eta - td.sin().powi(2)).sqrt() / td.cos();
            let cos_tt = (1.0 - (td.sin() / eta).powi(2)).sqrt();
            let mut sum = 0.0;
            for (p, b) in beta.iter().enumerate() {
                let mut half_int = 0.0;
                for l in 0..nh {
                    let h: f64 = -1.0 + 2.0 * (l as f64 + 0.5) / nh as f64;
                    let cos_gi = (1.0 - h * h).sqrt();
                    let cos_gt = (1.0 - h * h / (ep * ep)).sqrt();
                    let f_in = fresnel(eta, td.cos() * cos_gi);
                    let a = match p {
                        0 => f_in,
                        _ => {
                            (1.0 - f_in).powi(2)
                                * fresnel(1.0 / eta, cos_tt * cos_gt).powi(p as i32 - 1)
                        }
                    };
                    half_int += 0.5 * a * 2.0 / nh as f64;
                }
                sum += (-0.5 * th * th / (b * b)).exp() / (TAU.sqrt() * b) * half_int;
            }
            e += ti.cos().powi(2) * sum / td.cos().powi(2) * PI / nt as f64;
        }
        e
    }

    /// E(θ_o) = ∫ eval dω_i by direct quadrature (N_p is even in φ: integrate φ ∈ [0, π], ×2).
    fn energy_by_eval(m: &Marschner, theta_o: f64) -> f64 {
        let wo = dir(theta_o, FRAC_PI_2);
        let (nt, np) = (1000, 768);
        let mut e = 0.0;
        for k in 0..nt {
            let ti = -FRAC_PI_2 + PI * (k as f64 + 0.5) / nt as f64;
            let mut row = 0.0;
            for l in 0..np {
                let phi = PI * (l as f64 + 0.5) / np as f64;
                row += m.eval(wo, dir(ti, FRAC_PI_2 + phi), 0.0).x as f64;
            }
            e += row * 2.0 * PI / np as f64 * ti.cos() * PI / nt as f64;
        }
        e
    }

    /// Marschner is not energy conserving; regression oracle
    /// (docs/src/reference/hair-maths.md#marschners-energy).
    #[test]
    fn energy_matches_the_published_oracle() {
        let m = oracle_config(5.0);
        let beta = 5f64.to_radians();
        for (deg, want) in [
            (0.0, 1.96),
            (30.0, 1.95),
            (60.0, 1.87),
            (80.0, 1.62),
            (89.0, 2.47),
        ] {
            let t = f64::to_radians(deg);
            let direct = energy_by_eval(&m, t);
            let by_h = energy_by_h(beta, t);
            println!("θ_o = {deg:>2}°: E = {direct:.4} (eval quadrature), {by_h:.4} (h quadrature), oracle {want}");
            assert!(
                (direct / by_h - 1.0).abs() < 5e-3,
                "θ_o={deg}: {direct} vs {by_h}"
            );
            assert!(
                (direct / want - 1.0).abs() < 0.02,
                "θ_o={deg}: {direct} vs oracle {want}"
            );
        }
    }

    /// S(ω_i, ω_o) = S(ω_o, ω_i) (θ_h, |θ_d|, |φ| and cos 2φ_h are all symmetric;
    /// docs/src/reference/hair-maths.md#symmetry).
    #[test]
    fn reciprocity() {
        let mut rng = Sampler::from_seed(11);
        for inst in test_instances() {
            let m = build(&inst.params);
            for _ in 0..20_000 {
                let wo = sample_uniform_sphere(rng.next_2d());
                let wi = sample_uniform_sphere(rng.next_2d());
                let cos = |w: Vec3| spherical(w).0.cos() as f32;
                let a = m.eval(wo, wi, 0.3) / cos(wi);
                let b = m.eval(wi, wo, -0.7) / cos(wo);
                let tol = 1e-4 * a.max_element().max(b.max_element()) + 1e-20;
                assert!(
                    (a - b).abs().max_element() <= tol,
                    "{}: {a} vs {b}",
                    inst.name
                );
            }
        }
    }

    #[test]
    fn values_are_finite_non_negative_and_h_independent() {
        let mut rng = Sampler::from_seed(3);
        let m = build(&Params::default());
        let poles = [Vec3::X, -Vec3::X, Vec3::new(1.0, 1e-7, 0.0).normalize()];
        for k in 0..50_000 {
            let wo = if k < 3 {
                poles[k]
            } else {
                sample_uniform_sphere(rng.next_2d())
            };
            let wi = if k % 7 == 0 {
                poles[k % 3]
            } else {
                sample_uniform_sphere(rng.next_2d())
            };
            let f = m.eval(wo, wi, -1.0);
            assert!(f.is_finite() && f.min_element() >= 0.0, "{wo} {wi}: {f}");
            assert_eq!(f, m.eval(wo, wi, 1.0));
            let pdf = m.pdf(wo, wi, 0.0);
            assert!(pdf.is_finite() && pdf >= 0.0);
            if let Some(s) = m.sample(wo, 1.0, rng.next_4d()) {
                assert!(s.f.is_finite() && s.pdf.is_finite() && s.pdf > 0.0);
            }
        }
    }

    /// ∫ pdf dω = 1 by deterministic quadrature (dω = cos θ dθ dφ cancels the pdf's 1/cos θ_i).
    #[test]
    fn pdf_integrates_to_one() {
        // θ_i midpoint rule; in φ, 512 cells hold exactly two per linear piece of the tables, so
        // the φ quadrature is exact.
        for inst in test_instances().into_iter().filter(|t| t.name != "dark") {
            let m = build(&inst.params);
            for deg in [0.0, 35.0, -70.0, 89.9] {
                let wo = dir(f64::to_radians(deg), FRAC_PI_2);
                let (nt, np) = (400, 512);
                let mut total = 0.0;
                for k in 0..nt {
                    let ti = -FRAC_PI_2 + PI * (k as f64 + 0.5) / nt as f64;
                    for l in 0..np {
                        let phi = -PI + TAU * (l as f64 + 0.5) / np as f64;
                        let p = m.pdf(wo, dir(ti, FRAC_PI_2 + phi), 0.0) as f64;
                        total += p * ti.cos() * (PI / nt as f64) * (TAU / np as f64);
                    }
                }
                assert!(
                    (total - 1.0).abs() < 2e-3,
                    "{} θ_o={deg}: ∫pdf = {total}",
                    inst.name
                );
            }
        }
    }

    #[test]
    fn sampler_matches_pdf_chi2() {
        // θ_o = −80° puts the R lobe against the fiber axis (the window's job); φ_o ≠ π/2 checks
        // that the pdf stays exact off the canonical frame.
        let cases: Vec<(Params, f64)> = test_instances()
            .into_iter()
            .flat_map(|t| {
                let extra = matches!(t.name.as_str(), "brown" | "eccentric");
                std::iter::once((t.params.clone(), -80.0)).chain(extra.then_some((t.params, 20.0)))
            })
            .collect();
        let alpha = sidak_alpha(0.01, cases.len());
        for (k, (params, deg)) in cases.iter().enumerate() {
            let m = build(params);
            let wo = dir(f64::to_radians(*deg), 1.3);
            let chi = SphereChi2 {
                pole: Vec3::X,
                samples: 200_000,
                ..Default::default()
            };
            let (out, _, _) = chi.run(
                40 + k as u64,
                |s| m.sample(wo, 0.0, s.next_4d()).map(|s| s.wi),
                |wi| m.pdf(wo, wi, 0.0) as f64,
            );
            assert!(out.p_value > alpha, "{params:?} θ_o={deg}: {out:?}");
        }
    }

    /// Samples carry exactly eval and pdf, and the weight f/pdf stays bounded away from the
    /// singular corner θ_o → ±90°, θ_i → ∓90° (where S ∝ 1/cos²θ_d diverges, so no finite pdf
    /// can bound f/pdf). With a perfect sampler the weight would be ≈ 2·cos²θ_i/cos²θ_d·Σ_p∫N_p
    /// (≤ 2 × 4 × 1): a bound of 10 leaves room only for table and lobe-selection mismatch.
    #[test]
    fn sample_weights_are_consistent_and_bounded() {
        let mut rng = Sampler::from_seed(8);
        for inst in test_instances() {
            let m = build(&inst.params);
            let mut worst: f32 = 0.0;
            for k in 0..100_000 {
                // Half in the canonical frame (φ_o = π/2, |θ_o| ≤ 80°), half anywhere.
                let wo = if k % 2 == 0 {
                    dir(
                        (2.0 * rng.next_1d() as f64 - 1.0) * 80f64.to_radians(),
                        FRAC_PI_2,
                    )
                } else {
                    sample_uniform_sphere(rng.next_2d())
                };
                let Some(s) = m.sample(wo, 0.0, rng.next_4d()) else {
                    continue;
                };
                assert_eq!(s.f, m.eval(wo, s.wi, 0.0));
                assert_eq!(s.pdf, m.pdf(wo, s.wi, 0.0));
                if k % 2 == 0 {
                    worst = worst.max(luminance(s.f) / s.pdf);
                }
            }
            println!("{}: max f/pdf = {worst}", inst.name);
            assert!(worst < 10.0, "{}: max f/pdf = {worst}", inst.name);
        }
    }

    #[test]
    fn invalid_parameters_are_rejected() {
        let bad = [
            Params {
                beta_r: 0.0,
                ..Params::default()
            },
            Params {
                alpha_r: f32::NAN,
                ..Params::default()
            },
            Params {
                eta: 1.0,
                ..Params::default()
            },
            Params {
                eccentricity: 0.55,
                ..Params::default()
            },
            Params {
                caustic_fade: 0.0,
                ..Params::default()
            },
            Params {
                pigment: Pigment::SigmaA((-1.0, 0.0, 0.0)),
                ..Params::default()
            },
        ];
        for p in bad {
            assert!(Marschner::new(&p).is_err(), "{p:?}");
        }
        let e = Marschner::new(&Params {
            eccentricity: 0.55,
            ..Params::default()
        })
        .unwrap_err();
        assert_eq!(e.field, "eccentricity");
    }

    #[test]
    fn documented_ron_example_parses() {
        use crate::HairModel;
        let opts = ron::Options::default()
            .with_default_extension(ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES);
        let text = "Marschner(alpha_r: -7.5, beta_r: 7.5, pigment: Melanin(eumelanin: 0.4), \
                    eccentricity: 0.9)";
        let model: HairModel = opts.from_str(text).unwrap();
        let want = Params {
            pigment: Pigment::Melanin {
                eumelanin: 0.4,
                pheomelanin: 0.0,
                tint: crate::pigment::NO_TINT,
            },
            eccentricity: 0.9,
            ..Params::default()
        };
        assert_eq!(model, HairModel::Marschner(want));
        assert!(opts.from_str::<HairModel>("Marschner(beta: 5.0)").is_err());
        assert!(model
            .build(&tress_core::prepare::Preparation::new())
            .is_ok());
    }

    /// Costs (run with `--ignored --nocapture`).
    #[test]
    #[ignore]
    fn timing() {
        use std::hint::black_box;
        use std::time::Instant;
        let t0 = Instant::now();
        let m = build(&Params::default());
        println!("tables: {:.1} ms", t0.elapsed().as_secs_f64() * 1e3);
        let mut rng = Sampler::from_seed(1);
        type Case = (Vec3, Vec3, [f32; 4]);
        let dirs: Vec<Case> = (0..100_000)
            .map(|_| {
                (
                    sample_uniform_sphere(rng.next_2d()),
                    sample_uniform_sphere(rng.next_2d()),
                    rng.next_4d(),
                )
            })
            .collect();
        let time = |name: &str, f: &dyn Fn(&Case) -> f32| {
            let t = Instant::now();
            let mut acc = 0.0;
            for d in &dirs {
                acc += f(black_box(d));
            }
            black_box(acc);
            println!(
                "{name}: {:.0} ns/call",
                t.elapsed().as_secs_f64() * 1e9 / dirs.len() as f64
            );
        };
        time("eval", &|(wo, wi, _)| m.eval(*wo, *wi, 0.0).x);
        time("pdf", &|(wo, wi, _)| m.pdf(*wo, *wi, 0.0));
        time("sample", &|(wo, _, u)| {
            m.sample(*wo, 0.0, *u).map_or(0.0, |s| s.pdf)
        });
    }
}
