//! Text in the plots: measured and (in bitmaps) rasterised here with ab_glyph rather than by
//! plotters.
//!
//! plotters 0.3.7 draws ab_glyph text with two errors: it drops each glyph's left side bearing
//! and truncates its pen position to whole pixels, which spreads letters unevenly ("samp les
//! p er pixel"), and it truncates the vertical offset of each glyph toward zero, which at odd
//! sizes lifts small glyphs such as the decimal point a pixel above the digits' baseline
//! ("0·1"). [`Typeset`] wraps a drawing backend and places every glyph at its sub-pixel pen
//! position on one baseline. Sizes keep plotters' convention, which its SVG backend also uses:
//! a font of size `s` has an em of `s / 1.24` pixels, so PNG and SVG text match.

use ab_glyph::{point, Font, FontRef, GlyphId, PxScale, ScaleFont};
use anyhow::{anyhow, Result};
use plotters::prelude::*;
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};
use std::sync::OnceLock;

/// Where Debian (fonts-dejavu-core) and other distributions keep a sans-serif TrueType font.
const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
];

/// plotters' font size per em (its SVG backend writes `font-size: size / 1.24`).
const SIZE_PER_EM: f32 = 1.24;

/// The typeface of every label.
pub(super) struct Face {
    font: FontRef<'static>,
    /// Height of the capitals above the baseline, in ems.
    cap_height: f32,
}

/// The plots' typeface, loaded once from the system fonts and also registered as plotters'
/// "sans-serif" (which it needs to build text styles).
pub(super) fn face() -> Result<&'static Face> {
    static FACE: OnceLock<Result<Face, String>> = OnceLock::new();
    FACE.get_or_init(|| {
        let Some((path, bytes)) = FONT_PATHS
            .iter()
            .find_map(|p| std::fs::read(p).ok().map(|b| (p, b)))
        else {
            return Err(format!(
                "no TrueType font found for plot labels (looked in {}); install fonts-dejavu-core",
                FONT_PATHS.join(", ")
            ));
        };
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        let unusable = || format!("{path} is not a usable TrueType font");
        let font = FontRef::try_from_slice(bytes).map_err(|_| unusable())?;
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| unusable())?;
        let units_per_em = font.units_per_em().ok_or_else(unusable)?;
        let cap_height = font
            .outline(font.glyph_id('H'))
            .map(|o| o.bounds.min.y / units_per_em)
            .ok_or_else(unusable)?;
        Ok(Face { font, cap_height })
    })
    .as_ref()
    .map_err(|e| anyhow!("{e}"))
}

/// One line of text set at a size: its glyphs' pen positions and vertical metrics, in pixels.
pub(super) struct Line {
    scale: PxScale,
    glyphs: Vec<(GlyphId, f32)>,
    pub(super) width: f32,
    pub(super) ascent: f32,
    /// Below the baseline, positive.
    pub(super) descent: f32,
    pub(super) cap_height: f32,
}

impl Face {
    /// Sets `text` at plotters size `size`, with the font's kerning.
    pub(super) fn line(&self, text: &str, size: f64) -> Line {
        let em = size as f32 / SIZE_PER_EM;
        let units_per_em = self.font.units_per_em().unwrap_or(1000.0);
        // ab_glyph scales the font's ascent − descent to the pixel scale, not its em.
        let scale = PxScale::from(em * self.font.height_unscaled() / units_per_em);
        let font = self.font.as_scaled(scale);
        let mut glyphs = Vec::with_capacity(text.len());
        let mut pen = 0.0f32;
        let mut prev: Option<GlyphId> = None;
        for c in text.chars() {
            let id = font.glyph_id(c);
            if let Some(p) = prev {
                pen += font.kern(p, id);
            }
            glyphs.push((id, pen));
            pen += font.h_advance(id);
            prev = Some(id);
        }
        Line {
            scale,
            glyphs,
            width: pen,
            ascent: font.ascent(),
            descent: -font.descent(),
            cap_height: self.cap_height * em,
        }
    }

