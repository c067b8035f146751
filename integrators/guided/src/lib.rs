//! Path tracing guided by the light learned from the film's own training paths.
//!
//! A film's samples come in blocks that double in length (`block_spp`, then twice, four times as
//! many, …, as the radiance cache's). The first block is the path tracer's: nothing has been
//! learned yet, and short renders pay for no training. Before each later block, training paths
//! through the pixels of the film's window (its crop, or the whole film; `training_fraction` of the
//! block's samples per pixel, `training_spp` per pixel in all) record, at every vertex, the light
//! that arrived along the direction the path continued in and along the direction next-event
//! estimation looked in, each divided by the density it was drawn with ([`guide`]); each block's
//! paths are guided by what the blocks before learned, and its guide is built from all the records
//! so far. What a sample sees depends only on its block and the window, so the passes of one image
//! render each sample alike; a crop learns from its own pixels, at a cost in proportion to them.
//!
//! A block's samples draw each continuation from a mixture: with a probability learned per cell
//! from the guide's density of that cell, otherwise from the fiber's own sampling routine. The
//! probability is the one among eighths of `guide_probability` that would have given the
//! training paths' continuations in the cell the smallest second moment (estimated by
//! importance weights), so where the guide does not follow the light better than the fiber
//! does the cell's vertices are the path tracer's, at its cost. When the guide predicts no
//! gain at all, training stops and later blocks keep the last guide. The sample's weight is f
//! over the mixture's exact density (the fiber's density at a guided direction comes from its
//! `pdf`, the guide's at a fiber-sampled direction from its bins), and next-event estimation
//! is MIS-weighted against the same mixture, so the estimator is unbiased whatever was
//! learned. Only the first `guided_vertices` vertices are guided: a mixture's weights vary
//! where the fiber's own are nearly constant, and along light hair's long paths their products
//! grow heavy tails.
//!
//! A fiber has no normal and scatters into the whole sphere, so the guide is a density over the
//! whole sphere too, in world space, and is mixed with the fiber's density rather than
//! multiplied by it: the fiber's sampling keeps the specular cone and the forward lobe, the
//! guide adds the directions that the light inside the hair comes from.
//!
//! Optionally (`adjoint_roulette`), Russian roulette and splitting are driven by the radiance
//! the training paths saw leave each cell (Vorba & Křivánek 2016).
//!
//! docs/src/research/radiance-cache.md measures it.
//!
//! RON: `Guided(block_spp: 8, training_fraction: 0.0625, training_spp: 16, guide_probability: 0.5)`

#![warn(missing_docs)]

mod guide;

pub use guide::Target;
use guide::{ChunkRecords, Continuation, Guide, GuideCell, Records, SphereBins};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tress_core::film::FilmSettings;
use tress_core::integrator::{
    direct_light_sample, escaped_light, roulette, BuildError, FilmIntegrator,
};
use tress_core::math::Vec3;
use tress_core::prepare::Preparation;
use tress_core::{
    luminance, Hit, Integrator, IntegratorKind, Ray, Rgb, Sampler, Scene, ShadingPoint,
};
use tress_learned_light::{
    block_of, block_segments, check_ranges, BlockLearning, FilmKey, LastFilm, Lattice, OutOfRange,
    RadianceCache, Records as RadianceRecords,
};
use tress_path::{PathSettings, PathTracer};

