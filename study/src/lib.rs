//! tress-study: comparative convergence studies of integrators (`tress study STUDY.ron`;
//! `tress.study` in Python), and the image error metrics ([`metrics`]) they and `tress diff`
//! share. A study follows the measurement protocol of the book
//! (`docs/src/reference/hair-maths.md#measuring-an-estimator`) — an independent converged reference,
//! MSE and relative MSE, K repetitions with independent seeds and 95 % confidence intervals,
//! equal-spp and equal-time comparisons, efficiency and the MSE·spp convergence check. The
//! figures (plots, heat maps, crop sheets) are drawn by the caller, through [`Figures`].
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

#![warn(missing_docs)]

pub mod cost;
mod error;
mod execute;
mod figures;
mod file;
pub mod metrics;
pub mod picture;
mod plan;
mod progress;
mod render;
mod results;
mod stats;
mod tables;

pub use figures::{FigureFiles, Figures};
pub use plan::{Plan, PlanIntegrator, PlanReference, PlanScene, StudySettings};
pub use progress::{NotesOnStderr, Progress};
pub use results::{sheet_regions, RefKind, Results, SceneFigures};
pub use stats::{curve, Point, Stat};

pub use error::{Error, FiguresError, Result, SceneError};
use std::path::PathBuf;

/// What a study wrote, and how much of it this run rendered.
#[derive(Clone, Debug)]
pub struct StudyOutputs {
    /// The output folder.
    pub folder: PathBuf,
    /// `report.md`: the summary over scenes, then per-scene tables and, when drawn, figures.
    pub report: PathBuf,
    /// `results.csv`: one row per render, with its errors and costs.
    pub results_csv: PathBuf,
    /// `summary.csv`: one row per scene, integrator, spp and reference, over the repetitions.
    pub summary_csv: PathBuf,
    /// Renders the study compares (scenes × integrators × spp × repetitions), references aside.
    pub jobs: u64,
    /// Renders done by this run.
    pub rendered: u64,
    /// Finished renders of an earlier run that were read back instead.
    pub reused: u64,
    /// CPU seconds of this run's renders.
    pub render_seconds: f64,
}

/// Runs a study: renders what an earlier run in the output folder did not (reading the rest
/// back), measures every render, and writes `results.csv`, `summary.csv` and `report.md` —
/// with figures when `figures` draws them. `progress` hears of the samples done and gets the
/// notes for people.
pub fn run(
    settings: &StudySettings,
    progress: &dyn Progress,
    figures: Option<&dyn Figures>,
) -> Result<StudyOutputs> {
    let study = file::load(&settings.study)?;
    let plan = Plan::new(study, settings)?;
    std::fs::create_dir_all(&plan.out).map_err(|source| Error::CreateFolder {
        path: plan.out.clone(),
        source,
    })?;
    tables::check_outputs(&plan)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(settings.threads.unwrap_or(0))
        .build()
        .map_err(Error::ThreadPool)?;
    progress.start(plan.total_samples());
    let res = execute::execute(&plan, &pool, progress, settings);
    progress.finish();
    let res = res?;

    let csv = tables::write_csv(&plan, &res)?;
    let summary = tables::write_summary(&plan, &res)?;
    let drawn = match figures {
        Some(figures) => Some(
            (0..plan.scenes.len())
                .map(|si| figures.draw(&plan, &res, si).map_err(Error::Figures))
                .collect::<Result<Vec<_>>>()?,
        ),
        None => None,
    };
    let report = tables::write_report(&plan, &res, drawn.as_deref())?;
    let jobs = plan.scenes.len() * plan.integrators.len() * plan.spp.len() * plan.reps as usize;
    if settings.verbose {
        progress.note(&format!(
            "study '{}': {} scenes × {} integrators × {} spp × {} repetitions = {jobs} renders \
             plus references: rendered {}, reused {} ({:.2} s rendering)",
            plan.title,
            plan.scenes.len(),
            plan.integrators.len(),
            plan.spp.len(),
            plan.reps,
            res.rendered,
            res.reused,
            res.render_seconds
        ));
        let figures = match drawn {
            Some(_) => format!(
                ", plots in {}, crop sheets in {}",
                plan.out.join("plots").display(),
                plan.out.join("sheets").display()
            ),
            None => String::new(),
        };
        progress.note(&format!(
            "wrote {}, {}{figures}",
            csv.display(),
            report.display()
        ));
    }
    Ok(StudyOutputs {
        folder: plan.out.clone(),
        report,
        results_csv: csv,
        summary_csv: summary,
        jobs: jobs as u64,
        rendered: res.rendered as u64,
        reused: res.reused as u64,
        render_seconds: res.render_seconds,
    })
}
