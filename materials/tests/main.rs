//! The integration tests of tress-materials, one module per file, built as a single test
//! binary (a binary per file linked the whole dependency tree once per file; see `Cargo.toml`).

// Test code is not library code: it writes its fixtures and reads its settings (clippy.toml's
// rules are for the library).
#![allow(clippy::disallowed_methods)]

mod bcsdf_statistics;
mod chiang_reference;
mod fur_statements;
mod huang_cost;
mod huang_reference;
