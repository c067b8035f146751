//! Charts with plotters for `tress bcsdf plot`, `tress diff` and `tress study`: line charts (PNG
//! and SVG, linear or log axes), colour-mapped heat maps with a colour bar, and image sheets (PNG).

mod canvas;
mod charts;
mod heat;
mod sheet;
mod text;

pub use charts::{write_charts, Chart, Series};
pub use heat::{write_heat_maps, HeatPanel, LogScale};
pub use sheet::write_image_sheet;
