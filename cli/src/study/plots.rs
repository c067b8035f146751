//! The study's figures: plots of the convergence curves, error heat maps and crop sheets.

use crate::plot::{self, Chart, HeatPanel, Series};
use anyhow::Result;
use tress_study::metrics::MapKind;
use tress_study::picture::Picture;
use tress_study::{
    curve, sheet_regions, FigureFiles, Figures, FiguresError, Plan, Point, RefKind, Results, Stat,
};

/// Draws the figures with plotters.
pub(super) struct Plots;

impl Figures for Plots {
    fn draw(
        &self,
        plan: &Plan,
        results: &Results,
        scene: usize,
    ) -> Result<FigureFiles, FiguresError> {
        let plots = write_plots(plan, results, scene)?;
        let (heat_map, scale, sheets) = write_figures(plan, results, scene)?;
        Ok(FigureFiles {
            plots,
            heat_map,
            heat_scale: (scale.lo, scale.hi),
            sheets,
        })
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
        band: None,
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
        band_label: None,
    }
}

/// Per-integrator series of the mean `y(point)` against spp or time, shaded with its 95 %
/// confidence interval when there are repetitions.
fn series_of(
    plan: &Plan,
    curves: &[Vec<Point>],
    x: impl Fn(&Point) -> f64,
    y: impl Fn(&Point) -> Stat,
) -> Vec<Series> {
    plan.integrators
        .iter()
        .zip(curves)
        .map(|(i, c)| Series {
            name: i.label.clone(),
            points: c.iter().map(|p| (x(p), y(p).mean)).collect(),
            band: c
                .iter()
                .map(|p| y(p).ci.map(|ci| (y(p).mean - ci, y(p).mean + ci)))
                .collect(),
            reference: false,
        })
        .collect()
}

/// MSE·spp: flat for 1/N convergence.
fn mse_x_spp(p: &Point) -> Stat {
    let spp = p.spp as f64;
    Stat {
        mean: p.mse.mean * spp,
        ci: p.mse.ci.map(|ci| ci * spp),
    }
}

const PANEL_W: u32 = 430;
const PANEL_H: u32 = 360;

/// Convergence charts of one scene; returns the files written (stems relative to the output).
fn write_plots(plan: &Plan, res: &Results, si: usize) -> Result<Vec<String>> {
    let scene = &plan.scenes[si];
    let mut written = Vec::new();
    let spp_x = |p: &Point| p.spp as f64;
    let time_x = |p: &Point| p.time_s;
    let band_label = format!("95 % CI, {} repetitions", plan.reps);
    let mut plot = |stem: String, mut charts: Vec<Chart>| -> Result<()> {
        for c in &mut charts {
            c.band_label = Some(band_label.clone());
        }
        plot::write_charts(
            &plan.out.join(&stem),
            &plan.inputs,
            &charts,
            PANEL_W,
            PANEL_H,
        )?;
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
                series_of(plan, &common, spp_x, |p| p.mse),
                Some("1/N"),
            ),
            chart(
                format!("{name}: relMSE vs spp"),
                "samples per pixel",
                "relMSE",
                series_of(plan, &common, spp_x, |p| p.relmse),
                Some("1/N"),
            ),
            chart(
                format!("{name}: relMSE vs CPU time"),
                "render CPU time (s)",
                "relMSE",
                series_of(plan, &common, time_x, |p| p.relmse),
                Some("1/t"),
            ),
            chart(
                format!("{name}: MSE·spp (flat = 1/N)"),
                "samples per pixel",
                "MSE × spp",
                series_of(plan, &common, spp_x, mse_x_spp),
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
                    series_of(plan, &own, spp_x, |p| p.relmse),
                    Some("1/N"),
                ),
                chart(
                    format!("{name}: MSE·spp, own reference"),
                    "samples per pixel",
                    "MSE × spp",
                    series_of(plan, &own, spp_x, mse_x_spp),
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
                    series_of(plan, &c, spp_x, |p| p.relmse),
                    Some("1/N"),
                ),
                chart(
                    format!("{name}/{region}: relMSE vs CPU time"),
                    "render CPU time (s)",
                    "relMSE",
                    series_of(plan, &c, time_x, |p| p.relmse),
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
        &plan.inputs,
        &panels,
        scale,
        MapKind::Rel.label(),
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
            &plan.inputs,
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
