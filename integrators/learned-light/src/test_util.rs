//! Helpers of this crate's unit tests.

use tress_core::math::{Aabb, Vec3};

/// The box from the origin to (1, 1, 1).
pub(crate) fn unit_box() -> Aabb {
    Aabb {
        min: Vec3::ZERO,
        max: Vec3::ONE,
    }
}
