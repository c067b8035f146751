//! The fiber scattering interface.
//!
//! # Local fiber frame (used by every [`Bcsdf`])
//! - **x** = the curve tangent `t`, root → tip. `sin θ = ω.x`, θ ∈ [−π/2, π/2], +π/2 toward the tip.
//! - **z** = the unit vector ⟂ t pointing back toward the viewer: the component of `wo` (the
//!   direction the hit was seen from) orthogonal to `t`, normalised. Flat-curve ribbons face the
//!   ray, so z is also the ribbon normal.
//! - **y** = z × x, across the ribbon's width.
//! - Azimuth `φ = atan2(ω.z, ω.y)`, so `wo` always has φ_o = π/2 (up to the tangent component).
//! - **h** ∈ [−1, 1] is the signed offset of the hit from the fiber axis along **y**, in units of
//!   the fiber radius. With this sign, specular reflection (p = 0) leaves at
//!   φ_i − φ_o = −2·asin(h), the convention of pbrt and Chiang et al. 2016.
//!
//! Models that [use the fiber's orientation](Bcsdf::uses_orientation) (an elliptical fiber's
//! major axis) get directions in the *oriented* frame instead: x the tangent, z the orientation
//! made orthogonal to it, y = z × x; `h` is still measured along the view-facing y above.
//!
//! # Value convention
//! [`Bcsdf::eval`] returns `f(wo, wi) · cos θ_i` — the cosine to the fiber's normal plane is
//! *included* — so the scattered radiance is `L_o(wo) = ∫_{S²} eval(wo, wi) L_i(wi) dω_i` and an
//! energy-conserving, non-absorbing fiber integrates to exactly 1 (the white furnace). A sample's
//! Monte Carlo weight is `f / pdf`, with `pdf` per unit solid angle.

use crate::math::{Frame, Rgb, Vec3};
use std::fmt::Debug;

/// A direction sampled from a BCSDF, with its value (`eval` at `wi`) and solid-angle pdf.
#[derive(Clone, Copy, Debug)]
pub struct BcsdfSample {
    /// Sampled incident direction, unit, in the local fiber frame.
    pub wi: Vec3,
    /// `eval(wo, wi)`: includes cos θ_i (see the module docs).
    pub f: Rgb,
    /// Solid-angle density of `wi`.
    pub pdf: f32,
}

/// A fiber scattering function in the local fiber frame (module docs).
pub trait Bcsdf: Send + Sync + Debug {
    /// `f(wo, wi) · cos θ_i` for unit directions `wo`, `wi` at offset `h`.
    fn eval(&self, wo: Vec3, wi: Vec3, h: f32) -> Rgb;

    /// Importance-sample `wi` from four uniform numbers in [0, 1). `None` when no direction
    /// carries energy.
    fn sample(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<BcsdfSample>;

    /// The solid-angle density with which [`Bcsdf::sample`] produces `wi`.
    fn pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> f32;

    /// The direction [`Bcsdf::sample`] draws from the same numbers, with a Monte Carlo weight
    /// whose expectation is that of `f / pdf` — `E[weight · g(wi)] = ∫ eval(wo, wi) g(wi) dω_i`
    /// for every `g` — but which may differ from it sample by sample. For paths that need no
    /// density (no multiple importance sampling at the next vertex). The default is `f / pdf`;
    /// a model that samples each of its lobes exactly overrides it with the chosen lobe's
    /// attenuation over the probability of choosing it, and skips evaluating every lobe at the
    /// new direction.
    fn sample_weight(&self, wo: Vec3, h: f32, u: [f32; 4]) -> Option<(Vec3, Rgb)> {
        let s = self.sample(wo, h, u)?;
        (s.pdf > 0.0).then(|| (s.wi, s.f / s.pdf))
    }

    /// `(eval, pdf)` in one call, for next-event estimation with MIS, which needs both. Models
    /// whose two share per-hit work (angles, Fresnel, attenuations, lobe terms) override it.
    fn eval_pdf(&self, wo: Vec3, wi: Vec3, h: f32) -> (Rgb, f32) {
        (self.eval(wo, wi, h), self.pdf(wo, wi, h))
    }

    /// Names of the lobes `eval` is a sum of (e.g. R, TT, TRT, residual), for plots and the
    /// per-lobe dual-scattering tables. A model without a decomposition is one lobe.
    fn lobe_names(&self) -> &'static [&'static str] {
        &["all"]
    }

