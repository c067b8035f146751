//! Wavefront path tracing: the path tracer's estimator, with the paths of a wave of camera
//! samples advanced together one scattering event at a time.
//!
//! Each step shades every live path's vertex (next-event estimation and scattering, with the
//! path's own sampler, in the order `path` draws its numbers), then traces all the shadow
//! rays of the step as one batch and all the continuations as another
//! ([`Scene::occluded_many`], [`Scene::intersect_many`]), so an accelerator that traces many
//! rays at once faster than one at a time speeds every step up. Paths are shaded in the order
//! of the fiber segment they hit, so consecutive paths read the same geometry and material.
//! A sample's radiance does not depend on the other samples of its wave: the image is `path`'s,
//! bit for bit.
//!
//! RON: `Wavefront(max_depth: 100, rr_depth: 5)` (the settings of `Path`, the same defaults)

#![warn(missing_docs)]

use serde::{Deserialize, Serialize};
use tress_core::integrator::{
    direct_light_unoccluded, escaped_light, roulette, scatter, trace_path, BuildError, WaveSample,
};
use tress_core::math::Vec2;
use tress_core::prepare::Preparation;
use tress_core::shading::ShadingPoint;
use tress_core::{Hit, Integrator, IntegratorKind, Ray, Rgb, Sampler, Scene};

/// Wavefront path tracer settings: those of `Path`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct WavefrontSettings {
    /// Maximum number of scattering events (as `Path`'s).
    pub max_depth: u32,
    /// Bounces before Russian roulette starts.
    pub rr_depth: u32,
    /// Paths advanced together (default 128; 0 counts as 1): the render loop's waves are cut
    /// into groups of this many. More paths hide more of the light tables' memory latency; fewer keep the
    /// fibers each path shades and leaves in the cache until its rays are traced. The image
    /// does not depend on it.
    pub paths: u32,
}

impl Default for WavefrontSettings {
    fn default() -> Self {
        WavefrontSettings {
            max_depth: 100,
            rr_depth: 5,
            // Measured under an environment map (straight.hair tubes): groups of 128 took
            // 0.925 of path's CPU time, of 1024 0.962.
            paths: 128,
        }
    }
}

/// The wavefront path tracer.
#[derive(Clone, Debug)]
pub struct WavefrontPathTracer {
    settings: WavefrontSettings,
}

impl WavefrontPathTracer {
    /// A wavefront path tracer with `settings`.
    pub fn new(settings: WavefrontSettings) -> Self {
        WavefrontPathTracer { settings }
    }
}

impl IntegratorKind for WavefrontPathTracer {
    type Settings = WavefrontSettings;
    const NAME: &'static str = "wavefront";
    const UNBIASED: bool = true;

    fn build(
        settings: &WavefrontSettings,
        _: &Scene,
        _: &Preparation,
    ) -> Result<Box<dyn Integrator>, BuildError> {
        Ok(Box::new(WavefrontPathTracer::new(settings.clone())))
    }

    /// As `path`'s: deep enough for white furnaces to balance.
    fn test_settings() -> WavefrontSettings {
        WavefrontSettings {
            max_depth: 10_000,
            // Groups smaller than the render loop's waves, so that the tests cut them.
            paths: 100,
            ..Default::default()
        }
    }
}

/// A path arriving at a vertex, waiting to be shaded.
#[derive(Clone, Copy, Debug)]
struct Vertex {
    /// The sample in the wave.
    path: u32,
    ray: Ray,
    hit: Hit,
    throughput: Rgb,
    depth: u32,
}

/// A path's continuation, waiting to be traced.
#[derive(Clone, Copy, Debug)]
struct Continuation {
    path: u32,
    throughput: Rgb,
    depth: u32,
    /// The scattering density of the ray, where the lights at infinity it may find need it.
    scatter_pdf: Option<f32>,
}

/// The buffers of one wave, reused from step to step.
#[derive(Default)]
struct Buffers {
    vertices: Vec<Vertex>,
    shadow_rays: Vec<Ray>,
    /// Per shadow ray: its path and what it adds should nothing block it.
    shadow_gain: Vec<(u32, Rgb)>,
    blocked: Vec<bool>,
    next_rays: Vec<Ray>,
    next: Vec<Continuation>,
    hits: Vec<Option<Hit>>,
    /// Per vertex: its first two draws (the light's choice and its sample), `None` past the
    /// depth limit.
    draws: Vec<Option<(f32, Vec2)>>,
    /// The rays of `arrive` that escaped, with their states.
    escaped: Vec<(Ray, Continuation)>,
}

