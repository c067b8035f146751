//! The energy-conserving hair BCSDF of d'Eon, Francois, Hill, Letteri and Aubry 2011 ("An
//! Energy-Conserving Hair Reflectance Model"), importance-sampled after d'Eon, Marschner and
//! Hanika 2013 ("Importance Sampling for Physically-Based Hair Fiber Models").
//!
//! `eval = f·cos θ_i = Σ_{p=0}^{3} M_p(θ_i, θ_o) · N_p(φ, θ_o)` with φ = φ_i − φ_o:
//! - **M_p** is the von Mises–Fisher ("Bessel") longitudinal lobe of variance `v_p`, normalised so
//!   that `∫ M_p cos θ_i dθ_i = 1`. It is evaluated as `exp(ln c(v) − b + ln I₀(a))` with
//!   `a = cos θ_i cos θ_o / v`, `b = sin θ_i sin θ_o / v` and the normaliser
//!   `ln c(v) = −ln v − 1/v − ln(1 − e^{−2/v})` (exact for every v, no overflow); I₀ comes from the
//!   Abramowitz–Stegun polynomial fits (9.8.1 below a = 3.75, the e^{−a}-scaled 9.8.2 above;
//!   relative error < 4.8e-7, so the switch is continuous to < 6.4e-7).
//!   Scale tilt as in pbrt: M_R, M_TT, M_TRT use θ_o − 2α, θ_o + α, θ_o + 4α.
//! - **N_p(φ) = ½ ∫ A_p(h) D_p(φ − Φ(p, h)) dh** with `Φ = 2pγ_t − 2γ_i + pπ`, A_0 = F,
//!   A_1 = (1−F)²T, A_2 = (1−F)²FT² (exact unpolarised Fresnel F of η at cos θ_o cos γ_i,
//!   T = exp(−σ_a·2cos γ_t / cos θ_t)), and D_p a wrapped Gaussian of the lobe's own azimuthal width.
//!   The p ≥ 3 residual `A_3 = (1−F)²F²T³/(1−FT)` is added, azimuthally uniform with M_TRT untilted,
//!   so that with σ_a = 0 the white furnace is exactly 1 (without it, ≈0.89 at grazing angles).
//!
//! **N_p is tabulated over (φ, cos θ_o)**, 128 × 64, at construction — not over cos θ_d as in the
//! paper and in Tungsten. With θ_d the table row moves with θ_i, so the per-lobe M_p (different
//! widths and tilts) weigh the steep grazing-angle variation of the A_p differently: measured with
//! these same tables, the σ_a = 0 furnace at θ_o = 80° is then 0.87 / 0.78 / 0.86 for the three
//! white test instances (0.89 even at r_m = 0.03, from the 2° tilt alone). Over θ_o,
//! `∫ M_p N_p dω = ∫ N_p dφ` exactly and the furnace is 1 by construction (pbrt's choice for η'
//! and A_p). The price is exact reciprocity, which the tilt breaks anyway.
//!
//! Each table cell holds the *cell average* of N_p (the detector is integrated over the cell with
//! erf), so `∫ N_p dφ = ½∫A_p dh` holds exactly at any roughness, and lookups are bilinear
//! (piecewise linear in φ between cell centres). The h integral is a 1024-point midpoint rule in
//! γ_i = asin h, where Φ is smooth. Each lobe's detector has its own width (Tungsten uses β_R for
//! all three).
//!
//! The model is far-field: eval, sample and pdf ignore the hit offset h.
//!
//! **Sampling** (d'Eon 2013, tabulated variant): pick lobe p with probability ∝ luminance of
//! `∫ N_p dφ` at θ_o; sample θ_i from M_p around the tilted cone (stable vMF inversion); pick one
//! of the two bracketing table rows with probability ∝ its lerp weight × row integral; sample φ
//! exactly from that row's piecewise-linear luminance. The resulting density is exactly
//! `pdf = luminance(eval) / Σ_p luminance(∫ N_p dφ)`, so the sample weight f/pdf is
//! `Σ_p ∫N_p dφ · f/luminance(f)`: exactly 1 in a white furnace, and the per-channel
//! albedo/luminance ratio otherwise.
//!
//! | parameter | default | meaning |
//! |---|---|---|
//! | `longitudinal_roughness` | 0.1 | r_m ∈ [0, 1]: β_R = r_m·π/2 rad, β_TT = β_R/2, β_TRT = 2β_R (Marschner's ratios), `v_p = max(β_p, 0.04)²` |
//! | `azimuthal_roughness` | 0.3 | r_n ∈ [0, 1]: detector std-devs β_R = r_n·π/2, β_TT = β_R/2, β_TRT = 2β_R, each ≥ 0.04 rad |
//! | `alpha` | 2 | cuticle scale tilt α in degrees, [−15, 15] |
//! | `eta` | 1.55 | index of refraction, [1.01, 3] |
//! | `pigment` | `Melanin(eumelanin: 1.3)` | absorption σ_a ([`Pigment`]; `Color` uses r_n as Chiang's β_n) |
//!
//! The 0.04 rad floor (≈2.3°) keeps lobes resolvable by the 2.8° table cells and by Monte Carlo;
//! longitudinally it means v ≥ 0.0016, the limit below which public implementations lose M_p.
//!
//! RON: `DEon(longitudinal_roughness: 0.15, azimuthal_roughness: 0.3, alpha: 2.0, eta: 1.55,
//! pigment: Melanin(eumelanin: 1.3, pheomelanin: 0.2))`

use crate::pigment::Pigment;
use crate::{check_range, ModelParams, ParamError, TestInstance};
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use tress_core::math::{erfc, luminance, Rgb, Vec3};
use tress_core::{Bcsdf, BcsdfSample};

/// Table rows: cos θ_o = j / (N_COS − 1).
const N_COS: usize = 64;
/// Table columns: φ cells of width 2π / N_PHI over [−π, π).
const N_PHI: usize = 128;
/// Fine bins per φ cell into which the h-integral's point contributions are splatted.
const SPLAT: usize = 8;
const N_FINE: usize = N_PHI * SPLAT;
/// Midpoint nodes of the h-integral, in γ = asin h.
const N_GAMMA: usize = 1024;
/// Smallest longitudinal or azimuthal lobe std-dev, radians.
const BETA_MIN: f64 = 0.04;
/// Marschner's width ratios R : TT : TRT.
const LOBE_RATIO: [f64; 3] = [1.0, 0.5, 2.0];
/// Where I₀ switches from its small-argument to its exponentially scaled large-argument fit.
const I0_SWITCH: f64 = 3.75;
const CELL: f32 = std::f32::consts::TAU / N_PHI as f32;

