//! Dual scattering (Zinke, Yuksel, Weber & Keyser 2008) with light directions sampled
//! uniformly on the sphere, the paper's baseline. The estimator is `tress-dual-scattering`'s;
//! this crate only chooses the directions.
//!
//! RON: `DualUniform(d_f: None, d_b: None, grid_resolution: None)` (see [`DualSettings`]).

#![warn(missing_docs)]

use tress_core::sampling::{sample_uniform_sphere, INV_4PI};
use tress_core::{Rgb, Sampler, Scene};
use tress_dual_scattering::{DirectionSampling, DualScattering, HairPoint};

pub use tress_dual_scattering::{DualError, DualSettings};

/// Uniform directions on the sphere (pdf 1/4π): Zinke et al.'s baseline.
#[derive(Clone, Copy, Debug, Default)]
pub struct UniformDirections;

impl DirectionSampling for UniformDirections {
    fn estimate(&self, point: &HairPoint, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        let wi = sample_uniform_sphere(sampler.next_2d());
        point.radiance_from(scene, wi) / INV_4PI
    }
}

/// The `dual-uniform` integrator.
pub type DualUniform = DualScattering<UniformDirections>;

tress_dual_scattering::dual_scattering_integrator!(UniformDirections, "dual-uniform");
