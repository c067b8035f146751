//! Chiang, Bitterli, Tappan & Burley 2016, "A Practical and Controllable Hair and Fur Model for
//! Production Path Tracing" (Computer Graphics Forum 35(4)), in the form of pbrt-v4's `HairBxDF`
//! (Pharr, "The Implementation of a Hair Scattering Model", pbrt.org/hair.pdf), which Mitsuba 3's
//! `hair` plugin and Cycles' Principled Hair (Chiang) also follow.
//!
//! Lobes p = 0 (R), 1 (TT), 2 (TRT) and a residual p = 3 standing for all higher orders:
//! `eval = Σ_{p<3} M_p(θ_i; θ_o'(p)) A_p(θ_o, h) N_p(φ; h) + M_3(θ_i; θ_o) A_3 / (2π)`, with
//! - `A_p`: unpolarised dielectric Fresnel `f` at the 3D incidence cosine `cos θ_o cos γ_o`,
//!   `A_0 = f`, `A_1 = (1−f)² T`, `A_2 = A_1 T f`, `A_3 = A_2 f T / (1 − f T)`, with the per-pass
//!   transmittance `T = exp(−σ_a · 2 cos γ_t / cos θ_t)`; without absorption `Σ A_p = 1`, so the
//!   model conserves energy exactly (white furnace = 1 for every θ_o and h).
//! - `M_p`: the von Mises–Fisher longitudinal lobe
//!   `exp(−sin θ_i sin θ_o / v) I₀(cos θ_i cos θ_o / v) / (2 v sinh(1/v))`, variance
//!   `v_0 = (0.726 β_m + 0.812 β_m² + 3.7 β_m²⁰)²`, `v_1 = v_0/4`, `v_2 = v_3 = 4 v_0`, evaluated
//!   for every v in one overflow-free log form (see `longitudinal`).
//! - Scale tilt: lobe p sees θ_o rotated by −2α (R), +α (TT), +4α (TRT), 0 (residual).
//! - `N_p`: logistic of scale `s = √(π/8)(0.265 β_n + 1.194 β_n² + 5.372 β_n²²)` trimmed to
//!   [−π, π], centred on the exit azimuth `Φ(p, h) = 2p γ_t − 2 γ_o + p π`; uniform for p = 3.
//!
//! # Frame and signs
//! The local fiber frame of [`tress_core::bcsdf`] (identical to pbrt's hair frame):
//! x = tangent, `sin θ = ω.x`, `φ = atan2(ω.z, ω.y)`; the relative azimuth is `φ = φ_i − φ_o`;
//! `h ∈ [−1, 1]` is the signed offset along y, `γ_o = asin h`, so the specular R lobe is centred on
//! `φ = −2 asin h`. The model is not reciprocal (A_p, h and the tilt belong to ω_o), and it is not
//! even in φ: `f(h, φ) = f(−h, −φ)` but `f(h, φ) ≠ f(h, −φ)` in general.
//!
//! # Value convention
//! [`Bcsdf::eval`] returns `Σ_p M_p A_p N_p`, which is pbrt's `f · |cos θ|` (pbrt divides by the
//! shading-normal cosine in `f` and its integrator multiplies it back; here neither happens).
//!
//! # I₀ and reference values
//! `M_p` here uses ln I₀ from Abramowitz & Stegun 9.8.1/9.8.2 in its log form (the bounds are at
//! `i0_scaled_split`), so it follows the exact Bessel function everywhere; pbrt-v3's series
//! and asymptotic form do not (measured in docs/src/research/performance.md, "Chiang's I₀").
//! `tests/chiang_reference.rs` checks this implementation against an independent 40-digit
//! evaluation with the exact I₀ (`tests/chiang_reference.py`) on 1200 points — three fibers
//! (absorbing and not), five h, four θ_o, four θ_i, five Δφ — to 1e-4 relative.
//!
//! # Sampling
//! pbrt's procedure with four independent numbers instead of two demultiplexed ones: `u[0]` picks
//! the lobe with probability `P(p) = lum(A_p) / Σ_q lum(A_q)`, `u[1]`, `u[2]` draw θ_i from the
//! vMF lobe about the (tilted) mirror direction, `u[3]` draws Δφ from the trimmed logistic (uniform
//! for p = 3). `pdf` is the exact density of that mixture, `Σ_p P(p) M_p N_p`.
//!
//! # Evaluation in SIMD lanes
//! Lobe p's per-lobe values (variance, tilted θ_o, exit azimuth, A_p, P(p)) sit in lane p of
//! `f32x4` vectors (crate `wide`; SSE2 on baseline x86-64), so `M_p` and `N_p` of all four lobes
//! take one vector `exp` each, and the RGB transmittance, the pair (γ_t, γ_o), sampling's four
//! inverse-CDF logarithms and its two sines and cosines take one vector `exp`, `asin`, `ln` and
//! `sin_cos`. `exp`, `ln` and `sin_cos` are [`crate::simd_math`]'s, specialised to the arguments
//! passed here (exp of arguments ≤ 16, ln of positive numbers, bounded angles), because
//! `wide`'s general versions showed in Chiang's profile (docs/src/research/performance.md);
//! `asin` and `atan2` are `wide`'s.
//!
//! # Differences from pbrt-v4 (all keep its formulas; they make `pdf` the exact sampling density)
//! - I₀ uses the Abramowitz & Stegun approximations above instead of pbrt's 10-term series and
//!   asymptotic form.
//! - M_p is evaluated as `exp(−|m − u|²/(2v) + ln(I₀(a) e^{−a}) − ln v − ln(1 − e^{−2/v}))` with
//!   `u = (sin θ_i, cos θ_i)` and `m = (−sin θ_o, cos θ_o)`, which equals pbrt's two branches
//!   (direct for v > 0.1, logarithmic below) without the cancellation of `a − b − 1/v` in f32.
//! - The vMF sampler computes `1 − cos θ` from `ln(1 + x)` taken as `x ln u / (u − 1)` on the
//!   rounded `u = 1 + x` (accurate near the lobe's mode, where x → 0), and the
//!   random numbers of both inverse CDFs are clamped to ≥ 2⁻²⁴ (the spacing of 24-bit uniforms)
//!   instead of pbrt's 10⁻⁵, which moves 10⁻⁵ of each lobe's mass onto one cone. u = 0 itself must
//!   not reach the inverse CDFs: it maps onto the vMF's antipode and the logistic's trimmed end,
//!   where the density is 0 (in f32), yet a 24-bit generator returns it once in 2²⁴ draws.
//!
//! | parameter | default | meaning | pbrt / Mitsuba 3 / Cycles name |
//! |---|---|---|---|
//! | `beta_m` | 0.3 | longitudinal roughness, in [10⁻³, 1] | `beta_m` / `longitudinal_roughness` / Roughness |
//! | `beta_n` | 0.3 | azimuthal roughness, in [10⁻³, 1] | `beta_n` / `azimuthal_roughness` / Radial Roughness |
//! | `alpha` | 2.0 | cuticle scale tilt in **degrees**, in [−90, 90] (hair: 2–4) | `alpha` / `scale_tilt` / Offset |
//! | `eta` | 1.55 | index of refraction of the fiber, > 1 | `eta` / `int_ior`÷`ext_ior` / IOR |
//! | `pigment` | `Melanin(eumelanin: 1.3)` | absorption σ_a per unit radius ([`Pigment`]) | `sigma_a`, `eumelanin`, `pheomelanin`, `color` |
//!
//! β is bounded below by 10⁻³ (pbrt accepts 0, where v = s = 0 and M_p, N_p divide by zero): at
//! β = 10⁻³ the narrowest lobes (TT: angular std ≈ 3.6·10⁻⁴ rad; logistic scale ≈ 1.7·10⁻⁴ rad)
//! are still ~10³ times wider than the f32 resolution of a direction (~10⁻⁷ rad), so `eval` and
//! `pdf` stay accurate to ~10⁻³; narrower lobes approach a delta, which a BCSDF cannot represent.
//!
//! RON: `Chiang(beta_m: 0.3, beta_n: 0.3, alpha: 2.0, pigment: Melanin(eumelanin: 1.3, pheomelanin: 0.2))`

