//! `tress farm`: splits a render into independent `tress render` jobs — tiles (horizontal bands
//! of whole rows, via `--crop`) times sample-range passes (`--spp-offset`) — printed one shell
//! command per line for GNU parallel, a Slurm array job or an OpenCue layer, plus the
//! `tress merge` command that assembles their outputs into the image of the single full render.
//! Every job writes its exact sample sums (`--sums`), which the merge needs.

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use tress_core::film::Aov;
use tress_loader::integrators::IntegratorDesc;
use tress_loader::placeholders::{self, Defines};
use tress_loader::scene_desc;

fn parse_aov(s: &str) -> Result<Aov, String> {
    s.parse()
}

#[derive(Args, Debug)]
pub struct FarmArgs {
    /// Scene file (RON).
    pub scene: PathBuf,
    /// Number of tiles: horizontal bands of whole rows of the film (or of its crop window).
    #[arg(long, default_value_t = 1)]
    pub tiles: u32,
    /// Number of sample-range passes per tile.
    #[arg(long, default_value_t = 1)]
    pub passes: u32,
    /// Folder for the pieces and the merged image. Default: <scene name>-farm.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Samples per pixel of the whole render; overrides the scene's film.spp.
    #[arg(long)]
    pub spp: Option<u32>,
    /// Random seed; overrides the scene's film.seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Integrator override, passed to every job (see `tress render --integrator`).
    #[arg(long)]
    pub integrator: Option<String>,
    /// Worker threads per job (default: all cores of the machine running it), checked as
    /// `tress render --threads` checks it on this machine.
    #[arg(long, value_parser = crate::args::parse_threads)]
    pub threads: Option<usize>,
    /// Also write the alpha channel (passed to every job; see `tress render --alpha`).
    #[arg(long)]
    pub alpha: bool,
    /// Extra outputs, passed to every job (see `tress render --aov`).
    #[arg(long, value_delimiter = ',', value_parser = parse_aov)]
    pub aov: Vec<Aov>,
    /// Values for the scene's `${name}` placeholders, passed to every job (see `tress render
    /// -D`).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = placeholders::parse_define)]
    pub defines: Vec<(String, String)>,
    /// The tress executable the commands run. Default: this one, by absolute path.
    #[arg(long)]
    pub tress: Option<String>,
    /// Print only the merge command, to run once every job has finished.
    #[arg(long)]
    pub merge: bool,
}

