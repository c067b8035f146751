//! `tress study STUDY.ron`: comparative convergence studies of integrators, following the
//! protocol of hair-math.md §7.2 — an independent converged reference, MSE and relative MSE,
//! K repetitions with independent seeds and 95 % confidence intervals, equal-spp and equal-time
//! comparisons, efficiency and the MSE·spp convergence check.
//!
//! A study file (RON; paths relative to it):
//!
//! ```ron
//! (
//!     scenes: [File("scene_straight_brown_venice.ron"),
//!              Inline(name: "ball", scene: (camera: (...), film: (...), materials: {...}, objects: [...], lights: [...]))],
//!     integrators: [DualUniform(), DualMis(), Path(max_depth: 100)],
//!     spp: [1, 2, 4, 8, 16, 32, 64, 128, 256, 512],
//!     repetitions: 8,                // K independent runs per (scene, integrator, spp)
//!     seed: 1,                       // base seed of every derived seed
//!     reference: Render(integrator: Path(max_depth: 100), spp: 32768),  // or Exr("refs/{scene}.exr")
//!     references: PerIntegrator(spp: 8192),   // also each integrator's own converged render
//!     regions: [(name: "fringe", x: 40, y: 100, w: 32, h: 32)],        // film pixels
//!     film: (width: 256, height: 256),         // resolution override for every scene
//!     heatmap_spp: 16,               // error heat maps at this spp (default: the middle one)
//!     target_relmse: 0.01,           // "time to reach this relMSE" in the report
//!     exposure: 0.0,                 // of the PNG previews and crop sheets, in stops
//!     output: "results/straight",    // default: ./<study name>_study in the current folder
//!     quick: (spp: [1, 2, 4], repetitions: 2, reference_spp: 256, film: (width: 48, height: 48)),
//! )
//! ```
//!
//! Every render is an EXR (plus a PNG preview) under `renders/<scene>/`, carrying its settings
//! hash, render time (CPU and wall) and ray count as header attributes, so a rerun reads finished renders back
//! instead of redoing them. The seed of a render is a hash of the base seed, the scene name,
//! the integrator settings, spp and repetition; references hash a different tag, so they are
//! independent of every test render.

use crate::cost::timed;
use crate::diff::{self, Rect, REL_EPSILON};
use crate::integrators::IntegratorDesc;
use crate::plot::{self, Chart, HeatPanel, Picture, Series};
use crate::scene_desc::{self, BuiltScene, SceneDesc};
use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use indicatif::ProgressBar;
use serde::Deserialize;
use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tress_accel::DensitySettings;
use tress_core::film::FilmSettings;
use tress_core::image_io;
use tress_core::rng::hash_words;
use tress_core::{Image, Integrator};

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
    /// Worker threads (default: all cores). Images do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress bar and no summary.
    #[arg(long)]
    pub quiet: bool,
}

/// A study file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Study {
    /// Report title; default: the file name.
    #[serde(default)]
    pub name: Option<String>,
    pub scenes: Vec<SceneRef>,
    /// The integrators compared; the first is the baseline of the ratio tables.
    pub integrators: Vec<IntegratorDesc>,
    /// Samples per pixel, strictly increasing.
    pub spp: Vec<u32>,
    #[serde(default = "default_repetitions")]
    pub repetitions: u32,
    #[serde(default)]
    pub seed: u64,
    pub reference: Reference,
    #[serde(default)]
    pub references: References,
    #[serde(default)]
    pub regions: Vec<RegionDesc>,
    #[serde(default)]
    pub film: Option<FilmOverride>,
    #[serde(default)]
    pub output: Option<PathBuf>,
    #[serde(default)]
    pub heatmap_spp: Option<u32>,
    #[serde(default = "default_target")]
    pub target_relmse: f64,
    #[serde(default)]
    pub exposure: f32,
    #[serde(default)]
    pub quick: Quick,
}

fn default_repetitions() -> u32 {
    8
}

fn default_target() -> f64 {
    1e-2
}

/// A scene of the study; its own integrator, spp, seed and crop are ignored.
#[derive(Debug, Deserialize)]
pub enum SceneRef {
    /// A scene file; named by its file stem.
    File(PathBuf),
    /// A scene written in the study file (relative paths resolve against the study file).
    Inline { name: String, scene: Box<SceneDesc> },
}

/// The common reference every render is compared with.
#[derive(Debug, Deserialize)]
pub enum Reference {
    /// Rendered once per scene (cached in the output folder) with its own seed.
    Render {
        integrator: IntegratorDesc,
        spp: u32,
    },
    /// An EXR file per scene; `{scene}` in the path is replaced by the scene name.
    Exr(String),
}

/// Extra references.
#[derive(Debug, Default, Deserialize)]
pub enum References {
    /// Only the common reference.
    #[default]
    Common,
    /// Also compare each integrator with its own converged render at `spp` (no bias there, so
    /// it separates variance from bias).
    PerIntegrator { spp: u32 },
}

/// A named region of interest, in film pixels.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionDesc {
    pub name: String,
    pub x: u32,
    pub y: u32,
    pub w: u32,
    pub h: u32,
}

/// Film resolution for every scene of the study (the camera keeps its field of view).
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilmOverride {
    pub width: u32,
    pub height: u32,
}

/// What `--quick` changes; unset fields get scaled-down defaults.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Quick {
    pub spp: Option<Vec<u32>>,
    pub repetitions: Option<u32>,
    pub reference_spp: Option<u32>,
    pub per_integrator_spp: Option<u32>,
    pub film: Option<FilmOverride>,
}

/// Reads and parses a study file; errors name the file, line and column.
pub fn load(path: &Path) -> Result<Study> {
    let text = tress_core::files::read_regular_text(path)
        .with_context(|| format!("cannot read study file {}", path.display()))?;
    crate::ron_options()
        .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
        .from_str::<Study>(&text)
        .map_err(|e| {
            let p = e.span.start;
            let mut msg = format!("{}:{}:{}: {}", path.display(), p.line, p.col, e.code);
            if let Some(line) = text.lines().nth(p.line.saturating_sub(1)) {
                let caret = " ".repeat(line.chars().take(p.col.saturating_sub(1)).count());
                let _ = write!(msg, "\n    {line}\n    {caret}^");
            }
            anyhow!(msg)
        })
}

// ---------------------------------------------------------------------------------------------
// The plan: the study resolved against its file, --quick and the command line.

struct PlanScene {
    name: String,
    /// Where it came from, for messages.
    source: String,
    desc: SceneDesc,
    /// Relative paths of the scene resolve against this file's folder.
    base: PathBuf,
    /// Hash of everything that determines its images, for the render cache.
    content: u64,
    /// Regions of interest in this scene's film.
    regions: Vec<Rect>,
}

struct PlanIntegrator {
    desc: IntegratorDesc,
    label: String,
    ron: String,
}

enum PlanReference {
    Render {
        integrator: PlanIntegrator,
        spp: u32,
    },
    Exr(String),
}

struct Plan {
    title: String,
    study_path: PathBuf,
    command: String,
    out: PathBuf,
    scenes: Vec<PlanScene>,
    integrators: Vec<PlanIntegrator>,
    spp: Vec<u32>,
    reps: u32,
    seed: u64,
    reference: PlanReference,
    own_spp: Option<u32>,
    region_names: Vec<String>,
    heatmap_spp: u32,
    target_relmse: f64,
    gain: f32,
}