use crate::pigment::Pigment;
use crate::simd_math;
use crate::{check_range, ModelParams, ParamError, TestInstance};
use serde::{Deserialize, Serialize};
use std::f32::consts::{PI, TAU};
use tress_core::math::{luminance, safe_sqrt, Rgb, Vec3};
use tress_core::{Bcsdf, BcsdfSample};
use wide::f32x4;

/// Index of the residual lobe standing for all scattering orders ≥ 3.
const P_MAX: usize = 3;

/// Smallest random number fed to an inverse CDF: the spacing of 24-bit uniforms, so that
/// `1 − U_MIN` is still below 1 in f32 (module docs).
const U_MIN: f32 = 1.0 / (1u32 << 24) as f32;

/// Below e^{−80} ≈ 2·10⁻³⁵ a lobe value is taken as 0: `exp` of arguments under ≈ −87 is
/// subnormal, and arithmetic on subnormals takes a slow microcode path on x86 (sharp lobes spent
/// a fifth of `eval` there), and no sample is ever drawn where a lobe is that small (its inverse
/// CDFs stop at quantile 2⁻²⁴ ≈ e^{−17}).
const LN_NEGLIGIBLE: f32 = -80.0;

/// Lane p of the lobe vectors holds lobe p; this mask keeps the logistic lanes 0..2 and clears
/// the residual's lane 3, whose azimuthal factor is the uniform [`N_RESIDUAL`].
const N_LOGISTIC_LANES: f32x4 = f32x4::new([1.0, 1.0, 1.0, 0.0]);
const N_RESIDUAL: f32x4 = f32x4::new([0.0, 0.0, 0.0, 1.0 / TAU]);

/// Smallest accepted β_m, β_n (module docs).
pub const BETA_MIN: f32 = 1e-3;

/// Parameters of [`Chiang`]; the defaults are pbrt-v4's (module docs).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
#[schemars(rename = "ChiangParams")]
pub struct Params {
    /// Longitudinal roughness β_m, in [10⁻³, 1] (default 0.3).
    pub beta_m: f32,
    /// Azimuthal roughness β_n, in [10⁻³, 1] (default 0.3).
    pub beta_n: f32,
    /// Scale tilt in degrees.
    pub alpha: f32,
    /// Index of refraction of the fiber, greater than 1 (default 1.55).
    pub eta: f32,
    /// Absorption inside the fiber (default eumelanin 1.3).
    pub pigment: Pigment,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            beta_m: 0.3,
            beta_n: 0.3,
            alpha: 2.0,
            eta: 1.55,
            pigment: Pigment::default(),
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

    /// Scales β_m and β_n, within `BETA_MIN..=1`.
    fn scale_roughness(&mut self, scale: f32) {
        self.beta_m = (self.beta_m * scale).clamp(BETA_MIN, 1.0);
        self.beta_n = (self.beta_n * scale).clamp(BETA_MIN, 1.0);
    }
}

/// The Chiang et al. 2016 BCSDF, with the constants its parameters determine.
#[derive(Debug, Clone)]
pub struct Chiang {
    eta: f32,
    /// σ_a in lanes 0..2 (RGB), 0 in lane 3.
    sigma_a: f32x4,
    /// Longitudinal variance of lobe p, in lane p.
    v: f32x4,
    /// `1 / v` of lobe p in lane p.
    inv_v: f32x4,
    /// `−ln v − ln(1 − e^{−2/v})`: the log of the vMF normalisation without its e^{−1/v} factor.
    ln_norm: f32x4,
    /// `1 − e^{−2/v}` of lobe p in lane p, used by the vMF sampler.
    one_minus_e: f32x4,
    /// Logistic scale.
    s: f32,
    /// `1 / (s (CDF(π) − CDF(−π)))`: the trimmed logistic's normalisation including 1/s.
    logistic_norm: f32,
    /// `CDF(−π)` and `CDF(π) − CDF(−π)` of the logistic, for its inverse-CDF sampler.
    cdf_lo: f32,
    cdf_range: f32,
    /// sin and cos of the rotation of θ_o for lobes R, TT, TRT: −2α, α, 4α; 0 for the residual.
    tilt_sin: f32x4,
    tilt_cos: f32x4,
}

/// Everything that depends on (wo, h) only, shared by eval, pdf and sample. Per-lobe values sit
/// in lane p of an `f32x4`, so the four lobes are evaluated at once.
struct Geometry {
    /// wo's direction in the normal plane, unnormalised ([`normal_plane_direction`]).
    normal_o: (f32, f32),
    /// sin θ_o' and |cos θ_o'| seen by each lobe (tilted for p < 3).
    sin_o: f32x4,
    cos_o: f32x4,
    /// Exit azimuth Φ(p, h) of lobes 0..2 (lane 3 unused).
    phi_exit: f32x4,
    /// A_p of the red, green and blue channel, lobe p in lane p.
    ap: [f32x4; 3],
    /// Probability of sampling lobe p, in lane p.
    lobe_pdf: f32x4,
}

impl Geometry {
    /// A_p of lobe `p` as RGB.
    fn attenuation(&self, p: usize) -> Rgb {
        let [r, g, b] = self.ap.map(|c| c.as_array()[p]);
        Rgb::new(r, g, b)
    }

