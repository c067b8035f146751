//! Line charts: series on linear or log axes, with optional shaded intervals, in panels side by
//! side; the legend goes under each panel, so it never hides a curve.

use super::canvas::draw_bitmap;
use super::text::{self, Typeset};
use anyhow::{anyhow, bail, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor;
use std::io::Write as _;
use std::path::Path;
use tress_core::output_file::{Batch, Inputs};

/// One curve of a chart.
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Per point, the low and high ends of an interval around it (a confidence interval of a
    /// mean, say), shaded in the series' colour; one pair per point. On a log axis a low end
    /// at or below zero shades down to the bottom of the axis.
    pub band: Option<Vec<(f64, f64)>>,
    /// Drawn thin and grey as a reference line rather than data; it does not set the axes.
    pub reference: bool,
}

/// A 2-D line chart.
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    pub log_x: bool,
    pub log_y: bool,
    /// What the shaded bands are, for the legend (e.g. "95 % CI over 8 repetitions"); required
    /// when a series has a band.
    pub band_label: Option<String>,
}

/// A row of charts drawn side by side into `<stem>.png` and `<stem>.svg`, which may replace
/// none of `inputs`.
pub fn write_charts(
    stem: &Path,
    inputs: &Inputs,
    charts: &[Chart],
    panel_width: u32,
    height: u32,
) -> Result<()> {
    text::face()?;
    if charts.is_empty() {
        bail!("nothing to plot");
    }
    for chart in charts {
        check(chart).map_err(|e| anyhow!("chart '{}': {e}", chart.title))?;
    }
    let size = (panel_width * charts.len() as u32, height);
    let (png, svg) = (stem.with_extension("png"), stem.with_extension("svg"));
    if let Some(dir) = stem.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut svg_text = String::new();
    {
        let root =
            Typeset::vector(SVGBackend::with_string(&mut svg_text, size)).into_drawing_area();
        draw(&root, charts)?;
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e}", svg.display()))?;
    }
    // Both or neither: a PNG left without its SVG looked like a finished plot.
    let mut files = Batch::new(inputs);
    files.add(&png, |out| {
        draw_bitmap(out, size, |root| draw(root, charts))
    })?;
    files.add(&svg, |out| {
        out.write_all(svg_text.as_bytes())
            .with_context(|| format!("writing {}", svg.display()))
    })?;
    Ok(files.commit()?)
}

/// The chart's bands match their series and are labelled.
fn check(chart: &Chart) -> Result<()> {
    let mut banded = false;
    for s in &chart.series {
        if let Some(band) = &s.band {
            if band.len() != s.points.len() {
                bail!(
                    "series '{}' has {} points but {} band intervals",
                    s.name,
                    s.points.len(),
                    band.len()
                );
            }
            banded = true;
        }
    }
    if banded && chart.band_label.is_none() {
        bail!("the shaded bands have no legend label");
    }
    Ok(())
}

pub(super) fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    charts: &[Chart],
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(|e| anyhow!("{e:?}"))?;
    let panels = root.split_evenly((1, charts.len()));
    for (panel, chart) in panels.iter().zip(charts) {
        draw_one(panel, chart).map_err(|e| anyhow!("plotting '{}': {e}", chart.title))?;
    }
    Ok(())
}

/// The span of the finite values (positive ones on a log axis), padded; a fallback when empty.
pub(super) fn range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return if log { (0.1, 1.0) } else { (0.0, 1.0) };
    }
    if log {
        (lo / 1.5, hi * 1.5)
    } else if hi - lo < 1e-12 {
        (lo - 0.5, hi + 0.5)
    } else {
        let pad = 0.05 * (hi - lo);
        (lo - pad, hi + pad)
    }
}

/// How far (a factor, on a log axis) a band may stretch the y axis beyond the curves: intervals
/// of a few noisy repetitions can reach near zero, which would squash every curve to a line.
const BAND_REACH: f64 = 10.0;

