//! `tress render` and `tress info`.

use crate::integrators::IntegratorDesc;
use crate::scene_desc::{self, SceneDesc};
use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use tress_core::image_io;

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Scene file (RON).
    pub scene: PathBuf,
    /// Integrator: a name (path) or a RON value such as 'Path(max_depth: 8)'; overrides the scene's.
    #[arg(long)]
    pub integrator: Option<String>,
    /// Samples per pixel; overrides the scene's film.spp.
    #[arg(long)]
    pub spp: Option<u32>,
    /// Random seed; overrides the scene's film.seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads (default: all cores). The image does not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Render only the pixel window x0,y0,x1,y1 (x1, y1 exclusive). The image equals the same
    /// window of the full render bit for bit.
    #[arg(long, value_parser = parse_crop)]
    pub crop: Option<[u32; 4]>,
    /// Output EXR path; a PNG preview is written beside it. Default: <scene name>.exr in the
    /// current directory.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Exposure of the PNG preview, in stops.
    #[arg(long, default_value_t = 0.0)]
    pub exposure: f32,
    /// No progress bar and no summary.
    #[arg(long)]
    pub quiet: bool,
}

fn parse_crop(s: &str) -> Result<[u32; 4], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 4 {
        return Err(format!("expected x0,y0,x1,y1, got '{s}'"));
    }
    let mut out = [0u32; 4];
    for (o, p) in out.iter_mut().zip(parts) {
        *o = p
            .trim()
            .parse()
            .map_err(|_| format!("'{p}' is not a non-negative integer"))?;
    }
    Ok(out)
}

/// The scene file with command-line overrides applied.
fn load_with_overrides(args: &RenderArgs) -> Result<SceneDesc> {
    let mut desc = scene_desc::load(&args.scene)?;
    if let Some(name) = &args.integrator {
        desc.integrator = IntegratorDesc::parse_arg(name).map_err(anyhow::Error::msg)?;
    }
    if let Some(spp) = args.spp {
        desc.film.spp = spp;
    }
    if let Some(seed) = args.seed {
        desc.film.seed = seed;
    }
    if args.crop.is_some() {
        desc.film.crop = args.crop;
    }
    desc.film
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: film: {e}", args.scene.display()))?;
    Ok(desc)
}

pub fn render(args: RenderArgs) -> Result<()> {
    let desc = load_with_overrides(&args)?;
    let out = match &args.out {
        Some(p) => p.clone(),
        None => PathBuf::from(format!("{}.exr", scene_stem(&args.scene))),
    };
    if out.extension().and_then(|e| e.to_str()) != Some("exr") {
        bail!(
            "--out {}: the output must be an .exr file (a .png preview is written beside it)",
            out.display()
        );
    }
    let threads = args.threads.unwrap_or(0);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("creating the thread pool")?;
    let verbose = !args.quiet;

    let built = pool.install(|| scene_desc::build(&desc, &args.scene))?;
    if verbose {
        eprintln!("{}", built.summary);
    }
    let t_integrator = std::time::Instant::now();
    let integrator = desc.integrator.build(&built.scene).map_err(|e| {
        anyhow::anyhow!(
            "{}: integrator {}: {e:#}",
            args.scene.display(),
            desc.integrator.name()
        )
    })?;
    if verbose && !matches!(desc.integrator, IntegratorDesc::Path(_)) {
        eprintln!(
            "{} set up in {:.2} s (dual-scattering tables)",
            desc.integrator.name(),
            t_integrator.elapsed().as_secs_f64()
        );
    }
    let [x0, y0, x1, y1] = desc.film.window();
    let total = (x1 - x0) as u64 * (y1 - y0) as u64 * desc.film.spp as u64;
    let bar = progress_bar(total, verbose);
    let progress = |n: u64| bar.inc(n);
    let output = pool.install(|| {
        tress_core::render::render(&built.scene, integrator.as_ref(), &desc.film, &progress)
    });
    bar.finish_and_clear();

    let stats = &output.stats;
    let integrator_ron =
        ron::to_string(&desc.integrator).unwrap_or_else(|_| desc.integrator.name().to_string());
    let attributes = [
        ("tress:scene", args.scene.display().to_string()),
        ("tress:integrator", integrator_ron),
        ("tress:spp", desc.film.spp.to_string()),
        ("tress:seed", desc.film.seed.to_string()),
        (
            "tress:render_time_s",
            format!("{:.3}", stats.wall.as_secs_f64()),
        ),
        ("tress:rays", stats.rays.to_string()),
    ];
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating output folder {}", dir.display()))?;
    }
    image_io::write_exr(&out, &output.image, &attributes)?;
    let png = out.with_extension("png");
    image_io::write_png(&png, &output.image, args.exposure)?;
    if verbose {
        eprintln!(
            "rendered {}x{} at {} spp with {} in {:.2} s: {:.3} Msamples/s, {:.3} Mrays/s",
            x1 - x0,
            y1 - y0,
            desc.film.spp,
            desc.integrator.name(),
            stats.wall.as_secs_f64(),
            stats.samples_per_second() / 1e6,
            stats.rays_per_second() / 1e6
        );
        eprintln!("wrote {} and {}", out.display(), png.display());
    }
    if stats.nonfinite_samples > 0 {
        eprintln!(
            "warning: {} samples were NaN or infinite and were dropped",
            stats.nonfinite_samples
        );
    }
    Ok(())
}

pub fn info(scene: &Path) -> Result<()> {
    let desc = scene_desc::load(scene)?;
    desc.film
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: film: {e}", scene.display()))?;
    let built = scene_desc::build(&desc, scene)?;
    println!("{}", built.summary);
    println!(
        "film: {}x{} at {} spp, seed {}",
        desc.film.width, desc.film.height, desc.film.spp, desc.film.seed
    );
    println!(
        "integrator: {}",
        ron::to_string(&desc.integrator).unwrap_or_default()
    );
    Ok(())
}

fn scene_stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "render".into())
}

fn progress_bar(total: u64, verbose: bool) -> ProgressBar {
    if !verbose || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {percent}% ETA {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}
