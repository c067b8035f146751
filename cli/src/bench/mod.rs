//! `tress bench`: what the renderer achieves, measured against raw Embree in the same process.
//!
//! For each hair model — procedural wavy hair of 10k and 100k strands × 32 segments,
//! `straight.hair` when present, 1M strands with `--huge` — it measures
//! - build: load, BVH and density-grid times, peak RSS (VmHWM, reset per model) and bytes per
//!   segment;
//! - raw: Embree throughput for camera rays, rays bouncing off hair hit points in random
//!   directions, and shadow rays toward random directions, as single rays on a twin scene of
//!   the same curves built without filter support (`plain`: Embree alone, the baseline), on
//!   tress's scene without and with its self-intersection rule, as 8-wide packets, and as full
//!   `Accel` queries (with hit construction), on one thread and on N;
//! - integrator: samples/s and rays/s of every registered integrator rendering the model under
//!   the built-in sky, the mix of camera, bounce and shadow rays it traced, its ray rate
//!   divided by the raw rate of the same mix (raw rates weighted by the mix), and divided by
//!   the rate of its own recorded rays replayed in each raw mode;
//! - round: the models of the path tracer's ray-rate target again with round curves (tubes),
//!   raw and path only;
//! - scaling: time per sample of the large procedural model over the small one — at the same
//!   fiber radius (10× the optical thickness) and thinned to equal coverage (radius/√10, the
//!   same picture with 10× the primitives) — and the N-thread speedup;
//! - bcsdf: eval, sample, pdf and fused eval+pdf cost of every registered hair model,
//!   dual-scattering table build time.
//!
//! `--scene FILE` measures a scene file instead (`scene.rs`): its integrator rendering it, and
//! the rays of that render traced again by Embree alone and by tress's accelerator.
//!
//! Absolute figures follow the machine and its load; the ratios compare figures taken minutes
//! apart in one process. Every integrator render and ray replay is timed three times (once with
//! `--quick`) and the fastest run counts, as other processes can only slow a run down. Rows
//! carrying a target of the performance issue say whether it is met.

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use rayon::ThreadPool;
use std::hint::black_box;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tress_accel::{CurveShape, EmbreeAccel, HairOptions, SceneBuilder};
use tress_core::film::FilmSettings;
use tress_core::light::{EnvironmentMap, Light};
use tress_core::math::{Aabb, Vec3};
use tress_core::output_file::{self, Inputs};
use tress_core::prepare::Preparation;
use tress_core::{Bcsdf, Camera, Integrator, Material, Scene};
use tress_dual_scattering::density::{DensityGrid, DensitySettings};
use tress_groom::{HairFile, HairGeometry, HairStyle, ProceduralHair};
use tress_loader::integrators::IntegratorDesc;
use tress_loader::scene_desc;
use tress_materials::dual_scattering::{fingerprint, DualScatteringTables};
use tress_materials::{CostInputs, HairModel};

mod plan;
mod raw;
mod renders;
mod scene;
mod table;

use plan::*;
use raw::*;
use renders::*;
use table::*;

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Small models and short runs (well under a minute): a smoke test.
    #[arg(long)]
    pub quick: bool,
    /// Also build 1M strands × 32 segments and render a small image with it (several GiB).
    #[arg(long)]
    pub huge: bool,
    /// Also write the table to this CSV file (atomically).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Threads of the multi-threaded measurements (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Cem Yuksel `.hair` file benchmarked beside the procedural models; skipped with a note
    /// when absent.
    #[arg(long, default_value = "../shared/data/hair/straight.hair")]
    pub hair_file: PathBuf,
    /// Instead of the built-in models: render this scene with its integrator, and trace the
    /// rays it traced again with Embree alone (how close the render comes to Embree's speed).
    #[arg(long, conflicts_with_all = ["huge", "hair_file"])]
    pub scene: Option<PathBuf>,
    /// Samples per pixel of the `--scene` renders; overrides the scene's film.spp.
    #[arg(long, requires = "scene")]
    pub spp: Option<u32>,
}

