//! Statistical tests of every hair model in the registry: each test loops over
//! `HairModel::test_instances()`, so a newly registered model is covered without edits here.
//!
//! 1. `white_furnace_uniform`: ∫ eval dω = 1 ± 5 % (white instances), stratified uniform sampling.
//! 2. `white_furnace_importance_sampled`: mean f/pdf = 1 ± 1 % (white instances).
//! 3. `sample_returns_eval_and_pdf`: `sample`'s f and pdf equal `eval` and `pdf` at its wi.
//! 4. `importance_and_uniform_estimates_agree`: ∫ eval·L dω by both estimators, within 1 %.
//! 5. `sampler_matches_pdf_chi2`: χ² of `sample` against `pdf` over the sphere at four (θ_o, h);
//!    `sampler_matches_pdf_chi2_full_grid` (ignored, ~3× longer) runs all twelve.
//! 6. `pdf_integrates_to_one`: quadrature of `pdf` over the sphere, 1 ± 1 %.
//! 7. `outputs_are_finite_and_non_negative`: edge cases and a random sweep;
//!    `outputs_are_finite_along_the_fiber`: wo along the fiber with tiny sideways parts.
//!
//! `eval_cost` (ignored) prints ns per eval/pdf/sample of every instance.
//!
//! Every estimate is printed with its standard error (`cargo test -- --nocapture`), and every
//! tolerance is checked against that error so that no test can pass for lack of resolution.

use std::f32::consts::{FRAC_PI_2, TAU};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use tress_core::math::{fiber_direction, safe_sqrt, Rgb, Vec3};
use tress_core::prepare::Preparation;
use tress_core::rng::hash_words;
use tress_core::sampling::sample_uniform_sphere;
use tress_core::stats::{sidak_alpha, Chi2Outcome, SphereChi2};
use tress_core::{Bcsdf, Sampler};
use tress_materials::HairModel;

struct Instance {
    name: String,
    white_furnace: bool,
    bcsdf: Arc<dyn Bcsdf>,
}

/// One preparation context for the file's tests: each fur table is built once.
fn prep() -> &'static Preparation {
    static PREP: std::sync::OnceLock<Preparation> = std::sync::OnceLock::new();
    PREP.get_or_init(Preparation::new)
}

fn instances() -> Vec<Instance> {
    HairModel::test_instances()
        .into_iter()
        .map(|t| Instance {
            bcsdf: t
                .params
                .build(prep())
                .unwrap_or_else(|e| panic!("test instance {} is invalid: {e}", t.name)),
            name: t.name,
            white_furnace: t.white_furnace,
        })
        .collect()
}

/// The outgoing direction at longitudinal angle θ_o (degrees) in the fiber frame (φ_o = π/2).
fn wo_at(theta_deg: f32) -> Vec3 {
    let t = theta_deg.to_radians();
    fiber_direction(t.sin(), t.cos(), FRAC_PI_2)
}

/// A seed for one (test, instance, configuration): fixed per instance, so an instance's figures
/// do not move when other models are registered.
fn seed(test: u64, name: &str, a: f32, b: f32) -> u64 {
    let mut words: Vec<u64> = name.bytes().map(u64::from).collect();
    words.extend([test, a.to_bits() as u64, b.to_bits() as u64]);
    hash_words(&words)
}

/// A direction from a point of the unit square, uniform on the sphere with the pole on the
/// fiber axis (x): equal-area in sin θ.
fn sphere_point(u_sin: f32, u_phi: f32) -> Vec3 {
    let s = 2.0 * u_sin - 1.0;
    fiber_direction(s, safe_sqrt(1.0 - s * s), TAU * u_phi)
}

/// `f` over `jobs` on every core; results in job order. Workers only compute: assertions run
/// afterwards on the calling thread, once the whole table is printed.
fn par_map<J: Sync, R: Send>(jobs: &[J], f: impl Fn(&J) -> R + Sync) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(jobs.len().max(1));
    let mut out: Vec<Option<R>> = (0..jobs.len()).map(|_| None).collect();
    std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= jobs.len() {
                            break done;
                        }
                        done.push((i, f(&jobs[i])));
                    }
                })
            })
            .collect();
        for w in workers {
            for (i, r) in w.join().expect("worker panicked") {
                out[i] = Some(r);
            }
        }
    });
    out.into_iter().map(|r| r.expect("every job ran")).collect()
}

/// A per-channel estimate and its standard error.
#[derive(Clone, Copy, Debug)]
struct Estimate {
    mean: [f64; 3],
    se: [f64; 3],
}

impl Estimate {
    fn fmt(&self, k: usize) -> String {
        format!("{:.4}±{:.4}", self.mean[k], self.se[k])
    }

