//! `tress`: the command-line renderer.

// Every unsafe operation in its own block, with the reason it is sound.
#![warn(unsafe_op_in_unsafe_fn, clippy::undocumented_unsafe_blocks)]

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
    /// Tools for adding and tuning hair models: furnace, eval, plot.
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

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;
    use std::fmt::Write as _;

    /// The line of `docs/src/reference/commands.md` after which every command's `--help` is
    /// generated.
    const MARKER: &str =
        "<!-- Generated from the command line's own --help (cli/src/main.rs); do not edit \
        below. After changing a command, regenerate it with `TRESS_BLESS=1 cargo test --release \
        -p tress-cli --bin tress commands_reference`. -->";

    fn reference_path() -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/src/reference/commands.md")
    }

    /// `tress --help` and every command's, at a fixed width so the page does not depend on the
    /// terminal that generated it.
    fn help_pages() -> String {
        fn push(cmd: &mut clap::Command, name: &str, out: &mut String) {
            let help = cmd.render_long_help().to_string();
            let _ = write!(out, "### `{name}`\n\n```text\n{}\n```\n\n", help.trim_end());
            for sub in cmd.get_subcommands_mut().filter(|c| c.get_name() != "help") {
                let name = format!("{name} {}", sub.get_name());
                push(sub, &name, out);
            }
        }
        let mut root = Cli::command().term_width(100).max_term_width(100);
        root.build();
        let mut out = String::new();
        push(&mut root, "tress", &mut out);
        out
    }

    /// The committed page ends with what the commands print for `--help`; `TRESS_BLESS=1`
    /// rewrites that part.
    #[test]
    fn commands_reference_ends_with_the_help_of_every_command() {
        let path = reference_path();
        let page = std::fs::read_to_string(&path).unwrap();
        let head = page.split(MARKER).next().unwrap();
        let expected = format!("{head}{MARKER}\n\n{}", help_pages().trim_end());
        if std::env::var_os("TRESS_BLESS").is_some() {
            std::fs::write(&path, format!("{expected}\n")).unwrap();
        } else {
            assert!(
                page.trim_end() == expected,
                "{} is not what the commands print for --help: regenerate it with \
                 `TRESS_BLESS=1 cargo test --release -p tress-cli --bin tress commands_reference`",
                path.display()
            );
        }
    }

    /// Every command and option of the page's summary exists: `tress NAME` is a command (or
    /// `tress bcsdf NAME` one of its own) and each `--option` and `-D` written after it is one
    /// of that command's arguments.
    #[test]
    fn commands_reference_summary_names_real_commands_and_options() {
        let page = std::fs::read_to_string(reference_path()).unwrap();
        let summary = page
            .split("```sh\n")
            .nth(1)
            .unwrap()
            .split("```")
            .next()
            .unwrap();
        let mut root = Cli::command();
        root.build();
        let mut current: Option<clap::Command> = None;
        let mut checked = 0;
        for line in summary.lines() {
            let words: Vec<&str> = line.split("#").next().unwrap().split_whitespace().collect();
            if words.first() == Some(&"tress") {
                current = match words.get(1) {
                    Some(&"COMMAND") => None,
                    Some(name) => {
                        let cmd = root.find_subcommand(name).unwrap_or_else(|| {
                            panic!("commands.md names `tress {name}`, which is no command")
                        });
                        let sub = words.get(2).and_then(|w| cmd.find_subcommand(w));
                        Some(sub.unwrap_or(cmd).clone())
                    }
                    None => None,
                };
            }
            let Some(cmd) = &current else { continue };
            for word in &words {
                let option = word.trim_start_matches('[');
                let option = option.split(['=', ']', ' ']).next().unwrap();
                let known = if let Some(long) = option.strip_prefix("--") {
                    cmd.get_arguments().any(|a| a.get_long() == Some(long))
                } else if let Some(short) = option.strip_prefix('-').filter(|s| s.len() == 1) {
                    let c = short.chars().next().unwrap();
                    cmd.get_arguments().any(|a| a.get_short() == Some(c))
                } else {
                    continue;
                };
                assert!(
                    known,
                    "commands.md: `tress {}` has no option `{option}`",
                    cmd.get_name()
                );
                checked += 1;
            }
        }
        assert!(checked > 20, "only {checked} options found in the summary");
    }
}
