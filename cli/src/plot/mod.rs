//! Charts with plotters for `tress bcsdf plot`, `tress diff` and `tress study`: line charts (PNG
//! and SVG, linear or log axes), colour-mapped heat maps with a colour bar, and image sheets (PNG).

use anyhow::{anyhow, bail, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor;
use std::path::Path;
use text::Typeset;
use tress_core::image_io;
use tress_scene::picture::Picture;

mod charts;
mod text;
pub use charts::*;

/// The drawing area of a PNG being drawn.
type Bitmap<'a> = DrawingArea<Typeset<BitMapBackend<'a>>, Shift>;

/// A logarithmic colour scale `[lo, hi]` (values outside are clamped to its ends).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogScale {
    pub lo: f64,
    pub hi: f64,
}

impl LogScale {
    /// From the 1st to the 99.5th percentile of the positive finite values, widened to at least
    /// one decade about their geometric middle; `[1e-3, 1]` when no value is positive.
    pub fn fit(values: &[f32]) -> LogScale {
        let mut v: Vec<f32> = values
            .iter()
            .copied()
            .filter(|x| x.is_finite() && *x > 0.0)
            .collect();
        if v.is_empty() {
            return LogScale { lo: 1e-3, hi: 1.0 };
        }
        v.sort_by(f32::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] as f64;
        let (lo, hi) = (at(0.01), at(0.995));
        let mid = (lo * hi).sqrt();
        if hi / lo < 10.0 {
            LogScale {
                lo: mid / 10f64.sqrt(),
                hi: mid * 10f64.sqrt(),
            }
        } else {
            LogScale { lo, hi }
        }
    }

    /// Position of `v` on the scale, in [0, 1].
    fn position(&self, v: f64) -> f64 {
        if v.is_nan() || v <= self.lo {
            return 0.0;
        }
        ((v / self.lo).log10() / (self.hi / self.lo).log10()).clamp(0.0, 1.0)
    }
}

/// Control points of a perceptually ordered dark-to-bright colour map (black, purple, red,
/// orange, pale yellow): low error is dark.
const HEAT: [(f64, [u8; 3]); 9] = [
    (0.0, [0, 0, 4]),
    (0.125, [31, 12, 72]),
    (0.25, [85, 15, 109]),
    (0.375, [136, 34, 106]),
    (0.5, [186, 54, 85]),
    (0.625, [227, 89, 51]),
    (0.75, [249, 140, 10]),
    (0.875, [249, 201, 50]),
    (1.0, [252, 255, 164]),
];

/// The heat colour at `t` ∈ [0, 1].
pub fn heat_color(t: f64) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    let i = HEAT
        .iter()
        .rposition(|(p, _)| *p <= t)
        .unwrap_or(0)
        .min(HEAT.len() - 2);
    let ((p0, c0), (p1, c1)) = (HEAT[i], HEAT[i + 1]);
    let f = (t - p0) / (p1 - p0);
    [0, 1, 2].map(|k| (c0[k] as f64 + f * (c1[k] as f64 - c0[k] as f64)).round() as u8)
}

/// Non-finite errors are painted in this colour, which the heat map never uses.
const NON_FINITE: [u8; 3] = [0, 255, 0];

/// One panel of a heat-map figure: `width × height` values, row-major.
pub struct HeatPanel {
    pub title: String,
    pub width: u32,
    pub height: u32,
    pub values: Vec<f32>,
}

/// Display size of a `w × h` picture: enlarged by an integer factor until its long side reaches
/// `min_side`, or shrunk so it does not exceed `max_side`.
fn display_size(w: u32, h: u32, min_side: u32, max_side: u32) -> (u32, u32) {
    let long = w.max(h).max(1);
    if long < min_side {
        let k = min_side.div_ceil(long);
        (w * k, h * k)
    } else if long > max_side {
        let s = max_side as f64 / long as f64;
        (
            ((w as f64 * s).round() as u32).max(1),
            ((h as f64 * s).round() as u32).max(1),
        )
    } else {
        (w, h)
    }
}

const MARGIN: u32 = 12;
const GAP: u32 = 12;
const TITLE_H: u32 = 24;

/// Width of `text` in pixels at `size`.
fn text_width(text: &str, size: u32) -> Result<u32> {
    Ok(text::face()?.width(text, size as f64))
}

fn text_style(size: u32) -> TextStyle<'static> {
    ("sans-serif", size).into_font().color(&BLACK)
}

