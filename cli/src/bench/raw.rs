//! Raw Embree measurements: the synthetic ray sets, the query modes and their rates.

use super::plan::CHUNK;
use super::table::{cost_note, Table};
use anyhow::{bail, Result};
use rayon::prelude::*;
use rayon::ThreadPool;
use std::hint::black_box;
use std::sync::Arc;
use tress_accel::raw::{Exclusion, RawRay, PACKET};
use tress_accel::EmbreeAccel;
use tress_core::film::FilmSettings;
use tress_core::math::{Ray, Vec2};
use tress_core::rng::Pcg32;
use tress_core::sampling::sample_uniform_sphere;
use tress_core::{Accel, Camera, Hit};
use tress_study::cost::timed;

/// The three kinds of ray, as in a render: camera rays through the film, and rays leaving hair
/// hit points (found by random walks from the camera) in uniformly random directions — as
/// closest-hit queries (bounce) and as visibility queries to infinity (shadow).
pub(super) struct RaySets {
    pub(super) camera: Vec<RawRay>,
    pub(super) bounce: Vec<RawRay>,
    pub(super) shadow: Vec<RawRay>,
}

impl RaySets {
    pub(super) fn new(
        accel: &EmbreeAccel,
        camera: &Camera,
        film: &FilmSettings,
        n: usize,
    ) -> Result<Self> {
        let mut rng = Pcg32::new(5, 0);
        let camera_ray = |rng: &mut Pcg32| {
            let (x, y) = (rng.next_f32(), rng.next_f32());
            camera.generate_ray(
                x * film.width as f32,
                y * film.height as f32,
                film.width,
                film.height,
                Vec2::ZERO,
            )
        };
        let camera_rays: Vec<RawRay> = (0..n)
            .map(|_| RawRay {
                ray: camera_ray(&mut rng),
                t_near: 0.0,
            })
            .collect();
        let dir =
            |rng: &mut Pcg32| sample_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        // Hit points at depths 0..4 of random walks.
        let mut points: Vec<Hit> = Vec::with_capacity(n);
        let mut walks = 0;
        while points.len() < n && walks < 16 * n {
            walks += 1;
            let mut ray = camera_ray(&mut rng);
            for _ in 0..4 {
                let Some(hit) = accel.intersect(&ray) else {
                    break;
                };
                points.push(hit);
                ray = Ray::leaving(hit.p, dir(&mut rng), hit.prim);
            }
        }
        if points.is_empty() {
            bail!("the camera sees no hair");
        }
        let leaving = |rng: &mut Pcg32| -> Vec<RawRay> {
            (0..n)
                .map(|i| {
                    let hit = &points[i % points.len()];
                    RawRay {
                        ray: Ray::leaving(hit.p, dir(rng), hit.prim),
                        t_near: 0.0,
                    }
                })
                .collect()
        };
        let bounce = leaving(&mut rng);
        let shadow = leaving(&mut rng);
        Ok(RaySets {
            camera: camera_rays,
            bounce,
            shadow,
        })
    }
}

/// The ways a ray is traced in the raw section.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Mode {
    /// `rtcIntersect1`/`rtcOccluded1` on a twin scene of the same curves built without filter
    /// support: Embree alone, the baseline.
    Plain,
    /// `rtcIntersect1`/`rtcOccluded1` on tress's scene, with no filter callback.
    Embree1,
    /// The same with tress's self-intersection rule.
    Embree1Excl,
    /// `rtcIntersect8`/`rtcOccluded8`, no exclusion.
    Embree8,
    /// `Accel::intersect`/`occluded`: what the integrators call (hit construction included).
    Accel,
}

impl Mode {
    pub(super) fn name(self) -> &'static str {
        match self {
            Mode::Plain => "plain",
            Mode::Embree1 => "embree1",
            Mode::Embree1Excl => "embree1-excl",
            Mode::Embree8 => "embree8",
            Mode::Accel => "accel",
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Kind {
    Camera,
    Bounce,
    Shadow,
}

impl Kind {
    pub(super) const ALL: [Kind; 3] = [Kind::Camera, Kind::Bounce, Kind::Shadow];

    pub(super) fn name(self) -> &'static str {
        match self {
            Kind::Camera => "camera",
            Kind::Bounce => "bounce",
            Kind::Shadow => "shadow",
        }
    }
}

/// Raw rays/s by (kind, mode, threads).
pub(super) struct RawRates(Vec<(Kind, Mode, usize, f64)>);

impl RawRates {
    pub(super) fn get(&self, kind: Kind, mode: Mode, threads: usize) -> Option<f64> {
        // Camera rays leave no primitive: with and without the rule they are the same query.
        let mode = if kind == Kind::Camera && mode == Mode::Embree1Excl {
            Mode::Embree1
        } else {
            mode
        };
        self.0
            .iter()
            .find(|r| (r.0, r.1, r.2) == (kind, mode, threads))
            .map(|r| r.3)
    }

