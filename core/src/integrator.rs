//! The integrator interface: radiance along one camera ray.

use crate::accel::Hit;
use crate::film::FilmSettings;
use crate::light::Light;
use crate::math::{Ray, Rgb, Vec2, Vec3};
use crate::prepare::Preparation;
use crate::rng::Sampler;
use crate::sampling::power_heuristic;
use crate::scene::Scene;
use crate::shading::ShadingPoint;
use std::ops::Range;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Estimates the radiance arriving along a camera ray. The render loop in [`crate::render`] owns
/// tiles, seeding, film and progress, so an integrator only writes `li`.
pub trait Integrator: Send + Sync + std::fmt::Debug {
    /// One sample of the radiance arriving at the camera along `ray` (travelling away from it).
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb;

    /// [`Integrator::li`] for sample number `sample_index` of its pixel, which the render loop
    /// calls: integrators whose estimator changes as the samples accumulate (a cache refined
    /// for later samples) override it. It must depend on the index alone, never on which
    /// samples a pass renders.
    fn li_sample(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler, sample_index: u64) -> Rgb {
        let _ = sample_index;
        self.li(ray, scene, sampler)
    }

    /// [`Integrator::li_sample`] of every sample of `wave` (camera rays of several pixels and
    /// sample indices, each with its own sampler), into each sample's `radiance`: the render
    /// loop's entry point. Integrators that advance many paths together (tracing their rays in
    /// batches) override it; each sample's radiance must still be what `li_sample` returns
    /// for it, whatever the other samples of the wave, so that images do not depend on how
    /// the film is cut into tiles, passes and waves.
    fn li_wave(&self, scene: &Scene, wave: &mut [WaveSample]) {
        for w in wave {
            w.radiance = self.li_sample(&w.ray, scene, &mut w.sampler, w.sample_index);
        }
    }