    /// Width of `text` in whole pixels at plotters size `size`.
    pub(super) fn width(&self, text: &str, size: f64) -> u32 {
        self.line(text, size).width.ceil() as u32
    }
}

/// A drawing backend whose text is measured from the font's real metrics and, when `raster`,
/// drawn glyph by glyph; everything else goes to the wrapped backend. Vector backends (SVG)
/// keep drawing their text as text.
pub(super) struct Typeset<B> {
    inner: B,
    raster: bool,
}

impl<B: DrawingBackend> Typeset<B> {
    /// Wraps a bitmap backend: its text is rasterised here.
    pub(super) fn raster(inner: B) -> Self {
        Typeset {
            inner,
            raster: true,
        }
    }

    /// Wraps a vector backend: only text measurement is replaced.
    pub(super) fn vector(inner: B) -> Self {
        Typeset {
            inner,
            raster: false,
        }
    }
}

fn font_error<E: std::error::Error + Send + Sync>(e: anyhow::Error) -> DrawingErrorKind<E> {
    DrawingErrorKind::FontError(e.into())
}

impl<B: DrawingBackend> DrawingBackend for Typeset<B> {
    type ErrorType = B::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.inner.get_size()
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.ensure_prepared()
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.present()
    }

    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.fill_polygon(vert, style)
    }

    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        size: (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.blit_bitmap(pos, size, src)
    }

    fn estimate_text_size<S: BackendTextStyle>(
        &self,
        text: &str,
        style: &S,
    ) -> Result<(u32, u32), DrawingErrorKind<B::ErrorType>> {
        let line = face().map_err(font_error)?.line(text, style.size());
        let (w, h) = (
            line.width.ceil() as i32,
            (line.ascent + line.descent).ceil() as i32,
        );
        let (w, h) = style.transform().transform(w, h);
        Ok((w.unsigned_abs(), h.unsigned_abs()))
    }

    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        if !self.raster {
            return self.inner.draw_text(text, style, pos);
        }
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let face = face().map_err(font_error)?;
        let line = face.line(text, style.size());
        let font = face.font.as_scaled(line.scale);
        let anchor = style.anchor();
        let x0 = match anchor.h_pos {
            HPos::Left => 0.0,
            HPos::Center => -line.width / 2.0,
            HPos::Right => -line.width,
        };
        // Top and centre align the capitals (and so the digits), which is what sits against a
        // tick or an edge; bottom aligns the descenders.
        let baseline = match anchor.v_pos {
            VPos::Top => line.cap_height,
            VPos::Center => line.cap_height / 2.0,
            VPos::Bottom => -line.descent,
        };
        let transform = style.transform();
        let (width, height) = self.inner.get_size();
        for &(id, pen) in &line.glyphs {
            let glyph = id.with_scale_and_position(line.scale, point(x0 + pen, baseline));
            let Some(outline) = font.outline_glyph(glyph) else {
                continue;
            };
            let bounds = outline.px_bounds();
            let mut coverage = Vec::new();
            outline.draw(|x, y, c| coverage.push((x, y, c)));
            for (x, y, c) in coverage {
                if c <= 0.0 {
                    continue;
                }
                let (dx, dy) = transform.transform(
                    bounds.min.x as i32 + x as i32,
                    bounds.min.y as i32 + y as i32,
                );
                let (px, py) = (pos.0 + dx, pos.1 + dy);
                if px >= 0 && py >= 0 && (px as u32) < width && (py as u32) < height {
                    let shade = BackendColor {
                        alpha: color.alpha * c.min(1.0) as f64,
                        rgb: color.rgb,
                    };
                    self.inner.draw_pixel((px, py), shade)?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Renders `text` black on white into a `w × h` grey buffer (0 = white, 255 = black).
    fn render(text: &str, size: f64, w: u32, h: u32) -> Vec<u8> {
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root =
                Typeset::raster(BitMapBackend::with_buffer(&mut buf, (w, h))).into_drawing_area();
            let style = ("sans-serif", size).into_font().color(&BLACK).pos(
                plotters::style::text_anchor::Pos::new(HPos::Left, VPos::Top),
            );
            root.draw_text(text, &style, (2, 2)).unwrap();
            root.present().unwrap();
        }
        buf.chunks(3).map(|p| 255 - p[0]).collect()
    }

    /// Lowest inked row (the baseline, for glyphs without descenders) of the columns `x0..x1`.
    fn bottom(img: &[u8], w: u32, x0: u32, x1: u32) -> Option<u32> {
        let h = img.len() as u32 / w;
        (0..h)
            .rev()
            .find(|&y| (x0..x1).any(|x| img[(y * w + x) as usize] > 96))
    }

    /// Inked column ranges, left to right.
    fn columns(img: &[u8], w: u32) -> Vec<(u32, u32)> {
        let h = img.len() as u32 / w;
        let inked: Vec<bool> = (0..w)
            .map(|x| (0..h).any(|y| img[(y * w + x) as usize] > 40))
            .collect();
        let mut runs = Vec::new();
        let mut start = None;
        for (x, &on) in inked.iter().enumerate() {
            match (on, start) {
                (true, None) => start = Some(x as u32),
                (false, Some(s)) => {
                    runs.push((s, x as u32));
                    start = None;
                }
                _ => {}
            }
        }
        runs
    }

    #[test]
    fn the_decimal_point_sits_on_the_baseline_at_odd_sizes() {
        face().unwrap();
        for size in [13.0, 15.0, 17.0] {
            let (w, h) = (80, 30);
            let img = render("5.7", size, w, h);
            let runs = columns(&img, w);
            assert_eq!(runs.len(), 3, "size {size}: {runs:?}");
            let base: Vec<u32> = runs
                .iter()
                .map(|&(a, b)| bottom(&img, w, a, b).unwrap())
                .collect();
            // '5' and '.' both rest on the baseline; plotters' own drawing lifts the point.
            assert_eq!(base[0], base[1], "size {size}: bottoms {base:?}");
        }
    }

    #[test]
    fn letters_are_evenly_spaced() {
        face().unwrap();
        // "ll" then "pe": the gap inside a word must not exceed a space's width, as it did
        // with plotters' own drawing ("samp les p er").
        let (w, h) = (200, 30);
        let space = face().unwrap().line(" ", 13.0).width;
        let img = render("samples per", 13.0, w, h);
        let runs = columns(&img, w);
        let gaps: Vec<u32> = runs.windows(2).map(|r| r[1].0 - r[0].1).collect();
        let largest = *gaps.iter().max().unwrap() as f32;
        // The word gap is the largest, and clearly wider than any gap between letters.
        let letter_gaps: Vec<u32> = gaps
            .iter()
            .copied()
            .filter(|&g| (g as f32) < space)
            .collect();
        assert_eq!(
            gaps.len() - letter_gaps.len(),
            1,
            "gaps {gaps:?}, space {space}"
        );
        assert!(largest >= space - 1.0, "gaps {gaps:?}, space {space}");
        assert!(letter_gaps.iter().all(|&g| g <= 2), "gaps {gaps:?}");
    }

    #[test]
    fn measured_width_matches_the_ink() {
        face().unwrap();
        let (w, h) = (300, 30);
        let text = "relMSE vs CPU time";
        let img = render(text, 13.0, w, h);
        let runs = columns(&img, w);
        let ink = runs.last().unwrap().1 - runs[0].0;
        let measured = face().unwrap().width(text, 13.0);
        assert!(
            (ink as i32 - measured as i32).abs() <= 2,
            "ink {ink} px, measured {measured} px"
        );
    }
}