/// Parameters of [`DEon`] (module docs).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
#[schemars(rename = "DEonParams")]
pub struct Params {
    /// r_m in [0, 1]: longitudinal lobe width β_R = r_m·π/2 (default 0.1).
    pub longitudinal_roughness: f32,
    /// r_n in [0, 1]: azimuthal lobe width β_R = r_n·π/2 (default 0.3).
    pub azimuthal_roughness: f32,
    /// Degrees.
    pub alpha: f32,
    /// Index of refraction, in [1.01, 3] (default 1.55).
    pub eta: f32,
    /// Absorption inside the fiber (default eumelanin 1.3).
    pub pigment: Pigment,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            longitudinal_roughness: 0.1,
            azimuthal_roughness: 0.3,
            alpha: 2.0,
            eta: 1.55,
            pigment: Pigment::default(),
        }
    }
}

impl ModelParams for Params {
    /// The pigment, converted at the azimuthal roughness.
    fn pigment(&self) -> Option<(&Pigment, f32)> {
        Some((&self.pigment, self.azimuthal_roughness))
    }

    fn pigment_mut(&mut self) -> Option<&mut Pigment> {
        Some(&mut self.pigment)
    }

    /// Scales the longitudinal and azimuthal roughness, within [0, 1].
    fn scale_roughness(&mut self, scale: f32) {
        self.longitudinal_roughness = (self.longitudinal_roughness * scale).clamp(0.0, 1.0);
        self.azimuthal_roughness = (self.azimuthal_roughness * scale).clamp(0.0, 1.0);
    }
}

/// A longitudinal vMF lobe: variance and scale tilt.
#[derive(Clone, Debug)]
struct Longitudinal {
    v: f64,
    /// ln of the normaliser 1 / (2v sinh(1/v)).
    ln_norm: f64,
    /// e^{−2/v}, for the sampler.
    exp_m2v: f64,
    sin_tilt: f64,
    cos_tilt: f64,
}

impl Longitudinal {
    fn new(v: f64, tilt: f64) -> Self {
        let exp_m2v = (-2.0 / v).exp();
        Longitudinal {
            v,
            // 2v sinh(1/v) = v e^{1/v} (1 − e^{−2/v}).
            ln_norm: -v.ln() - 1.0 / v - (-exp_m2v).ln_1p(),
            exp_m2v,
            sin_tilt: tilt.sin(),
            cos_tilt: tilt.cos(),
        }
    }

    /// (sin, cos) of the tilted outgoing angle; cos folded to ≥ 0 so the cone stays a cone.
    #[inline]
    fn tilted(&self, sin_o: f64, cos_o: f64) -> (f64, f64) {
        (
            sin_o * self.cos_tilt + cos_o * self.sin_tilt,
            (cos_o * self.cos_tilt - sin_o * self.sin_tilt).abs(),
        )
    }

    /// M_p(θ_i, θ_o), normalised so that ∫ M cos θ_i dθ_i = 1.
    #[inline]
    fn eval(&self, sin_i: f64, cos_i: f64, sin_o: f64, cos_o: f64) -> f64 {
        let (so, co) = self.tilted(sin_o, cos_o);
        let a = cos_i * co / self.v;
        let b = sin_i * so / self.v;
        if a <= I0_SWITCH {
            (self.ln_norm - b).exp() * i0_small(a)
        } else {
            // e^{a} folded into the exponent: a − b − 1/v ≤ 0, so nothing overflows.
            (self.ln_norm - b + a).exp() * i0_scaled_large(a)
        }
    }

    /// Samples (sin θ_i, cos θ_i) with density M_p cos θ_i: a vMF direction around the mirrored,
    /// tilted cone direction, read off as an elevation (d'Eon 2013; stable for small v).
    #[inline]
    fn sample(&self, sin_o: f64, cos_o: f64, u1: f32, u2: f32) -> (f64, f64) {
        let (so, co) = self.tilted(sin_o, cos_o);
        // 1 − u ∈ (0, 1]: the logarithm stays finite even when e^{−2/v} underflows.
        let w = 1.0 - u1 as f64;
        let cos_s = (1.0 + self.v * (w + (1.0 - w) * self.exp_m2v).ln()).clamp(-1.0, 1.0);
        let sin_s = (1.0 - cos_s * cos_s).max(0.0).sqrt();
        let sin_i = (-cos_s * so + sin_s * (TAU * u2 as f64).cos() * co).clamp(-1.0, 1.0);
        (sin_i, (1.0 - sin_i * sin_i).max(0.0).sqrt())
    }
}

/// I₀(x) for 0 ≤ x ≤ 3.75: Abramowitz & Stegun 9.8.1, error < 1.6e-7 (I₀ ≥ 1, so relative).
#[inline]
fn i0_small(x: f64) -> f64 {
    const C: [f64; 7] = [
        1.0, 3.5156229, 3.0899424, 1.2067492, 0.2659732, 0.0360768, 0.0045813,
    ];
    let t2 = (x / I0_SWITCH) * (x / I0_SWITCH);
    C.iter().rev().fold(0.0, |acc, c| acc * t2 + c)
}

/// e^{−x} I₀(x) for x ≥ 3.75: Abramowitz & Stegun 9.8.2; the fit of √x e^{−x} I₀ ≥ 0.3989 is good
/// to 1.9e-7, i.e. < 4.8e-7 relative.
#[inline]
fn i0_scaled_large(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.39894228,
        0.01328592,
        0.00225319,
        -0.00157565,
        0.00916281,
        -0.02057706,
        0.02635537,
        -0.01647633,
        0.00392377,
    ];
    let r = I0_SWITCH / x;
    C.iter().rev().fold(0.0, |acc, c| acc * r + c) / x.sqrt()
}

/// ln I₀(x), with the same branches as [`Longitudinal::eval`].
#[cfg(test)]
fn ln_i0(x: f64) -> f64 {
    if x <= I0_SWITCH {
        i0_small(x).ln()
    } else {
        x + i0_scaled_large(x).ln()
    }
}

