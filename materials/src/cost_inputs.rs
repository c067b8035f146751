//! The inputs a BCSDF's cost per call is timed on, shared by `tress bench` and the Huang cost
//! harness (`tests/huang_cost.rs`) so that their figures are of the same calls.

use tress_core::math::{Vec2, Vec3};
use tress_core::rng::Pcg32;
use tress_core::sampling::sample_uniform_sphere;

/// [`CostInputs::LEN`] calls' arguments from fixed seeds: uniform direction pairs `(ω_o, ω_i)`,
/// offsets h uniform in [−1, 1] and sampling numbers.
pub struct CostInputs {
    /// `(ω_o, ω_i)` pairs.
    pub dirs: Vec<(Vec3, Vec3)>,
    /// Offsets across the fiber.
    pub hs: Vec<f32>,
    /// Numbers for `sample` and `sample_weight`.
    pub us: Vec<[f32; 4]>,
}

impl CostInputs {
    /// Inputs per set: calls cycle through them (`i % LEN`).
    pub const LEN: usize = 4096;

    /// The inputs (the same every time).
    pub fn new() -> Self {
        let mut rng = Pcg32::new(11, 0);
        let mut dir = || sample_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        let dirs = (0..Self::LEN).map(|_| (dir(), dir())).collect();
        let mut rng = Pcg32::new(12, 0);
        let hs = (0..Self::LEN).map(|_| 2.0 * rng.next_f32() - 1.0).collect();
        let us = (0..Self::LEN)
            .map(|_| std::array::from_fn(|_| rng.next_f32()))
            .collect();
        CostInputs { dirs, hs, us }
    }
}

impl Default for CostInputs {
    fn default() -> Self {
        Self::new()
    }
}
