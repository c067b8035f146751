//! The tests of the `tress` binary, one module per file, built as a single test binary (a
//! binary per file linked the whole dependency tree once per file; see `Cargo.toml`).

mod bench;
mod cli;
mod common;
mod farm;
mod hardening;
mod log_format;
mod outputs;
mod study;
mod usd;
