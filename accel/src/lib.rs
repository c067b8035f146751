//! tress-accel: Embree geometry for tress — hair as flat or round curves, triangle meshes and
//! spheres behind [`tress_core::Accel`]. The strands come from `tress-groom`'s readers and
//! generators.
//!
//! # Building an accelerator from a HAIR file
//!
//! ```no_run
//! use tress_accel::{HairOptions, SceneBuilder};
//! use tress_core::{Accel, math::{Ray, Vec3}};
//! use tress_groom::HairFile;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let hair = HairFile::new("straight.hair").read()?; // Z-up file → Y-up world
//! let accel = SceneBuilder::new()?
//!     .add_hair(&hair, &HairOptions::default(), 0)? // material 0
//!     .add_sphere(Vec3::new(0.0, 40.0, 0.0), 10.0, 1)? // material 1
//!     .build()?;
//! println!("{}", accel.info());
//! let hit = accel.intersect(&Ray::new(Vec3::new(0.0, 40.0, 100.0), -Vec3::Z));
//! # Ok(()) }
//! ```
//!
//! `examples/preview.rs` renders a quick shaded preview of any hair source.
//!
//! For dual scattering, [`tress_core::Accel::hair_curves`] hands the fibers of a built
//! accelerator to the density grid (in `tress-dual-scattering`);
//! [`EmbreeAccel::count_fibers_crossed`] is its brute-force reference.
//!
//! # Fibers: flat or round curves, the local frame and `h`
//!
//! Hair is drawn by default with Embree's *flat* curves: ribbons of the fiber's width that
//! always face the ray. Embree meets a ribbon at the depth of the curve axis point nearest the
//! ray, offset sideways (perpendicular to the ray) by at most the radius; tress reports the hit
//! where the ray enters the segment's tube (its capsule, at the local radius), as a tube would
//! be hit, so rays leave fibers from their surface. With [`CurveShape::Round`] the fibers are
//! tubes and Embree's hit already lies on the tube's surface. The offset from the axis across
//! the ray, and so `h`, is the same for both. The radius is interpolated along each segment
//! with the same basis as the positions ([`CurveBasis`]).
//!
//! A fiber hit ([`tress_core::HitKind::Fiber`]) carries:
//! - `tangent`: the unit derivative of the curve at the hit's curve parameter, pointing root →
//!   tip (strands are stored root first);
//! - `h` ∈ [−1, 1]: with `axis` the curve point at the hit's parameter and `y` the width axis of
//!   `FiberFrame::new(tangent, -ray.dir)` — x = tangent, z = the direction back toward the ray
//!   origin made orthogonal to the tangent, **y = z × x** — `h = (p − axis)·y / radius`, clamped
//!   to [−1, 1]. So for a fiber along +x seen by a ray travelling along −z, y = +y and a hit on
//!   the +y side of the axis has h > 0. This is the frame of `tress_core::bcsdf`, in which
//!   specular reflection leaves at φ_i − φ_o = −2 asin h (pbrt's convention);
//! - `radius`: the interpolated radius at the hit; `strand`: the strand's index in its hair
//!   object (its index in the file, also when strands are subsampled); `v`: the parameter along
//!   the whole strand, `(segment + u) / segments`, 0 at the root and 1 at the tip.
//!
//! Surfaces (meshes, spheres) report `HitKind::Surface { normal }`: the unit geometric normal,
//! flipped to face the incoming ray.
//!
//! # Self-intersection
//!
//! A ray made with `Ray::leaving(p, dir, prim)` never reports `prim`: a ray cannot re-enter the
//! convex primitive it leaves (a triangle, a sphere seen from outside, a fiber segment), and a
//! flat ribbon faces *every* ray, so a ray leaving a fiber in almost any direction would
//! otherwise "hit" its own ribbon again.
//!
//! The neighbouring segments of the same strand overlap the one the ray leaves at the joints,
//! and ribbon hit points lie inside the fiber (at the axis depth), so rays leaving near a joint,
//! or grazing along the strand, would also hit the neighbours' ribbons from inside the fiber —
//! at distances up to the segment length for grazing rays, so no fixed distance cut-off works.
//! The rule used instead is geometric: each segment is enclosed in a capsule (axis chord plus
//! radius; for cubic bases padded by the curve's distance from the chord). A hit on another
//! segment `k` of the strand the ray leaves (segment `s`) is skipped exactly when the ray stays
//! inside the union of the capsules of segments `s..=k` from its origin until it enters capsule
//! `k` — then the ray never left the fiber and the "hit" is the ribbon seen from inside. Hits
//! reached through free space (a curl of the same strand, another strand, a mesh) are kept.
//! Tubes need the same rule: a ray leaving a tube's surface inward (transmission) meets the
//! tube's far wall and its neighbours' walls from inside. Capsules are padded by 0.1% of the radius plus float rounding of the origin, so borderline
//! cases count as inside. This runs in an Embree context filter carried only by queries that
//! exclude a primitive (the excluded primitive travels in the intersection context), so
//! occlusion queries get the same rule, and camera rays pay no callback at all.
//!
//! Embree has its own self-intersection avoidance for flat curves: it drops every hit nearer
//! the ray's origin than twice the hit curve's radius. In hair that drops real fibers — the
//! neighbour a fiber touches, and in dense hair any fiber within a diameter — so light passed
//! through hair it should meet: shadow rays from the fibers a camera saw in a layer of fibers
//! 1.4 deep passed 62 % of the time where the fibers' positions give 33 %, and fixing this
//! alone made the path tracer's hair on the studies' scenes 3–16 % darker, whatever its colour
//! (docs/src/research/dual-scattering-accuracy.md#the-path-tracer-was-wrong-fixed has the net
//! change with the tube walls above). Every query therefore reaches Embree from slightly behind its origin (2.05 of the
//! scene's largest fiber radius) with its interval moved by as much: the culling never
//! applies, and the rule above alone decides.

// Test code is not library code: it writes its fixtures and reads what it is asked to bless
// (clippy.toml's rules are for the library).
#![cfg_attr(test, allow(clippy::disallowed_methods))]
#![warn(missing_docs)]
// Every unsafe operation in its own block, with the reason it is sound.
#![warn(unsafe_op_in_unsafe_fn, clippy::undocumented_unsafe_blocks)]

mod curve_data;
mod curves;
mod embree;
mod error;
mod fp_mode;
pub mod mesh;
mod options;
mod orientation;

pub use curve_data::HairSegment;
pub use curves::{CurveBasis, CurveShape, Overlaps};
pub use embree::raw;
pub use embree::{AccelInfo, EmbreeAccel, ObjectInfo, ObjectKind, SceneBuilder};
pub use error::{Error, Result};
pub use mesh::TriangleMesh;
pub use options::HairOptions;
pub use orientation::FiberOrientation;
