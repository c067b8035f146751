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
//! Absolute figures follow the machine and its load; the ratios compare figures taken minutes
//! apart in one process. Every integrator render and ray replay is timed three times (once with
//! `--quick`) and the fastest run counts, as other processes can only slow a run down. Rows
//! carrying a target of the performance issue say whether it is met.

use crate::cost::{timed, Cost};
use crate::integrators::IntegratorDesc;
use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use rayon::prelude::*;
use rayon::ThreadPool;
use std::cell::{Cell, RefCell};
use std::fmt::Write as _;
use std::hint::black_box;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;
use tress_accel::raw::{Exclusion, RawRay, PACKET};
use tress_accel::{
    CurveShape, DensityGrid, EmbreeAccel, HairFile, HairGeometry, HairOptions, HairStyle,
    ProceduralHair, SceneBuilder,
};
use tress_core::film::FilmSettings;
use tress_core::light::{EnvironmentMap, Light};
use tress_core::math::{Aabb, Ray, Vec2, Vec3};
use tress_core::rng::Pcg32;
use tress_core::sampling::sample_uniform_sphere;
use tress_core::{Accel, Bcsdf, Camera, Hit, Integrator, Material, Scene};
use tress_materials::dual_scattering::{DualScatteringCache, DualScatteringSettings};
use tress_materials::HairModel;

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
}

/// The table's columns, in order.
pub const COLUMNS: [&str; 7] = [
    "model", "section", "metric", "threads", "value", "unit", "note",
];

/// One measurement.
struct Row {
    model: String,
    section: &'static str,
    metric: String,
    threads: Option<usize>,
    value: Option<f64>,
    unit: &'static str,
    note: String,
}

#[derive(Default)]
struct Table {
    rows: Vec<Row>,
}

