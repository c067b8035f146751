//! Line charts (PNG and SVG) with plotters, for `tress bcsdf plot` and the study reports.

use anyhow::{anyhow, bail, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

/// Where Debian (fonts-dejavu-core) and other distributions keep a sans-serif TrueType font.
const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
];

/// Registers a system font as plotters' "sans-serif" once (plotters draws text with ab_glyph and
/// ships no font of its own).
fn ensure_font() -> Result<()> {
    static FONT: OnceLock<Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        for p in FONT_PATHS {
            if let Ok(bytes) = std::fs::read(p) {
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                return plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
                    .map_err(|_| format!("{p} is not a usable TrueType font"));
            }
        }
        Err(format!(
            "no TrueType font found for plot labels (looked in {}); install fonts-dejavu-core",
            FONT_PATHS.join(", ")
        ))
    })
    .clone()
    .map_err(|e| anyhow!(e))
}

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
    let png = stem.with_extension("png");
    let svg = stem.with_extension("svg");
    let dir = stem
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;

    let tmp_png = tempfile::Builder::new().suffix(".png").tempfile_in(dir)?;
    {
        let root = BitMapBackend::new(tmp_png.path(), size).into_drawing_area();
        draw(&root, charts)?;
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e}", png.display()))?;
    }
    tmp_png
        .persist(&png)
        .with_context(|| format!("writing {}", png.display()))?;

    let mut svg_text = String::new();
    {
        let root = SVGBackend::with_string(&mut svg_text, size).into_drawing_area();
        draw(&root, charts)?;
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e}", svg.display()))?;
    }
    crate::atomic_write(&svg, svg_text.as_bytes())
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, charts: &[Chart]) -> Result<()>
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

fn range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
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

const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

fn draw_one<DB: DrawingBackend>(
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
            ctx.configure_mesh()
                .x_desc(chart.x_label.as_str())
                .y_desc(chart.y_label.as_str())
                .label_style(("sans-serif", 13))
                .draw()?;
            for (i, s) in chart.series.iter().enumerate() {
                let color = if s.reference {
                    RGBColor(150, 150, 150)
                } else {
                    PALETTE[i % PALETTE.len()]
                };
                let pts: Vec<(f64, f64)> = s
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
    match (chart.log_x, chart.log_y) {
        (false, false) => finish!(builder.build_cartesian_2d(xs.0..xs.1, ys.0..ys.1)?),
        (true, false) => finish!(builder.build_cartesian_2d((xs.0..xs.1).log_scale(), ys.0..ys.1)?),
        (false, true) => finish!(builder.build_cartesian_2d(xs.0..xs.1, (ys.0..ys.1).log_scale())?),
        (true, true) => {
            finish!(builder.build_cartesian_2d((xs.0..xs.1).log_scale(), (ys.0..ys.1).log_scale())?)
        }
    }
    Ok(())
}
