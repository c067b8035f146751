//! Reading the binary hair formats (HAIR, TressFX, USC-HairSalon): whole regular files, and
//! little-endian fields at byte offsets the readers have already checked against the length.

use std::path::Path;
use tress_core::math::Vec3;

/// The bytes of a hair file whose format has no fiber radius, after checking the `radius`
/// option the reader supplies instead.
pub(crate) fn read_with_radius(path: &Path, radius: f32) -> crate::Result<Vec<u8>> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(crate::Error::InvalidOption(crate::InvalidOption {
            object: path.display().to_string(),
            field: "radius",
            reason: format!("must be finite and positive, got {radius}"),
        }));
    }
    tress_core::files::read_regular(path).map_err(|source| crate::Error::Io {
        path: path.to_owned(),
        source,
    })
}

/// The `u32` at byte `at`.
pub(crate) fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// The `f32` at byte `at`.
pub(crate) fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_bits(u32_at(b, at))
}

/// Three consecutive `f32`s at byte `at`.
pub(crate) fn vec3_at(b: &[u8], at: usize) -> Vec3 {
    Vec3::new(f32_at(b, at), f32_at(b, at + 4), f32_at(b, at + 8))
}
