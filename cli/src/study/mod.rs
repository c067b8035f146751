//! `tress study STUDY.ron`: comparative convergence studies of integrators, following the
//! protocol of hair-math.md §7.2 — an independent converged reference, MSE and relative MSE,
//! K repetitions with independent seeds and 95 % confidence intervals, equal-spp and equal-time
//! comparisons, efficiency and the MSE·spp convergence check.
//!
//! A study file (RON; paths relative to it):
//!
//! ```ron
//! (
//!     scenes: [File("scene_straight_brown_venice.ron"),
//!              Inline(name: "ball", scene: (camera: (...), film: (...), materials: {...}, objects: [...], lights: [...]))],
//!     integrators: [DualUniform(), DualMis(), Path(max_depth: 100)],
//!     spp: [1, 2, 4, 8, 16, 32, 64, 128, 256, 512],
//!     repetitions: 8,                // K independent runs per (scene, integrator, spp)
//!     seed: 1,                       // base seed of every derived seed
//!     reference: Render(integrator: Path(max_depth: 100), spp: 32768),  // or Exr("refs/{scene}.exr")
//!     references: PerIntegrator(spp: 8192),   // also each integrator's own converged render
//!     regions: [(name: "fringe", x: 40, y: 100, w: 32, h: 32)],        // film pixels
//!     film: (width: 256, height: 256),         // resolution override for every scene
//!     heatmap_spp: 16,               // error heat maps at this spp (default: the middle one)
//!     target_relmse: 0.01,           // "time to reach this relMSE" in the report
//!     exposure: 0.0,                 // of the PNG previews and crop sheets, in stops
//!     output: "results/straight",    // default: ./<study name>_study in the current folder
//!     quick: (spp: [1, 2, 4], repetitions: 2, reference_spp: 256, film: (width: 48, height: 48)),
//! )
//! ```
//!
//! Every render is an EXR (plus a PNG preview) under `renders/<scene>/`, carrying its settings
//! hash, render time (CPU and wall) and ray count as header attributes, so a rerun reads finished renders back
//! instead of redoing them. The seed of a render is a hash of the base seed, the scene name,
//! the integrator settings, spp and repetition; references hash a different tag, so they are
//! independent of every test render.

use crate::cost::timed;
use crate::diff::{self, Rect, REL_EPSILON};
use crate::plot::{self, Chart, HeatPanel, Picture, Series};
use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use indicatif::ProgressBar;
use serde::Deserialize;
use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tress_core::film::FilmSettings;
use tress_core::image_io;
use tress_core::rng::hash_words;
use tress_core::{Image, Integrator};
use tress_scene::integrators::IntegratorDesc;
use tress_scene::scene_desc::{self, BuiltScene, SceneDesc};

mod measure;
mod plan;
mod plots;
mod render;
mod report;
mod stats;
use measure::*;
use plan::*;
use plots::*;
use render::*;
use report::*;
use stats::*;

#[derive(Args, Debug)]
pub struct StudyArgs {
    /// Study file (RON).
    pub study: PathBuf,
    /// Scaled-down run for smoke tests: the study's `quick` section, or by default spp ≤ 16,
    /// at most 3 repetitions, lighter references and films of at most 64 pixels a side.
    #[arg(long)]
    pub quick: bool,
    /// Output folder (default: the study's `output`, else ./<study name>_study; `_quick` is
    /// appended for --quick).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Worker threads (default: all cores). Images do not depend on it.
    #[arg(long, value_parser = crate::parse_threads)]
    pub threads: Option<usize>,
    /// No progress bar and no summary.
    #[arg(long)]
    pub quiet: bool,
}

/// A study file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Study {
    /// Report title; default: the file name.
    #[serde(default)]
    pub name: Option<String>,
    pub scenes: Vec<SceneRef>,
    /// The integrators compared; the first is the baseline of the ratio tables.
    pub integrators: Vec<IntegratorDesc>,
    /// Samples per pixel, strictly increasing.
    pub spp: Vec<u32>,
    #[serde(default = "default_repetitions")]
    pub repetitions: u32,
    #[serde(default)]
    pub seed: u64,
    pub reference: Reference,
    #[serde(default)]
    pub references: References,
    #[serde(default)]
    pub regions: Vec<RegionDesc>,
    #[serde(default)]
    pub film: Option<FilmOverride>,
    #[serde(default)]
    pub output: Option<PathBuf>,
    #[serde(default)]
    pub heatmap_spp: Option<u32>,
    #[serde(default = "default_target")]
    pub target_relmse: f64,
    #[serde(default)]
    pub exposure: f32,
    #[serde(default)]
    pub quick: Quick,
}

fn default_repetitions() -> u32 {
    8
}

fn default_target() -> f64 {
    1e-2
}

/// A scene of the study; its own integrator, spp, seed and crop are ignored.
#[derive(Debug, Deserialize)]
pub enum SceneRef {
    /// A scene file; named by its file stem.
    File(PathBuf),
    /// A scene written in the study file (relative paths resolve against the study file).
    Inline { name: String, scene: Box<SceneDesc> },
}