fn valid_name(s: &str) -> bool {
    !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// A stable 64-bit hash of a string (FNV-1a, then mixed), for seeds and cache keys.
fn str_hash(s: &str) -> u64 {
    bytes_hash(s.as_bytes())
}

/// The hash of an image's pixel values (bits), recorded in cached renders.
fn pixels_hash(image: &tress_core::Image) -> String {
    let bytes: Vec<u8> = image
        .pixels
        .iter()
        .flat_map(|p| p.to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    format!("{:016x}", bytes_hash(&bytes))
}

/// [`str_hash`] of any bytes (files' contents for the cache key).
fn bytes_hash(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
    }
    tress_core::rng::mix64(h)
}

/// Seeds: tags keep test renders and references apart.
const TAG_TEST: u64 = 0x7e57;
const TAG_REFERENCE: u64 = 0x5ef0;

fn test_seed(base: u64, scene: &str, ron: &str, spp: u32, rep: u32) -> u64 {
    hash_words(&[
        base,
        str_hash(scene),
        str_hash(ron),
        spp as u64,
        rep as u64,
        TAG_TEST,
    ])
}

fn reference_seed(base: u64, scene: &str, ron: &str, spp: u32) -> u64 {
    hash_words(&[
        base,
        str_hash(scene),
        str_hash(ron),
        spp as u64,
        TAG_REFERENCE,
    ])
}

fn plan_integrator(desc: IntegratorDesc, label: String) -> PlanIntegrator {
    let ron = ron::to_string(&desc).unwrap_or_else(|_| format!("{desc:?}"));
    PlanIntegrator { desc, label, ron }
}

/// Middle of the spp list on a log scale.
fn middle_spp(spp: &[u32]) -> u32 {
    spp[spp.len() / 2]
}

impl Plan {
    fn new(study: Study, args: &StudyArgs) -> Result<Plan> {
        let path = &args.study;
        let here = |what: String| anyhow!("{}: {what}", path.display());
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "study".into());

        if study.scenes.is_empty() {
            return Err(here("scenes: the list is empty".into()));
        }
        if study.integrators.is_empty() {
            return Err(here("integrators: the list is empty".into()));
        }
        let check_spp = |field: &str, spp: &[u32]| -> Result<()> {
            if spp.is_empty() {
                return Err(here(format!("{field}: the list is empty")));
            }
            if spp[0] == 0 || spp.windows(2).any(|w| w[0] >= w[1]) {
                return Err(here(format!(
                    "{field}: {spp:?} must be positive and strictly increasing"
                )));
            }
            Ok(())
        };
        check_spp("spp", &study.spp)?;
        if study.repetitions == 0 {
            return Err(here("repetitions must be at least 1".into()));
        }
        if !(study.target_relmse.is_finite() && study.target_relmse > 0.0) {
            return Err(here(format!(
                "target_relmse = {} must be finite and positive",
                study.target_relmse
            )));
        }
        if !study.exposure.is_finite() {
            return Err(here(format!(
                "exposure = {} must be finite",
                study.exposure
            )));
        }
        let mut region_names: Vec<String> = Vec::new();
        for r in &study.regions {
            if !valid_name(&r.name) {
                return Err(here(format!(
                    "regions: name '{}' must be letters, digits, '_' or '-'",
                    r.name
                )));
            }
            if region_names.contains(&r.name) {
                return Err(here(format!("regions: '{}' is defined twice", r.name)));
            }
            if r.w == 0 || r.h == 0 {
                return Err(here(format!("regions: '{}' is empty", r.name)));
            }
            region_names.push(r.name.clone());
        }
        if let Some(h) = study.heatmap_spp {
            if !study.spp.contains(&h) {
                return Err(here(format!(
                    "heatmap_spp = {h} is not one of spp {:?}",
                    study.spp
                )));
            }
        }

        // --quick: scaled-down settings.
        let q = &study.quick;
        let quick = args.quick;
        let spp = match (&q.spp, quick) {
            (Some(s), true) => {
                check_spp("quick.spp", s)?;
                s.clone()
            }
            (None, true) => {
                let small: Vec<u32> = study.spp.iter().copied().filter(|&s| s <= 16).collect();
                if small.len() >= 2 {
                    small
                } else {
                    study.spp.iter().copied().take(3).collect()
                }
            }
            (_, false) => study.spp.clone(),
        };
        let reps = match (q.repetitions, quick) {
            (Some(0), true) => return Err(here("quick.repetitions must be at least 1".into())),
            (Some(r), true) => r,
            (None, true) => study.repetitions.min(3),
            (_, false) => study.repetitions,
        };
        let max_spp = *spp.last().unwrap_or(&1);
        let quick_ref = |full: u32, set: Option<u32>| -> u32 {
            match (set, quick) {
                (Some(s), true) => s,
                (None, true) => full.min((16 * max_spp).max(64)),
                (_, false) => full,
            }
        };
        let reference = match study.reference {
            Reference::Render { integrator, spp } => {
                let spp = quick_ref(spp, q.reference_spp);
                if spp == 0 {
                    return Err(here("reference: spp must be at least 1".into()));
                }
                let label = integrator.name().to_string();
                PlanReference::Render {
                    integrator: plan_integrator(integrator, label),
                    spp,
                }
            }
            Reference::Exr(p) => PlanReference::Exr(p),
        };
        let own_spp = match study.references {
            References::Common => None,
            References::PerIntegrator { spp } => {
                let spp = quick_ref(spp, q.per_integrator_spp);
                if spp == 0 {
                    return Err(here(
                        "references: PerIntegrator spp must be at least 1".into(),
                    ));
                }
                Some(spp)
            }
        };
        let heatmap_spp = match study.heatmap_spp {
            Some(h) if spp.contains(&h) => h,
            _ => middle_spp(&spp),
        };

        // Integrator labels: the short name, numbered when several share it.
        let names: Vec<&str> = study.integrators.iter().map(|d| d.name()).collect();
        let integrators: Vec<PlanIntegrator> = study
            .integrators
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let name = names[i];
                let label = if names.iter().filter(|n| **n == name).count() > 1 {
                    let k = names[..=i].iter().filter(|n| **n == name).count();
                    format!("{name}-{k}")
                } else {
                    name.to_string()
                };
                plan_integrator(d.clone(), label)
            })
            .collect();
        let mut seen: Vec<&str> = Vec::new();
        for i in &integrators {
            if seen.contains(&i.ron.as_str()) {
                return Err(here(format!("integrators: {} is listed twice", i.ron)));
            }
            seen.push(&i.ron);
        }

        // Scenes, with the film override and --quick resolution applied.
        let mut scenes: Vec<PlanScene> = Vec::new();
        for (i, s) in study.scenes.into_iter().enumerate() {
            let (name, source, mut desc, base) = match s {
                SceneRef::File(p) => {
                    let file = scene_desc::resolve(path, &p);
                    let desc = scene_desc::load(&file)
                        .with_context(|| format!("{}: scenes[{i}]", path.display()))?;
                    let name: String = file
                        .file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_default()
                        .chars()
                        .map(|c| if valid_name(&c.to_string()) { c } else { '_' })
                        .collect();
                    (name, file.display().to_string(), desc, file)
                }
                SceneRef::Inline { name, scene } => {
                    if !valid_name(&name) {
                        return Err(here(format!(
                            "scenes[{i}]: name '{name}' must be letters, digits, '_' or '-'"
                        )));
                    }
                    let source = format!("{} (inline scene '{name}')", path.display());
                    (name, source, *scene, path.clone())
                }
            };
            if scenes.iter().any(|o| o.name == name) {
                return Err(here(format!(
                    "scenes[{i}]: a scene named '{name}' is already in the study; scene names \
                     (file stems) must differ"
                )));
            }
            if let Some(f) = study.film {
                desc.film.width = f.width;
                desc.film.height = f.height;
            }
            desc.film.crop = None;
            desc.film.spp = 1;
            desc.film.seed = 0;
            desc.film
                .validate()
                .map_err(|e| here(format!("scene '{name}': film: {e}")))?;
            let (w0, h0) = (desc.film.width, desc.film.height);
            if quick {
                // An EXR reference fixes the resolution.
                let exr_ref = matches!(reference, PlanReference::Exr(_));
                match q.film {
                    Some(f) => {
                        desc.film.width = f.width;
                        desc.film.height = f.height;
                    }
                    None if !exr_ref && w0.max(h0) > 64 => {
                        let s = 64.0 / w0.max(h0) as f64;
                        desc.film.width = ((w0 as f64 * s).round() as u32).max(1);
                        desc.film.height = ((h0 as f64 * s).round() as u32).max(1);
                    }
                    None => {}
                }
                desc.film
                    .validate()
                    .map_err(|e| here(format!("quick.film: {e}")))?;
            }
            let (w, h) = (desc.film.width, desc.film.height);
            let mut regions = Vec::new();
            for r in &study.regions {
                // Region coordinates refer to the study's film; --quick scales them along.
                let sx = |v: u32| (v as u64 * w as u64 / w0 as u64) as u32;
                let sy = |v: u32| (v as u64 * h as u64 / h0 as u64) as u32;
                let rect = Rect {
                    x: sx(r.x),
                    y: sy(r.y),
                    w: sx(r.w).max(1),
                    h: sy(r.h).max(1),
                };
                let film = Rect { x: 0, y: 0, w, h };
                if rect.x as u64 + rect.w as u64 > w as u64
                    || rect.y as u64 + rect.h as u64 > h as u64
                {
                    return Err(here(format!(
                        "regions: '{}' ({rect}) is not inside scene '{name}''s {}x{} film",
                        r.name, film.w, film.h
                    )));
                }
                regions.push(rect);
            }
            let mut keyed = desc.clone();
            keyed.integrator = IntegratorDesc::default();
            // The files' contents and tress's version too: replacing an environment map (or
            // updating tress) must not reuse renders of the old one.
            let mut files = String::new();
            for f in desc.referenced_files(&base) {
                let bytes = std::fs::read(&f)
                    .map_err(|e| here(format!("scene '{name}': {}: {e}", f.display())))?;
                files.push_str(&format!("{:016x}|", bytes_hash(&bytes)));
            }
            let content = str_hash(&format!(
                "{}|{}|{files}|tress {}",
                ron::to_string(&keyed).unwrap_or_else(|_| format!("{keyed:?}")),
                base.display(),
                env!("CARGO_PKG_VERSION")
            ));
            scenes.push(PlanScene {
                name,
                source,
                desc,
                base,
                content,
                regions,
            });
        }

        let out = match (&args.out, &study.output) {
            (Some(o), _) => o.clone(),
            (None, Some(o)) => suffix(scene_desc::resolve(path, o), quick),
            (None, None) => suffix(PathBuf::from(format!("{stem}_study")), quick),
        };
        let command = format!(
            "tress study {}{}",
            path.display(),
            if quick { " --quick" } else { "" }
        );
        Ok(Plan {
            title: study.name.unwrap_or(stem),
            study_path: path.clone(),
            command,
            out,
            scenes,
            integrators,
            spp,
            reps,
            seed: study.seed,
            reference,
            own_spp,
            region_names,
            heatmap_spp,
            target_relmse: study.target_relmse,
            gain: study.exposure.exp2(),
        })
    }

    /// Samples of all renders, for the progress bar.
    fn total_samples(&self) -> u64 {
        let n = self.integrators.len() as u64;
        let per_pixel = self.spp.iter().map(|&s| s as u64).sum::<u64>() * self.reps as u64 * n
            + match &self.reference {
                PlanReference::Render { spp, .. } => *spp as u64,
                PlanReference::Exr(_) => 0,
            }
            + self.own_spp.map_or(0, |s| s as u64 * n);
        self.scenes
            .iter()
            .map(|s| s.desc.film.width as u64 * s.desc.film.height as u64 * per_pixel)
            .sum()
    }
}

