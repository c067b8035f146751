//! `tress bench --scene`: a scene's own render against Embree alone tracing the same rays.
//!
//! The scene is built twice: as a render builds it, with its queries counted and recorded, and
//! as a twin without Embree's filter support (Embree alone). An untimed render records every
//! ray; the timed renders (one thread, then all) are followed by replays of exactly those rays
//! on the twin and on tress's accelerator, as in the built-in models' `integrator` rows.

use super::renders::CountingAccel;
use super::{Accels, ModelRenders, Plan, Table, Timing};
use anyhow::{Context, Result};
use rayon::ThreadPool;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use tress_loader::scene_desc;

/// Benchmarks the scene at `path` (its integrator, film and lights; `spp` overrides its
/// film's) on every pool, into `table`.
pub(super) fn bench_scene(
    path: &Path,
    spp: Option<u32>,
    plan: &Plan,
    pools: &[(usize, ThreadPool)],
    table: &mut Table,
) -> Result<()> {
    let prep = crate::default_preparation();
    let mut desc = scene_desc::load(path)?;
    if let Some(spp) = spp {
        desc.film.spp = spp;
    }
    let (_, big_pool) = pools.last().expect("a pool");
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    );

    eprintln!("bench: {name}: building the scene and its twin without filters");
    let recording = Arc::new(AtomicBool::new(false));
    let mut tress_accel = None;
    let built = big_pool.install(|| {
        scene_desc::build_wrapped(&desc, path, &prep, |accel| {
            let accel = Arc::new(accel);
            tress_accel = Some(Arc::clone(&accel));
            Box::new(CountingAccel {
                inner: accel,
                record: Arc::clone(&recording),
            })
        })
    })?;
    let tress = tress_accel.expect("the scene's accelerator");
    let plain = big_pool.install(|| scene_desc::build_plain_accel(&desc, path, &prep))?;
    let accels = Accels { tress, plain };

    crate::print_warnings(&prep);
    let integrator = big_pool
        .install(|| desc.integrator.build(&built.scene, &prep))
        .with_context(|| path.display().to_string())?;
    // A per-film precomputation (a radiance cache) is made once, untimed: the rows measure
    // the render that follows it.
    let never = std::sync::atomic::AtomicBool::new(false);
    let samples = 0..desc.film.spp as u64;
    let prepared = big_pool
        .install(|| integrator.for_film(&built.scene, &desc.film, samples, &never, &|_| {}));
    let integrator = prepared
        .as_ref()
        .map_or(integrator.as_ref(), |p| p.integrator.as_ref());

    let renders = ModelRenders {
        name: &name,
        full: true,
        ray_target: false,
        plan,
        scene: &built.scene,
        film: &desc.film,
        pools,
        recording: &recording,
        accels: Some(&accels),
        raw: None,
    };
    let mut per_sample: Vec<Timing> = Vec::new();
    renders.bench(&desc.integrator, integrator, table, &mut per_sample);
    Ok(())
}