pub fn run(args: BenchArgs) -> Result<()> {
    let plan = Plan::new(args.quick);
    let pools = thread_pools(args.threads)?;
    let mut table = Table::default();
    let inputs = match &args.scene {
        Some(path) => scene_desc::load(path)?.inputs(path)?,
        None => [&args.hair_file].into_iter().collect(),
    };
    // Refused before measuring, not after.
    if let Some(csv) = &args.csv {
        output_file::check(csv, &inputs)?;
    }
    if let Some(path) = &args.scene {
        scene::bench_scene(path, args.spp, &plan, &pools, &mut table)?;
        return finish(&table, args.csv.as_deref(), &inputs);
    }
    let material = HairModel::Chiang(Default::default());
    let bcsdf = material
        .build(&Preparation::new())
        .map_err(|e| anyhow!("hair material: {e}"))?;
    eprintln!("bench: BCSDF costs and dual-scattering tables");
    bench_bcsdfs(&mut table, plan.bcsdf_calls)?;
    // One preparation context for the whole run. The tables are built here, through it, to
    // time the build apart from any render; the integrators of every model then find them in
    // it (the same model and settings) instead of building them again per model.
    let prep = Preparation::with_limits(crate::limits_from_env());
    bench_tables(&mut table, &plan, &bcsdf, &prep)?;
    let models = models(&args, &plan, &mut table);
    let mut per_sample: Vec<Timing> = Vec::new();
    for spec in &models {
        bench_model(
            spec,
            &plan,
            &pools,
            &bcsdf,
            &prep,
            &mut table,
            &mut per_sample,
        )
        .with_context(|| format!("model {}", spec.name))?;
    }
    scaling(&mut table, &plan, &per_sample, &pools);
    finish(&table, args.csv.as_deref(), &inputs)
}

