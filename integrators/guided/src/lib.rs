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
//! the same mixture, so the estimator is unbiased whatever was learned.
//!
//! A fiber has no normal and scatters into the whole sphere, so the guide is a density over the
//! whole sphere too, in world space, and is mixed with the fiber's density rather than
//! multiplied by it: the fiber's sampling keeps the specular cone and the forward lobe, the
//! guide adds the directions that the light inside the hair comes from.
//!
//! RON: `Guided(training_spp: 4, training_rounds: 3, guide_probability: 0.5)`

#![warn(missing_docs)]

mod guide;

pub use guide::Target;
use guide::{ChunkRecords, Guide, Records, SphereBins};

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
use tress_core::{luminance, Integrator, IntegratorKind, Ray, Rgb, Sampler, Scene, ShadingPoint};
use tress_learned_light::{FilmKey, Lattice};

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

/// Settings that cannot describe a guide.
#[derive(Debug, thiserror::Error)]
pub enum GuidedSettingsError {
    /// A value outside its range.
    #[error("guided settings: {field} = {value}: {why}")]
    OutOfRange {
        /// The setting.
        field: &'static str,
        /// Its value.
        value: f64,
        /// The range it must lie in.
        why: &'static str,
    },
}

impl GuidedSettings {
    fn check(&self) -> Result<(), GuidedSettingsError> {
        let s = self;
        let candidates = match s.sampling {
            Sampling::Resampled { candidates } => candidates,
            Sampling::Mixture => 1,
        };
        let checks: [(&'static str, f64, bool, &'static str); 8] = [
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
                (1..=s.finest_cells_log2.min(12) + 1).contains(&s.levels),
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
        ];
        for (field, value, ok, why) in checks {
            if !ok {
                return Err(GuidedSettingsError::OutOfRange { field, value, why });
            }
        }
        Ok(())
    }
}

/// The `guided` integrator as built for a scene: the guide of the film last rendered is kept,
/// so the waves and sample ranges of one image train it once.
#[derive(Debug)]
pub struct GuidedPathTracer {
    settings: GuidedSettings,
    trained: Mutex<Option<(FilmKey, Arc<Trained>)>>,
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
            trained: Mutex::new(None),
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
        let mut trained = self.trained.lock().unwrap_or_else(|e| e.into_inner());
        let t = match trained.as_ref() {
            Some((k, t)) if *k == key => t.clone(),
            _ => {
                let t = Arc::new(Trained::new(&self.settings, scene, key, cancel, progress)?);
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

/// The integrator with its guide for one film.
struct Trained {
    settings: GuidedSettings,
    guide: Guide,
    description: String,
}

impl std::fmt::Debug for Trained {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.description)
    }
}

impl Integrator for Trained {
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        trace(&self.settings, Some(&self.guide), ray, scene, sampler, None)
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
        let rounds = settings.training_rounds;
        // Paths per pixel of each round: the last `training_spp`, each before it half.
        let spp: Vec<u64> = (0..rounds)
            .map(|r| (settings.training_spp as u64 >> (rounds - 1 - r)).max(1))
            .collect();
        let total = film.pixels() * spp.iter().sum::<u64>();
        let mut records = Records::new(bins);
        let mut guide: Option<Guide> = None;
        let mut first = 0;
        for round_spp in spp {
            let paths = first..first + film.pixels() * round_spp;
            let current = guide.as_ref();
            tress_learned_light::train(
                scene,
                film,
                TRAINING_STREAM,
                paths.clone(),
                cancel,
                &|done| progress((first + done) as f64 / total as f64),
                |ray, sampler, chunk: &mut (ChunkRecords, Vec<Vertex>)| {
                    let (records, vertices) = chunk;
                    vertices.clear();
                    trace(settings, current, ray, scene, sampler, Some(vertices));
                    record(settings.target, &lattice, &bins, vertices, records);
                },
                |(chunk, _)| records.merge(&chunk),
            )?;
            guide = Some(Guide::new(lattice, &records, settings.min_records));
            first = paths.end;
        }
        let guide = guide.expect("at least one training round");
        let description = format!(
            "{} ({:.1} MB) from {total} training paths in {rounds} rounds, built in {:.2} s",
            guide.describe(),
            guide.bytes() as f64 / 1e6,
            start.elapsed().as_secs_f64()
        );
        Some(Trained {
            settings: settings.clone(),
            guide,
            description,
        })
    }
}

