//! The integration tests of tress-materials, one module per file, built as a single test
//! binary (a binary per file linked the whole dependency tree once per file; see `Cargo.toml`).

mod bcsdf_statistics;
mod chiang_reference;