    /// The largest relative standard error over the channels with a non-zero mean.
    fn rel_se(&self) -> f64 {
        (0..3)
            .filter(|&c| self.mean[c] != 0.0)
            .map(|c| self.se[c] / self.mean[c].abs())
            .fold(0.0, f64::max)
    }
}

/// Runs `estimate(level)` for level 0, 1, 2 (each level should take 4× the samples of the last)
/// until its relative standard error is below `target`: the sample count adapts to the lobes'
/// sharpness, the tolerance the result is then held to does not.
fn refine(target: f64, estimate: impl Fn(u32) -> Estimate) -> (Estimate, u32) {
    let mut level = 0;
    loop {
        let e = estimate(level);
        if e.rel_se() < target || level == 2 {
            return (e, level);
        }
        level += 1;
    }
}

/// Mean of `g` over the unit square by stratified sampling: `n[0]×n[1]` equal strata with two
/// independent uniform samples in each, so that the within-stratum variance, and with it the
/// standard error, is estimated without bias from the two samples' difference.
fn stratified_mean(n: [usize; 2], rng: &mut Sampler, g: impl Fn([f32; 2]) -> Rgb) -> Estimate {
    let strata = (n[0] * n[1]) as f64;
    let (mut sum, mut var) = ([0.0f64; 3], [0.0f64; 3]);
    for i in 0..n[0] {
        for j in 0..n[1] {
            let mut y = [[0.0f64; 3]; 2];
            for y in &mut y {
                let u = [
                    (i as f32 + rng.next_1d()) / n[0] as f32,
                    (j as f32 + rng.next_1d()) / n[1] as f32,
                ];
                let v = g(u);
                *y = [v.x as f64, v.y as f64, v.z as f64];
            }
            for c in 0..3 {
                sum[c] += 0.5 * (y[0][c] + y[1][c]);
                // Var of the stratum's mean of two = E[(y₀ − y₁)²] / 4.
                var[c] += 0.25 * (y[0][c] - y[1][c]).powi(2);
            }
        }
    }
    Estimate {
        mean: sum.map(|s| s / strata),
        se: var.map(|v| v.sqrt() / strata),
    }
}

/// Mean of `g(h, u)` over h uniform in [−1, 1] and u uniform in the unit square: `n_h` strata in
/// h with two independent h in each, and for every h a jittered grid of `n[0]×n[1]` cells over
/// u. The standard error comes from the two grid means of each h stratum, so it includes both
/// the variation with h and the noise of each grid. (Stratifying h and u jointly would be far
/// worse: the lobes move with h, so a (u, h) cell does not see a smooth integrand.)
fn h_averaged_mean(
    n_h: usize,
    n: [usize; 2],
    rng: &mut Sampler,
    g: impl Fn(f32, [f32; 2]) -> Rgb,
) -> Estimate {
    let (mut sum, mut var) = ([0.0f64; 3], [0.0f64; 3]);
    let cells = (n[0] * n[1]) as f64;
    for k in 0..n_h {
        let mut y = [[0.0f64; 3]; 2];
        for y in &mut y {
            let h = 2.0 * (k as f32 + rng.next_1d()) / n_h as f32 - 1.0;
            let mut acc = [0.0f64; 3];
            for i in 0..n[0] {
                for j in 0..n[1] {
                    let u = [
                        (i as f32 + rng.next_1d()) / n[0] as f32,
                        (j as f32 + rng.next_1d()) / n[1] as f32,
                    ];
                    let v = g(h, u);
                    for (a, x) in acc.iter_mut().zip([v.x, v.y, v.z]) {
                        *a += x as f64;
                    }
                }
            }
            *y = acc.map(|a| a / cells);
        }
        for c in 0..3 {
            sum[c] += 0.5 * (y[0][c] + y[1][c]);
            var[c] += 0.25 * (y[0][c] - y[1][c]).powi(2);
        }
    }
    Estimate {
        mean: sum.map(|s| s / n_h as f64),
        se: var.map(|v| v.sqrt() / n_h as f64),
    }
}

/// Mean and standard error of `n` independent draws of `g`.
fn mc_mean(n: usize, seed: u64, mut g: impl FnMut(&mut Sampler) -> Rgb) -> Estimate {
    let mut rng = Sampler::from_seed(seed);
    let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
    for _ in 0..n {
        let v = g(&mut rng);
        for (c, x) in [v.x, v.y, v.z].into_iter().enumerate() {
            sum[c] += x as f64;
            sum2[c] += (x as f64) * (x as f64);
        }
    }
    let nf = n as f64;
    let mean = sum.map(|s| s / nf);
    let mut se = [0.0; 3];
    for c in 0..3 {
        se[c] = ((sum2[c] / nf - mean[c] * mean[c]).max(0.0) / (nf - 1.0)).sqrt();
    }
    Estimate { mean, se }
}

