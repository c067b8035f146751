//! The cross-crate tests, one module per file, built as a single test binary (a binary per
//! file linked the whole dependency tree once per file; see `Cargo.toml`).

// Test code is not library code: it writes its fixtures and reads its settings (clippy.toml's
// rules are for the library).
#![allow(clippy::disallowed_methods)]

mod determinism;
mod docs_links;
mod dual_scattering;
mod furnace;
mod groom_inputs;
mod guided;
mod library_dependencies;
mod library_sources;
mod outputs;
mod radiance_cache;
mod round_curves;
mod strand_variation;
mod test_files;
mod wavefront;
mod workspace;
