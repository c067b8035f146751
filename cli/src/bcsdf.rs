//! `tress bcsdf`: tools for people who add or tune hair models.

use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, Subcommand};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use tress_core::math::{fiber_direction, unit, Vec3};
use tress_core::output_file::{self, Inputs};
use tress_core::{Bcsdf, Sampler};
use tress_materials::HairModel;

#[derive(Subcommand, Debug)]
pub enum BcsdfCommand {
    /// Albedo ∫ f cos θ_i dω (averaged over h) against θ_o: 1 means energy conserving.
    Furnace(FurnaceArgs),
    /// Evaluate f and pdf for directions read from a CSV file.
    Eval(EvalArgs),
    /// Plot the longitudinal and azimuthal profiles of each lobe (PNG and SVG).
    Plot(PlotArgs),
}

#[derive(Args, Debug)]
pub struct PlotArgs {
    /// The hair model as RON.
    #[arg(long)]
    pub model: String,
    /// Outgoing inclination θ_o in degrees.
    #[arg(long, default_value_t = 30.0, allow_hyphen_values = true)]
    pub theta_o: f32,
    /// Offset h across the fiber; default: averaged over h ∈ [-1, 1].
    #[arg(long, allow_hyphen_values = true)]
    pub h: Option<f32>,
    /// Output PNG (an SVG is written beside it).
    #[arg(long, default_value = "lobes.png")]
    pub out: PathBuf,
}

#[derive(Args, Debug)]
pub struct FurnaceArgs {
    /// The hair model as RON, e.g. 'Chiang(beta_m: 0.3, beta_n: 0.3, pigment: SigmaA(0, 0, 0))'.
    #[arg(long)]
    pub model: String,
    /// Importance samples per θ_o.
    #[arg(long, default_value_t = 400_000)]
    pub samples: u32,
    /// θ_o step in degrees (from -90 to 90).
    #[arg(long, default_value_t = 15.0)]
    pub step: f32,
    /// Print CSV instead of a table.
    #[arg(long)]
    pub csv: bool,
}

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// The hair model as RON.
    #[arg(long)]
    pub model: String,
    /// CSV rows `h, wi_x, wi_y, wi_z, wo_x, wo_y, wo_z` in the local fiber frame (x = tangent,
    /// z toward the viewer; see docs/src/guide/scenes.md). A header line is allowed.
    #[arg(long)]
    pub input: PathBuf,
    /// Output CSV (default: standard output).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// Output f·cos θ_i (tress's `eval`) instead of the BCSDF f.
    #[arg(long)]
    pub with_cosine: bool,
}

pub fn run(cmd: BcsdfCommand) -> Result<()> {
    match cmd {
        BcsdfCommand::Furnace(a) => furnace(a),
        BcsdfCommand::Eval(a) => eval(a),
        BcsdfCommand::Plot(a) => plot(a),
    }
}

fn build_model(ron_text: &str) -> Result<Arc<dyn Bcsdf>> {
    let model: HairModel = tress_loader::ron_options()
        .from_str(ron_text)
        .map_err(|e| {
            anyhow!(
                "--model: {e}\n  registered models: {}",
                HairModel::names().join(", ")
            )
        })?;
    let prep = crate::default_preparation();
    let bcsdf = model.build(&prep).map_err(|e| anyhow!("--model: {e}"));
    crate::print_warnings(&prep);
    bcsdf
}

/// Mean and standard error of an albedo estimator over `samples` draws at θ_o with h uniform:
/// `f/pdf` of the model's own sampler (`importance`), or `4π·f` for uniform sphere directions.
pub fn albedo(
    bcsdf: &dyn Bcsdf,
    theta_o: f32,
    samples: u32,
    seed: u64,
    importance: bool,
) -> ([f64; 3], [f64; 3]) {
    let wo = fiber_direction(theta_o.sin(), theta_o.cos(), std::f32::consts::FRAC_PI_2);
    let mut rng = Sampler::from_seed(seed);
    let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
    for _ in 0..samples {
        let h = 2.0 * rng.next_1d() - 1.0;
        let w = if importance {
            match bcsdf.sample(wo, h, rng.next_4d()) {
                Some(s) if s.pdf > 0.0 => s.f / s.pdf,
                _ => Vec3::ZERO,
            }
        } else {
            let wi = tress_core::sampling::sample_uniform_sphere(rng.next_2d());
            bcsdf.eval(wo, wi, h) * (4.0 * std::f32::consts::PI)
        };
        for c in 0..3 {
            sum[c] += w[c] as f64;
            sum2[c] += (w[c] as f64).powi(2);
        }
    }
    let n = samples as f64;
    let mean = sum.map(|s| s / n);
    let se = std::array::from_fn(|c| ((sum2[c] / n - mean[c] * mean[c]).max(0.0) / n).sqrt());
    (mean, se)
}

