//! Path tracing that ends its paths in a radiance cache trained on the film's own paths.
//!
//! Samples fall in blocks that double in length (`block_spp`, then twice as many, …); before
//! the first sample of a block, the block's cache is trained on `training_spp · 2^b`
//! path-traced paths per pixel (block b; each block's paths include the block before's), so
//! the cache's error falls as samples accumulate. The paths record, at every vertex, the radiance leaving it toward the previous vertex as the rest of the path
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
//! Records are kept per vertex number (`match_depth`): a lookup at a path's vertex d reads
//! records made at training paths' vertex d, which are spread over a cell as the lookups are.
//! The records' cells are bounded (`max_record_cells`): past the bound, the class with the most
//! drops its finest level, so a render's memory stays flat however many blocks it reaches.
//!
//! RON: `RadianceCache(training_spp: 4, block_spp: 32, traced_bounces: 2)`

#![warn(missing_docs)]

use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tress_core::film::FilmSettings;
use tress_core::integrator::{
    direct_light, escaped_light, roulette, scatter, trace_path, BuildError, FilmIntegrator,
};
use tress_core::math::Vec3;
use tress_core::prepare::Preparation;
use tress_core::{Integrator, IntegratorKind, Ray, Rgb, Sampler, Scene, ShadingPoint};
use tress_learned_light::{
    block_of, block_segments, check_ranges, BlockLearning, FilmKey, LastFilm, Lattice, OutOfRange,
    RadianceCache, Records,
};

/// Radiance-cache settings.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CacheSettings {
    /// Training paths per pixel of the film's window (its crop, or the whole film), each
    /// traced to its end, for the first block of samples; each later block's cache is trained
    /// on twice as many.
    pub training_spp: u32,
    /// Samples of the first block: sample blocks double in length (`block_spp`, then
    /// `2 block_spp`, …), and each renders with a cache of its own trained on twice the paths
    /// of the block before, so that the cache's error keeps falling as samples accumulate.
    pub block_spp: u32,
    /// Vertices traced exactly before the cache is read grow by this many with each block,
    /// so that what the cache averages weighs less and less and the image converges to the
    /// path tracer's. With 0 the cache's bias falls only as its cells get finer: 3.0–4.1 % in
    /// a channel on light hair at 512–1024 spp, against 2.8 % at most with 1, which costs
    /// 1.25–1.6× the time to equal error.
    pub handoff_growth: u32,
    /// Whether a lookup at a path's vertex number d reads only records made at training
    /// paths' vertex number d (the last class, 5, holds every deeper one; 23 with a growing
    /// hand-off). Training paths
    /// start at the camera as rendered paths do, so their vertices of one number are spread
    /// over a cell as the lookups at that number are; records of all numbers together are
    /// not (the points a path reaches early are more open than deeper ones).
    pub match_depth: bool,
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
    /// Cells (cell, direction bin, vertex-number class) the training records may fill: past
    /// it, the class with the most cells is summed one level coarser (its finest level
    /// dropped) until they fit, so that memory stays flat however many samples a render
    /// takes, at the cost of coarser lookups in later blocks. The default, 2^19 (524,288), keeps
    /// a 512² render of 100,000 strands about 120 MiB over the path tracer, under 256 MiB with
    /// room for the allocator's run-to-run spread (the records and the caches built from them;
    /// 2^20 measured 190–230 MiB); a 64² film of light hair reaches it only past 480 spp.
    pub max_record_cells: u64,
    /// Scattering events of a path (training and rendering) before it ends.
    pub max_depth: u32,
    /// Bounces before Russian roulette starts.
    pub rr_depth: u32,
}

impl Default for CacheSettings {
    fn default() -> Self {
        CacheSettings {
            training_spp: 4,
            block_spp: 32,
            handoff_growth: 1,
            match_depth: true,
            traced_bounces: 2,
            finest_cells_log2: 7,
            levels: 8,
            direction_bins: 4,
            min_records: 16,
            max_record_cells: 1 << 19,
            max_depth: 100,
            rr_depth: 5,
        }
    }
}

