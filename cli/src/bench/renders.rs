//! The integrators' renders: counted and recorded queries, timing, replays and their report.

use super::plan::{strand_label, thin_label, Plan, CHUNK};
use super::raw::{Accels, Kind, Mode, RawRates};
use super::table::{cost_note, target, Table};
use rayon::prelude::*;
use rayon::ThreadPool;
use std::cell::{Cell, RefCell};
use std::fmt::Write as _;
use std::hint::black_box;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use tress_accel::raw::{Exclusion, RawRay};
use tress_accel::EmbreeAccel;
use tress_core::accel::HairCurves;
use tress_core::film::FilmSettings;
use tress_core::math::{Aabb, Ray};
use tress_core::{Accel, Hit, Integrator, Scene};
use tress_loader::integrators::IntegratorDesc;
use tress_study::cost::{timed, Cost};

/// Query kinds counted and recorded by [`CountingAccel`].
pub(super) const CAMERA: usize = 0;
pub(super) const BOUNCE: usize = 1;
pub(super) const SHADOW: usize = 2;

thread_local! {
    /// Queries on this thread, by kind.
    static QUERIES: Cell<[u64; 3]> = const { Cell::new([0; 3]) };
    /// Rays traced on this thread while recording, with their kind.
    static RECORDED: RefCell<Vec<(usize, Ray)>> = const { RefCell::new(Vec::new()) };
}

/// The accelerator with its queries counted by kind, and recorded on demand: closest-hit
/// queries leaving no primitive are camera rays (the bench scenes hold only hair, so every
/// other ray leaves one).
pub(super) struct CountingAccel {
    pub(super) inner: Arc<EmbreeAccel>,
    pub(super) record: Arc<AtomicBool>,
}

impl CountingAccel {
    pub(super) fn note(&self, kind: usize, ray: &Ray) {
        QUERIES.with(|q| {
            let mut v = q.get();
            v[kind] += 1;
            q.set(v);
        });
        if self.record.load(Ordering::Relaxed) {
            RECORDED.with(|r| r.borrow_mut().push((kind, *ray)));
        }
    }
}

impl Accel for CountingAccel {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.note(
            if ray.exclude.is_none() {
                CAMERA
            } else {
                BOUNCE
            },
            ray,
        );
        self.inner.intersect(ray)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.note(SHADOW, ray);
        self.inner.occluded(ray)
    }

    fn occluded_by_surfaces(&self, ray: &Ray) -> bool {
        self.inner.occluded_by_surfaces(ray)
    }

    /// None in the bench scenes (hair only), so the scene never asks for surface-only queries.
    fn has_surfaces(&self) -> bool {
        self.inner.has_surfaces()
    }

    fn bounds(&self) -> Aabb {
        self.inner.bounds()
    }

    fn hair_curves(&self) -> Vec<(u32, Arc<dyn HairCurves>)> {
        self.inner.hair_curves()
    }
}

/// Queries counted on every thread of `pool`.
pub(super) fn queries(pool: &ThreadPool) -> [u64; 3] {
    pool.broadcast(|_| QUERIES.with(Cell::get))
        .into_iter()
        .fold([0; 3], |a, b| std::array::from_fn(|i| a[i] + b[i]))
}

/// Seconds per sample and per traced ray of one render.
pub(super) struct Timing {
    pub(super) model: String,
    pub(super) integrator: &'static str,
    pub(super) threads: usize,
    pub(super) per_sample: f64,
    pub(super) per_ray: f64,
    pub(super) cpu_per_sample: Option<f64>,
    pub(super) waiting: Option<f64>,
}

pub(super) struct RenderRun {
    pub(super) cost: Cost,
    pub(super) samples: u64,
    /// Camera, bounce, shadow rays traced.
    pub(super) traced: [u64; 3],
}