/// Guided path tracer settings.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GuidedSettings {
    /// Samples per pixel of the first sample block, which is the path tracer's (nothing is
    /// learned yet); each block after it is twice as long as the one before.
    pub block_spp: u32,
    /// Training paths per pixel traced before each later block, as a fraction of the block's
    /// samples per pixel (at least one), until `training_spp` are reached.
    pub training_fraction: f32,
    /// Training paths per pixel in all; later blocks keep the last guide.
    pub training_spp: u32,
    /// The largest probability of sampling a continuation from the guide (the rest from the
    /// fiber's own sampling), in [0, 1); each cell's own is learned among eighths of it,
    /// unless `learn_probability` is off.
    pub guide_probability: f32,
    /// Whether each cell learns its probability of drawing from the guide; otherwise every
    /// cell uses `guide_probability`.
    pub learn_probability: bool,
    /// Vertices of a path, from the camera's, at which continuations use the guide; deeper
    /// ones use the fiber's own sampling. A mixture's weight f / density varies from sample to
    /// sample where the fiber's own is nearly constant, and along the long paths of light
    /// hair the products of those weights grow heavy tails (measured: a white furnace with
    /// every vertex guided averaged 0.60 at 8 spp and 0.64 at 32 although each weight
    /// averages 1), so only the first few vertices are guided.
    pub guided_vertices: u32,
    /// What the guide's density follows.
    pub target: Target,
    /// Cells along the longest side of the scene's bounds at the finest level, as a power of
    /// two (6: 64 cells).
    pub finest_cells_log2: u32,
    /// Levels of cells, each with half the cells per side of the one before.
    pub levels: u32,
    /// Records a cell must hold before its density guides.
    pub min_records: u32,
    /// Equal-height bands of the sphere's direction bins.
    pub z_bins: u32,
    /// Azimuthal sectors of the sphere's direction bins.
    pub phi_bins: u32,
    /// Russian roulette and splitting driven by the learned radiance (Vorba & Křivánek 2016):
    /// from the second vertex on, a path whose expected contribution — its throughput times
    /// the radiance the cache expects to leave the vertex toward it — is below the pixel's
    /// expected value is ended with the matching probability, one above it is split into up to
    /// eight, each reweighted so that the estimate stays unbiased. Otherwise the path tracer's
    /// roulette on the throughput alone.
    pub adjoint_roulette: bool,
    /// Scattering events of a path (training and rendering) before it ends.
    pub max_depth: u32,
    /// Bounces before Russian roulette starts.
    pub rr_depth: u32,
}

impl Default for GuidedSettings {
    fn default() -> Self {
        GuidedSettings {
            block_spp: 8,
            training_fraction: 0.0625,
            training_spp: 16,
            guide_probability: 0.5,
            learn_probability: true,
            guided_vertices: 2,
            target: Target::Radiance,
            finest_cells_log2: 6,
            levels: 6,
            min_records: 256,
            z_bins: 8,
            phi_bins: 16,
            adjoint_roulette: false,
            max_depth: 100,
            rr_depth: 5,
        }
    }
}

impl GuidedSettings {
    /// The path tracer of the same depth and roulette.
    fn path_tracer(&self) -> PathTracer {
        PathTracer::new(PathSettings {
            max_depth: self.max_depth,
            rr_depth: self.rr_depth,
        })
    }

    fn check(&self) -> Result<(), OutOfRange> {
        let s = self;
        check_ranges(
            GuidedPathTracer::NAME,
            &[
                (
                    "block_spp",
                    s.block_spp as f64,
                    (1..=4096).contains(&s.block_spp),
                    "must lie in 1..=4096",
                ),
                (
                    "training_fraction",
                    s.training_fraction as f64,
                    s.training_fraction > 0.0 && s.training_fraction <= 1.0,
                    "must lie in (0, 1]",
                ),
                (
                    "training_spp",
                    s.training_spp as f64,
                    s.training_spp <= 4096,
                    "must lie in 0..=4096",
                ),
                (
                    "guide_probability",
                    s.guide_probability as f64,
                    (0.0..1.0).contains(&s.guide_probability),
                    "must lie in [0, 1)",
                ),
                (
                    "finest_cells_log2",
                    s.finest_cells_log2 as f64,
                    (1..=12).contains(&s.finest_cells_log2),
                    "must lie in 1..=12",
                ),
                (
                    "levels",
                    s.levels as f64,
                    (1..=s.finest_cells_log2.saturating_add(1)).contains(&s.levels),
                    "must lie in 1..=finest_cells_log2 + 1",
                ),
                (
                    "z_bins",
                    s.z_bins as f64,
                    (1..=256).contains(&s.z_bins) && (1..=256).contains(&s.phi_bins),
                    "z_bins and phi_bins must lie in 1..=256",
                ),
                (
                    "min_records",
                    s.min_records as f64,
                    s.min_records >= 1,
                    "must be at least 1",
                ),
            ],
        )
    }