/// The common reference every render is compared with.
#[derive(Debug, Deserialize)]
pub enum Reference {
    /// Rendered once per scene (cached in the output folder) with its own seed.
    Render {
        integrator: IntegratorDesc,
        spp: u32,
    },
    /// An EXR file per scene; `{scene}` in the path is replaced by the scene name.
    Exr(String),
}

/// Extra references.
#[derive(Debug, Default, Deserialize)]
pub enum References {
    /// Only the common reference.
    #[default]
    Common,
    /// Also compare each integrator with its own converged render at `spp` (no bias there, so
    /// it separates variance from bias).
    PerIntegrator { spp: u32 },
}

/// A named region of interest, in film pixels.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionDesc {
    pub name: String,
    pub x: u32,
    pub y: u32,
    pub w: u32,
    pub h: u32,
}

/// Film resolution for every scene of the study (the camera keeps its field of view).
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilmOverride {
    pub width: u32,
    pub height: u32,
}

/// What `--quick` changes; unset fields get scaled-down defaults.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Quick {
    pub spp: Option<Vec<u32>>,
    pub repetitions: Option<u32>,
    pub reference_spp: Option<u32>,
    pub per_integrator_spp: Option<u32>,
    pub film: Option<FilmOverride>,
}

/// Reads and parses a study file; errors name the file, line and column.
pub fn load(path: &Path) -> Result<Study> {
    let text = tress_core::files::read_regular_text(path)
        .with_context(|| format!("cannot read study file {}", path.display()))?;
    tress_scene::ron_options()
        .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
        .from_str::<Study>(&text)
        .map_err(|e| {
            let p = e.span.start;
            let mut msg = format!("{}:{}:{}: {}", path.display(), p.line, p.col, e.code);
            if let Some(line) = text.lines().nth(p.line.saturating_sub(1)) {
                let caret = " ".repeat(line.chars().take(p.col.saturating_sub(1)).count());
                let _ = write!(msg, "\n    {line}\n    {caret}^");
            }
            anyhow!(msg)
        })
}

/// What a study wrote, and how much of it this run rendered.
#[derive(Clone, Debug)]
pub struct StudyOutputs {
    /// The output folder.
    pub folder: PathBuf,
    /// `report.md`: the summary over scenes, then per-scene tables and figures.
    pub report: PathBuf,
    /// `results.csv`: one row per render, with its errors and costs.
    pub results_csv: PathBuf,
    /// `summary.csv`: one row per scene, integrator, spp and reference, over the repetitions.
    pub summary_csv: PathBuf,
    /// Renders done by this run.
    pub rendered: u64,
    /// Finished renders of an earlier run that were read back instead.
    pub reused: u64,
}

