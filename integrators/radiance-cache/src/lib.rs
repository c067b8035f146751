//! Path tracing that ends its paths in a radiance cache trained on the film's own paths.
//!
//! Before the first sample of a film, `training_spp` path-traced paths per pixel record, at
//! every vertex, the radiance leaving it toward the previous vertex as the rest of the path
//! estimated it: an unbiased estimate of the light a point sends in a direction, however many
//! bounces along the fibers it took. Records are averaged per cell and direction bin
//! ([`cache`]).
//!
//! A camera path shades its first `traced_bounces` vertices as the path tracer does
//! (next-event estimation, MIS, a sampled continuation) and takes the radiance leaving the next
//! vertex from the cache, where a cell has enough records (else it goes on tracing): a final
//! gather, two bounces deep by default. The point the camera sees, its neighbours and their
//! direct light are exact, and only the light arriving from further away is averaged, so the
//! cells can be much coarser than the fibers. The cache holds the whole outgoing radiance, not the part
//! left after next-event estimation: that part depends on how open each point is, which a
//! cell averages, and a point more open than its cell's average would get its direct light
//! twice (measured: a white furnace at β = 0.9 returned 1.034).
//! docs/src/research/radiance-cache.md measures it against the path tracer.
//!
//! RON: `RadianceCache(training_spp: 8, traced_bounces: 2)`

#![warn(missing_docs)]

mod cache;

use cache::{Lattice, RadianceCache, Records};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tress_core::film::FilmSettings;
use tress_core::integrator::{
    direct_light, escaped_light, roulette, scatter, BuildError, FilmIntegrator,
};
use tress_core::math::Vec3;
use tress_core::prepare::Preparation;
use tress_core::rng::hash_words;
use tress_core::{Integrator, IntegratorKind, Ray, Rgb, Sampler, Scene, ShadingPoint};

/// Radiance-cache settings.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CacheSettings {
    /// Training paths per pixel of the film (over the whole film, whatever its crop), each
    /// traced to its end.
    pub training_spp: u32,
    /// Vertices of a camera path shaded exactly before the cache is used. The points a path
    /// reaches early are more open than the average of their cell's records, so the later the
    /// cache is read the less its averaging darkens: measured on blond hair (64², hair means
    /// ÷ the path tracer's), 0.94 at 1 and 0.98–0.99 at 2, the default. 0 takes the visible
    /// point's own radiance from the cache: cheapest, and no noise from directions.
    pub traced_bounces: u32,
    /// Cells along the longest side of the scene's bounds at the finest level, as a power of
    /// two (7: 128 cells).
    pub finest_cells_log2: u32,
    /// Levels of cells, each with half the cells per side of the one before.
    pub levels: u32,
    /// Direction bins per side of the octahedral map (4: 16 bins).
    pub direction_bins: u32,
    /// Records a cell must average before lookups use it.
    pub min_records: u32,
    /// Scattering events of a path (training and rendering) before it ends.
    pub max_depth: u32,
    /// Bounces before Russian roulette starts.
    pub rr_depth: u32,
}

impl Default for CacheSettings {
    fn default() -> Self {
        CacheSettings {
            training_spp: 8,
            traced_bounces: 2,
            finest_cells_log2: 7,
            levels: 8,
            direction_bins: 4,
            min_records: 64,
            max_depth: 100,
            rr_depth: 5,
        }
    }
}

/// Settings that cannot describe a cache.
#[derive(Debug, thiserror::Error)]
pub enum CacheSettingsError {
    /// A value outside its range.
    #[error("radiance-cache settings: {field} = {value}: {why}")]
    OutOfRange {
        /// The setting.
        field: &'static str,
        /// Its value.
        value: u32,
        /// The range it must lie in.
        why: &'static str,
    },
}

impl CacheSettings {
    fn check(&self) -> Result<(), CacheSettingsError> {
        let checks: [(&'static str, u32, bool, &'static str); 5] = [
            (
                "training_spp",
                self.training_spp,
                (1..=4096).contains(&self.training_spp),
                "must lie in 1..=4096",
            ),
            (
                "finest_cells_log2",
                self.finest_cells_log2,
                (1..=16).contains(&self.finest_cells_log2),
                "must lie in 1..=16 (2 to 65 536 cells per side)",
            ),
            (
                "levels",
                self.levels,
                (1..=self.finest_cells_log2.min(15) + 1).contains(&self.levels),
                "must lie in 1..=finest_cells_log2 + 1",
            ),
            (
                "direction_bins",
                self.direction_bins,
                (1..=64).contains(&self.direction_bins),
                "must lie in 1..=64",
            ),
            (
                "min_records",
                self.min_records,
                self.min_records >= 1,
                "must be at least 1",
            ),
        ];
        for (field, value, ok, why) in checks {
            if !ok {
                return Err(CacheSettingsError::OutOfRange { field, value, why });
            }
        }
        Ok(())
    }
}

