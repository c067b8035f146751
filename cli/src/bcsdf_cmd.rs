//! `tress bcsdf`: tools for people who add or tune hair models.

use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, Subcommand};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use tress_core::math::{fiber_direction, Vec3};
use tress_core::{Bcsdf, Sampler};
use tress_materials::HairModel;

#[derive(Subcommand, Debug)]
pub enum BcsdfCommand {
    /// Albedo ∫ f cos θ_i dω (averaged over h) against θ_o: 1 means energy conserving.
    Furnace(FurnaceArgs),
    /// Evaluate f and pdf for directions read from a CSV file.
    Eval(EvalArgs),
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
    /// z toward the viewer; see the README). A header line is allowed.
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
    }
}

fn build_model(ron_text: &str) -> Result<Arc<dyn Bcsdf>> {
    let model: HairModel = crate::ron_options().from_str(ron_text).map_err(|e| {
        anyhow!(
            "--model: {e}\n  registered models: {}",
            HairModel::names().join(", ")
        )
    })?;
    model.build().map_err(|e| anyhow!("--model: {e}"))
}

/// Mean and standard error of f/pdf over `samples` importance samples at θ_o, h uniform.
pub fn albedo(bcsdf: &dyn Bcsdf, theta_o: f32, samples: u32, seed: u64) -> ([f64; 3], [f64; 3]) {
    let wo = fiber_direction(theta_o.sin(), theta_o.cos(), std::f32::consts::FRAC_PI_2);
    let mut rng = Sampler::from_seed(seed);
    let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
    for _ in 0..samples {
        let h = 2.0 * rng.next_1d() - 1.0;
        if let Some(s) = bcsdf.sample(wo, h, rng.next_4d()) {
            if s.pdf > 0.0 {
                let w = s.f / s.pdf;
                for c in 0..3 {
                    sum[c] += w[c] as f64;
                    sum2[c] += (w[c] as f64).powi(2);
                }
            }
        }
    }
    let n = samples as f64;
    let mean = sum.map(|s| s / n);
    let se = std::array::from_fn(|c| ((sum2[c] / n - mean[c] * mean[c]).max(0.0) / n).sqrt());
    (mean, se)
}

fn furnace(a: FurnaceArgs) -> Result<()> {
    let bcsdf = build_model(&a.model)?;
    if !(a.step > 0.0 && a.step <= 90.0) {
        bail!("--step must lie in (0, 90] degrees");
    }
    let mut out = String::new();
    if a.csv {
        out.push_str("theta_o_deg,albedo_r,albedo_g,albedo_b,stderr_r,stderr_g,stderr_b\n");
    } else {
        writeln!(
            out,
            "{:>8}  {:>8} {:>8} {:>8}   {:>9}",
            "θ_o (°)", "R", "G", "B", "std err"
        )?;
    }
    let mut t = -90.0f32;
    while t <= 90.0 + 1e-3 {
        // Exactly ±90° looks straight along the fiber, where every model degenerates.
        let theta = t.clamp(-89.5, 89.5);
        let (m, se) = albedo(
            bcsdf.as_ref(),
            theta.to_radians(),
            a.samples,
            1 + t.to_bits() as u64,
        );
        if a.csv {
            writeln!(
                out,
                "{theta},{},{},{},{},{},{}",
                m[0], m[1], m[2], se[0], se[1], se[2]
            )?;
        } else {
            writeln!(
                out,
                "{theta:>8.1}  {:>8.4} {:>8.4} {:>8.4}   {:>9.2e}",
                m[0],
                m[1],
                m[2],
                se.iter().cloned().fold(0.0, f64::max)
            )?;
        }
        t += a.step;
    }
    print!("{out}");
    Ok(())
}

fn eval(a: EvalArgs) -> Result<()> {
    let bcsdf = build_model(&a.model)?;
    let text = std::fs::read_to_string(&a.input)
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
        if wi.length() == 0.0 || wo.length() == 0.0 {
            bail!("{}:{}: zero-length direction", a.input.display(), i + 1);
        }
        let (wi, wo) = (wi.normalize(), wo.normalize());
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
        Some(p) => crate::atomic_write(&p, out.as_bytes())?,
        None => print!("{out}"),
    }
    Ok(())
}
