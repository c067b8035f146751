//! Path tracing guided by the light learned from the film's own training paths.
//!
//! Before the first sample of a film, `training_rounds` rounds of training paths through the
//! film's pixels (`training_spp` per pixel in the last round, half as many in each round before)
//! record, at every vertex, the light that arrived along the direction the path continued in
//! and along the direction next-event estimation looked in, each divided by the density it was
//! drawn with ([`guide`]). Each round's paths are guided by what the rounds before learned.
//! The render then samples each continuation from a mixture: with probability
//! `guide_probability` from the learned density of the cell around the vertex, otherwise from
//! the fiber's own sampling routine. The sample's weight is f over the mixture's exact density
//! (the fiber's density at a guided direction comes from its `pdf`, the guide's at a
//! fiber-sampled direction from its bins), and next-event estimation is MIS-weighted against
//! the same mixture, so the estimator is unbiased whatever was learned. Only the first
//! `guided_vertices` vertices are guided: a mixture's weights vary where the fiber's own are
//! nearly constant, and along light hair's long paths their products grow heavy tails.
//!
//! A fiber has no normal and scatters into the whole sphere, so the guide is a density over the
//! whole sphere too, in world space, and is mixed with the fiber's density rather than
//! multiplied by it: the fiber's sampling keeps the specular cone and the forward lobe, the
//! guide adds the directions that the light inside the hair comes from.
//!
//! Optionally (`adjoint_roulette`), Russian roulette and splitting are driven by the radiance
//! the training paths saw leave each cell (Vorba & Křivánek 2016).
//!
//! docs/src/research/radiance-cache.md measures it: unbiased, but not yet faster than the path
//! tracer on hair.
//!
//! RON: `Guided(training_spp: 4, training_rounds: 3, guide_probability: 0.5)`

#![warn(missing_docs)]

mod guide;

pub use guide::Target;
use guide::{ChunkRecords, Guide, Records, SphereBins};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::atomic::AtomicBool;
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
    check_ranges, FilmKey, LastFilm, Lattice, OutOfRange, RadianceCache, Records as RadianceRecords,
};

/// Guided path tracer settings.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GuidedSettings {
    /// Training paths per pixel of the whole film in the last training round; each round
    /// before traces half as many.
    pub training_spp: u32,
    /// Training rounds, each guided by the ones before.
    pub training_rounds: u32,
    /// Probability of sampling a continuation from the guide where a cell has one (the rest
    /// from the fiber's own sampling), in [0, 1).
    pub guide_probability: f32,
    /// Vertices of a path, from the camera's, at which continuations use the guide; deeper
    /// ones use the fiber's own sampling. A mixture's weight f / density varies from sample to
    /// sample where the fiber's own is nearly constant, and along the long paths of light
    /// hair the products of those weights grow heavy tails (measured: a white furnace with
    /// every vertex guided averaged 0.60 at 8 spp and 0.64 at 32 although each weight
    /// averages 1), so only the first few vertices are guided.
    pub guided_vertices: u32,
    /// What the guide's density follows.
    pub target: Target,
    /// How continuations use the guide.
    pub sampling: Sampling,
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
            training_spp: 4,
            training_rounds: 3,
            guide_probability: 0.5,
            guided_vertices: 2,
            target: Target::Radiance,
            sampling: Sampling::Mixture,
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

/// How a continuation uses the guide.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum Sampling {
    /// With probability `guide_probability` a direction from the guide, otherwise from the
    /// fiber; weighted by the mixture's exact density, which next-event estimation is
    /// MIS-weighted against.
    Mixture,
    /// Resampled importance sampling: `candidates` directions from the fiber's own sampling,
    /// one kept with probability proportional to its weight times the guide's density there;
    /// the kept direction's weight is the fiber's times the candidates' mean over the
    /// guide's density. It has no density, so lights that next-event estimation samples are
    /// left to it alone (escaping continuations do not count them).
    Resampled {
        /// Candidates drawn per continuation.
        candidates: u32,
    },
}

