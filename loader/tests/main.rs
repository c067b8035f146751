//! The integration tests of tress-loader, one module per file, built as a single test binary
//! (a binary per file linked the whole dependency tree once per file; see `Cargo.toml`).

mod scene_types;
mod strand_variation;
