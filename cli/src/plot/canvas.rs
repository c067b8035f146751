//! Bitmaps being drawn: their text, pictures and writing them as PNG.

use super::text::{self, Typeset};
use anyhow::{anyhow, bail, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;
use tress_core::image_io;
use tress_core::output_file::{self, Inputs, Sink};
use tress_study::picture::Picture;

/// The drawing area of a PNG being drawn.
pub(super) type Bitmap<'a> = DrawingArea<Typeset<BitMapBackend<'a>>, Shift>;

/// Display size of a `w × h` picture: enlarged by an integer factor until its long side reaches
/// `min_side`, or shrunk so it does not exceed `max_side`.
pub(super) fn display_size(w: u32, h: u32, min_side: u32, max_side: u32) -> (u32, u32) {
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

pub(super) const MARGIN: u32 = 12;
pub(super) const GAP: u32 = 12;
pub(super) const TITLE_H: u32 = 24;

/// Width of `text` in pixels at `size`.
pub(super) fn text_width(text: &str, size: u32) -> Result<u32> {
    Ok(text::face()?.width(text, size as f64))
}

/// The labels' font at `size` pixels, in black.
pub(super) fn text_style(size: u32) -> TextStyle<'static> {
    ("sans-serif", size).into_font().color(&BLACK)
}

/// Draws a bitmap of `size` with `draw` and writes it to `path` (PNG), creating its folder;
/// it may replace none of `inputs`.
pub(super) fn write_bitmap(
    path: &Path,
    inputs: &Inputs,
    size: (u32, u32),
    draw: impl FnOnce(&Bitmap) -> Result<()>,
) -> Result<()> {
    if path.extension().and_then(|e| e.to_str()) != Some("png") {
        bail!("{}: expected a .png file name", path.display());
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    output_file::write(path, inputs, |out| draw_bitmap(out, size, draw))
}

/// Draws a bitmap of `size` with `draw` and writes it into `out` as a PNG.
pub(super) fn draw_bitmap(
    out: &mut Sink,
    size: (u32, u32),
    draw: impl FnOnce(&Bitmap) -> Result<()>,
) -> Result<()> {
    text::face()?;
    let (w, h) = size;
    let mut rgb = vec![0u8; w as usize * h as usize * 3];
    {
        let root = Typeset::raster(BitMapBackend::with_buffer(&mut rgb, size)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("{e:?}"))?;
        draw(&root)?;
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e}", out.path().display()))?;
    }
    Ok(image_io::write_srgb_png(out, w, h, &rgb)?)
}

/// Draws `pic` with its top left corner at `pos`.
pub(super) fn blit(root: &Bitmap, pos: (i32, i32), pic: &Picture) -> Result<()> {
    let element = BitMapElement::with_owned_buffer(pos, (pic.width, pic.height), pic.rgb.clone())
        .ok_or_else(|| anyhow!("picture buffer does not match its size"))?;
    root.draw(&element).map_err(|e| anyhow!("{e:?}"))
}

/// Draws `text` at `size` pixels with its top left corner at `pos`.
pub(super) fn draw_text(root: &Bitmap, text: &str, size: u32, pos: (i32, i32)) -> Result<()> {
    root.draw_text(text, &text_style(size), pos)
        .map_err(|e| anyhow!("{e:?}"))
}