impl GuidedSettings {
    fn check(&self) -> Result<(), OutOfRange> {
        let s = self;
        let candidates = match s.sampling {
            Sampling::Resampled { candidates } => candidates,
            Sampling::Mixture => 1,
        };
        check_ranges(
            GuidedPathTracer::NAME,
            &[
                (
                    "candidates",
                    candidates as f64,
                    (1..=64).contains(&candidates),
                    "must lie in 1..=64",
                ),
                (
                    "training_spp",
                    s.training_spp as f64,
                    (1..=4096).contains(&s.training_spp),
                    "must lie in 1..=4096",
                ),
                (
                    "training_rounds",
                    s.training_rounds as f64,
                    (1..=12).contains(&s.training_rounds),
                    "must lie in 1..=12",
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
}

/// The `guided` integrator as built for a scene: the guide of the film last rendered is kept,
/// so the waves and sample ranges of one image train it once.
#[derive(Debug)]
pub struct GuidedPathTracer {
    settings: GuidedSettings,
    trained: LastFilm<Trained>,
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
        }))
    }

    /// Two short training rounds, few records per cell, the camera's vertex alone guided,
    /// and paths deep enough for white furnaces.
    fn test_settings() -> GuidedSettings {
        GuidedSettings {
            guided_vertices: 1,
            training_spp: 2,
            training_rounds: 2,
            min_records: 64,
            max_depth: 10_000,
            ..Default::default()
        }
    }
}

impl Integrator for GuidedPathTracer {
    /// Without a film there is no guide: the fiber's own sampling alone.
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        trace(&self.settings, None, ray, scene, sampler, None)
    }

    fn for_film(
        &self,
        scene: &Scene,
        film: &FilmSettings,
        _: Range<u64>,
        cancel: &AtomicBool,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Option<FilmIntegrator> {
        let key = FilmKey::of(film);
        let t = self.trained.get_or_train(
            key,
            |_| true,
            |_| Trained::new(&self.settings, scene, key, cancel, progress),
        )?;
        Some(FilmIntegrator {
            note: t.description.clone(),
            integrator: t,
        })
    }
}

/// The integrator with its guide for one film.
struct Trained {
    settings: GuidedSettings,
    learned: Learned,
    description: String,
}

/// What training learned: the directions light comes from, and (for adjoint-driven roulette)
/// the radiance leaving each cell.
struct Learned {
    guide: Guide,
    radiance: Option<RadianceCache>,
}

impl std::fmt::Debug for Trained {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.description)
    }
}

impl Integrator for Trained {
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        trace(
            &self.settings,
            Some(&self.learned),
            ray,
            scene,
            sampler,
            None,
        )
    }
}

/// Stream tag of the training paths' random numbers (apart from every pixel sample's).
const TRAINING_STREAM: u64 = 0x6775_6964_6564_0001;