/// Draws `root` into `path` (PNG) through a temporary file, so readers never see a partial image.
fn write_bitmap(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&Bitmap) -> Result<()>,
) -> Result<()> {
    text::face()?;
    if path.extension().and_then(|e| e.to_str()) != Some("png") {
        bail!("{}: expected a .png file name", path.display());
    }
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let tmp = image_io::output_temp_file(dir, ".png")?;
    {
        let root = Typeset::raster(BitMapBackend::new(tmp.path(), size)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("{e:?}"))?;
        draw(&root)?;
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e}", path.display()))?;
    }
    // The bare io::Error: the PersistError would keep the temporary file alive with it.
    tmp.persist(path)
        .map_err(|e| e.error)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

fn blit(root: &Bitmap, pos: (i32, i32), pic: &Picture) -> Result<()> {
    let element = BitMapElement::with_owned_buffer(pos, (pic.width, pic.height), pic.rgb.clone())
        .ok_or_else(|| anyhow!("picture buffer does not match its size"))?;
    root.draw(&element).map_err(|e| anyhow!("{e:?}"))
}

fn draw_text(root: &Bitmap, text: &str, size: u32, pos: (i32, i32)) -> Result<()> {
    root.draw_text(text, &text_style(size), pos)
        .map_err(|e| anyhow!("{e:?}"))
}

/// Heat maps side by side, one per panel, colour-mapped on the shared logarithmic `scale`, with a
/// colour bar labelled in powers of ten and `label` (what the values are) underneath; PNG.
pub fn write_heat_maps(
    path: &Path,
    panels: &[HeatPanel],
    scale: LogScale,
    label: &str,
) -> Result<()> {
    if panels.is_empty() {
        bail!("no heat map to draw");
    }
    let sizes: Vec<(u32, u32)> = panels
        .iter()
        .map(|p| display_size(p.width, p.height, 256, 512))
        .collect();
    let max_h = sizes.iter().map(|s| s.1).max().unwrap_or(1);
    // Each panel's slot is wide enough for its title.
    let slots = panels
        .iter()
        .zip(&sizes)
        .map(|(p, s)| Ok(s.0.max(text_width(&p.title, 15)?)))
        .collect::<Result<Vec<u32>>>()?;
    let caption = format!(
        "colour: {label}, log scale {} to {} (green: not finite)",
        scientific(scale.lo, 3),
        scientific(scale.hi, 3)
    );
    const BAR_W: u32 = 18;
    const BAR_LABELS: u32 = 64;
    let width = (MARGIN + slots.iter().map(|w| w + GAP).sum::<u32>() + BAR_W + BAR_LABELS)
        .max(2 * MARGIN + text_width(&caption, 13)?);
    let height = MARGIN + TITLE_H + max_h + 8 + 20 + MARGIN;
    write_bitmap(path, (width, height), |root| {
        let mut x = MARGIN as i32;
        let top = (MARGIN + TITLE_H) as i32;
        for ((panel, &(dw, dh)), slot) in panels.iter().zip(&sizes).zip(&slots) {
            if panel.values.len() != panel.width as usize * panel.height as usize {
                bail!("heat map '{}' has the wrong number of values", panel.title);
            }
            let mut rgb = Vec::with_capacity(panel.values.len() * 3);
            for v in &panel.values {
                let c = if v.is_finite() {
                    heat_color(scale.position(*v as f64))
                } else {
                    NON_FINITE
                };
                rgb.extend_from_slice(&c);
            }
            let pic = Picture {
                width: panel.width,
                height: panel.height,
                rgb,
            }
            .resized(dw, dh);
            blit(root, (x, top), &pic)?;
            draw_text(root, &panel.title, 15, (x, MARGIN as i32))?;
            x += (slot + GAP) as i32;
        }
        // Colour bar: bright (high error) at the top.
        let bar: Vec<u8> = (0..max_h)
            .flat_map(|y| {
                let c = heat_color(1.0 - y as f64 / (max_h - 1).max(1) as f64);
                (0..BAR_W).flat_map(move |_| c)
            })
            .collect();
        blit(
            root,
            (x, top),
            &Picture {
                width: BAR_W,
                height: max_h,
                rgb: bar,
            },
        )?;
        let y_of = |v: f64| top + ((1.0 - scale.position(v)) * (max_h - 1) as f64).round() as i32;
        let mut ticks: Vec<f64> = Vec::new();
        let (k0, k1) = (
            scale.lo.log10().ceil() as i32,
            scale.hi.log10().floor() as i32,
        );
        for k in k0..=k1 {
            ticks.push(10f64.powi(k));
        }
        if ticks.len() < 2 {
            ticks = vec![scale.lo, scale.hi];
        }
        let bx = x + BAR_W as i32;
        for t in ticks {
            let y = y_of(t);
            root.draw(&PathElement::new(vec![(bx, y), (bx + 4, y)], BLACK))
                .map_err(|e| anyhow!("{e:?}"))?;
            let style = text_style(13).pos(text_anchor::Pos::new(
                text_anchor::HPos::Left,
                text_anchor::VPos::Center,
            ));
            root.draw_text(&scientific(t, 3), &style, (bx + 6, y))
                .map_err(|e| anyhow!("{e:?}"))?;
        }
        draw_text(root, &caption, 13, (MARGIN as i32, top + max_h as i32 + 8))
    })
}

