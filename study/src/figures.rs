//! The figures of a study's report, drawn by whoever can draw.

use crate::error::FiguresError;
use crate::plan::Plan;
use crate::results::Results;

/// Draws a study's figures — convergence plots, error heat maps, crop sheets — for its report.
/// This library draws none (it has no plotting); `tress study` passes its plotters drawing.
pub trait Figures {
    /// Writes the figures of scene `scene` (an index into `plan.scenes`) under `plan.out`, and
    /// says which files the report links to.
    fn draw(
        &self,
        plan: &Plan,
        results: &Results,
        scene: usize,
    ) -> Result<FigureFiles, FiguresError>;
}

/// The figure files of one scene, relative to the output folder.
pub struct FigureFiles {
    /// Convergence plots: stems of a PNG (which the report shows) and an SVG each.
    pub plots: Vec<String>,
    /// The relative error heat maps at [`Plan::heatmap_spp`] (a PNG).
    pub heat_map: String,
    /// The log colour scale of the heat maps, (black, pale yellow).
    pub heat_scale: (f64, f64),
    /// Crop sheets (PNGs), one per sheet region.
    pub sheets: Vec<String>,
}