/// Unpolarised Fresnel reflectance of a dielectric of index η > 1 seen from outside.
fn fresnel(cos_i: f64, eta: f64) -> f64 {
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    let cos_t = (1.0 - sin_t2).max(0.0).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// Standard normal mass on [lo, hi], accurate in both tails.
fn normal_mass(lo: f64, hi: f64) -> f64 {
    let s = std::f64::consts::FRAC_1_SQRT_2;
    if lo >= 0.0 {
        0.5 * (erfc(lo * s) - erfc(hi * s))
    } else if hi <= 0.0 {
        0.5 * (erfc(-hi * s) - erfc(-lo * s))
    } else {
        1.0 - 0.5 * erfc(hi * s) - 0.5 * erfc(-lo * s)
    }
}

/// Wraps an angle to [−π, π).
#[inline]
fn wrap(x: f64) -> f64 {
    (x + PI).rem_euclid(TAU) - PI
}

/// `k[d]`: average over a table cell of a wrapped Gaussian (std-dev `beta`) centred on a fine bin,
/// when the cell starts `d` fine bins after it. Renormalised so each fine bin's mass lands in the
/// cells exactly (for every sub-cell offset).
fn detector_kernel(beta: f64) -> Vec<f64> {
    let fine = TAU / N_FINE as f64;
    let cell = TAU / N_PHI as f64;
    let images = (8.0 * beta / TAU).ceil() as i32 + 1;
    let mut k: Vec<f64> = (0..N_FINE)
        .map(|d| {
            let x0 = wrap(d as f64 * fine);
            (-images..=images)
                .map(|n| {
                    let c = x0 + n as f64 * TAU;
                    normal_mass(c / beta, (c + cell) / beta)
                })
                .sum::<f64>()
                / cell
        })
        .collect();
    for offset in 0..SPLAT {
        let mass: f64 = k[offset..].iter().step_by(SPLAT).sum::<f64>() * cell;
        k[offset..]
            .iter_mut()
            .step_by(SPLAT)
            .for_each(|x| *x /= mass);
    }
    k
}

/// Attenuations A_0..A_3 at one (cos θ, h) per RGB channel, and the exit azimuths Φ(p) for
/// p = 0, 1, 2. `eta_cos` = η' cos θ = √(η² − sin²θ).
fn attenuations(cos_o: f64, eta: f64, sigma_a: [f64; 3], gamma: f64) -> ([[f64; 3]; 4], [f64; 3]) {
    let sin_o2 = 1.0 - cos_o * cos_o;
    let eta_cos = (eta * eta - sin_o2).sqrt();
    let cos_theta_t = eta_cos / eta;
    let (h, cos_g) = gamma.sin_cos();
    let sin_gt = h * cos_o / eta_cos;
    let gamma_t = sin_gt.asin();
    let cos_gt = (1.0 - sin_gt * sin_gt).max(0.0).sqrt();
    let f = fresnel(cos_o * cos_g, eta);
    let chord = 2.0 * cos_gt / cos_theta_t;
    let mut a = [[0.0; 3]; 4];
    for c in 0..3 {
        let t = if sigma_a[c] > 0.0 {
            (-sigma_a[c] * chord).exp()
        } else {
            1.0
        };
        let ft = f * t;
        a[0][c] = f;
        a[1][c] = (1.0 - f) * (1.0 - f) * t;
        a[2][c] = a[1][c] * ft;
        // Σ_{p≥3} A_p; FT = 1 only when F = 1, where (1−F)² already makes it 0.
        a[3][c] = if ft < 1.0 {
            a[2][c] * ft / (1.0 - ft)
        } else {
            0.0
        };
    }
    let phi = std::array::from_fn(|p| {
        let p = p as f64;
        2.0 * p * gamma_t - 2.0 * gamma + p * PI
    });
    (a, phi)
}

/// One lobe's N_p(φ, cos θ_o) table and its sampling data.
#[derive(Clone, Debug)]
struct AzimuthalTable {
    /// Cell averages of N_p, row-major [row][cell]; the function is linear between cell centres.
    rgb: Vec<Rgb>,
    lum: Vec<f32>,
    /// Per row, the normalised CDF over the N_PHI segments joining consecutive (cyclic) centres.
    cdf: Vec<f32>,
    /// Per row, ∫ luminance(N_p) dφ.
    lum_integral: Vec<f32>,
}

impl AzimuthalTable {
    fn new(rgb: Vec<Rgb>) -> Self {
        let lum: Vec<f32> = rgb.iter().map(|&c| luminance(c).max(0.0)).collect();
        let mut cdf = vec![0.0f32; N_COS * (N_PHI + 1)];
        let mut lum_integral = vec![0.0f32; N_COS];
        for j in 0..N_COS {
            let l = &lum[j * N_PHI..(j + 1) * N_PHI];
            let mut acc = vec![0.0f64; N_PHI + 1];
            for k in 0..N_PHI {
                acc[k + 1] = acc[k] + 0.5 * (l[k] + l[(k + 1) % N_PHI]) as f64 * CELL as f64;
            }
            let total = acc[N_PHI];
            lum_integral[j] = total as f32;
            let row = &mut cdf[j * (N_PHI + 1)..(j + 1) * (N_PHI + 1)];
            for (c, a) in row.iter_mut().zip(&acc) {
                *c = if total > 0.0 { (a / total) as f32 } else { 0.0 };
            }
        }
        AzimuthalTable {
            rgb,
            lum,
            cdf,
            lum_integral,
        }
    }

    #[inline]
    fn value(&self, row: RowLerp, col: PhiLerp) -> Rgb {
        let at = |j: usize| {
            let r = &self.rgb[j * N_PHI..(j + 1) * N_PHI];
            r[col.k0] * (1.0 - col.f) + r[col.k1] * col.f
        };
        at(row.j) * (1.0 - row.t) + at(row.j + 1) * row.t
    }

    /// ∫ luminance(N_p) dφ at the interpolated row.
    #[inline]
    fn lum_integral(&self, row: RowLerp) -> f32 {
        self.lum_integral[row.j] * (1.0 - row.t) + self.lum_integral[row.j + 1] * row.t
    }

    /// φ with density luminance(N_p(φ, row)) / lum_integral(row): one of the two rows with
    /// probability ∝ weight × integral (`u_row`), then exactly from its piecewise-linear shape.
    fn sample(&self, row: RowLerp, u_row: f32, u: f32) -> f32 {
        let w0 = (1.0 - row.t) * self.lum_integral[row.j];
        let w1 = row.t * self.lum_integral[row.j + 1];
        let j = if u_row * (w0 + w1) < w0 {
            row.j
        } else {
            row.j + 1
        };
        let cdf = &self.cdf[j * (N_PHI + 1)..(j + 1) * (N_PHI + 1)];
        let k = cdf
            .partition_point(|&c| c <= u)
            .saturating_sub(1)
            .min(N_PHI - 1);
        let width = cdf[k + 1] - cdf[k];
        let uk = if width > 0.0 {
            ((u - cdf[k]) / width).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let l = &self.lum[j * N_PHI..(j + 1) * N_PHI];
        let x = sample_linear(uk, l[k], l[(k + 1) % N_PHI]);
        let phi = -std::f32::consts::PI + (k as f32 + 0.5 + x) * CELL;
        if phi >= std::f32::consts::PI {
            phi - std::f32::consts::TAU
        } else {
            phi
        }
    }
}

/// x ∈ [0, 1] with density ∝ a(1 − x) + b x, by inverting the quadratic CDF in its
/// cancellation-free form.
#[inline]
fn sample_linear(u: f32, a: f32, b: f32) -> f32 {
    let denom = a + ((1.0 - u) * a * a + u * b * b).sqrt();
    if denom > 0.0 {
        (u * (a + b) / denom).clamp(0.0, 1.0)
    } else {
        u
    }
}

/// Linear interpolation position between table rows for cos θ_o.
#[derive(Clone, Copy, Debug)]
struct RowLerp {
    j: usize,
    t: f32,
}

impl RowLerp {
    #[inline]
    fn new(cos_o: f32) -> Self {
        let x = cos_o.clamp(0.0, 1.0) * (N_COS - 1) as f32;
        let j = (x as usize).min(N_COS - 2);
        RowLerp {
            j,
            t: (x - j as f32).clamp(0.0, 1.0),
        }
    }

    #[inline]
    fn lerp<T>(&self, v: &[T]) -> T
    where
        T: Copy + std::ops::Mul<f32, Output = T> + std::ops::Add<Output = T>,
    {
        v[self.j] * (1.0 - self.t) + v[self.j + 1] * self.t
    }
}

/// Linear interpolation position between the cell centres −π + (k + ½)·2π/N_PHI for φ.
#[derive(Clone, Copy, Debug)]
struct PhiLerp {
    k0: usize,
    k1: usize,
    f: f32,
}

impl PhiLerp {
    #[inline]
    fn new(phi: f32) -> Self {
        let s = (phi + std::f32::consts::PI) / CELL - 0.5;
        let fl = s.floor();
        let k0 = (fl as i32).rem_euclid(N_PHI as i32) as usize;
        PhiLerp {
            k0,
            k1: (k0 + 1) % N_PHI,
            f: (s - fl).clamp(0.0, 1.0),
        }
    }
}

/// Σ a_i b_i over N_FINE terms with four independent partial sums, which lets the compiler
/// vectorise it.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    const _: () = assert!(N_FINE.is_multiple_of(4));
    let mut acc = [0.0f64; 4];
    for (x, y) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for l in 0..4 {
            acc[l] += x[l] * y[l];
        }
    }
    acc.iter().sum()
}