fn suffix(p: PathBuf, quick: bool) -> PathBuf {
    if !quick {
        return p;
    }
    let mut s = p.into_os_string();
    s.push("_quick");
    PathBuf::from(s)
}

// ---------------------------------------------------------------------------------------------
// Rendering, with the cache.

/// One image to obtain.
struct Job<'a> {
    integrator: &'a PlanIntegrator,
    spp: u32,
    seed: u64,
    exr: PathBuf,
}

struct Rendered {
    image: Image,
    /// The render's cost: CPU seconds of the render threads (wall seconds where the kernel
    /// does not report CPU time), so that other load on the machine does not skew equal-time
    /// comparisons.
    time_s: f64,
    wall_s: f64,
    rays: u64,
}

enum Cached {
    Missing,
    Stale(String),
    Hit(Rendered),
}

/// The study's render loop over one scene: builds the scene and integrators only when a render
/// is actually needed, so a fully cached rerun reads images only.
struct SceneRunner<'a> {
    scene: &'a PlanScene,
    /// Built scenes by the density grid they hold.
    built: Vec<(Option<DensitySettings>, BuiltScene)>,
    integrators: HashMap<String, Box<dyn Integrator>>,
    pool: &'a rayon::ThreadPool,
    bar: &'a ProgressBar,
    verbose: bool,
    rendered: usize,
    reused: usize,
    render_seconds: f64,
}

/// A message on stderr that does not garble the progress bar (which drops messages when hidden).
fn note(bar: &ProgressBar, msg: String) {
    if bar.is_hidden() {
        eprintln!("{msg}");
    } else {
        bar.println(msg);
    }
}

fn attribute<'a>(attrs: &'a [(String, String)], key: &str) -> Option<&'a str> {
    attrs
        .iter()
        .find(|(n, _)| n == key)
        .map(|(_, v)| v.as_str())
}

