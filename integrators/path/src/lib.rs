//! Unidirectional path tracing — tress's ground truth.
//!
//! At every vertex: next-event estimation toward one light chosen uniformly (constant skies are
//! left to the scattered ray: `Light::is_sampled_directly`), combined by
//! multiple importance sampling (power heuristic) with the scattering-sampled direction, which
//! is reused as the ray that finds lights at infinity. Russian roulette after `rr_depth` bounces.
//!
//! RON: `Path(max_depth: 100, rr_depth: 5)`

#![warn(missing_docs)]

use serde::{Deserialize, Serialize};
use tress_core::integrator::trace_path;
use tress_core::integrator::BuildError;
use tress_core::prepare::Preparation;
use tress_core::{Integrator, IntegratorKind, Ray, Rgb, Sampler, Scene};

/// Path tracer settings.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PathSettings {
    /// Maximum number of scattering events. Light hair needs many (each fiber passes most of the
    /// light on), hence the high default.
    pub max_depth: u32,
    /// Bounces before Russian roulette starts.
    pub rr_depth: u32,
}

impl Default for PathSettings {
    fn default() -> Self {
        PathSettings {
            max_depth: 100,
            rr_depth: 5,
        }
    }
}

/// The path integrator.
#[derive(Clone, Debug)]
pub struct PathTracer {
    settings: PathSettings,
}

impl PathTracer {
    /// A path tracer with `settings`.
    pub fn new(settings: PathSettings) -> Self {
        PathTracer { settings }
    }
}

impl IntegratorKind for PathTracer {
    type Settings = PathSettings;
    const NAME: &'static str = "path";
    const UNBIASED: bool = true;

    fn build(
        settings: &PathSettings,
        _: &Scene,
        _: &Preparation,
    ) -> Result<Box<dyn Integrator>, BuildError> {
        Ok(Box::new(PathTracer::new(settings.clone())))
    }

    /// Paths deep enough for white furnaces to balance (Russian roulette keeps them short
    /// where they carry little).
    fn test_settings() -> PathSettings {
        PathSettings {
            max_depth: 10_000,
            ..Default::default()
        }
    }
}

impl Integrator for PathTracer {
    fn li(&self, camera_ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        let PathSettings {
            max_depth,
            rr_depth,
        } = self.settings;
        trace_path(scene, camera_ray, max_depth, rr_depth, sampler, |_| None)
    }
}