    /// A_p as RGB, p = 0..3.
    fn attenuations(&self) -> [Rgb; 4] {
        let [r, g, b] = self.ap.map(f32x4::to_array);
        std::array::from_fn(|p| Rgb::new(r[p], g[p], b[p]))
    }
}

/// A direction drawn by [`Chiang::draw`], with what evaluating or weighting it needs.
struct Draw {
    g: Geometry,
    lobe: usize,
    wi: Vec3,
    /// (sin θ_i, cos θ_i, φ_i − φ_o) the direction was built from.
    angles: (f32, f32, f32),
}

impl Chiang {
    /// Validates `p` and precomputes the lobe variances, logistic scale and tilts.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        check_range("beta_m", p.beta_m, BETA_MIN, 1.0)?;
        check_range("beta_n", p.beta_n, BETA_MIN, 1.0)?;
        check_range("alpha", p.alpha, -90.0, 90.0)?;
        if !(p.eta.is_finite() && p.eta > 1.0) {
            return Err(ParamError::new(
                "eta",
                p.eta,
                "must be finite and greater than 1",
            ));
        }
        let sigma_a = p.pigment.sigma_a(p.beta_n)?;

        let bm = p.beta_m as f64;
        let v0 = (0.726 * bm + 0.812 * bm * bm + 3.7 * bm.powi(20)).powi(2);
        let v = [v0, 0.25 * v0, 4.0 * v0, 4.0 * v0];

        let bn = p.beta_n as f64;
        let s = (std::f64::consts::PI / 8.0).sqrt()
            * (0.265 * bn + 1.194 * bn * bn + 5.372 * bn.powi(22));
        let pi = std::f64::consts::PI;
        let cdf_lo = 1.0 / (1.0 + (pi / s).exp());
        // CDF(π) − CDF(−π) = tanh(π/(2s)), without cancellation for large s.
        let cdf_range = (pi / (2.0 * s)).tanh();

        let a = (p.alpha as f64).to_radians();
        let tilt = [-2.0 * a, a, 4.0 * a, 0.0];

