//! `tress study STUDY.ron`: a comparative study of integrators (`tress_study`, which
//! describes the study file), with a progress bar and the figures drawn by plotters.

mod plots;

use crate::args::RunArgs;
use crate::logging::Log;
use crate::progress::progress_bar;
use anyhow::Result;
use clap::Args;
use indicatif::ProgressBar;
use std::path::PathBuf;
use tress_study::{self as study, Progress, StudyOutputs, StudySettings};

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
    #[command(flatten)]
    pub run: RunArgs,
}

/// The study's progress bar; notes go above it, or to stderr when it is hidden or done.
struct Bar(ProgressBar);

impl Progress for Bar {
    fn start(&self, samples: u64) {
        self.0.set_length(samples);
    }
    fn advance(&self, samples: u64) {
        self.0.inc(samples);
    }
    fn note(&self, line: &str) {
        if self.0.is_hidden() || self.0.is_finished() {
            eprintln!("{line}");
        } else {
            self.0.println(line);
        }
    }
    fn finish(&self) {
        self.0.finish_and_clear();
    }
}

pub fn run(args: StudyArgs, log: &mut Log) -> Result<StudyOutputs> {
    let settings = StudySettings {
        study: args.study,
        quick: args.quick,
        out: args.out,
        threads: args.run.threads,
        verbose: !args.run.quiet,
        limits: crate::limits_from_env(),
        table_dir: args.run.table_dir(),
    };
    let bar = Bar(progress_bar(0, settings.verbose, "study "));
    let outputs = study::run(&settings, &bar, Some(&plots::Plots))?;
    // The summary of `--log-format json`.
    log.record("output", &outputs.folder);
    log.record("report", &outputs.report);
    log.record("results_csv", &outputs.results_csv);
    log.record("jobs", outputs.jobs);
    log.record("rendered", outputs.rendered);
    log.record("reused", outputs.reused);
    log.record("render_s", outputs.render_seconds);
    Ok(outputs)
}