impl SceneRunner<'_> {
    fn key(&self, job: &Job) -> String {
        format!(
            "{:016x}",
            hash_words(&[
                self.scene.content,
                str_hash(&job.integrator.ron),
                job.spp as u64,
                job.seed
            ])
        )
    }

    fn cached(&self, job: &Job, key: &str) -> Cached {
        if !job.exr.exists() {
            return Cached::Missing;
        }
        let (image, attrs) = match image_io::read_exr(&job.exr) {
            Ok(r) => r,
            Err(e) => return Cached::Stale(format!("unreadable ({e})")),
        };
        if attribute(&attrs, "tress:study_key") != Some(key) {
            return Cached::Stale("made with other settings".into());
        }
        // An image edited after the render (attributes kept) must not pass for the render.
        if attribute(&attrs, "tress:pixels_hash") != Some(pixels_hash(&image).as_str()) {
            return Cached::Stale("its pixels changed since it was rendered".into());
        }
        let film = &self.scene.desc.film;
        if (
            image.full_width,
            image.full_height,
            image.width,
            image.height,
        ) != (film.width, film.height, film.width, film.height)
        {
            return Cached::Stale("wrong size".into());
        }
        let number = |key| attribute(&attrs, key).and_then(|v| v.parse().ok());
        let time_s = number("tress:render_cpu_s");
        let wall_s = number("tress:render_time_s");
        let rays = attribute(&attrs, "tress:rays").and_then(|v| v.parse().ok());
        match (time_s, wall_s, rays) {
            (Some(time_s), Some(wall_s), Some(rays)) => Cached::Hit(Rendered {
                image,
                time_s,
                wall_s,
                rays,
            }),
            _ => Cached::Stale("no render time or ray count".into()),
        }
    }

    fn run(&mut self, job: &Job) -> Result<Rendered> {
        let film = FilmSettings {
            spp: job.spp,
            seed: job.seed,
            ..self.scene.desc.film.clone()
        };
        let samples = film.width as u64 * film.height as u64 * film.spp as u64;
        let key = self.key(job);
        match self.cached(job, &key) {
            Cached::Hit(r) => {
                self.reused += 1;
                self.bar.inc(samples);
                return Ok(r);
            }
            Cached::Stale(why) if self.verbose => {
                note(
                    self.bar,
                    format!("re-rendering {}: {why}", job.exr.display()),
                );
            }
            _ => {}
        }

        let scene = &self.scene;
        let pool = self.pool;
        // The scene carries the density grid its integrator asks for, so integrators with
        // different grid needs get different builds of it.
        let grid = job.integrator.desc.density_grid();
        let b = match self.built.iter().position(|(g, _)| *g == grid) {
            Some(b) => b,
            None => {
                let desc = SceneDesc {
                    integrator: job.integrator.desc.clone(),
                    ..scene.desc.clone()
                };
                let built = pool.install(|| scene_desc::build(&desc, &scene.base))?;
                self.built.push((grid, built));
                self.built.len() - 1
            }
        };
        let built = &self.built[b].1;
        let integrator = match self.integrators.entry(job.integrator.ron.clone()) {
            Entry::Occupied(e) => e.into_mut(),
            Entry::Vacant(e) => {
                e.insert(job.integrator.desc.build(&built.scene).with_context(|| {
                    format!("{}: integrator {}", scene.source, job.integrator.ron)
                })?)
            }
        };
        let bar = self.bar;
        let progress = |n: u64| bar.inc(n);
        let (output, cost) = timed(|| {
            pool.install(|| {
                tress_core::render::render(&built.scene, integrator.as_ref(), &film, &progress)
            })
        });
        let stats = &output.stats;
        if stats.nonfinite_samples > 0 {
            note(
                bar,
                format!(
                    "warning: {}: {} samples were NaN or infinite and were dropped",
                    job.exr.display(),
                    stats.nonfinite_samples
                ),
            );
        }
        let wall_s = stats.wall.as_secs_f64();
        let time_s = cost.cpu.unwrap_or(wall_s);
        let attributes = [
            ("tress:scene", scene.source.clone()),
            ("tress:integrator", job.integrator.ron.clone()),
            ("tress:spp", job.spp.to_string()),
            ("tress:seed", job.seed.to_string()),
            ("tress:render_time_s", wall_s.to_string()),
            ("tress:render_cpu_s", time_s.to_string()),
            ("tress:rays", stats.rays.to_string()),
            ("tress:study_key", key),
            ("tress:pixels_hash", pixels_hash(&output.image)),
        ];
        if let Some(dir) = job.exr.parent() {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("creating output folder {}", dir.display()))?;
        }
        image_io::write_exr(&job.exr, &output.image, &attributes)?;
        image_io::write_png(job.exr.with_extension("png"), &output.image, 0.0)?;
        self.rendered += 1;
        self.render_seconds += time_s;
        Ok(Rendered {
            image: output.image,
            time_s,
            wall_s,
            rays: stats.rays,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Measurements.

/// Errors of one render against one reference over one region.
#[derive(Clone, Copy, Debug)]
struct Errors {
    mse: f64,
    relmse: f64,
    mean: f64,
    ref_mean: f64,
}

impl From<&diff::Metrics> for Errors {
    fn from(m: &diff::Metrics) -> Self {
        Errors {
            mse: m.mse_all(),
            relmse: m.relmse_all(),
            mean: m.mean_a_all(),
            ref_mean: m.mean_b_all(),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum RefKind {
    Common,
    Own,
}

impl RefKind {
    fn name(self) -> &'static str {
        match self {
            RefKind::Common => "common",
            RefKind::Own => "own",
        }
    }
}

/// One line of results.csv.
struct Row {
    scene: usize,
    integrator: usize,
    spp: u32,
    rep: u32,
    seed: u64,
    time_s: f64,
    wall_s: f64,
    rays: u64,
    reference: RefKind,
    whole: Errors,
    regions: Vec<Errors>,
}

/// Errors of `img` against `reference` over the whole image and each region.
fn measure(img: &Image, reference: &Image, regions: &[Rect]) -> (Errors, Vec<Errors>) {
    let whole = Errors::from(&diff::metrics(img, reference, Rect::window_of(img)));
    let regions = regions
        .iter()
        .map(|r| Errors::from(&diff::metrics(img, reference, *r)))
        .collect();
    (whole, regions)
}

/// A tone-mapped crop for the sheets.
fn picture(img: &Image, r: Rect, gain: f32) -> Picture {
    let mut rgb = Vec::with_capacity(r.w as usize * r.h as usize * 3);
    for y in r.y..r.y + r.h {
        for x in r.x..r.x + r.w {
            let p = img.get(x - img.x0, y - img.y0);
            rgb.extend([p.x, p.y, p.z].map(|c| plot::srgb8(c, gain)));
        }
    }
    Picture {
        width: r.w,
        height: r.h,
        rgb,
    }
}

/// What the figures need from one scene.
struct SceneFigures {
    /// Per integrator: the relative error map at `heatmap_spp`, repetition 0.
    heat: Vec<Option<Vec<f32>>>,
    /// [sheet region][integrator][spp index]: crops of repetition 0.
    crops: Vec<Vec<Vec<Option<Picture>>>>,
    /// [sheet region]: the common reference crop; [sheet region][integrator]: own reference crops.
    ref_crops: Vec<Picture>,
    own_crops: Vec<Vec<Option<Picture>>>,
}

struct Results {
    rows: Vec<Row>,
    /// MSE of the mean image of the repetitions, by (scene, integrator, spp, reference).
    mean_mse: HashMap<(usize, usize, u32, RefKind), f64>,
    figures: Vec<SceneFigures>,
    rendered: usize,
    reused: usize,
    render_seconds: f64,
}

/// Sheet regions: the study's regions, or the whole film when it names none.
fn sheet_regions(plan: &Plan, scene: &PlanScene) -> Vec<(String, Rect)> {
    if plan.region_names.is_empty() {
        let f = &scene.desc.film;
        vec![(
            "full".into(),
            Rect {
                x: 0,
                y: 0,
                w: f.width,
                h: f.height,
            },
        )]
    } else {
        plan.region_names
            .iter()
            .cloned()
            .zip(scene.regions.iter().copied())
            .collect()
    }
}

/// The render of a reference: its file name holds the integrator settings' hash, so the common
/// reference and an integrator's own reference with the same settings are one file.
fn reference_job<'a>(
    plan: &Plan,
    scene: &PlanScene,
    integrator: &'a PlanIntegrator,
    spp: u32,
) -> Job<'a> {
    Job {
        integrator,
        spp,
        seed: reference_seed(plan.seed, &scene.name, &integrator.ron, spp),
        exr: plan.out.join("references").join(&scene.name).join(format!(
            "{}_{spp}spp_{:08x}.exr",
            integrator.desc.name(),
            str_hash(&integrator.ron) as u32
        )),
    }
}

fn execute(
    plan: &Plan,
    pool: &rayon::ThreadPool,
    bar: &ProgressBar,
    verbose: bool,
) -> Result<Results> {
    let mut results = Results {
        rows: Vec::new(),
        mean_mse: HashMap::new(),
        figures: Vec::new(),
        rendered: 0,
        reused: 0,
        render_seconds: 0.0,
    };
    for (si, scene) in plan.scenes.iter().enumerate() {
        let mut runner = SceneRunner {
            scene,
            built: Vec::new(),
            integrators: HashMap::new(),
            pool,
            bar,
            verbose,
            rendered: 0,
            reused: 0,
            render_seconds: 0.0,
        };
        let common = match &plan.reference {
            PlanReference::Render { integrator, spp } => {
                runner
                    .run(&reference_job(plan, scene, integrator, *spp))?
                    .image
            }
            PlanReference::Exr(template) => {
                let file = scene_desc::resolve(
                    &plan.study_path,
                    Path::new(&template.replace("{scene}", &scene.name)),
                );
                let (img, _) = image_io::read_exr(&file).with_context(|| {
                    format!(
                        "{}: reference of scene '{}'",
                        plan.study_path.display(),
                        scene.name
                    )
                })?;
                let film = &scene.desc.film;
                if (img.full_width, img.full_height, img.width, img.height)
                    != (film.width, film.height, film.width, film.height)
                {
                    bail!(
                        "reference {} is a window {} of a {}x{} film, but scene '{}' ({}) renders a full {}x{} film",
                        file.display(),
                        Rect::window_of(&img),
                        img.full_width,
                        img.full_height,
                        scene.name,
                        scene.source,
                        film.width,
                        film.height
                    );
                }
                img
            }
        };
        let mut own: Vec<Option<Image>> = Vec::new();
        for integrator in &plan.integrators {
            own.push(match plan.own_spp {
                Some(spp) => Some(
                    runner
                        .run(&reference_job(plan, scene, integrator, spp))?
                        .image,
                ),
                None => None,
            });
        }

        let sheets = sheet_regions(plan, scene);
        let mut fig = SceneFigures {
            heat: vec![None; plan.integrators.len()],
            crops: vec![vec![vec![None; plan.spp.len()]; plan.integrators.len()]; sheets.len()],
            ref_crops: sheets
                .iter()
                .map(|(_, r)| picture(&common, *r, plan.gain))
                .collect(),
            own_crops: sheets
                .iter()
                .map(|(_, r)| {
                    own.iter()
                        .map(|o| o.as_ref().map(|img| picture(img, *r, plan.gain)))
                        .collect()
                })
                .collect(),
        };
        let dir = plan.out.join("renders").join(&scene.name);
        for (ii, integrator) in plan.integrators.iter().enumerate() {
            for (k, &spp) in plan.spp.iter().enumerate() {
                // Sum of the repetitions, for the bias estimate from their mean image.
                let mut sum = vec![[0.0f64; 3]; common.pixels.len()];
                for rep in 0..plan.reps {
                    let seed = test_seed(plan.seed, &scene.name, &integrator.ron, spp, rep);
                    let job = Job {
                        integrator,
                        spp,
                        seed,
                        exr: dir.join(format!("{}_{spp:05}spp_rep{rep:02}.exr", integrator.label)),
                    };
                    let r = runner.run(&job)?;
                    for (s, p) in sum.iter_mut().zip(&r.image.pixels) {
                        for c in 0..3 {
                            s[c] += p[c] as f64;
                        }
                    }
                    let mut push = |reference: &Image, kind: RefKind| {
                        let (whole, regions) = measure(&r.image, reference, &scene.regions);
                        results.rows.push(Row {
                            scene: si,
                            integrator: ii,
                            spp,
                            rep,
                            seed,
                            time_s: r.time_s,
                            wall_s: r.wall_s,
                            rays: r.rays,
                            reference: kind,
                            whole,
                            regions,
                        });
                    };
                    push(&common, RefKind::Common);
                    if let Some(o) = &own[ii] {
                        push(o, RefKind::Own);
                    }
                    if rep == 0 {
                        for (g, (_, rect)) in sheets.iter().enumerate() {
                            fig.crops[g][ii][k] = Some(picture(&r.image, *rect, plan.gain));
                        }
                        if spp == plan.heatmap_spp {
                            fig.heat[ii] = Some(diff::error_map(
                                &r.image,
                                &common,
                                Rect::window_of(&common),
                                diff::MapKind::Rel,
                            ));
                        }
                    }
                }
                if plan.reps > 1 {
                    let mut mean = common.clone();
                    let k = plan.reps as f64;
                    for (m, s) in mean.pixels.iter_mut().zip(&sum) {
                        *m = glam::Vec3::new(
                            (s[0] / k) as f32,
                            (s[1] / k) as f32,
                            (s[2] / k) as f32,
                        );
                    }
                    let window = Rect::window_of(&mean);
                    let mse = |r: &Image| diff::metrics(&mean, r, window).mse_all();
                    results
                        .mean_mse
                        .insert((si, ii, spp, RefKind::Common), mse(&common));
                    if let Some(o) = &own[ii] {
                        results.mean_mse.insert((si, ii, spp, RefKind::Own), mse(o));
                    }
                }
            }
        }
        results.figures.push(fig);
        results.rendered += runner.rendered;
        results.reused += runner.reused;
        results.render_seconds += runner.render_seconds;
    }
    Ok(results)
}

// ---------------------------------------------------------------------------------------------
// Statistics over repetitions.

/// Mean and the half-width of its 95 % confidence interval (Student t; none for one value).
#[derive(Clone, Copy, Debug)]
struct Stat {
    mean: f64,
    ci: Option<f64>,
}

/// The 97.5 % quantile of Student's t with `df` degrees of freedom.
fn t975(df: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    if (1..=30).contains(&df) {
        return TABLE[df - 1];
    }
    // Cornish–Fisher expansion about the normal quantile; within 1e-3 beyond 30 dof.
    let z = 1.959_964f64;
    let n = df.max(1) as f64;
    z + (z.powi(3) + z) / (4.0 * n)
        + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * n * n)
}

fn stat(v: &[f64]) -> Stat {
    let n = v.len();
    let mean = v.iter().sum::<f64>() / n.max(1) as f64;
    let ci = (n > 1).then(|| {
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        t975(n - 1) * (var / n as f64).sqrt()
    });
    Stat { mean, ci }
}

/// Averages over the repetitions of one (integrator, spp) setting.
#[derive(Clone, Copy, Debug)]
struct Point {
    spp: u32,
    mse: Stat,
    relmse: Stat,
    time_s: f64,
    /// Mean squared bias over the pixels and channels, (K·MSE(mean image) − mean MSE)/(K − 1)
    /// for K ≥ 2 repetitions: unbiased, since the mean of K independent renders has the same
    /// bias and 1/K of the variance. It includes the reference's own squared error.
    bias2: Option<f64>,
}

/// The convergence curve of one integrator in one scene, against one reference, over the whole
/// image (`region` None) or a region.
fn curve(
    res: &Results,
    plan: &Plan,
    scene: usize,
    integrator: usize,
    kind: RefKind,
    region: Option<usize>,
) -> Vec<Point> {
    plan.spp
        .iter()
        .filter_map(|&spp| {
            let rows: Vec<&Row> = res
                .rows
                .iter()
                .filter(|r| {
                    r.scene == scene
                        && r.integrator == integrator
                        && r.reference == kind
                        && r.spp == spp
                })
                .collect();
            if rows.is_empty() {
                return None;
            }
            let err = |r: &Row| match region {
                None => r.whole,
                Some(g) => r.regions[g],
            };
            let mse: Vec<f64> = rows.iter().map(|r| err(r).mse).collect();
            let rel: Vec<f64> = rows.iter().map(|r| err(r).relmse).collect();
            let time: Vec<f64> = rows.iter().map(|r| r.time_s).collect();
            let mse = stat(&mse);
            let k = rows.len() as f64;
            let bias2 = match region {
                None => res
                    .mean_mse
                    .get(&(scene, integrator, spp, kind))
                    .map(|m| (k * m - mse.mean) / (k - 1.0)),
                Some(_) => None,
            };
            Some(Point {
                spp,
                mse,
                relmse: stat(&rel),
                time_s: stat(&time).mean,
                bias2,
            })
        })
        .collect()
}

/// Piecewise-linear interpolation of `y(x)` in log-log space; `None` outside the sampled range
/// (no extrapolation). `pts` need not be sorted.
fn loglog_at(pts: &[(f64, f64)], x: f64) -> Option<f64> {
    let mut p: Vec<(f64, f64)> = pts
        .iter()
        .copied()
        .filter(|(a, b)| *a > 0.0 && *b > 0.0 && a.is_finite() && b.is_finite())
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    if p.is_empty() || x < p[0].0 || x > p[p.len() - 1].0 {
        return None;
    }
    if p.len() == 1 {
        return Some(p[0].1);
    }
    let i = p.partition_point(|q| q.0 < x).clamp(1, p.len() - 1);
    let ((x0, y0), (x1, y1)) = (p[i - 1], p[i]);
    if x == x1 {
        return Some(y1);
    }
    if x1 == x0 {
        return Some(y0);
    }
    let f = (x.ln() - x0.ln()) / (x1.ln() - x0.ln());
    Some((y0.ln() + f * (y1.ln() - y0.ln())).exp())
}

/// Where a curve first reaches relMSE ≤ `target`: (spp, seconds), interpolated in log-log
/// between the settings around the crossing.
enum Reach {
    /// Already at the smallest spp.
    AtOnce(u32, f64),
    At(f64, f64),
    Never(f64),
}

fn reach(points: &[Point], target: f64) -> Reach {
    let k = match points.iter().position(|p| p.relmse.mean <= target) {
        None => {
            let best = points
                .iter()
                .map(|p| p.relmse.mean)
                .fold(f64::INFINITY, f64::min);
            return Reach::Never(best);
        }
        Some(k) => k,
    };
    if k == 0 {
        return Reach::AtOnce(points[0].spp, points[0].time_s);
    }
    let (a, b) = (&points[k - 1], &points[k]);
    let f = (target.ln() - a.relmse.mean.ln()) / (b.relmse.mean.ln() - a.relmse.mean.ln());
    let lerp = |u: f64, v: f64| (u.ln() + f * (v.ln() - u.ln())).exp();
    Reach::At(
        lerp(a.spp as f64, b.spp as f64),
        lerp(a.time_s.max(1e-9), b.time_s.max(1e-9)),
    )
}

/// One line on how MSE·spp evolves: flat for unbiased 1/N convergence, rising for an error
/// floor, which the bias estimate then attributes to bias or to heavy-tailed variance. `noise`
/// is the reference's own noise (an spp-independent additive term of every MSE and bias², the
/// test seeds being independent of the reference's), subtracted first when known.
fn verdict(points: &[Point], noise: Option<f64>) -> String {
    let (Some(first), Some(last)) = (points.first(), points.last()) else {
        return "no data".into();
    };
    if points.len() < 2 {
        return "a single spp setting: no convergence trend".into();
    }
    let n = noise.unwrap_or(0.0);
    let p0 = (first.mse.mean - n) * first.spp as f64;
    let p1 = (last.mse.mean - n) * last.spp as f64;
    let span = format!("{} to {} spp", first.spp, last.spp);
    if p0.is_nan() || p0 <= 0.0 {
        return format!(
            "MSE at {} spp is at the reference noise: cannot judge",
            first.spp
        );
    }
    let rise = p1 / p0;
    // Split the MSE at the highest spp into bias² and variance.
    let split = last.bias2.map(|b| {
        let b2 = (b - n).max(0.0);
        (b2, (last.mse.mean - n - b2).max(0.0))
    });
    let at = last.spp;
    if rise > 2.0 {
        match split {
            Some((b2, var)) if b2 > var => format!(
                "**bias**: MSE·spp rises ×{rise:.2} from {span} and at {at} spp bias² ≈ \
                 {b2:.3e} (RMS {:.3e}) exceeds the variance {var:.3e}: the estimator converges \
                 to a different image than this reference",
                b2.sqrt()
            ),
            Some((b2, var)) => format!(
                "**excess variance**: MSE·spp rises ×{rise:.2} from {span}, but at {at} spp the \
                 mean of the repetitions is as close as independent noise predicts (bias² ≈ \
                 {b2:.3e} < variance {var:.3e}): heavy-tailed samples (rare and very bright) \
                 that low spp rarely draw"
            ),
            None => format!(
                "**error floor**: MSE·spp rises ×{rise:.2} from {span} (one repetition: bias \
                 and heavy-tailed variance cannot be told apart)"
            ),
        }
    } else {
        let trend = if rise < 0.5 {
            format!(
                "MSE·spp falls ×{:.2} from {span}: faster than 1/N",
                1.0 / rise
            )
        } else {
            format!("flat (×{rise:.2} from {span}): consistent with unbiased 1/N convergence")
        };
        match split {
            // An error floor that MSE·spp does not show yet at these spp (the variance still
            // dominates at the low end) but that the repetitions' mean already does.
            Some((b2, var)) if b2 > var => format!(
                "**bias**: at {at} spp bias² ≈ {b2:.3e} (RMS {:.3e}) exceeds the variance \
                 {var:.3e}, though MSE·spp only changes ×{rise:.2} from {span}: the estimator \
                 converges to a different image than this reference",
                b2.sqrt()
            ),
            Some((b2, var)) => {
                format!("{trend}; at {at} spp bias² ≈ {b2:.3e}, variance ≈ {var:.3e}")
            }
            None => trend,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Outputs.

fn write_csv(plan: &Plan, res: &Results) -> Result<PathBuf> {
    let mut s = String::from(
        "scene,integrator,spp,rep,seed,cpu_s,wall_s,rays,reference,mse,relmse,mean,ref_mean",
    );
    for r in &plan.region_names {
        let _ = write!(s, ",{r}_mse,{r}_relmse,{r}_mean");
    }
    s.push('\n');
    for r in &res.rows {
        let e = &r.whole;
        let _ = write!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            plan.scenes[r.scene].name,
            plan.integrators[r.integrator].label,
            r.spp,
            r.rep,
            r.seed,
            r.time_s,
            r.wall_s,
            r.rays,
            r.reference.name(),
            e.mse,
            e.relmse,
            e.mean,
            e.ref_mean
        );
        for g in &r.regions {
            let _ = write!(s, ",{},{},{}", g.mse, g.relmse, g.mean);
        }
        s.push('\n');
    }
    let path = plan.out.join("results.csv");
    crate::atomic_write(&path, s.as_bytes())?;
    Ok(path)
}

fn fmt_stat(s: Stat) -> String {
    match s.ci {
        Some(ci) => format!("{:.3e} ± {:.1e}", s.mean, ci),
        None => format!("{:.3e}", s.mean),
    }
}

/// The 1/N (or 1/t) slope through the first point of the first series, as a reference line.
fn slope_line(series: &[Series], name: &str) -> Option<Series> {
    let (x0, y0) = *series.first()?.points.first()?;
    let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
    let (lo, hi) = xs.fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(x), b.max(x)));
    (lo > 0.0 && hi > lo).then(|| Series {
        name: name.into(),
        points: vec![(lo, y0 * x0 / lo), (hi, y0 * x0 / hi)],
        reference: true,
    })
}

fn chart(
    title: String,
    x_label: &str,
    y_label: &str,
    mut series: Vec<Series>,
    slope: Option<&str>,
) -> Chart {
    if let Some(name) = slope {
        if let Some(line) = slope_line(&series, name) {
            series.push(line);
        }
    }
    Chart {
        title,
        x_label: x_label.into(),
        y_label: y_label.into(),
        series,
        log_x: true,
        log_y: true,
    }
}

/// Per-integrator series of `f(point)` against spp or time.
fn series_of(
    plan: &Plan,
    curves: &[Vec<Point>],
    x: impl Fn(&Point) -> f64,
    y: impl Fn(&Point) -> f64,
) -> Vec<Series> {
    plan.integrators
        .iter()
        .zip(curves)
        .map(|(i, c)| Series {
            name: i.label.clone(),
            points: c.iter().map(|p| (x(p), y(p))).collect(),
            reference: false,
        })
        .collect()
}

const PANEL_W: u32 = 430;
const PANEL_H: u32 = 360;

/// Convergence charts of one scene; returns the files written (stems relative to the output).
fn write_plots(plan: &Plan, res: &Results, si: usize) -> Result<Vec<String>> {
    let scene = &plan.scenes[si];
    let mut written = Vec::new();
    let spp_x = |p: &Point| p.spp as f64;
    let time_x = |p: &Point| p.time_s;
    let mut plot = |stem: String, charts: Vec<Chart>| -> Result<()> {
        plot::write_charts(&plan.out.join(&stem), &charts, PANEL_W, PANEL_H)?;
        written.push(stem);
        Ok(())
    };
    let n = plan.integrators.len();
    let common: Vec<Vec<Point>> = (0..n)
        .map(|i| curve(res, plan, si, i, RefKind::Common, None))
        .collect();
    let name = &scene.name;
    plot(
        format!("plots/{name}_convergence"),
        vec![
            chart(
                format!("{name}: MSE vs spp"),
                "samples per pixel",
                "MSE",
                series_of(plan, &common, spp_x, |p| p.mse.mean),
                Some("1/N"),
            ),
            chart(
                format!("{name}: relMSE vs spp"),
                "samples per pixel",
                "relMSE",
                series_of(plan, &common, spp_x, |p| p.relmse.mean),
                Some("1/N"),
            ),
            chart(
                format!("{name}: relMSE vs CPU time"),
                "render CPU time (s)",
                "relMSE",
                series_of(plan, &common, time_x, |p| p.relmse.mean),
                Some("1/t"),
            ),
            chart(
                format!("{name}: MSE·spp (flat = 1/N)"),
                "samples per pixel",
                "MSE × spp",
                series_of(plan, &common, spp_x, |p| p.mse.mean * p.spp as f64),
                None,
            ),
        ],
    )?;
    if plan.own_spp.is_some() {
        let own: Vec<Vec<Point>> = (0..n)
            .map(|i| curve(res, plan, si, i, RefKind::Own, None))
            .collect();
        plot(
            format!("plots/{name}_convergence_own"),
            vec![
                chart(
                    format!("{name}: relMSE vs spp, own reference"),
                    "samples per pixel",
                    "relMSE",
                    series_of(plan, &own, spp_x, |p| p.relmse.mean),
                    Some("1/N"),
                ),
                chart(
                    format!("{name}: MSE·spp, own reference"),
                    "samples per pixel",
                    "MSE × spp",
                    series_of(plan, &own, spp_x, |p| p.mse.mean * p.spp as f64),
                    None,
                ),
            ],
        )?;
    }
    for (g, region) in plan.region_names.iter().enumerate() {
        let c: Vec<Vec<Point>> = (0..n)
            .map(|i| curve(res, plan, si, i, RefKind::Common, Some(g)))
            .collect();
        plot(
            format!("plots/{name}_{region}_convergence"),
            vec![
                chart(
                    format!("{name}/{region}: relMSE vs spp"),
                    "samples per pixel",
                    "relMSE",
                    series_of(plan, &c, spp_x, |p| p.relmse.mean),
                    Some("1/N"),
                ),
                chart(
                    format!("{name}/{region}: relMSE vs CPU time"),
                    "render CPU time (s)",
                    "relMSE",
                    series_of(plan, &c, time_x, |p| p.relmse.mean),
                    Some("1/t"),
                ),
            ],
        )?;
    }
    Ok(written)
}

/// Heat maps and crop sheets of one scene; returns (heat map file, its scale, sheet files).
fn write_figures(
    plan: &Plan,
    res: &Results,
    si: usize,
) -> Result<(String, plot::LogScale, Vec<String>)> {
    let scene = &plan.scenes[si];
    let fig = &res.figures[si];
    let film = &scene.desc.film;
    let panels: Vec<HeatPanel> = plan
        .integrators
        .iter()
        .zip(&fig.heat)
        .filter_map(|(i, h)| {
            h.as_ref().map(|values| HeatPanel {
                title: format!("{} at {} spp", i.label, plan.heatmap_spp),
                width: film.width,
                height: film.height,
                values: values.clone(),
            })
        })
        .collect();
    let all: Vec<f32> = panels
        .iter()
        .flat_map(|p| p.values.iter().copied())
        .collect();
    let scale = plot::LogScale::fit(&all);
    let heat = format!("plots/{}_heatmap_{}spp.png", scene.name, plan.heatmap_spp);
    plot::write_heat_maps(
        &plan.out.join(&heat),
        &panels,
        scale,
        diff::MapKind::Rel.label(),
    )?;

    let mut sheets = Vec::new();
    for (g, (region, rect)) in sheet_regions(plan, scene).iter().enumerate() {
        let mut cols: Vec<String> = plan.spp.iter().map(|s| format!("{s} spp")).collect();
        cols.push("reference".into());
        if plan.own_spp.is_some() {
            cols.push("own reference".into());
        }
        let rows: Vec<String> = plan.integrators.iter().map(|i| i.label.clone()).collect();
        let cells: Vec<Vec<Option<Picture>>> = (0..plan.integrators.len())
            .map(|i| {
                let mut row = fig.crops[g][i].clone();
                row.push(Some(fig.ref_crops[g].clone()));
                if plan.own_spp.is_some() {
                    row.push(fig.own_crops[g][i].clone());
                }
                row
            })
            .collect();
        let file = format!("sheets/{}_{region}.png", scene.name);
        plot::write_image_sheet(
            &plan.out.join(&file),
            &format!(
                "{} / {region} ({rect}), repetition 0, exposure {:+.1} stops",
                scene.name,
                plan.gain.log2()
            ),
            &rows,
            &cols,
            &cells,
        )?;
        sheets.push(file);
    }
    Ok((heat, scale, sheets))
}

/// The MSE·spp of the reference's own integrator at the smallest spp over the reference spp:
/// the reference noise in every MSE, when the reference integrator is one of the study's.
fn common_noise(plan: &Plan, res: &Results, si: usize) -> Option<f64> {
    let PlanReference::Render { integrator, spp } = &plan.reference else {
        return None;
    };
    let i = plan
        .integrators
        .iter()
        .position(|p| p.ron == integrator.ron)?;
    let c = curve(res, plan, si, i, RefKind::Common, None);
    let p = c.first()?;
    Some(p.mse.mean * p.spp as f64 / *spp as f64)
}

fn own_noise(plan: &Plan, res: &Results, si: usize, i: usize) -> Option<f64> {
    let spp = plan.own_spp?;
    let c = curve(res, plan, si, i, RefKind::Own, None);
    let p = c.first()?;
    Some(p.mse.mean * p.spp as f64 / spp as f64)
}

fn table_header(s: &mut String, cols: &[&str]) {
    let _ = writeln!(s, "| {} |", cols.join(" | "));
    let _ = writeln!(s, "|{}", "---|".repeat(cols.len()));
}

fn error_table(s: &mut String, plan: &Plan, curves: &[Vec<Point>]) {
    table_header(
        s,
        &[
            "integrator",
            "spp",
            "MSE (± 95 % CI)",
            "relMSE (± 95 % CI)",
            "bias² (est.)",
            "CPU time (s)",
            "MSE·spp",
            "efficiency 1/(relMSE·s)",
        ],
    );
    for (i, c) in plan.integrators.iter().zip(curves) {
        for p in c {
            let bias2 = p.bias2.map_or("".into(), |b| format!("{b:.2e}"));
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {bias2} | {:.3} | {:.3e} | {:.3e} |",
                i.label,
                p.spp,
                fmt_stat(p.mse),
                fmt_stat(p.relmse),
                p.time_s,
                p.mse.mean * p.spp as f64,
                1.0 / (p.relmse.mean * p.time_s.max(1e-9))
            );
        }
    }
    s.push('\n');
}

