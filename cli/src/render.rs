//! `tress render` and `tress info`.
//!
//! A render runs in waves of samples — cumulative 1, 2, 4, 8, … up to the requested spp — whose
//! exact sums are appended (see `tress_core::render`), so the image does not depend on the waves.
//! Between waves the render can stop at a time limit, write a partial image, or, after Ctrl-C,
//! stop and write the samples finished so far.

use crate::args::RunArgs;
use crate::interrupt::Interrupt;
use crate::logging::Log;
use crate::progress::progress_bar;
use crate::render_file::{self, parse_crop, Identity, PreviewArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tress_core::film::{Aov, Outputs};
use tress_core::image_io::Attribute;
use tress_core::output_file::{self, Inputs};
use tress_core::render::{self, RenderStats, SampleSums};
use tress_core::Integrator;
use tress_loader::integrators::IntegratorDesc;
use tress_loader::placeholders;
use tress_loader::scene_desc::{self, SceneDesc};

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
    /// Film width in pixels; overrides the scene's film.width (the camera keeps its vertical
    /// field of view, so a wider film sees more to the sides).
    #[arg(long)]
    pub width: Option<u32>,
    /// Film height in pixels; overrides the scene's film.height.
    #[arg(long)]
    pub height: Option<u32>,
    /// Render sample indices N..N+spp of every pixel instead of 0..spp (same seed stream), so
    /// that `tress merge` can add them to a render of 0..N exactly.
    #[arg(long, default_value_t = 0)]
    pub spp_offset: u64,
    /// Random seed; overrides the scene's film.seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Render only the pixel window x0,y0,x1,y1 (x1, y1 exclusive). The image equals the same
    /// window of the full render bit for bit, except with integrators that learn from the
    /// film's paths (radiance-cache, guided): they learn from the window's pixels alone.
    #[arg(long, value_parser = parse_crop)]
    pub crop: Option<[u32; 4]>,
    /// Output EXR path; a PNG preview is written beside it. Default: <scene name>.exr in the
    /// current directory.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Stop after the sample wave (1, 2, 4, … spp) that ends past this many seconds of
    /// rendering (an integrator's training included); the outputs record the spp reached.
    #[arg(long, value_parser = parse_seconds, allow_hyphen_values = true)]
    pub time_limit: Option<f64>,
    /// Also write the EXR and PNG after every wave, so the output always holds the samples
    /// finished so far.
    #[arg(long)]
    pub partial: bool,
    /// Values for the scene's `${name}` placeholders: `-D spp=64 -D groom=curly`.
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = placeholders::parse_define)]
    pub defines: Vec<(String, String)>,
    /// Also write the exact sample sums into the EXR, so that `tress merge` can join it with
    /// other tiles and sample ranges bit for bit (larger files; `tress farm` jobs use it).
    #[arg(long)]
    pub sums: bool,
    /// Also write an alpha channel A: the fraction of each pixel's camera rays that hit
    /// geometry, hair or surface (one extra occlusion query per sample, about 4 % of a
    /// sample's time).
    #[arg(long)]
    pub alpha: bool,
    /// Extra outputs, comma-separated, written as EXR layers: depth (depth.Z: distance to the
    /// first hit), tangent (tangent.XYZ: fiber tangent there), albedo (albedo.RGB: the first
    /// hit's directional albedo), variance (variance.RGB: variance of the pixel value).
    #[arg(long, value_delimiter = ',', value_parser = parse_aov)]
    pub aov: Vec<Aov>,
    #[command(flatten)]
    pub preview: PreviewArgs,
    #[command(flatten)]
    pub run: RunArgs,
}

fn parse_aov(s: &str) -> Result<Aov, String> {
    s.parse()
}

impl RenderArgs {
    /// What the render records besides radiance.
    fn outputs(&self) -> Outputs {
        Outputs {
            alpha: self.alpha,
            aovs: self.aov.iter().copied().collect(),
        }
    }
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..1e9).contains(&v) => Ok(v),
        Ok(v) if v >= 1e9 => Err(format!(
            "{s} seconds is more than the 1e9 (about 32 years) a time limit may be"
        )),
        _ => Err(format!("'{s}' is not a number of seconds >= 0")),
    }
}

