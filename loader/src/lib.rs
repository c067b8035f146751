//! tress's scene layer, under both front ends (the `tress` command line and the Python
//! bindings): scene files with their `${name}` placeholders, objects, materials and lights, built
//! into a renderable [`tress_core::Scene`], and the integrator registry (comparative studies are
//! `tress-study`'s, above it). It holds no process-wide state and reads no environment
//! variables: everything a run depends on is passed in.

// Test code is not library code: it writes its fixtures and reads what it is asked to bless
// (clippy.toml's rules are for the library).
#![cfg_attr(test, allow(clippy::disallowed_methods))]
#![warn(missing_docs)]

pub mod error;
pub mod geometry;
pub mod integrators;
pub mod lights;
pub mod materials;
pub mod paths;
pub mod placeholders;
pub mod reference;
pub mod ron_format;
pub mod scene_desc;
pub mod threads;

pub use error::{Error, Result};
pub use ron_format::options as ron_options;
pub use threads::check_threads;