/// `summary.csv`: the report's numbers per (scene, integrator, spp, reference).
fn write_summary(plan: &Plan, res: &Results) -> Result<PathBuf> {
    let mut s = String::from(
        "scene,integrator,spp,reference,repetitions,mse,mse_ci95,relmse,relmse_ci95,bias2,cpu_s,mse_x_spp,efficiency\n",
    );
    let kinds: &[RefKind] = if plan.own_spp.is_some() {
        &[RefKind::Common, RefKind::Own]
    } else {
        &[RefKind::Common]
    };
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
    for (si, sc) in plan.scenes.iter().enumerate() {
        for (ii, integ) in plan.integrators.iter().enumerate() {
            for &kind in kinds {
                for p in curve(res, plan, si, ii, kind, None) {
                    let _ = writeln!(
                        s,
                        "{},{},{},{},{},{},{},{},{},{},{},{},{}",
                        sc.name,
                        integ.label,
                        p.spp,
                        kind.name(),
                        plan.reps,
                        p.mse.mean,
                        opt(p.mse.ci),
                        p.relmse.mean,
                        opt(p.relmse.ci),
                        opt(p.bias2),
                        p.time_s,
                        p.mse.mean * p.spp as f64,
                        1.0 / (p.relmse.mean * p.time_s.max(1e-9))
                    );
                }
            }
        }
    }
    let path = plan.out.join("summary.csv");
    crate::atomic_write(&path, s.as_bytes())?;
    Ok(path)
}

