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
use tress_core::integrator::BuildError;
use tress_core::integrator::{direct_light, escaped_light, roulette, scatter};
use tress_core::prepare::Preparation;
use tress_core::{Integrator, IntegratorKind, Ray, Rgb, Sampler, Scene, ShadingPoint};

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
        let mut radiance = Rgb::ZERO;
        let mut throughput = Rgb::ONE;
        let mut ray = *camera_ray;
        // Density of the scattering sample that produced `ray`, when its MIS weight needs it;
        // None for the camera ray.
        let mut scatter_pdf: Option<f32> = None;

        for depth in 0.. {
            let Some(hit) = scene.intersect(&ray) else {
                for light in scene.lights.infinite() {
                    let select_pdf = scene.lights.select_pdf_of(light);
                    radiance += escaped_light(light, ray.dir, scatter_pdf, select_pdf, throughput);
                }
                break;
            };
            if depth >= self.settings.max_depth {
                break;
            }
            let sp = ShadingPoint::new(&hit, &ray, &scene.materials);

            // Next-event estimation.
            let u_select = sampler.next_1d();
            let u_light = sampler.next_2d();
            if let Some((light, select_pdf)) = scene.lights.choose(u_select) {
                radiance += direct_light(scene, &sp, light, u_light, select_pdf, throughput);
            }

            let density_needed = scene.lights.weighs_escapes();
            let Some((next, pdf)) = scatter(&sp, sampler, &mut throughput, density_needed) else {
                break;
            };
            scatter_pdf = pdf;
            ray = next;

            if roulette(depth, self.settings.rr_depth, &mut throughput, sampler).is_none() {
                break;
            }
        }
        radiance
    }
}
