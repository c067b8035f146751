//! The renderable scene: camera, geometry, materials, lights.

use crate::accel::{Accel, FiberDensity, Hit};
use crate::bcsdf::Bcsdf;
use crate::camera::Camera;
use crate::light::Light;
use crate::math::{Aabb, Ray, Rgb};
use std::cell::Cell;
use std::sync::Arc;

/// How a hit scatters light.
#[derive(Clone, Debug)]
pub enum Material {
    /// A hair fiber scattering function.
    Hair(Arc<dyn Bcsdf>),
    /// A Lambertian surface (heads, occluders, floors).
    Diffuse {
        /// Reflectance per channel, in [0, 1].
        albedo: Rgb,
    },
}

/// Everything an integrator needs to shade.
pub struct Scene {
    /// The camera primary rays start from.
    pub camera: Camera,
    /// Ray queries against all geometry; prefer the counting wrappers on `Scene`.
    pub accel: Box<dyn Accel>,
    /// Materials, indexed by [`Hit::material`].
    pub materials: Vec<Material>,
    /// All lights; next-event estimation picks one uniformly.
    pub lights: Vec<Light>,
    /// Hair density for the dual-scattering integrators; `None` when no integrator needs it.
    pub density: Option<Box<dyn FiberDensity>>,
}

thread_local! {
    static RAYS_TRACED: Cell<u64> = const { Cell::new(0) };
}

/// Rays traced by the calling thread so far (the render loop takes differences around each tile).
pub fn rays_traced_on_this_thread() -> u64 {
    RAYS_TRACED.with(|c| c.get())
}

impl Scene {
    /// Closest hit, counted in the ray statistics.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        RAYS_TRACED.with(|c| c.set(c.get() + 1));
        self.accel.intersect(ray)
    }

    /// Visibility test, counted in the ray statistics.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        RAYS_TRACED.with(|c| c.set(c.get() + 1));
        self.accel.occluded(ray)
    }

    /// Visibility against non-hair surfaces only, counted in the ray statistics.
    #[inline]
    pub fn occluded_by_surfaces(&self, ray: &Ray) -> bool {
        if !self.accel.has_surfaces() {
            return false;
        }
        RAYS_TRACED.with(|c| c.set(c.get() + 1));
        self.accel.occluded_by_surfaces(ray)
    }

    /// Bounds of all geometry.
    pub fn bounds(&self) -> Aabb {
        self.accel.bounds()
    }

    /// Lights seen by rays that escape the scene (environment, constant, distant with a disc).
    pub fn escaped_radiance(&self, dir: crate::math::Vec3) -> Rgb {
        self.lights.iter().map(|l| l.le(dir)).sum()
    }
}
