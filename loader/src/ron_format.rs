//! RON as tress reads and writes it.

/// RON options for everything tress parses: newtype variants may omit their inner parentheses,
/// so `Chiang(beta_m: 0.3)` and `Path(max_depth: 8)` read naturally.
pub fn options() -> ron::Options {
    ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES)
}
