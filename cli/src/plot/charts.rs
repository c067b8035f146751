//! Line charts: series on linear or log axes, in panels side by side.

use super::*;

/// One curve of a chart.
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Drawn dashed-looking (thin, grey) as a reference line rather than data.
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
}

/// A row of charts drawn side by side into `<stem>.png` and `<stem>.svg`, written atomically.
pub fn write_charts(stem: &Path, charts: &[Chart], panel_width: u32, height: u32) -> Result<()> {
    ensure_font()?;
    if charts.is_empty() {
        bail!("nothing to plot");
    }
    let size = (panel_width * charts.len() as u32, height);
    let svg = stem.with_extension("svg");
    // Also creates the folder the SVG goes to.
    write_bitmap(&stem.with_extension("png"), size, |root| draw(root, charts))?;

    let mut svg_text = String::new();
    {
        let root = SVGBackend::with_string(&mut svg_text, size).into_drawing_area();
        draw(&root, charts)?;
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e}", svg.display()))?;
    }
    crate::atomic_write(&svg, svg_text.as_bytes())
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
        let (lo, hi) = (lo / 1.5, hi * 1.5);
        // plotters labels log axes at powers of ten: keep one inside the range.
        if lo.log10().ceil() > hi.log10().floor() {
            (10f64.powf(lo.log10().floor()), hi)
        } else {
            (lo, hi)
        }
    } else if hi - lo < 1e-12 {
        (lo - 0.5, hi + 0.5)
    } else {
        let pad = 0.05 * (hi - lo);
        (lo - pad, hi + pad)
    }
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

pub(super) fn draw_one<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    chart: &Chart,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let xs = range(
        chart
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0)),
        chart.log_x,
    );
    let ys = range(
        chart
            .series
            .iter()
            .filter(|s| !s.reference)
            .flat_map(|s| s.points.iter().map(|p| p.1)),
        chart.log_y,
    );
    let mut builder = ChartBuilder::on(area);
    builder
        .caption(&chart.title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70);
    macro_rules! finish {
        ($ctx:expr) => {{
            let mut ctx = $ctx;
            let fx = |v: &f64| tick_label(*v, chart.log_x);
            let fy = |v: &f64| tick_label(*v, chart.log_y);
            ctx.configure_mesh()
                .x_desc(chart.x_label.as_str())
                .y_desc(chart.y_label.as_str())
                .x_label_formatter(&fx)
                .y_label_formatter(&fy)
                .bold_line_style(RGBColor(215, 215, 215))
                .light_line_style(RGBColor(244, 244, 244))
                .label_style(("sans-serif", 13))
                .draw()?;
            for (i, s) in chart.series.iter().enumerate() {
                let color = if s.reference {
                    RGBColor(150, 150, 150)
                } else {
                    PALETTE[i % PALETTE.len()]
                };
                let mut pts: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|p| {
                        p.0.is_finite()
                            && p.1.is_finite()
                            && (!chart.log_y || p.1 > 0.0)
                            && (!chart.log_x || p.0 > 0.0)
                    })
                    .collect();
                if s.reference {
                    // Reference lines do not set the axis range, and plotters does not clip, so
                    // clip them here lest they run over the labels.
                    pts = clip_polyline(&pts, xs, ys, chart.log_x, chart.log_y);
                }
                let style = ShapeStyle {
                    color: color.to_rgba(),
                    filled: false,
                    stroke_width: if s.reference { 1 } else { 2 },
                };
                ctx.draw_series(LineSeries::new(pts.clone(), style))?
                    .label(s.name.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
                if !s.reference && pts.len() <= 16 {
                    ctx.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
                }
            }
            ctx.configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 13))
                .position(SeriesLabelPosition::UpperRight)
                .draw()?;
        }};
    }
    // Log axes get explicit ticks: plotters' own start at the first power of ten in range.
    let log_axis = |r: (f64, f64)| {
        let (bold, light) = log_ticks(r);
        (r.0..r.1)
            .log_scale()
            .with_key_points(bold)
            .with_light_points(light)
    };
    match (chart.log_x, chart.log_y) {
        (false, false) => finish!(builder.build_cartesian_2d(xs.0..xs.1, ys.0..ys.1)?),
        (true, false) => finish!(builder.build_cartesian_2d(log_axis(xs), ys.0..ys.1)?),
        (false, true) => finish!(builder.build_cartesian_2d(xs.0..xs.1, log_axis(ys))?),
        (true, true) => finish!(builder.build_cartesian_2d(log_axis(xs), log_axis(ys))?),
    }
    Ok(())
}

/// Labelled and minor ticks of a log axis over `r`: the 1, 2, 5 multiples of each power of ten
/// with minor ticks at every integer multiple, or over more than four decades the powers of ten
/// with minor ticks at their 2 and 5 multiples.
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
    if (hi / lo).log10() > 4.0 {
        (at(&[1.0]), at(&[1.0, 2.0, 5.0]))
    } else {
        (
            at(&[1.0, 2.0, 5.0]),
            at(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]),
        )
    }
}

/// A short tick label: up to four significant digits, exponent notation for very small or large
/// values; on log axes only the 1, 2 and 5 multiples of a power of ten are labelled (plotters
/// puts a tick at every integer multiple, which would overlap).
pub(super) fn tick_label(v: f64, log: bool) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    let e = a.log10().floor();
    if log {
        let m = (a / 10f64.powf(e)).round() as i64;
        if ![1, 2, 5, 10].contains(&m) {
            return String::new();
        }
    }
    if (1e-3..1e5).contains(&a) {
        let decimals = (3.0 - e).clamp(0.0, 6.0) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        let s = format!("{v:.2e}");
        // 2.50e-4 → 2.5e-4, 1.00e-6 → 1e-6
        match s.split_once('e') {
            Some((m, x)) if m.contains('.') => {
                format!("{}e{x}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => s,
        }
    }
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
    let fwd = |v: f64, log: bool| if log { v.log10() } else { v };
    let inv = |v: f64, log: bool| if log { 10f64.powf(v) } else { v };
    let (x0, x1) = (fwd(xs.0, log_x), fwd(xs.1, log_x));
    let (y0, y1) = (fwd(ys.0, log_y), fwd(ys.1, log_y));
    let mut out: Vec<(f64, f64)> = Vec::new();
    for w in pts.windows(2) {
        let (ax, ay) = (fwd(w[0].0, log_x), fwd(w[0].1, log_y));
        let (bx, by) = (fwd(w[1].0, log_x), fwd(w[1].1, log_y));
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
        let at = |t: f64| (inv(ax + t * dx, log_x), inv(ay + t * dy, log_y));
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