/// MSE of `other` over MSE of `base` at each of `base`'s spp settings.
fn ratios_at_equal_spp(base: &[Point], other: &[Point]) -> Vec<f64> {
    base.iter()
        .zip(other)
        .map(|(b, o)| o.mse.mean / b.mse.mean)
        .collect()
}

/// MSE of `other` (interpolated log-log in time) over MSE of `base` at each of `base`'s
/// times; `None` outside `other`'s time range.
fn ratios_at_equal_time(base: &[Point], other: &[Point]) -> Vec<Option<f64>> {
    let pts: Vec<(f64, f64)> = other.iter().map(|p| (p.time_s, p.mse.mean)).collect();
    base.iter()
        .map(|b| loglog_at(&pts, b.time_s).map(|m| m / b.mse.mean))
        .collect()
}

/// "min–max (geometric mean g)" of positive finite values, or "–" when there are none.
fn ratio_range(values: impl IntoIterator<Item = f64>) -> String {
    let v: Vec<f64> = values
        .into_iter()
        .filter(|r| r.is_finite() && *r > 0.0)
        .collect();
    if v.is_empty() {
        return "–".into();
    }
    let min = v.iter().copied().fold(f64::INFINITY, f64::min);
    let max = v.iter().copied().fold(0.0, f64::max);
    let geo = (v.iter().map(|r| r.ln()).sum::<f64>() / v.len() as f64).exp();
    format!("{min:.2}–{max:.2} (geo. mean {geo:.2})")
}