impl CacheSettings {
    fn check(&self) -> Result<(), OutOfRange> {
        check_ranges(
            RadianceCacheIntegrator::NAME,
            &[
                (
                    "block_spp",
                    self.block_spp as f64,
                    self.block_spp >= 1,
                    "must be at least 1",
                ),
                (
                    "handoff_growth",
                    self.handoff_growth as f64,
                    self.handoff_growth <= 16,
                    "must lie in 0..=16",
                ),
                (
                    "training_spp",
                    self.training_spp as f64,
                    (1..=4096).contains(&self.training_spp),
                    "must lie in 1..=4096",
                ),
                (
                    "finest_cells_log2",
                    self.finest_cells_log2 as f64,
                    (1..=16).contains(&self.finest_cells_log2),
                    "must lie in 1..=16 (2 to 65 536 cells per side)",
                ),
                (
                    "levels",
                    self.levels as f64,
                    (1..=(self.finest_cells_log2.saturating_add(1)).min(Lattice::MAX_LEVELS))
                        .contains(&self.levels),
                    "must lie in 1..=finest_cells_log2 + 1 and at most 16",
                ),
                (
                    "direction_bins",
                    self.direction_bins as f64,
                    (1..=64).contains(&self.direction_bins),
                    "must lie in 1..=64",
                ),
                (
                    "min_records",
                    self.min_records as f64,
                    self.min_records >= 1,
                    "must be at least 1",
                ),
                (
                    "max_record_cells",
                    self.max_record_cells as f64,
                    self.max_record_cells >= 1,
                    "must be at least 1",
                ),
            ],
        )
    }
}

/// The `radiance-cache` integrator as built for a scene: the cache of the film last rendered
/// is kept, so the waves and sample ranges of one image train it once.
#[derive(Debug)]
pub struct RadianceCacheIntegrator {
    settings: CacheSettings,
    trained: LastFilm<Trained>,
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
            trained: LastFilm::default(),
        }))
    }

    /// A coarse cache from one path per pixel, sample blocks of two (so that the tests' few
    /// samples cross blocks), a budget of record cells that the tests' small films exceed from
    /// the first block (a 40² film of dark hair fills 160–660), so that they hold coarsened
    /// caches to the same images for any threads and pass, and paths deep enough for
    /// white furnaces.
    fn test_settings() -> CacheSettings {
        CacheSettings {
            training_spp: 1,
            block_spp: 2,
            max_record_cells: 128,
            max_depth: 10_000,
            ..Default::default()
        }
    }
}

impl Integrator for RadianceCacheIntegrator {
    /// Without a film there is no cache: every path is traced to its end.
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        trace(&self.settings, None, 0, ray, scene, sampler)
    }

    fn for_film(
        &self,
        scene: &Scene,
        film: &FilmSettings,
        samples: Range<u64>,
        cancel: &AtomicBool,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Option<FilmIntegrator> {
        let block_spp = self.settings.block_spp;
        self.trained.for_film(
            &self.settings,
            block_spp,
            scene,
            film,
            samples,
            cancel,
            progress,
        )
    }

    /// One segment a sample block, so that a render holds one block's caches at a time.
    fn sample_segments(&self, samples: Range<u64>) -> Vec<Range<u64>> {
        block_segments(self.settings.block_spp, samples)
    }
}

/// The integrator with the caches of one film's sample blocks.
struct Trained {
    settings: CacheSettings,
    /// The first block that has a cache.
    first_block: u32,
    /// The caches of blocks `first_block..`.
    caches: Vec<BlockCaches>,
    /// The records of the training paths traced, per vertex-number class (empty below the
    /// first class read), for the training of later blocks to go on from. Taken by that
    /// training, so that a render whose waves reach new blocks holds the caches of the blocks
    /// it is rendering and one set of records, never every block's caches at once.
    records: Mutex<Option<Vec<Records>>>,
    /// Training paths traced for the film, this training's and those it went on from.
    traced: u64,
    /// Wall seconds of training for the film, this training's and those it went on from.
    seconds: f64,
    /// How the caches were made, for logs.
    description: String,
}

