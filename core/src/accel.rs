//! The ray-intersection interface implemented by `tress-accel` (Embree).

pub use crate::math::PrimId;
use crate::math::{Aabb, Ray, Vec3};
use glam::Vec4;
use std::sync::Arc;

/// What was hit.
#[derive(Clone, Copy, Debug)]
pub enum HitKind {
    /// A hair fiber.
    Fiber {
        /// Unit curve tangent at the hit, root → tip.
        tangent: Vec3,
        /// Signed offset across the fiber in [−1, 1], measured along the y axis of
        /// `FiberFrame::new(tangent, -ray.dir)` (see `tress_core::bcsdf`).
        h: f32,
        /// Fiber radius at the hit.
        radius: f32,
        /// Index of the strand within its hair object.
        strand: u32,
        /// Parameter along the strand, 0 at the root and 1 at the tip.
        v: f32,
        /// The fiber's orientation about its axis at the hit (world space, orthogonal to the
        /// tangent up to interpolation): the major axis of an elliptical fiber. Only models
        /// that [use it](crate::Bcsdf::uses_orientation) see it, and only scenes with such a
        /// model keep it: elsewhere it is zero.
        orientation: Vec3,
    },
    /// A surface (triangle mesh, sphere).
    Surface {
        /// Unit geometric normal, facing the side the ray came from.
        normal: Vec3,
    },
}

/// A ray hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the ray to the hit (ray directions are unit).
    pub t: f32,
    /// Hit point, in world space.
    pub p: Vec3,
    /// The primitive hit; rays continuing from the hit exclude it ([`Ray::leaving`]).
    pub prim: PrimId,
    /// Index into `Scene::materials`.
    pub material: u32,
    /// Fiber or surface, with the local geometry at the hit.
    pub kind: HitKind,
}

/// Ray queries against the scene geometry.
pub trait Accel: Send + Sync {
    /// Closest hit in `(0, ray.t_max)`, skipping `ray.exclude`.
    fn intersect(&self, ray: &Ray) -> Option<Hit>;
    /// Whether anything blocks `(0, ray.t_max)`, skipping `ray.exclude`.
    fn occluded(&self, ray: &Ray) -> bool;
    /// [`Accel::intersect`] of each of `rays`, into `hits` (as long). The hits must be
    /// exactly those of `intersect`; an accelerator overrides it where it traces many rays
    /// at once faster than one at a time.
    fn intersect_many(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        for (ray, hit) in rays.iter().zip(hits) {
            *hit = self.intersect(ray);
        }
    }
    /// [`Accel::occluded`] of each of `rays`, into `blocked` (as long); as
    /// [`Accel::intersect_many`], the answers must be those of `occluded`.
    fn occluded_many(&self, rays: &[Ray], blocked: &mut [bool]) {
        for (ray, b) in rays.iter().zip(blocked) {
            *b = self.occluded(ray);
        }
    }
    /// Whether a surface that is not hair (a mesh, a sphere) blocks `(0, ray.t_max)`; fibers are
    /// transparent to this query (dual scattering accounts for them statistically).
    fn occluded_by_surfaces(&self, ray: &Ray) -> bool;
    /// Whether there is any surface for [`Accel::occluded_by_surfaces`] to find; without one
    /// the query traces nothing (and is not counted as a ray).
    fn has_surfaces(&self) -> bool {
        true
    }
    /// Bounds of all geometry.
    fn bounds(&self) -> Aabb;
    /// The hair objects of this geometry with their geometry ids ([`PrimId::geom`]), as
    /// intersected: for data derived from the fibers themselves (the dual-scattering density
    /// grid, built through [`crate::Scene::fiber_density`]). None by default.
    fn hair_curves(&self) -> Vec<(u32, Arc<dyn HairCurves>)> {
        Vec::new()
    }
}

/// The fibers of one hair object as an accelerator intersects them — after transform,
/// subsampling and radius scale and taper — segment by segment ([`PrimId::prim`]).
pub trait HairCurves: Send + Sync {
    /// Curve segments (primitives).
    fn segments(&self) -> usize;
    /// Calls `f(a, b)` for the straight pieces (xyz = position, w = radius) approximating
    /// segment `prim`, root to tip: the segment itself when linear, a few chords of a cubic.
    fn for_each_piece(&self, prim: usize, f: &mut dyn FnMut(Vec4, Vec4));
    /// Whether segments `a` and `b` belong to the same strand.
    fn same_strand(&self, a: usize, b: usize) -> bool;
}

/// Why derived geometry (a density grid) could not be built.
pub type BuildError = Box<dyn std::error::Error + Send + Sync>;

/// Hair density along rays, for dual scattering: the expected number of fibers a ray crosses.
/// Implemented by the voxel density grid in `tress-dual-scattering`; kept apart from [`Accel`] because it
/// answers a statistical question, not an intersection one.
pub trait FiberDensity: Send + Sync {
    /// Expected number of fibers crossed along `ray` over `(0, ray.t_max)`.
    fn fibers_crossed(&self, ray: &Ray) -> f32 {
        self.fibers_crossed_up_to(ray, f32::INFINITY)
    }
    /// [`Self::fibers_crossed`], except that counting may stop once the count reaches `limit`
    /// (the result is then at least `limit`): a caller for whom every count past `limit` means
    /// the same need not pay for the rest of the ray.
    fn fibers_crossed_up_to(&self, ray: &Ray, limit: f32) -> f32;
    /// One line for logs: resolution, memory, what it stores.
    fn describe(&self) -> String;
}
