//! Command-line arguments shared by the commands.

use clap::Args;

/// How a command that renders runs: `--threads` and `--quiet`, flattened into the arguments of
/// `render`, `study` and `calibrate`.
#[derive(Args, Clone, Copy, Debug)]
pub struct RunArgs {
    /// Worker threads (default: all cores). Images do not depend on it.
    #[arg(long, value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// No progress bars and no summary.
    #[arg(long)]
    pub quiet: bool,
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
}

/// [`tress_loader::check_threads`] as a command-line value parser.
pub fn parse_threads(s: &str) -> Result<usize, String> {
    tress_loader::check_threads(s.parse().map_err(|e| format!("{e}"))?)
}
