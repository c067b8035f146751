//! Diffuse fiber (the diffuse term of Kajiya & Kay 1989), energy normalised.
//!
//! Scattering is proportional to cos θ_i — the projected width the fiber shows the incident
//! light — and uniform in azimuth: `eval = albedo · cos θ_i / π²`, since ∫_{S²} cos θ dω = π².
//! A baseline, and the model the first path-tracer furnace test uses.
//!
//! | parameter | default | meaning |
//! |---|---|---|
//! | `albedo` | (0.8, 0.8, 0.8) | fraction of energy scattered, per RGB channel, in [0, 1] |
//!
//! RON: `LambertianFiber(albedo: (0.9, 0.7, 0.5))`

use crate::pigment::Pigment;
use crate::{check_range, ModelParams, ParamError, TestInstance};
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;
use tress_core::math::{fiber_direction, safe_sqrt, Rgb, Vec3};
use tress_core::{Bcsdf, BcsdfSample};

const INV_PI2: f32 = 1.0 / (PI * PI);

/// Parameters of [`LambertianFiber`].
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
#[schemars(rename = "LambertianFiberParams")]
pub struct Params {
    /// Fraction of energy scattered per RGB channel, each in [0, 1] (default 0.8).
    pub albedo: (f32, f32, f32),
}

impl Default for Params {
    fn default() -> Self {
        Params {
            albedo: (0.8, 0.8, 0.8),
        }
    }
}

/// The albedo is the fiber's colour and it has no roughness: strands cannot vary it.
impl ModelParams for Params {
    fn pigment(&self) -> Option<(&Pigment, f32)> {
        None
    }

    fn pigment_mut(&mut self) -> Option<&mut Pigment> {
        None
    }

    fn scale_roughness(&mut self, _scale: f32) {}
}

/// The energy-normalised diffuse fiber (module docs).
#[derive(Debug, Clone)]
pub struct LambertianFiber {
    albedo: Rgb,
}

impl LambertianFiber {
    /// Checks that every albedo channel lies in [0, 1].
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        for v in [p.albedo.0, p.albedo.1, p.albedo.2] {
            check_range("albedo", v, 0.0, 1.0)?;
        }
        Ok(LambertianFiber {
            albedo: Rgb::new(p.albedo.0, p.albedo.1, p.albedo.2),
        })
    }
}

impl Bcsdf for LambertianFiber {
    fn eval(&self, _wo: Vec3, wi: Vec3, _h: f32) -> Rgb {
        self.albedo * (safe_sqrt(1.0 - wi.x * wi.x) * INV_PI2)
    }

    fn sample(&self, _wo: Vec3, _h: f32, u: [f32; 4]) -> Option<BcsdfSample> {
        // The density of sin θ is ∝ cos θ·(dω = d sinθ dφ) = √(1 − s²): the x coordinate of a
        // point uniform in the unit disk has exactly that (semicircle) distribution.
        let r = u[0].sqrt();
        let sin_theta = r * (2.0 * PI * u[1]).cos();
        let cos_theta = safe_sqrt(1.0 - sin_theta * sin_theta);
        let wi = fiber_direction(sin_theta, cos_theta, 2.0 * PI * u[2]);
        let pdf = cos_theta * INV_PI2;
        (pdf > 0.0).then(|| BcsdfSample {
            wi,
            f: self.albedo * pdf,
            pdf,
        })
    }

    fn pdf(&self, _wo: Vec3, wi: Vec3, _h: f32) -> f32 {
        safe_sqrt(1.0 - wi.x * wi.x) * INV_PI2
    }
}

/// Parameter sets the statistical tests run on this model ([`crate::HairModel::test_instances`]).
pub fn test_instances() -> Vec<TestInstance<Params>> {
    vec![
        TestInstance {
            name: "white".into(),
            params: Params {
                albedo: (1.0, 1.0, 1.0),
            },
            white_furnace: true,
        },
        TestInstance {
            name: "brown".into(),
            params: Params {
                albedo: (0.5, 0.3, 0.1),
            },
            white_furnace: false,
        },
    ]
}