/// Prints the table, and writes it to `csv` when given (replacing none of `inputs`).
fn finish(table: &Table, csv: Option<&std::path::Path>, inputs: &Inputs) -> Result<()> {
    print!("{}", table.text());
    if let Some(path) = csv {
        output_file::write_bytes(path, inputs, table.csv().as_bytes())?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// The pools of the measurements: one thread, and `threads` (default: all cores) when more.
fn thread_pools(threads: Option<usize>) -> Result<Vec<(usize, ThreadPool)>> {
    let threads =
        threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    if threads == 0 {
        bail!("--threads must be at least 1");
    }
    let pool = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .context("creating a thread pool")
    };
    let mut pools = vec![(1, pool(1)?)];
    if threads > 1 {
        pools.push((threads, pool(threads)?));
    }
    Ok(pools)
}

/// Builds the dual-scattering tables of `bcsdf` into `prep`, timed.
fn bench_tables(
    table: &mut Table,
    plan: &Plan,
    bcsdf: &Arc<dyn Bcsdf>,
    prep: &Preparation,
) -> Result<()> {
    let tables = prep
        .get_or_build((fingerprint(bcsdf.as_ref()), plan.tables.clone()), || {
            DualScatteringTables::new(bcsdf.as_ref(), &plan.tables, prep.limits())
        })
        .map_err(|e| anyhow!("dual-scattering tables: {e}"))?;
    table.push(
        ("Chiang/brown", "bcsdf"),
        "ds_tables_build",
        None,
        tables.build_time().as_secs_f64(),
        "s",
        format!(
            "{} θ nodes, {} h nodes, quadrature {}×{}",
            plan.tables.theta_nodes,
            plan.tables.h_nodes,
            plan.tables.theta_quad,
            plan.tables.phi_quad
        ),
    );
    Ok(())
}

/// The models of the run: the procedural pair, the large one thinned, the hair file when
/// present (else a note in the table), the huge one with `--huge`, and the ray-rate target's
/// models again with round curves.
fn models(args: &BenchArgs, plan: &Plan, table: &mut Table) -> Vec<ModelSpec> {
    let mut models: Vec<ModelSpec> = plan
        .strands
        .iter()
        .map(|&n| ModelSpec {
            name: strand_label(n),
            source: Source::Procedural(n, RADIUS),
            full: true,
            all_integrators: true,
            curve: CurveShape::Flat,
        })
        .collect();
    // Strand count alone, without the 10× optical thickness the fixed radius also brings.
    let [small, large] = plan.strands;
    models.push(ModelSpec {
        name: thin_label(large),
        source: Source::Procedural(large, equal_coverage_radius(large, small)),
        full: true,
        all_integrators: true,
        curve: CurveShape::Flat,
    });
    let file_name = args
        .hair_file
        .file_name()
        .map_or_else(|| "hair file".into(), |n| n.to_string_lossy().into_owned());
    if args.hair_file.is_file() {
        models.push(ModelSpec {
            name: file_name,
            source: Source::File(args.hair_file.clone()),
            full: true,
            all_integrators: true,
            curve: CurveShape::Flat,
        });
    } else {
        table.note(
            &file_name,
            "build",
            "skipped",
            format!("{} not found", args.hair_file.display()),
        );
    }
    if args.huge {
        models.push(ModelSpec {
            name: strand_label(HUGE_STRANDS),
            source: Source::Procedural(HUGE_STRANDS, RADIUS),
            full: false,
            all_integrators: false,
            curve: CurveShape::Flat,
        });
    }
    // The models of the ray-rate target again as tubes, for the path tracer.
    let round: Vec<ModelSpec> = models
        .iter()
        .filter(|m| ray_target(&m.source, plan))
        .map(|m| ModelSpec {
            name: format!("{} round", m.name),
            source: m.source.clone(),
            full: true,
            all_integrators: false,
            curve: CurveShape::Round,
        })
        .collect();
    models.extend(round);
    models
}

/// eval, sample and pdf cost of one instance of every registered hair model (the first
/// pigmented test instance, so absorption is exercised).
fn bench_bcsdfs(table: &mut Table, calls: usize) -> Result<()> {
    let CostInputs { dirs, hs, us } = CostInputs::new();
    let instances = HairModel::test_instances();
    for name in HairModel::names() {
        let prefix = format!("{name}/");
        let of_model: Vec<_> = instances
            .iter()
            .filter(|t| t.name.starts_with(&prefix))
            .collect();
        let Some(instance) = of_model
            .iter()
            .find(|t| !t.white_furnace)
            .or(of_model.first())
        else {
            continue;
        };
        // Built alone (its tables, if any, built and not stored): the rows time calls.
        let bcsdf = instance
            .params
            .build(&Preparation::new())
            .map_err(|e| anyhow!("{}: {e}", instance.name))?;
        let b: &dyn Bcsdf = bcsdf.as_ref();
        let time = |f: &dyn Fn(usize) -> f32| {
            let start = Instant::now();
            let mut acc = 0.0f32;
            for i in 0..calls {
                acc += f(i % CostInputs::LEN);
            }
            black_box(acc);
            start.elapsed().as_secs_f64() * 1e9 / calls as f64
        };
        let eval = time(&|i| b.eval(dirs[i].0, dirs[i].1, hs[i]).x);
        let sample = time(&|i| b.sample(dirs[i].0, hs[i], us[i]).map_or(0.0, |s| s.pdf));
        let sample_weight = time(&|i| {
            b.sample_weight(dirs[i].0, hs[i], us[i])
                .map_or(0.0, |(_, w)| w.x)
        });
        let pdf = time(&|i| b.pdf(dirs[i].0, dirs[i].1, hs[i]));
        let eval_pdf = time(&|i| {
            let (f, pdf) = b.eval_pdf(dirs[i].0, dirs[i].1, hs[i]);
            f.x + pdf
        });
        for (metric, ns) in [
            ("eval", eval),
            ("sample", sample),
            ("sample_weight", sample_weight),
            ("pdf", pdf),
            ("eval_pdf", eval_pdf),
        ] {
            table.push(
                (&instance.name, "bcsdf"),
                metric,
                Some(1),
                ns,
                "ns/call",
                "",
            );
        }
    }
    Ok(())
}

/// Peak resident memory (VmHWM in /proc/self/status), in bytes.
fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line["VmHWM:".len()..]
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb * 1024)
}

