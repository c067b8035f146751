//! `tress`: the command-line renderer.

// The commands live in the library target, with their unit tests; the binary parses the command
// line and dispatches. (Nothing else links the library: Python and the fuzz targets call the
// loader and the readers directly.)
use tress_cli::{bcsdf, bench, calibrate, diff, farm, interrupt, logging, merge, render, study};

use anyhow::Result;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use std::io::IsTerminal;
use std::path::PathBuf;

/// tress — a physically based hair renderer.
#[derive(Parser, Debug)]
#[command(name = "tress", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// How to report: human, or json (no progress bars; the last line on stdout is one JSON
    /// object with the command's status and results).
    #[arg(long, global = true, value_enum, default_value_t = logging::LogFormat::Human)]
    log_format: logging::LogFormat,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a scene to a linear EXR and a tone-mapped PNG preview.
    Render(render::RenderArgs),
    /// Print what a scene contains: strands, segments, bounds, memory.
    Info {
        /// Scene file (RON).
        scene: PathBuf,
        /// Values for the scene's `${name}` placeholders: `-D spp=64`.
        #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = tress_loader::placeholders::parse_define)]
        defines: Vec<(String, String)>,
    },
    /// Tools for adding and tuning hair models: furnace, eval.
    #[command(subcommand)]
    Bcsdf(bcsdf::BcsdfCommand),
    /// Comparative convergence study of integrators (error vs spp and time, report, plots).
    Study(study::StudyArgs),
    /// Error metrics of an EXR against a reference EXR, and an error heat map.
    Diff(diff::DiffArgs),
    /// Performance against raw Embree in the same run: builds, memory, rays/s, scaling.
    Bench(bench::BenchArgs),
    /// Assemble tiles and sample-range passes of one render into the full image, bit for bit.
    Merge(merge::MergeArgs),
    /// Print a render split into tiles x passes as shell commands for a render farm.
    Farm(farm::FarmArgs),
    /// Fit dual scattering's d_f and d_b to a short path-traced reference of a scene.
    Calibrate(calibrate::CalibrateArgs),
    /// Write a commented starter scene (procedural hair on a head under the built-in sky).
    Init {
        /// Where to write it; an existing file is not overwritten.
        #[arg(default_value = "scene.ron")]
        path: PathBuf,
    },
}

fn main() {
    // Rust ignores SIGPIPE, so printing into a closed pipe (`tress info scene.ron | head -1`)
    // panicked with "Broken pipe"; the default action ends the process quietly, as it does
    // for other Unix tools. Outputs are files written through temporaries, never stdout.
    #[cfg(unix)]
    // SAFETY: first thing in `main`, before any thread exists; SIG_DFL is a valid action.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let matches = Cli::command().get_matches();
    let command = matches.subcommand_name().unwrap_or_default().to_string();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let mut log = logging::Log::new(cli.log_format);
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        // Colours and timestamps are for people at a terminal; logs and CI get plain lines.
        .with_ansi(std::io::stderr().is_terminal())
        .without_time()
        .init();
    let result = run(cli, &mut log);
    log.finish(
        &command,
        match &result {
            Ok(()) => logging::Outcome::Ok,
            Err(e) if e.is::<interrupt::Interrupted>() => logging::Outcome::Interrupted,
            Err(e) => logging::Outcome::Error(e),
        },
    );
    if let Err(e) = result {
        let code = match e.downcast_ref::<interrupt::Interrupted>() {
            Some(stopped) => stopped.exit_code,
            None => {
                eprintln!("error: {e:#}");
                1
            }
        };
        // Nothing may outlive the error's destructor (a temporary file it owns).
        drop(e);
        std::process::exit(code);
    }
}

fn run(cli: Cli, log: &mut logging::Log) -> Result<()> {
    // JSON reports replace the progress bars and the readable summaries.
    let quiet = log.json();
    match cli.command {
        Command::Render(mut args) => {
            args.run.quiet |= quiet;
            render::render(args, log)
        }
        Command::Info { scene, defines } => render::info(&scene, &defines),
        Command::Bcsdf(cmd) => bcsdf::run(cmd),
        Command::Study(mut args) => {
            args.run.quiet |= quiet;
            study::run(args, log).map(|_| ())
        }
        Command::Diff(args) => diff::run(args, log),
        Command::Bench(args) => bench::run(args),
        Command::Merge(mut args) => {
            args.quiet |= quiet;
            merge::run(args)
        }
        Command::Farm(args) => farm::run(args),
        Command::Calibrate(mut args) => {
            args.run.quiet |= quiet;
            calibrate::run(args)
        }
        Command::Init { path } => init(&path),
    }
}

/// The starter scene of `tress init`.
const STARTER_SCENE: &str = include_str!("templates/starter.ron");

/// `tress init`: writes the starter scene, unless `path` exists.
fn init(path: &std::path::Path) -> Result<()> {
    if path.exists() {
        anyhow::bail!("{} exists: not overwritten", path.display());
    }
    // Written from the binary itself: no file is read.
    tress_core::output_file::write_bytes(
        path,
        &tress_core::output_file::Inputs::default(),
        STARTER_SCENE.as_bytes(),
    )?;
    eprintln!(
        "wrote {}; render it with: tress render {}",
        path.display(),
        path.display()
    );
    Ok(())
}