/// The `radiance-cache` integrator as built for a scene: the cache of the film last rendered
/// is kept, so the waves and sample ranges of one image train it once.
#[derive(Debug)]
pub struct RadianceCacheIntegrator {
    settings: CacheSettings,
    trained: Mutex<Option<(FilmKey, Arc<Trained>)>>,
}

/// What a cache depends on besides the scene: the film's size and seed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct FilmKey {
    width: u32,
    height: u32,
    seed: u64,
}

impl IntegratorKind for RadianceCacheIntegrator {
    type Settings = CacheSettings;
    const NAME: &'static str = "radiance-cache";
    const UNBIASED: bool = false;

    fn build(
        settings: &CacheSettings,
        _: &Scene,
        _: &Preparation,
    ) -> Result<Box<dyn Integrator>, BuildError> {
        settings.check()?;
        Ok(Box::new(RadianceCacheIntegrator {
            settings: settings.clone(),
            trained: Mutex::new(None),
        }))
    }

    /// A coarse cache from one path per pixel, and paths deep enough for white furnaces.
    fn test_settings() -> CacheSettings {
        CacheSettings {
            training_spp: 1,
            max_depth: 10_000,
            ..Default::default()
        }
    }
}

impl Integrator for RadianceCacheIntegrator {
    /// Without a film there is no cache: every path is traced to its end.
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        trace(&self.settings, None, ray, scene, sampler)
    }

    fn for_film(
        &self,
        scene: &Scene,
        film: &FilmSettings,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Option<FilmIntegrator> {
        let key = FilmKey {
            width: film.width,
            height: film.height,
            seed: film.seed,
        };
        let mut trained = self.trained.lock().unwrap_or_else(|e| e.into_inner());
        let t = match trained.as_ref() {
            Some((k, t)) if *k == key => t.clone(),
            _ => {
                let t = Arc::new(Trained::new(&self.settings, scene, key, progress));
                *trained = Some((key, t.clone()));
                t
            }
        };
        Some(FilmIntegrator {
            note: t.description.clone(),
            integrator: t,
        })
    }
}

/// The integrator with its cache for one film.
struct Trained {
    settings: CacheSettings,
    cache: RadianceCache,
    /// How the cache was made, for logs.
    description: String,
}

impl std::fmt::Debug for Trained {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.description)
    }
}

impl Integrator for Trained {
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        trace(&self.settings, Some(&self.cache), ray, scene, sampler)
    }
}

/// Paths traced per training task: fixed, so the records each task sums — and so the cache —
/// are the same for any number of threads.
const TRAINING_CHUNK: u64 = 256;
/// Chunks traced in parallel before their records are merged.
const TRAINING_BATCH: u64 = 64;
/// Stream tag of the training paths' random numbers (apart from every pixel sample's).
const TRAINING_STREAM: u64 = 0x7261_6469_616e_6365;