/// Builds the three lobe tables and the per-row residual ½∫A_3 dh.
fn build_tables(eta: f64, sigma_a: [f64; 3], beta_az: [f64; 3]) -> ([AzimuthalTable; 3], Vec<Rgb>) {
    let kernels: Vec<Vec<f64>> = beta_az
        .iter()
        .map(|&b| {
            let k = detector_kernel(b);
            // g[i] = k[(−i) mod N_FINE], doubled, so that cell c's weights k[(c·SPLAT − m) mod N]
            // for m = 0..N are the contiguous slice g[N − c·SPLAT..].
            (0..2 * N_FINE)
                .map(|i| k[(2 * N_FINE - i) % N_FINE])
                .collect()
        })
        .collect();
    let mut tables = vec![vec![Rgb::ZERO; N_COS * N_PHI]; 3];
    let mut residual = vec![Rgb::ZERO; N_COS];
    let d_gamma = PI / N_GAMMA as f64;
    let fine_width = TAU / N_FINE as f64;
    let mut fine = vec![
        [
            vec![0.0f64; N_FINE],
            vec![0.0f64; N_FINE],
            vec![0.0f64; N_FINE]
        ];
        3
    ];
    for j in 0..N_COS {
        let cos_o = j as f64 / (N_COS - 1) as f64;
        fine.iter_mut()
            .flatten()
            .for_each(|ch| ch.iter_mut().for_each(|x| *x = 0.0));
        let mut res = [0.0f64; 3];
        for i in 0..N_GAMMA {
            let gamma = -FRAC_PI_2 + (i as f64 + 0.5) * d_gamma;
            let (a, phi) = attenuations(cos_o, eta, sigma_a, gamma);
            // ½ dh = ½ cos γ dγ.
            let w = 0.5 * gamma.cos() * d_gamma;
            for c in 0..3 {
                res[c] += w * a[3][c];
            }
            for p in 0..3 {
                let s = (wrap(phi[p]) + PI) / fine_width;
                let m = s.floor();
                let frac = s - m;
                let m0 = (m as usize) % N_FINE;
                let m1 = (m0 + 1) % N_FINE;
                for c in 0..3 {
                    fine[p][c][m0] += (1.0 - frac) * w * a[p][c];
                    fine[p][c][m1] += frac * w * a[p][c];
                }
            }
        }
        residual[j] = Rgb::new(res[0] as f32, res[1] as f32, res[2] as f32);
        for p in 0..3 {
            for k in 0..N_PHI {
                let start = N_FINE - k * SPLAT;
                let ker = &kernels[p][start..start + N_FINE];
                let v: [f64; 3] = std::array::from_fn(|c| dot(&fine[p][c], ker));
                tables[p][j * N_PHI + k] = Rgb::new(v[0] as f32, v[1] as f32, v[2] as f32);
            }
        }
    }
    let mut it = tables.into_iter().map(AzimuthalTable::new);
    let tables = std::array::from_fn(|_| it.next().expect("three lobes"));
    (tables, residual)
}

/// The d'Eon 2011 BCSDF with precomputed azimuthal tables (module docs).
pub struct DEon {
    long: [Longitudinal; 3],
    /// M for p ≥ 3: TRT's variance, untilted.
    long_residual: Longitudinal,
    az: [AzimuthalTable; 3],
    /// ½∫A_3 dh per row (N_3 = this / 2π).
    residual: Vec<Rgb>,
    residual_lum: Vec<f32>,
    beta_az: [f64; 3],
    sigma_a: Rgb,
    eta: f32,
}

impl std::fmt::Debug for DEon {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DEon")
            .field("v", &self.long.each_ref().map(|l| l.v))
            .field("beta_az", &self.beta_az)
            .field("sigma_a", &self.sigma_a)
            .field("eta", &self.eta)
            .finish_non_exhaustive()
    }
}