/// The scene file with command-line overrides applied.
fn load_with_overrides(args: &RenderArgs) -> Result<SceneDesc> {
    let defines = placeholders::defines(&args.defines)?;
    let mut desc = scene_desc::load_with(&args.scene, &defines)?;
    if let Some(name) = &args.integrator {
        desc.integrator = IntegratorDesc::parse_arg(name).map_err(anyhow::Error::msg)?;
    }
    if let Some(spp) = args.spp {
        desc.film.spp = spp;
    }
    if let Some(seed) = args.seed {
        desc.film.seed = seed;
    }
    if let Some(width) = args.width {
        desc.film.width = width;
    }
    if let Some(height) = args.height {
        desc.film.height = height;
    }
    if args.crop.is_some() {
        desc.film.crop = args.crop;
    }
    desc.film
        .validate_for_outputs(&args.outputs(), &crate::limits_from_env())
        .map_err(|e| anyhow::anyhow!("{}: film: {e}", args.scene.display()))?;
    if args.spp_offset.checked_add(desc.film.spp as u64).is_none() {
        bail!(
            "--spp-offset {} + {} spp exceeds the largest sample index",
            args.spp_offset,
            desc.film.spp
        );
    }
    Ok(desc)
}

/// Identifies the image a scene description renders, whatever its spp and crop: pieces with the
/// same hash and seed can be merged. FNV-1a of the description's RON text and of the contents of
/// the files it reads (tiles rendered against different versions of one hair file must not be
/// merged), so the value is the same on every machine and build.
fn scene_hash(desc: &SceneDesc, scene_path: &Path) -> Result<String> {
    let mut d = desc.clone();
    d.film.spp = 1;
    d.film.crop = None;
    let text = ron::to_string(&d).context("describing the scene for its hash")?;
    let files = desc.files_hash(scene_path)?;
    let hash = text
        .bytes()
        .chain(files.to_le_bytes())
        .fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
        });
    Ok(format!("{hash:016x}"))
}

/// Why the wave loop ended.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Status {
    Complete,
    Partial,
    TimeLimit,
    Interrupted,
}

impl Status {
    fn label(self) -> &'static str {
        match self {
            Status::Complete => "complete",
            Status::Partial => "partial",
            Status::TimeLimit => "time-limit",
            Status::Interrupted => "interrupted",
        }
    }
}

/// What the output files need besides the sums.
struct OutputFiles<'a> {
    args: &'a RenderArgs,
    desc: &'a SceneDesc,
    out: PathBuf,
    /// The scene and the files it reads, which the outputs may not replace.
    inputs: Inputs,
    identity: Identity,
    camera: &'a tress_core::Camera,
}

impl OutputFiles<'_> {
    fn write(&self, sums: &SampleSums, stats: &RenderStats, status: Status) -> Result<()> {
        let integrator_ron = ron::to_string(&self.desc.integrator)
            .unwrap_or_else(|_| self.desc.integrator.name().to_string());
        let film = &self.desc.film;
        let attributes = [
            (
                "tress:scene",
                Attribute::Text(self.args.scene.display().to_string()),
            ),
            ("tress:integrator", Attribute::Text(integrator_ron)),
            ("tress:spp_requested", Attribute::whole(film.spp.into())),
            ("tress:status", Attribute::Text(status.label().into())),
            (
                "tress:render_time_s",
                Attribute::Double(stats.wall.as_secs_f64()),
            ),
            ("tress:rays", Attribute::Double(stats.rays as f64)),
            // Included in the render time.
            (
                "tress:precompute_time_s",
                Attribute::Double(stats.precompute.as_secs_f64()),
            ),
            // Samples that came out NaN or infinite and were left out of the sums.
            (
                "tress:dropped_samples",
                Attribute::Double(stats.nonfinite_samples as f64),
            ),
            (
                "worldToCamera",
                Attribute::Matrix(self.camera.world_to_camera()),
            ),
            (
                "worldToNDC",
                Attribute::Matrix(self.camera.world_to_ndc(film.width, film.height)),
            ),
        ];
        // Renders writing the same outputs at once take turns, so that the EXR and the PNG
        // left behind come from one render (an advisory lock on their folder, released on
        // drop; other programs are not held up).
        let folder = match self.out.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let turn = std::fs::File::open(folder)
            .and_then(|f| f.lock().map(|()| f))
            .with_context(|| format!("locking {} for writing", folder.display()))?;
        let written = self.args.preview.write_with(
            &self.out,
            &self.inputs,
            |o| render_file::write_render(o, sums, self.args.sums, &self.identity, &attributes),
            &sums.image(),
        );
        drop(turn);
        written
    }
}

