//! tress-core: the small trait surfaces ([`Bcsdf`], [`Accel`], [`Integrator`]) and everything the
//! integrators share — math, sampling, RNG, camera, film, lights, scene and the one render loop.
//!
//! This crate depends on neither Embree nor RON: geometry comes in through [`Accel`], scene files
//! are loaded by `tress-loader`, which also holds the integrator registry.

// Test code is not library code: it writes its fixtures and reads what it is asked to bless
// (clippy.toml's rules are for the library).
#![cfg_attr(test, allow(clippy::disallowed_methods))]
#![warn(missing_docs)]
// Every unsafe operation in its own block, with the reason it is sound.
#![warn(unsafe_op_in_unsafe_fn, clippy::undocumented_unsafe_blocks)]

pub mod accel;
pub mod bcsdf;
pub mod camera;
pub mod envmap;
pub mod files;
pub mod film;
pub mod image_io;
pub mod integrator;
pub mod light;
pub mod light_sample;
pub mod limits;
pub mod math;
pub mod output_file;
pub mod prepare;
pub mod render;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod shading;
pub mod stats;
pub mod stored_table;
#[cfg(test)]
mod test_util;

pub use accel::{Accel, FiberDensity, HairCurves, Hit, HitKind, PrimId};
pub use bcsdf::{Bcsdf, BcsdfSample, FiberFrame};
pub use camera::Camera;
pub use film::Image;
pub use integrator::{FilmIntegrator, Integrator, IntegratorKind};
pub use light::Light;
pub use math::{luminance, Aabb, Frame, Ray, Rgb};
pub use rng::Sampler;
pub use scene::{Material, Scene};
pub use shading::ShadingPoint;