    /// Rays/s of a mix of `counts` rays per kind, each kind at its raw rate in `mode`.
    pub(super) fn mix(&self, counts: [u64; 3], mode: Mode, threads: usize) -> Option<f64> {
        let mut seconds = 0.0;
        for (kind, &n) in Kind::ALL.iter().zip(&counts) {
            if n > 0 {
                seconds += n as f64 / self.get(*kind, mode, threads)?;
            }
        }
        (seconds > 0.0).then(|| counts.iter().sum::<u64>() as f64 / seconds)
    }
}

pub(super) fn bench_raw(
    model: &str,
    accels: &Accels,
    rays: &RaySets,
    pools: &[(usize, ThreadPool)],
    table: &mut Table,
) -> RawRates {
    let mut rates = Vec::new();
    for (threads, pool) in pools {
        for kind in Kind::ALL {
            let set = match kind {
                Kind::Camera => &rays.camera,
                Kind::Bounce => &rays.bounce,
                Kind::Shadow => &rays.shadow,
            };
            let modes: &[Mode] = if kind == Kind::Camera {
                &[Mode::Plain, Mode::Embree1, Mode::Embree8, Mode::Accel]
            } else {
                &[
                    Mode::Plain,
                    Mode::Embree1,
                    Mode::Embree1Excl,
                    Mode::Embree8,
                    Mode::Accel,
                ]
            };
            for &mode in modes {
                let chunk_hits = |c: &[RawRay]| trace_chunk(accels, kind, mode, c);
                // Warm-up: wakes the pool's threads and touches the top of the BVH.
                let warm = &set[..set.len().min(threads * CHUNK)];
                black_box(pool.install(|| warm.par_chunks(CHUNK).map(chunk_hits).sum::<u64>()));
                let (hits, cost) =
                    timed(|| pool.install(|| set.par_chunks(CHUNK).map(chunk_hits).sum::<u64>()));
                let rate = set.len() as f64 / cost.wall;
                rates.push((kind, mode, *threads, rate));
                table.push(
                    (model, "raw"),
                    format!("{}/{}", kind.name(), mode.name()),
                    Some(*threads),
                    rate / 1e6,
                    "Mrays/s",
                    format!(
                        "{:.1}% {}; {}",
                        100.0 * hits as f64 / set.len() as f64,
                        if kind == Kind::Shadow {
                            "blocked"
                        } else {
                            "hit"
                        },
                        cost_note(set.len(), &cost)
                    ),
                );
            }
        }
    }
    RawRates(rates)
}

/// tress's scene and its twin without filter support.
pub(super) struct Accels {
    pub(super) tress: Arc<EmbreeAccel>,
    pub(super) plain: EmbreeAccel,
}

impl Accels {
    /// The scene a mode queries: the twin for [`Mode::Plain`], tress's for the others.
    pub(super) fn for_mode(&self, mode: Mode) -> &EmbreeAccel {
        if mode == Mode::Plain {
            &self.plain
        } else {
            &self.tress
        }
    }
}

/// Traces a chunk of rays; returns how many hit (or are blocked).
pub(super) fn trace_chunk(accels: &Accels, kind: Kind, mode: Mode, rays: &[RawRay]) -> u64 {
    let closest = kind != Kind::Shadow;
    let accel = accels.for_mode(mode);
    let single = |exclusion| -> u64 {
        rays.iter()
            .map(|r| {
                u64::from(if closest {
                    accel.raw_intersect(r, exclusion).is_some()
                } else {
                    accel.raw_occluded(r, exclusion)
                })
            })
            .sum()
    };
    match mode {
        Mode::Plain | Mode::Embree1 => single(Exclusion::Off),
        Mode::Embree1Excl => single(Exclusion::Tress),
        Mode::Embree8 => rays
            .chunks(PACKET)
            .map(|p| {
                if closest {
                    accel
                        .raw_intersect8(p)
                        .iter()
                        .filter(|h| h.is_some())
                        .count() as u64
                } else {
                    accel.raw_occluded8(p).iter().filter(|&&b| b).count() as u64
                }
            })
            .sum(),
        Mode::Accel => rays
            .iter()
            .map(|r| {
                u64::from(if closest {
                    accel.intersect(&r.ray).is_some()
                } else {
                    accel.occluded(&r.ray)
                })
            })
            .sum(),
    }
}