        Ok(Chiang {
            eta: p.eta,
            sigma_a: f32x4::new([sigma_a.x, sigma_a.y, sigma_a.z, 0.0]),
            v: f32x4::new(v.map(|v| v as f32)),
            inv_v: f32x4::new(v.map(|v| (1.0 / v) as f32)),
            ln_norm: f32x4::new(v.map(vmf_ln_norm)),
            one_minus_e: f32x4::new(v.map(|v| (-(-2.0 / v).exp_m1()) as f32)),
            s: s as f32,
            logistic_norm: (1.0 / (s * cdf_range)) as f32,
            cdf_lo: cdf_lo as f32,
            cdf_range: cdf_range as f32,
            tilt_sin: f32x4::new(tilt.map(|t| t.sin() as f32)),
            tilt_cos: f32x4::new(tilt.map(|t| t.cos() as f32)),
        })
    }

    fn geometry(&self, wo: Vec3, h: f32) -> Geometry {
        let h = h.clamp(-1.0, 1.0);
        let sin_o = wo.x.clamp(-1.0, 1.0);
        let cos_o = safe_sqrt((1.0 - sin_o) * (1.0 + sin_o));

        // Refraction in the normal plane (Bravais index η' = √(η² − sin²θ_o)/cos θ_o), written
        // without dividing by cos θ_o, which vanishes along the fiber. The same root is η cos θ_t.
        let eta = self.eta;
        let inv_root = 1.0 / (eta * eta - sin_o * sin_o).sqrt();
        let sin_gamma_t = h * cos_o * inv_root;
        let cos_gamma_t = safe_sqrt(1.0 - sin_gamma_t * sin_gamma_t);
        // γ_t and γ_o in two lanes of one vector asin.
        let [gamma_t, gamma_o, _, _] = f32x4::new([sin_gamma_t, h, 0.0, 0.0])
            .clamp(f32x4::splat(-1.0), f32x4::ONE)
            .asin()
            .to_array();
        // The three channels' transmittance over the path 2 cos γ_t / cos θ_t in one vector exp
        // (lane 3 spare).
        let t = simd_math::exp(self.sigma_a * f32x4::splat(-2.0 * eta * cos_gamma_t * inv_root));

        let f = fresnel_dielectric(cos_o * safe_sqrt(1.0 - h * h), eta);
        let a1 = f32x4::splat((1.0 - f) * (1.0 - f)) * t;
        let a2 = a1 * t * f32x4::splat(f);
        let ft = f32x4::splat(f) * t;
        // 1 − fT = 0 only when f = 1 (h = ±1), where a2 = 0: the floor turns 0/0 into 0.
        let a3 = a2 * ft / (f32x4::ONE - ft).max(f32x4::splat(f32::MIN_POSITIVE));
        // From lanes = channels to lanes = lobes.
        let [r, g, b, _] = f32x4::transpose([f32x4::splat(f), a1, a2, a3]);

        let lum = r * f32x4::splat(luminance(Rgb::X))
            + g * f32x4::splat(luminance(Rgb::Y))
            + b * f32x4::splat(luminance(Rgb::Z));
        let [l0, l1, l2, l3] = lum.to_array();
        let total = l0 + l1 + l2 + l3;
        let lobe_pdf = if total > 0.0 {
            lum / f32x4::splat(total)
        } else {
            f32x4::ZERO
        };

        // Lane 3's rotation by 0 (sin 0, cos 1) leaves θ_o exactly as it is.
        let (sin_o, cos_o) = (f32x4::splat(sin_o), f32x4::splat(cos_o));
        let [phi_r, phi_tt, phi_trt] =
            [0.0f32, 1.0, 2.0].map(|p| 2.0 * p * gamma_t - 2.0 * gamma_o + p * PI);
        Geometry {
            normal_o: normal_plane_direction(wo),
            sin_o: sin_o * self.tilt_cos + cos_o * self.tilt_sin,
            cos_o: (cos_o * self.tilt_cos - sin_o * self.tilt_sin).abs(),
            phi_exit: f32x4::new([phi_r, phi_tt, phi_trt, 0.0]),
            ap: [r, g, b],
            lobe_pdf,
        }
    }

    /// (eval, pdf) at `wi`: the two sums share every M_p and N_p.
    fn eval_pdf_at(&self, g: &Geometry, wi: Vec3) -> (Rgb, f32) {
        let (sin_i, cos_i, phi) = self.angles_i(g, wi);
        self.eval_pdf_angles(g, sin_i, cos_i, phi)
    }

    /// (eval, pdf) at the direction of angles (θ_i, φ_i − φ_o) given by their sine, cosine and
    /// difference: a sampled direction is evaluated at the angles it was drawn from, without
    /// taking them back from its vector.
    fn eval_pdf_angles(&self, g: &Geometry, sin_i: f32, cos_i: f32, phi: f32) -> (Rgb, f32) {
        let mn = self.lobes(g, sin_i, cos_i, phi);
        let [r, gr, b] = g.ap;
        // Lane p of each product is lobe p's term; transposed, lane c of row p is its term in
        // channel c (3: the pdf), so the sum of rows is (f, pdf).
        let [t0, t1, t2, t3] = f32x4::transpose([r * mn, gr * mn, b * mn, g.lobe_pdf * mn]);
        let [fr, fg, fb, pdf] = (t0 + t1 + t2 + t3).to_array();
        (Rgb::new(fr, fg, fb), pdf)
    }

    /// (sin θ_i, cos θ_i, φ_i − φ_o), the azimuth difference from one atan2 of the normal-plane
    /// projections' cross and dot products (wide's, in one lane: inlined, and a few times
    /// cheaper than libm's).
    fn angles_i(&self, g: &Geometry, wi: Vec3) -> (f32, f32, f32) {
        let sin_i = wi.x.clamp(-1.0, 1.0);
        let cos_i = safe_sqrt((1.0 - sin_i) * (1.0 + sin_i));
        let (y, z) = g.normal_o;
        let cross = f32x4::splat(y * wi.z - z * wi.y);
        let phi = cross.atan2(f32x4::splat(y * wi.y + z * wi.z)).as_array()[0];
        (sin_i, cos_i, phi)
    }

    /// `M_p N_p` of the four lobes, lobe p in lane p.
    fn lobes(&self, g: &Geometry, sin_i: f32, cos_i: f32, phi: f32) -> f32x4 {
        let m = longitudinal(
            self.inv_v,
            self.ln_norm,
            f32x4::splat(sin_i),
            f32x4::splat(cos_i),
            g.sin_o,
            g.cos_o,
        );
        let n = self.trimmed_logistic(wrap_pi(f32x4::splat(phi) - g.phi_exit));
        m * n.mul_add(N_LOGISTIC_LANES, N_RESIDUAL)
    }

    /// The trimmed logistic at angles in [−π, π], lane by lane.
    fn trimmed_logistic(&self, x: f32x4) -> f32x4 {
        let t = x.abs() / f32x4::splat(self.s);
        // Clamped so that exp never sees the far tail, which the select then zeroes.
        let negligible = t.simd_gt(f32x4::splat(-LN_NEGLIGIBLE));
        let e = simd_math::exp(-t.min(f32x4::splat(-LN_NEGLIGIBLE)));
        let one_plus_e = f32x4::ONE + e;
        let n = f32x4::splat(self.logistic_norm) * e / (one_plus_e * one_plus_e);
        negligible.select(f32x4::ZERO, n)
    }

    /// Inverse CDFs at `u_m` of the vMF lobes about their mirror directions and at `u_n` of the
    /// logistic trimmed to [−π, π]: (`1 − cos θ*` of each lobe, the azimuth's offset from a
    /// lobe's centre); the residual's vMF is TRT's (v_3 = v_2). All four logarithms are taken
    /// in one vector `ln`, and none depends on wo or h, so the CPU overlaps them with the
    /// geometry.
    fn sample_offsets(&self, u_m: f32, u_n: f32) -> ([f32; 4], f32) {
        // vMF: cos θ* = 1 + v ln(u + (1 − u) e^{−2/v}) = 1 + v ln(1 + x).
        let x = f32x4::splat(-(1.0 - u_m.max(U_MIN))) * self.one_minus_e;
        let one_plus_x = f32x4::ONE + x;
        let q = u_n.max(U_MIN) * self.cdf_range + self.cdf_lo;
        let [u0, u1, u2, _] = one_plus_x.to_array();
        let ln = simd_math::ln(f32x4::new([u0, u1, u2, q / (1.0 - q)]));
        // ln(1 + x) accurate near x = 0 (the lobe's mode): x ln(u) / (u − 1) with u = 1 + x
        // rounded cancels the rounding of u; x itself where u rounds to 1.
        let ln_1p = one_plus_x
            .simd_eq(f32x4::ONE)
            .select(x, ln * (x / (one_plus_x - f32x4::ONE)));
        let [w0, w1, w2, _] = (-self.v * ln_1p).min(f32x4::splat(2.0)).to_array();
        ([w0, w1, w2, w2], (self.s * ln.as_array()[3]).clamp(-PI, PI))
    }

    /// Draws a lobe, then θ_i from its longitudinal lobe and Δφ from its azimuthal one: the
    /// geometry, the lobe, the direction and its angles (sin θ_i, cos θ_i, Δφ).
    fn draw(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<Draw> {
        let (w_lobes, offset) = self.sample_offsets(u[1], u[3]);
        let g = self.geometry(wo, h);

        // The first lobe whose cumulative probability exceeds u[0] has positive probability;
        // if rounding leaves u[0] above the total, take the last lobe that can occur.
        let mut cdf = 0.0;
        let mut lobe = None;
        let lobe_pdf = g.lobe_pdf.to_array();
        for (p, &prob) in lobe_pdf.iter().enumerate() {
            cdf += prob;
            if u[0] < cdf {
                lobe = Some(p);
                break;
            }
        }
        let p = lobe.or_else(|| lobe_pdf.iter().rposition(|&q| q > 0.0))?;

        // θ_i: vMF about the mirror direction (−sin θ_o', cos θ_o') at angle θ* (1 − cos θ* = w),
        // then a uniform azimuth 2π u[2] about that axis. Δφ: the trimmed logistic about Φ(p, h),
        // uniform for the residual.
        let w = w_lobes[p];
        let dphi = if p < P_MAX {
            g.phi_exit.as_array()[p] + offset
        } else {
            TAU * u[3]
        };
        let (sin, cos) = simd_math::sin_cos(f32x4::new([TAU * u[2], dphi, 0.0, 0.0]));
        let [_, sin_d, _, _] = sin.to_array();
        let [cos_axis, cos_d, _, _] = cos.to_array();

        let (sin_o, cos_o) = (g.sin_o.as_array()[p], g.cos_o.as_array()[p]);
        let cos_star = 1.0 - w;
        let sin_star = safe_sqrt(w * (2.0 - w));
        let sin_i = (-cos_star * sin_o + sin_star * cos_axis * cos_o).clamp(-1.0, 1.0);
        let cos_i = safe_sqrt((1.0 - sin_i) * (1.0 + sin_i));

        // φ_i = φ_o + Δφ by the angle-addition formulas from wo's own (cos φ_o, sin φ_o).
        let (y, z) = g.normal_o;
        let r = (y * y + z * z).sqrt();
        let (cos_phi_o, sin_phi_o) = (y / r, z / r);
        let wi = Vec3::new(
            sin_i,
            cos_i * (cos_phi_o * cos_d - sin_phi_o * sin_d),
            cos_i * (sin_phi_o * cos_d + cos_phi_o * sin_d),
        );
        Some(Draw {
            g,
            lobe: p,
            wi,
            angles: (sin_i, cos_i, dphi),
        })
    }
}