fn furnace(a: FurnaceArgs) -> Result<()> {
    let bcsdf = build_model(&a.model)?;
    // A step below 0.01° would mean over 18 000 rows (and one below f32 resolution, none).
    if !(a.step >= 0.01 && a.step <= 90.0) {
        bail!("--step must lie in [0.01, 90] degrees");
    }
    if a.samples < 2 {
        bail!("--samples must be at least 2 (the standard error needs two)");
    }
    let mut out = String::new();
    if a.csv {
        out.push_str("theta_o_deg,albedo_r,albedo_g,albedo_b,stderr_r,stderr_g,stderr_b,uniform_r,uniform_g,uniform_b,uniform_stderr_r,uniform_stderr_g,uniform_stderr_b\n");
    } else {
        writeln!(out, "albedo ∫ f cos θ_i dω, h uniform in [-1, 1]: importance-sampled, and a uniform-sphere check")?;
        writeln!(
            out,
            "{:>8}  {:>8} {:>8} {:>8} {:>9}   {:>8} {:>8} {:>8} {:>9}",
            "θ_o (°)", "R", "G", "B", "std err", "unif R", "unif G", "unif B", "std err"
        )?;
    }
    let mut t = -90.0f32;
    while t <= 90.0 + 1e-3 {
        // Exactly ±90° looks straight along the fiber, where every model degenerates.
        let theta = t.clamp(-89.5, 89.5);
        let seed = 1 + t.to_bits() as u64;
        let (m, se) = albedo(bcsdf.as_ref(), theta.to_radians(), a.samples, seed, true);
        let (um, use_) = albedo(bcsdf.as_ref(), theta.to_radians(), a.samples, seed, false);
        let max = |v: [f64; 3]| v.iter().cloned().fold(0.0, f64::max);
        if a.csv {
            writeln!(
                out,
                "{theta},{},{},{},{},{},{},{},{},{},{},{},{}",
                m[0],
                m[1],
                m[2],
                se[0],
                se[1],
                se[2],
                um[0],
                um[1],
                um[2],
                use_[0],
                use_[1],
                use_[2]
            )?;
        } else {
            writeln!(
                out,
                "{theta:>8.1}  {:>8.4} {:>8.4} {:>8.4} {:>9.1e}   {:>8.4} {:>8.4} {:>8.4} {:>9.1e}",
                m[0],
                m[1],
                m[2],
                max(se),
                um[0],
                um[1],
                um[2],
                max(use_)
            )?;
        }
        t += a.step;
    }
    print!("{out}");
    Ok(())
}

fn eval(a: EvalArgs) -> Result<()> {
    let bcsdf = build_model(&a.model)?;
    let text = tress_core::files::read_regular_text(&a.input)
        .with_context(|| format!("cannot read {}", a.input.display()))?;
    let mut out = String::from(if a.with_cosine {
        "f_cos_r,f_cos_g,f_cos_b,pdf\n"
    } else {
        "f_r,f_g,f_b,pdf\n"
    });
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let parsed: Option<Vec<f32>> = fields.iter().map(|f| f.parse::<f32>().ok()).collect();
        let Some(v) = parsed else {
            if i == 0 {
                continue; // header
            }
            bail!(
                "{}:{}: expected 7 numbers h,wi_x,wi_y,wi_z,wo_x,wo_y,wo_z",
                a.input.display(),
                i + 1
            );
        };
        if v.len() != 7 || v.iter().any(|x| !x.is_finite()) {
            bail!(
                "{}:{}: expected 7 finite numbers h,wi_x,wi_y,wi_z,wo_x,wo_y,wo_z",
                a.input.display(),
                i + 1
            );
        }
        let h = v[0];
        if !(-1.0..=1.0).contains(&h) {
            bail!(
                "{}:{}: h = {h} must lie in [-1, 1]",
                a.input.display(),
                i + 1
            );
        }
        let (wi, wo) = (Vec3::new(v[1], v[2], v[3]), Vec3::new(v[4], v[5], v[6]));
        let (Some(wi), Some(wo)) = (unit(wi), unit(wo)) else {
            bail!("{}:{}: zero-length direction", a.input.display(), i + 1);
        };
        let f_cos = bcsdf.eval(wo, wi, h);
        let cos_theta_i = (1.0 - wi.x * wi.x).max(0.0).sqrt();
        let f = if a.with_cosine {
            f_cos
        } else if cos_theta_i > 0.0 {
            f_cos / cos_theta_i
        } else {
            Vec3::ZERO
        };
        writeln!(out, "{},{},{},{}", f.x, f.y, f.z, bcsdf.pdf(wo, wi, h))?;
    }
    match a.output {
        Some(p) => {
            let inputs: Inputs = [&a.input].into_iter().collect();
            output_file::write_bytes(&p, &inputs, out.as_bytes())?
        }
        None => print!("{out}"),
    }
    Ok(())
}