    /// The part of `eval` due to lobe `p` (indexing `lobe_names`); the lobes sum to `eval`.
    fn eval_lobe(&self, wo: Vec3, wi: Vec3, h: f32, p: usize) -> Rgb {
        if p == 0 {
            self.eval(wo, wi, h)
        } else {
            Rgb::ZERO
        }
    }

    /// [`Bcsdf::eval_lobe`] of every lobe for every direction of `wis`, at one `wo` and `h`:
    /// `out[i * lobes + p]` for `wis[i]` and lobe `p` (`out.len()` = `wis.len()` × lobe
    /// count). Quadratures over `wi` (the dual-scattering tables) call this; models whose
    /// per-`(wo, h)` work (Fresnel, attenuations, exit azimuths) dominates compute it once here
    /// and must give exactly what `eval_lobe` gives.
    fn eval_lobes_batch(&self, wo: Vec3, h: f32, wis: &[Vec3], out: &mut [Rgb]) {
        let lobes = self.lobe_names().len();
        debug_assert_eq!(out.len(), wis.len() * lobes);
        for (&wi, row) in wis.iter().zip(out.chunks_exact_mut(lobes)) {
            for (p, v) in row.iter_mut().enumerate() {
                *v = self.eval_lobe(wo, wi, h, p);
            }
        }
    }

    /// Whether the model depends on the fiber's orientation about its axis (an elliptical
    /// cross-section). If so, the shading point hands it directions in the *oriented* frame
    /// ([`FiberFrame::oriented`]: z the fiber's orientation, e.g. its major axis) instead of the
    /// view-facing one; `h` keeps its meaning (measured along the view-facing frame's y, which
    /// the model rebuilds from `wo`). By default false, and models that leave it so see exactly
    /// the view-facing frame, whatever orientation the groom carries.
    fn uses_orientation(&self) -> bool {
        false
    }
}

/// The local frame at a fiber hit (module docs): built from the tangent and the direction the hit
/// is seen from. Accelerators compute `h` against exactly this frame.
#[derive(Clone, Copy, Debug)]
pub struct FiberFrame(pub Frame);

impl FiberFrame {
    /// Frame with x = `tangent`, z = `toward_viewer` made orthogonal to it.
    pub fn new(tangent: Vec3, toward_viewer: Vec3) -> Self {
        let x = tangent.normalize();
        let z_raw = toward_viewer - x * toward_viewer.dot(x);
        let z = if z_raw.length_squared() > 1e-12 {
            z_raw.normalize()
        } else {
            // Looking straight along the fiber: any normal will do.
            Frame::from_z(x).x
        };
        FiberFrame(Frame {
            x,
            y: z.cross(x),
            z,
        })
    }

    /// Frame with x = `tangent` and z = `orientation` made orthogonal to it: the frame of models
    /// that [use the orientation](Bcsdf::uses_orientation). Falls back to the view-facing frame
    /// toward `toward_viewer` where the orientation is (nearly) along the tangent.
    pub fn oriented(tangent: Vec3, orientation: Vec3, toward_viewer: Vec3) -> Self {
        let x = tangent.normalize();
        let z_raw = orientation - x * orientation.dot(x);
        if z_raw.length_squared() <= 1e-12 {
            return Self::new(tangent, toward_viewer);
        }
        let z = z_raw.normalize();
        FiberFrame(Frame {
            x,
            y: z.cross(x),
            z,
        })
    }

    /// World vector `v` in fiber-frame coordinates (x along the tangent).
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        self.0.to_local(v)
    }

    /// Fiber-frame coordinates `v` back to a world vector.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.0.to_world(v)
    }

    /// Across-width axis (y): the direction along which `h` is measured.
    pub fn width_axis(&self) -> Vec3 {
        self.0.y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fiber_frame_is_right_handed_and_faces_viewer() {
        let t = Vec3::new(0.0, 1.0, 0.2).normalize();
        let wo = Vec3::new(0.3, 0.1, 1.0).normalize();
        let f = FiberFrame::new(t, wo);
        assert!((f.0.x.cross(f.0.y) - f.0.z).length() < 1e-5);
        let l = f.to_local(wo);
        assert!(l.y.abs() < 1e-5 && l.z > 0.0);
    }
}