impl Bcsdf for Chiang {
    fn eval(&self, wo: Vec3, wi: Vec3, h: f32) -> Rgb {
        self.eval_pdf_at(&self.geometry(wo, h), wi).0
    }

    fn sample(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<BcsdfSample> {
        let Draw { g, wi, angles, .. } = self.draw(wo, h, u)?;
        let (f, pdf) = self.eval_pdf_angles(&g, angles.0, angles.1, angles.2);
        (pdf > 0.0 && pdf.is_finite()).then_some(BcsdfSample { wi, f, pdf })
    }

    // Each lobe's M_p and N_p are sampled exactly (the vMF about the lobe's mirror direction,
    // the trimmed logistic or the uniform azimuth), so a sample of lobe p has f_p / pdf_p = A_p,
    // and choosing p with probability P(p) makes A_p / P(p) an unbiased weight: the other lobes'
    // values at the new direction are not needed.
    fn sample_weight(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<(Vec3, Rgb)> {
        let Draw { g, lobe, wi, .. } = self.draw(wo, h, u)?;
        let weight = g.attenuation(lobe) / g.lobe_pdf.as_array()[lobe];
        weight.is_finite().then_some((wi, weight))
    }

    fn pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> f32 {
        self.eval_pdf_at(&self.geometry(wo, h), wi).1
    }

    fn eval_pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> (Rgb, f32) {
        self.eval_pdf_at(&self.geometry(wo, h), wi)
    }

    fn lobe_names(&self) -> &'static [&'static str] {
        &["R", "TT", "TRT", "residual"]
    }

    fn eval_lobe(&self, wo: Vec3, wi: Vec3, h: f32, p: usize) -> Rgb {
        if p > P_MAX {
            return Rgb::ZERO;
        }
        let g = self.geometry(wo, h);
        let (sin_i, cos_i, phi) = self.angles_i(&g, wi);
        g.attenuation(p) * self.lobes(&g, sin_i, cos_i, phi).as_array()[p]
    }

    // The geometry (Fresnel, attenuations, exit azimuths) once for all directions, and the
    // angles of each direction once for all lobes: the same operations as `eval_lobe`.
    fn eval_lobes_batch(&self, wo: Vec3, h: f32, wis: &[Vec3], out: &mut [Rgb]) {
        let g = self.geometry(wo, h);
        let ap = g.attenuations();
        for (&wi, row) in wis.iter().zip(out.chunks_exact_mut(P_MAX + 1)) {
            let (sin_i, cos_i, phi) = self.angles_i(&g, wi);
            let mn = self.lobes(&g, sin_i, cos_i, phi).to_array();
            for ((v, &ap), mn) in row.iter_mut().zip(&ap).zip(mn) {
                *v = ap * mn;
            }
        }
    }
}

/// `w`'s direction in the normal plane, unnormalised, the reference of azimuths: (w.y, w.z), but
/// scaled up by its larger component where its squared length is not a normal f32 (sideways
/// parts under ~1e-19, w along the fiber), since that length and the cross and dot products
/// with wi would lose their precision there and vanish further down (`draw` divided 0 by 0);
/// (1, 0) on the axis itself, where φ is undefined and taken as 0.
fn normal_plane_direction(w: Vec3) -> (f32, f32) {
    let (y, z) = (w.y, w.z);
    if y * y + z * z >= f32::MIN_POSITIVE {
        return (y, z);
    }
    let m = y.abs().max(z.abs());
    if m == 0.0 {
        (1.0, 0.0)
    } else {
        (y / m, z / m)
    }
}

/// `−ln v − ln(1 − e^{−2/v})`, the log of `e^{1/v} / (2 v sinh(1/v))`.
fn vmf_ln_norm(v: f64) -> f32 {
    (-v.ln() - (-(-2.0 / v).exp_m1()).ln()) as f32
}

/// The vMF longitudinal lobe M_p(v; θ_i, θ_o), normalised so that ∫ M cos θ_i dθ_i = 1, lane by
/// lane (lobe p's `1/v`, `ln_norm` and tilted θ_o in lane p).
///
/// `exp(−b) I₀(a) / (2v sinh(1/v))` with `a = cos θ_i cos θ_o / v`, `b = sin θ_i sin θ_o / v`
/// equals `exp((a − b − 1/v) + ln_norm) · I₀(a) e^{−a}`, and `a − b − 1/v = −|u − m|²/(2v)`
/// for the unit vectors `u = (sin θ_i, cos θ_i)`, `m = (−sin θ_o, cos θ_o)`: a sum of squares,
/// so tiny v neither overflows nor cancels. One `exp` per lobe: the scaled Bessel factor is
/// folded into its argument (small a) or multiplied after it (large a), never taken as a log.
fn longitudinal(
    inv_v: f32x4,
    ln_norm: f32x4,
    sin_i: f32x4,
    cos_i: f32x4,
    sin_o: f32x4,
    cos_o: f32x4,
) -> f32x4 {
    // The Bessel factor is at most I₀(3.75) ≈ 9.1 (≈ e^{2.2}) on the small-argument branch and
    // below 1 on the other, so a lobe under this cut stays negligible after multiplying it in.
    const LN_CUT: f32 = LN_NEGLIGIBLE - 2.3;
    let ds = sin_i + sin_o;
    let dc = cos_i - cos_o;
    let a = cos_i * cos_o * inv_v;
    let ln_gauss = ln_norm - (ds * ds + dc * dc) * (f32x4::HALF * inv_v);
    let (ln_part, bessel) = i0_scaled_split(a);
    let ln_m = ln_gauss + ln_part;
    // Clamped so that exp never sees the far tail, which the select then zeroes.
    let m = simd_math::exp(ln_m.max(f32x4::splat(LN_CUT))) * bessel;
    ln_m.simd_lt(f32x4::splat(LN_CUT)).select(f32x4::ZERO, m)
}

/// `I₀(x) e^{−x}` for x ≥ 0 as `exp(ln_part) · factor`, from Abramowitz & Stegun 9.8.1
/// (x ≤ 3.75, |ε| < 1.6·10⁻⁷: `(−x, I₀(x))`) and 9.8.2 (x > 3.75, |ε| < 1.9·10⁻⁷ on
/// √x e^{−x} I₀(x): `(0, that / √x)`), so the caller adds `ln_part` to its own exponent. Both
/// branches are evaluated in every lane and the right one selected (the other may be inf or NaN).
#[allow(clippy::excessive_precision)] // the published coefficients, digit for digit
fn i0_scaled_split(x: f32x4) -> (f32x4, f32x4) {
    let c = f32x4::splat;
    let small = x.simd_le(c(3.75));
    // Estrin's scheme: pairs of terms in parallel rather than one long Horner chain.
    let t = (x * c(1.0 / 3.75)) * (x * c(1.0 / 3.75));
    let t2 = t * t;
    let p_small = (c(1.0) + t * c(3.515_622_9))
        + t2 * (c(3.089_942_4) + t * c(1.206_749_2))
        + t2 * t2 * ((c(0.265_973_2) + t * c(0.036_076_8)) + t2 * c(0.004_581_3));
    let t = c(3.75) / x;
    let t2 = t * t;
    let t4 = t2 * t2;
    let p_large = (c(0.398_942_28) + t * c(0.013_285_92))
        + t2 * (c(0.002_253_19) + t * c(-0.001_575_65))
        + t4 * ((c(0.009_162_81) + t * c(-0.020_577_06))
            + t2 * (c(0.026_355_37) + t * c(-0.016_476_33)))
        + t4 * t4 * c(0.003_923_77);
    (
        small.select(-x, f32x4::ZERO),
        small.select(p_small, p_large / x.sqrt()),
    )
}

/// Wraps angles to [−π, π].
fn wrap_pi(x: f32x4) -> f32x4 {
    x - f32x4::splat(TAU) * (x * f32x4::splat(1.0 / TAU)).round_ties_even()
}

/// Unpolarised Fresnel reflectance entering a dielectric of index `eta` > 1 from outside.
fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    let cos_t = safe_sqrt(1.0 - sin_t2);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let r_par = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (r_perp * r_perp + r_par * r_par)
}

