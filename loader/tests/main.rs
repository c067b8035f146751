//! The integration tests of tress-scene, one module per file, built as a single test binary
//! (a binary per file linked the whole dependency tree once per file; see `Cargo.toml`).

mod run_study;
mod scene_types;
mod strand_variation;
