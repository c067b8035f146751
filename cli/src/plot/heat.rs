//! Heat maps: per-pixel values colour-mapped on a shared logarithmic scale, with a colour bar.

use super::canvas::{blit, display_size, draw_text, text_style, text_width, write_bitmap};
use super::canvas::{GAP, MARGIN, TITLE_H};
use super::charts::scientific;
use anyhow::{anyhow, bail, Result};
use plotters::prelude::*;
use plotters::style::text_anchor;
use std::path::Path;
use tress_core::output_file::Inputs;
use tress_study::picture::Picture;

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

/// Heat maps side by side, one per panel, colour-mapped on the shared logarithmic `scale`, with a
/// colour bar labelled in powers of ten and `label` (what the values are) underneath; PNG, which
/// may replace none of `inputs`.
pub fn write_heat_maps(
    path: &Path,
    inputs: &Inputs,
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
    write_bitmap(path, inputs, (width, height), |root| {
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

#[cfg(test)]
mod tests {
    use super::*;

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