/// Resets the peak (VmHWM) to the current RSS, so it measures one model; false where the
/// kernel does not allow it (then the peak is the process's).
fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

const MIB: f64 = 1024.0 * 1024.0;

/// A camera framing the hair from the front, close enough that it fills most of a 40° view.
fn framing(bounds: &Aabb) -> Camera {
    let fov = 40.0f32;
    let center = bounds.center();
    let radius = 0.5 * bounds.extent().length();
    let distance = 0.7 * radius / (0.5 * fov.to_radians()).tan();
    let from = center + distance * Vec3::new(0.35, 0.1, 1.0).normalize();
    Camera::perspective(from, center, Vec3::Y, fov, 0.0, None)
}

fn load(spec: &ModelSpec) -> Result<HairGeometry> {
    Ok(match &spec.source {
        Source::Procedural(strands, radius) => ProceduralHair {
            style: HairStyle::Wavy {
                amplitude: 0.05,
                frequency: 2.0,
            },
            seed: 7,
            strands: *strands,
            radius: *radius,
            points_per_strand: SEGMENTS + 1,
            ..Default::default()
        }
        .generate(&crate::limits_from_env())?,
        Source::File(path) => HairFile::new(path).read()?,
    })
}

/// A model built as `tress render` builds it, with the cost of each step.
struct BuiltModel {
    accel: EmbreeAccel,
    /// The density grid the dual-scattering integrators read at their default resolution.
    grid: DensityGrid,
    /// The baseline: the same curves with no filter support (full models only).
    plain: Option<EmbreeAccel>,
    load: Duration,
    bvh: Duration,
    grid_time: Duration,
    /// Peak memory after the build, before the baseline's.
    peak: Option<u64>,
}

/// Loads and builds `spec` in `pool` (the builds run in the render's thread pool, as in
/// `tress render`).
fn build_model(spec: &ModelSpec, pool: &ThreadPool) -> Result<BuiltModel> {
    let t0 = Instant::now();
    let hair = load(spec)?;
    let load_time = t0.elapsed();
    let t1 = Instant::now();
    let options = HairOptions {
        curve: spec.curve,
        ..Default::default()
    };
    let accel = pool.install(|| SceneBuilder::new()?.add_hair(&hair, &options, 0)?.build())?;
    let bvh_time = t1.elapsed();
    drop(hair);
    // Its cost is part of the build; the scene hands the grid to the integrators.
    let t2 = Instant::now();
    let grid = pool.install(|| {
        DensityGrid::build(
            tress_core::Accel::hair_curves(&accel),
            &DensitySettings::default(),
            &crate::limits_from_env(),
        )
    })?;
    let grid_time = t2.elapsed();
    let peak = peak_rss();
    // The baseline's build quality and basis are tress's; built after the peak above so that
    // it measures tress's own build.
    let plain = spec
        .full
        .then(|| -> Result<EmbreeAccel> {
            let hair = load(spec)?;
            Ok(pool.install(|| {
                SceneBuilder::new()?
                    .without_filters()
                    .add_hair(&hair, &options, 0)?
                    .build()
            })?)
        })
        .transpose()?;
    Ok(BuiltModel {
        accel,
        grid,
        plain,
        load: load_time,
        bvh: bvh_time,
        grid_time,
        peak,
    })
}

