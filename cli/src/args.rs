//! Command-line arguments shared by the commands.

use clap::Args;
use std::path::PathBuf;
use tress_core::prepare::Preparation;

/// How a command that renders runs: `--threads`, `--quiet` and the table cache, flattened into
/// the arguments of `render`, `study` and `calibrate`.
#[derive(Args, Clone, Debug)]
pub struct RunArgs {
    /// Worker threads (default: all cores). Images do not depend on it.
    #[arg(long, value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// No progress bars and no summary.
    #[arg(long)]
    pub quiet: bool,
    /// Folder where precomputed tables (the fur model's medulla tables) are kept between runs
    /// [default: $XDG_CACHE_HOME/tress, else ~/.cache/tress]. Images do not depend on it.
    #[arg(long, value_name = "DIR")]
    pub table_cache: Option<PathBuf>,
    /// Keep no tables between runs: build them in every run.
    #[arg(long, conflicts_with = "table_cache")]
    pub no_table_cache: bool,
}

impl RunArgs {
    /// A pool of the worker threads.
    pub fn thread_pool(&self) -> anyhow::Result<rayon::ThreadPool> {
        use anyhow::Context;
        rayon::ThreadPoolBuilder::new()
            .num_threads(self.threads.unwrap_or(0))
            .build()
            .context("creating the thread pool")
    }

    /// The table folder: `--table-cache`, none with `--no-table-cache`, else the default
    /// ([`crate::default_table_dir`]).
    pub fn table_dir(&self) -> Option<PathBuf> {
        if self.no_table_cache {
            None
        } else {
            self.table_cache.clone().or_else(crate::default_table_dir)
        }
    }

    /// The run's preparation context: the limits the environment sets and the table folder.
    pub fn preparation(&self) -> Preparation {
        Preparation::with_limits(crate::limits_from_env()).with_table_dir(self.table_dir())
    }
}

/// [`tress_loader::check_threads`] as a command-line value parser.
pub fn parse_threads(s: &str) -> Result<usize, String> {
    tress_loader::check_threads(s.parse().map_err(|e| format!("{e}"))?)
}