impl std::fmt::Debug for Trained {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.description)
    }
}

impl Integrator for Trained {
    /// Traced with the cache of the sample's block.
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        self.li_sample(ray, scene, sampler, 0)
    }

    fn li_sample(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler, sample_index: u64) -> Rgb {
        let block = block_of(self.settings.block_spp, sample_index);
        let cache = block
            .checked_sub(self.first_block)
            .and_then(|i| self.caches.get(i as usize));
        trace(&self.settings, cache, block, ray, scene, sampler)
    }
}

/// Vertex-number classes of records (see [`CacheSettings::match_depth`]) with a fixed
/// hand-off. Lookups past the hand-off's vertex happen only where its class has too few
/// records, so few classes beyond it are needed: 16 classes rendered the same images as 6 and
/// took 44 MB more (512², 100k strands).
const DEPTH_CLASSES: u32 = 6;
/// Classes with a hand-off that grows: a block whose hand-off reaches the last class would
/// read records pooled over every deeper vertex, darker than its own (measured: 4–6 % dark on
/// platinum heads at 512–1024 spp with 6 classes); 24 last to block 21 at a growth of 1.
const GROWING_DEPTH_CLASSES: u32 = 24;

impl CacheSettings {
    /// The vertex number at which block `block`'s paths first read the cache.
    fn handoff(&self, block: u32) -> u32 {
        self.traced_bounces
            .saturating_add(block.saturating_mul(self.handoff_growth))
    }

    /// Record classes by vertex number.
    fn depth_classes(&self) -> u32 {
        if self.handoff_growth == 0 {
            DEPTH_CLASSES
        } else {
            GROWING_DEPTH_CLASSES
        }
    }

    /// The record class of vertex number `depth`.
    fn depth_class(&self, depth: u32) -> u32 {
        if self.match_depth {
            depth.min(self.depth_classes() - 1)
        } else {
            0
        }
    }
}

/// One sample block's caches, one per record class from `first_class` on.
struct BlockCaches {
    first_class: u32,
    caches: Vec<RadianceCache>,
}

impl BlockCaches {
    fn lookup(&self, class: u32, p: Vec3, dir: Vec3) -> Option<Rgb> {
        self.caches
            .get(class.checked_sub(self.first_class)? as usize)?
            .lookup(p, dir)
    }
}

/// Stream tag of the training paths' random numbers (apart from every pixel sample's).
const TRAINING_STREAM: u64 = 0x7261_6469_616e_6365;

impl BlockLearning for Trained {
    type Settings = CacheSettings;