pub(super) fn render(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    pool: &ThreadPool,
) -> RenderRun {
    let before = queries(pool);
    let (out, cost) =
        timed(|| pool.install(|| tress_core::render::render(scene, integrator, film, &|_| {})));
    let after = queries(pool);
    let d: [u64; 3] = std::array::from_fn(|i| after[i] - before[i]);
    RenderRun {
        cost,
        samples: out.stats.samples,
        traced: [d[CAMERA], d[BOUNCE], d[SHADOW]],
    }
}

/// Renders once, recording every ray traced (in each thread's order).
pub(super) fn record_rays(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    pool: &ThreadPool,
    recording: &AtomicBool,
) -> Vec<(usize, Ray)> {
    let take = || {
        pool.broadcast(|_| RECORDED.with(|r| std::mem::take(&mut *r.borrow_mut())))
            .concat()
    };
    take();
    recording.store(true, Ordering::Relaxed);
    pool.install(|| tress_core::render::render(scene, integrator, film, &|_| {}));
    recording.store(false, Ordering::Relaxed);
    take()
}

/// How recorded rays are traced again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ReplayMode {
    /// As in the raw measurements.
    Raw(Mode),
    /// Embree alone (the twin without filter support), each ray leaving a fiber started where
    /// it leaves that fiber ([`tress_accel::EmbreeAccel::fiber_exit`], computed before the
    /// timing): Embree finding the hits the rule keeps, without the callbacks. [`Mode::Plain`]
    /// instead lets such rays stop at the fiber they leave, which is no answer a renderer can
    /// use and a cheaper query.
    PlainPastFiber,
}

impl ReplayMode {
    pub(super) fn name(self) -> &'static str {
        match self {
            ReplayMode::Raw(mode) => mode.name(),
            ReplayMode::PlainPastFiber => "plain-past-fiber",
        }
    }
}

/// A replay of an integrator's recorded rays: rays/s and the cost, per mode.
pub(super) struct Replay {
    pub(super) mode: ReplayMode,
    pub(super) rays: usize,
    pub(super) rate: f64,
    pub(super) cost: Cost,
}

/// Traces the recorded rays again, raw, in chunks of the recorded order.
pub(super) fn replay(
    accels: &Accels,
    rays: &[(usize, Ray)],
    pool: &ThreadPool,
    integrator: &str,
    runs: usize,
) -> Vec<Replay> {
    eprintln!("bench:   replaying {} rays of {integrator}", rays.len());
    let raw_rays = |t_near: &dyn Fn(&Ray) -> f32| -> Vec<(usize, RawRay)> {
        rays.iter()
            .map(|&(kind, ray)| {
                let t_near = t_near(&ray);
                (kind, RawRay { ray, t_near })
            })
            .collect()
    };
    let from_origin = raw_rays(&|_| 0.0);
    let past_fiber = raw_rays(&|ray| accels.tress.fiber_exit(ray));
    [
        ReplayMode::Raw(Mode::Plain),
        ReplayMode::PlainPastFiber,
        ReplayMode::Raw(Mode::Embree1),
        ReplayMode::Raw(Mode::Embree1Excl),
        ReplayMode::Raw(Mode::Accel),
    ]
    .into_iter()
    .map(|replay_mode| {
        let (mode, rays) = match replay_mode {
            ReplayMode::Raw(mode) => (mode, &from_origin),
            ReplayMode::PlainPastFiber => (Mode::Plain, &past_fiber),
        };
        let accel = accels.for_mode(mode);
        let exclusion = if mode == Mode::Embree1Excl {
            Exclusion::Tress
        } else {
            Exclusion::Off
        };
        let chunk = |c: &[(usize, RawRay)]| -> u64 {
            c.iter()
                .map(|(kind, r)| {
                    u64::from(match (mode, *kind) {
                        (Mode::Accel, SHADOW) => accel.occluded(&r.ray),
                        (Mode::Accel, _) => accel.intersect(&r.ray).is_some(),
                        (_, SHADOW) => accel.raw_occluded(r, exclusion),
                        _ => accel.raw_intersect(r, exclusion).is_some(),
                    })
                })
                .sum()
        };
        let (hits, cost) = (0..runs)
            .map(|_| timed(|| pool.install(|| rays.par_chunks(CHUNK).map(chunk).sum::<u64>())))
            .min_by(|a, b| a.1.wall.total_cmp(&b.1.wall))
            .expect("at least one run");
        black_box(hits);
        Replay {
            mode: replay_mode,
            rays: rays.len(),
            rate: rays.len() as f64 / cost.wall,
            cost,
        }
    })
    .collect()
}