impl Table {
    /// A row of `section` for `model` (`at` = (model, section)).
    fn push(
        &mut self,
        at: (&str, &'static str),
        metric: impl Into<String>,
        threads: Option<usize>,
        value: f64,
        unit: &'static str,
        note: impl Into<String>,
    ) {
        let (model, section) = at;
        self.rows.push(Row {
            model: model.to_string(),
            section,
            metric: metric.into(),
            threads,
            value: Some(value),
            unit,
            note: note.into(),
        });
    }

    fn note(&mut self, model: &str, section: &'static str, metric: &str, note: String) {
        self.rows.push(Row {
            model: model.to_string(),
            section,
            metric: metric.to_string(),
            threads: None,
            value: None,
            unit: "",
            note,
        });
    }

    fn cells(&self) -> Vec<[String; 7]> {
        self.rows
            .iter()
            .map(|r| {
                [
                    r.model.clone(),
                    r.section.to_string(),
                    r.metric.clone(),
                    r.threads.map_or(String::new(), |t| t.to_string()),
                    r.value.map_or(String::new(), format_value),
                    r.unit.to_string(),
                    r.note.clone(),
                ]
            })
            .collect()
    }

    /// Aligned text, one row per line, headed by [`COLUMNS`].
    fn text(&self) -> String {
        let cells = self.cells();
        let mut width = COLUMNS.map(|c| c.chars().count());
        for row in &cells {
            for (w, c) in width.iter_mut().zip(row) {
                *w = (*w).max(c.chars().count());
            }
        }
        let line = |row: &[String]| {
            let mut s = String::new();
            for (i, (c, w)) in row.iter().zip(width).enumerate() {
                // Numbers right-aligned, the last column unpadded.
                if i == 4 {
                    let _ = write!(s, "{c:>w$}  ");
                } else if i + 1 == row.len() {
                    s.push_str(c);
                } else {
                    let _ = write!(s, "{c:<w$}  ");
                }
            }
            s.trim_end().to_string() + "\n"
        };
        let mut out = line(&COLUMNS.map(String::from));
        for row in &cells {
            out.push_str(&line(row));
        }
        out
    }

    fn csv(&self) -> String {
        let field = |c: &str| {
            if c.contains([',', '"', '\n']) {
                format!("\"{}\"", c.replace('"', "\"\""))
            } else {
                c.to_string()
            }
        };
        let mut out = COLUMNS.join(",") + "\n";
        for row in self.cells() {
            out.push_str(&row.iter().map(|c| field(c)).collect::<Vec<_>>().join(","));
            out.push('\n');
        }
        out
    }
}

/// Four significant digits, no exponent for the usual magnitudes.
fn format_value(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (3 - v.abs().log10().floor() as i32).clamp(0, 6) as usize;
    format!("{v:.digits$}")
}

/// Sizes of one run.
struct Plan {
    /// Procedural strand counts: the scaling pair (small, large).
    strands: [u32; 2],
    /// Rays per kind in the raw measurements.
    rays: usize,
    /// Film of the integrator renders: width = height, spp.
    film: (u32, u32),
    /// BCSDF calls per timing.
    bcsdf_calls: usize,
    /// Timed repetitions of every integrator render and replay; the fastest counts, since
    /// interference from other processes only ever slows a run down.
    runs: usize,
    /// Resolution of the dual-scattering tables whose build time is measured.
    tables: DualScatteringSettings,
    /// Every registered integrator: with test settings for `--quick`, defaults otherwise.
    integrators: Vec<IntegratorDesc>,
}

impl Plan {
    fn new(quick: bool) -> Plan {
        if quick {
            Plan {
                strands: [1_000, 10_000],
                rays: 1 << 12,
                film: (32, 2),
                bcsdf_calls: 20_000,
                runs: 1,
                tables: DualScatteringSettings {
                    theta_nodes: 16,
                    h_nodes: 8,
                    theta_quad: 16,
                    phi_quad: 24,
                    walks: 1024,
                    ..Default::default()
                },
                integrators: IntegratorDesc::all_for_tests(),
            }
        } else {
            Plan {
                strands: [10_000, 100_000],
                rays: 1 << 18,
                film: (128, 8),
                bcsdf_calls: 400_000,
                runs: 3,
                tables: DualScatteringSettings::default(),
                integrators: IntegratorDesc::all(),
            }
        }
    }
}

/// Segments per procedural strand.
const SEGMENTS: u32 = 32;
/// Strands of the `--huge` model.
const HUGE_STRANDS: u32 = 1_000_000;
/// Raw queries handed to a worker at a time (a multiple of the packet width).
const CHUNK: usize = 1024;

/// Where a model's hair comes from.
#[derive(Clone)]
enum Source {
    /// Procedural wavy hair: strands, fiber radius.
    Procedural(u32, f32),
    File(PathBuf),
}

/// Whether the path tracer's ray-rate target applies: the large procedural model (100k strands
/// at the common radius) and the hair file.
fn ray_target(source: &Source, plan: &Plan) -> bool {
    match *source {
        Source::Procedural(n, r) => n == plan.strands[1] && n == 100_000 && r == RADIUS,
        Source::File(_) => true,
    }
}

/// Fiber radius of the procedural models (the procedural default).
const RADIUS: f32 = 0.004;

/// Radius of `strands` fibers covering as much as `reference` fibers of [`RADIUS`] do (equal
/// total cross-section, so equal optical thickness and the same picture).
fn equal_coverage_radius(strands: u32, reference: u32) -> f32 {
    RADIUS * (reference as f32 / strands as f32).sqrt()
}

/// Label of the large procedural model thinned to the small one's coverage.
fn thin_label(strands: u32) -> String {
    format!("{}-thin", strand_label(strands))
}

struct ModelSpec {
    name: String,
    source: Source,
    /// Raw measurements and the integrators' renders; otherwise (the huge model) the path
    /// tracer on a small film only.
    full: bool,
    /// Every integrator, or only the path tracer (the round-curve variants).
    all_integrators: bool,
    curve: CurveShape,
}

fn strand_label(n: u32) -> String {
    if n >= 1_000_000 && n.is_multiple_of(1_000_000) {
        format!("{}M", n / 1_000_000)
    } else if n >= 1000 && n.is_multiple_of(1000) {
        format!("{}k", n / 1000)
    } else {
        n.to_string()
    }
}

pub fn run(args: BenchArgs) -> Result<()> {
    let plan = Plan::new(args.quick);
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
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

    let mut table = Table::default();
    let material = HairModel::Chiang(Default::default());
    let bcsdf = material
        .build()
        .map_err(|e| anyhow!("hair material: {e}"))?;
    eprintln!("bench: BCSDF costs and dual-scattering tables");
    bench_bcsdfs(&mut table, plan.bcsdf_calls)?;
    // Built once here (the integrators fetch them from the process-wide cache) so the build
    // time is measured apart from any render.
    let tables = DualScatteringCache::global()
        .get_or_build(bcsdf.as_ref(), &plan.tables)
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
        .filter(|m| ray_target(&m.source, &plan))
        .map(|m| ModelSpec {
            name: format!("{} round", m.name),
            source: m.source.clone(),
            full: true,
            all_integrators: false,
            curve: CurveShape::Round,
        })
        .collect();
    models.extend(round);

    let mut per_sample: Vec<Timing> = Vec::new();
    for spec in &models {
        bench_model(spec, &plan, &pools, &bcsdf, &mut table, &mut per_sample)
            .with_context(|| format!("model {}", spec.name))?;
    }
    scaling(&mut table, &plan, &per_sample, &pools);

    let text = table.text();
    print!("{text}");
    if let Some(path) = &args.csv {
        crate::atomic_write(path, table.csv().as_bytes())?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// eval, sample and pdf cost of one instance of every registered hair model (the first
/// pigmented test instance, so absorption is exercised).
fn bench_bcsdfs(table: &mut Table, calls: usize) -> Result<()> {
    const INPUTS: usize = 4096;
    let mut rng = Pcg32::new(11, 0);
    let mut dir = || sample_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
    let dirs: Vec<(Vec3, Vec3)> = (0..INPUTS).map(|_| (dir(), dir())).collect();
    let mut rng = Pcg32::new(12, 0);
    let hs: Vec<f32> = (0..INPUTS).map(|_| 2.0 * rng.next_f32() - 1.0).collect();
    let us: Vec<[f32; 4]> = (0..INPUTS)
        .map(|_| std::array::from_fn(|_| rng.next_f32()))
        .collect();
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
        let bcsdf = instance
            .params
            .build()
            .map_err(|e| anyhow!("{}: {e}", instance.name))?;
        let b: &dyn Bcsdf = bcsdf.as_ref();
        let time = |f: &dyn Fn(usize) -> f32| {
            let start = Instant::now();
            let mut acc = 0.0f32;
            for i in 0..calls {
                acc += f(i % INPUTS);
            }
            black_box(acc);
            start.elapsed().as_secs_f64() * 1e9 / calls as f64
        };
        let eval = time(&|i| b.eval(dirs[i].0, dirs[i].1, hs[i]).x);
        let sample = time(&|i| b.sample(dirs[i].0, hs[i], us[i]).map_or(0.0, |s| s.pdf));
        let pdf = time(&|i| b.pdf(dirs[i].0, dirs[i].1, hs[i]));
        let eval_pdf = time(&|i| {
            let (f, pdf) = b.eval_pdf(dirs[i].0, dirs[i].1, hs[i]);
            f.x + pdf
        });
        for (metric, ns) in [
            ("eval", eval),
            ("sample", sample),
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
        .generate()?,
        Source::File(path) => HairFile::new(path).read()?,
    })
}

fn bench_model(
    spec: &ModelSpec,
    plan: &Plan,
    pools: &[(usize, ThreadPool)],
    bcsdf: &Arc<dyn Bcsdf>,
    table: &mut Table,
    per_sample: &mut Vec<Timing>,
) -> Result<()> {
    let name = spec.name.as_str();
    eprintln!("bench: {name}: building");
    let peak_is_per_model = reset_peak_rss();
    let (max_threads, big_pool) = pools.last().map(|(n, p)| (*n, p)).expect("a pool");

    // As `tress render` does: the builds run in the render's thread pool.
    let t0 = Instant::now();
    let hair = load(spec)?;
    let load_time = t0.elapsed();
    let t1 = Instant::now();
    let options = HairOptions {
        curve: spec.curve,
        ..Default::default()
    };
    let accel = big_pool.install(|| SceneBuilder::new()?.add_hair(&hair, &options, 0)?.build())?;
    let bvh_time = t1.elapsed();
    drop(hair);
    // The grid of the first integrator that reads one (its cost is part of the build).
    let grid_settings = plan
        .integrators
        .iter()
        .find_map(IntegratorDesc::density_grid)
        .unwrap_or_default();
    let t2 = Instant::now();
    let grid = big_pool.install(|| DensityGrid::build(&accel, &grid_settings))?;
    let grid_time = t2.elapsed();
    let build_peak = peak_rss();
    // The baseline: the same curves, basis and build quality with no filter support, built
    // after the peak above so that it measures tress's own build.
    let plain = spec
        .full
        .then(|| -> Result<EmbreeAccel> {
            let hair = load(spec)?;
            Ok(big_pool.install(|| {
                SceneBuilder::new()?
                    .without_filters()
                    .add_hair(&hair, &options, 0)?
                    .build()
            })?)
        })
        .transpose()?;

    let info = accel.info().clone();
    let segments = info.segments as f64;
    let build = |t: &mut Table, metric: &str, value: f64, unit: &'static str, note: String| {
        t.push((name, "build"), metric, None, value, unit, note)
    };
    build(table, "strands", info.strands as f64, "", String::new());
    build(table, "segments", segments, "", String::new());
    build(table, "load", load_time.as_secs_f64(), "s", String::new());
    build(
        table,
        "bvh",
        bvh_time.as_secs_f64(),
        "s",
        format!("{max_threads} threads"),
    );
    build(
        table,
        "grid",
        grid_time.as_secs_f64(),
        "s",
        grid.info().to_string(),
    );
    let total = (load_time + bvh_time + grid_time).as_secs_f64();
    let large = name == strand_label(plan.strands[1]) && plan.strands[1] == 100_000;
    build(
        table,
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
        table,
        "accel_bytes_per_segment",
        info.memory_bytes as f64 / segments,
        "B",
        "Embree (BVH, buffers) + hit/filter data".into(),
    );
    build(
        table,
        "grid_bytes_per_segment",
        grid.info().memory_bytes as f64 / segments,
        "B",
        String::new(),
    );
    let scope = if peak_is_per_model {
        "peak since this model started"
    } else {
        "process peak (VmHWM reset unsupported)"
    };
    if let Some(peak) = build_peak {
        let peak_mib = peak as f64 / MIB;
        build(
            table,
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

    let (film_side, spp) = if spec.full { plan.film } else { (64, 1) };
    let camera = framing(&info.bounds);
    let film = FilmSettings {
        width: film_side,
        height: film_side,
        spp,
        seed: 1,
        crop: None,
    };
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
    let scene = Scene {
        camera,
        accel: Box::new(CountingAccel {
            inner: Arc::clone(&accel),
            record: Arc::clone(&recording),
        }),
        materials: vec![Material::Hair(Arc::clone(bcsdf))],
        lights: vec![Light::Environment(EnvironmentMap::builtin_sky(0.0, 1.0)?)],
        density: Some(Box::new(grid)),
    };
    // The ray-rate target and the huge and round models concern the path tracer.
    let descs: Vec<IntegratorDesc> = if spec.all_integrators {
        plan.integrators.clone()
    } else {
        plan.integrators
            .iter()
            .filter(|d| d.name() == "path")
            .cloned()
            .collect()
    };
    let render_pools: Vec<&(usize, ThreadPool)> = if spec.full {
        pools.iter().collect()
    } else {
        pools.iter().rev().take(1).collect()
    };
    for desc in &descs {
        let integrator = desc
            .build(&scene)
            .map_err(|e| anyhow!("integrator {}: {e:#}", desc.name()))?;
        // An untimed pass records every ray the integrator traces (it also warms up); the
        // timed renders below repeat exactly that work (the image depends only on the seed).
        let recorded = if spec.full {
            eprintln!("bench: {name}: {}: recording its rays", desc.name());
            Some(record_rays(
                &scene,
                integrator.as_ref(),
                &film,
                big_pool,
                &recording,
            ))
        } else {
            None
        };
        for (n, pool) in render_pools.iter().map(|(n, p)| (*n, p)) {
            eprintln!("bench: {name}: {} on {n} thread(s)", desc.name());
            let r = (0..plan.runs)
                .map(|_| render(&scene, integrator.as_ref(), &film, pool))
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
                .zip(accels.as_ref())
                .map(|(rays, accels)| replay(accels, rays, pool, desc.name(), plan.runs));
            report_render(
                table,
                RenderReport {
                    model: name,
                    integrator: desc.name(),
                    threads: n,
                    ray_target: ray_target(&spec.source, plan),
                },
                &r,
                raw.as_ref(),
                replay.as_deref(),
            );
        }
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

fn target(what: &str, met: bool) -> String {
    format!("target {what}: {}", if met { "met" } else { "MISSED" })
}

/// The three kinds of ray, as in a render: camera rays through the film, and rays leaving hair
/// hit points (found by random walks from the camera) in uniformly random directions — as
/// closest-hit queries (bounce) and as visibility queries to infinity (shadow).
struct RaySets {
    camera: Vec<RawRay>,
    bounce: Vec<RawRay>,
    shadow: Vec<RawRay>,
}

impl RaySets {
    fn new(accel: &EmbreeAccel, camera: &Camera, film: &FilmSettings, n: usize) -> Result<Self> {
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
enum Mode {
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
    fn name(self) -> &'static str {
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
enum Kind {
    Camera,
    Bounce,
    Shadow,
}

impl Kind {
    const ALL: [Kind; 3] = [Kind::Camera, Kind::Bounce, Kind::Shadow];

    fn name(self) -> &'static str {
        match self {
            Kind::Camera => "camera",
            Kind::Bounce => "bounce",
            Kind::Shadow => "shadow",
        }
    }
}

/// Raw rays/s by (kind, mode, threads).
struct RawRates(Vec<(Kind, Mode, usize, f64)>);

impl RawRates {
    fn get(&self, kind: Kind, mode: Mode, threads: usize) -> Option<f64> {
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
    fn mix(&self, counts: [u64; 3], mode: Mode, threads: usize) -> Option<f64> {
        let mut seconds = 0.0;
        for (kind, &n) in Kind::ALL.iter().zip(&counts) {
            if n > 0 {
                seconds += n as f64 / self.get(*kind, mode, threads)?;
            }
        }
        (seconds > 0.0).then(|| counts.iter().sum::<u64>() as f64 / seconds)
    }
}

fn bench_raw(
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
struct Accels {
    tress: Arc<EmbreeAccel>,
    plain: EmbreeAccel,
}

/// Traces a chunk of rays; returns how many hit (or are blocked).
fn trace_chunk(accels: &Accels, kind: Kind, mode: Mode, rays: &[RawRay]) -> u64 {
    let closest = kind != Kind::Shadow;
    let accel = if mode == Mode::Plain {
        &accels.plain
    } else {
        &*accels.tress
    };
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

/// Query kinds counted and recorded by [`CountingAccel`].
const CAMERA: usize = 0;
const BOUNCE: usize = 1;
const SHADOW: usize = 2;

thread_local! {
    /// Queries on this thread, by kind.
    static QUERIES: Cell<[u64; 3]> = const { Cell::new([0; 3]) };
    /// Rays traced on this thread while recording, with their kind.
    static RECORDED: RefCell<Vec<(usize, Ray)>> = const { RefCell::new(Vec::new()) };
}

/// The accelerator with its queries counted by kind, and recorded on demand: closest-hit
/// queries leaving no primitive are camera rays (the bench scenes hold only hair, so every
/// other ray leaves one).
struct CountingAccel {
    inner: Arc<EmbreeAccel>,
    record: Arc<AtomicBool>,
}

impl CountingAccel {
    fn note(&self, kind: usize, ray: &Ray) {
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
}

/// Queries counted on every thread of `pool`.
fn queries(pool: &ThreadPool) -> [u64; 3] {
    pool.broadcast(|_| QUERIES.with(Cell::get))
        .into_iter()
        .fold([0; 3], |a, b| std::array::from_fn(|i| a[i] + b[i]))
}

/// "hit 59.0%, 1.234 M/CPU-s, 12% waiting"-style note of a raw measurement.
fn cost_note(rays: usize, cost: &Cost) -> String {
    let mut note = String::new();
    if let Some(cpu) = cost.cpu.filter(|&c| c > 0.0) {
        let _ = write!(note, "{:.3} M per CPU-s", rays as f64 / cpu / 1e6);
    }
    if let Some(w) = cost.waiting() {
        let _ = write!(note, ", {:.0}% waiting for a core", 100.0 * w);
    }
    note
}

/// Seconds per sample and per traced ray of one render.
struct Timing {
    model: String,
    integrator: &'static str,
    threads: usize,
    per_sample: f64,
    per_ray: f64,
    cpu_per_sample: Option<f64>,
    waiting: Option<f64>,
}

struct RenderRun {
    cost: Cost,
    samples: u64,
    /// Camera, bounce, shadow rays traced.
    traced: [u64; 3],
}

fn render(
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
fn record_rays(
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

/// A replay of an integrator's recorded rays: rays/s and the cost, per mode.
struct Replay {
    mode: Mode,
    rays: usize,
    rate: f64,
    cost: Cost,
}

/// Traces the recorded rays again, raw, in chunks of the recorded order.
fn replay(
    accels: &Accels,
    rays: &[(usize, Ray)],
    pool: &ThreadPool,
    integrator: &str,
    runs: usize,
) -> Vec<Replay> {
    eprintln!("bench:   replaying {} rays of {integrator}", rays.len());
    [Mode::Plain, Mode::Embree1, Mode::Embree1Excl, Mode::Accel]
        .into_iter()
        .map(|mode| {
            let accel = if mode == Mode::Plain {
                &accels.plain
            } else {
                &*accels.tress
            };
            let exclusion = if mode == Mode::Embree1Excl {
                Exclusion::Tress
            } else {
                Exclusion::Off
            };
            let chunk = |c: &[(usize, Ray)]| -> u64 {
                c.iter()
                    .map(|(kind, ray)| {
                        let r = RawRay {
                            ray: *ray,
                            t_near: 0.0,
                        };
                        u64::from(match (mode, *kind) {
                            (Mode::Accel, SHADOW) => accel.occluded(ray),
                            (Mode::Accel, _) => accel.intersect(ray).is_some(),
                            (_, SHADOW) => accel.raw_occluded(&r, exclusion),
                            _ => accel.raw_intersect(&r, exclusion).is_some(),
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
                mode,
                rays: rays.len(),
                rate: rays.len() as f64 / cost.wall,
                cost,
            }
        })
        .collect()
}

#[derive(Clone, Copy)]
struct RenderReport<'a> {
    model: &'a str,
    integrator: &'static str,
    threads: usize,
    /// Whether the path tracer's ray-rate target applies (the large procedural model and the
    /// hair file).
    ray_target: bool,
}

fn report_render(
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
    let with_target = |note: String, ratio: f64, mode: Mode| {
        if path_target && mode == Mode::Plain {
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
fn scaling(table: &mut Table, plan: &Plan, per_sample: &[Timing], pools: &[(usize, ThreadPool)]) {
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