    /// Training paths per pixel traced before block `block` (≥ 1), when `traced` were before.
    fn training_before(&self, block: u32, traced: u64) -> u64 {
        let block_len = (self.block_spp as u64).saturating_mul(1u64 << block.min(40));
        let wanted = ((block_len as f64 * self.training_fraction as f64).round() as u64).max(1);
        wanted.min((self.training_spp as u64).saturating_sub(traced))
    }
}

/// The `guided` integrator as built for a scene: the guides of the film last rendered are
/// kept, so the waves and sample ranges of one image train them once.
#[derive(Debug)]
pub struct GuidedPathTracer {
    settings: GuidedSettings,
    trained: LastFilm<Trained>,
    unguided: PathTracer,
}

impl IntegratorKind for GuidedPathTracer {
    type Settings = GuidedSettings;
    const NAME: &'static str = "guided";
    const UNBIASED: bool = true;

    fn build(
        settings: &GuidedSettings,
        _: &Scene,
        _: &Preparation,
    ) -> Result<Box<dyn Integrator>, BuildError> {
        settings.check()?;
        Ok(Box::new(GuidedPathTracer {
            settings: settings.clone(),
            trained: LastFilm::default(),
            unguided: settings.path_tracer(),
        }))
    }

    /// Blocks of one sample (so that the tests' few samples are guided), one training path
    /// per pixel before each, few records per cell, the camera's vertex alone guided, and
    /// paths deep enough for white furnaces.
    fn test_settings() -> GuidedSettings {
        GuidedSettings {
            block_spp: 1,
            training_fraction: 0.25,
            training_spp: 4,
            guided_vertices: 1,
            min_records: 64,
            max_depth: 10_000,
            ..Default::default()
        }
    }
}

impl Integrator for GuidedPathTracer {
    /// Without a film there is no guide: the path tracer's.
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        self.unguided.li(ray, scene, sampler)
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

    /// One segment a sample block, so that a render holds one block's guide at a time.
    fn sample_segments(&self, samples: Range<u64>) -> Vec<Range<u64>> {
        block_segments(self.settings.block_spp, samples)
    }
}

/// The integrator with the guides of one film's sample blocks.
struct Trained {
    settings: GuidedSettings,
    /// The first block it renders.
    first_block: u32,
    /// What blocks `first_block..` are guided by (`None`: the path tracer's first block).
    guides: Vec<Option<Arc<Learned>>>,
    /// What renders the blocks that nothing guides.
    unguided: PathTracer,
    /// Where the training of later blocks goes on from; taken by that training.
    training: Mutex<Option<Training>>,
    /// How the guides were made, for logs.
    description: String,
}

/// The state of a film's training after some blocks.
struct Training {
    /// The last block trained for.
    block: u32,
    /// Training paths traced per pixel.
    traced: u64,
    /// Whether training has stopped (all paths traced, or no gain predicted).
    stopped: bool,
    records: Records,
    radiance_records: RadianceRecords,
    /// The last block's guide.
    learned: Option<Arc<Learned>>,
    /// Wall seconds of training so far.
    seconds: f64,
    /// The last guide's predicted gain (second moment of fiber sampling over the mixture's).
    gain: f64,
}

/// What training learned: the directions light comes from, and (for adjoint-driven roulette)
/// the radiance leaving each cell.
struct Learned {
    guide: Guide,
    radiance: Option<RadianceCache>,
    /// Whether any path is sampled differently from the path tracer's.
    guiding: bool,
}

impl std::fmt::Debug for Trained {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.description)
    }
}

impl Integrator for Trained {
    /// Traced with the guide of the sample's block.
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        self.li_sample(ray, scene, sampler, 0)
    }

    /// Where nothing was learned, or what was learned guides nowhere, the path tracer's own
    /// loop renders the sample, at its cost.
    fn li_sample(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler, sample_index: u64) -> Rgb {
        let block = block_of(self.settings.block_spp, sample_index);
        let learned = block
            .checked_sub(self.first_block)
            .and_then(|i| self.guides.get(i as usize))
            .and_then(|g| g.as_deref())
            .filter(|l| l.guiding);
        match learned {
            Some(l) => trace(&self.settings, Some(l), ray, scene, sampler, None),
            None => self.unguided.li(ray, scene, sampler),
        }
    }
}