/// A vertex of a training path: what it saw by next-event estimation, where it continued,
/// and (filled in backwards once the path has ended) the radiance the rest of the path brought
/// back.
struct Vertex {
    p: Vec3,
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
/// brought back is the radiance leaving the vertex after it.
fn record(
    target: Target,
    lattice: &Lattice,
    bins: &SphereBins,
    vertices: &mut [Vertex],
    records: &mut ChunkRecords,
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
        after = leaving;
    }
}

/// The radiance along `camera_ray`: path tracing with next-event estimation, continuations
/// drawn from the mixture of `guide` and the fibers' sampling. With `vertices`, the path's
/// vertices are recorded for training (the last one's `incident` holds the light its
/// continuation found on escaping).
fn trace(
    settings: &GuidedSettings,
    guide: Option<&Guide>,
    camera_ray: &Ray,
    scene: &Scene,
    sampler: &mut Sampler,
    mut vertices: Option<&mut Vec<Vertex>>,
) -> Rgb {
    let mut radiance = Rgb::ZERO;
    let mut throughput = Rgb::ONE;
    let mut ray = *camera_ray;
    let mut scatter_pdf: Option<f32> = None;
    let density_needed = scene.lights.weighs_escapes();
    // Whether the ray being traced is a continuation chosen by resampling.
    let mut resampled_continuation = false;
    for depth in 0.. {
        let Some(hit) = scene.intersect(&ray) else {
            let mut escaped = Rgb::ZERO;
            for light in scene.lights.infinite() {
                let select_pdf = scene.lights.select_pdf_of(light);
                escaped += match (scatter_pdf, resampled_continuation) {
                    // Next-event estimation alone counts the lights it samples.
                    (Some(_), true) if select_pdf > 0.0 => Rgb::ZERO,
                    (Some(_), true) => escaped_light(light, ray.dir, Some(1.0), 0.0, Rgb::ONE),
                    _ => escaped_light(light, ray.dir, scatter_pdf, select_pdf, Rgb::ONE),
                };
            }
            radiance += throughput * escaped;
            if let Some(last) = vertices.as_mut().and_then(|v| v.last_mut()) {
                last.incident = escaped;
            }
            break;
        };
        if depth >= settings.max_depth {
            break;
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
        let resampled = match settings.sampling {
            Sampling::Resampled { candidates } => Some(candidates),
            Sampling::Mixture => None,
        };
        // With resampling, next-event estimation alone counts the lights it samples.
        let density = |wi: Vec3, pdf: f32| match (&mixture, resampled) {
            (Some(_), Some(_)) => 0.0,
            (Some(m), None) => m.pdf(wi, pdf),
            (None, _) => pdf,
        };

        let u_select = sampler.next_1d();
        let u_light = sampler.next_2d();
        let mut direct = None;
        if let Some((light, select_pdf)) = scene.lights.choose(u_select) {
            if let Some(d) = direct_light_sample(scene, &sp, light, u_light, select_pdf, density) {
                radiance += d.contribution(throughput);
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
        throughput *= weight;
        let survive = roulette(depth, settings.rr_depth, &mut throughput, sampler);
        if let (true, Some(survive)) = (vertices.is_some(), survive) {
            vertex.continuation = Some((wi, weight / survive, pdf));
        }
        if let Some(v) = vertices.as_mut() {
            v.push(vertex);
        }
        if survive.is_none() {
            break;
        }
        scatter_pdf = density_needed.then_some(pdf);
        resampled_continuation = mixture.is_some() && resampled.is_some();
        ray = sp.spawn(wi);
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
