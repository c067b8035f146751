//! tress-groom: hair input for tress — the groom readers (Cem Yuksel `.hair`, AMD TressFX
//! `.tfx`, USC-HairSalon `.data`, PLY, the `Shape "curve"`s of pbrt scenes, USD
//! `BasisCurves`), procedural hair and child strands, each giving validated strands in a
//! [`HairGeometry`]. [`HairSource`] is how a scene file names one. Turning strands into
//! intersectable curves is `tress-accel`'s job; this crate knows no Embree.
//!
//! ```no_run
//! use tress_groom::{HairSource, HairStyle, ProceduralHair};
//! use tress_core::limits::Limits;
//!
//! # fn main() -> Result<(), tress_groom::Error> {
//! let hair = HairSource::File("straight.hair".into()).load(&Limits::default())?; // Z-up → Y-up
//! let wavy = ProceduralHair { style: HairStyle::Ball, ..Default::default() }
//!     .generate(&Limits::default())?;
//! println!("{} + {} strands", hair.strand_count(), wavy.strand_count());
//! # Ok(()) }
//! ```

// Test code is not library code: it writes its fixtures and reads what it is asked to bless
// (clippy.toml's rules are for the library).
#![cfg_attr(test, allow(clippy::disallowed_methods))]
#![warn(missing_docs)]

mod children;
pub mod cyhair;
mod error;
pub mod geometry;
mod le_bytes;
pub mod pbrt;
pub mod ply;
pub mod procedural;
pub mod source;
#[cfg(any(test, feature = "test-util"))]
pub mod test_util;
pub mod tfx;
pub mod usc;
pub mod usd;

pub use children::ChildStrands;
pub use cyhair::HairFile;
pub use error::{Error, InvalidGeometry, InvalidOption, Result};
pub use geometry::{HairAttribute, HairGeometry, Rotation, Transform};
pub use pbrt::PbrtFile;
pub use ply::PlyFile;
pub use procedural::{HairStyle, ProceduralHair};
pub use source::HairSource;
pub use tfx::TfxFile;
pub use usc::UscFile;
pub use usd::UsdFile;
