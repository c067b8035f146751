//! `tress calibrate`: fits the dual-scattering density factors d_f and d_b of a groom and
//! material to a short path-traced reference, and chooses how many hair bounces to trace before
//! the estimate (`path_bounces`).
//!
//! Dual scattering's expected image is bilinear in its free parameters: with the fiber-medium
//! tables `F = V·(f_s + d_b·B) + (1 − V)·d_f·T·(S + d_b·B')`, so the mean over any set of
//! pixels is `A + x·B + y·C + x·y·D` with `x = d_f`, `y = d_b` (the paper's closed forms carry
//! d_f twice: there `x = d_f²`). Four renders at the corners of [0, 1]² therefore give that
//! mean for every (d_f, d_b), and the fit minimises the squared relative error of the three
//! channels' means over the hair pixels against the path tracer's. A traced bounce only moves
//! where the estimate is taken, so the means stay bilinear: each candidate `path_bounces` gets
//! its own four corners and fit, and the one whose fitted means come closest is kept (dark hair
//! gains from a traced bounce, light hair loses: README). A last render checks the choice.

use crate::args::RunArgs;
use crate::progress::progress_bar;
use crate::render_file::parse_crop;
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use tress_core::film::FilmSettings;
use tress_core::output_file::{self, Inputs};
use tress_core::render::render_samples;
use tress_core::{Hit, HitKind, Image, Integrator, Ray, Rgb, Sampler, Scene};
use tress_dual_uniform::DualSettings;
use tress_loader::integrators::IntegratorDesc;
use tress_loader::scene_desc::{self, SceneDesc};
use tress_materials::dual_scattering::{DensityFactors, MultipleScattering};
use tress_study::metrics::REL_EPSILON;

#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// Scene file (RON): the groom, material, lights and camera to calibrate for.
    pub scene: PathBuf,
    /// Calibrate on the pixel window x0,y0,x1,y1 only (faster; pick one with hair in it).
    #[arg(long, value_parser = parse_crop)]
    pub crop: Option<[u32; 4]>,
    /// Samples per pixel of the path-traced reference.
    #[arg(long, default_value_t = 256)]
    pub reference_spp: u32,
    /// Samples per pixel of each dual-scattering render.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// The dual-scattering integrator to calibrate (a name or RON value); default: the
    /// scene's, if it is one, else dual-mis.
    #[arg(long)]
    pub integrator: Option<String>,
    /// Hair bounces traced before the estimate to try (`path_bounces`), comma-separated; the
    /// one whose fitted means come closest to the reference is kept.
    #[arg(long, value_delimiter = ',', default_value = "0,1")]
    pub path_bounces: Vec<u32>,
    /// Write the calibrated integrator (RON, for a scene's `integrator:` or `--integrator`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub run: RunArgs,
}

/// Renders 1 where the camera sees hair first, 0 elsewhere: averaged over a pixel's samples,
/// its hair coverage.
#[derive(Debug)]
struct HairCoverage;

impl Integrator for HairCoverage {
    fn li(&self, ray: &Ray, scene: &Scene, _: &mut Sampler) -> Rgb {
        match scene.intersect(ray) {
            Some(Hit {
                kind: HitKind::Fiber { .. },
                ..
            }) => Rgb::ONE,
            _ => Rgb::ZERO,
        }
    }
}

/// Per-channel means over the masked pixels.
fn masked_mean(img: &Image, mask: &[bool]) -> [f64; 3] {
    let mut sum = [0.0f64; 3];
    for (p, _) in img.pixels.iter().zip(mask).filter(|(_, &m)| m) {
        for (s, v) in sum.iter_mut().zip(p.to_array()) {
            *s += v as f64;
        }
    }
    let n = mask.iter().filter(|&&m| m).count().max(1) as f64;
    sum.map(|s| s / n)
}