/// A sampled curve: (x, y) points.
type Profile = Vec<(f64, f64)>;

/// Marginal profiles of `eval_lobe` (luminance): over θ_i (integrated over φ) and over φ
/// (integrated over θ_i), each integrating to the lobe's albedo.
fn lobe_profiles(bcsdf: &dyn Bcsdf, theta_o: f32, hs: &[f32], lobe: usize) -> (Profile, Profile) {
    use std::f64::consts::PI;
    const N_THETA: usize = 180;
    const N_PHI: usize = 360;
    let wo = fiber_direction(theta_o.sin(), theta_o.cos(), std::f32::consts::FRAC_PI_2);
    let mut by_theta = vec![0.0f64; N_THETA];
    let mut by_phi = vec![0.0f64; N_PHI];
    let (d_theta, d_phi) = (PI / N_THETA as f64, 2.0 * PI / N_PHI as f64);
    for (i, bt) in by_theta.iter_mut().enumerate() {
        let theta = -PI / 2.0 + (i as f64 + 0.5) * d_theta;
        let cos_t = theta.cos();
        for (j, bp) in by_phi.iter_mut().enumerate() {
            let phi_rel = -PI + (j as f64 + 0.5) * d_phi;
            // φ_i = φ_o + Δφ with φ_o = π/2 in the local frame.
            let wi = fiber_direction(
                theta.sin() as f32,
                cos_t as f32,
                (std::f64::consts::FRAC_PI_2 + phi_rel) as f32,
            );
            let v: f64 = hs
                .iter()
                .map(|&h| tress_core::luminance(bcsdf.eval_lobe(wo, wi, h, lobe)) as f64)
                .sum::<f64>()
                / hs.len() as f64;
            *bt += v * cos_t * d_phi;
            *bp += v * cos_t * d_theta;
        }
    }
    (
        by_theta
            .iter()
            .enumerate()
            .map(|(i, v)| ((-90.0 + (i as f64 + 0.5)), *v))
            .collect(),
        by_phi
            .iter()
            .enumerate()
            .map(|(j, v)| ((-180.0 + (j as f64 + 0.5)), *v))
            .collect(),
    )
}

fn plot(a: PlotArgs) -> Result<()> {
    use crate::plot::{write_charts, Chart, Series};
    let bcsdf = build_model(&a.model)?;
    if !(-89.9..=89.9).contains(&a.theta_o) {
        bail!("--theta-o must lie in [-89.9, 89.9] degrees");
    }
    let hs: Vec<f32> = match a.h {
        Some(h) if (-1.0..=1.0).contains(&h) => vec![h],
        Some(h) => bail!("--h = {h} must lie in [-1, 1]"),
        None => (0..16).map(|i| -1.0 + (i as f32 + 0.5) / 8.0).collect(),
    };
    let names = bcsdf.lobe_names();
    let (mut longitudinal, mut azimuthal) = (Vec::new(), Vec::new());
    for (p, name) in names.iter().enumerate() {
        let (lt, az) = lobe_profiles(bcsdf.as_ref(), a.theta_o.to_radians(), &hs, p);
        longitudinal.push(Series {
            name: name.to_string(),
            points: lt,
            band: None,
            reference: false,
        });
        azimuthal.push(Series {
            name: name.to_string(),
            points: az,
            band: None,
            reference: false,
        });
    }
    let h_text =
        a.h.map(|h| format!("h = {h}"))
            .unwrap_or_else(|| "h averaged".into());
    let charts = [
        Chart {
            title: format!("longitudinal, θ_o = {}°, {h_text}", a.theta_o),
            x_label: "θ_i (degrees)".into(),
            y_label: "∫ f cos θ_i dφ (per radian)".into(),
            series: longitudinal,
            log_x: false,
            log_y: false,
            band_label: None,
        },
        Chart {
            title: format!("azimuthal, θ_o = {}°, {h_text}", a.theta_o),
            x_label: "φ_i − φ_o (degrees)".into(),
            y_label: "∫ f cos θ_i dθ_i (per radian)".into(),
            series: azimuthal,
            log_x: false,
            log_y: false,
            band_label: None,
        },
    ];
    let stem = a.out.with_extension("");
    // The model is given on the command line: no file is read.
    write_charts(&stem, &Inputs::default(), &charts, 640, 440)?;
    eprintln!(
        "wrote {} and {}",
        stem.with_extension("png").display(),
        stem.with_extension("svg").display()
    );
    Ok(())
}