impl DEon {
    /// Validates `p` and tabulates each lobe's N_p over (φ, cos θ_o).
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        check_range("longitudinal_roughness", p.longitudinal_roughness, 0.0, 1.0)?;
        check_range("azimuthal_roughness", p.azimuthal_roughness, 0.0, 1.0)?;
        check_range("alpha", p.alpha, -15.0, 15.0)?;
        check_range("eta", p.eta, 1.01, 3.0)?;
        let sigma_a = p.pigment.sigma_a(p.azimuthal_roughness)?;
        let beta_m = FRAC_PI_2 * p.longitudinal_roughness as f64;
        let beta_n = FRAC_PI_2 * p.azimuthal_roughness as f64;
        let alpha = (p.alpha as f64).to_radians();
        let tilt = [-2.0 * alpha, alpha, 4.0 * alpha];
        let v: [f64; 3] = std::array::from_fn(|i| (LOBE_RATIO[i] * beta_m).max(BETA_MIN).powi(2));
        let beta_az: [f64; 3] = std::array::from_fn(|i| (LOBE_RATIO[i] * beta_n).max(BETA_MIN));
        let (az, residual) =
            build_tables(p.eta as f64, sigma_a.to_array().map(|s| s as f64), beta_az);
        Ok(DEon {
            long: std::array::from_fn(|i| Longitudinal::new(v[i], tilt[i])),
            long_residual: Longitudinal::new(v[2], 0.0),
            az,
            residual_lum: residual.iter().map(|&c| luminance(c)).collect(),
            residual,
            beta_az,
            sigma_a,
            eta: p.eta,
        })
    }

    /// Sampling probabilities (unnormalised) of lobes R, TT, TRT, residual at θ_o: the luminance of
    /// ∫ N_p dφ.
    #[inline]
    fn lobe_weights(&self, row: RowLerp) -> [f32; 4] {
        [
            self.az[0].lum_integral(row),
            self.az[1].lum_integral(row),
            self.az[2].lum_integral(row),
            row.lerp(&self.residual_lum),
        ]
    }

    /// Σ_p M_p N_p; the residual term only if `with_residual` (tests evaluate R+TT+TRT alone).
    /// The lobes `lobes` (0 R, 1 TT, 2 TRT, 3 the p ≥ 3 residual) summed.
    fn eval_lobes(&self, wo: Vec3, wi: Vec3, lobes: std::ops::Range<usize>) -> Rgb {
        let o = Angles::new(wo);
        let (sin_i, cos_i) = sin_cos_theta(wi);
        let phi = o.relative_phi(wi);
        let row = RowLerp::new(o.cos as f32);
        let col = PhiLerp::new(phi);
        let mut f = Rgb::ZERO;
        for (p, (long, az)) in self.long.iter().zip(&self.az).enumerate() {
            if !lobes.contains(&p) {
                continue;
            }
            let m = long.eval(sin_i, cos_i, o.sin, o.cos) as f32;
            if m > 0.0 {
                f += az.value(row, col) * m;
            }
        }
        if lobes.contains(&3) {
            let m = self.long_residual.eval(sin_i, cos_i, o.sin, o.cos) as f32;
            f += row.lerp(&self.residual) * (m / std::f32::consts::TAU);
        }
        f
    }
}

#[inline]
fn sin_cos_theta(w: Vec3) -> (f64, f64) {
    let s = (w.x as f64).clamp(-1.0, 1.0);
    (s, (1.0 - s * s).max(0.0).sqrt())
}

/// The outgoing direction's longitudinal angle and azimuth reference.
struct Angles {
    sin: f64,
    cos: f64,
    /// Unit azimuth direction (y, z) of wo in the normal plane; +y when wo lies along the fiber.
    ey: f32,
    ez: f32,
}

impl Angles {
    #[inline]
    fn new(wo: Vec3) -> Self {
        let (sin, cos) = sin_cos_theta(wo);
        let len2 = wo.y * wo.y + wo.z * wo.z;
        let (ey, ez) = if len2 > 1e-12 {
            let inv = len2.sqrt().recip();
            (wo.y * inv, wo.z * inv)
        } else {
            (1.0, 0.0)
        };
        Angles { sin, cos, ey, ez }
    }

    /// φ_i − φ_o ∈ [−π, π].
    #[inline]
    fn relative_phi(&self, wi: Vec3) -> f32 {
        let c = self.ey * wi.y + self.ez * wi.z;
        let s = self.ey * wi.z - self.ez * wi.y;
        s.atan2(c)
    }

    /// The direction at elevation (sin θ, cos θ) and relative azimuth φ.
    #[inline]
    fn direction(&self, sin_i: f64, cos_i: f64, phi: f32) -> Vec3 {
        let (s, c) = phi.sin_cos();
        let ci = cos_i as f32;
        Vec3::new(
            sin_i as f32,
            ci * (self.ey * c - self.ez * s),
            ci * (self.ez * c + self.ey * s),
        )
    }
}

impl Bcsdf for DEon {
    fn eval(&self, wo: Vec3, wi: Vec3, _h: f32) -> Rgb {
        self.eval_lobes(wo, wi, 0..4)
    }

    fn lobe_names(&self) -> &'static [&'static str] {
        &["R", "TT", "TRT", "residual"]
    }

    fn eval_lobe(&self, wo: Vec3, wi: Vec3, _h: f32, p: usize) -> Rgb {
        self.eval_lobes(wo, wi, p..p + 1)
    }

    fn sample(&self, wo: Vec3, _h: f32, u: [f32; 4]) -> Option<BcsdfSample> {
        let o = Angles::new(wo);
        let row = RowLerp::new(o.cos as f32);
        let w = self.lobe_weights(row);
        let total: f32 = w.iter().sum();
        // Table entries are finite and non-negative, so this only rejects a fully absorbing fiber.
        if total <= 0.0 {
            return None;
        }
        // Choose the lobe with u[0], then reuse its position inside the lobe's interval.
        let mut x = u[0] * total;
        let mut lobe = 3;
        for (p, &wp) in w.iter().enumerate() {
            if x < wp || (p == 3 && wp > 0.0) {
                lobe = p;
                break;
            }
            x -= wp;
        }
        if w[lobe] <= 0.0 {
            // Rounding walked past the last non-empty lobe.
            lobe = w.iter().rposition(|&wp| wp > 0.0)?;
            x = w[lobe];
        }
        let u_row = (x / w[lobe]).clamp(0.0, 1.0);
        let (sin_i, cos_i, phi) = if lobe < 3 {
            let (s, c) = self.long[lobe].sample(o.sin, o.cos, u[1], u[2]);
            (s, c, self.az[lobe].sample(row, u_row, u[3]))
        } else {
            let (s, c) = self.long_residual.sample(o.sin, o.cos, u[1], u[2]);
            (s, c, std::f32::consts::TAU * u[3] - std::f32::consts::PI)
        };
        let wi = o.direction(sin_i, cos_i, phi);
        let f = self.eval_lobes(wo, wi, 0..4);
        let pdf = luminance(f) / total;
        (pdf > 0.0 && pdf.is_finite()).then_some(BcsdfSample { wi, f, pdf })
    }

    fn pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> f32 {
        self.eval_pdf(wo, wi, h).1
    }

    fn eval_pdf(&self, wo: Vec3, wi: Vec3, _h: f32) -> (Rgb, f32) {
        // Lobe choice ∝ luminance(∫N_p dφ), and each lobe's (θ, φ) density is
        // M_p luminance(N_p) / luminance(∫N_p dφ): the mixture is luminance(eval) / Σ weights.
        let f = self.eval_lobes(wo, wi, 0..4);
        let row = RowLerp::new(Angles::new(wo).cos as f32);
        let total: f32 = self.lobe_weights(row).iter().sum();
        (
            f,
            if total > 0.0 {
                luminance(f) / total
            } else {
                0.0
            },
        )
    }
}