/// A grid of pictures with a title, row labels on the left and column labels on top (an empty
/// cell is left white); PNG. All pictures are shown at the size of the largest one, enlarged by
/// an integer factor when small so single pixels stay visible.
pub fn write_image_sheet(
    path: &Path,
    title: &str,
    row_labels: &[String],
    col_labels: &[String],
    cells: &[Vec<Option<Picture>>],
) -> Result<()> {
    let (mut cw, mut ch) = (1u32, 1u32);
    for p in cells.iter().flatten().flatten() {
        cw = cw.max(p.width);
        ch = ch.max(p.height);
    }
    let (cw, ch) = display_size(cw, ch, 96, 256);
    const CELL_GAP: u32 = 4;
    let mut label_w = 0;
    for l in row_labels {
        label_w = label_w.max(text_width(l, 13)? + 12);
    }
    let cols = col_labels
        .len()
        .max(cells.iter().map(Vec::len).max().unwrap_or(0)) as u32;
    let rows = cells.len() as u32;
    let top = MARGIN + TITLE_H + 20;
    let width = (MARGIN + label_w + cols * (cw + CELL_GAP) + MARGIN)
        .max(2 * MARGIN + text_width(title, 15)?);
    let height = top + rows * (ch + CELL_GAP) + MARGIN;
    write_bitmap(path, (width, height), |root| {
        draw_text(root, title, 15, (MARGIN as i32, MARGIN as i32))?;
        let x_of = |c: u32| (MARGIN + label_w + c * (cw + CELL_GAP)) as i32;
        let y_of = |r: u32| (top + r * (ch + CELL_GAP)) as i32;
        for (c, l) in col_labels.iter().enumerate() {
            draw_text(root, l, 13, (x_of(c as u32), (top - 18) as i32))?;
        }
        for (r, row) in cells.iter().enumerate() {
            if let Some(l) = row_labels.get(r) {
                draw_text(
                    root,
                    l,
                    13,
                    (MARGIN as i32, y_of(r as u32) + ch as i32 / 2 - 7),
                )?;
            }
            for (c, cell) in row.iter().enumerate() {
                if let Some(p) = cell {
                    blit(root, (x_of(c as u32), y_of(r as u32)), &p.resized(cw, ch))?;
                }
            }
        }
        Ok(())
    })
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
            &[chart(Some(vec![(0.5, 2.0)]), Some("CI"))],
            300,
            200,
        )
        .unwrap_err();
        assert!(format!("{e:#}").contains("2 points but 1 band"), "{e:#}");
        let e =
            write_charts(&stem, &[chart(Some(vec![(0.5, 2.0); 2]), None)], 300, 200).unwrap_err();
        assert!(format!("{e:#}").contains("no legend label"), "{e:#}");
        write_charts(
            &stem,
            &[chart(Some(vec![(0.5, 2.0); 2]), Some("CI"))],
            300,
            200,
        )
        .unwrap();
        assert!(stem.with_extension("png").exists() && stem.with_extension("svg").exists());
    }

    #[test]
    fn log_scale_and_colours() {
        let s = LogScale { lo: 1e-3, hi: 1e-1 };
        assert_eq!(s.position(1e-2), 0.5);
        assert_eq!(s.position(0.0), 0.0);
        assert_eq!(s.position(5.0), 1.0);
        assert_eq!(heat_color(0.0), [0, 0, 4]);
        assert_eq!(heat_color(1.0), [252, 255, 164]);
        // Brightness rises along the map, so a larger error always looks brighter.
        let lum = |c: [u8; 3]| 0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64;
        for i in 0..100 {
            assert!(lum(heat_color((i + 1) as f64 / 100.0)) > lum(heat_color(i as f64 / 100.0)));
        }
        let flat = LogScale::fit(&[0.5; 10]);
        assert!((flat.hi / flat.lo - 10.0).abs() < 1e-9);
        assert_eq!(
            LogScale::fit(&[0.0, f32::NAN]),
            LogScale { lo: 1e-3, hi: 1.0 }
        );
    }
}