    /// The caches of sample blocks `blocks`: block `b`'s from the first `training_spp · 2^b`
    /// training paths per pixel (each block's paths include the block before's). Goes on from
    /// `before`, the training of earlier blocks of the same film, where it traced no more paths
    /// than the first of `blocks` needs; the records are the same sums of the same paths in
    /// the same order either way, so the caches are too. `None` when cancelled.
    fn train(
        settings: &CacheSettings,
        scene: &Scene,
        film: FilmKey,
        blocks: Range<u32>,
        before: Option<Arc<Trained>>,
        cancel: &AtomicBool,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Option<Self> {
        let start = Instant::now();
        let lattice = Lattice::new(
            scene.bounds(),
            settings.finest_cells_log2,
            settings.levels,
            settings.direction_bins,
        );
        let paths_of = |block: u32| film.pixels() * ((settings.training_spp as u64) << block);
        let total = paths_of(blocks.end - 1);
        let went_on = before
            .filter(|b| b.traced <= paths_of(blocks.start))
            .and_then(|b| {
                let records = b.records.lock().unwrap_or_else(|e| e.into_inner()).take()?;
                Some((records, b.traced, b.seconds))
            });
        let (mut records, mut traced, seconds_before) = went_on.unwrap_or_else(|| {
            let empty = vec![Records::default(); settings.depth_classes() as usize];
            (empty, 0, 0.0)
        });
        let first_traced = traced;
        let mut caches = Vec::new();
        for block in 0..blocks.end {
            if paths_of(block) < traced {
                continue;
            }
            let paths = traced..paths_of(block);
            train(
                settings,
                scene,
                film,
                lattice,
                paths.clone(),
                cancel,
                &|done| {
                    let done = paths.start + done - first_traced;
                    progress(done as f64 / (total - first_traced).max(1) as f64)
                },
                &mut records,
            )?;
            traced = paths.end;
            if block >= blocks.start {
                let first_class = settings.depth_class(settings.handoff(block));
                let last_class = settings.depth_class(u32::MAX);
                caches.push(BlockCaches {
                    first_class,
                    caches: records[first_class as usize..=last_class as usize]
                        .iter()
                        .map(|r| RadianceCache::new(lattice, r, settings.min_records))
                        .collect(),
                });
            }
        }
        let seconds = seconds_before + start.elapsed().as_secs_f64();
        let last = &caches.last().expect("at least one block").caches[0];
        let first_read = settings.depth_class(settings.handoff(0)) as usize;
        let description = format!(
            "{} caches for sample blocks {}..{} (the last {}), from {total} training paths \
             ({} record cells of at most {}, finest levels by vertex class {:?}), built in \
             {seconds:.2} s",
            caches.len(),
            blocks.start,
            blocks.end,
            last.describe(),
            records.iter().map(Records::cells).sum::<usize>(),
            settings.max_record_cells,
            records[first_read..]
                .iter()
                .map(Records::level)
                .collect::<Vec<_>>(),
        );
        Some(Trained {
            settings: settings.clone(),
            first_block: blocks.start,
            caches,
            records: Mutex::new(Some(records)),
            traced,
            seconds,
            description,
        })
    }

    /// Whether it has the caches of every block of `blocks`.
    fn covers(&self, blocks: &Range<u32>) -> bool {
        blocks.start >= self.first_block
            && blocks.end <= self.first_block + self.caches.len() as u32
    }

    fn description(&self) -> &str {
        &self.description
    }
}

/// Adds the records of training paths `paths` through the film's pixels to `records`.
/// `progress` gets the paths done; `None` when cancelled.
#[allow(clippy::too_many_arguments)]
fn train(
    settings: &CacheSettings,
    scene: &Scene,
    film: FilmKey,
    lattice: Lattice,
    paths: Range<u64>,
    cancel: &AtomicBool,
    progress: &(dyn Fn(u64) + Sync),
    records: &mut [Records],
) -> Option<()> {
    // Classes below the first hand-off's are never read (the hand-off only recedes).
    let first_read = settings.depth_class(settings.handoff(0));
    tress_learned_light::train(
        scene,
        film,
        TRAINING_STREAM,
        paths,
        cancel,
        progress,
        |ray, sampler, chunk: &mut (Vec<Records>, Vec<Vertex>)| {
            let (chunk_records, vertices) = chunk;
            chunk_records.resize_with(settings.depth_classes() as usize, Records::default);
            training_path(settings, ray, scene, sampler, vertices);
            for (depth, v) in vertices.iter().enumerate() {
                let class = settings.depth_class(depth as u32);
                if class >= first_read {
                    chunk_records[class as usize].add(&lattice, v.p, v.wo, v.radiance);
                }
            }
        },
        |(chunk, _)| {
            for (records, chunk) in records.iter_mut().zip(&chunk) {
                records.merge(chunk);
            }
            bound(records, &lattice, settings.max_record_cells);
        },
    )
}

/// Coarsens the records of the class with the most cells, a level at a time, until all
/// classes together fill at most `max_cells` (or every class is at the coarsest level, whose
/// cells are few). The class read most, the hand-off's, keeps its finest level longest where
/// deeper ones, read only where it has too few records, fill more. Called after each chunk's
/// merge, in the chunks' fixed order, so when the records are coarsened depends only on the
/// scene, the film and the paths traced, never on threads.
fn bound(records: &mut [Records], lattice: &Lattice, max_cells: u64) {
    while records.iter().map(|r| r.cells() as u64).sum::<u64>() > max_cells {
        let largest = records
            .iter_mut()
            .filter(|r| r.level() + 1 < lattice.levels())
            .max_by_key(|r| r.cells());
        let Some(records) = largest else { return };
        records.coarsen(lattice);
    }
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
    cache: Option<&BlockCaches>,
    block: u32,
    camera_ray: &Ray,
    scene: &Scene,
    sampler: &mut Sampler,
) -> Rgb {
    let handoff = settings.handoff(block);
    let (max_depth, rr_depth) = (settings.max_depth, settings.rr_depth);
    trace_path(scene, camera_ray, max_depth, rr_depth, sampler, |v| {
        let cache = cache.filter(|_| v.depth >= handoff)?;
        let cached = cache.lookup(settings.depth_class(v.depth), v.hit.p, -v.ray.dir)?;
        Some(v.throughput * cached)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_bound_is_the_one_stated() {
        let with = |finest_cells_log2, levels| CacheSettings {
            finest_cells_log2,
            levels,
            ..CacheSettings::default()
        };
        assert!(with(7, 8).check().is_ok());
        assert!(with(7, 9).check().is_err());
        // At 16 cells log2 the 4 bits of a cache key, not finest_cells_log2 + 1, bound it.
        assert!(with(16, 16).check().is_ok());
        let e = with(16, 17).check().unwrap_err();
        assert_eq!(e.field, "levels");
        assert!(e.why.contains("at most 16"), "{}", e.why);
    }

    #[test]
    fn records_are_classed_by_vertex_number_when_matched() {
        let matched = CacheSettings {
            handoff_growth: 0,
            ..Default::default()
        };
        assert_eq!(matched.depth_class(0), 0);
        assert_eq!(matched.depth_class(3), 3);
        assert_eq!(matched.depth_class(1000), DEPTH_CLASSES - 1);
        let pooled = CacheSettings {
            match_depth: false,
            handoff_growth: 0,
            ..Default::default()
        };
        assert_eq!(pooled.depth_class(7), 0);
        assert_eq!(pooled.handoff(3), pooled.traced_bounces);
        let growing = CacheSettings {
            handoff_growth: 2,
            ..Default::default()
        };
        assert_eq!(growing.handoff(3), growing.traced_bounces + 6);
        assert_eq!(growing.depth_class(20), 20);
    }

    #[test]
    fn records_are_coarsened_to_their_budget_and_still_looked_up() {
        let unit = tress_core::math::Aabb {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        let lattice = Lattice::new(unit, 5, 6, 2);
        // Class 1 gets 4× the records of class 0, over the same fixed pseudo-random points.
        let mut records = vec![Records::default(); 2];
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for i in 0..20_000 {
            let p = Vec3::new(next(), next(), next());
            let dir = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize();
            records[usize::from(i % 5 != 0)].add(&lattice, p, dir, Rgb::splat(next()));
        }
        let cells = |r: &[Records]| r.iter().map(|r| r.cells() as u64).sum::<u64>();
        let (before, budget) = (cells(&records), 15_000);
        assert!(before > budget, "{before}");
        bound(&mut records, &lattice, budget);
        assert!(cells(&records) <= budget, "{}", cells(&records));
        assert_eq!(records.iter().map(|r| r.count).sum::<u64>(), 20_000);
        // The fuller class was coarsened, the other keeps its finest level.
        assert_eq!((records[0].level(), records[1].level()), (0, 1));
        for r in &records {
            let cache = RadianceCache::new(lattice, r, 4);
            for p in [Vec3::splat(0.1), Vec3::new(0.9, 0.5, 0.3)] {
                let radiance = cache.lookup(p, Vec3::Z).expect("a cell with records");
                assert!((0.0..1.0).contains(&radiance.x), "{radiance}");
            }
        }
        // A budget below what the coarsest level holds coarsens every class to it, and stops.
        bound(&mut records, &lattice, 1);
        assert_eq!((records[0].level(), records[1].level()), (5, 5));
        assert_eq!(cells(&records), 8);
    }
}