/// The y values that set the axis: the data points, and their bands within [`BAND_REACH`].
fn y_extent(chart: &Chart) -> Vec<f64> {
    let data = || chart.series.iter().filter(|s| !s.reference);
    let mut ys: Vec<f64> = data().flat_map(|s| s.points.iter().map(|p| p.1)).collect();
    let (lo, hi) = range(ys.iter().copied(), chart.log_y);
    let (lo, hi) = if chart.log_y {
        (lo / BAND_REACH, hi * BAND_REACH)
    } else {
        let reach = (BAND_REACH - 1.0) * (hi - lo);
        (lo - reach, hi + reach)
    };
    let bands = data().filter_map(|s| s.band.as_ref()).flatten();
    ys.extend(
        bands
            .flat_map(|&(a, b)| [a, b])
            .filter(|v| (lo..=hi).contains(v)),
    );
    ys
}

pub(super) const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

const REFERENCE_GREY: RGBColor = RGBColor(150, 150, 150);
/// Opacity of the shaded bands: overlapping bands of two series stay distinguishable.
const BAND_ALPHA: f64 = 0.2;
/// Series with at most this many points get a marker at each.
const MAX_MARKED: usize = 16;

const LABEL_SIZE: u32 = 13;
const LEGEND_ROW: u32 = 18;
const SWATCH: u32 = 22;

fn series_color(chart: &Chart, i: usize) -> RGBColor {
    if chart.series[i].reference {
        REFERENCE_GREY
    } else {
        // Data series are numbered without the reference lines, so colours do not shift when
        // one is added.
        let k = chart.series[..i].iter().filter(|s| !s.reference).count();
        PALETTE[k % PALETTE.len()]
    }
}

fn line_style(s: &Series, color: RGBColor) -> ShapeStyle {
    ShapeStyle {
        color: color.to_rgba(),
        filled: false,
        stroke_width: if s.reference { 1 } else { 2 },
    }
}

/// One legend entry: a swatch and its text.
struct Entry {
    text: String,
    color: RGBColor,
    line: Option<ShapeStyle>,
    shaded: bool,
    marker: bool,
}

fn legend_entries(chart: &Chart) -> Vec<Entry> {
    let mut entries: Vec<Entry> = chart
        .series
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let color = series_color(chart, i);
            Entry {
                text: s.name.clone(),
                color,
                line: Some(line_style(s, color)),
                shaded: s.band.is_some(),
                marker: !s.reference && s.points.len() <= MAX_MARKED,
            }
        })
        .collect();
    if let (Some(label), true) = (
        &chart.band_label,
        chart.series.iter().any(|s| s.band.is_some()),
    ) {
        entries.push(Entry {
            text: label.clone(),
            color: REFERENCE_GREY,
            line: None,
            shaded: true,
            marker: false,
        });
    }
    entries
}

/// Lays the entries out in rows of at most `width` pixels: each entry's (row, x offset).
fn legend_layout(entries: &[Entry], width: u32) -> Result<Vec<(u32, u32)>> {
    let face = text::face()?;
    let mut at = Vec::with_capacity(entries.len());
    let (mut row, mut x) = (0u32, 0u32);
    for e in entries {
        let w = SWATCH + 6 + face.width(&e.text, LABEL_SIZE as f64);
        if x > 0 && x + w > width {
            row += 1;
            x = 0;
        }
        at.push((row, x));
        x += w + 16;
    }
    Ok(at)
}

fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[Entry],
    layout: &[(u32, u32)],
    left: u32,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let label = ("sans-serif", LABEL_SIZE)
        .into_font()
        .color(&BLACK)
        .pos(text_anchor::Pos::new(
            text_anchor::HPos::Left,
            text_anchor::VPos::Center,
        ));
    for (e, &(row, dx)) in entries.iter().zip(layout) {
        let x = (left + dx) as i32;
        let y = (row * LEGEND_ROW + LEGEND_ROW / 2) as i32;
        if e.shaded {
            area.draw(&Rectangle::new(
                [(x, y - 6), (x + SWATCH as i32, y + 6)],
                e.color.mix(BAND_ALPHA).filled(),
            ))?;
        }
        if let Some(style) = e.line {
            area.draw(&PathElement::new(
                vec![(x, y), (x + SWATCH as i32, y)],
                style,
            ))?;
        }
        if e.marker {
            area.draw(&Circle::new(
                (x + SWATCH as i32 / 2, y),
                3,
                e.color.filled(),
            ))?;
        }
        area.draw_text(&e.text, &label, (x + SWATCH as i32 + 6, y))?;
    }
    Ok(())
}

