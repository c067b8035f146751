//! The renderable scene: camera, geometry, materials, lights.

use crate::accel::{Accel, BuildError, FiberDensity, HairCurves, Hit};
use crate::bcsdf::Bcsdf;
use crate::camera::Camera;
use crate::light::Light;
use crate::limits::Limits;
use crate::math::{Aabb, Ray, Rgb};
use crate::prepare::Preparation;
use std::cell::Cell;
use std::hash::{Hash, Hasher};
use std::sync::{Arc, Weak};
use std::time::Instant;
use thread_local::ThreadLocal;

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

/// Everything an integrator needs to shade. A scene knows nothing of integrators: what one
/// derives from it (a density grid) it asks for while it is built ([`Scene::fiber_density`]).
pub struct Scene {
    /// The camera primary rays start from.
    pub camera: Camera,
    /// Ray queries against all geometry (private: data derived from it is cached under its
    /// identity, so it must not change; queries go through the counting wrappers).
    accel: Arc<dyn Accel>,
    /// Materials, indexed by [`Hit::material`].
    pub materials: Vec<Material>,
    /// All lights, with the subsets the integrators sample from (found once).
    pub lights: Lights,
    /// Rays traced through this scene, per thread (the render loop takes differences around
    /// each tile).
    rays: ThreadLocal<Cell<u64>>,
}

/// The key of a density grid in a [`Preparation`]: whose geometry, at what resolution.
struct DensityKey {
    /// The geometry, by address. A weak reference keeps the allocation (not the geometry)
    /// alive, so no other scene's geometry can take the address while the entry exists.
    geometry: Weak<dyn Accel>,
    resolution: Option<u32>,
}

impl DensityKey {
    fn address(&self) -> *const () {
        self.geometry.as_ptr() as *const ()
    }
}

impl PartialEq for DensityKey {
    fn eq(&self, other: &Self) -> bool {
        self.address() == other.address() && self.resolution == other.resolution
    }
}

impl Eq for DensityKey {}

impl Hash for DensityKey {
    fn hash<H: Hasher>(&self, state: &mut H) {
        self.address().hash(state);
        self.resolution.hash(state);
    }
}

/// The scene's lights and the subsets integrators choose from, found once when the scene is
/// made (`Vec<Light>::into()`), not per sample: those next-event estimation samples (path
/// tracing picks one uniformly: every light but uniform skies, see
/// [`Light::is_sampled_directly`]), those with area (non-delta: dual scattering's light
/// strategy mixes them) and the delta lights (evaluated one by one).
#[derive(Clone, Debug, Default)]
pub struct Lights {
    all: Vec<Light>,
    sampled: Vec<usize>,
    non_delta: Vec<usize>,
    delta: Vec<usize>,
    weighs_escapes: bool,
    sampling_reads_tables: bool,
}

impl From<Vec<Light>> for Lights {
    fn from(all: Vec<Light>) -> Self {
        let (delta, non_delta) = (0..all.len()).partition(|&i| all[i].is_delta());
        let sampled = (0..all.len())
            .filter(|&i| all[i].is_sampled_directly())
            .collect();
        let weighs_escapes = all
            .iter()
            .any(|l| l.is_infinite() && !l.is_delta() && l.is_sampled_directly());
        let sampling_reads_tables = all
            .iter()
            .any(|l| l.sampling_reads_table() && l.is_sampled_directly());
        Lights {
            all,
            sampled,
            non_delta,
            delta,
            weighs_escapes,
            sampling_reads_tables,
        }
    }
}

impl Lights {
    /// Every light, in scene order.
    pub fn all(&self) -> &[Light] {
        &self.all
    }

    /// Whether the scene has no light.
    pub fn is_empty(&self) -> bool {
        self.all.is_empty()
    }

    /// One of the lights next-event estimation samples, chosen uniformly by `u` ∈ [0, 1),
    /// with the probability of that choice.
    pub fn choose(&self, u: f32) -> Option<(&Light, f32)> {
        let i = choose(self.sampled.len(), u)?;
        Some((&self.all[self.sampled[i]], self.select_pdf()))
    }

    /// Probability with which [`Self::choose`] picks any one light it can pick (0 when none).
    pub fn select_pdf(&self) -> f32 {
        if self.sampled.is_empty() {
            0.0
        } else {
            1.0 / self.sampled.len() as f32
        }
    }