/// Stream tag of the training paths' random numbers (apart from every pixel sample's).
const TRAINING_STREAM: u64 = 0x6775_6964_6564_0001;

/// Continuations kept per block's training to learn the cells' probabilities from (24 bytes
/// each): enough for a few hundred per cell, bounded whatever the film's size.
const CONTINUATION_BUDGET: u64 = 1 << 20;

/// The smallest predicted gain for which training goes on.
const MIN_GAIN: f64 = 1.1;

/// What a film's training paths are traced and recorded with.
struct Learning<'a> {
    settings: &'a GuidedSettings,
    scene: &'a Scene,
    film: FilmKey,
    lattice: Lattice,
    radiance_lattice: Lattice,
    bins: SphereBins,
}

impl<'a> Learning<'a> {
    fn new(settings: &'a GuidedSettings, scene: &'a Scene, film: FilmKey) -> Self {
        let lattice_with = |bins| {
            Lattice::new(
                scene.bounds(),
                settings.finest_cells_log2,
                settings.levels,
                bins,
            )
        };
        Learning {
            settings,
            scene,
            film,
            lattice: lattice_with(1),
            radiance_lattice: lattice_with(RADIANCE_DIRECTION_BINS),
            bins: SphereBins::new(settings.z_bins, settings.phi_bins),
        }
    }
}

impl Training {
    /// Traces `n` more training paths per pixel, guided by the last guide, adds their records,
    /// and builds the next guide from all the records so far (learning its cells'
    /// probabilities from these paths' continuations). `progress` gets the paths done; `None`
    /// when cancelled.
    fn train(
        &mut self,
        learning: &Learning,
        n: u64,
        cancel: &AtomicBool,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Option<()> {
        let Learning {
            settings,
            scene,
            film,
            ..
        } = *learning;
        let paths = self.traced * film.pixels()..(self.traced + n) * film.pixels();
        let current = self.learned.clone();
        let mut continuations = Vec::new();
        let stride = (paths.end - paths.start)
            .saturating_mul(settings.guided_vertices as u64)
            .div_ceil(CONTINUATION_BUDGET)
            .max(1);
        let mut seen = 0u64;
        tress_learned_light::train(
            scene,
            film,
            TRAINING_STREAM,
            paths,
            cancel,
            progress,
            |ray, sampler, chunk: &mut (ChunkRecords, RadianceRecords, Vec<Vertex>)| {
                let (records, radiance_records, vertices) = chunk;
                vertices.clear();
                trace(
                    settings,
                    current.as_deref(),
                    ray,
                    scene,
                    sampler,
                    Some(vertices),
                );
                let radiance_records = settings.adjoint_roulette.then_some(radiance_records);
                record(
                    settings,
                    (&learning.lattice, &learning.radiance_lattice),
                    &learning.bins,
                    vertices,
                    records,
                    radiance_records,
                );
            },
            |(chunk, radiance_chunk, _)| {
                self.records.merge(&chunk);
                self.radiance_records.merge(&radiance_chunk);
                // Every stride-th continuation, in path order: bounded memory.
                for c in &chunk.continuations {
                    if seen.is_multiple_of(stride) {
                        continuations.push(*c);
                    }
                    seen += 1;
                }
            },
        )?;
        self.traced += n;
        let mut guide = Guide::new(
            learning.lattice,
            &self.records,
            settings.min_records,
            settings.guide_probability,
        );
        if settings.learn_probability {
            self.gain = guide.learn_probabilities(&continuations, settings.guide_probability);
            self.stopped |= self.gain < MIN_GAIN;
        }
        // Training paths are neither rouletted nor split by the learned radiance, so only the
        // render needs it.
        let radiance = settings.adjoint_roulette.then(|| {
            RadianceCache::new(
                learning.radiance_lattice,
                &self.radiance_records,
                RADIANCE_MIN_RECORDS,
            )
        });
        let guiding = radiance.is_some() || guide.probabilities().0 > 0.0;
        self.learned = Some(Arc::new(Learned {
            guide,
            radiance,
            guiding,
        }));
        Some(())
    }
}

impl BlockLearning for Trained {
    type Settings = GuidedSettings;