pub(super) fn draw_one<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    chart: &Chart,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    const MARGIN: u32 = 12;
    const Y_LABEL_AREA: u32 = 70;
    // The legend sits under the chart, aligned with the plotting area.
    let (width, height) = area.dim_in_pixel();
    let entries = legend_entries(chart);
    let layout = legend_layout(
        &entries,
        width.saturating_sub(MARGIN * 2 + Y_LABEL_AREA).max(1),
    )?;
    let rows = layout.iter().map(|l| l.0 + 1).max().unwrap_or(0);
    let legend_h = rows * LEGEND_ROW + MARGIN / 2;
    let (plot_area, legend_area) = area.split_vertically(height.saturating_sub(legend_h));
    draw_legend(&legend_area, &entries, &layout, MARGIN + Y_LABEL_AREA)?;

    let xs = range(
        chart
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0)),
        chart.log_x,
    );
    let ys = range(y_extent(chart).into_iter(), chart.log_y);
    let x_ticks = Ticks::new(xs, chart.log_x);
    let y_ticks = Ticks::new(ys, chart.log_y);
    let mut builder = ChartBuilder::on(&plot_area);
    builder
        .caption(&chart.title, ("sans-serif", 18))
        .margin(MARGIN)
        .x_label_area_size(40)
        .y_label_area_size(Y_LABEL_AREA);
    macro_rules! finish {
        ($ctx:expr) => {{
            let mut ctx = $ctx;
            let fx = |v: &f64| x_ticks.label(*v);
            let fy = |v: &f64| y_ticks.label(*v);
            ctx.configure_mesh()
                .x_desc(chart.x_label.as_str())
                .y_desc(chart.y_label.as_str())
                .x_label_formatter(&fx)
                .y_label_formatter(&fy)
                .bold_line_style(RGBColor(215, 215, 215))
                .light_line_style(RGBColor(244, 244, 244))
                .label_style(("sans-serif", LABEL_SIZE))
                .axis_desc_style(("sans-serif", LABEL_SIZE + 1))
                .draw()?;
            let on_axes = |p: &(f64, f64)| {
                p.0.is_finite()
                    && p.1.is_finite()
                    && (!chart.log_y || p.1 > 0.0)
                    && (!chart.log_x || p.0 > 0.0)
            };
            // Bands first, so every line stays on top of every band.
            for (i, s) in chart.series.iter().enumerate() {
                let Some(band) = &s.band else { continue };
                let color = series_color(chart, i);
                let polygon = band_polygon(&s.points, band, ys, chart.log_x, chart.log_y);
                if polygon.len() >= 3 {
                    ctx.draw_series(std::iter::once(Polygon::new(
                        polygon,
                        color.mix(BAND_ALPHA).filled(),
                    )))?;
                }
            }
            for (i, s) in chart.series.iter().enumerate() {
                let color = series_color(chart, i);
                let mut pts: Vec<(f64, f64)> = s.points.iter().copied().filter(on_axes).collect();
                if s.reference {
                    // Reference lines do not set the axis range, and plotters does not clip, so
                    // clip them here lest they run over the labels.
                    pts = clip_polyline(&pts, xs, ys, chart.log_x, chart.log_y);
                }
                ctx.draw_series(LineSeries::new(pts.clone(), line_style(s, color)))?;
                if !s.reference && s.points.len() <= MAX_MARKED {
                    ctx.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
                }
            }
        }};
    }
    // Log axes get explicit ticks: plotters' own start at the first power of ten in range.
    let log_axis = |r: (f64, f64), t: &Ticks| {
        (r.0..r.1)
            .log_scale()
            .with_key_points(t.labelled.clone())
            .with_light_points(t.minor.clone())
    };
    match (chart.log_x, chart.log_y) {
        (false, false) => finish!(builder.build_cartesian_2d(xs.0..xs.1, ys.0..ys.1)?),
        (true, false) => finish!(builder.build_cartesian_2d(log_axis(xs, &x_ticks), ys.0..ys.1)?),
        (false, true) => finish!(builder.build_cartesian_2d(xs.0..xs.1, log_axis(ys, &y_ticks))?),
        (true, true) => {
            finish!(builder.build_cartesian_2d(log_axis(xs, &x_ticks), log_axis(ys, &y_ticks))?)
        }
    }
    Ok(())
}