const FURNACE_THETAS: [f32; 4] = [0.0, 30.0, 60.0, 80.0];

/// (instance, θ_o) for every white-furnace instance and every θ_o of `FURNACE_THETAS`.
fn furnace_jobs(all: &[Instance]) -> Vec<(usize, f32)> {
    all.iter()
        .enumerate()
        .filter(|(_, t)| t.white_furnace)
        .flat_map(|(i, _)| FURNACE_THETAS.map(|th| (i, th)))
        .collect()
}

/// Asserts that every channel of the estimates of `jobs` is 1 within `percent` %, with a
/// standard error below a quarter of the tolerance, so that the test has the resolution to fail.
fn assert_furnace<'a>(
    all: &[Instance],
    jobs: &[(usize, f32)],
    est: impl IntoIterator<Item = &'a Estimate>,
    percent: f64,
) {
    let tol = percent / 100.0;
    for ((i, th), e) in jobs.iter().zip(est) {
        for c in 0..3 {
            let ctx = format!("{} θ_o = {th}°, channel {c}: {}", all[*i].name, e.fmt(c));
            assert!(4.0 * e.se[c] < tol, "{ctx}: too noisy to test ±{percent} %");
            assert!(
                (e.mean[c] - 1.0).abs() < tol,
                "{ctx}: not within {percent} % of 1"
            );
        }
    }
}

#[test]
fn white_furnace_uniform() {
    let all = instances();
    let jobs = furnace_jobs(&all);
    // h uniform in [−1, 1] (16 strata × 2), wi uniform on the sphere (a 125·2ᴸ × 250·2ᴸ
    // jittered grid in (sin θ, φ) per h): 10⁶·4ᴸ samples at refinement level L.
    let est = par_map(&jobs, |&(i, th)| {
        let b = &all[i].bcsdf;
        let wo = wo_at(th);
        refine(0.0125 / 4.0, |level| {
            let k = 1 << level;
            let mut rng = Sampler::from_seed(seed(1, &all[i].name, th, level as f32));
            h_averaged_mean(16, [125 * k, 250 * k], &mut rng, |h, u| {
                b.eval(wo, sphere_point(u[0], u[1]), h) * (2.0 * TAU)
            })
        })
    });
    println!(
        "\nwhite furnace, uniform sphere sampling (h uniform): ∫ eval dω, channel 0 ± s.e. \
         (refinement level: 10⁶·4ᴸ samples)"
    );
    print_theta_table(&all, &jobs, &est, |(e, l)| format!("{} L{l}", e.fmt(0)));
    assert_furnace(&all, &jobs, est.iter().map(|(e, _)| e), 5.0);
}

#[test]
fn white_furnace_importance_sampled() {
    let all = instances();
    let jobs = furnace_jobs(&all);
    let est = par_map(&jobs, |&(i, th)| {
        let b = &all[i].bcsdf;
        let wo = wo_at(th);
        mc_mean(200_000, seed(2, &all[i].name, th, 0.0), |rng| {
            let h = 2.0 * rng.next_1d() - 1.0;
            b.sample_weight(wo, h, rng.next_4d())
                .map_or(Rgb::ZERO, |(_, weight)| weight)
        })
    });
    println!(
        "\nwhite furnace, importance sampled (h uniform): mean sample weight, channel 0 ± s.e."
    );
    print_theta_table(&all, &jobs, &est, |e| e.fmt(0));
    assert_furnace(&all, &jobs, &est, 1.0);
}

/// Prints one row per instance and one column per θ_o of `jobs`.
fn print_theta_table<T>(
    all: &[Instance],
    jobs: &[(usize, f32)],
    results: &[T],
    cell: impl Fn(&T) -> String,
) {
    let header: String = FURNACE_THETAS
        .iter()
        .map(|t| format!("{:>20}", format!("θ_o={t}°")))
        .collect();
    println!("{:<32}{header}", "instance");
    let mut row = String::new();
    for (k, ((i, _), r)) in jobs.iter().zip(results).enumerate() {
        if k == 0 || jobs[k - 1].0 != *i {
            if !row.is_empty() {
                println!("{row}");
            }
            row = format!("{:<32}", all[*i].name);
        }
        row += &format!("{:>20}", cell(r));
    }
    println!("{row}");
}

/// Fails, naming `name`, with the count `what` describes and the first `shown` of `bad`,
/// unless `bad` is empty.
fn assert_none(name: &str, bad: &[String], what: &str, shown: usize) {
    assert!(
        bad.is_empty(),
        "{name}: {} {what}, e.g.\n{}",
        bad.len(),
        bad[..bad.len().min(shown)].join("\n")
    );
}