impl WavefrontPathTracer {
    /// Traces `rays` (their paths and states in `states`) and turns each into the vertex it
    /// reaches, or adds the lights at infinity its path escapes to.
    fn arrive(
        scene: &Scene,
        wave: &mut [WaveSample],
        rays: &[Ray],
        states: &[Continuation],
        hits: &mut Vec<Option<Hit>>,
        vertices: &mut Vec<Vertex>,
        escaped: &mut Vec<(Ray, Continuation)>,
    ) {
        hits.clear();
        hits.resize(rays.len(), None);
        scene.intersect_many(rays, hits);
        vertices.clear();
        escaped.clear();
        for ((ray, c), hit) in rays.iter().zip(states).zip(hits.iter()) {
            match hit {
                Some(hit) => vertices.push(Vertex {
                    path: c.path,
                    ray: *ray,
                    hit: *hit,
                    throughput: c.throughput,
                    depth: c.depth,
                }),
                None => {
                    // The map's texels toward all the escapes are fetched before any is read.
                    if c.scatter_pdf.is_some() {
                        scene.lights.infinite().for_each(|l| l.prefetch_le(ray.dir));
                    }
                    escaped.push((*ray, *c));
                }
            }
        }
        for (ray, c) in escaped.iter() {
            let radiance = &mut wave[c.path as usize].radiance;
            for light in scene.lights.infinite() {
                let select_pdf = scene.lights.select_pdf_of(light);
                *radiance += escaped_light(light, ray.dir, c.scatter_pdf, select_pdf, c.throughput);
            }
        }
    }
}

impl Integrator for WavefrontPathTracer {
    fn li(&self, camera_ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        let WavefrontSettings {
            max_depth,
            rr_depth,
            ..
        } = self.settings;
        trace_path(scene, camera_ray, max_depth, rr_depth, sampler, |_| None)
    }

    fn li_wave(&self, scene: &Scene, wave: &mut [WaveSample]) {
        let mut b = Buffers::default();
        for group in wave.chunks_mut(self.settings.paths.max(1) as usize) {
            self.advance(scene, group, &mut b);
        }
    }
}

impl WavefrontPathTracer {
    /// Advances the paths of `wave` together to their ends, with `b` as scratch space.
    fn advance(&self, scene: &Scene, wave: &mut [WaveSample], b: &mut Buffers) {
        let WavefrontSettings {
            max_depth,
            rr_depth,
            ..
        } = self.settings;
        let density_needed = scene.lights.weighs_escapes();
        // The camera rays: a camera ray that escapes sees the lights at infinity unweighted.
        // (The buffers hold the last rays of the group before.)
        b.next_rays.clear();
        b.next.clear();
        b.next_rays.extend(wave.iter().map(|w| w.ray));
        b.next
            .extend((0..wave.len() as u32).map(|path| Continuation {
                path,
                throughput: Rgb::ONE,
                depth: 0,
                scatter_pdf: None,
            }));
        for w in wave.iter_mut() {
            w.radiance = Rgb::ZERO;
        }
        Self::arrive(
            scene,
            wave,
            &b.next_rays,
            &b.next,
            &mut b.hits,
            &mut b.vertices,
            &mut b.escaped,
        );
        while !b.vertices.is_empty() {
            // Paths at the same fiber segment one after another: shading reads its control
            // points and material once for all of them.
            b.vertices
                .sort_unstable_by_key(|v| (v.hit.prim.geom, v.hit.prim.prim, v.path));
            b.shadow_rays.clear();
            b.shadow_gain.clear();
            b.next_rays.clear();
            b.next.clear();
            // Every vertex's first two draws, taken ahead of its shading (its path's stream
            // is unchanged: they are its first), so that the light tables they read (an
            // environment map's alias entries) are fetched for all vertices at once.
            b.draws.clear();
            for v in &b.vertices {
                if v.depth >= max_depth {
                    b.draws.push(None);
                    continue;
                }
                let sampler = &mut wave[v.path as usize].sampler;
                let u_select = sampler.next_1d();
                let u_light = sampler.next_2d();
                if let Some((light, _)) = scene.lights.choose(u_select) {
                    light.prefetch_sample(u_light);
                }
                b.draws.push(Some((u_select, u_light)));
            }
            for (v, draws) in b.vertices.iter().zip(&b.draws) {
                let Some((u_select, u_light)) = *draws else {
                    continue;
                };
                let sampler = &mut wave[v.path as usize].sampler;
                // Then exactly `continue_path`'s draws, in its order.
                let sp = ShadingPoint::new(&v.hit, &v.ray, &scene.materials);
                if let Some((light, select_pdf)) = scene.lights.choose(u_select) {
                    if let Some((shadow, d)) =
                        direct_light_unoccluded(&sp, light, u_light, select_pdf, |_, pdf| pdf)
                    {
                        b.shadow_rays.push(shadow);
                        b.shadow_gain.push((v.path, d.contribution(v.throughput)));
                    }
                }
                let mut throughput = v.throughput;
                let Some((next, scatter_pdf)) =
                    scatter(&sp, sampler, &mut throughput, density_needed)
                else {
                    continue;
                };
                if roulette(v.depth, rr_depth, &mut throughput, sampler).is_none() {
                    continue;
                }
                b.next_rays.push(next);
                b.next.push(Continuation {
                    path: v.path,
                    throughput,
                    depth: v.depth + 1,
                    scatter_pdf,
                });
            }
            // A path's light arriving at this vertex is added before what its continuation
            // finds, as `path` adds them, so the sums round alike.
            b.blocked.clear();
            b.blocked.resize(b.shadow_rays.len(), true);
            scene.occluded_many(&b.shadow_rays, &mut b.blocked);
            for (&(path, gain), &blocked) in b.shadow_gain.iter().zip(&b.blocked) {
                if !blocked {
                    wave[path as usize].radiance += gain;
                }
            }
            Self::arrive(
                scene,
                wave,
                &b.next_rays,
                &b.next,
                &mut b.hits,
                &mut b.vertices,
                &mut b.escaped,
            );
        }
    }
}