    /// Precomputation that depends on the film as well as the scene (a radiance cache trained
    /// on paths through the film's own pixels), reporting the fraction done to `progress`. The
    /// render loop calls it before its first sample, so its cost is render time, and renders
    /// with what it returns; `None` renders with `self`, and so does a precomputation stopped
    /// by `cancel` (the render loop then stops before its first sample). What it builds may
    /// depend on the film's size, seed and crop window (a crop learns from its own pixels, at a
    /// cost in proportion to them) and on the sample indices `samples` to be rendered, never on
    /// threads or on how the render loop cuts the window into tiles and waves: the passes of
    /// one image must render each sample alike.
    fn for_film(
        &self,
        scene: &Scene,
        film: &FilmSettings,
        samples: Range<u64>,
        cancel: &AtomicBool,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Option<FilmIntegrator> {
        let _ = (scene, film, samples, cancel, progress);
        None
    }

    /// The consecutive ranges `samples` splits into for [`Integrator::for_film`]: the render
    /// loop prepares for and renders one after another, so that what was prepared for one is
    /// let go before the next is prepared (a radiance cache's sample blocks, each with caches
    /// of its own). The whole range by default.
    fn sample_segments(&self, samples: Range<u64>) -> Vec<Range<u64>> {
        vec![samples]
    }
}

/// One camera sample of a wave ([`Integrator::li_wave`]).
#[derive(Clone, Debug)]
pub struct WaveSample {
    /// The camera ray.
    pub ray: Ray,
    /// The sample's own random numbers (they depend only on pixel, sample index and seed).
    pub sampler: Sampler,
    /// The sample's index in its pixel.
    pub sample_index: u64,
    /// The radiance along `ray`, which `li_wave` writes.
    pub radiance: Rgb,
}

/// An integrator prepared for one film by [`Integrator::for_film`].
#[derive(Clone, Debug)]
pub struct FilmIntegrator {
    /// What renders the film.
    pub integrator: Arc<dyn Integrator>,
    /// What was built and what it cost, one line for logs.
    pub note: String,
}

/// An integrator as the registry lists it (the `integrators!` table of `tress-loader`): how
/// its settings are written, what it needs of the scene, how it is built and how the
/// cross-crate tests hold it. Each integrator crate implements this once, on a type of its own,
/// so that adding an integrator is its crate plus one registry line.
pub trait IntegratorKind {
    /// The settings as scene files write them, e.g. `Path(max_depth: 64)`.
    type Settings: Clone
        + Default
        + PartialEq
        + std::fmt::Debug
        + serde::Serialize
        + serde::de::DeserializeOwned;
    /// The command-line name (`path`, `dual-mis`): lower case, words joined by `-`.
    const NAME: &'static str;
    /// Whether the images converge to the exact solution of the scene (white-furnace tests hold
    /// it to 1 %) rather than to an approximation (held to not creating energy).
    const UNBIASED: bool;
    /// Builds the integrator for `scene`; its precomputations (tables, the scene's density
    /// grid: [`Scene::fiber_density`]) happen here, fetched from or added to the run's `prep` so
    /// that integrators of one run share them.
    fn build(
        settings: &Self::Settings,
        scene: &Scene,
        prep: &Preparation,
    ) -> Result<Box<dyn Integrator>, BuildError>;
    /// Settings that exercise everything but run quickly, for the cross-crate tests.
    fn test_settings() -> Self::Settings {
        Self::Settings::default()
    }
}

/// Why an integrator could not be built for a scene (the integrator's own error).
pub use crate::accel::BuildError;

/// Continues a path at `sp` by sampling its scattering function: the next ray, with
/// `throughput` multiplied by the sample's weight, and — when `density_needed`, because the
/// next vertex weighs the lights at infinity it may find by MIS — the sample's density. `None`
/// ends the path (no sample, or one that carries nothing). Without the density the weight is
/// [`Bcsdf::sample_weight`]'s, which may skip evaluating the whole model.
///
/// [`Bcsdf::sample_weight`]: crate::Bcsdf::sample_weight
pub fn scatter(
    sp: &ShadingPoint,
    sampler: &mut Sampler,
    throughput: &mut Rgb,
    density_needed: bool,
) -> Option<(Ray, Option<f32>)> {
    let u = sampler.next_4d();
    let (wi, weight, pdf) = if density_needed {
        let s = sp.sample(u)?;
        if s.pdf <= 0.0 {
            return None;
        }
        (s.wi, s.f / s.pdf, Some(s.pdf))
    } else {
        let (wi, weight) = sp.sample_weight(u)?;
        (wi, weight, None)
    };
    if weight == Rgb::ZERO {
        return None;
    }
    *throughput *= weight;
    Some((sp.spawn(wi), pdf))
}

/// A path arriving at one of its vertices.
#[derive(Clone, Copy, Debug)]
pub struct PathVertex {
    /// The ray that found the vertex.
    pub ray: Ray,
    /// The vertex.
    pub hit: Hit,
    /// The path's weight on arriving.
    pub throughput: Rgb,
    /// The vertex's number along the path: the camera ray's hit is 0.
    pub depth: u32,
}

/// The path tracer's estimate of the radiance along `camera_ray`: at every vertex next-event
/// estimation toward one light, MIS-weighted against the scattering-sampled continuation, which
/// also finds the lights at infinity; Russian roulette after `rr_depth` bounces; no vertex
/// shaded past `max_depth`. `end_at` is asked on arriving at each vertex and may end the path
/// there with the radiance it returns, throughput included (a cache's final gather); `|_| None`
/// traces every path to its end.
pub fn trace_path(
    scene: &Scene,
    camera_ray: &Ray,
    max_depth: u32,
    rr_depth: u32,
    sampler: &mut Sampler,
    end_at: impl FnMut(&PathVertex) -> Option<Rgb>,
) -> Rgb {
    prefetch_next_light(scene, sampler);
    let Some(hit) = scene.intersect(camera_ray) else {
        let mut radiance = Rgb::ZERO;
        for light in scene.lights.infinite() {
            let select_pdf = scene.lights.select_pdf_of(light);
            radiance += escaped_light(light, camera_ray.dir, None, select_pdf, Rgb::ONE);
        }
        return radiance;
    };
    let first = PathVertex {
        ray: *camera_ray,
        hit,
        throughput: Rgb::ONE,
        depth: 0,
    };
    continue_path(scene, first, max_depth, rr_depth, sampler, end_at)
}

/// [`trace_path`] from a vertex the path has reached: the radiance the rest of the path brings
/// back to the camera through it (its throughput included).
pub fn continue_path(
    scene: &Scene,
    mut vertex: PathVertex,
    max_depth: u32,
    rr_depth: u32,
    sampler: &mut Sampler,
    mut end_at: impl FnMut(&PathVertex) -> Option<Rgb>,
) -> Rgb {
    let mut radiance = Rgb::ZERO;
    let density_needed = scene.lights.weighs_escapes();
    loop {
        if let Some(end) = end_at(&vertex) {
            radiance += end;
            break;
        }
        if vertex.depth >= max_depth {
            break;
        }
        let sp = ShadingPoint::new(&vertex.hit, &vertex.ray, &scene.materials);
        let u_select = sampler.next_1d();
        let u_light = sampler.next_2d();
        if let Some((light, select_pdf)) = scene.lights.choose(u_select) {
            radiance += direct_light(scene, &sp, light, u_light, select_pdf, vertex.throughput);
        }
        // The density of the continuation, for the MIS weight of the lights at infinity it may
        // find, when that weight needs it.
        let Some((next, scatter_pdf)) =
            scatter(&sp, sampler, &mut vertex.throughput, density_needed)
        else {
            break;
        };
        if roulette(vertex.depth, rr_depth, &mut vertex.throughput, sampler).is_none() {
            break;
        }
        prefetch_next_light(scene, sampler);
        let Some(hit) = scene.intersect(&next) else {
            for light in scene.lights.infinite() {
                let select_pdf = scene.lights.select_pdf_of(light);
                radiance +=
                    escaped_light(light, next.dir, scatter_pdf, select_pdf, vertex.throughput);
            }
            break;
        };
        vertex = PathVertex {
            ray: next,
            hit,
            throughput: vertex.throughput,
            depth: vertex.depth + 1,
        };
    }
    radiance
}

/// Peeks at the draws the next vertex of a path takes first from `sampler` (its choice of
/// light and the light's sample) and asks for the table entry they pick to be brought into
/// the cache: issued before the ray to that vertex is traced, the fetch (a likely miss into an
/// environment map's records) overlaps the trace. `sampler` is not advanced, so no result
/// changes.
#[inline]
fn prefetch_next_light(scene: &Scene, sampler: &Sampler) {
    if !scene.lights.sampling_reads_tables() {
        return;
    }
    let mut ahead = sampler.clone();
    let u_select = ahead.next_1d();
    let u_light = ahead.next_2d();
    if let Some((light, _)) = scene.lights.choose(u_select) {
        light.prefetch_sample(u_light);
    }
}

/// Russian roulette after a path's scattering event number `depth` (from 0), from `rr_depth`
/// on: a path whose `throughput` has fallen below 1 survives with that probability (at most
/// 0.95) and is reweighted. Returns the probability the throughput was divided by (1 without
/// roulette), or `None` when the path ends. Only paths that have lost energy are rouletted:
/// white hair keeps a throughput of ~1 over hundreds of bounces, and rouletting it anyway would
/// make the surviving paths' weights grow geometrically (heavy-tailed noise).
pub fn roulette(
    depth: u32,
    rr_depth: u32,
    throughput: &mut Rgb,
    sampler: &mut Sampler,
) -> Option<f32> {
    let max_throughput = throughput.max_element();
    if depth + 1 < rr_depth || max_throughput >= 1.0 {
        return Some(1.0);
    }
    let survive = max_throughput.min(0.95);
    if sampler.next_1d() >= survive {
        return None;
    }
    *throughput /= survive;
    Some(survive)
}

/// Next-event estimation at `sp` toward `light`, chosen with probability `select_pdf`: what
/// it adds to a path of weight `throughput`, MIS-weighted (power heuristic) against sampling
/// the scattering function, which cannot find delta lights (their weight is 1). Zero when the
/// light is blocked or sends nothing.
pub fn direct_light(
    scene: &Scene,
    sp: &ShadingPoint,
    light: &Light,
    u: Vec2,
    select_pdf: f32,
    throughput: Rgb,
) -> Rgb {
    direct_light_sample(scene, sp, light, u, select_pdf, |_, scatter_pdf| {
        scatter_pdf
    })
    .map_or(Rgb::ZERO, |d| d.contribution(throughput))
}

/// One next-event estimate at a shading point, before it is weighed by the path's throughput.
#[derive(Clone, Copy, Debug)]
pub struct DirectSample {
    /// Unit direction toward the light.
    pub wi: Vec3,
    /// The scattering value toward `wi` (cosine included).
    pub f: Rgb,
    /// Radiance arriving along `wi`.
    pub radiance: Rgb,
    /// MIS weight over the light sample's density (selection included): `radiance · scale`
    /// estimates the incident radiance's integral.
    pub scale: f32,
}

impl DirectSample {
    /// What the estimate adds to a path of weight `throughput`.
    pub fn contribution(&self, throughput: Rgb) -> Rgb {
        throughput * self.f * self.radiance * self.scale
    }
}

/// [`direct_light`]'s estimate before the throughput, for integrators that sample scattering
/// directions with a density of their own: `scatter_density(wi, pdf)` maps the scattering
/// function's density `pdf` of `wi` to the density with which the integrator would have
/// sampled `wi`, against which the light sample is MIS-weighted. `None` when the light is
/// blocked or sends nothing.
pub fn direct_light_sample(
    scene: &Scene,
    sp: &ShadingPoint,
    light: &Light,
    u: Vec2,
    select_pdf: f32,
    scatter_density: impl Fn(Vec3, f32) -> f32,
) -> Option<DirectSample> {
    let (shadow, sample) = direct_light_unoccluded(sp, light, u, select_pdf, scatter_density)?;
    (!scene.occluded(&shadow)).then_some(sample)
}

/// [`direct_light_sample`] before its shadow ray is traced: the shadow ray, and the estimate
/// should nothing block it. For integrators that trace the shadow rays of many paths together.
pub fn direct_light_unoccluded(
    sp: &ShadingPoint,
    light: &Light,
    u: Vec2,
    select_pdf: f32,
    scatter_density: impl Fn(Vec3, f32) -> f32,
) -> Option<(Ray, DirectSample)> {
    let ls = light.sample_li(sp.p, u)?;
    // The scattering pdf comes with f at little extra cost.
    let (f, scatter_pdf) = sp.eval_pdf(ls.wi);
    if !(ls.pdf > 0.0 && f != Rgb::ZERO && ls.radiance != Rgb::ZERO) {
        return None;
    }
    let shadow = sp.spawn(ls.wi).with_t_max(ls.distance * (1.0 - 1e-4));
    let light_pdf = select_pdf * ls.pdf;
    let weight = if ls.is_delta {
        1.0
    } else {
        power_heuristic(light_pdf, scatter_density(ls.wi, scatter_pdf))
    };
    Some((
        shadow,
        DirectSample {
            wi: ls.wi,
            f,
            radiance: ls.radiance,
            scale: weight / light_pdf,
        },
    ))
}

/// What the light at infinity `light` adds to a path of weight `throughput` that escaped along
/// `dir`, MIS-weighted against next-event estimation choosing it with probability
/// `select_pdf`. `scatter_pdf` is the density of the scattering sample that produced the ray;
/// `None` for a camera ray, which light sampling cannot produce (weight 1), and which sees
/// environment maps interpolated between texels ([`Light::le_seen`]), and for a scattered ray
/// where no light at infinity is sampled directly ([`Lights::weighs_escapes`]: weight 1 too,
/// and the lights it can find, constant skies, look the same either way).
///
/// [`Lights::weighs_escapes`]: crate::scene::Lights::weighs_escapes
pub fn escaped_light(
    light: &Light,
    dir: Vec3,
    scatter_pdf: Option<f32>,
    select_pdf: f32,
    throughput: Rgb,
) -> Rgb {
    // A camera ray sees the light directly: no MIS weight, and environment maps smooth.
    let Some(scatter_pdf) = scatter_pdf else {
        return throughput * light.le_seen(dir);
    };
    let (le, light_pdf) = light.le_pdf(dir);
    if le == Rgb::ZERO {
        return Rgb::ZERO;
    }
    throughput * le * power_heuristic(scatter_pdf, select_pdf * light_pdf)
}
