//! The error type of `tress-study`. Every variant names the study file, or the scene, render or
//! output it is about; a variant caused by another error keeps it as its source and leaves its
//! text to it, so that a chain printed whole (`{:#}`) names each cause once.

use std::path::PathBuf;
use tress_core::image_io::ImageError;
use tress_core::output_file::OutputError;

/// Why a study could not be planned, run or written.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The study file could not be read.
    #[error("cannot read study file {}", path.display())]
    Read {
        /// The study file.
        path: PathBuf,
        /// The operating system's error (or invalid UTF-8).
        #[source]
        source: std::io::Error,
    },
    /// The text is not a valid study description.
    #[error("{}:{error}", path.display())]
    Syntax {
        /// The study file.
        path: PathBuf,
        /// Where and what (boxed: RON's error is large, and every result of the crate would
        /// carry its size).
        error: Box<tress_loader::ron_format::SyntaxError>,
    },
    /// A setting of the study is invalid (`spp: the list is empty`, ...).
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The study file.
        path: PathBuf,
        /// The field and what is wrong with it.
        message: String,
    },
    /// A scene of the study could not be loaded, its film set or its files hashed.
    #[error("{}: {place}", path.display())]
    Scene {
        /// The study file.
        path: PathBuf,
        /// Where in the study: `scenes[i]` or `scene 'name'`.
        place: String,
        /// Why (boxed: the loader's error is large, and every result of the crate would carry
        /// its size).
        #[source]
        source: Box<SceneError>,
    },
    /// The films `quick.film` makes are invalid.
    #[error("{}: quick.film", path.display())]
    QuickFilm {
        /// The study file.
        path: PathBuf,
        /// What is wrong with them.
        #[source]
        source: tress_core::film::FilmError,
    },
    /// A scene could not be built (the error names its file).
    #[error(transparent)]
    Build(#[from] tress_loader::Error),
    /// An integrator could not be built for a scene.
    #[error("{scene}: integrator {integrator}")]
    Integrator {
        /// The scene's file (or the study, for an inline scene).
        scene: String,
        /// The integrator, as RON.
        integrator: String,
        /// The integrator's error.
        #[source]
        source: tress_core::integrator::BuildError,
    },
    /// The reference EXR of a scene could not be read.
    #[error("{}: reference of scene '{scene}'", study.display())]
    ReadReference {
        /// The study file.
        study: PathBuf,
        /// The scene's name.
        scene: String,
        /// Why.
        #[source]
        source: ImageError,
    },
    /// The reference EXR of a scene holds NaN or infinite pixels.
    #[error("{}: reference of scene '{scene}'", study.display())]
    NotFiniteReference {
        /// The study file.
        study: PathBuf,
        /// The scene's name.
        scene: String,
        /// How many pixels, in which file.
        #[source]
        source: crate::metrics::NotFinite,
    },
    /// A scene's reference EXR is not a full film of the scene's size.
    #[error(
        "reference {} is a window {window} of a {full_width}x{full_height} film, but scene \
         '{scene}' ({source_file}) renders a full {width}x{height} film",
        path.display()
    )]
    ReferenceWindow {
        /// The EXR.
        path: PathBuf,
        /// Its data window.
        window: crate::metrics::Rect,
        /// Its film's width.
        full_width: u32,
        /// Its film's height.
        full_height: u32,
        /// The scene's name.
        scene: String,
        /// The scene's file (or the study, for an inline scene).
        source_file: String,
        /// The scene's film width.
        width: u32,
        /// The scene's film height.
        height: u32,
    },
    /// An output folder could not be created.
    #[error("creating output folder {}", path.display())]
    CreateFolder {
        /// The folder.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The study's thread pool could not be started.
    #[error("creating the thread pool")]
    ThreadPool(#[source] rayon::ThreadPoolBuildError),
    /// A render could not be written (the error names the file).
    #[error(transparent)]
    Image(#[from] ImageError),
    /// A table or the report could not be written (the error names the file).
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The figures could not be drawn (the error is the drawer's own).
    #[error(transparent)]
    Figures(FiguresError),
}

/// The error of a [`Figures`](crate::Figures) drawer: its own, whatever it is (the study passes
/// it on).
pub type FiguresError = Box<dyn std::error::Error + Send + Sync>;

/// Why a scene of a study could not be planned.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// Its file could not be loaded, or the files it reads hashed.
    #[error(transparent)]
    Load(#[from] tress_loader::Error),
    /// Its film, as the study sets it, is invalid.
    #[error("film")]
    Film(#[source] tress_core::film::FilmError),
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