#[test]
fn sample_returns_eval_and_pdf() {
    let all = instances();
    let failures = par_map(&all, |t| {
        let mut rng = Sampler::from_seed(seed(3, &t.name, 0.0, 0.0));
        let mut bad = Vec::new();
        let mut checked = 0;
        for _ in 0..20_000 {
            let wo = wo_at((rng.next_1d() * 2.0 - 1.0).asin().to_degrees());
            let h = 2.0 * rng.next_1d() - 1.0;
            let Some(s) = t.bcsdf.sample(wo, h, rng.next_4d()) else {
                continue;
            };
            // Along the fiber axis φ_i is undefined and f32 rounding of wi moves it freely.
            if s.wi.x.abs() > 0.9999 {
                continue;
            }
            checked += 1;
            let f = t.bcsdf.eval(wo, s.wi, h);
            let pdf = t.bcsdf.pdf(wo, s.wi, h);
            let f_err = (s.f - f).abs().max_element() / f.max_element().max(1e-30);
            let pdf_err = (s.pdf - pdf).abs() / pdf.max(1e-30);
            if f_err > 1e-3 || pdf_err > 1e-3 {
                bad.push(format!(
                    "wo {wo} h {h} wi {}: sample (f {}, pdf {}) vs eval {f}, pdf {pdf}",
                    s.wi, s.f, s.pdf
                ));
            }
        }
        (checked, bad)
    });
    for (t, (checked, bad)) in all.iter().zip(&failures) {
        println!("{:<32} {checked} samples checked", t.name);
        assert!(*checked > 10_000, "{}: too few samples", t.name);
        let what = format!("of {checked} samples disagree with eval/pdf");
        assert_none(&t.name, bad, &what, 5);
    }
}

/// (θ_o in degrees, h) at which the integral tests compare two estimators.
const CONFIGS: [(f32, f32); 3] = [(-40.0, 0.6), (10.0, -0.3), (70.0, 0.9)];

/// (instance, index into `CONFIGS`) for every instance and configuration.
fn config_jobs(all: &[Instance]) -> Vec<(usize, usize)> {
    (0..all.len())
        .flat_map(|i| (0..CONFIGS.len()).map(move |c| (i, c)))
        .collect()
}

