//! Little-endian fields of the binary hair formats (HAIR, TressFX), read at byte offsets the
//! readers have already checked against the file's length.

use tress_core::math::Vec3;

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
