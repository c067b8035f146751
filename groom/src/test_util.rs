//! Test grooms for the unit tests of this crate and of the crates that build on grooms (the
//! `test-util` feature): a few strands, a synthetic `.hair` file, the shared data set's files.

use crate::cyhair::{
    FLAG_COLOR, FLAG_POINTS, FLAG_SEGMENTS, FLAG_THICKNESS, FLAG_TRANSPARENCY, HEADER_BYTES,
};
use crate::HairGeometry;
use std::path::{Path, PathBuf};
use tress_core::math::{Vec2, Vec3};
use tress_core::rng::Pcg32;
use tress_core::sampling::sample_uniform_sphere;

/// Hair made of `strands`, every point of radius `radius`.
pub fn hair(strands: &[Vec<Vec3>], radius: f32) -> HairGeometry {
    let mut g = HairGeometry::empty("test hair");
    for s in strands {
        g.push_strand(s, radius);
    }
    g
}

/// `points` evenly spaced points from `from` to `to`.
pub fn line(from: Vec3, to: Vec3, points: usize) -> Vec<Vec3> {
    (0..points)
        .map(|i| from.lerp(to, i as f32 / (points - 1) as f32))
        .collect()
}

/// A uniform random direction.
pub fn rng_dir(rng: &mut Pcg32) -> Vec3 {
    sample_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()))
}

/// Optional per-strand and per-point arrays of a synthetic `.hair` file.
#[derive(Default)]
pub struct HairArrays {
    /// Segments per strand.
    pub segments: Option<Vec<u16>>,
    /// Thickness per point.
    pub thickness: Option<Vec<f32>>,
    /// Transparency per point.
    pub transparency: Option<Vec<f32>>,
    /// Colour per point.
    pub colors: Option<Vec<[f32; 3]>>,
}

/// A `.hair` file of `points` (and the arrays of `a`), its header claiming `header_strands`
/// strands of `default_segments` segments, default thickness 0.25, transparency 0.5 and colour
/// (0.1, 0.2, 0.3).
pub fn hair_file_bytes(
    header_strands: u32,
    points: &[[f32; 3]],
    a: &HairArrays,
    default_segments: u32,
) -> Vec<u8> {
    let flag = |present: bool, bit: u32| if present { bit } else { 0 };
    let flags = FLAG_POINTS
        | flag(a.segments.is_some(), FLAG_SEGMENTS)
        | flag(a.thickness.is_some(), FLAG_THICKNESS)
        | flag(a.transparency.is_some(), FLAG_TRANSPARENCY)
        | flag(a.colors.is_some(), FLAG_COLOR);
    let mut b = Vec::new();
    b.extend_from_slice(b"HAIR");
    for v in [header_strands, points.len() as u32, flags, default_segments] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in [0.25f32, 0.5, 0.1, 0.2, 0.3] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.resize(HEADER_BYTES, 0);
    b[40..48].copy_from_slice(b"test hai");
    if let Some(s) = &a.segments {
        s.iter().for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
    }
    let floats = points
        .iter()
        .flatten()
        .chain(a.thickness.iter().flatten())
        .chain(a.transparency.iter().flatten())
        .chain(a.colors.iter().flatten().flatten());
    floats.for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
    b
}

/// A hair file of the real data set, `../shared/data/hair` beside the workspace. The tests that
/// read one are ignored, their names hold `shared_data`, and CI runs them where the data is
/// (`.ci/run`); run without it, they fail here.
pub fn shared_data(name: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/hair")
        .join(name);
    assert!(
        p.exists(),
        "{} is absent: this test needs the real data set beside the workspace (../shared/data)",
        p.display()
    );
    p
}