/// `sample_weight` draws the direction `sample` draws from the same numbers, and its weight has
/// the expectation of `f / pdf` in every channel: over one set of draws the mean of the two
/// weights' difference is zero within 5 standard errors and rounding (paired: the difference's
/// noise is only how far the two weights spread apart, so a bias of a few tenths of a percent
/// shows).
#[test]
fn sample_weight_draws_samples_direction_with_the_same_mean() {
    const DRAWS: usize = 100_000;
    let all = instances();
    let jobs = config_jobs(&all);
    let results = par_map(&jobs, |&(i, c)| {
        let (th, h) = CONFIGS[c];
        let b = &all[i].bcsdf;
        let wo = wo_at(th);
        let mut mismatches = Vec::new();
        let mut weight_sum = [0.0f64; 3];
        let difference = mc_mean(DRAWS, seed(11, &all[i].name, th, h), |rng| {
            let u = rng.next_4d();
            let sampled = b.sample(wo, h, u).filter(|s| s.pdf > 0.0);
            let weighted = b.sample_weight(wo, h, u);
            match (sampled, weighted) {
                (Some(s), Some((wi, weight))) if s.wi == wi => {
                    for (sum, w) in weight_sum.iter_mut().zip([weight.x, weight.y, weight.z]) {
                        *sum += w as f64;
                    }
                    weight - s.f / s.pdf
                }
                (None, None) => Rgb::ZERO,
                (s, w) => {
                    mismatches.push(format!(
                        "u {u:?}: sample gives {:?}, sample_weight {w:?}",
                        s.map(|s| s.wi)
                    ));
                    Rgb::ZERO
                }
            }
        });
        (difference, weight_sum.map(|s| s / DRAWS as f64), mismatches)
    });
    let mut failures = Vec::new();
    for ((i, c), (difference, mean_weight, mismatches)) in jobs.iter().zip(&results) {
        let (th, h) = CONFIGS[*c];
        let name = &all[*i].name;
        println!(
            "{name:<32} θ_o={th:>5}° h={h:>4}: mean weight {:.5}, mean difference {:.2e} ± {:.2e}",
            mean_weight[0], difference.mean[0], difference.se[0]
        );
        assert_none(
            name,
            mismatches,
            "draws differ between sample and sample_weight",
            3,
        );
        for (k, weight) in mean_weight.iter().enumerate() {
            let (mean, se) = (difference.mean[k], difference.se[k]);
            // A floor of 10⁻⁶ relative: f/pdf rounds where the lobe weight is exact.
            if mean.abs() > 5.0 * se + 1e-6 * weight {
                failures.push(format!(
                    "{name} θ_o {th}° h {h} channel {k}: sample_weight's mean {weight:.6} \
                     differs from f/pdf's by {mean:.2e} ± {se:.2e} (more than 5 s.e.)"
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A smooth positive radiance in the fiber frame.
fn test_radiance(w: Vec3) -> f32 {
    1.0 + w.z * w.z + 0.5 * w.x
}

#[test]
fn importance_and_uniform_estimates_agree() {
    let all = instances();
    let jobs = config_jobs(&all);
    let est = par_map(&jobs, |&(i, c)| {
        let (th, h) = CONFIGS[c];
        let b = &all[i].bcsdf;
        let wo = wo_at(th);
        // Each estimator's relative s.e. is brought below 0.17 %, so that the combined one is
        // below 0.25 % and a 1 % difference is a 4σ event.
        let uniform = refine(0.0017, |level| {
            let k = 1 << level;
            let mut rng = Sampler::from_seed(seed(4, &all[i].name, th, h + level as f32));
            stratified_mean([400 * k, 400 * k], &mut rng, |u| {
                let wi = sphere_point(u[0], u[1]);
                b.eval(wo, wi, h) * (test_radiance(wi) * 2.0 * TAU)
            })
        });
        let sampled = refine(0.0017, |level| {
            let n = 300_000 << (2 * level);
            mc_mean(n, seed(5, &all[i].name, th, h + level as f32), |rng| {
                b.sample_weight(wo, h, rng.next_4d())
                    .map_or(Rgb::ZERO, |(wi, weight)| weight * test_radiance(wi))
            })
        });
        (uniform, sampled)
    });
    println!(
        "\n∫ eval·L dω, L = 1 + ω_z² + ω_x/2: uniform (stratified, 3.2·10⁵·4ᴸ samples) vs \
         importance sampled (3·10⁵·4ᴸ), channel 0"
    );
    let mut failures = Vec::new();
    for ((i, c), ((u, lu), (s, ls))) in jobs.iter().zip(&est) {
        let (th, h) = CONFIGS[*c];
        println!(
            "{:<32} θ_o={th:>5}° h={h:>4}: uniform {} L{lu}  sampled {} L{ls}",
            all[*i].name,
            u.fmt(0),
            s.fmt(0)
        );
        for k in 0..3 {
            let reference = u.mean[k];
            let sigma = (u.se[k].powi(2) + s.se[k].powi(2)).sqrt() / reference;
            let diff = (s.mean[k] - reference) / reference;
            if sigma >= 0.0025 || diff.abs() >= 0.01 {
                failures.push(format!(
                    "{} θ_o {th}° h {h} channel {k}: uniform {} sampled {}: relative difference \
                     {diff:.4}, combined relative s.e. {sigma:.4} (must be < 0.01 and < 0.0025)",
                    all[*i].name,
                    u.fmt(k),
                    s.fmt(k)
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

const CHI2_THETAS: [f32; 4] = [-60.0, 0.0, 30.0, 75.0];
const CHI2_HS: [f32; 3] = [-0.8, 0.1, 0.9];

/// Every (θ_o, h) of the χ² grid.
fn chi2_grid() -> Vec<(f32, f32)> {
    CHI2_THETAS
        .into_iter()
        .flat_map(|th| CHI2_HS.map(|h| (th, h)))
        .collect()
}

/// χ² on four (θ_o, h) of the grid (every θ_o, every h); the whole grid is
/// `sampler_matches_pdf_chi2_full_grid` (ignored: ~3× the time).
#[test]
fn sampler_matches_pdf_chi2() {
    chi2_suite(&[(-60.0, -0.8), (0.0, 0.1), (30.0, 0.9), (75.0, -0.8)]);
}

#[test]
#[ignore]
fn sampler_matches_pdf_chi2_full_grid() {
    chi2_suite(&chi2_grid());
}

/// χ² test of `sample` against `pdf` for every instance at each of `configs`, at family level
/// 0.01 (Šidák over all tests of the run). Failing histograms are written to the temp directory.
fn chi2_suite(configs: &[(f32, f32)]) {
    let all = instances();
    let jobs: Vec<(usize, f32, f32)> = (0..all.len())
        .flat_map(|i| configs.iter().map(move |&(th, h)| (i, th, h)))
        .collect();
    // 4×4 sub-cells per cell are not enough for the sharpest test lobes (β = 0.1, std ≈ 0.04 rad
    // ≈ one sub-cell): their midpoint error shows up as p ≈ 1e-13 at 10⁶ samples; 8×8 is not.
    let chi2 = SphereChi2 {
        pole: Vec3::X,
        res_cos: 50,
        res_phi: 100,
        sub: 8,
        samples: 1_000_000,
        min_expected: 5.0,
    };
    let runs: Vec<(Chi2Outcome, Vec<f64>, Vec<f64>)> = par_map(&jobs, |&(i, th, h)| {
        let b = &all[i].bcsdf;
        let wo = wo_at(th);
        chi2.run(
            seed(6, &all[i].name, th, h),
            |rng| b.sample(wo, h, rng.next_4d()).map(|s| s.wi),
            |wi| b.pdf(wo, wi, h) as f64,
        )
    });
    let alpha = sidak_alpha(0.01, jobs.len());
    println!(
        "\nχ² of sample vs pdf: p-values ({} tests, Šidák per-test level {alpha:.2e})",
        jobs.len()
    );
    let header: String = configs
        .iter()
        .map(|(t, h)| format!("{:>10}", format!("{t}°/{h}")))
        .collect();
    println!("{:<32}{header}", "instance θ_o/h");
    for (i, t) in all.iter().enumerate() {
        let row: String = jobs
            .iter()
            .zip(&runs)
            .filter(|((j, _, _), _)| *j == i)
            .map(|(_, (o, _, _))| format!("{:>10.3e}", o.p_value))
            .collect();
        println!("{:<32}{row}", t.name);
    }
    let mut failures = Vec::new();
    for ((i, th, h), (o, observed, expected)) in jobs.iter().zip(&runs) {
        if o.p_value >= alpha {
            continue;
        }
        let name = &all[*i].name;
        let path = std::env::temp_dir().join(format!(
            "tress-chi2-{}-theta{th}-h{h}.tsv",
            name.replace('/', "_")
        ));
        let mut text = format!(
            "# {name} θ_o {th}° h {h}: {o:?}\n# rows: cos-to-x bins ({}), columns: φ bins ({}); \
             observed block, then expected block\n",
            chi2.res_cos, chi2.res_phi
        );
        for grid in [observed, expected] {
            for row in grid.chunks(chi2.res_phi) {
                let line: Vec<String> = row.iter().map(|x| format!("{x:.2}")).collect();
                text += &line.join("\t");
                text.push('\n');
            }
        }
        let written = std::fs::write(&path, text).map_or_else(
            |e| format!("(histograms not written: {e})"),
            |_| format!("histograms in {}", path.display()),
        );
        failures.push(format!(
            "{name} θ_o {th}° h {h}: χ² = {:.1} (dof {}), p = {:.3e} < {alpha:.2e}, \
             {} samples in zero-pdf cells; {written}",
            o.statistic, o.dof, o.p_value, o.samples_in_empty_cells
        ));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn pdf_integrates_to_one() {
    let all = instances();
    let grid = chi2_grid();
    let jobs: Vec<(usize, f32, f32)> = (0..all.len())
        .flat_map(|i| grid.iter().map(move |&(th, h)| (i, th, h)))
        .collect();
    // Midpoint rule on 256 × 512 equal-area cells (Δ sin θ = 0.0078, Δφ = 0.012): several nodes
    // per standard deviation of the sharpest test lobes.
    let (nc, np) = (256usize, 512usize);
    let integrals = par_map(&jobs, |&(i, th, h)| {
        let b = &all[i].bcsdf;
        let wo = wo_at(th);
        let mut sum = 0.0f64;
        for a in 0..nc {
            for c in 0..np {
                let wi = sphere_point((a as f32 + 0.5) / nc as f32, (c as f32 + 0.5) / np as f32);
                sum += b.pdf(wo, wi, h) as f64;
            }
        }
        sum * 4.0 * std::f64::consts::PI / (nc * np) as f64
    });
    println!("\n∫ pdf dω: min and max over θ_o ∈ {CHI2_THETAS:?}, h ∈ {CHI2_HS:?}");
    for (i, t) in all.iter().enumerate() {
        let mine: Vec<f64> = jobs
            .iter()
            .zip(&integrals)
            .filter(|((j, _, _), _)| *j == i)
            .map(|(_, v)| *v)
            .collect();
        let lo = mine.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = mine.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        println!("{:<32} {lo:.5} … {hi:.5}", t.name);
    }
    for ((i, th, h), v) in jobs.iter().zip(&integrals) {
        assert!(
            (v - 1.0).abs() < 0.01,
            "{} θ_o {th}° h {h}: ∫ pdf = {v}",
            all[*i].name
        );
    }
}

#[test]
fn outputs_are_finite_and_non_negative() {
    let all = instances();
    let problems = par_map(&all, |t| {
        let b = t.bcsdf.as_ref();
        let mut bad = Vec::new();
        // Edges: h at and next to ±1, directions at and next to the fiber axis, extreme u.
        let hs = [-1.0, -0.999_999, 0.0, 0.999_999, 1.0];
        let sins = [-1.0, -0.999_99, -0.5, 0.0, 0.5, 0.999_99, 1.0];
        let us = [
            [0.0; 4],
            [0.999_999_9; 4],
            [0.5, 0.0, 0.999_999_9, 0.0],
            [0.3, 0.999_999_9, 0.0, 0.7],
        ];
        for &h in &hs {
            for &so in &sins {
                let wo = fiber_direction(so, safe_sqrt(1.0 - so * so), FRAC_PI_2);
                for &si in &sins {
                    for phi in [0.0, 1.0, 3.0, -2.0] {
                        let wi = fiber_direction(si, safe_sqrt(1.0 - si * si), phi);
                        for u in us {
                            check_finite(b, wo, wi, h, u, &mut bad);
                        }
                    }
                }
            }
        }
        // Random sweep over arbitrary directions (wo not necessarily in the y = 0 half-plane).
        let mut rng = Sampler::from_seed(seed(7, &t.name, 0.0, 0.0));
        for _ in 0..100_000 {
            let wo = sample_uniform_sphere(rng.next_2d());
            let wi = sample_uniform_sphere(rng.next_2d());
            let h = 2.0 * rng.next_1d() - 1.0;
            check_finite(b, wo, wi, h, rng.next_4d(), &mut bad);
        }
        bad
    });
    for (t, bad) in all.iter().zip(&problems) {
        assert_none(&t.name, bad, "problems", 10);
    }
}

/// Outgoing directions along the fiber with a tiny sideways part, of every size down to the
/// smallest subnormal and in every sideways direction, across h: every output is finite, and
/// `sample`'s f and pdf are `eval_pdf`'s at its wi (the azimuth of such a wo is as much a
/// reference for `pdf` as for `sample`). Along the axis itself φ_o is undefined.
#[test]
fn outputs_are_finite_along_the_fiber() {
    // Down to where y² + z² loses its precision (~1e-19) and vanishes (~3e-23), and beyond.
    let sideways = [
        1e-4,
        1e-8,
        1e-19,
        1e-22,
        3e-23,
        1e-30,
        1e-40,
        f32::from_bits(1),
    ];
    let mut wos = Vec::new();
    for x in [1.0f32, -1.0] {
        for a in sideways.into_iter().chain([0.0]) {
            for c in sideways {
                for (sa, sc) in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)] {
                    wos.push(Vec3::new(x, sa * a, sc * c));
                    wos.push(Vec3::new(x, sc * c, sa * a));
                }
            }
        }
    }
    let all = instances();
    let problems = par_map(&all, |t| {
        let b = t.bcsdf.as_ref();
        let mut bad = Vec::new();
        let mut rng = Sampler::from_seed(seed(8, &t.name, 0.0, 0.0));
        for &wo in &wos {
            for h in [-1.0, -0.999_999, -0.4, 0.0, 0.7, 0.999_999, 1.0] {
                for _ in 0..3 {
                    let u = rng.next_4d();
                    let wi = sample_uniform_sphere(rng.next_2d());
                    check_finite(b, wo, wi, h, u, &mut bad);
                    let Some(s) = b.sample(wo, h, u) else {
                        continue;
                    };
                    // As in `sample_returns_eval_and_pdf`: near the axis φ_i is undefined.
                    if s.wi.x.abs() > 0.9999 {
                        continue;
                    }
                    let (f, pdf) = b.eval_pdf(wo, s.wi, h);
                    let f_err = (s.f - f).abs().max_element() / f.max_element().max(1e-30);
                    let pdf_err = (s.pdf - pdf).abs() / pdf.max(1e-30);
                    if f_err > 1e-3 || pdf_err > 1e-3 {
                        bad.push(format!(
                            "wo {wo:?} h {h} wi {}: sample (f {}, pdf {}) vs eval {f}, pdf {pdf}",
                            s.wi, s.f, s.pdf
                        ));
                    }
                }
            }
        }
        bad
    });
    for (t, bad) in all.iter().zip(&problems) {
        assert_none(&t.name, bad, "problems", 10);
    }
}

/// Pushes onto `bad` every output of `b` at (wo, wi, h, u) that is not finite, not
/// non-negative, or (directions) not of unit length.
fn check_finite(b: &dyn Bcsdf, wo: Vec3, wi: Vec3, h: f32, u: [f32; 4], bad: &mut Vec<String>) {
    let unit = |w: Vec3| w.is_finite() && (w.length() - 1.0).abs() < 1e-3;
    let (f_both, pdf_both) = b.eval_pdf(wo, wi, h);
    for (what, f, pdf) in [
        ("eval, pdf", b.eval(wo, wi, h), b.pdf(wo, wi, h)),
        ("eval_pdf", f_both, pdf_both),
    ] {
        if !(f.is_finite() && f.min_element() >= 0.0 && pdf.is_finite() && pdf >= 0.0) {
            bad.push(format!("{what}(wo {wo:?}, wi {wi:?}, h {h}) = {f}, {pdf}"));
        }
    }
    if let Some(s) = b.sample(wo, h, u) {
        let ok = unit(s.wi)
            && s.f.is_finite()
            && s.f.min_element() >= 0.0
            && s.pdf.is_finite()
            && s.pdf > 0.0;
        if !ok {
            bad.push(format!("sample(wo {wo:?}, h {h}, u {u:?}) = {s:?}"));
        }
    }
    if let Some((wi, weight)) = b.sample_weight(wo, h, u) {
        if !(unit(wi) && weight.is_finite() && weight.min_element() >= 0.0) {
            bad.push(format!(
                "sample_weight(wo {wo:?}, h {h}, u {u:?}) = ({wi:?}, {weight})"
            ));
        }
    }
}

/// Cost of eval, pdf and sample per registered instance (not an assertion):
/// `cargo test --release -p tress-materials --test integration -- --ignored --nocapture eval_cost`.
#[test]
#[ignore]
fn eval_cost() {
    use std::hint::black_box;
    use std::time::Instant;
    let n = 200_000;
    let mut rng = Sampler::from_seed(7000);
    /// (wo, wi, h, u) of one call.
    type Input = (Vec3, Vec3, f32, [f32; 4]);
    let inputs: Vec<Input> = (0..n)
        .map(|_| {
            let wo = wo_at((rng.next_1d() * 2.0 - 1.0).asin().to_degrees());
            (
                wo,
                sample_uniform_sphere(rng.next_2d()),
                2.0 * rng.next_1d() - 1.0,
                rng.next_4d(),
            )
        })
        .collect();
    println!(
        "\n{:<32}{:>12}{:>12}{:>12}",
        "instance", "eval ns", "pdf ns", "sample ns"
    );
    for t in instances() {
        let b = &t.bcsdf;
        // The fastest of five passes: other processes only ever add time.
        let time = |f: &dyn Fn(&Input)| {
            (0..5)
                .map(|_| {
                    let start = Instant::now();
                    for x in &inputs {
                        f(black_box(x));
                    }
                    start.elapsed().as_nanos() as f64 / n as f64
                })
                .fold(f64::INFINITY, f64::min)
        };
        let e = time(&|&(wo, wi, h, _)| {
            black_box(b.eval(wo, wi, h));
        });
        let p = time(&|&(wo, wi, h, _)| {
            black_box(b.pdf(wo, wi, h));
        });
        let s = time(&|&(wo, _, h, u)| {
            black_box(b.sample(wo, h, u));
        });
        println!("{:<32}{e:>12.1}{p:>12.1}{s:>12.1}", t.name);
    }
}

/// The fused `eval_pdf` is `(eval, pdf)` for every model (bit for bit: the integrators may use
/// either).
#[test]
fn eval_pdf_is_eval_and_pdf() {
    let mut rng = tress_core::Sampler::from_seed(78);
    for inst in HairModel::test_instances() {
        let b = inst.params.build(prep()).unwrap();
        for _ in 0..500 {
            let wo = tress_core::sampling::sample_uniform_sphere(rng.next_2d());
            let wi = tress_core::sampling::sample_uniform_sphere(rng.next_2d());
            let h = 2.0 * rng.next_1d() - 1.0;
            assert_eq!(
                b.eval_pdf(wo, wi, h),
                (b.eval(wo, wi, h), b.pdf(wo, wi, h)),
                "{} at wo {wo}, wi {wi}, h {h}",
                inst.name
            );
        }
    }
}

/// Every model's lobes (`eval_lobe`) sum to `eval`: the per-lobe plots and dual-scattering
/// tables rely on it.
#[test]
fn lobes_sum_to_eval() {
    let mut rng = tress_core::Sampler::from_seed(77);
    for inst in HairModel::test_instances() {
        let b = inst.params.build(prep()).unwrap();
        let lobes = b.lobe_names().len();
        for _ in 0..500 {
            let wo = tress_core::sampling::sample_uniform_sphere(rng.next_2d());
            let wi = tress_core::sampling::sample_uniform_sphere(rng.next_2d());
            let h = 2.0 * rng.next_1d() - 1.0;
            let total = b.eval(wo, wi, h);
            let sum: tress_core::Rgb = (0..lobes).map(|p| b.eval_lobe(wo, wi, h, p)).sum();
            assert!(
                (total - sum)
                    .abs()
                    .cmple(1e-4 * total.abs() + tress_core::Rgb::splat(1e-6))
                    .all(),
                "{}: eval {total} vs Σ lobes {sum}",
                inst.name
            );
            assert_eq!(
                b.eval_lobe(wo, wi, h, lobes),
                tress_core::Rgb::ZERO,
                "{}",
                inst.name
            );
        }
    }
}