/// `v` in axis space: log10 on a log axis.
fn to_axis(v: f64, log: bool) -> f64 {
    if log {
        v.log10()
    } else {
        v
    }
}

/// Back from axis space.
fn from_axis(v: f64, log: bool) -> f64 {
    if log {
        10f64.powf(v)
    } else {
        v
    }
}

/// The outline of a band (upper edge forward, lower edge back), clamped to the y range in axis
/// space (log10 on log axes), where its edges are straight like the drawn lines; points off a
/// log x axis are dropped and low ends at or below zero on a log y axis go to the bottom.
pub(super) fn band_polygon(
    points: &[(f64, f64)],
    band: &[(f64, f64)],
    ys: (f64, f64),
    log_x: bool,
    log_y: bool,
) -> Vec<(f64, f64)> {
    let (y0, y1) = (to_axis(ys.0, log_y), to_axis(ys.1, log_y));
    let mut lower = Vec::new();
    let mut upper = Vec::new();
    for (p, &(lo, hi)) in points.iter().zip(band) {
        if !p.0.is_finite() || (log_x && p.0 <= 0.0) || !(lo.is_finite() && hi.is_finite()) {
            continue;
        }
        let x = to_axis(p.0, log_x);
        let lo = if log_y && lo <= 0.0 {
            y0
        } else {
            to_axis(lo, log_y)
        };
        let hi = if log_y && hi <= 0.0 {
            y0
        } else {
            to_axis(hi, log_y)
        };
        lower.push((x, lo.min(hi)));
        upper.push((x, hi.max(lo)));
    }
    let mut outline = clamp_edge(&upper, y0, y1);
    let mut back = clamp_edge(&lower, y0, y1);
    back.reverse();
    outline.extend(back);
    outline
        .into_iter()
        .map(|(x, y)| (from_axis(x, log_x), from_axis(y, log_y)))
        .collect()
}

/// A polyline clamped to `y0 ≤ y ≤ y1`, with a vertex added wherever it crosses either line,
/// so the clamped polyline is exactly its part inside the slab pressed onto the slab's edges.
fn clamp_edge(pts: &[(f64, f64)], y0: f64, y1: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(pts.len() * 2);
    for (i, &(x, y)) in pts.iter().enumerate() {
        if i > 0 {
            let (px, py) = pts[i - 1];
            let mut cuts: Vec<f64> = [y0, y1]
                .iter()
                .filter(|&&b| (py - b) * (y - b) < 0.0)
                .map(|&b| (b - py) / (y - py))
                .collect();
            cuts.sort_by(f64::total_cmp);
            for t in cuts {
                out.push((px + t * (x - px), (py + t * (y - py)).clamp(y0, y1)));
            }
        }
        out.push((x, y.clamp(y0, y1)));
    }
    out
}

/// The ticks of one axis and how their labels are written.
pub(super) struct Ticks {
    log: bool,
    /// Ticks with a label (on a log axis: also the bold grid lines).
    labelled: Vec<f64>,
    /// Unlabelled grid lines of a log axis.
    minor: Vec<f64>,
    /// Every label of the axis in powers of ten (`2×10⁻³`), or every one as a decimal number.
    scientific: bool,
}

