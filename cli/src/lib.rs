//! The scene layer of the `tress` binary as a library: scene files, their objects and the
//! integrator registry. The binary uses it as is, so fuzz targets (`cli/fuzz`) and tests reach
//! exactly the parser and validation the binary runs.

pub mod geometry;
pub mod integrators;
pub mod scene_desc;

/// RON options for everything tress parses: newtype variants may omit their inner parentheses,
/// so `Chiang(beta_m: 0.3)` and `Path(max_depth: 8)` read naturally.
pub fn ron_options() -> ron::Options {
    ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES)
}
