//! Image sheets: a grid of pictures with row and column labels.

use super::canvas::{blit, display_size, draw_text, text_width, write_bitmap};
use super::canvas::{MARGIN, TITLE_H};
use anyhow::Result;
use std::path::Path;
use tress_core::output_file::Inputs;
use tress_study::picture::Picture;

/// A grid of pictures with a title, row labels on the left and column labels on top (an empty
/// cell is left white); PNG, which may replace none of `inputs`. All pictures are shown at the size of the largest one, enlarged by
/// an integer factor when small so single pixels stay visible.
pub fn write_image_sheet(
    path: &Path,
    inputs: &Inputs,
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
    write_bitmap(path, inputs, (width, height), |root| {
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