    /// The guides of sample blocks `blocks`, going on from `before` (the training of earlier
    /// blocks of the same film) where it has trained for no block past the first of `blocks`;
    /// the records are the same sums of the same paths in the same order either way, so the
    /// guides are too. `None` when cancelled.
    fn train(
        settings: &GuidedSettings,
        scene: &Scene,
        film: FilmKey,
        blocks: Range<u32>,
        before: Option<Arc<Trained>>,
        cancel: &AtomicBool,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Option<Self> {
        let start = Instant::now();
        let learning = Learning::new(settings, scene, film);
        let went_on = before.and_then(|b| {
            let mut training = b.training.lock().unwrap_or_else(|e| e.into_inner());
            training.take_if(|t| t.block <= blocks.start)
        });
        let mut t = went_on.unwrap_or_else(|| Training {
            block: 0,
            traced: 0,
            stopped: settings.training_spp == 0,
            records: Records::new(learning.bins),
            radiance_records: RadianceRecords::default(),
            learned: None,
            seconds: 0.0,
            gain: 1.0,
        });
        let seconds_before = t.seconds;
        // Training paths per pixel of each block still to train for, unless training stops
        // on the way: the same sums of `training_before` the blocks will make.
        let mut planned = Vec::new();
        let mut traced = t.traced;
        for block in t.block + 1..blocks.end {
            let n = if t.stopped {
                0
            } else {
                settings.training_before(block, traced)
            };
            traced += n;
            planned.push(n);
        }
        let total = film.pixels() * planned.iter().sum::<u64>().max(1);
        let mut done = 0;
        let mut guides = Vec::new();
        let mut planned = planned.into_iter();
        for block in 0..blocks.end {
            if block > t.block {
                let n = planned.next().filter(|_| !t.stopped).unwrap_or(0);
                if n > 0 {
                    t.train(&learning, n, cancel, &|d| {
                        progress((done + d) as f64 / total as f64)
                    })?;
                    done += n * film.pixels();
                }
                t.stopped |= t.traced >= settings.training_spp as u64;
                t.block = block;
            }
            if block >= blocks.start {
                guides.push(t.learned.clone());
            }
        }
        t.seconds = seconds_before + start.elapsed().as_secs_f64();
        let description = match &t.learned {
            None => format!(
                "sample blocks {}..{}: the path tracer's (nothing learned yet)",
                blocks.start, blocks.end
            ),
            Some(l) => {
                let (share, mean) = l.guide.probabilities();
                let guided = if share > 0.0 {
                    format!(
                        "{:.0} % of cells guided with probability {mean:.2} on average",
                        share * 100.0
                    )
                } else {
                    "no cell guided (the path tracer's)".to_string()
                };
                format!(
                    "sample blocks {}..{}: {} ({:.1} MB){}; {} training paths a pixel so far, \
                     {guided}, predicted gain {:.2}{}; trained in {:.2} s",
                    blocks.start,
                    blocks.end,
                    l.guide.describe(),
                    l.guide.bytes() as f64 / 1e6,
                    l.radiance
                        .as_ref()
                        .map_or(String::new(), |r| format!(" and {}", r.describe())),
                    t.traced,
                    t.gain,
                    if t.stopped { ", training stopped" } else { "" },
                    t.seconds,
                )
            }
        };
        Some(Trained {
            settings: settings.clone(),
            first_block: blocks.start,
            guides,
            unguided: settings.path_tracer(),
            training: Mutex::new(Some(t)),
            description,
        })
    }

    /// Whether it has the guides of every block of `blocks`.
    fn covers(&self, blocks: &Range<u32>) -> bool {
        blocks.start >= self.first_block
            && blocks.end <= self.first_block + self.guides.len() as u32
    }

    fn description(&self) -> &str {
        &self.description
    }
}

/// Direction bins per side of the octahedral map of the radiance cache that drives roulette.
const RADIANCE_DIRECTION_BINS: u32 = 4;
/// Records a cell of that cache needs before roulette trusts it.
const RADIANCE_MIN_RECORDS: u32 = 16;

/// A vertex of a training path: what it saw by next-event estimation, where it continued,
/// and (filled in backwards once the path has ended) the radiance the rest of the path brought
/// back.
struct Vertex {
    p: Vec3,
    /// Toward the previous vertex.
    wo: Vec3,
    /// Next-event estimation's direction, and what it found there: the scattering value and
    /// the MIS-weighted incident radiance over the light sample's density.
    direct: Option<(Vec3, Rgb, Rgb)>,
    /// Where the path went on from here; `None` when it ended here.
    continuation: Option<Step>,
    /// The radiance arriving along the continuation, as the rest of the path estimated it.
    incident: Rgb,
}

/// A continuation: its direction, f·cos over the density it was drawn with, that density, and
/// the fiber's own density of the direction.
#[derive(Clone, Copy)]
struct Step {
    wi: Vec3,
    weight: Rgb,
    pdf: f32,
    fiber_pdf: f32,
}

/// Records a training path's vertices, from the last back: the light each continuation
/// brought back is the radiance leaving the vertex after it; the radiance leaving each vertex
/// toward the one before goes into `radiance_records`, when given. The continuations of
/// guided vertices are kept for learning the cells' probabilities.
fn record(
    settings: &GuidedSettings,
    (lattice, radiance_lattice): (&Lattice, &Lattice),
    bins: &SphereBins,
    vertices: &mut [Vertex],
    records: &mut ChunkRecords,
    mut radiance_records: Option<&mut RadianceRecords>,
) {
    let mut after = vertices.last().map_or(Rgb::ZERO, |v| v.incident);
    for (depth, v) in vertices.iter_mut().enumerate().rev() {
        v.incident = after;
        let mut leaving = Rgb::ZERO;
        if let Some((wi, f, li)) = v.direct {
            let value = match settings.target {
                Target::Radiance => luminance(li),
                Target::Contribution => luminance(f * li),
            };
            records.add(lattice, bins, v.p, wi, value);
            leaving += f * li;
        }
        if let Some(step) = v.continuation {
            let value = match settings.target {
                Target::Radiance => luminance(after) / step.pdf,
                Target::Contribution => luminance(step.weight * after),
            };
            records.add(lattice, bins, v.p, step.wi, value);
            if (depth as u32) < settings.guided_vertices {
                let estimate = luminance(step.weight * after);
                records.continuations.extend(Continuation::new(
                    lattice,
                    bins,
                    v.p,
                    step.wi,
                    estimate,
                    step.pdf,
                    step.fiber_pdf,
                ));
            }
            leaving += step.weight * after;
        }
        if let Some(r) = radiance_records.as_mut() {
            r.add(radiance_lattice, v.p, v.wo, leaving);
        }
        after = leaving;
    }
}

/// A path waiting to be shaded at its next vertex: a split's copies wait on a stack.
#[derive(Clone, Copy)]
struct PathState {
    ray: Ray,
    hit: Hit,
    throughput: Rgb,
    depth: u32,
}

/// Most copies a path is split into at one vertex.
const MAX_SPLIT: u32 = 8;
/// Least probability with which adjoint-driven roulette keeps a path: where the cache
/// underestimates, a path must still survive often enough not to be a firefly.
const MIN_SURVIVAL: f32 = 0.05;

/// The radiance along `camera_ray`: path tracing with next-event estimation, continuations
/// drawn from the mixture of the learned guide and the fibers' sampling. With `vertices`,
/// the path's vertices are recorded for training (the last one's `incident` holds the light
/// its continuation found on escaping); training paths are neither split nor rouletted by
/// the learned radiance.
fn trace(
    settings: &GuidedSettings,
    learned: Option<&Learned>,
    camera_ray: &Ray,
    scene: &Scene,
    sampler: &mut Sampler,
    mut vertices: Option<&mut Vec<Vertex>>,
) -> Rgb {
    let density_needed = scene.lights.weighs_escapes();
    let guide = learned.map(|l| &l.guide);
    let adjoint = learned
        .filter(|_| vertices.is_none())
        .and_then(|l| l.radiance.as_ref());
    let Some(hit) = scene.intersect(camera_ray) else {
        return scene
            .lights
            .infinite()
            .map(|light| escaped_light(light, camera_ray.dir, None, 1.0, Rgb::ONE))
            .sum();
    };
    // The pixel's expected value, as the cache sees the camera's vertex.
    let pixel = adjoint
        .and_then(|a| a.lookup(hit.p, -camera_ray.dir))
        .map(luminance)
        .filter(|&v| v > 0.0);
    let mut radiance = Rgb::ZERO;
    let mut next_path = Some(PathState {
        ray: *camera_ray,
        hit,
        throughput: Rgb::ONE,
        depth: 0,
    });
    // A split's copies wait here; empty (and never allocated) without splitting.
    let mut stack = Vec::new();
    while let Some(mut path) = next_path.take().or_else(|| stack.pop()) {
        loop {
            let PathState {
                ray, hit, depth, ..
            } = path;
            if depth >= settings.max_depth {
                break;
            }
            // Adjoint-driven roulette and splitting on arriving at the vertex; where the cache
            // knows nothing, the throughput's roulette after scattering instead.
            let mut adjoint_rouletted = false;
            if let (Some(cache), Some(pixel), true) = (adjoint, pixel, depth > 0) {
                if let Some(expected) = cache.lookup(hit.p, -ray.dir) {
                    adjoint_rouletted = true;
                    let ratio = luminance(path.throughput * expected) / pixel;
                    if ratio < 1.0 {
                        let survive = ratio.max(MIN_SURVIVAL);
                        if sampler.next_1d() >= survive {
                            break;
                        }
                        path.throughput /= survive;
                    } else {
                        let copies = (ratio.round() as u32).clamp(1, MAX_SPLIT);
                        path.throughput /= copies as f32;
                        for _ in 1..copies {
                            stack.push(path);
                        }
                    }
                }
            }
            let sp = ShadingPoint::new(&hit, &ray, &scene.materials);
            // Cells that learned not to guide are the path tracer's, at its cost.
            let mixture = guide
                .filter(|_| depth < settings.guided_vertices)
                .and_then(|g| {
                    let cell = g.find(hit.p).filter(|c| c.probability > 0.0)?;
                    Some(Mixture { guide: g, cell })
                });
            let density = |wi: Vec3, pdf: f32| match &mixture {
                Some(m) => m.pdf(wi, pdf),
                None => pdf,
            };

            let u_select = sampler.next_1d();
            let u_light = sampler.next_2d();
            let mut direct = None;
            if let Some((light, select_pdf)) = scene.lights.choose(u_select) {
                if let Some(d) =
                    direct_light_sample(scene, &sp, light, u_light, select_pdf, density)
                {
                    radiance += d.contribution(path.throughput);
                    direct = Some((d.wi, d.f, d.radiance * d.scale));
                }
            }

            let continuation = match &mixture {
                Some(m) => {
                    let u_mix = sampler.next_1d();
                    m.sample(&sp, u_mix, sampler.next_4d())
                }
                None => sp
                    .sample(sampler.next_4d())
                    .filter(|s| s.pdf > 0.0)
                    .map(|s| Step {
                        wi: s.wi,
                        weight: s.f / s.pdf,
                        pdf: s.pdf,
                        fiber_pdf: s.pdf,
                    }),
            }
            .filter(|s| s.weight != Rgb::ZERO && s.weight.is_finite());
            let mut vertex = Vertex {
                p: hit.p,
                wo: -ray.dir,
                direct,
                continuation: None,
                incident: Rgb::ZERO,
            };
            let Some(step) = continuation else {
                if let Some(v) = vertices.as_mut() {
                    v.push(vertex);
                }
                break;
            };
            path.throughput *= step.weight;
            let survive = if adjoint_rouletted {
                Some(1.0)
            } else {
                roulette(depth, settings.rr_depth, &mut path.throughput, sampler)
            };
            if let (true, Some(survive)) = (vertices.is_some(), survive) {
                vertex.continuation = Some(Step {
                    weight: step.weight / survive,
                    ..step
                });
            }
            if let Some(v) = vertices.as_mut() {
                v.push(vertex);
            }
            if survive.is_none() {
                break;
            }
            let next = sp.spawn(step.wi);
            let scatter_pdf = density_needed.then_some(step.pdf);
            let Some(next_hit) = scene.intersect(&next) else {
                let escaped: Rgb = scene
                    .lights
                    .infinite()
                    .map(|light| {
                        let select_pdf = scene.lights.select_pdf_of(light);
                        escaped_light(light, next.dir, scatter_pdf, select_pdf, Rgb::ONE)
                    })
                    .sum();
                radiance += path.throughput * escaped;
                if let Some(last) = vertices.as_mut().and_then(|v| v.last_mut()) {
                    last.incident = escaped;
                }
                break;
            };
            path = PathState {
                ray: next,
                hit: next_hit,
                throughput: path.throughput,
                depth: depth + 1,
            };
        }
    }
    radiance
}

/// The mixture a continuation is drawn from at one vertex: the guide's density of the vertex's
/// cell, with the cell's probability, and the shading point's own.
struct Mixture<'a> {
    guide: &'a Guide,
    cell: &'a GuideCell,
}

impl Mixture<'_> {
    /// The mixture's density at `wi`, where the shading point's own is `pdf`.
    fn pdf(&self, wi: Vec3, pdf: f32) -> f32 {
        let a = self.cell.probability;
        a * self.guide.pdf(self.cell, wi) + (1.0 - a) * pdf
    }