/// relMSE over the masked pixels, with `tress diff`'s ε.
fn masked_relmse(img: &Image, reference: &Image, mask: &[bool]) -> f64 {
    let mut sum = 0.0;
    let mut n = 0usize;
    for ((a, r), _) in img
        .pixels
        .iter()
        .zip(&reference.pixels)
        .zip(mask)
        .filter(|(_, &m)| m)
    {
        for (a, r) in a.to_array().into_iter().zip(r.to_array()) {
            let (a, r) = (a as f64, r as f64);
            sum += (a - r) * (a - r) / (r * r + REL_EPSILON);
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

/// The hair-pixel means `A + x·B + y·C + x·y·D` from the four corner renders.
struct Bilinear {
    corner: [[[f64; 3]; 2]; 2],
}

impl Bilinear {
    fn at(&self, x: f64, y: f64) -> [f64; 3] {
        let c = &self.corner;
        std::array::from_fn(|k| {
            c[0][0][k] * (1.0 - x) * (1.0 - y)
                + c[1][0][k] * x * (1.0 - y)
                + c[0][1][k] * (1.0 - x) * y
                + c[1][1][k] * x * y
        })
    }
}

/// Squared relative error of the channel means.
fn misfit(m: [f64; 3], reference: [f64; 3]) -> f64 {
    m.iter()
        .zip(reference)
        .map(|(m, r)| (m / r - 1.0).powi(2))
        .sum()
}

/// The (x, y) ∈ [0, 1]² of least misfit: a grid search, then a finer one around its best.
fn fit(model: &Bilinear, reference: [f64; 3]) -> (f64, f64) {
    let mut best = (0.0, 0.0, f64::INFINITY);
    let search = |x0: f64, x1: f64, y0: f64, y1: f64, best: &mut (f64, f64, f64)| {
        let steps = 100;
        for i in 0..=steps {
            for j in 0..=steps {
                let x = x0 + (x1 - x0) * i as f64 / steps as f64;
                let y = y0 + (y1 - y0) * j as f64 / steps as f64;
                let e = misfit(model.at(x, y), reference);
                if e < best.2 {
                    *best = (x, y, e);
                }
            }
        }
    };
    search(0.0, 1.0, 0.0, 1.0, &mut best);
    let (x, y) = (best.0, best.1);
    search(
        (x - 0.01).max(0.0),
        (x + 0.01).min(1.0),
        (y - 0.01).max(0.0),
        (y + 0.01).min(1.0),
        &mut best,
    );
    (best.0, best.1)
}

fn ratios(m: [f64; 3], reference: [f64; 3]) -> String {
    format!(
        "{:.3} / {:.3} / {:.3}",
        m[0] / reference[0],
        m[1] / reference[1],
        m[2] / reference[2]
    )
}

/// One candidate `path_bounces` with its bilinear model of the hair means, the fitted
/// `x = d_f^power`, `y = d_b` and their misfit against the reference.
struct Candidate {
    path_bounces: u32,
    bilinear: Bilinear,
    x: f64,
    y: f64,
    misfit: f64,
}

/// The dual-scattering integrator being calibrated: its settings, and its kind.
struct Target {
    settings: DualSettings,
    with_settings: fn(DualSettings) -> IntegratorDesc,
}

impl Target {
    /// The integrator with `d_f`, `d_b` and `path_bounces` set.
    fn with_factors(&self, d_f: f64, d_b: f64, path_bounces: u32) -> IntegratorDesc {
        (self.with_settings)(DualSettings {
            d_f: Some(d_f as f32),
            d_b: Some(d_b as f32),
            path_bounces,
            ..self.settings.clone()
        })
    }
}

/// The scene with the crop applied, the integrator to calibrate (set as the scene's) and the
/// path tracer of the reference: the scene's own, or one 100 bounces deep.
fn load(args: &CalibrateArgs) -> Result<(SceneDesc, Target, IntegratorDesc)> {
    let mut desc = scene_desc::load(&args.scene)?;
    if let Some(crop) = args.crop {
        desc.film.crop = Some(crop);
    }
    desc.film
        .validate_for_render(&crate::limits_from_env())
        .map_err(|e| anyhow::anyhow!("{}: film: {e}", args.scene.display()))?;
    for (what, spp) in [("--reference-spp", args.reference_spp), ("--spp", args.spp)] {
        if spp == 0 {
            bail!("{what} must be at least 1");
        }
    }
    let chosen = match &args.integrator {
        Some(arg) => IntegratorDesc::parse_arg(arg).map_err(anyhow::Error::msg)?,
        None => match &desc.integrator {
            d @ (IntegratorDesc::DualUniform(_) | IntegratorDesc::DualMis(_)) => d.clone(),
            _ => IntegratorDesc::DualMis(Default::default()),
        },
    };
    let (settings, with_settings): (DualSettings, fn(DualSettings) -> IntegratorDesc) = match chosen
    {
        IntegratorDesc::DualUniform(s) => (s, IntegratorDesc::DualUniform),
        IntegratorDesc::DualMis(s) => (s, IntegratorDesc::DualMis),
        // Only the dual-scattering integrators have density factors to fit.
        other => bail!(
            "--integrator: calibration fits a dual-scattering integrator (dual-uniform or \
                 dual-mis), not {}",
            other.name()
        ),
    };
    let reference_integrator = match &desc.integrator {
        IntegratorDesc::Path(p) => IntegratorDesc::Path(p.clone()),
        _ => IntegratorDesc::Path(tress_path::PathSettings {
            max_depth: 100,
            ..Default::default()
        }),
    };
    desc.integrator = with_settings(settings.clone());
    let target = Target {
        settings,
        with_settings,
    };
    Ok((desc, target, reference_integrator))
}

/// Renders of the scene's film (or crop window) at some spp, each with a progress bar.
struct Renders<'a> {
    pool: &'a rayon::ThreadPool,
    scene: &'a Scene,
    film: &'a FilmSettings,
    /// Nothing cancels them; the render loop wants a flag.
    cancel: AtomicBool,
    verbose: bool,
}

impl Renders<'_> {
    fn render(&self, integrator: &dyn Integrator, spp: u32, label: &str) -> Result<Image> {
        let film = FilmSettings {
            spp,
            ..self.film.clone()
        };
        let [x0, y0, x1, y1] = film.window();
        let bar = progress_bar(
            (x1 - x0) as u64 * (y1 - y0) as u64 * spp as u64,
            self.verbose,
            label,
        );
        let out = self
            .pool
            .install(|| {
                render_samples(
                    self.scene,
                    integrator,
                    &film,
                    0..spp as u64,
                    &self.cancel,
                    &|n| bar.inc(n),
                )
            })
            .context("render interrupted")?;
        bar.finish_and_clear();
        Ok(out.sums.image())
    }
}

/// The pixels that are mostly hair, and how many there are (refused when none is).
fn hair_mask(renders: &Renders, args: &CalibrateArgs) -> Result<(Vec<bool>, usize)> {
    let coverage = renders.render(&HairCoverage, 16, "hair coverage")?;
    let mask: Vec<bool> = coverage.pixels.iter().map(|p| p.x >= 0.5).collect();
    let hair_pixels = mask.iter().filter(|&&m| m).count();
    if hair_pixels == 0 {
        bail!(
            "{}: no pixel of the film{} is mostly hair; choose a --crop with hair in it",
            args.scene.display(),
            if args.crop.is_some() { " window" } else { "" }
        );
    }
    Ok((mask, hair_pixels))
}

/// Fitting the factors: the renders of the integrator being calibrated, over the hair pixels,
/// against the path-traced reference's means there.
struct Fitting<'a> {
    renders: &'a Renders<'a>,
    target: &'a Target,
    prep: &'a tress_core::prepare::Preparation,
    spp: u32,
    mask: &'a [bool],
    reference_mean: [f64; 3],
    /// `x = d_f^forward_power` is what the hair means are bilinear in (the paper's d_f enters
    /// squared; see the module docs).
    forward_power: f64,
    /// The integrator's own `(x, y)`.
    default: (f64, f64),
}