#[derive(Clone, Copy)]
pub(super) struct RenderReport<'a> {
    pub(super) model: &'a str,
    pub(super) integrator: &'static str,
    pub(super) threads: usize,
    /// Whether the path tracer's ray-rate target applies (the large procedural model and the
    /// hair file).
    pub(super) ray_target: bool,
}

pub(super) fn report_render(
    table: &mut Table,
    at: RenderReport,
    r: &RenderRun,
    raw: Option<&RawRates>,
    replay: Option<&[Replay]>,
) {
    let (model, threads) = (at.model, Some(at.threads));
    let secs = r.cost.wall;
    let traced: u64 = r.traced.iter().sum();
    let rate = traced as f64 / secs;
    let cpu_rate = r.cost.cpu.filter(|&c| c > 0.0).map(|c| traced as f64 / c);
    let metric = |m: &str| format!("{}/{m}", at.integrator);
    let mut push = |m: &str, value: f64, unit: &'static str, note: String| {
        table.push((model, "integrator"), metric(m), threads, value, unit, note)
    };
    push(
        "samples_per_s",
        r.samples as f64 / secs / 1e6,
        "Msamples/s",
        String::new(),
    );
    push(
        "time_per_sample",
        secs / r.samples as f64 * 1e6,
        "us",
        String::new(),
    );
    push(
        "rays_per_s",
        rate / 1e6,
        "Mrays/s",
        cost_note(traced as usize, &r.cost),
    );
    push(
        "rays_per_sample",
        traced as f64 / r.samples as f64,
        "",
        String::new(),
    );
    for (kind, &n) in Kind::ALL.iter().zip(&r.traced) {
        push(
            &format!("mix_{}", kind.name()),
            n as f64 / traced.max(1) as f64,
            "",
            String::new(),
        );
    }
    // The target compares the path tracer with raw Embree tracing the same rays.
    let path_target = at.ray_target && at.integrator == "path";
    let with_target = |note: String, ratio: f64, mode: ReplayMode| {
        if path_target && mode == ReplayMode::Raw(Mode::Plain) {
            format!("{note}; {}", target("≥ 0.75", ratio >= 0.75))
        } else {
            note
        }
    };
    // The measure: the raw rates of the synthetic ray sets, weighted by this mix.
    if let Some(raw) = raw {
        for (mode, what) in [
            (Mode::Plain, "Embree without filter support"),
            (Mode::Embree1, "raw Embree"),
            (Mode::Embree1Excl, "raw Embree with the exclusion rule"),
        ] {
            if let Some(mix) = raw.mix(r.traced, mode, at.threads) {
                let ratio = rate / mix;
                push(
                    &format!("ratio_vs_{}", mode.name()),
                    ratio,
                    "",
                    format!(
                        "÷ {what}, synthetic rays weighted by this mix: {:.3} Mrays/s (not the \
                         integrator's rays: see ratio_vs_replay)",
                        mix / 1e6
                    ),
                );
            }
        }
    }
    // The same rays the integrator traced, traced again raw.
    for rep in replay.unwrap_or_default() {
        let ratio = rate / rep.rate;
        push(
            &format!("ratio_vs_replay_{}", rep.mode.name()),
            ratio,
            "",
            with_target(
                format!(
                    "÷ its own rays replayed as {}: {:.3} Mrays/s",
                    rep.mode.name(),
                    rep.rate / 1e6
                ),
                ratio,
                rep.mode,
            ),
        );
        if let (Some(cpu_rate), Some(rep_cpu)) = (cpu_rate, rep.cost.cpu.filter(|&c| c > 0.0)) {
            let rep_cpu_rate = rep.rays as f64 / rep_cpu;
            let ratio = cpu_rate / rep_cpu_rate;
            push(
                &format!("ratio_vs_replay_{}_cpu", rep.mode.name()),
                ratio,
                "",
                with_target(
                    format!(
                        "per CPU-second, immune to other processes' load: {:.3} ÷ {:.3} Mrays/CPU-s",
                        cpu_rate / 1e6,
                        rep_cpu_rate / 1e6
                    ),
                    ratio,
                    rep.mode,
                ),
            );
        }
    }
}