/// The report's first section: per scene and integrator, the ratios against the baseline
/// summarised over all spp, the cost per sample and the convergence verdict.
fn summary_section(s: &mut String, plan: &Plan, res: &Results) {
    let base_label = &plan.integrators[0].label;
    let _ = writeln!(
        s,
        "## Summary
"
    );
    let _ = writeln!(
        s,
        "MSE ratios X / `{base_label}` against the common reference over all spp settings \
         (below 1: X has less error), the CPU time per sample relative to `{base_label}`, and \
         the convergence verdict against the common reference (details per scene below).\n"
    );
    table_header(
        s,
        &[
            "scene",
            "integrator",
            "MSE ratio, equal spp",
            "MSE ratio, equal time",
            "time per sample",
            "verdict",
        ],
    );
    for (si, sc) in plan.scenes.iter().enumerate() {
        let noise = common_noise(plan, res, si);
        let base = curve(res, plan, si, 0, RefKind::Common, None);
        for (ii, integ) in plan.integrators.iter().enumerate() {
            let c = curve(res, plan, si, ii, RefKind::Common, None);
            let verdict = verdict(&c, noise);
            let verdict = verdict.split(':').next().unwrap_or_default();
            if ii == 0 {
                let _ = writeln!(
                    s,
                    "| {} | {} | 1 | 1 | 1 | {verdict} |",
                    sc.name, integ.label
                );
                continue;
            }
            let cost = ratio_range(base.iter().zip(&c).map(|(b, o)| o.time_s / b.time_s));
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {cost} | {verdict} |",
                sc.name,
                integ.label,
                ratio_range(ratios_at_equal_spp(&base, &c)),
                ratio_range(ratios_at_equal_time(&base, &c).into_iter().flatten()),
            );
        }
    }
    s.push('\n');
}

fn write_report(plan: &Plan, res: &Results, figures: &[SceneOutputs]) -> Result<PathBuf> {
    let mut s = String::new();
    let _ = writeln!(s, "# Study: {}\n", plan.title);
    let _ = writeln!(
        s,
        "Made by `{}` ({} renders made, {} read back from earlier runs).\n",
        plan.command, res.rendered, res.reused
    );
    let _ = writeln!(s, "## Settings\n");
    for sc in &plan.scenes {
        let f = &sc.desc.film;
        let _ = writeln!(
            s,
            "- scene `{}`: {} ({}x{})",
            sc.name, sc.source, f.width, f.height
        );
    }
    for i in &plan.integrators {
        let _ = writeln!(s, "- integrator `{}`: `{}`", i.label, i.ron);
    }
    let _ = writeln!(
        s,
        "- spp: {:?}; {} repetitions each with independent seeds (hash of base seed {}, scene, \
         integrator settings, spp and repetition)",
        plan.spp, plan.reps, plan.seed
    );
    match &plan.reference {
        PlanReference::Render { integrator, spp } => {
            let _ = writeln!(
                s,
                "- common reference: `{}` at {spp} spp, its own seed (independent of every test render)",
                integrator.ron
            );
        }
        PlanReference::Exr(t) => {
            let _ = writeln!(s, "- common reference: EXR `{t}`");
        }
    }
    if let Some(spp) = plan.own_spp {
        let _ = writeln!(
            s,
            "- own references: each integrator's converged render at {spp} spp (separates its \
             variance from its bias against the common reference)"
        );
    }
    let _ = writeln!(
        s,
        "\nMetrics, over all pixels and the three channels of render I against reference R: \
         MSE = mean (I − R)²; relMSE = mean (I − R)² / (R² + ε) with ε = {REL_EPSILON}. \
         Tables give the mean over the repetitions ± the half-width of its 95 % confidence \
         interval (Student t). bias² (est.) = (K·MSE(mean of the K repetitions) − mean MSE)/(K − 1), \
         the squared bias averaged over pixels and channels (unbiased; it includes the \
         reference's own error, and is noisy when the samples are heavy-tailed). Efficiency = \
         1 / (relMSE · render time). Render time is the CPU time of the render threads \
         (summed over threads; wall time is in `results.csv`), so other load on the machine \
         does not tilt the equal-time comparisons. MSE·spp is constant \
         for an unbiased estimator converging as 1/N; a rising tail is an error floor (bias \
         against the reference, or the reference's own noise, estimated below when possible). \
         Ratios are X / `{}` (below 1: X has less error). Equal-time ratios interpolate each \
         integrator's log-log MSE-vs-time curve at the baseline's times (blank outside its \
         range). Every render's numbers are in `results.csv`, these tables' in `summary.csv`.\n",
        plan.integrators[0].label
    );

    let n = plan.integrators.len();
    if n > 1 {
        summary_section(&mut s, plan, res);
    }
    for (si, sc) in plan.scenes.iter().enumerate() {
        let out = &figures[si];
        let _ = writeln!(s, "## Scene `{}`\n", sc.name);
        for p in &out.plots {
            let _ = writeln!(s, "![{p}]({p}.png)\n");
        }
        let common: Vec<Vec<Point>> = (0..n)
            .map(|i| curve(res, plan, si, i, RefKind::Common, None))
            .collect();
        let _ = writeln!(s, "### Error against the common reference\n");
        error_table(&mut s, plan, &common);
        let own: Option<Vec<Vec<Point>>> = plan.own_spp.map(|_| {
            (0..n)
                .map(|i| curve(res, plan, si, i, RefKind::Own, None))
                .collect()
        });
        if let Some(own) = &own {
            let _ = writeln!(s, "### Error against each integrator's own reference\n");
            error_table(&mut s, plan, own);
        }

        if n > 1 {
            let base = &common[0];
            let others: Vec<&str> = plan.integrators[1..]
                .iter()
                .map(|i| i.label.as_str())
                .collect();
            let _ = writeln!(
                s,
                "### MSE ratio at equal spp (X / `{}`)\n",
                plan.integrators[0].label
            );
            let mut cols = vec!["spp"];
            cols.extend(&others);
            table_header(&mut s, &cols);
            let by_spp: Vec<Vec<f64>> = common[1..]
                .iter()
                .map(|c| ratios_at_equal_spp(base, c))
                .collect();
            for (k, b) in base.iter().enumerate() {
                let _ = write!(s, "| {} |", b.spp);
                for r in &by_spp {
                    let _ = write!(s, " {:.3} |", r[k]);
                }
                s.push('\n');
            }
            let _ = writeln!(
                s,
                "\n### MSE ratio at equal time (X / `{}`)\n",
                plan.integrators[0].label
            );
            let mut cols = vec!["CPU time (s)"];
            cols.extend(&others);
            table_header(&mut s, &cols);
            let by_time: Vec<Vec<Option<f64>>> = common[1..]
                .iter()
                .map(|c| ratios_at_equal_time(base, c))
                .collect();
            for (k, b) in base.iter().enumerate() {
                let _ = write!(s, "| {:.4} |", b.time_s);
                for r in &by_time {
                    match r[k] {
                        Some(r) => {
                            let _ = write!(s, " {r:.3} |");
                        }
                        None => s.push_str("  |"),
                    }
                }
                s.push('\n');
            }
            s.push('\n');
        }

        let _ = writeln!(s, "### Time to relMSE = {:.1e}\n", plan.target_relmse);
        table_header(&mut s, &["integrator", "spp", "CPU time (s)"]);
        for (i, c) in plan.integrators.iter().zip(&common) {
            let _ = match reach(c, plan.target_relmse) {
                Reach::AtOnce(spp, t) => writeln!(s, "| {} | ≤ {spp} | ≤ {t:.4} |", i.label),
                Reach::At(spp, t) => writeln!(s, "| {} | {spp:.1} | {t:.4} |", i.label),
                Reach::Never(best) => writeln!(
                    s,
                    "| {} | not reached (best relMSE {best:.3e}) | |",
                    i.label
                ),
            };
        }

        let _ = writeln!(s, "\n### Convergence verdicts (MSE·spp)\n");
        let noise = common_noise(plan, res, si);
        if let Some(nz) = noise {
            let _ = writeln!(
                s,
                "Common reference noise ≈ {nz:.3e} (MSE·spp of its integrator at the lowest spp / \
                 reference spp), subtracted before judging.\n"
            );
        }
        for (i, c) in plan.integrators.iter().enumerate() {
            let _ = writeln!(
                s,
                "- `{}` vs common reference: {}",
                plan.integrators[i].label,
                verdict(&common[i], noise)
            );
            if let Some(own) = &own {
                let _ = writeln!(
                    s,
                    "- `{}` vs own reference: {}",
                    c.label,
                    verdict(&own[i], own_noise(plan, res, si, i))
                );
            }
        }
        s.push('\n');

        if !plan.region_names.is_empty() {
            let _ = writeln!(s, "### Regions: relMSE against the common reference\n");
            let mut cols = vec!["region".to_string(), "integrator".to_string()];
            cols.extend(plan.spp.iter().map(|x| format!("{x} spp")));
            let cols: Vec<&str> = cols.iter().map(String::as_str).collect();
            table_header(&mut s, &cols);
            for (g, region) in plan.region_names.iter().enumerate() {
                let rect = sc.regions[g];
                for (i, integ) in plan.integrators.iter().enumerate() {
                    let c = curve(res, plan, si, i, RefKind::Common, Some(g));
                    let _ = write!(s, "| {region} ({rect}) | {} |", integ.label);
                    for p in &c {
                        let _ = write!(s, " {} |", fmt_stat(p.relmse));
                    }
                    s.push('\n');
                }
            }
            s.push('\n');
        }

        let _ = writeln!(
            s,
            "### Per-pixel error at {} spp (repetition 0)\n\n![heat map]({})\n\nColour: \
             per-pixel sqrt(mean over RGB of (I − R)² / (R² + {REL_EPSILON})), log scale from \
             {:.2e} (black) to {:.2e} (pale yellow), shared by the panels.\n",
            plan.heatmap_spp, out.heat, out.scale.lo, out.scale.hi
        );
        let _ = writeln!(
            s,
            "### Crops (rows: integrators; columns: spp, then the reference{})\n",
            if plan.own_spp.is_some() {
                " and the integrator's own reference"
            } else {
                ""
            }
        );
        for sheet in &out.sheets {
            let _ = writeln!(s, "![{sheet}]({sheet})\n");
        }
    }
    let path = plan.out.join("report.md");
    crate::atomic_write(&path, s.as_bytes())?;
    Ok(path)
}