impl Fitting<'_> {
    /// A render with the factors `d_f`, `d_b` and `path_bounces`.
    fn image(&self, d_f: f64, d_b: f64, path_bounces: u32, label: &str) -> Result<Image> {
        let integrator = self
            .target
            .with_factors(d_f, d_b, path_bounces)
            .build(self.renders.scene, self.prep)?;
        self.renders.render(integrator.as_ref(), self.spp, label)
    }

    /// Fits the factors for `path_bounces` from the four corner renders, and says how well
    /// the defaults and the fit match.
    fn candidate(&self, path_bounces: u32) -> Result<Candidate> {
        let mut corner = [[[0.0; 3]; 2]; 2];
        for (i, row) in corner.iter_mut().enumerate() {
            for (j, c) in row.iter_mut().enumerate() {
                let label = format!("path_bounces = {path_bounces}, d_f = {i}, d_b = {j}");
                let img = self.image(i as f64, j as f64, path_bounces, &label)?;
                *c = masked_mean(&img, self.mask);
            }
        }
        let bilinear = Bilinear { corner };
        let (x, y) = fit(&bilinear, self.reference_mean);
        let (default_x, default_y) = self.default;
        println!(
            "path_bounces = {path_bounces}: default d_f = {:.3}, d_b = {:.3}: ÷ path {}; fitted \
             d_f = {:.3}, d_b = {:.3}: ÷ path {} (predicted)",
            default_x.powf(1.0 / self.forward_power),
            default_y,
            ratios(bilinear.at(default_x, default_y), self.reference_mean),
            x.powf(1.0 / self.forward_power),
            y,
            ratios(bilinear.at(x, y), self.reference_mean),
        );
        let misfit = misfit(bilinear.at(x, y), self.reference_mean);
        Ok(Candidate {
            path_bounces,
            bilinear,
            x,
            y,
            misfit,
        })
    }

    /// The candidate `path_bounces` whose fit comes closest to the reference.
    fn best(&self, path_bounces: &[u32]) -> Result<Candidate> {
        let mut candidates = path_bounces.to_vec();
        candidates.sort_unstable();
        candidates.dedup();
        let mut best: Option<Candidate> = None;
        for &path_bounces in &candidates {
            let candidate = self.candidate(path_bounces)?;
            if best.as_ref().is_none_or(|b| candidate.misfit < b.misfit) {
                best = Some(candidate);
            }
        }
        best.ok_or_else(|| anyhow::anyhow!("--path-bounces: give at least one value"))
    }
}

