//! The integrator interface: radiance along one camera ray.

use crate::math::{Ray, Rgb};
use crate::rng::Sampler;
use crate::scene::Scene;

/// Estimates the radiance arriving along a camera ray. The render loop in [`crate::render`] owns
/// tiles, seeding, film and progress, so an integrator only writes `li`.
pub trait Integrator: Send + Sync + std::fmt::Debug {
    /// One sample of the radiance arriving at the camera along `ray` (travelling away from it).
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb;
}