pub fn render(args: RenderArgs, log: &mut Log) -> Result<()> {
    let desc = load_with_overrides(&args)?;
    let inputs = desc.inputs(&args.scene)?;
    let out = output_path(&args, &inputs)?;
    let pool = args.run.thread_pool()?;
    let verbose = !args.run.quiet;

    // One preparation context for the run: the scene's models and the integrator take what
    // they precompute from it (and from the table folder it names).
    let prep = args.run.preparation();
    let built = pool.install(|| scene_desc::build(&desc, &args.scene, &prep))?;
    if verbose {
        eprintln!("{}", built.summary);
    }
    let integrator = build_integrator(&args, &desc, &built.scene, &pool, &prep, verbose)?;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating output folder {}", dir.display()))?;
    }
    let files = OutputFiles {
        args: &args,
        desc: &desc,
        out: out.clone(),
        inputs,
        identity: Identity {
            seed: desc.film.seed,
            scene_hash: scene_hash(&desc, &args.scene)?,
        },
        camera: &built.scene.camera,
    };

    let interrupt = Interrupt::install()?;
    let render = Waves {
        args: &args,
        desc: &desc,
        scene: &built.scene,
        integrator: integrator.as_ref(),
        pool: &pool,
        files: &files,
    };
    let rendered = render.run(interrupt.cancel_flag(), verbose)?;
    if rendered.reached == 0 {
        eprintln!(
            "interrupted before the first sample of every pixel was finished: nothing written"
        );
        return Err(interrupt.interrupted().into());
    }
    files.write(&rendered.sums, &rendered.stats, rendered.status)?;
    report(&args, &desc, &out, &rendered, log);
    if rendered.status == Status::Interrupted {
        return Err(interrupt.interrupted().into());
    }
    Ok(())
}

/// The EXR to write: `--out`, by default `<scene name>.exr`; refused unless an `.exr`, or when
/// it or its PNG could not be written (a directory, one of `inputs`: [`output_file::check`]).
fn output_path(args: &RenderArgs, inputs: &Inputs) -> Result<PathBuf> {
    let out = match &args.out {
        Some(p) => p.clone(),
        None => PathBuf::from(format!("{}.exr", scene_stem(&args.scene))),
    };
    if !out
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        bail!(
            "--out {}: the output must be an .exr file (a .png preview is written beside it)",
            out.display()
        );
    }
    // Refused before rendering, not after.
    for path in args.preview.outputs(&out) {
        output_file::check(&path, inputs)?;
    }
    Ok(out)
}

/// Builds the scene's integrator; tells what it precomputed, and how long that took when it is
/// worth a line (dual-scattering tables).
fn build_integrator(
    args: &RenderArgs,
    desc: &SceneDesc,
    scene: &tress_core::Scene,
    pool: &rayon::ThreadPool,
    prep: &tress_core::prepare::Preparation,
    verbose: bool,
) -> Result<Box<dyn Integrator>> {
    let t_integrator = Instant::now();
    let integrator = pool
        .install(|| desc.integrator.build(scene, prep))
        .with_context(|| args.scene.display().to_string())?;
    let setup = t_integrator.elapsed();
    // What the models and the integrator built or read; warnings (a stored table refused)
    // are printed either way.
    (prep.take_notes().iter())
        .filter(|line| verbose || line.starts_with("warning"))
        .for_each(|line| eprintln!("{line}"));
    if verbose && setup >= Duration::from_millis(50) {
        eprintln!(
            "{} set up in {:.2} s",
            desc.integrator.name(),
            setup.as_secs_f64()
        );
    }
    Ok(integrator)
}

