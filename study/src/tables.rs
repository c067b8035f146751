//! Outputs: `results.csv`, `summary.csv` and `report.md`.

use crate::error::Result;
use crate::figures::FigureFiles;
use crate::metrics::REL_EPSILON;
use crate::plan::{Plan, PlanReference};
use crate::results::{RefKind, Results};
use crate::stats::{curve, extrapolated_reach, loglog_at, reach, verdict, Point, Reach, Stat};
use std::fmt::Write as _;
use std::path::PathBuf;
use tress_core::output_file;

const RESULTS_CSV: &str = "results.csv";
const SUMMARY_CSV: &str = "summary.csv";
const REPORT: &str = "report.md";

/// Refuses, before any render, tables that could not be written ([`output_file::check`]: a
/// directory in the way, one of the study's inputs).
pub(super) fn check_outputs(plan: &Plan) -> Result<()> {
    for name in [RESULTS_CSV, SUMMARY_CSV, REPORT] {
        output_file::check(&plan.out.join(name), &plan.inputs)?;
    }
    Ok(())
}

pub(super) fn write_csv(plan: &Plan, res: &Results) -> Result<PathBuf> {
    let mut s = String::from(
        "scene,integrator,spp,rep,seed,cpu_s,wall_s,precompute_s,rays,reference,mse,relmse,mean,\
         ref_mean",
    );
    for r in &plan.region_names {
        let _ = write!(s, ",{r}_mse,{r}_relmse,{r}_mean");
    }
    s.push('\n');
    for r in &res.rows {
        let e = &r.whole;
        let _ = write!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            plan.scenes[r.scene].name,
            plan.integrators[r.integrator].label,
            r.spp,
            r.rep,
            r.seed,
            r.time_s,
            r.wall_s,
            r.precompute_s,
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
    let path = plan.out.join(RESULTS_CSV);
    output_file::write_bytes(&path, &plan.inputs, s.as_bytes())?;
    Ok(path)
}

pub(super) fn fmt_stat(s: Stat) -> String {
    match s.ci {
        Some(ci) => format!("{:.3e} ± {:.1e}", s.mean, ci),
        None => format!("{:.3e}", s.mean),
    }
}

/// The MSE·spp of the reference's own integrator at the smallest spp over the reference spp:
/// the reference noise in every MSE, when the reference integrator is one of the study's.
pub(super) fn common_noise(plan: &Plan, res: &Results, si: usize) -> Option<f64> {
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

pub(super) fn own_noise(plan: &Plan, res: &Results, si: usize, i: usize) -> Option<f64> {
    let spp = plan.own_spp?;
    let c = curve(res, plan, si, i, RefKind::Own, None);
    let p = c.first()?;
    Some(p.mse.mean * p.spp as f64 / spp as f64)
}

pub(super) fn table_header(s: &mut String, cols: &[&str]) {
    let _ = writeln!(s, "| {} |", cols.join(" | "));
    let _ = writeln!(s, "|{}", "---|".repeat(cols.len()));
}

pub(super) fn error_table(s: &mut String, plan: &Plan, curves: &[Vec<Point>]) {
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

/// Time to the target relMSE against each integrator's own reference — its noise alone, the
/// cost of converging whatever it converges to — and the baseline's time ÷ each one's (above
/// 1: sooner than the baseline). A curve that stops short is extrapolated at 1/N from its
/// highest spp, and says so.
pub(super) fn own_reach_table(s: &mut String, plan: &Plan, own: &[Vec<Point>]) {
    let target = plan.target_relmse;
    let _ = writeln!(
        s,
        "\n### Time to relMSE = {target:.1e} against each integrator's own reference\n"
    );
    let times: Vec<Option<(f64, f64, bool)>> = own
        .iter()
        .map(|c| match reach(c, target) {
            Reach::AtOnce(spp, t) => Some((spp as f64, t, false)),
            Reach::At(spp, t) => Some((spp, t, false)),
            Reach::Never(_) => extrapolated_reach(c, target).map(|(spp, t)| (spp, t, true)),
        })
        .collect();
    let base = plan.integrators[0].label.as_str();
    table_header(
        s,
        &[
            "integrator",
            "spp",
            "CPU time (s)",
            &format!("`{base}`'s time ÷ this"),
        ],
    );
    for ((i, c), t) in plan.integrators.iter().zip(own).zip(&times) {
        let Some((spp, time, extrapolated)) = *t else {
            let _ = writeln!(s, "| {} | not reached | | |", i.label);
            continue;
        };
        let ratio = match times[0] {
            Some((_, base_time, base_extrapolated)) => format!(
                "{}{:.2}",
                if extrapolated || base_extrapolated {
                    "≈ "
                } else {
                    ""
                },
                base_time / time
            ),
            None => String::new(),
        };
        let how = match c.last() {
            Some(last) if extrapolated => {
                format!(" (extrapolated at 1/N from {} spp)", last.spp)
            }
            _ => String::new(),
        };
        let _ = writeln!(s, "| {} | {spp:.1}{how} | {time:.4} | {ratio} |", i.label);
    }
}

/// `summary.csv`: the report's numbers per (scene, integrator, spp, reference).
pub(super) fn write_summary(plan: &Plan, res: &Results) -> Result<PathBuf> {
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
    let path = plan.out.join(SUMMARY_CSV);
    output_file::write_bytes(&path, &plan.inputs, s.as_bytes())?;
    Ok(path)
}

/// MSE of `other` over MSE of `base` at each of `base`'s spp settings.
pub(super) fn ratios_at_equal_spp(base: &[Point], other: &[Point]) -> Vec<f64> {
    base.iter()
        .zip(other)
        .map(|(b, o)| o.mse.mean / b.mse.mean)
        .collect()
}

/// MSE of `other` (interpolated log-log in time) over MSE of `base` at each of `base`'s
/// times; `None` outside `other`'s time range.
pub(super) fn ratios_at_equal_time(base: &[Point], other: &[Point]) -> Vec<Option<f64>> {
    let pts: Vec<(f64, f64)> = other.iter().map(|p| (p.time_s, p.mse.mean)).collect();
    base.iter()
        .map(|b| loglog_at(&pts, b.time_s).map(|m| m / b.mse.mean))
        .collect()
}

/// "min–max (geometric mean g)" of positive finite values, or "–" when there are none.
pub(super) fn ratio_range(values: impl IntoIterator<Item = f64>) -> String {
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
pub(super) fn summary_section(s: &mut String, plan: &Plan, res: &Results) {
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

/// `report.md`, with the figures of each scene when they were drawn.
pub(super) fn write_report(
    plan: &Plan,
    res: &Results,
    figures: Option<&[FigureFiles]>,
) -> Result<PathBuf> {
    let mut s = String::new();
    settings_section(&mut s, plan, res);
    if figures.is_none() {
        let _ = writeln!(
            s,
            "No figures: this run drew none. `{}` (with `--out {}`) draws the plots, heat maps \
             and crop sheets, reading these renders back.\n",
            plan.command,
            plan.out.display()
        );
    }
    if plan.integrators.len() > 1 {
        summary_section(&mut s, plan, res);
    }
    for si in 0..plan.scenes.len() {
        scene_section(&mut s, plan, res, si, figures.map(|f| &f[si]));
    }
    let path = plan.out.join(REPORT);
    output_file::write_bytes(&path, &plan.inputs, s.as_bytes())?;
    Ok(path)
}

/// The title, the settings and the definitions of the metrics.
fn settings_section(s: &mut String, plan: &Plan, res: &Results) {
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
    for (ii, i) in plan.integrators.iter().enumerate() {
        let _ = write!(s, "- integrator `{}`: `{}`", i.label, i.ron);
        // A per-film precomputation (a radiance cache) is part of every render's time; say
        // how much.
        let precompute: Vec<f64> = res
            .rows
            .iter()
            .filter(|r| r.integrator == ii && r.reference == RefKind::Common)
            .map(|r| r.precompute_s)
            .collect();
        let longest = precompute.iter().copied().fold(0.0, f64::max);
        if longest > 0.0 {
            let shortest = precompute.iter().copied().fold(f64::INFINITY, f64::min);
            let _ = write!(
                s,
                "; its per-film precomputation took {shortest:.3}–{longest:.3} s of wall time \
                 per render, included in its render times"
            );
        }
        s.push('\n');
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
}

/// One scene's section: its plots, tables, verdicts and figures.
fn scene_section(s: &mut String, plan: &Plan, res: &Results, si: usize, out: Option<&FigureFiles>) {
    let sc = &plan.scenes[si];
    let n = plan.integrators.len();
    let _ = writeln!(s, "## Scene `{}`\n", sc.name);
    for p in out.iter().flat_map(|o| &o.plots) {
        let _ = writeln!(s, "![{p}]({p}.png)\n");
    }
    let common: Vec<Vec<Point>> = (0..n)
        .map(|i| curve(res, plan, si, i, RefKind::Common, None))
        .collect();
    let _ = writeln!(s, "### Error against the common reference\n");
    error_table(s, plan, &common);
    let own: Option<Vec<Vec<Point>>> = plan.own_spp.map(|_| {
        (0..n)
            .map(|i| curve(res, plan, si, i, RefKind::Own, None))
            .collect()
    });
    if let Some(own) = &own {
        let _ = writeln!(s, "### Error against each integrator's own reference\n");
        error_table(s, plan, own);
    }
    if n > 1 {
        ratio_tables(s, plan, &common);
    }
    reach_table(s, plan, &common);
    if let Some(own) = &own {
        own_reach_table(s, plan, own);
    }
    verdicts(s, plan, res, si, &common, own.as_deref());
    if !plan.region_names.is_empty() {
        regions_table(s, plan, res, si);
    }
    if let Some(out) = out {
        figures_section(s, plan, out);
    }
}

/// MSE ratios of each integrator over the baseline, at equal spp and at equal time.
fn ratio_tables(s: &mut String, plan: &Plan, common: &[Vec<Point>]) {
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
    table_header(s, &cols);
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
    table_header(s, &cols);
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

/// Time to the target relMSE against the common reference.
fn reach_table(s: &mut String, plan: &Plan, common: &[Vec<Point>]) {
    let _ = writeln!(s, "### Time to relMSE = {:.1e}\n", plan.target_relmse);
    table_header(s, &["integrator", "spp", "CPU time (s)"]);
    for (i, c) in plan.integrators.iter().zip(common) {
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
}

/// The convergence verdicts against the common reference and, when there are, the own ones.
fn verdicts(
    s: &mut String,
    plan: &Plan,
    res: &Results,
    si: usize,
    common: &[Vec<Point>],
    own: Option<&[Vec<Point>]>,
) {
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
}

/// relMSE per region, integrator and spp, against the common reference.
fn regions_table(s: &mut String, plan: &Plan, res: &Results, si: usize) {
    let sc = &plan.scenes[si];
    let _ = writeln!(s, "### Regions: relMSE against the common reference\n");
    let mut cols = vec!["region".to_string(), "integrator".to_string()];
    cols.extend(plan.spp.iter().map(|x| format!("{x} spp")));
    let cols: Vec<&str> = cols.iter().map(String::as_str).collect();
    table_header(s, &cols);
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

/// The heat map and the crop sheets.
fn figures_section(s: &mut String, plan: &Plan, out: &FigureFiles) {
    let _ = writeln!(
        s,
        "### Per-pixel error at {} spp (repetition 0)\n\n![heat map]({})\n\nColour: \
         per-pixel sqrt(mean over RGB of (I − R)² / (R² + {REL_EPSILON})), log scale from \
         {:.2e} (black) to {:.2e} (pale yellow), shared by the panels.\n",
        plan.heatmap_spp, out.heat_map, out.heat_scale.0, out.heat_scale.1
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