/// Time per sample of the large procedural model over the small one, and the N-thread speedup.
pub(super) fn scaling(
    table: &mut Table,
    plan: &Plan,
    per_sample: &[Timing],
    pools: &[(usize, ThreadPool)],
) {
    let find = |model: &str, integrator: &str, threads: usize| {
        per_sample
            .iter()
            .find(|r| r.model == model && r.integrator == integrator && r.threads == threads)
    };
    let small = strand_label(plan.strands[0]);
    // The same radius makes the large model 10× optically thicker (longer paths, more
    // shadow-ray occlusion); the thinned one isolates the strand count.
    let pairs = [
        (
            strand_label(plan.strands[1]),
            "same radius: 10× the optical thickness",
        ),
        (thin_label(plan.strands[1]), "equal coverage: radius/√10"),
    ];
    let max_threads = pools.last().map_or(1, |p| p.0);
    for integrator in IntegratorDesc::NAMES {
        for (large, what) in &pairs {
            let pair = format!("{large}/{small}");
            for (threads, _) in pools {
                if let (Some(a), Some(b)) = (
                    find(&small, integrator, *threads),
                    find(large, integrator, *threads),
                ) {
                    let ratio = b.per_sample / a.per_sample;
                    table.push(
                        (&pair, "scaling"),
                        format!("{integrator}/time_per_sample_ratio"),
                        Some(*threads),
                        ratio,
                        "",
                        format!("{what}; {}", target("≤ 1.25", ratio <= 1.25)),
                    );
                    table.push(
                        (&pair, "scaling"),
                        format!("{integrator}/time_per_ray_ratio"),
                        Some(*threads),
                        b.per_ray / a.per_ray,
                        "",
                        "the cost per ray traced",
                    );
                }
            }
        }
        if max_threads > 1 {
            let mut models: Vec<&str> = per_sample.iter().map(|r| r.model.as_str()).collect();
            models.dedup();
            for model in models {
                if let (Some(one), Some(many)) = (
                    find(model, integrator, 1),
                    find(model, integrator, max_threads),
                ) {
                    let speedup = one.per_sample / many.per_sample;
                    let mut note = if max_threads == 2 {
                        target("≥ 1.8", speedup >= 1.8)
                    } else {
                        String::new()
                    };
                    if let (Some(a), Some(b)) = (one.cpu_per_sample, many.cpu_per_sample) {
                        let _ = write!(
                            note,
                            "; CPU time per sample, {max_threads} threads ÷ 1: {:.3}",
                            b / a
                        );
                    }
                    if let Some(w) = many.waiting {
                        let _ = write!(
                            note,
                            "; its threads waited for a core {:.0}% of the time",
                            100.0 * w
                        );
                    }
                    table.push(
                        (model, "scaling"),
                        format!("{integrator}/speedup"),
                        Some(max_threads),
                        speedup,
                        "×",
                        note,
                    );
                }
            }
        }
    }
}