/// The render loop: waves of samples until the target spp, a time limit or an interrupt.
struct Waves<'a> {
    args: &'a RenderArgs,
    desc: &'a SceneDesc,
    scene: &'a tress_core::Scene,
    integrator: &'a dyn Integrator,
    pool: &'a rayon::ThreadPool,
    files: &'a OutputFiles<'a>,
}

/// What the render loop finished.
struct Rendered {
    sums: SampleSums,
    stats: RenderStats,
    /// Samples per pixel finished.
    reached: u64,
    status: Status,
}

impl Waves<'_> {
    /// Renders waves of cumulative 1, 2, 4, … spp, writing the partial image after each with
    /// `--partial`. Before each of a wave's sample segments ([`Integrator::sample_segments`])
    /// the integrator prepares for its samples ([`Integrator::for_film`]: a radiance cache
    /// trains the caches of the segment's sample block, going on from the block before, whose
    /// caches it lets go), with a bar of its own; that time counts as render time.
    fn run(&self, cancel: &AtomicBool, verbose: bool) -> Result<Rendered> {
        let (args, film) = (self.args, &self.desc.film);
        let outputs = args.outputs();
        let [x0, y0, x1, y1] = film.window();
        let target = film.spp as u64;
        let first = args.spp_offset;
        let bar = progress_bar((x1 - x0) as u64 * (y1 - y0) as u64 * target, verbose, "");
        let limit = args.time_limit.map(Duration::from_secs_f64);
        // The limit counts the precomputation (a radiance cache's training) as render time.
        let start = Instant::now();
        let mut stats = RenderStats::default();
        let mut sums = SampleSums::empty(
            film.window(),
            film.width,
            film.height,
            first,
            outputs.clone(),
        );
        let mut reached = 0u64;
        let mut status = Status::Complete;
        while reached < target {
            let next = (2 * reached).clamp(1, target);
            // A wave that reaches into a new sample block is prepared for and rendered block by
            // block, so that one block's caches are held at a time.
            for samples in self
                .integrator
                .sample_segments(first + reached..first + next)
            {
                if !self.render_segment(samples, &mut sums, &mut stats, cancel, verbose, &bar)? {
                    status = Status::Interrupted;
                    break;
                }
            }
            if status == Status::Interrupted {
                break;
            }
            reached = next;
            if reached < target {
                if limit.is_some_and(|l| start.elapsed() >= l) {
                    status = Status::TimeLimit;
                    break;
                }
                if args.partial {
                    self.files.write(&sums, &stats, Status::Partial)?;
                }
            }
        }
        bar.finish_and_clear();
        Ok(Rendered {
            sums,
            stats,
            reached,
            status,
        })
    }

    /// Prepares for and renders sample indices `samples`, appending their sums to `sums`;
    /// `false` when cancelled.
    fn render_segment(
        &self,
        samples: std::ops::Range<u64>,
        sums: &mut SampleSums,
        stats: &mut RenderStats,
        cancel: &AtomicBool,
        verbose: bool,
        bar: &indicatif::ProgressBar,
    ) -> Result<bool> {
        let (film, outputs) = (&self.desc.film, self.args.outputs());
        let progress = |n: u64| bar.inc(n);
        let t_prepare = Instant::now();
        let prepared = bar.suspend(|| {
            let prepare_bar = progress_bar(1000, verbose, "precomputing ");
            let prepared = self.pool.install(|| {
                self.integrator
                    .for_film(self.scene, film, samples.clone(), cancel, &|done| {
                        prepare_bar.set_position((done * 1000.0) as u64)
                    })
            });
            prepare_bar.finish_and_clear();
            prepared
        });
        if cancel.load(Ordering::Relaxed) {
            return Ok(false);
        }
        let prepare_time = t_prepare.elapsed();
        stats.add(&RenderStats {
            wall: prepare_time,
            precompute: prepare_time,
            ..Default::default()
        });
        let integrator: &dyn Integrator = match &prepared {
            Some(p) => {
                if stats.precompute_note.as_ref() != Some(&p.note) {
                    if verbose {
                        bar.suspend(|| eprintln!("{}", p.note));
                    }
                    stats.precompute_note = Some(p.note.clone());
                }
                p.integrator.as_ref()
            }
            None => self.integrator,
        };
        let segment = self.pool.install(|| {
            render::render_outputs(
                self.scene, integrator, film, &outputs, samples, cancel, &progress,
            )
        });
        let Some(segment) = segment else {
            return Ok(false);
        };
        sums.append(&segment.sums).map_err(anyhow::Error::msg)?;
        stats.add(&segment.stats);
        Ok(true)
    }
}

