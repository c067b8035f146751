//! The `tress` binary's commands, over `tress-loader` (scene files, the integrator registry)
//! and `tress-study` (studies, image metrics). The binary uses them as they are, so tests reach exactly the
//! commands the binary runs.

#![warn(missing_docs)]

// The commands. `main.rs` parses the command line and calls into these; they are the binary's
// internals, not an API, so they stay out of the documentation.
#[doc(hidden)]
pub mod args;
#[doc(hidden)]
pub mod bcsdf;
#[doc(hidden)]
pub mod bench;
#[doc(hidden)]
pub mod calibrate;
#[doc(hidden)]
pub mod diff;
#[doc(hidden)]
pub mod farm;
#[doc(hidden)]
pub mod interrupt;
#[doc(hidden)]
pub mod logging;
#[doc(hidden)]
pub mod merge;
mod plot;
mod progress;
#[doc(hidden)]
pub mod render;
mod render_file;
#[doc(hidden)]
pub mod study;

/// The run's limits as the environment sets them (`TRESS_MEMORY_LIMIT_GIB`,
/// `TRESS_ALLOW_SLOW_TABLES`): the front end reads them here and hands them to the libraries.
pub fn limits_from_env() -> tress_core::limits::Limits {
    use tress_core::limits::{Limits, ALLOW_SLOW_TABLES_VAR, MEMORY_LIMIT_VAR};
    Limits::from_environment_values(
        std::env::var(MEMORY_LIMIT_VAR).ok().as_deref(),
        std::env::var_os(ALLOW_SLOW_TABLES_VAR).is_some(),
    )
}

/// Where tables are kept between runs unless `--table-cache` or `--no-table-cache` says
/// otherwise: `$XDG_CACHE_HOME/tress` (an absolute `XDG_CACHE_HOME`, as the XDG base directory
/// specification asks), else `$HOME/.cache/tress`; none without either.
pub fn default_table_dir() -> Option<std::path::PathBuf> {
    let absolute = |var: &str| {
        std::env::var_os(var)
            .map(std::path::PathBuf::from)
            .filter(|p| p.is_absolute())
    };
    absolute("XDG_CACHE_HOME")
        .or_else(|| absolute("HOME").map(|home| home.join(".cache")))
        .map(|cache| cache.join("tress"))
}

/// The preparation context of a command without `--table-cache` (`info`, `bench`, `bcsdf`): the
/// environment's limits and the default table folder.
pub fn default_preparation() -> tress_core::prepare::Preparation {
    tress_core::prepare::Preparation::with_limits(limits_from_env())
        .with_table_dir(default_table_dir())
}

/// Prints the warnings among `prep`'s notes (a stored table refused, one that could not be
/// stored), for a command that prints no other notes.
pub fn print_warnings(prep: &tress_core::prepare::Preparation) {
    (prep.take_notes().iter())
        .filter(|line| line.starts_with("warning"))
        .for_each(|line| eprintln!("{line}"));
}