pub fn run(args: CalibrateArgs) -> Result<()> {
    let (desc, target, reference_integrator) = load(&args)?;
    let inputs = desc.inputs(&args.scene)?;
    // Refused before the renders, not after.
    if let Some(out) = &args.out {
        output_file::check(out, &inputs)?;
    }
    let pool = args.run.thread_pool()?;
    // One preparation context: the scene's models and the corner and check renders share
    // their tables.
    let prep = args.run.preparation();
    let built = pool.install(|| scene_desc::build(&desc, &args.scene, &prep))?;
    crate::print_warnings(&prep);
    let renders = Renders {
        pool: &pool,
        scene: &built.scene,
        film: &desc.film,
        cancel: AtomicBool::new(false),
        verbose: !args.run.quiet,
    };
    let (mask, hair_pixels) = hair_mask(&renders, &args)?;
    let path = reference_integrator.build(&built.scene, &prep)?;
    let reference = renders.render(path.as_ref(), args.reference_spp, "path reference")?;
    let reference_mean = masked_mean(&reference, &mask);
    if reference_mean.iter().any(|&m| m <= 0.0) {
        bail!("the path-traced reference is black in a channel over the hair pixels");
    }

    let settings = &target.settings;
    let model = settings.tables.multiple_scattering;
    // The paper's d_f enters squared (module docs).
    let forward_power = match model {
        MultipleScattering::Paper => 2.0,
        MultipleScattering::FiberMedium => 1.0,
    };
    let defaults = DensityFactors::for_model(model);
    let default_x = (settings.d_f.unwrap_or(defaults.d_f) as f64).powf(forward_power);
    let default_y = settings.d_b.unwrap_or(defaults.d_b) as f64;
    println!(
        "{}: {hair_pixels} hair pixels; path reference {} spp, dual scattering {} spp ({model:?})",
        args.scene.display(),
        args.reference_spp,
        args.spp
    );
    println!(
        "path reference, hair mean R/G/B: {:.4} / {:.4} / {:.4}",
        reference_mean[0], reference_mean[1], reference_mean[2]
    );
    let fitting = Fitting {
        renders: &renders,
        target: &target,
        prep: &prep,
        spp: args.spp,
        mask: &mask,
        reference_mean,
        forward_power,
        default: (default_x, default_y),
    };
    let best = fitting.best(&args.path_bounces)?;
    conclude(&args, &fitting, &best, &reference, &inputs)
}