impl Trained {
    fn new(
        settings: &CacheSettings,
        scene: &Scene,
        film: FilmKey,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Self {
        let start = Instant::now();
        let lattice = Lattice::new(
            scene.bounds(),
            settings.finest_cells_log2,
            settings.levels,
            settings.direction_bins,
        );
        let paths = film.width as u64 * film.height as u64 * settings.training_spp as u64;
        let records = train(settings, scene, film, lattice, paths, &|done| {
            progress(done as f64 / paths as f64)
        });
        let cache = RadianceCache::new(lattice, records, settings.min_records);
        let description = format!(
            "{} from {paths} training paths, built in {:.2} s",
            cache.describe(),
            start.elapsed().as_secs_f64()
        );
        Trained {
            settings: settings.clone(),
            cache,
            description,
        }
    }
}

/// The records of `paths` training paths through the film's pixels. `progress` gets the
/// paths done.
fn train(
    settings: &CacheSettings,
    scene: &Scene,
    film: FilmKey,
    lattice: Lattice,
    paths: u64,
    progress: &(dyn Fn(u64) + Sync),
) -> Records {
    let pixels = film.width as u64 * film.height as u64;
    let done = AtomicU64::new(0);
    let chunks = paths.div_ceil(TRAINING_CHUNK);
    let mut records = Records::default();
    // A batch of chunks at a time, merged before the next, so that only one batch's unmerged
    // records are held at once.
    for batch in (0..chunks).step_by(TRAINING_BATCH as usize) {
        let chunk_records: Vec<Records> = (batch..(batch + TRAINING_BATCH).min(chunks))
            .into_par_iter()
            .map(|chunk| {
                let mut records = Records::default();
                let mut vertices = Vec::new();
                let range = chunk * TRAINING_CHUNK..((chunk + 1) * TRAINING_CHUNK).min(paths);
                let n = range.end - range.start;
                for i in range {
                    let pixel = i % pixels;
                    let (x, y) = (pixel % film.width as u64, pixel / film.width as u64);
                    let mut sampler =
                        Sampler::from_seed(hash_words(&[film.seed, TRAINING_STREAM, i]));
                    let jitter = sampler.next_2d();
                    let lens = sampler.next_2d();
                    let ray = scene.camera.generate_ray(
                        x as f32 + jitter.x,
                        y as f32 + jitter.y,
                        film.width,
                        film.height,
                        lens,
                    );
                    training_path(settings, &ray, scene, &mut sampler, &mut vertices);
                    for v in &vertices {
                        records.add(&lattice, v.p, v.wo, v.radiance);
                    }
                }
                progress(done.fetch_add(n, Ordering::Relaxed) + n);
                records
            })
            .collect();
        for chunk in &chunk_records {
            records.merge(chunk);
        }
    }
    records
}

/// A vertex of a training path with the radiance the rest of the path brought back from it.
struct Vertex {
    p: Vec3,
    /// Toward the previous vertex.
    wo: Vec3,
    /// Next-event estimation at the vertex, then the whole radiance leaving it toward `wo`
    /// (filled in backwards once the path has ended): what the cache records.
    radiance: Rgb,
    /// f·cos/pdf of the continuation, divided by the roulette's survival probability (zero when
    /// the path ended here).
    weight: Rgb,
}

/// Traces one training path as the path tracer would and fills `vertices` with its vertices
/// and the radiance leaving each toward the one before.
fn training_path(
    settings: &CacheSettings,
    camera_ray: &Ray,
    scene: &Scene,
    sampler: &mut Sampler,
    vertices: &mut Vec<Vertex>,
) {
    vertices.clear();
    let mut ray = *camera_ray;
    let mut throughput = Rgb::ONE;
    // What arrives at the last vertex from its continuation when that escapes.
    let mut escaped = Rgb::ZERO;
    // Density of the last continuation, for the MIS weight of the light its ray finds (when
    // that weight needs it).
    let mut scatter_pdf = None;
    for depth in 0..settings.max_depth {
        let Some(hit) = scene.intersect(&ray) else {
            if !vertices.is_empty() {
                for light in scene.lights.infinite() {
                    let select_pdf = scene.lights.select_pdf_of(light);
                    escaped += escaped_light(light, ray.dir, scatter_pdf, select_pdf, Rgb::ONE);
                }
            }
            break;
        };
        let sp = ShadingPoint::new(&hit, &ray, &scene.materials);
        let u_select = sampler.next_1d();
        let u_light = sampler.next_2d();
        let direct = scene
            .lights
            .choose(u_select)
            .map_or(Rgb::ZERO, |(light, p)| {
                direct_light(scene, &sp, light, u_light, p, Rgb::ONE)
            });
        let mut vertex = Vertex {
            p: hit.p,
            wo: -ray.dir,
            radiance: direct,
            weight: Rgb::ZERO,
        };
        let mut weight = Rgb::ONE;
        let density_needed = scene.lights.weighs_escapes();
        let Some((next, pdf)) = scatter(&sp, sampler, &mut weight, density_needed) else {
            vertices.push(vertex);
            break;
        };
        throughput *= weight;
        // The path tracer's roulette; a path it ends keeps this vertex's direct light only.
        let Some(survive) = roulette(depth, settings.rr_depth, &mut throughput, sampler) else {
            vertices.push(vertex);
            break;
        };
        vertex.weight = weight / survive;
        vertices.push(vertex);
        ray = next;
        scatter_pdf = pdf;
    }
    let mut after = escaped;
    for v in vertices.iter_mut().rev() {
        v.radiance += v.weight * after;
        after = v.radiance;
    }
}

/// The radiance along `camera_ray`: the path tracer's estimator for the first
/// `traced_bounces` vertices, then the cache's radiance leaving the next vertex (or more
/// tracing where the cache has nothing there).
fn trace(
    settings: &CacheSettings,
    cache: Option<&RadianceCache>,
    camera_ray: &Ray,
    scene: &Scene,
    sampler: &mut Sampler,
) -> Rgb {
    let mut radiance = Rgb::ZERO;
    let mut throughput = Rgb::ONE;
    let mut ray = *camera_ray;
    let mut scatter_pdf: Option<f32> = None;
    for depth in 0.. {
        let Some(hit) = scene.intersect(&ray) else {
            for light in scene.lights.infinite() {
                let select_pdf = scene.lights.select_pdf_of(light);
                radiance += escaped_light(light, ray.dir, scatter_pdf, select_pdf, throughput);
            }
            break;
        };
        if depth >= settings.traced_bounces {
            if let Some(cached) = cache.and_then(|c| c.lookup(hit.p, -ray.dir)) {
                radiance += throughput * cached;
                break;
            }
        }
        if depth >= settings.max_depth {
            break;
        }
        let sp = ShadingPoint::new(&hit, &ray, &scene.materials);
        let u_select = sampler.next_1d();
        let u_light = sampler.next_2d();
        if let Some((light, select_pdf)) = scene.lights.choose(u_select) {
            radiance += direct_light(scene, &sp, light, u_light, select_pdf, throughput);
        }
        let density_needed = scene.lights.weighs_escapes();
        let Some((next, pdf)) = scatter(&sp, sampler, &mut throughput, density_needed) else {
            break;
        };
        scatter_pdf = pdf;
        ray = next;
        if roulette(depth, settings.rr_depth, &mut throughput, sampler).is_none() {
            break;
        }
    }
    radiance
}