/// Parameter sets the statistical tests run on this model ([`crate::HairModel::test_instances`]).
pub fn test_instances() -> Vec<TestInstance<Params>> {
    let white = |name: &str, rm: f32, rn: f32| TestInstance {
        name: name.into(),
        params: Params {
            longitudinal_roughness: rm,
            azimuthal_roughness: rn,
            pigment: Pigment::SigmaA((0.0, 0.0, 0.0)),
            ..Params::default()
        },
        white_furnace: true,
    };
    vec![
        white("white_smooth", 0.1, 0.2),
        white("white_medium", 0.3, 0.4),
        white("white_rough", 0.7, 0.8),
        TestInstance {
            name: "brown".into(),
            params: Params {
                longitudinal_roughness: 0.2,
                azimuthal_roughness: 0.3,
                pigment: Pigment::Melanin {
                    eumelanin: 1.3,
                    pheomelanin: 0.0,
                    tint: crate::pigment::NO_TINT,
                },
                ..Params::default()
            },
            white_furnace: false,
        },
        TestInstance {
            name: "blond".into(),
            params: Params {
                longitudinal_roughness: 0.15,
                azimuthal_roughness: 0.25,
                alpha: 3.0,
                pigment: Pigment::Melanin {
                    eumelanin: 0.3,
                    pheomelanin: 0.1,
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
    use tress_core::math::fiber_direction;
    use tress_core::rng::Sampler;
    use tress_core::sampling::sample_uniform_sphere;

    fn instance(name: &str) -> DEon {
        let t = test_instances()
            .into_iter()
            .find(|t| t.name == name)
            .expect("instance");
        DEon::new(&t.params).unwrap()
    }

    fn wo_at(theta_deg: f32) -> Vec3 {
        let t = theta_deg.to_radians();
        fiber_direction(t.sin(), t.cos(), std::f32::consts::FRAC_PI_2)
    }

    /// ∫_{S²} g(ω) dω by the midpoint rule in (θ, φ), dω = cos θ dθ dφ.
    fn sphere_quadrature(n_theta: usize, n_phi: usize, mut g: impl FnMut(Vec3) -> f64) -> f64 {
        let dt = PI / n_theta as f64;
        let dp = TAU / n_phi as f64;
        let mut sum = 0.0;
        for i in 0..n_theta {
            let th = -FRAC_PI_2 + (i as f64 + 0.5) * dt;
            let mut row = 0.0;
            for k in 0..n_phi {
                let ph = -PI + (k as f64 + 0.5) * dp;
                row += g(fiber_direction(th.sin() as f32, th.cos() as f32, ph as f32));
            }
            sum += row * th.cos() * dt * dp;
        }
        sum
    }

    /// A direction at elevation θ (degrees) and relative azimuth φ (radians) from `wo_at`.
    fn wi_at(theta_deg: f32, phi: f32) -> Vec3 {
        let t = theta_deg.to_radians();
        fiber_direction(t.sin(), t.cos(), std::f32::consts::FRAC_PI_2 + phi)
    }

    #[test]
    fn m_is_normalised_for_every_variance_and_angle() {
        let n = 40_000;
        let dt = PI / n as f64;
        for v in [0.002, 0.005, 0.01, 0.03, 0.1, 0.3, 1.0, 2.0] {
            let lobe = Longitudinal::new(v, 0.0);
            for th_o in [0.0f64, 0.5, 1.0, 1.4, 1.55] {
                let (so, co) = th_o.sin_cos();
                let integral: f64 = (0..n)
                    .map(|i| {
                        let (si, ci) = (-FRAC_PI_2 + (i as f64 + 0.5) * dt).sin_cos();
                        lobe.eval(si, ci, so, co) * ci * dt
                    })
                    .sum();
                assert!(
                    (integral - 1.0).abs() < 1e-4,
                    "v = {v}, θ_o = {th_o}: ∫ M cos θ dθ = {integral}"
                );
            }
        }
    }

    #[test]
    fn ln_i0_branches_are_accurate_and_continuous() {
        // Reference: the power series summed far past convergence (fine in f64 up to x ≈ 700).
        let reference = |x: f64| {
            let q = 0.25 * x * x;
            let (mut term, mut sum) = (1.0f64, 1.0f64);
            for k in 1..400 {
                term *= q / (k * k) as f64;
                sum += term;
            }
            sum.ln()
        };
        // An error in ln I₀ is the relative error of I₀. A&S bound the absolute error by 1.6e-7
        // on I₀ ≥ 1 and by 1.9e-7 on √x e^{−x} I₀ ≥ 0.3989: relative < 4.8e-7.
        for x in [0.0, 0.5, 2.0, 3.7, 3.75, 3.8, 5.0, 12.0, 30.0, 100.0, 600.0] {
            let err = (ln_i0(x) - reference(x)).abs();
            assert!(err < 4.8e-7, "ln I0({x}): {} vs {}", ln_i0(x), reference(x));
        }
        // The switch itself: relative jump in I₀ (= jump in ln I₀).
        let jump = (ln_i0(I0_SWITCH + 1e-9) - ln_i0(I0_SWITCH)).abs();
        assert!(jump < 6.4e-7, "ln I0 jumps by {jump} at the switch");
        // And in M, with θ_o, θ_i fixed and v crossing the value where a = 3.75.
        let (si, ci) = (-0.3f64).sin_cos();
        let (so, co) = 0.3f64.sin_cos();
        let v_switch = ci * co / I0_SWITCH;
        let below = Longitudinal::new(v_switch * (1.0 + 1e-9), 0.0).eval(si, ci, so, co);
        let above = Longitudinal::new(v_switch * (1.0 - 1e-9), 0.0).eval(si, ci, so, co);
        assert!(
            (below / above - 1.0).abs() < 6.4e-7,
            "M: {below} vs {above}"
        );
    }

    #[test]
    fn table_rows_integrate_to_the_h_integral_of_a_p() {
        let params = Params {
            pigment: Pigment::SigmaA((0.05, 0.4, 2.0)),
            ..Params::default()
        };
        let m = DEon::new(&params).unwrap();
        let n = 200_000;
        for j in [0, 1, 20, 45, N_COS - 1] {
            let cos_o = j as f64 / (N_COS - 1) as f64;
            // Independent quadrature: midpoint in h rather than in γ.
            let mut expect = [[0.0f64; 3]; 4];
            for i in 0..n {
                let h = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                let (a, _) = attenuations(cos_o, 1.55, [0.05, 0.4, 2.0], h.asin());
                for (e, ap) in expect.iter_mut().zip(&a) {
                    for (ec, ac) in e.iter_mut().zip(ap) {
                        *ec += 0.5 * ac * 2.0 / n as f64;
                    }
                }
            }
            for (p, e) in expect.iter().enumerate() {
                let got = if p < 3 {
                    m.az[p].rgb[j * N_PHI..(j + 1) * N_PHI]
                        .iter()
                        .fold(Rgb::ZERO, |s, &x| s + x)
                        * CELL
                } else {
                    m.residual[j]
                };
                for (c, &e) in e.iter().enumerate() {
                    assert!(
                        (got[c] as f64 - e).abs() <= 1e-4 * e + 1e-7,
                        "row {j}, lobe {p}, channel {c}: ∫N dφ = {} vs ½∫A dh = {e}",
                        got[c]
                    );
                }
            }
        }
    }

    #[test]
    fn residual_closes_energy_and_two_lobe_deficit_matches_reference() {
        let m = instance("white_medium");
        for j in 0..N_COS {
            let row = RowLerp {
                j: j.min(N_COS - 2),
                t: if j == N_COS - 1 { 1.0 } else { 0.0 },
            };
            let total: f32 = m.lobe_weights(row).iter().sum();
            assert!((total - 1.0).abs() < 1e-5, "row {j}: Σ_p ∫N_p dφ = {total}");
        }
        // Σ_{p≤2} ½∫A_p dh = 0.992 / 0.986 / 0.886 at 0 / 45 / 80°
        // (docs/src/reference/hair-maths.md#energy-without-the-residual).
        for (deg, want) in [(0.0f32, 0.992f32), (45.0, 0.986), (80.0, 0.886)] {
            let row = RowLerp::new(deg.to_radians().cos());
            let w = m.lobe_weights(row);
            let three = w[0] + w[1] + w[2];
            assert!((three - want).abs() < 0.003, "{deg}°: R+TT+TRT = {three}");
        }
    }

    #[test]
    fn white_furnace_by_quadrature() {
        for name in ["white_smooth", "white_medium", "white_rough"] {
            let m = instance(name);
            for deg in [0.0f32, 30.0, 60.0, 80.0, 89.0] {
                let wo = wo_at(deg);
                let all = sphere_quadrature(1000, 512, |wi| m.eval(wo, wi, 0.0).x as f64);
                println!("{name} θ_o = {deg}°: furnace {all:.5}");
                assert!(
                    (all - 1.0).abs() < 1e-3,
                    "{name} θ_o = {deg}°: furnace {all}"
                );
                if deg == 0.0 || deg == 80.0 {
                    let three =
                        sphere_quadrature(1000, 512, |wi| m.eval_lobes(wo, wi, 0..3).x as f64);
                    let want = if deg == 0.0 { 0.992 } else { 0.886 };
                    println!("{name} θ_o = {deg}°: R+TT+TRT only {three:.5}");
                    assert!(
                        (three - want).abs() < 0.003,
                        "{name} {deg}°: R+TT+TRT = {three}"
                    );
                }
            }
        }
    }

    #[test]
    fn azimuthal_tables_and_eval_are_even_in_phi() {
        let m = instance("blond");
        for t in &m.az {
            for j in 0..N_COS {
                let r = &t.rgb[j * N_PHI..(j + 1) * N_PHI];
                for k in 0..N_PHI / 2 {
                    let (a, b) = (r[k], r[N_PHI - 1 - k]);
                    assert!(
                        (a - b).abs().max_element() <= 1e-4 * a.max(b).max_element() + 1e-7,
                        "row {j}, cell {k}: {a} vs {b}"
                    );
                }
            }
        }
        let wo = wo_at(25.0);
        for phi in [0.1f32, 0.7, 1.9, 3.0] {
            let (a, b) = (
                m.eval(wo, wi_at(-20.0, phi), 0.0),
                m.eval(wo, wi_at(-20.0, -phi), 0.0),
            );
            assert!(
                (a - b).abs().max_element() <= 1e-4 * a.max_element(),
                "φ = ±{phi}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn pdf_integrates_to_one() {
        for name in ["brown", "white_smooth"] {
            let m = instance(name);
            for deg in [10.0f32, 70.0] {
                let wo = wo_at(deg);
                let total = sphere_quadrature(1000, 512, |wi| m.pdf(wo, wi, 0.0) as f64);
                assert!(
                    (total - 1.0).abs() < 1e-3,
                    "{name} θ_o = {deg}°: ∫pdf = {total}"
                );
            }
        }
    }

    #[test]
    fn samples_carry_eval_and_pdf_and_unit_weight_in_the_furnace() {
        let mut rng = Sampler::from_seed(11);
        for t in test_instances() {
            let m = DEon::new(&t.params).unwrap();
            let mut lost = 0;
            for i in 0..20_000u32 {
                let mut wo = sample_uniform_sphere(rng.next_2d());
                if i.is_multiple_of(100) {
                    wo = Vec3::new(if i.is_multiple_of(200) { 1.0 } else { -1.0 }, 0.0, 0.0);
                }
                let h = 2.0 * rng.next_1d() - 1.0;
                let Some(s) = m.sample(wo, h, rng.next_4d()) else {
                    lost += 1;
                    continue;
                };
                assert_eq!(s.f, m.eval(wo, s.wi, h), "{}: f", t.name);
                assert_eq!(s.pdf, m.pdf(wo, s.wi, h), "{}: pdf", t.name);
                let weight = s.f / s.pdf;
                assert!(weight.is_finite() && weight.min_element() >= 0.0);
                if t.white_furnace {
                    assert!(
                        (weight - Rgb::ONE).abs().max_element() < 1e-3,
                        "{}: weight {weight}",
                        t.name
                    );
                } else {
                    // f / pdf = Σ_p ∫N_p dφ · f / lum(f): each channel's share of the luminance.
                    assert!(weight.max_element() < 20.0, "{}: weight {weight}", t.name);
                }
            }
            assert!(lost < 20, "{}: {lost} samples lost", t.name);
        }
    }

    #[test]
    fn phi_sampler_matches_the_interpolated_row_chi2() {
        // The sphere χ² cannot resolve the table cells; this one bins φ at a quarter cell, where
        // the piecewise-linear density is exactly linear within each bin (midpoint rule exact).
        let m = instance("white_smooth");
        let bins = 4 * N_PHI;
        let width = std::f32::consts::TAU / bins as f32;
        let mut rng = Sampler::from_seed(9);
        for (lobe, cos_o) in [(0, 0.93f32), (1, 0.5), (2, 0.21), (0, 0.008), (2, 0.024)] {
            let az = &m.az[lobe];
            let row = RowLerp::new(cos_o);
            assert!(
                row.t > 0.1 && row.t < 0.9,
                "the test must straddle two rows"
            );
            let n = 1_000_000;
            let mut observed = vec![0.0f64; bins];
            for _ in 0..n {
                let phi = az.sample(row, rng.next_1d(), rng.next_1d());
                let b = ((phi + std::f32::consts::PI) / width) as usize;
                observed[b.min(bins - 1)] += 1.0;
            }
            let norm = az.lum_integral(row);
            let expected: Vec<f64> = (0..bins)
                .map(|b| {
                    let mid = -std::f32::consts::PI + (b as f32 + 0.5) * width;
                    (luminance(az.value(row, PhiLerp::new(mid))) / norm * width) as f64 * n as f64
                })
                .collect();
            let out = tress_core::stats::chi2_test(&observed, &expected, 5.0);
            assert!(
                out.p_value > 0.01 / 3.0,
                "lobe {lobe}: χ² p = {} ({out:?})",
                out.p_value
            );
        }
    }

    #[test]
    fn sampler_matches_pdf_chi2() {
        let instances = test_instances();
        let angles = [20.0f32, -75.0];
        let alpha = tress_core::stats::sidak_alpha(0.01, instances.len() * angles.len());
        for t in &instances {
            let m = DEon::new(&t.params).unwrap();
            for deg in angles {
                let wo = wo_at(deg);
                let chi2 = tress_core::stats::SphereChi2 {
                    pole: Vec3::X,
                    samples: 300_000,
                    ..Default::default()
                };
                let (out, _, _) = chi2.run(
                    5,
                    |s| m.sample(wo, 0.0, s.next_4d()).map(|x| x.wi),
                    |wi| m.pdf(wo, wi, 0.0) as f64,
                );
                assert!(
                    out.p_value > alpha,
                    "{} θ_o = {deg}°: χ² p = {} ({:?})",
                    t.name,
                    out.p_value,
                    out
                );
            }
        }
    }

    #[test]
    fn extreme_directions_stay_finite() {
        let m = instance("brown");
        let mut rng = Sampler::from_seed(3);
        let poles = [Vec3::X, -Vec3::X, Vec3::new(1.0, 1e-7, 0.0).normalize()];
        for i in 0..20_000 {
            let pick = |rng: &mut Sampler, k: usize| {
                if k.is_multiple_of(7) {
                    poles[k % 3]
                } else {
                    sample_uniform_sphere(rng.next_2d())
                }
            };
            let wo = pick(&mut rng, i);
            let wi = pick(&mut rng, i / 3);
            let h = [-1.0, 1.0, 0.0][i % 3];
            let f = m.eval(wo, wi, h);
            let pdf = m.pdf(wo, wi, h);
            assert!(
                f.is_finite() && f.min_element() >= 0.0,
                "eval({wo}, {wi}) = {f}"
            );
            assert!(pdf.is_finite() && pdf >= 0.0, "pdf({wo}, {wi}) = {pdf}");
            if let Some(s) = m.sample(wo, h, rng.next_4d()) {
                assert!(s.wi.is_finite() && s.f.is_finite() && s.pdf.is_finite());
                assert!((s.wi.length() - 1.0).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn invalid_parameters_name_their_field() {
        assert_rejected(
            DEon::new,
            &[
                (|p| p.longitudinal_roughness = 1.5, "longitudinal_roughness"),
                (|p| p.azimuthal_roughness = f32::NAN, "azimuthal_roughness"),
                (|p| p.alpha = 40.0, "alpha"),
                (|p| p.eta = 0.9, "eta"),
                (|p| p.pigment = Pigment::SigmaA((-1.0, 0.0, 0.0)), "sigma_a"),
            ],
        );
        assert!(DEon::new(&Params::default()).is_ok());
    }

    #[test]
    #[ignore = "timing; run with --ignored --nocapture"]
    fn timing() {
        use std::hint::black_box;
        use std::time::Instant;
        let t0 = Instant::now();
        let builds = 10;
        for _ in 0..builds {
            black_box(DEon::new(&Params::default()).unwrap());
        }
        println!(
            "table build: {:.2} ms",
            t0.elapsed().as_secs_f64() * 1e3 / builds as f64
        );
        let m = DEon::new(&Params::default()).unwrap();
        let mut rng = Sampler::from_seed(1);
        let n = 1_000_000;
        let dirs: Vec<(Vec3, Vec3, [f32; 4])> = (0..n)
            .map(|_| {
                (
                    sample_uniform_sphere(rng.next_2d()),
                    sample_uniform_sphere(rng.next_2d()),
                    rng.next_4d(),
                )
            })
            .collect();
        let t = Instant::now();
        let mut acc = Rgb::ZERO;
        for (wo, wi, _) in &dirs {
            acc += m.eval(*wo, *wi, 0.0);
        }
        black_box(acc);
        println!("eval: {:.1} ns", t.elapsed().as_secs_f64() * 1e9 / n as f64);
        let t = Instant::now();
        let mut p = 0.0;
        for (wo, wi, _) in &dirs {
            p += m.pdf(*wo, *wi, 0.0);
        }
        black_box(p);
        println!("pdf: {:.1} ns", t.elapsed().as_secs_f64() * 1e9 / n as f64);
        let t = Instant::now();
        let mut acc = 0.0;
        for (wo, _, u) in &dirs {
            acc += m.sample(*wo, 0.0, *u).map_or(0.0, |s| s.pdf);
        }
        black_box(acc);
        println!(
            "sample (incl. eval + pdf): {:.1} ns",
            t.elapsed().as_secs_f64() * 1e9 / n as f64
        );
    }
}
