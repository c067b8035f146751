//! Study files: what a study compares (see the module documentation of [`crate::study`]).

use crate::error::{Error, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use tress_loader::integrators::IntegratorDesc;
use tress_loader::ron_format::SyntaxError;
use tress_loader::scene_desc::SceneDesc;

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
    let text = tress_core::files::read_regular_text(path).map_err(|source| Error::Read {
        path: path.to_owned(),
        source,
    })?;
    tress_loader::ron_format::options()
        .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
        .from_str::<Study>(&text)
        .map_err(|e| Error::Syntax {
            path: path.to_owned(),
            error: Box::new(SyntaxError::new(&text, e)),
        })
}