impl Ticks {
    pub(super) fn new(r: (f64, f64), log: bool) -> Ticks {
        let (labelled, minor) = if log {
            log_ticks(r)
        } else {
            (Vec::new(), Vec::new())
        };
        let big = r.0.abs().max(r.1.abs());
        // One notation per axis: "0.001" beside "5×10⁻⁴" reads as two scales.
        let scientific = big >= 1e5 || if log { r.0 < 1e-3 } else { big < 1e-3 };
        Ticks {
            log,
            labelled,
            minor,
            scientific,
        }
    }

    /// The label of tick `v`; empty on a log axis for ticks that get none.
    pub(super) fn label(&self, v: f64) -> String {
        if self.log
            && !self
                .labelled
                .iter()
                .any(|t| (t - v).abs() <= 1e-9 * t.abs())
        {
            return String::new();
        }
        if self.scientific {
            scientific(v, 3)
        } else {
            decimal(v)
        }
    }
}

/// Labelled and minor ticks of a log axis over `r`: the 1, 2, 5 multiples of each power of ten
/// with minor ticks at every integer multiple, or over more than 3.5 decades the powers of ten
/// with minor ticks at their 2 and 5 multiples; every integer multiple is labelled when fewer
/// than two 1, 2, 5 multiples fall inside `r`.
pub(super) fn log_ticks(r: (f64, f64)) -> (Vec<f64>, Vec<f64>) {
    let (lo, hi) = r;
    let at = |mults: &[f64]| -> Vec<f64> {
        let mut v = Vec::new();
        for k in lo.log10().floor() as i32..=hi.log10().ceil() as i32 {
            for m in mults {
                // Dividing by 10^|k| rounds 0.3 to the double nearest 0.3, as the labels expect.
                let t = if k >= 0 {
                    m * 10f64.powi(k)
                } else {
                    m / 10f64.powi(-k)
                };
                if t >= lo * (1.0 - 1e-12) && t <= hi * (1.0 + 1e-12) {
                    v.push(t);
                }
            }
        }
        v
    };
    let all = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
    if (hi / lo).log10() > 3.5 {
        (at(&[1.0]), at(&[1.0, 2.0, 5.0]))
    } else {
        let labelled = at(&[1.0, 2.0, 5.0]);
        if labelled.len() >= 2 {
            (labelled, at(&all))
        } else {
            (at(&all), Vec::new())
        }
    }
}

/// Up to four significant digits, without trailing zeros; a true minus sign.
pub(super) fn decimal(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let e = v.abs().log10().floor();
    let decimals = (3.0 - e).clamp(0.0, 6.0) as usize;
    let s = format!("{v:.decimals$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    s.replace('-', "−")
}

/// `v` as `m×10ⁿ` with at most `digits` significant digits in `m`, or `10ⁿ` when `m` is 1.
pub(super) fn scientific(v: f64, digits: usize) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let s = format!("{:.*e}", digits.saturating_sub(1), v.abs());
    let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
    let m = if m.contains('.') {
        m.trim_end_matches('0').trim_end_matches('.')
    } else {
        m
    };
    let e: i32 = e.parse().unwrap_or(0);
    let sign = if v < 0.0 { "−" } else { "" };
    if m == "1" {
        format!("{sign}10{}", superscript(e))
    } else {
        format!("{sign}{m}×10{}", superscript(e))
    }
}

/// An integer in superscript digits (`-3` → `⁻³`).
fn superscript(n: i32) -> String {
    const DIGITS: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let mut s = String::new();
    if n < 0 {
        s.push('⁻');
    }
    for c in n.unsigned_abs().to_string().chars() {
        s.push(DIGITS[c.to_digit(10).unwrap_or(0) as usize]);
    }
    s
}

