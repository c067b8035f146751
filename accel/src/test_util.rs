//! Builders and data shared by the unit tests of several modules.

use crate::HairGeometry;
use std::path::{Path, PathBuf};
use tress_core::math::{Vec2, Vec3};
use tress_core::rng::Pcg32;
use tress_core::sampling::sample_uniform_sphere;

/// Hair made of `strands`, every point of radius `radius`.
pub(crate) fn hair(strands: &[Vec<Vec3>], radius: f32) -> HairGeometry {
    let mut g = HairGeometry::empty("test hair");
    for s in strands {
        g.push_strand(s, radius);
    }
    g
}

/// `points` evenly spaced points from `from` to `to`.
pub(crate) fn line(from: Vec3, to: Vec3, points: usize) -> Vec<Vec3> {
    (0..points)
        .map(|i| from.lerp(to, i as f32 / (points - 1) as f32))
        .collect()
}

/// A uniform random direction.
pub(crate) fn rng_dir(rng: &mut Pcg32) -> Vec3 {
    sample_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()))
}

/// A hair file of the shared data set, or None (said on stdout) where the checkout lacks it.
pub(crate) fn shared_data(name: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/hair")
        .join(name);
    if p.exists() {
        Some(p)
    } else {
        println!("skipping: {} is absent", p.display());
        None
    }
}