/// Parameter sets the statistical tests run on this model ([`crate::HairModel::test_instances`]).
pub fn test_instances() -> Vec<TestInstance<Params>> {
    let white = |name: &str, beta_m, beta_n, alpha| TestInstance {
        name: name.into(),
        params: Params {
            beta_m,
            beta_n,
            alpha,
            pigment: Pigment::SigmaA((0.0, 0.0, 0.0)),
            ..Params::default()
        },
        white_furnace: true,
    };
    vec![
        white("white_smooth", 0.1, 0.1, 0.0),
        white("white_default", 0.3, 0.3, 2.0),
        white("white_rough", 0.6, 0.7, 4.0),
        white("white_very_rough", 0.9, 0.9, 0.0),
        TestInstance {
            name: "brown".into(),
            params: Params::default(),
            white_furnace: false,
        },
        TestInstance {
            name: "blond".into(),
            params: Params {
                beta_m: 0.2,
                beta_n: 0.5,
                alpha: 3.0,
                eta: 1.6,
                pigment: Pigment::Melanin {
                    eumelanin: 0.3,
                    pheomelanin: 0.15,
                    tint: crate::pigment::NO_TINT,
                },
            },
            white_furnace: false,
        },
        TestInstance {
            name: "auburn_color".into(),
            params: Params {
                beta_m: 0.4,
                beta_n: 0.2,
                alpha: -2.0,
                pigment: Pigment::Color((0.55, 0.25, 0.12)),
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
    use std::f32::consts::FRAC_PI_2;
    use tress_core::math::fiber_direction;

    fn chiang(beta_m: f32, beta_n: f32, alpha: f32, pigment: Pigment) -> Chiang {
        Chiang::new(&Params {
            beta_m,
            beta_n,
            alpha,
            pigment,
            ..Params::default()
        })
        .unwrap()
    }

    /// wo at θ_o in the fiber frame (φ_o = π/2) and wi at θ_i, φ_i − φ_o = `phi`.
    fn dirs(theta_o: f32, theta_i: f32, phi: f32) -> (Vec3, Vec3) {
        (
            fiber_direction(theta_o.sin(), theta_o.cos(), FRAC_PI_2),
            fiber_direction(theta_i.sin(), theta_i.cos(), FRAC_PI_2 + phi),
        )
    }

    fn rel(a: f32, b: f64) -> f64 {
        (a as f64 - b).abs() / b.abs()
    }

    /// One lobe of variance `v` through the lane-wise [`super::longitudinal`].
    fn longitudinal(v: f32, ln_norm: f32, sin_i: f32, cos_i: f32, sin_o: f32, cos_o: f32) -> f32 {
        let s = f32x4::splat;
        let m = super::longitudinal(
            s(1.0 / v),
            s(ln_norm),
            s(sin_i),
            s(cos_i),
            s(sin_o),
            s(cos_o),
        );
        m.as_array()[0]
    }

    /// One argument through the lane-wise [`super::i0_scaled_split`].
    fn i0_scaled_split(x: f32) -> (f32, f32) {
        let (ln_part, factor) = super::i0_scaled_split(f32x4::splat(x));
        (ln_part.as_array()[0], factor.as_array()[0])
    }

    #[test]
    fn attenuations_sum_to_one_without_absorption() {
        let c = chiang(0.3, 0.3, 2.0, Pigment::SigmaA((0.0, 0.0, 0.0)));
        let brown = chiang(0.3, 0.3, 2.0, Pigment::default());
        for i in 0..=40 {
            let h = -1.0 + i as f32 / 20.0;
            for j in 0..=36 {
                let theta_o = (-90.0 + 5.0 * j as f32).to_radians();
                let wo = fiber_direction(theta_o.sin(), theta_o.cos(), FRAC_PI_2);
                let g = c.geometry(wo, h);
                let sum: Rgb = g.attenuations().iter().sum();
                assert!(
                    (sum - Rgb::ONE).abs().max_element() < 1e-6,
                    "h {h} θ_o {theta_o}: {sum}"
                );
                let absorbing: Rgb = brown.geometry(wo, h).attenuations().iter().sum();
                assert!(absorbing.max_element() <= 1.0 && absorbing.min_element() >= 0.0);
            }
        }
    }

    /// ∫ M cos θ_i dθ_i by the midpoint rule in θ_i.
    fn m_integral(v: f32, theta_o: f32) -> f64 {
        let n = 40_000;
        let d = std::f64::consts::PI / n as f64;
        let ln_norm = vmf_ln_norm(v as f64);
        (0..n)
            .map(|k| {
                let t = -std::f64::consts::FRAC_PI_2 + (k as f64 + 0.5) * d;
                let (s, c) = (t.sin() as f32, t.cos() as f32);
                longitudinal(v, ln_norm, s, c, theta_o.sin(), theta_o.cos()) as f64 * t.cos() * d
            })
            .sum()
    }

    #[test]
    fn longitudinal_is_normalised_and_continuous() {
        // 1.3e-7 is v_TT at β_m = BETA_MIN; 110 is v_TRT at β_m = 1.
        for v in [
            1.3e-7, 1e-5, 0.002, 0.01, 0.05, 0.0999, 0.1, 0.1001, 0.3, 1.0, 2.0, 110.0,
        ] {
            for theta_o in [0.0f32, 0.5, 1.0, 1.5, -1.2] {
                let i = m_integral(v, theta_o);
                assert!((i - 1.0).abs() < 1e-4, "v {v} θ_o {theta_o}: ∫M cos = {i}");
            }
        }
        // pbrt switches between a direct and a logarithmic form at v = 0.1; the single form here
        // must be continuous there (oracle: relative jump < 1e-3) ...
        let m = |v: f32| {
            longitudinal(
                v,
                vmf_ln_norm(v as f64),
                0.1f32.sin(),
                0.1f32.cos(),
                0.2f32.sin(),
                0.2f32.cos(),
            )
        };
        let (lo, hi) = (m(0.1 * (1.0 - 1e-4)), m(0.1 * (1.0 + 1e-4)));
        assert!((lo / hi - 1.0).abs() < 1e-3, "{lo} {hi}");
        // ... and so must the switch of the I₀ approximation at 3.75.
        let i0_scaled = |x: f32| {
            let (ln_part, factor) = i0_scaled_split(x);
            ln_part.exp() * factor
        };
        let jump = i0_scaled(3.75) / i0_scaled(3.750_001) - 1.0;
        assert!(jump.abs() < 2e-6, "{jump}");
    }

    #[test]
    #[allow(clippy::excessive_precision)] // oracle values as printed by mpmath
    fn longitudinal_matches_mpmath() {
        // Produced once with mpmath (40 digits): exp(−b)·besseli(0, a)/(2v·sinh(1/v)).
        // The first case is the R peak at β_m = 0.3, θ_o = θ_i = 0 (a = 11.8), where pbrt's
        // 10-term I₀ series is 1.7 % low.
        let oracle: [(f32, f32, f32, f64); 7] = [
            (0.084_611_174_475_053_5, 0.0, 0.0, 1.386_767_631_096_17),
            (0.002, -0.31, 0.3, 9.123_984_444_352_8),
            (0.05, 0.2, -0.1, 1.645_699_434_182_52),
            (0.1, 0.4, -0.5, 1.357_140_415_169_11),
            (0.3, 1.0, 0.2, 0.132_601_984_181_4),
            (5.0, -1.2, 0.7, 0.560_486_673_074_95),
            (100.0, 0.3, 1.4, 0.498_538_036_242_365),
        ];
        for (v, ti, to, want) in oracle {
            let got = longitudinal(
                v,
                vmf_ln_norm(v as f64),
                ti.sin(),
                ti.cos(),
                to.sin(),
                to.cos(),
            );
            // θ enters as f32; at v = 0.002 a rounding of 6e-8 rad moves M by ~1e-5 relative.
            assert!(
                rel(got, want) < 5e-5,
                "v {v} θ_i {ti} θ_o {to}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn trimmed_logistic_is_normalised_and_sampler_inverts_its_cdf() {
        for beta_n in [BETA_MIN, 0.01, 0.1, 0.3, 0.6, 0.9, 1.0] {
            let c = chiang(0.3, beta_n, 0.0, Pigment::default());
            let n = 200_000;
            let d = 2.0 * std::f64::consts::PI / n as f64;
            let acc: f64 = (0..n)
                .map(|k| {
                    let x = -std::f64::consts::PI + (k as f64 + 0.5) * d;
                    c.trimmed_logistic(f32x4::splat(x as f32)).as_array()[0] as f64 * d
                })
                .sum();
            // With s = 1.7e-4 (β_n = 1e-3) the midpoint grid (3e-5) still resolves the lobe.
            assert!((acc - 1.0).abs() < 1e-5, "β_n {beta_n}: ∫N = {acc}");
            // The sampler inverts the closed-form trimmed CDF.
            let s = c.s as f64;
            let cdf = |x: f64| 1.0 / (1.0 + (-x / s).exp());
            let pi = std::f64::consts::PI;
            for u in [0.01f32, 0.2, 0.5, 0.77, 0.99] {
                let x = c.sample_offsets(0.5, u).1 as f64;
                let back = (cdf(x) - cdf(-pi)) / (cdf(pi) - cdf(-pi));
                assert!(
                    (back - u as f64).abs() < 1e-4,
                    "β_n {beta_n} u {u}: CDF(x) = {back}"
                );
            }
        }
    }

    #[test]
    #[allow(clippy::excessive_precision)] // oracle values as printed by mpmath
    fn eval_and_pdf_match_mpmath() {
        // Produced once by an independent mpmath script (40 digits, exact Bessel I₀, direct vMF
        // form, pbrt-v4 tilt and Φ conventions): (β_m, β_n, α°, η, σ_a, θ_o, θ_i, φ, h) →
        // (eval RGB, pdf). σ_a "brown" = 1.3·(0.419, 0.697, 1.37).
        let brown = Pigment::Melanin {
            eumelanin: 1.3,
            pheomelanin: 0.0,
            tint: crate::pigment::NO_TINT,
        };
        let cases: [(Params, [f32; 4], [f64; 3], f64); 5] = [
            (
                Params {
                    pigment: brown.clone(),
                    ..Params::default()
                },
                [0.3, -0.2, 1.0, 0.5],
                [
                    5.944_572_542_83e-5,
                    1.375_734_963_72e-5,
                    5.837_241_190_16e-7,
                ],
                9.680_578_308_35e-5,
            ),
            (
                Params {
                    pigment: brown.clone(),
                    ..Params::default()
                },
                [0.3, -0.2, -1.0, 0.5],
                [0.143_133_604_177, 0.143_123_025_717, 0.143_121_444_891],
                0.615_258_098_612,
            ),
            (
                Params {
                    pigment: brown,
                    ..Params::default()
                },
                [0.0, 0.05, 3.0, -0.3],
                [0.258_692_481_372, 0.127_291_540_994, 0.022_868_469_386_2],
                0.651_112_538_855,
            ),
            (
                Params {
                    beta_m: 0.2,
                    beta_n: 0.5,
                    alpha: 3.0,
                    eta: 1.6,
                    pigment: Pigment::SigmaA((0.1, 0.2, 0.4)),
                },
                [-1.0, 0.9, -2.5, 0.8],
                [0.146_791_194_771, 0.141_516_166_385, 0.135_784_839_464],
                0.207_094_774_218,
            ),
            (
                Params {
                    beta_m: 0.7,
                    beta_n: 0.2,
                    alpha: 0.0,
                    pigment: Pigment::SigmaA((0.0, 0.0, 0.0)),
                    ..Params::default()
                },
                [1.2, -1.3, 0.3, -0.95],
                [0.013_768_274_290_4; 3],
                0.013_768_274_290_4,
            ),
        ];
        for (params, [to, ti, phi, h], want_f, want_pdf) in cases {
            let c = Chiang::new(&params).unwrap();
            let (wo, wi) = dirs(to, ti, phi);
            let f = c.eval(wo, wi, h);
            for k in 0..3 {
                assert!(
                    rel(f[k], want_f[k]) < 2e-4,
                    "{params:?} case {to} {ti} {phi} {h}: {f} vs {want_f:?}"
                );
            }
            let pdf = c.pdf(wo, wi, h);
            assert!(
                rel(pdf, want_pdf) < 2e-4,
                "{params:?}: pdf {pdf} vs {want_pdf}"
            );
        }
    }

    #[test]
    fn azimuth_is_mirror_symmetric_but_not_even() {
        let c = chiang(0.3, 0.3, 2.0, Pigment::default());
        let (wo, wi_pos) = dirs(0.3, -0.2, 1.0);
        let (_, wi_neg) = dirs(0.3, -0.2, -1.0);
        let f_pos = c.eval(wo, wi_pos, 0.5);
        let f_neg = c.eval(wo, wi_neg, 0.5);
        let f_mirror = c.eval(wo, wi_neg, -0.5);
        // At h = 0.5 the R lobe sits at φ = −2 asin 0.5 = −π/3: φ = −1 is near it, φ = +1 is not.
        assert!(f_neg.x > 100.0 * f_pos.x, "{f_pos} {f_neg}");
        assert!(
            ((f_mirror - f_pos) / f_pos).abs().max_element() < 1e-4,
            "{f_pos} {f_mirror}"
        );
    }

    #[test]
    fn sampling_weights_are_one_without_absorption() {
        let mut rng = tress_core::Sampler::from_seed(11);
        for (bm, bn) in [(0.1, 0.4), (0.3, 0.6), (0.5, 0.8), (0.9, 0.4)] {
            let c = chiang(bm, bn, 2.0, Pigment::SigmaA((0.0, 0.0, 0.0)));
            for _ in 0..10_000 {
                let theta_o = (rng.next_1d() - 0.5) * PI;
                let wo = fiber_direction(theta_o.sin(), theta_o.cos(), FRAC_PI_2);
                let h = 2.0 * rng.next_1d() - 1.0;
                let s = c
                    .sample(wo, h, rng.next_4d())
                    .expect("white fiber always scatters");
                let w = s.f / s.pdf;
                assert!((w - Rgb::ONE).abs().max_element() < 1e-5, "{w}");
            }
        }
    }

    #[test]
    fn lobes_sum_to_eval() {
        let c = chiang(0.3, 0.3, 2.0, Pigment::default());
        assert_eq!(c.lobe_names().len(), P_MAX + 1);
        for (to, ti, phi, h) in [
            (0.3, -0.2, 1.0, 0.5),
            (-1.0, 0.9, -2.5, 0.8),
            (1.4, 0.0, 3.1, -1.0),
        ] {
            let (wo, wi) = dirs(to, ti, phi);
            let sum: Rgb = (0..=P_MAX).map(|p| c.eval_lobe(wo, wi, h, p)).sum();
            let f = c.eval(wo, wi, h);
            assert!(
                (sum - f).abs().max_element() <= 1e-6 * f.max_element(),
                "{sum} vs {f}"
            );
        }
        assert_eq!(c.eval_lobe(Vec3::Z, Vec3::Z, 0.0, P_MAX + 1), Rgb::ZERO);
    }

    #[test]
    fn zero_random_numbers_do_not_reach_zero_density() {
        // u = 0 fed to the inverse CDFs lands on the vMF antipode / the logistic's trimmed end,
        // where the pdf underflows: a 24-bit generator produces it once in 2²⁴ draws, enough for
        // a χ² test with 10⁶ samples to see a sample in a cell of expected count 0.
        let c = chiang(0.1, 0.1, 0.0, Pigment::SigmaA((0.0, 0.0, 0.0)));
        let wo = fiber_direction(
            75f32.to_radians().sin(),
            75f32.to_radians().cos(),
            FRAC_PI_2,
        );
        for lobe_u in [0.01, 0.35, 0.9, 0.999] {
            for u in [
                [lobe_u, 0.0, 0.54, 0.5],
                [lobe_u, 0.5, 0.3, 0.0],
                [lobe_u, 0.0, 0.0, 0.0],
            ] {
                let s = c.sample(wo, -0.8, u).unwrap();
                assert!(s.pdf > 1e-12, "u {u:?}: pdf {}", s.pdf);
            }
        }
    }

    #[test]
    fn invalid_parameters_are_rejected_by_name() {
        assert_rejected(
            Chiang::new,
            &[
                (|p| p.beta_m = 0.0, "beta_m"),
                (|p| p.beta_m = 1.5, "beta_m"),
                (|p| p.beta_n = f32::NAN, "beta_n"),
                (|p| p.alpha = 120.0, "alpha"),
                (|p| p.eta = 1.0, "eta"),
                (|p| p.eta = f32::INFINITY, "eta"),
                (
                    |p| {
                        p.pigment = Pigment::Melanin {
                            eumelanin: -1.0,
                            pheomelanin: 0.0,
                            tint: crate::pigment::NO_TINT,
                        }
                    },
                    "eumelanin",
                ),
            ],
        );
        assert!(Chiang::new(&Params {
            beta_m: BETA_MIN,
            beta_n: 1.0,
            ..Params::default()
        })
        .is_ok());
    }

    #[test]
    fn documented_ron_example_parses() {
        use crate::HairModel;
        let opts = ron::Options::default()
            .with_default_extension(ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES);
        let text = "Chiang(beta_m: 0.3, beta_n: 0.3, alpha: 2.0, \
                    pigment: Melanin(eumelanin: 1.3, pheomelanin: 0.2))";
        let model: HairModel = opts.from_str(text).unwrap();
        let want = Params {
            pigment: Pigment::Melanin {
                eumelanin: 1.3,
                pheomelanin: 0.2,
                tint: crate::pigment::NO_TINT,
            },
            ..Params::default()
        };
        assert_eq!(model, HairModel::Chiang(want));
        assert!(opts.from_str::<HairModel>("Chiang(beta: 0.3)").is_err());
        assert_eq!(
            opts.from_str::<HairModel>("Chiang()").unwrap(),
            HairModel::Chiang(Params::default())
        );
    }
}
