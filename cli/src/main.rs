//! `tress`: the command-line renderer.

mod bcsdf_cmd;
mod bench;
mod calibrate;
mod cost;
mod diff;
mod farm;
mod interrupt;
mod merge;
mod plot;
mod render_cmd;
mod render_file;
mod study;

// The scene layer lives in the library target so that fuzz targets reach it too.
use tress_cli::{integrators, ron_options, scene_desc};

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::io::IsTerminal;
use std::path::PathBuf;

/// tress — a physically based hair renderer.
#[derive(Parser, Debug)]
#[command(name = "tress", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a scene to a linear EXR and a tone-mapped PNG preview.
    Render(render_cmd::RenderArgs),
    /// Print what a scene contains: strands, segments, bounds, memory.
    Info {
        /// Scene file (RON).
        scene: PathBuf,
    },
    /// Tools for adding and tuning hair models: furnace, eval.
    #[command(subcommand)]
    Bcsdf(bcsdf_cmd::BcsdfCommand),
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
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        // Colours and timestamps are for people at a terminal; logs and CI get plain lines.
        .with_ansi(std::io::stderr().is_terminal())
        .without_time()
        .init();
    if let Err(e) = run(cli) {
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

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Render(args) => render_cmd::render(args),
        Command::Info { scene } => render_cmd::info(&scene),
        Command::Bcsdf(cmd) => bcsdf_cmd::run(cmd),
        Command::Study(args) => study::run(args),
        Command::Diff(args) => diff::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Merge(args) => merge::run(args),
        Command::Farm(args) => farm::run(args),
        Command::Calibrate(args) => calibrate::run(args),
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
    atomic_write(path, STARTER_SCENE.as_bytes())?;
    eprintln!(
        "wrote {}; render it with: tress render {}",
        path.display(),
        path.display()
    );
    Ok(())
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, so readers
/// never see a partial file.
pub fn atomic_write(path: &std::path::Path, bytes: &[u8]) -> Result<()> {
    use anyhow::Context;
    use std::io::Write;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let mut tmp = tress_core::image_io::output_temp_file(dir, ".tmp")
        .with_context(|| format!("cannot write in {}", dir.display()))?;
    tmp.write_all(bytes)
        .with_context(|| format!("writing {}", path.display()))?;
    // The bare io::Error: a kept PersistError would hold (and so leave behind) the temporary
    // file until the error is dropped, and would print the io error twice.
    tmp.persist(path)
        .map_err(|e| e.error)
        .with_context(|| format!("cannot create {}", path.display()))?;
    Ok(())
}
