//! What a study measured: errors of every render, and what its figures show.

use crate::metrics::{self, Rect};
use crate::picture::Picture;
use crate::plan::{Plan, PlanScene};
use std::collections::HashMap;

/// Errors of one render against one reference over one region.
#[derive(Clone, Copy, Debug)]
pub(super) struct Errors {
    pub(super) mse: f64,
    pub(super) relmse: f64,
    pub(super) mean: f64,
    pub(super) ref_mean: f64,
}

impl From<&metrics::Metrics> for Errors {
    fn from(m: &metrics::Metrics) -> Self {
        Errors {
            mse: m.mse_all(),
            relmse: m.relmse_all(),
            mean: m.mean_a_all(),
            ref_mean: m.mean_b_all(),
        }
    }
}

/// Which reference a render is compared with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RefKind {
    /// The study's common reference.
    Common,
    /// The integrator's own converged render.
    Own,
}

impl RefKind {
    /// As `results.csv` and `summary.csv` write it.
    pub fn name(self) -> &'static str {
        match self {
            RefKind::Common => "common",
            RefKind::Own => "own",
        }
    }
}

/// One line of results.csv.
pub(super) struct Row {
    pub(super) scene: usize,
    pub(super) integrator: usize,
    pub(super) spp: u32,
    pub(super) rep: u32,
    pub(super) seed: u64,
    pub(super) time_s: f64,
    pub(super) wall_s: f64,
    pub(super) precompute_s: f64,
    pub(super) rays: u64,
    pub(super) reference: RefKind,
    pub(super) whole: Errors,
    pub(super) regions: Vec<Errors>,
}

/// What the figures need from one scene.
pub struct SceneFigures {
    /// Per integrator: the relative error map at `heatmap_spp`, repetition 0, row-major over
    /// the film.
    pub heat: Vec<Option<Vec<f32>>>,
    /// Crops of repetition 0, by sheet region, integrator and spp index.
    pub crops: Vec<Vec<Vec<Option<Picture>>>>,
    /// The common reference's crop, by sheet region.
    pub ref_crops: Vec<Picture>,
    /// The crops of the integrators' own references, by sheet region and integrator.
    pub own_crops: Vec<Vec<Option<Picture>>>,
}

/// What a study measured.
pub struct Results {
    /// One per render and reference it is compared with: the lines of `results.csv`.
    pub(super) rows: Vec<Row>,
    /// MSE of the mean image of the repetitions, by (scene, integrator, spp, reference).
    pub(super) mean_mse: HashMap<(usize, usize, u32, RefKind), f64>,
    /// Per scene, what its figures show.
    pub figures: Vec<SceneFigures>,
    /// Renders done by this run.
    pub rendered: usize,
    /// Finished renders of an earlier run read back instead.
    pub reused: usize,
    /// CPU seconds of this run's renders.
    pub render_seconds: f64,
}

/// Sheet regions: the study's regions, or the whole film when it names none.
pub fn sheet_regions(plan: &Plan, scene: &PlanScene) -> Vec<(String, Rect)> {
    if plan.region_names.is_empty() {
        let f = &scene.desc.film;
        vec![(
            "full".into(),
            Rect {
                x: 0,
                y: 0,
                w: f.width,
                h: f.height,
            },
        )]
    } else {
        plan.region_names
            .iter()
            .cloned()
            .zip(scene.regions.iter().copied())
            .collect()
    }
}