/// The build rows of model `name`; `scope` says what the peak memory covers.
fn report_build(
    table: &mut Table,
    name: &str,
    plan: &Plan,
    built: &BuiltModel,
    max_threads: usize,
    scope: &str,
) {
    let info = built.accel.info();
    let segments = info.segments as f64;
    let mut build = |metric: &str, value: f64, unit: &'static str, note: String| {
        table.push((name, "build"), metric, None, value, unit, note)
    };
    build("strands", info.strands as f64, "", String::new());
    build("segments", segments, "", String::new());
    build("load", built.load.as_secs_f64(), "s", String::new());
    build(
        "bvh",
        built.bvh.as_secs_f64(),
        "s",
        format!("{max_threads} threads"),
    );
    build(
        "grid",
        built.grid_time.as_secs_f64(),
        "s",
        built.grid.info().to_string(),
    );
    let total = (built.load + built.bvh + built.grid_time).as_secs_f64();
    let large = name == strand_label(plan.strands[1]) && plan.strands[1] == 100_000;
    build(
        "load+bvh+grid",
        total,
        "s",
        if large {
            target("≤ 3 s", total <= 3.0)
        } else {
            String::new()
        },
    );
    build(
        "accel_bytes_per_segment",
        info.memory_bytes as f64 / segments,
        "B",
        "Embree (BVH, buffers) + hit/filter data".into(),
    );
    build(
        "grid_bytes_per_segment",
        built.grid.info().memory_bytes as f64 / segments,
        "B",
        String::new(),
    );
    if let Some(peak) = built.peak {
        let peak_mib = peak as f64 / MIB;
        build(
            "peak_rss_build",
            peak_mib,
            "MiB",
            if large {
                format!("{scope}; {}", target("≤ 1024 MiB", peak_mib <= 1024.0))
            } else {
                scope.into()
            },
        );
    }
}

fn bench_model(
    spec: &ModelSpec,
    plan: &Plan,
    pools: &[(usize, ThreadPool)],
    bcsdf: &Arc<dyn Bcsdf>,
    prep: &Preparation,
    table: &mut Table,
    per_sample: &mut Vec<Timing>,
) -> Result<()> {
    let name = spec.name.as_str();
    eprintln!("bench: {name}: building");
    let peak_is_per_model = reset_peak_rss();
    let (max_threads, big_pool) = pools.last().map(|(n, p)| (*n, p)).expect("a pool");
    let built = build_model(spec, big_pool)?;
    let scope = if peak_is_per_model {
        "peak since this model started"
    } else {
        "process peak (VmHWM reset unsupported)"
    };
    report_build(table, name, plan, &built, max_threads, scope);

    let (film_side, spp) = if spec.full { plan.film } else { (64, 1) };
    let camera = framing(&built.accel.info().bounds);
    let film = FilmSettings {
        width: film_side,
        height: film_side,
        spp,
        seed: 1,
        crop: None,
    };
    let BuiltModel {
        accel, grid, plain, ..
    } = built;
    let accel = Arc::new(accel);
    let accels = plain.map(|plain| Accels {
        tress: Arc::clone(&accel),
        plain,
    });
    let raw = match &accels {
        Some(accels) => {
            eprintln!("bench: {name}: raw Embree");
            let rays = RaySets::new(&accel, &camera, &film, plan.rays)?;
            Some(bench_raw(name, accels, &rays, pools, table))
        }
        None => None,
    };

    let recording = Arc::new(AtomicBool::new(false));
    let scene = Scene::new(
        camera,
        Box::new(CountingAccel {
            inner: Arc::clone(&accel),
            record: Arc::clone(&recording),
        }),
        vec![Material::Hair(Arc::clone(bcsdf))],
        vec![Light::Environment(EnvironmentMap::builtin_sky(0.0, 1.0)?)].into(),
    );
    // The grid at the default resolution was built (and timed) with the BVH: the run's
    // preparation hands it to the dual-scattering integrators instead of building another.
    scene
        .fiber_density(prep, None, |_, _| Ok(Arc::new(grid)))
        .map_err(|e| anyhow!("{name}: {e}"))?;
    let renders = ModelRenders {
        name,
        full: spec.full,
        ray_target: ray_target(&spec.source, plan),
        plan,
        scene: &scene,
        film: &film,
        pools,
        recording: &recording,
        accels: accels.as_ref(),
        raw: raw.as_ref(),
    };
    // The ray-rate target and the huge and round models concern the path tracer.
    for desc in plan
        .integrators
        .iter()
        .filter(|d| spec.all_integrators || d.name() == "path")
    {
        let integrator = desc.build(&scene, prep)?;
        renders.bench(desc, integrator.as_ref(), table, per_sample);
    }
    if let Some(peak) = peak_rss() {
        let peak_mib = peak as f64 / MIB;
        let note = if spec.full {
            scope.to_string()
        } else {
            format!(
                "{scope}; {film_side}×{film_side} at {spp} spp; {}",
                target("≤ 24 GiB", peak_mib <= 24.0 * 1024.0)
            )
        };
        table.push((name, "build"), "peak_rss", None, peak_mib, "MiB", note);
    }
    Ok(())
}