/// Figure files of one scene, for the report.
struct SceneOutputs {
    plots: Vec<String>,
    heat: String,
    scale: plot::LogScale,
    sheets: Vec<String>,
}

pub fn run(args: StudyArgs) -> Result<()> {
    let study = load(&args.study)?;
    let plan = Plan::new(study, &args)?;
    let verbose = !args.quiet;
    std::fs::create_dir_all(&plan.out)
        .with_context(|| format!("creating output folder {}", plan.out.display()))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("creating the thread pool")?;
    let bar = crate::render_cmd::progress_bar(plan.total_samples(), verbose, "study ");
    let res = execute(&plan, &pool, &bar, verbose);
    bar.finish_and_clear();
    let res = res?;

    let csv = write_csv(&plan, &res)?;
    write_summary(&plan, &res)?;
    let mut outputs = Vec::new();
    for si in 0..plan.scenes.len() {
        let plots = write_plots(&plan, &res, si)?;
        let (heat, scale, sheets) = write_figures(&plan, &res, si)?;
        outputs.push(SceneOutputs {
            plots,
            heat,
            scale,
            sheets,
        });
    }
    let report = write_report(&plan, &res, &outputs)?;
    if verbose {
        let renders =
            plan.scenes.len() * plan.integrators.len() * plan.spp.len() * plan.reps as usize;
        eprintln!(
            "study '{}': {} scenes × {} integrators × {} spp × {} repetitions = {renders} renders \
             plus references: rendered {}, reused {} ({:.2} s rendering)",
            plan.title,
            plan.scenes.len(),
            plan.integrators.len(),
            plan.spp.len(),
            plan.reps,
            res.rendered,
            res.reused,
            res.render_seconds
        );
        eprintln!(
            "wrote {}, {}, plots in {}, crop sheets in {}",
            csv.display(),
            report.display(),
            plan.out.join("plots").display(),
            plan.out.join("sheets").display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn student_t_quantiles() {
        assert_eq!(t975(1), 12.706);
        assert_eq!(t975(30), 2.042);
        // Tabulated values for 40 and 120 degrees of freedom.
        assert!((t975(40) - 2.021).abs() < 1e-3);
        assert!((t975(120) - 1.980).abs() < 1e-3);
        let s = stat(&[1.0, 2.0, 3.0]);
        assert_eq!(s.mean, 2.0);
        assert!((s.ci.unwrap() - 4.303 / 3f64.sqrt()).abs() < 1e-12);
        assert!(stat(&[5.0]).ci.is_none());
    }

    #[test]
    fn log_log_interpolation() {
        let pts = [(1.0, 1.0), (100.0, 1e-2), (10.0, 1e-1)];
        assert!(
            (loglog_at(&pts, 31.622_776_601_683_793).unwrap() - 10f64.powf(-1.5)).abs() < 1e-12
        );
        assert_eq!(loglog_at(&pts, 0.5), None);
        assert_eq!(loglog_at(&pts, 100.0), Some(1e-2));
    }

    fn pt(spp: u32, mse: f64, time_s: f64) -> Point {
        let s = Stat {
            mean: mse,
            ci: None,
        };
        Point {
            spp,
            mse: s,
            relmse: s,
            time_s,
            bias2: None,
        }
    }

    #[test]
    fn verdicts_and_time_to_target() {
        let unbiased: Vec<Point> = [1, 4, 16, 64]
            .iter()
            .map(|&n| pt(n, 1.0 / n as f64, n as f64))
            .collect();
        assert!(verdict(&unbiased, None).starts_with("flat"));
        let biased: Vec<Point> = [1, 4, 16, 64]
            .iter()
            .map(|&n| pt(n, 1.0 / n as f64 + 0.1, n as f64))
            .collect();
        assert!(verdict(&biased, None).contains("error floor"));
        // Reference noise alone is not taken for bias once subtracted.
        let noisy: Vec<Point> = [1, 4, 16, 64]
            .iter()
            .map(|&n| pt(n, 1.0 / n as f64 + 0.02, n as f64))
            .collect();
        assert!(verdict(&noisy, None).contains("error floor"));
        assert!(verdict(&noisy, Some(0.02)).starts_with("flat"));
        // With a bias estimate the floor is attributed: to bias when bias² dominates the MSE…
        let mut split = biased.clone();
        split[3].bias2 = Some(0.1);
        assert!(verdict(&split, None).starts_with("**bias**"));
        // …and to heavy-tailed variance when the mean image is as close as 1/K predicts.
        split[3].bias2 = Some(0.001);
        assert!(verdict(&split, None).starts_with("**excess variance**"));
        // A bias that dominates at the highest spp is reported even before MSE·spp rises.
        let mut early = unbiased.clone();
        early[3].bias2 = Some(0.6 / 64.0);
        assert!(verdict(&early, None).starts_with("**bias**"));
        early[3].bias2 = Some(0.3 / 64.0);
        assert!(verdict(&early, None).starts_with("flat"));
        // relMSE 1/N reaches 0.1 at 10 spp and 10 s.
        match reach(&unbiased, 0.1) {
            Reach::At(spp, t) => {
                assert!((spp - 10.0).abs() < 1e-9 && (t - 10.0).abs() < 1e-9);
            }
            _ => panic!("target not found"),
        }
        assert!(matches!(reach(&unbiased, 2.0), Reach::AtOnce(1, _)));
        assert!(matches!(reach(&unbiased, 1e-3), Reach::Never(_)));
    }

    #[test]
    fn seeds_are_distinct_and_stable() {
        let a = test_seed(1, "s", "Path(())", 4, 0);
        assert_eq!(a, test_seed(1, "s", "Path(())", 4, 0));
        let others = [
            test_seed(2, "s", "Path(())", 4, 0),
            test_seed(1, "t", "Path(())", 4, 0),
            test_seed(1, "s", "Path((max_depth:8))", 4, 0),
            test_seed(1, "s", "Path(())", 8, 0),
            test_seed(1, "s", "Path(())", 4, 1),
            reference_seed(1, "s", "Path(())", 4),
        ];
        assert!(others.iter().all(|&o| o != a));
    }
}