pub fn run(args: StudyArgs) -> Result<StudyOutputs> {
    let study = load(&args.study)?;
    let plan = Plan::new(study, &args)?;
    let verbose = !args.quiet;
    std::fs::create_dir_all(&plan.out)
        .with_context(|| format!("creating output folder {}", plan.out.display()))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("creating the thread pool")?;
    let bar = crate::render_cmd::progress_bar(plan.total_samples(), verbose, "study ");
    let res = execute(&plan, &pool, &bar, verbose);
    bar.finish_and_clear();
    let res = res?;

    let csv = write_csv(&plan, &res)?;
    write_summary(&plan, &res)?;
    let mut outputs = Vec::new();
    for si in 0..plan.scenes.len() {
        let plots = write_plots(&plan, &res, si)?;
        let (heat, scale, sheets) = write_figures(&plan, &res, si)?;
        outputs.push(SceneOutputs {
            plots,
            heat,
            scale,
            sheets,
        });
    }
    let report = write_report(&plan, &res, &outputs)?;
    let renders = plan.scenes.len() * plan.integrators.len() * plan.spp.len() * plan.reps as usize;
    // The summary of `--log-format json`.
    crate::logging::record("output", &plan.out);
    crate::logging::record("report", &report);
    crate::logging::record("results_csv", &csv);
    crate::logging::record("jobs", renders);
    crate::logging::record("rendered", res.rendered);
    crate::logging::record("reused", res.reused);
    crate::logging::record("render_s", res.render_seconds);
    if verbose {
        eprintln!(
            "study '{}': {} scenes × {} integrators × {} spp × {} repetitions = {renders} renders \
             plus references: rendered {}, reused {} ({:.2} s rendering)",
            plan.title,
            plan.scenes.len(),
            plan.integrators.len(),
            plan.spp.len(),
            plan.reps,
            res.rendered,
            res.reused,
            res.render_seconds
        );
        eprintln!(
            "wrote {}, {}, plots in {}, crop sheets in {}",
            csv.display(),
            report.display(),
            plan.out.join("plots").display(),
            plan.out.join("sheets").display()
        );
    }
    Ok(StudyOutputs {
        folder: plan.out.clone(),
        report,
        results_csv: csv,
        summary_csv: plan.out.join("summary.csv"),
        rendered: res.rendered as u64,
        reused: res.reused as u64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn student_t_quantiles() {
        // Tabulated values (to the table's three decimals).
        for (df, want) in [
            (1, 12.706),
            (2, 4.303),
            (30, 2.042),
            (40, 2.021),
            (120, 1.980),
        ] {
            assert!((t975(df) - want).abs() < 1e-3, "t975({df}) = {}", t975(df));
        }
        let s = stat(&[1.0, 2.0, 3.0]);
        assert_eq!(s.mean, 2.0);
        assert!((s.ci.unwrap() - 4.303 / 3f64.sqrt()).abs() < 1e-3);
        assert!(stat(&[5.0]).ci.is_none());
    }

    #[test]
    fn log_log_interpolation() {
        let pts = [(1.0, 1.0), (100.0, 1e-2), (10.0, 1e-1)];
        assert!(
            (loglog_at(&pts, 31.622_776_601_683_793).unwrap() - 10f64.powf(-1.5)).abs() < 1e-12
        );
        assert_eq!(loglog_at(&pts, 0.5), None);
        assert_eq!(loglog_at(&pts, 100.0), Some(1e-2));
    }

    fn pt(spp: u32, mse: f64, time_s: f64) -> Point {
        let s = Stat {
            mean: mse,
            ci: None,
        };
        Point {
            spp,
            mse: s,
            relmse: s,
            time_s,
            bias2: None,
        }
    }

    #[test]
    fn verdicts_and_time_to_target() {
        let unbiased: Vec<Point> = [1, 4, 16, 64]
            .iter()
            .map(|&n| pt(n, 1.0 / n as f64, n as f64))
            .collect();
        assert!(verdict(&unbiased, None).starts_with("flat"));
        let biased: Vec<Point> = [1, 4, 16, 64]
            .iter()
            .map(|&n| pt(n, 1.0 / n as f64 + 0.1, n as f64))
            .collect();
        assert!(verdict(&biased, None).contains("error floor"));
        // Reference noise alone is not taken for bias once subtracted.
        let noisy: Vec<Point> = [1, 4, 16, 64]
            .iter()
            .map(|&n| pt(n, 1.0 / n as f64 + 0.02, n as f64))
            .collect();
        assert!(verdict(&noisy, None).contains("error floor"));
        assert!(verdict(&noisy, Some(0.02)).starts_with("flat"));
        // With a bias estimate the floor is attributed: to bias when bias² dominates the MSE…
        let mut split = biased.clone();
        split[3].bias2 = Some(0.1);
        assert!(verdict(&split, None).starts_with("**bias**"));
        // …and to heavy-tailed variance when the mean image is as close as 1/K predicts.
        split[3].bias2 = Some(0.001);
        assert!(verdict(&split, None).starts_with("**excess variance**"));
        // A bias that dominates at the highest spp is reported even before MSE·spp rises.
        let mut early = unbiased.clone();
        early[3].bias2 = Some(0.6 / 64.0);
        assert!(verdict(&early, None).starts_with("**bias**"));
        early[3].bias2 = Some(0.3 / 64.0);
        assert!(verdict(&early, None).starts_with("flat"));
        // relMSE 1/N reaches 0.1 at 10 spp and 10 s.
        match reach(&unbiased, 0.1) {
            Reach::At(spp, t) => {
                assert!((spp - 10.0).abs() < 1e-9 && (t - 10.0).abs() < 1e-9);
            }
            _ => panic!("target not found"),
        }
        assert!(matches!(reach(&unbiased, 2.0), Reach::AtOnce(1, _)));
        assert!(matches!(reach(&unbiased, 1e-3), Reach::Never(_)));
        // Short of it, 1/N from the last setting (relMSE 1/64 at 64 spp and 64 s) gets there at
        // 1000 spp and 1000 s; a reached target is not extrapolated.
        let (spp, t) = extrapolated_reach(&unbiased, 1e-3).unwrap();
        assert!(
            (spp - 1000.0).abs() < 1e-6 && (t - 1000.0).abs() < 1e-6,
            "{spp} {t}"
        );
        assert!(extrapolated_reach(&unbiased, 0.1).is_none());
    }

    #[test]
    fn seeds_are_distinct_and_stable() {
        let a = test_seed(1, "s", "Path(())", 4, 0);
        assert_eq!(a, test_seed(1, "s", "Path(())", 4, 0));
        let others = [
            test_seed(2, "s", "Path(())", 4, 0),
            test_seed(1, "t", "Path(())", 4, 0),
            test_seed(1, "s", "Path((max_depth:8))", 4, 0),
            test_seed(1, "s", "Path(())", 8, 0),
            test_seed(1, "s", "Path(())", 4, 1),
            reference_seed(1, "s", "Path(())", 4),
        ];
        assert!(others.iter().all(|&o| o != a));
    }
}