    /// A direction from the mixture.
    fn sample(&self, sp: &ShadingPoint, u_mix: f32, u: [f32; 4]) -> Option<Step> {
        let a = self.cell.probability;
        let (wi, f, pdf, fiber_pdf) = if u_mix < a {
            let (wi, guide_pdf) = self.guide.sample(self.cell, [u[0], u[1], u[2]]);
            let (f, own_pdf) = sp.eval_pdf(wi);
            (wi, f, a * guide_pdf + (1.0 - a) * own_pdf, own_pdf)
        } else {
            let s = sp.sample(u)?;
            (s.wi, s.f, self.pdf(s.wi, s.pdf), s.pdf)
        };
        (pdf > 0.0).then(|| Step {
            wi,
            weight: f / pdf,
            pdf,
            fiber_pdf,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_bound_is_the_one_stated() {
        for finest_cells_log2 in [1, 6, 12] {
            let with = |levels| GuidedSettings {
                finest_cells_log2,
                levels,
                ..GuidedSettings::default()
            };
            assert!(with(finest_cells_log2 + 1).check().is_ok());
            let e = with(finest_cells_log2 + 2).check().unwrap_err();
            assert_eq!(e.field, "levels");
            assert_eq!(e.why, "must lie in 1..=finest_cells_log2 + 1");
        }
        // An out-of-range finest_cells_log2 is named, not an overflow.
        let e = GuidedSettings {
            finest_cells_log2: u32::MAX,
            ..GuidedSettings::default()
        }
        .check()
        .unwrap_err();
        assert_eq!(e.field, "finest_cells_log2");
    }

    #[test]
    fn training_grows_with_the_blocks_until_its_total() {
        let s = GuidedSettings::default();
        // block_spp 8, a sixteenth: blocks of 16, 32, 64, 128, 256 samples train 1, 2, 4, 8
        // paths a pixel, then what is left of the 16.
        let mut traced = 0;
        let per_block: Vec<u64> = (1..=6)
            .map(|b| {
                let n = s.training_before(b, traced);
                traced += n;
                n
            })
            .collect();
        assert_eq!(per_block, vec![1, 2, 4, 8, 1, 0]);
        // Huge block numbers neither overflow nor exceed the total.
        assert_eq!(s.training_before(u32::MAX, 0), 16);
    }
}