/// The integrators' renders of one model: its scene (queries counted) and film, and what they
/// are compared with.
struct ModelRenders<'a> {
    /// The model's label in the table.
    name: &'a str,
    /// Whether its rays are recorded and replayed, and rendered on every pool.
    full: bool,
    /// Whether the path tracer's ray-rate target applies to it.
    ray_target: bool,
    plan: &'a Plan,
    scene: &'a Scene,
    film: &'a FilmSettings,
    pools: &'a [(usize, ThreadPool)],
    /// Set while the rays traced are recorded.
    recording: &'a AtomicBool,
    /// tress's accelerator and the baseline, for replays (full models only).
    accels: Option<&'a Accels>,
    /// Raw Embree rates (full models only).
    raw: Option<&'a RawRates>,
}

impl ModelRenders<'_> {
    /// Times `integrator`'s render on each pool (all of them for full models, else the largest)
    /// and its recorded rays replayed raw.
    fn bench(
        &self,
        desc: &IntegratorDesc,
        integrator: &dyn Integrator,
        table: &mut Table,
        per_sample: &mut Vec<Timing>,
    ) {
        let (plan, name) = (self.plan, self.name);
        let (_, big_pool) = self.pools.last().expect("a pool");
        // An untimed pass records every ray the integrator traces (it also warms up); the
        // timed renders below repeat exactly that work (the image depends only on the seed).
        let recorded = if self.full {
            eprintln!("bench: {name}: {}: recording its rays", desc.name());
            Some(record_rays(
                self.scene,
                integrator,
                self.film,
                big_pool,
                self.recording,
            ))
        } else {
            None
        };
        let render_pools: Vec<&(usize, ThreadPool)> = if self.full {
            self.pools.iter().collect()
        } else {
            self.pools.iter().rev().take(1).collect()
        };
        for (n, pool) in render_pools.iter().map(|(n, p)| (*n, p)) {
            eprintln!("bench: {name}: {} on {n} thread(s)", desc.name());
            let r = (0..plan.runs)
                .map(|_| render(self.scene, integrator, self.film, pool))
                .min_by(|a, b| a.cost.wall.total_cmp(&b.cost.wall))
                .expect("at least one run");
            let traced = r.traced.iter().sum::<u64>().max(1) as f64;
            per_sample.push(Timing {
                model: name.to_string(),
                integrator: desc.name(),
                threads: n,
                per_sample: r.cost.wall / r.samples as f64,
                per_ray: r.cost.wall / traced,
                cpu_per_sample: r.cost.cpu.map(|c| c / r.samples as f64),
                waiting: r.cost.waiting(),
            });
            let replay = recorded
                .as_ref()
                .zip(self.accels)
                .map(|(rays, accels)| replay(accels, rays, pool, desc.name(), plan.runs));
            report_render(
                table,
                RenderReport {
                    model: name,
                    integrator: desc.name(),
                    threads: n,
                    ray_target: self.ray_target,
                },
                &r,
                self.raw,
                replay.as_deref(),
            );
        }
    }
}
