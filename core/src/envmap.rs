//! Equirectangular environment map with importance sampling.

use crate::light::LightSample;
use crate::math::{Rgb, Vec2, Vec3};

/// An equirectangular environment map (see `crate::light` for the direction convention).
#[derive(Clone, Debug)]
pub struct EnvironmentMap {}

impl EnvironmentMap {
    pub fn sample(&self, _u: Vec2) -> Option<LightSample> {
        todo!("environment map sampling")
    }
    pub fn pdf(&self, _wi: Vec3) -> f32 {
        todo!("environment map pdf")
    }
    pub fn radiance(&self, _dir: Vec3) -> Rgb {
        todo!("environment map lookup")
    }
}
