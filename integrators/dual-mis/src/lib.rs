//! Dual scattering with multiple importance sampling: one direction from the lights at
//! infinity (environment-map importance sampling) and one from the dual-scattering shading
//! function F (`DualScatteringShading::sample_direction`: lobe selection by attenuation,
//! longitudinal and azimuthal sampling, exact pdf), combined with the power heuristic. The
//! estimator itself is `tress_dual_scattering::DualScattering`; only the directions differ.
//!
//! RON: `DualMis(d_f: Some(0.9), d_b: None)` (settings as for `DualUniform`)

#![warn(missing_docs)]

use tress_core::sampling::power_heuristic;
use tress_core::{Rgb, Sampler, Scene};
use tress_dual_scattering::{DirectionSampling, DualScattering, HairPoint};

pub use tress_dual_scattering::{DualError, DualSettings};

/// Light sampling and F sampling, one sample each, power heuristic.
#[derive(Clone, Copy, Debug, Default)]
pub struct MisDirections;

/// The `dual-mis` integrator.
pub type DualMis = DualScattering<MisDirections>;

tress_dual_scattering::dual_scattering_integrator!(MisDirections, "dual-mis");

impl DirectionSampling for MisDirections {
    fn estimate(&self, point: &HairPoint, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        let lights = &scene.lights;
        if lights.non_delta().len() == 0 {
            return Rgb::ZERO;
        }
        let select_pdf = lights.non_delta_select_pdf();
        // Light strategy density of a direction: the mixture over the light choice, matching
        // `radiance_from`, which sums every light at infinity.
        let light_pdf = |wi| {
            lights
                .non_delta()
                .map(|l| select_pdf * l.pdf_li(wi))
                .sum::<f32>()
        };
        let mut radiance = Rgb::ZERO;

        let (u_select, u_light, u_f) = (sampler.next_1d(), sampler.next_2d(), sampler.next_4d());
        // One mixture for the light sample's pdf and the F sample.
        let f_sampler = point.shading.direction_sampler(point.wo_local);
        let Some((light, _)) = lights.choose_non_delta(u_select) else {
            return Rgb::ZERO;
        };
        if let Some(ls) = light.sample_li(point.sp.p, u_light) {
            let p_light = light_pdf(ls.wi);
            if p_light > 0.0 {
                let p_f = f_sampler.pdf(point.to_local(ls.wi), point.h);
                radiance +=
                    point.radiance_from(scene, ls.wi) * (power_heuristic(p_light, p_f) / p_light);
            }
        }
        if let Some((wi_local, p_f)) = f_sampler.sample(point.h, u_f) {
            let wi = point.to_world(wi_local);
            let w = power_heuristic(p_f, light_pdf(wi));
            radiance += point.radiance_from(scene, wi) * (w / p_f);
        }
        radiance
    }
}