/// Quotes `s` for a POSIX shell when it holds anything but plain path characters.
fn shell_quote(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "_-./,:=+@%".contains(c));
    if plain {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

fn utf8(p: &Path) -> Result<String> {
    p.to_str().map(shell_quote).ok_or_else(|| {
        anyhow!(
            "{}: the path is not valid UTF-8, so it cannot be printed as a command",
            p.display()
        )
    })
}

pub fn run(args: FarmArgs) -> Result<()> {
    let defines = placeholders::defines(&args.defines)?;
    let mut desc = scene_desc::load_with(&args.scene, &defines)?;
    if let Some(spp) = args.spp {
        desc.film.spp = spp;
    }
    if let Some(seed) = args.seed {
        desc.film.seed = seed;
    }
    if let Some(name) = &args.integrator {
        IntegratorDesc::parse_arg(name).map_err(anyhow::Error::msg)?;
    }
    let film = &desc.film;
    film.validate()
        .map_err(|e| anyhow!("{}: film: {e}", args.scene.display()))?;
    let [x0, y0, x1, y1] = film.window();
    let rows = y1 - y0;
    if args.tiles == 0 || args.tiles > rows {
        bail!(
            "--tiles {}: must lie in 1..={rows} (tiles are bands of whole rows of the {}x{} window)",
            args.tiles,
            x1 - x0,
            rows
        );
    }
    if args.passes == 0 || args.passes > film.spp {
        bail!(
            "--passes {}: must lie in 1..={} (each pass renders at least one sample per pixel)",
            args.passes,
            film.spp
        );
    }

    let cwd = std::env::current_dir().context("finding the current folder")?;
    let scene = std::fs::canonicalize(&args.scene)
        .with_context(|| format!("cannot find scene file {}", args.scene.display()))?;
    let stem = scene
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "render".into());
    let dir = cwd.join(
        args.out
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("{stem}-farm"))),
    );
    // Every job would fail on what is wrong here: refuse it before printing them.
    if dir.exists() && !dir.is_dir() {
        bail!(
            "--out {}: exists and is not a folder (the pieces and the merged image go in it)",
            args.out.as_deref().unwrap_or(&dir).display()
        );
    }
    let tress = match &args.tress {
        // A path must name an executable file; a bare name is looked up where the jobs run.
        Some(t) if t.contains('/') && !is_executable(Path::new(t)) => {
            bail!("--tress {t}: not an executable file")
        }
        Some(t) => shell_quote(t),
        None => utf8(&std::env::current_exe().context("finding the tress executable")?)?,
    };
    let common = job_options(&args, &defines);

    let (tiles, passes) = (args.tiles as u64, args.passes as u64);
    let spp = film.spp as u64;
    let (tw, pw) = (digits(tiles - 1), digits(passes - 1));
    let mut jobs = Vec::new();
    let mut pieces = Vec::new();
    for t in 0..tiles {
        let ty0 = y0 as u64 + t * rows as u64 / tiles;
        let ty1 = y0 as u64 + (t + 1) * rows as u64 / tiles;
        for p in 0..passes {
            let (s0, s1) = (p * spp / passes, (p + 1) * spp / passes);
            let piece = dir.join(format!("{stem}-t{t:0tw$}-p{p:0pw$}.exr"));
            jobs.push(format!(
                "{tress} render {} --crop {x0},{ty0},{x1},{ty1} --spp-offset {s0} --spp {}{common} \
                 --sums --out {} --no-preview --quiet",
                utf8(&scene)?,
                s1 - s0,
                utf8(&piece)?
            ));
            pieces.push(utf8(&piece)?);
        }
    }
    let crop = match film.crop {
        Some([a, b, c, d]) => format!(" --crop {a},{b},{c},{d}"),
        None => String::new(),
    };
    let merge = format!(
        "{tress} merge {} {} --expect-spp {spp}{crop}",
        utf8(&dir.join(format!("{stem}.exr")))?,
        pieces.join(" ")
    );
    if args.merge {
        println!("{merge}");
    } else {
        for j in &jobs {
            println!("{j}");
        }
        eprintln!(
            "# {} jobs ({} tiles x {} passes of {} spp in all); when every job has finished, run:\n# {merge}",
            jobs.len(),
            tiles,
            passes,
            spp
        );
    }
    Ok(())
}

/// The options every render job shares: the placeholders' values, the seed, integrator, threads
/// and outputs given to `tress farm`, each with a leading space.
fn job_options(args: &FarmArgs, defines: &Defines) -> String {
    let mut common = Vec::new();
    for (name, value) in defines {
        common.push(format!("-D {}", shell_quote(&format!("{name}={value}"))));
    }
    if let Some(seed) = args.seed {
        common.push(format!("--seed {seed}"));
    }
    if let Some(name) = &args.integrator {
        common.push(format!("--integrator {}", shell_quote(name)));
    }
    if let Some(t) = args.threads {
        common.push(format!("--threads {t}"));
    }
    if args.alpha {
        common.push("--alpha".into());
    }
    let aovs: BTreeSet<Aov> = args.aov.iter().copied().collect();
    if !aovs.is_empty() {
        let names: Vec<&str> = aovs.iter().map(|a| a.name()).collect();
        common.push(format!("--aov {}", names.join(",")));
    }
    common.iter().map(|c| format!(" {c}")).collect::<String>()
}

/// Whether `path` is a regular file someone may execute.
fn is_executable(path: &Path) -> bool {
    let Ok(meta) = std::fs::metadata(path) else {
        return false;
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        meta.is_file() && meta.permissions().mode() & 0o111 != 0
    }
    #[cfg(not(unix))]
    meta.is_file()
}

/// Decimal digits of `n` (at least 1), for zero-padded names that sort in order.
fn digits(n: u64) -> usize {
    n.checked_ilog10().map_or(1, |d| d as usize + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoting_keeps_plain_words_and_protects_the_rest() {
        assert_eq!(shell_quote("/a/b-c_d.exr"), "/a/b-c_d.exr");
        assert_eq!(shell_quote("Path(max_depth: 8)"), "'Path(max_depth: 8)'");
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
        assert_eq!(shell_quote(""), "''");
        assert_eq!((digits(0), digits(9), digits(10)), (1, 1, 2));
    }
}
