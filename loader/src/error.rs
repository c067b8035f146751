//! The error type of `tress-loader`. Every variant names the scene file and, where there is
//! one, the place in it (line and column, `objects[i]`, `lights[i]`, a material); a variant
//! caused by another error keeps it as its source and leaves its text to it, so that a chain
//! printed whole (`{:#}`, as the command line prints errors) names each cause once.

use crate::ron_format::SyntaxError;
use glam::Vec3;
use std::path::PathBuf;
use tress_materials::ParamError;

/// Why a scene could not be loaded or built.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The scene file could not be read.
    #[error("cannot read scene file {}", path.display())]
    Read {
        /// The scene file.
        path: PathBuf,
        /// The operating system's error (or invalid UTF-8).
        #[source]
        source: std::io::Error,
    },
    /// A `${name}` placeholder could not be filled, or a define is not used.
    #[error("{}:{message}", path.display())]
    Placeholder {
        /// The scene file.
        path: PathBuf,
        /// `line:column: what`, or ` -D name: what` for an unused define.
        message: String,
    },
    /// The text is not a valid scene description.
    #[error("{}:{error}", path.display())]
    Syntax {
        /// The scene file.
        path: PathBuf,
        /// Where and what (boxed: RON's error is large, and every result of the crate would
        /// carry its size).
        error: Box<SyntaxError>,
    },
    /// A `-D name=value` is given twice.
    #[error("-D {name} is given twice ({name}={first} and {name}={second}): give it once")]
    DefinedTwice {
        /// The placeholder's name.
        name: String,
        /// The first value.
        first: String,
        /// The second value.
        second: String,
    },
    /// The files of a hair object could not be listed (a pbrt groom's includes).
    #[error("{}", scene.display())]
    HairFiles {
        /// The scene file.
        scene: PathBuf,
        /// The groom reader's error.
        #[source]
        source: tress_groom::Error,
    },
    /// A file the scene reads could not be read to hash its contents.
    #[error("{}: {}", scene.display(), file.display())]
    Input {
        /// The scene file.
        scene: PathBuf,
        /// The file it reads.
        file: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The camera's settings are invalid.
    #[error("{}", scene.display())]
    Camera {
        /// The scene file.
        scene: PathBuf,
        /// What is wrong with them.
        #[source]
        source: tress_core::camera::CameraError,
    },
    /// A hair material's parameters are invalid.
    #[error("{}: material '{name}'", scene.display())]
    HairMaterial {
        /// The scene file.
        scene: PathBuf,
        /// The material's name.
        name: String,
        /// What is wrong with its parameters.
        #[source]
        source: ParamError,
    },
    /// A diffuse material's albedo lies outside [0, 1].
    #[error("{}: material '{name}': albedo {albedo} must lie in [0, 1]", scene.display())]
    Albedo {
        /// The scene file.
        scene: PathBuf,
        /// The material's name.
        name: String,
        /// The albedo given.
        albedo: Vec3,
    },
    /// A light's environment map could not be read (or the built-in sky made).
    #[error("{}: lights[{index}]", scene.display())]
    EnvironmentMap {
        /// The scene file.
        scene: PathBuf,
        /// The light's index in `lights`.
        index: usize,
        /// Why.
        #[source]
        source: tress_core::image_io::ImageError,
    },
    /// A light's parameters make no light.
    #[error("{}: lights[{index}]", scene.display())]
    Light {
        /// The scene file.
        scene: PathBuf,
        /// The light's index in `lights`.
        index: usize,
        /// What is wrong with them.
        #[source]
        source: tress_core::light::LightError,
    },
    /// An object could not be loaded or added to the scene.
    #[error("{}: objects[{index}]", scene.display())]
    Object {
        /// The scene file.
        scene: PathBuf,
        /// The object's index in `objects`.
        index: usize,
        /// Why (boxed: the groom and Embree errors are large, and every result of the crate
        /// would carry their size).
        #[source]
        source: Box<ObjectError>,
    },
    /// The integrator could not be built for the scene.
    #[error("{}", scene.display())]
    Integrator {
        /// The scene file.
        scene: PathBuf,
        /// Why.
        #[source]
        source: crate::integrators::IntegratorError,
    },
    /// Embree could not start or build the scene's geometry.
    #[error("{}", scene.display())]
    Accel {
        /// The scene file.
        scene: PathBuf,
        /// Embree's error, or the memory limit's.
        #[source]
        source: tress_accel::Error,
    },
}

/// Why an object could not be loaded or added to the scene.
#[derive(Debug, thiserror::Error)]
pub enum ObjectError {
    /// It names a material the scene does not define.
    #[error("unknown material '{name}' (defined: {})", defined.join(", "))]
    UnknownMaterial {
        /// The name given.
        name: String,
        /// The names the scene defines.
        defined: Vec<String>,
    },
    /// Hair names a material that is no hair model.
    #[error("hair needs a Hair(...) material, but '{name}' is not one")]
    NotHairMaterial {
        /// The material's name.
        name: String,
    },
    /// A mesh or sphere names a hair model.
    #[error("{kind} need a Diffuse(...) material, but '{name}' is a hair model")]
    NotSurfaceMaterial {
        /// `meshes` or `spheres`.
        kind: &'static str,
        /// The material's name.
        name: String,
    },
    /// The hair could not be read or generated.
    #[error(transparent)]
    Groom(#[from] tress_groom::Error),
    /// The object could not be read (a mesh) or added to the accelerator.
    #[error(transparent)]
    Accel(#[from] tress_accel::Error),
    /// The hair's per-strand variation of its material could not be made.
    #[error("material '{material}'")]
    Variation {
        /// The hair's material.
        material: String,
        /// Why.
        #[source]
        source: VariationError,
    },
}

/// Why the per-strand variation of a hair object's material could not be made.
#[derive(Debug, thiserror::Error)]
pub enum VariationError {
    /// The variation's settings do not fit the model.
    #[error(transparent)]
    Settings(#[from] ParamError),
    /// `file_colors` is asked of hair whose file has one colour for all strands.
    #[error(
        "variation.file_colors: {hair} stores no colour per strand or per point, only the \
         default colour {color} for all"
    )]
    UniformFileColor {
        /// The hair's name.
        hair: String,
        /// The file's one colour.
        color: Vec3,
    },
    /// `file_colors` is asked of hair whose file has no colours.
    #[error("variation.file_colors: {hair} stores no colours")]
    NoFileColors {
        /// The hair's name.
        hair: String,
    },
    /// The varied hair could not be added to the accelerator (a variant a strand could not
    /// take is reported here too, naming the strand).
    #[error(transparent)]
    Accel(#[from] tress_accel::Error),
    /// The model has no pigment to vary.
    #[error("variation: the model has no pigment")]
    NoPigment,
    /// A variant's parameters make no model.
    #[error("variation: variant σ_a = {sigma_a}, roughness × {roughness}")]
    Variant {
        /// The variant's absorption.
        sigma_a: Vec3,
        /// Its roughness scale.
        roughness: f32,
        /// Why.
        #[source]
        source: ParamError,
    },
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