/// Renders the fitted factors to check them, says how well they match, and writes them with
/// `--out`.
fn conclude(
    args: &CalibrateArgs,
    fitting: &Fitting,
    best: &Candidate,
    reference: &Image,
    inputs: &Inputs,
) -> Result<()> {
    let Candidate {
        path_bounces,
        ref bilinear,
        x,
        y,
        ..
    } = *best;
    let (mask, reference_mean) = (fitting.mask, fitting.reference_mean);
    let (d_f, d_b) = (x.powf(1.0 / fitting.forward_power), y);
    let fitted_image = fitting.image(d_f, d_b, path_bounces, "check")?;
    let fitted_mean = masked_mean(&fitted_image, mask);
    println!(
        "fitted  path_bounces = {path_bounces}, d_f = {d_f:.3}, d_b = {d_b:.3}: ÷ path {} \
         (predicted), {} (rendered), hair relMSE {:.3e}",
        ratios(bilinear.at(x, y), reference_mean),
        ratios(fitted_mean, reference_mean),
        masked_relmse(&fitted_image, reference, mask)
    );
    // Stopped at a bound with a channel still more than 1 % off: say which factor ran out.
    let worst = bilinear
        .at(x, y)
        .iter()
        .zip(reference_mean)
        .map(|(m, r)| (m / r - 1.0).abs())
        .fold(0.0, f64::max);
    for (name, v) in [("d_f", x), ("d_b", y)] {
        if (v <= 0.0 || v >= 1.0) && worst > 0.01 {
            println!(
                "note: {name} stopped at the end of [0, 1] with a channel {:.1} % off: the \
                 approximation cannot match the reference by scaling its terms within [0, 1]",
                100.0 * worst
            );
        }
    }
    if let Some(out) = &args.out {
        let fitted = fitting.target.with_factors(
            f64::from((d_f * 1000.0).round() as f32 / 1000.0),
            f64::from((d_b * 1000.0).round() as f32 / 1000.0),
            path_bounces,
        );
        let text = format!(
            "// tress calibrate {}: hair mean ÷ path {} (R/G/B)\n{}\n",
            args.scene.display(),
            ratios(fitted_mean, reference_mean),
            tress_loader::ron_options()
                .to_string_pretty(&fitted, ron::ser::PrettyConfig::default())?
        );
        output_file::write_bytes(out, inputs, text.as_bytes())?;
        println!("wrote {}", out.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fit_recovers_the_factors_of_a_bilinear_model() {
        // Means of an exactly bilinear model, with the reference taken at (0.4, 0.8).
        let model = Bilinear {
            corner: [
                [[0.1, 0.08, 0.05], [0.15, 0.1, 0.06]],
                [[0.2, 0.12, 0.07], [0.3, 0.16, 0.08]],
            ],
        };
        let (x, y) = fit(&model, model.at(0.4, 0.8));
        assert!((x - 0.4).abs() < 1e-3 && (y - 0.8).abs() < 1e-3, "{x} {y}");
        // Out of reach: the fit stops at the border.
        let (x, _) = fit(&model, [1.0, 1.0, 1.0]);
        assert_eq!(x, 1.0);
    }
}
