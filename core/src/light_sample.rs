//! What lights and the environment maps they may hold ([`crate::envmap`]) share: a light
//! sample as a shading point sees it, and the brightest value a light may have.

use crate::math::{Rgb, Vec3};

/// A light sample as seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point toward the light.
    pub wi: Vec3,
    /// Radiance arriving along `wi` (for a point light: intensity / distance²).
    pub radiance: Rgb,
    /// Solid-angle pdf; for delta lights the probability (1) of the chosen direction.
    pub pdf: f32,
    /// Distance to the light (infinite for lights at infinity).
    pub distance: f32,
    /// Whether the light is a delta distribution (no MIS possible).
    pub is_delta: bool,
}

/// The brightest radiance, irradiance or intensity a light may have: paths multiply it by
/// throughputs well above 1 (BSDF over pdf), and a product beyond f32 is a dropped sample.
pub const MAX_LIGHT: f32 = 1e30;