/// The closing lines for people, the fields of the JSON summary, and a warning when samples
/// were dropped.
fn report(args: &RenderArgs, desc: &SceneDesc, out: &Path, rendered: &Rendered, log: &mut Log) {
    let Rendered {
        stats,
        reached,
        status,
        ..
    } = rendered;
    let (reached, status) = (*reached, *status);
    let target = desc.film.spp as u64;
    let first = args.spp_offset;
    let verbose = !args.run.quiet;
    let png = out.with_extension("png");
    if verbose || status == Status::Interrupted {
        let wrote = if args.preview.no_preview {
            out.display().to_string()
        } else {
            format!("{} and {}", out.display(), png.display())
        };
        let spp_text = match status {
            Status::Complete => format!("{reached} spp"),
            Status::TimeLimit => format!(
                "{reached} of {target} spp (time limit of {} s reached)",
                args.time_limit.unwrap_or_default()
            ),
            _ => format!("{reached} of {target} spp (interrupted)"),
        };
        let range = if first > 0 {
            format!(" (samples {first}..{})", first + reached)
        } else {
            String::new()
        };
        let [x0, y0, x1, y1] = desc.film.window();
        eprintln!(
            "rendered {}x{} at {spp_text}{range} with {} in {:.2} s: {:.3} Msamples/s, {:.3} Mrays/s",
            x1 - x0,
            y1 - y0,
            desc.integrator.name(),
            stats.wall.as_secs_f64(),
            stats.samples_per_second() / 1e6,
            stats.rays_per_second() / 1e6
        );
        eprintln!("wrote {wrote}");
    }
    // The summary line of `--log-format json`.
    log.record("outputs", args.preview.outputs(out));
    log.record("integrator", desc.integrator.name());
    log.record("spp", reached);
    log.record("spp_requested", target);
    log.record("render_status", status.label());
    log.record("time_s", stats.wall.as_secs_f64());
    log.record("precompute_s", stats.precompute.as_secs_f64());
    log.record("rays", stats.rays);
    log.record("mrays_per_s", stats.rays_per_second() / 1e6);
    log.record("nonfinite_samples", stats.nonfinite_samples);
    if stats.nonfinite_samples > 0 {
        let share = stats.nonfinite_samples as f64 / stats.samples.max(1) as f64;
        // A few dropped samples are noise; more than one in 10⁴ biases the image visibly.
        let loud = if share > 1e-4 {
            "WARNING: the image is biased darker where they fell; "
        } else {
            ""
        };
        eprintln!(
            "warning: {} of {} samples ({:.3} %) were NaN or infinite and were dropped; \
             {loud}the EXR records the count (tress:dropped_samples)",
            stats.nonfinite_samples,
            stats.samples,
            100.0 * share
        );
    }
}

pub fn info(scene: &Path, defines: &[(String, String)]) -> Result<()> {
    let desc = scene_desc::load_with(scene, &placeholders::defines(defines)?)?;
    desc.film
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: film: {e}", scene.display()))?;
    let prep = crate::default_preparation();
    let built = scene_desc::build(&desc, scene, &prep)?;
    crate::print_warnings(&prep);
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