    /// Probability with which [`Self::choose`] picks `light`: 0 for a light it never samples,
    /// whose radiance found by a scattered ray then takes the whole MIS weight.
    pub fn select_pdf_of(&self, light: &Light) -> f32 {
        if light.is_sampled_directly() {
            self.select_pdf()
        } else {
            0.0
        }
    }

    /// Whether next-event estimation samples a light that escaping rays can find (an
    /// environment map or a sun disc), so that a scattered ray's MIS weight needs the density
    /// of its direction. Without one, every light at infinity it finds takes the whole weight.
    pub fn weighs_escapes(&self) -> bool {
        self.weighs_escapes
    }

    /// Whether sampling a light may read a table too large for the cache (an environment
    /// map's), so that fetching its entry ahead ([`Light::prefetch_sample`]) pays.
    pub fn sampling_reads_tables(&self) -> bool {
        self.sampling_reads_tables
    }

    /// The lights at infinity (environment maps, constant skies, suns, disc or delta).
    pub fn infinite(&self) -> impl Iterator<Item = &Light> {
        self.all.iter().filter(|l| l.is_infinite())
    }

    /// The lights with area (not delta), in scene order.
    pub fn non_delta(&self) -> impl ExactSizeIterator<Item = &Light> {
        self.non_delta.iter().map(|&i| &self.all[i])
    }

    /// One non-delta light chosen uniformly by `u` ∈ [0, 1), with the probability of that
    /// choice.
    pub fn choose_non_delta(&self, u: f32) -> Option<(&Light, f32)> {
        let i = choose(self.non_delta.len(), u)?;
        Some((&self.all[self.non_delta[i]], self.non_delta_select_pdf()))
    }

    /// Probability with which [`Self::choose_non_delta`] picks any one light (0 when none).
    pub fn non_delta_select_pdf(&self) -> f32 {
        if self.non_delta.is_empty() {
            0.0
        } else {
            1.0 / self.non_delta.len() as f32
        }
    }

    /// The delta lights (points, suns without a disc), in scene order.
    pub fn delta(&self) -> impl Iterator<Item = &Light> {
        self.delta.iter().map(|&i| &self.all[i])
    }
}

/// Index `⌊u·n⌋` of `n` items (clamped to the last), if there is any.
fn choose(n: usize, u: f32) -> Option<usize> {
    (n > 0).then(|| ((u * n as f32) as usize).min(n - 1))
}

impl Scene {
    /// A scene of `accel`'s geometry.
    pub fn new(
        camera: Camera,
        accel: Box<dyn Accel>,
        materials: Vec<Material>,
        lights: Lights,
    ) -> Self {
        Scene {
            camera,
            accel: Arc::from(accel),
            materials,
            lights,
            rays: ThreadLocal::new(),
        }
    }

    /// Rays the calling thread has traced through this scene so far (the render loop takes
    /// differences around each tile).
    pub fn rays_traced_on_this_thread(&self) -> u64 {
        self.rays.get().map_or(0, Cell::get)
    }

    #[inline]
    fn count_ray(&self) {
        self.count_rays(1);
    }

    #[inline]
    fn count_rays(&self, n: usize) {
        let rays = self.rays.get_or_default();
        rays.set(rays.get() + n as u64);
    }

    /// The geometry, for queries that bypass the ray statistics (tests, benchmarks).
    pub fn accel(&self) -> &dyn Accel {
        self.accel.as_ref()
    }

    /// The scene's fiber density at `resolution` (voxels along the longest side; `None`: chosen
    /// from the fibers), made by `build` from the accelerator's hair curves within `prep`'s
    /// limits on the run's first request and shared after; `Ok(None)` when the scene has no
    /// hair. The build is noted in `prep`.
    pub fn fiber_density(
        &self,
        prep: &Preparation,
        resolution: Option<u32>,
        build: impl FnOnce(
            Vec<(u32, Arc<dyn HairCurves>)>,
            &Limits,
        ) -> Result<Arc<dyn FiberDensity>, BuildError>,
    ) -> Result<Option<Arc<dyn FiberDensity>>, BuildError> {
        let key = DensityKey {
            geometry: Arc::downgrade(&self.accel),
            resolution,
        };
        let grid = prep.get_or_build(key, || {
            let curves = self.accel.hair_curves();
            if curves.is_empty() {
                return Ok(None);
            }
            let start = Instant::now();
            let grid = build(curves, prep.limits())?;
            prep.note(format!(
                "{} built in {:.2} s",
                grid.describe(),
                start.elapsed().as_secs_f64()
            ));
            Ok::<_, BuildError>(Some(grid))
        })?;
        Ok(grid.as_ref().clone())
    }