impl Trained {
    fn new(
        settings: &GuidedSettings,
        scene: &Scene,
        film: FilmKey,
        cancel: &AtomicBool,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Option<Self> {
        let start = Instant::now();
        let lattice = Lattice::new(
            scene.bounds(),
            settings.finest_cells_log2,
            settings.levels,
            1,
        );
        let bins = SphereBins::new(settings.z_bins, settings.phi_bins);
        let radiance_lattice = Lattice::new(
            scene.bounds(),
            settings.finest_cells_log2,
            settings.levels,
            RADIANCE_DIRECTION_BINS,
        );
        let rounds = settings.training_rounds;
        // Paths per pixel of each round: the last `training_spp`, each before it half.
        let spp: Vec<u64> = (0..rounds)
            .map(|r| (settings.training_spp as u64 >> (rounds - 1 - r)).max(1))
            .collect();
        let total = film.pixels() * spp.iter().sum::<u64>();
        let mut records = Records::new(bins);
        let mut radiance_records = RadianceRecords::default();
        let mut learned: Option<Learned> = None;
        let mut first = 0;
        for round_spp in spp {
            let paths = first..first + film.pixels() * round_spp;
            let current = learned.as_ref();
            tress_learned_light::train(
                scene,
                film,
                TRAINING_STREAM,
                paths.clone(),
                cancel,
                &|done| progress((first + done) as f64 / total as f64),
                |ray, sampler, chunk: &mut (ChunkRecords, RadianceRecords, Vec<Vertex>)| {
                    let (records, radiance_records, vertices) = chunk;
                    vertices.clear();
                    trace(settings, current, ray, scene, sampler, Some(vertices));
                    let lattices = (&lattice, &radiance_lattice);
                    let radiance_records = settings.adjoint_roulette.then_some(radiance_records);
                    record(
                        settings.target,
                        lattices,
                        &bins,
                        vertices,
                        records,
                        radiance_records,
                    );
                },
                |(chunk, radiance_chunk, _)| {
                    records.merge(&chunk);
                    radiance_records.merge(&radiance_chunk);
                },
            )?;
            // Training paths are neither rouletted nor split by the learned radiance, so only
            // the render needs it.
            learned = Some(Learned {
                guide: Guide::new(lattice, &records, settings.min_records),
                radiance: None,
            });
            first = paths.end;
        }
        let mut learned = learned.expect("at least one training round");
        if settings.adjoint_roulette {
            learned.radiance = Some(RadianceCache::new(
                radiance_lattice,
                &radiance_records,
                RADIANCE_MIN_RECORDS,
            ));
        }
        let description = format!(
            "{} ({:.1} MB){}, from {total} training paths in {rounds} rounds, built in {:.2} s",
            learned.guide.describe(),
            learned.guide.bytes() as f64 / 1e6,
            learned
                .radiance
                .as_ref()
                .map_or(String::new(), |r| format!(" and {}", r.describe())),
            start.elapsed().as_secs_f64()
        );
        Some(Trained {
            settings: settings.clone(),
            learned,
            description,
        })
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
    /// The continuation's direction, f·cos over its density, and that density; `None` when
    /// the path ended here.
    continuation: Option<(Vec3, Rgb, f32)>,
    /// The radiance arriving along the continuation, as the rest of the path estimated it.
    incident: Rgb,
}

/// Records a training path's vertices, from the last back: the light each continuation
/// brought back is the radiance leaving the vertex after it; the radiance leaving each vertex
/// toward the one before goes into `radiance_records`, when given.
fn record(
    target: Target,
    (lattice, radiance_lattice): (&Lattice, &Lattice),
    bins: &SphereBins,
    vertices: &mut [Vertex],
    records: &mut ChunkRecords,
    mut radiance_records: Option<&mut RadianceRecords>,
) {
    let mut after = vertices.last().map_or(Rgb::ZERO, |v| v.incident);
    for v in vertices.iter_mut().rev() {
        v.incident = after;
        let mut leaving = Rgb::ZERO;
        if let Some((wi, f, li)) = v.direct {
            let value = match target {
                Target::Radiance => luminance(li),
                Target::Contribution => luminance(f * li),
            };
            records.add(lattice, bins, v.p, wi, value);
            leaving += f * li;
        }
        if let Some((wi, weight, pdf)) = v.continuation {
            let value = match target {
                Target::Radiance => luminance(after) / pdf,
                Target::Contribution => luminance(weight * after),
            };
            records.add(lattice, bins, v.p, wi, value);
            leaving += weight * after;
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
    let resampled = match settings.sampling {
        Sampling::Resampled { candidates } => Some(candidates),
        Sampling::Mixture => None,
    };
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
    let mut stack = vec![PathState {
        ray: *camera_ray,
        hit,
        throughput: Rgb::ONE,
        depth: 0,
    }];
    while let Some(mut path) = stack.pop() {
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
            let mixture = guide
                .filter(|_| depth < settings.guided_vertices)
                .and_then(|g| {
                    let cdf = g.find(hit.p)?;
                    Some(Mixture {
                        guide: g,
                        cdf,
                        probability: settings.guide_probability,
                    })
                });
            let resampling = mixture.is_some() && resampled.is_some();
            // With resampling, next-event estimation alone counts the lights it samples.
            let density = |wi: Vec3, pdf: f32| match &mixture {
                Some(_) if resampling => 0.0,
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

            let continuation = match (&mixture, resampled) {
                (Some(m), Some(candidates)) => m.resample(&sp, candidates, sampler),
                (Some(m), None) => {
                    let u_mix = sampler.next_1d();
                    m.sample(&sp, u_mix, sampler.next_4d())
                }
                (None, _) => sp
                    .sample(sampler.next_4d())
                    .filter(|s| s.pdf > 0.0)
                    .map(|s| (s.wi, s.f / s.pdf, s.pdf)),
            }
            .filter(|(_, weight, _)| *weight != Rgb::ZERO && weight.is_finite());
            let mut vertex = Vertex {
                p: hit.p,
                wo: -ray.dir,
                direct,
                continuation: None,
                incident: Rgb::ZERO,
            };
            let Some((wi, weight, pdf)) = continuation else {
                if let Some(v) = vertices.as_mut() {
                    v.push(vertex);
                }
                break;
            };
            path.throughput *= weight;
            let survive = if adjoint_rouletted {
                Some(1.0)
            } else {
                roulette(depth, settings.rr_depth, &mut path.throughput, sampler)
            };
            if let (true, Some(survive)) = (vertices.is_some(), survive) {
                vertex.continuation = Some((wi, weight / survive, pdf));
            }
            if let Some(v) = vertices.as_mut() {
                v.push(vertex);
            }
            if survive.is_none() {
                break;
            }
            let next = sp.spawn(wi);
            let scatter_pdf = density_needed.then_some(pdf);
            let Some(next_hit) = scene.intersect(&next) else {
                let mut escaped = Rgb::ZERO;
                for light in scene.lights.infinite() {
                    let select_pdf = scene.lights.select_pdf_of(light);
                    escaped += match scatter_pdf {
                        // Next-event estimation alone counts the lights it samples.
                        Some(_) if resampling && select_pdf > 0.0 => Rgb::ZERO,
                        Some(_) if resampling => {
                            escaped_light(light, next.dir, Some(1.0), 0.0, Rgb::ONE)
                        }
                        _ => escaped_light(light, next.dir, scatter_pdf, select_pdf, Rgb::ONE),
                    };
                }
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
/// cell and the shading point's own.
struct Mixture<'a> {
    guide: &'a Guide,
    cdf: &'a [f32],
    probability: f32,
}

impl Mixture<'_> {
    /// The mixture's density at `wi`, where the shading point's own is `pdf`.
    fn pdf(&self, wi: Vec3, pdf: f32) -> f32 {
        self.probability * self.guide.pdf(self.cdf, wi) + (1.0 - self.probability) * pdf
    }

    /// A direction from the mixture: its f·cos over the mixture's density, and that density.
    fn sample(&self, sp: &ShadingPoint, u_mix: f32, u: [f32; 4]) -> Option<(Vec3, Rgb, f32)> {
        let (wi, f, pdf) = if u_mix < self.probability {
            let (wi, guide_pdf) = self.guide.sample(self.cdf, [u[0], u[1], u[2]]);
            let (f, own_pdf) = sp.eval_pdf(wi);
            (
                wi,
                f,
                self.probability * guide_pdf + (1.0 - self.probability) * own_pdf,
            )
        } else {
            let s = sp.sample(u)?;
            (s.wi, s.f, self.pdf(s.wi, s.pdf))
        };
        (pdf > 0.0).then(|| (wi, f / pdf, pdf))
    }

    /// Resampled importance sampling with the fiber's sampling as the source and its weight
    /// times the guide's density as the target: the kept direction, its weight (the fiber's
    /// f·cos over the target, times the candidates' mean target-to-source ratio) and the
    /// density resampling approximately drew it with (for training records only).
    fn resample(
        &self,
        sp: &ShadingPoint,
        candidates: u32,
        sampler: &mut Sampler,
    ) -> Option<(Vec3, Rgb, f32)> {
        let mut sum = 0.0f32;
        let mut kept: Option<(Vec3, Rgb, f32, f32)> = None;
        for _ in 0..candidates {
            let u = sampler.next_4d();
            let u_keep = sampler.next_1d();
            let Some(s) = sp.sample(u).filter(|s| s.pdf > 0.0) else {
                continue;
            };
            let weight = s.f / s.pdf;
            let ratio = luminance(weight) * self.guide.pdf(self.cdf, s.wi);
            if !(ratio > 0.0 && ratio.is_finite()) {
                continue;
            }
            sum += ratio;
            if u_keep * sum < ratio {
                kept = Some((s.wi, weight, ratio, s.pdf));
            }
        }
        let (wi, weight, ratio, pdf) = kept?;
        let mean = sum / candidates as f32;
        // f / target = weight / ratio (the fiber's density cancels), times the mean ratio;
        // resampling drew `wi` with about the target over the mean ratio as its density.
        let scale = mean / ratio;
        Some((wi, weight * scale, pdf / scale))
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
}