/// The visible part of a polyline inside the axis ranges (in log space on log axes): its first
/// contiguous run, which is all of it for the straight reference lines it is used for.
pub(super) fn clip_polyline(
    pts: &[(f64, f64)],
    xs: (f64, f64),
    ys: (f64, f64),
    log_x: bool,
    log_y: bool,
) -> Vec<(f64, f64)> {
    let (x0, x1) = (to_axis(xs.0, log_x), to_axis(xs.1, log_x));
    let (y0, y1) = (to_axis(ys.0, log_y), to_axis(ys.1, log_y));
    let mut out: Vec<(f64, f64)> = Vec::new();
    for w in pts.windows(2) {
        let (ax, ay) = (to_axis(w[0].0, log_x), to_axis(w[0].1, log_y));
        let (bx, by) = (to_axis(w[1].0, log_x), to_axis(w[1].1, log_y));
        // Liang–Barsky: the parameter interval [t0, t1] of the segment inside the box.
        let (dx, dy) = (bx - ax, by - ay);
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        let mut visible = true;
        for (p, q) in [(-dx, ax - x0), (dx, x1 - ax), (-dy, ay - y0), (dy, y1 - ay)] {
            if p == 0.0 {
                if q < 0.0 {
                    visible = false;
                }
            } else {
                let r = q / p;
                if p < 0.0 {
                    t0 = t0.max(r);
                } else {
                    t1 = t1.min(r);
                }
            }
        }
        if !visible || t0 > t1 {
            if !out.is_empty() {
                break;
            }
            continue;
        }
        let at = |t: f64| (from_axis(ax + t * dx, log_x), from_axis(ay + t * dy, log_y));
        if out.is_empty() {
            out.push(at(t0));
        }
        out.push(at(t1));
        if t1 < 1.0 {
            break;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_lines_are_clipped_to_the_axes() {
        // 1/N from (1, 1) to (1000, 1e-3), clipped to y ≥ 1e-2 in log-log: ends at x = 100.
        let c = clip_polyline(
            &[(1.0, 1.0), (1000.0, 1e-3)],
            (1.0, 1000.0),
            (1e-2, 10.0),
            true,
            true,
        );
        assert_eq!(c.len(), 2);
        assert!((c[0].0 - 1.0).abs() < 1e-9 && (c[0].1 - 1.0).abs() < 1e-9);
        assert!((c[1].0 - 100.0).abs() < 1e-6 && (c[1].1 - 1e-2).abs() < 1e-9);
        // Entirely outside: nothing is drawn.
        assert!(clip_polyline(
            &[(1.0, 100.0), (10.0, 50.0)],
            (1.0, 10.0),
            (0.1, 1.0),
            true,
            true
        )
        .is_empty());
    }

    #[test]
    fn log_ticks_cover_partial_decades() {
        let (bold, light) = log_ticks((0.015, 0.3));
        assert_eq!(bold, [0.02, 0.05, 0.1, 0.2]);
        assert_eq!(light.len(), 8 + 3);
        // Over more than 3.5 decades only the powers of ten are labelled.
        let (bold, light) = log_ticks((1e-7, 1.0));
        assert_eq!(bold.len(), 8);
        assert_eq!(light.len(), 8 + 2 * 7);
        assert_eq!(
            log_ticks((1.0, 512.0)).0,
            [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0]
        );
        // Less than a factor 2.5: every integer multiple gets a label.
        assert_eq!(log_ticks((0.31, 0.58)).0, [0.4, 0.5]);
    }

    #[test]
    fn tick_labels_use_one_notation_per_axis() {
        assert_eq!(decimal(0.30000000000000004), "0.3");
        assert_eq!(decimal(1234.0), "1234");
        assert_eq!(decimal(0.001234), "0.001234");
        assert_eq!(decimal(-0.5), "−0.5");
        assert_eq!(decimal(0.0), "0");
        assert_eq!(scientific(5.27e-4, 3), "5.27×10⁻⁴");
        assert_eq!(scientific(1e-3, 3), "10⁻³");
        assert_eq!(scientific(2.5e-12, 3), "2.5×10⁻¹²");
        assert_eq!(scientific(9.9996e-5, 3), "10⁻⁴");
        assert_eq!(scientific(-3e5, 3), "−3×10⁵");
        assert_eq!(scientific(20.0, 3), "2×10¹");

        // spp from 1 to 512: decimals, 1-2-5 multiples labelled, others not.
        let spp = Ticks::new((0.67, 768.0), true);
        assert_eq!(spp.label(1.0), "1");
        assert_eq!(spp.label(200.0), "200");
        assert_eq!(spp.label(300.0), "");
        // MSE over four decades: powers of ten only, all as powers.
        let mse = Ticks::new((3e-5, 0.2), true);
        assert_eq!(mse.label(1e-4), "10⁻⁴");
        assert_eq!(mse.label(0.1), "10⁻¹");
        assert_eq!(mse.label(5e-4), "");
        // A short log axis reaching below 10⁻³: 1-2-5 multiples as powers of ten.
        let short = Ticks::new((3e-4, 0.03), true);
        assert_eq!(short.label(5e-4), "5×10⁻⁴");
        assert_eq!(short.label(0.02), "2×10⁻²");
        // Linear axes: decimals unless the values are tiny or huge.
        assert_eq!(Ticks::new((0.0, 2.5), false).label(0.5), "0.5");
        assert_eq!(Ticks::new((0.0, 2.5e-4), false).label(1.5e-4), "1.5×10⁻⁴");
        assert_eq!(Ticks::new((-1e6, 1e6), false).label(-5e5), "−5×10⁵");
    }

    #[test]
    fn bands_are_clamped_to_the_axis_in_axis_space() {
        // Log y over [1e-3, 1]: a band from 1e-4 to 1e-1 at x = 1 and from 1e-2 to 10 at x = 10.
        let poly = band_polygon(
            &[(1.0, 1e-2), (10.0, 1.0)],
            &[(1e-4, 1e-1), (1e-2, 10.0)],
            (1e-3, 1.0),
            true,
            true,
        );
        let log: Vec<(f64, f64)> = poly.iter().map(|p| (p.0.log10(), p.1.log10())).collect();
        let want = [
            (0.0, -1.0), // upper edge at x = 1
            (0.5, 0.0),  // it crosses the top of the axis half-way
            (1.0, 0.0),  // and stays pressed against it
            (1.0, -2.0), // lower edge back from x = 10
            (0.5, -3.0), // it crosses the bottom of the axis half-way
            (0.0, -3.0), // and stays pressed against it
        ];
        assert_eq!(log.len(), want.len(), "{log:?}");
        for (g, w) in log.iter().zip(want) {
            assert!(
                (g.0 - w.0).abs() < 1e-9 && (g.1 - w.1).abs() < 1e-9,
                "{log:?}"
            );
        }
        // A low end at or below zero shades down to the bottom of a log axis.
        let poly = band_polygon(
            &[(1.0, 0.1), (2.0, 0.1)],
            &[(-0.2, 0.2), (0.0, 0.2)],
            (1e-3, 1.0),
            false,
            true,
        );
        assert!(
            poly.iter()
                .rev()
                .take(2)
                .all(|p| (p.1 - 1e-3).abs() < 1e-15),
            "{poly:?}"
        );
    }

    #[test]
    fn bands_must_match_their_series() {
        let chart = |band: Option<Vec<(f64, f64)>>, label: Option<&str>| Chart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![Series {
                name: "s".into(),
                points: vec![(1.0, 1.0), (2.0, 0.5)],
                band,
                reference: false,
            }],
            log_x: true,
            log_y: true,
            band_label: label.map(str::to_string),
        };
        let dir = tempfile::tempdir().unwrap();
        let stem = dir.path().join("c");
        let e = write_charts(
            &stem,
            &Inputs::default(),
            &[chart(Some(vec![(0.5, 2.0)]), Some("CI"))],
            300,
            200,
        )
        .unwrap_err();
        assert!(format!("{e:#}").contains("2 points but 1 band"), "{e:#}");
        let e = write_charts(
            &stem,
            &Inputs::default(),
            &[chart(Some(vec![(0.5, 2.0); 2]), None)],
            300,
            200,
        )
        .unwrap_err();
        assert!(format!("{e:#}").contains("no legend label"), "{e:#}");
        write_charts(
            &stem,
            &Inputs::default(),
            &[chart(Some(vec![(0.5, 2.0); 2]), Some("CI"))],
            300,
            200,
        )
        .unwrap();
        assert!(stem.with_extension("png").exists() && stem.with_extension("svg").exists());
    }
}