    /// Closest hit, counted in the ray statistics.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.count_ray();
        self.accel.intersect(ray)
    }

    /// Visibility test, counted in the ray statistics.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.count_ray();
        self.accel.occluded(ray)
    }

    /// [`Scene::intersect`] of each of `rays` into `hits` (as long), counted in the ray
    /// statistics.
    pub fn intersect_many(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.count_rays(rays.len());
        self.accel.intersect_many(rays, hits);
    }

    /// [`Scene::occluded`] of each of `rays` into `blocked` (as long), counted in the ray
    /// statistics.
    pub fn occluded_many(&self, rays: &[Ray], blocked: &mut [bool]) {
        self.count_rays(rays.len());
        self.accel.occluded_many(rays, blocked);
    }

    /// Visibility against non-hair surfaces only, counted in the ray statistics.
    #[inline]
    pub fn occluded_by_surfaces(&self, ray: &Ray) -> bool {
        if !self.accel.has_surfaces() {
            return false;
        }
        self.count_ray();
        self.accel.occluded_by_surfaces(ray)
    }

    /// Bounds of all geometry.
    pub fn bounds(&self) -> Aabb {
        self.accel.bounds()
    }

    /// Lights seen by rays that escape the scene (environment, constant, distant with a disc).
    pub fn escaped_radiance(&self, dir: crate::math::Vec3) -> Rgb {
        self.lights.all().iter().map(|l| l.le(dir)).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;

    #[test]
    fn lights_are_split_once_and_chosen_uniformly() {
        let point = Light::Point {
            position: Vec3::ZERO,
            intensity: Rgb::ONE,
        };
        let sky = Light::Constant { radiance: Rgb::ONE };
        let sun = |half_angle_rad| Light::Distant {
            direction: -Vec3::Y,
            radiance: Rgb::ONE,
            half_angle_rad,
        };
        let lights: Lights = vec![point, sky, sun(0.0), sun(0.01)].into();
        assert_eq!(lights.all().len(), 4);
        assert_eq!(lights.select_pdf(), 1.0 / 3.0);
        // Uniform over all but the uniform sky: u picks ⌊3u⌋; u = 1 stays on the last.
        for (u, want) in [(0.0, 0), (0.34, 2), (0.66, 2), (0.67, 3), (1.0, 3)] {
            let (l, pdf) = lights.choose(u).unwrap();
            assert!(std::ptr::eq(l, &lights.all()[want]), "u = {u}");
            assert_eq!(pdf, 1.0 / 3.0);
        }
        assert_eq!(lights.select_pdf_of(&lights.all()[1]), 0.0);
        assert_eq!(lights.select_pdf_of(&lights.all()[3]), 1.0 / 3.0);
        // The sky and the disc sun have area; the point and the zero-width sun are delta.
        let non_delta: Vec<_> = lights.non_delta().collect();
        assert_eq!(non_delta.len(), 2);
        assert!(std::ptr::eq(non_delta[0], &lights.all()[1]));
        assert!(std::ptr::eq(non_delta[1], &lights.all()[3]));
        assert_eq!(lights.delta().count(), 2);
        assert_eq!(lights.non_delta_select_pdf(), 0.5);
        let (l, pdf) = lights.choose_non_delta(0.6).unwrap();
        assert!(std::ptr::eq(l, &lights.all()[3]) && pdf == 0.5);
        // Both suns and the sky are at infinity; the point is not.
        assert_eq!(lights.infinite().count(), 3);
        let none = Lights::from(Vec::new());
        assert!(none.is_empty() && none.choose(0.5).is_none());
        assert!(none.choose_non_delta(0.5).is_none() && none.non_delta_select_pdf() == 0.0);
    }
}
