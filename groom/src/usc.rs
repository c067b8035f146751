//! Reader for USC-HairSalon `.data` files (Hu et al. 2015, "Single-View Hair Modeling Using a
//! Hairstyle Database": 343 hairstyles on a common head).
//!
//! Layout (little-endian, no header beyond the count): i32 strand count, then per strand an
//! i32 point count n and n float3 positions, Y-up, in metres (a head is about 0.2 wide). Strands
//! of one point mark bald scalp samples and are skipped. The fiber radius is not in the file, so
//! it is an option (default 0.00004: 80 µm hair in metres).

use crate::error::{format_error, Result};
use crate::geometry::HairGeometry;
use crate::le_bytes::{read_with_radius, u32_at, vec3_at};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
#[cfg(test)]
use tress_core::math::Vec3;

/// A USC-HairSalon `.data` file to load.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct UscFile {
    /// Path of the `.data` file, used as given (resolve relative paths first).
    pub path: PathBuf,
    /// Fiber radius in file units (default 0.00004: 80 µm hair, the file being in metres).
    #[serde(default = "default_radius")]
    pub radius: f32,
}

fn default_radius() -> f32 {
    0.00004
}

impl UscFile {
    /// The file at `path` with the default fiber radius.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        UscFile {
            path: path.into(),
            radius: default_radius(),
        }
    }

    /// Reads and validates the file.
    pub fn read(&self) -> Result<HairGeometry> {
        let bytes = read_with_radius(&self.path, self.radius)?;
        parse(&bytes, &self.path, self.radius)
    }
}

fn parse(bytes: &[u8], path: &Path, radius: f32) -> Result<HairGeometry> {
    let fail = |reason: String| format_error(path, reason);
    if bytes.len() < 4 {
        return Err(fail(format!(
            "truncated: {} bytes, a USC-HairSalon file starts with a 4-byte strand count",
            bytes.len()
        )));
    }
    let strands = u32_at(bytes, 0) as i32;
    if strands <= 0 {
        return Err(fail(format!("the file says it has {strands} strands")));
    }
    // Each strand needs at least its 4-byte count: refuse absurd counts before allocating.
    if strands as u64 * 4 > bytes.len() as u64 - 4 {
        return Err(fail(format!(
            "the file says {strands} strands, more than its {} bytes can hold",
            bytes.len()
        )));
    }
    let mut hair = HairGeometry::empty(path.display().to_string());
    let mut at = 4usize;
    for s in 0..strands {
        if at + 4 > bytes.len() {
            return Err(fail(format!(
                "truncated: strand {s} of {strands} starts at byte {at}, past the end ({} bytes)",
                bytes.len()
            )));
        }
        let n = u32_at(bytes, at) as i32;
        at += 4;
        let size = (n.max(0) as u64) * 12;
        if n < 0 || at as u64 + size > bytes.len() as u64 {
            return Err(fail(format!(
                "truncated or corrupt: strand {s} says {n} points ({size} bytes at byte {at}), \
                 past the end of the file ({} bytes)",
                bytes.len()
            )));
        }
        let start = at;
        let points = (0..n as usize).map(move |i| vec3_at(bytes, start + 12 * i));
        at += size as usize;
        // One point: a bald scalp sample, not a strand.
        if n < 2 {
            continue;
        }
        hair.points.extend(points);
        hair.strand_offsets.push(hair.points.len() as u32);
    }
    if at != bytes.len() {
        return Err(fail(format!(
            "{} bytes after the last of the {strands} strands: not a USC-HairSalon file",
            bytes.len() - at
        )));
    }
    if hair.strand_count() == 0 {
        return Err(fail("no strand has two points or more".into()));
    }
    hair.radii = vec![radius; hair.points.len()];
    hair.validate()?;
    Ok(hair)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file of `strands` (point lists).
    fn write(strands: &[Vec<[f32; 3]>]) -> Vec<u8> {
        let mut b = (strands.len() as i32).to_le_bytes().to_vec();
        for s in strands {
            b.extend((s.len() as i32).to_le_bytes());
            for v in s.iter().flatten() {
                b.extend(v.to_le_bytes());
            }
        }
        b
    }

    fn read(bytes: &[u8]) -> Result<HairGeometry> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.data");
        std::fs::write(&path, bytes).unwrap();
        UscFile::new(&path).read()
    }

    #[test]
    fn strands_are_read_and_scalp_samples_skipped() {
        let strands = vec![
            vec![[0.0, 0.1, 0.0], [0.0, 0.05, 0.01], [0.0, 0.0, 0.02]],
            vec![[0.05, 0.1, 0.0]],
            vec![[0.1, 0.1, 0.0], [0.1, 0.0, 0.0]],
        ];
        let hair = read(&write(&strands)).unwrap();
        assert_eq!(hair.strand_count(), 2);
        assert_eq!(hair.point_count(), 5);
        assert_eq!(hair.points[3], Vec3::new(0.1, 0.1, 0.0));
        assert!(hair.radii.iter().all(|&r| r == default_radius()));
    }

    #[test]
    fn bad_files_are_errors_naming_the_problem() {
        let good = write(&[vec![[0.0; 3], [1.0, 0.0, 0.0]]]);
        let mut absurd = good.clone();
        absurd[..4].copy_from_slice(&i32::MAX.to_le_bytes());
        let mut long_strand = good.clone();
        long_strand[4..8].copy_from_slice(&1_000_000i32.to_le_bytes());
        let mut trailing = good.clone();
        trailing.extend([0u8; 5]);
        let cases: [(&[u8], &str); 7] = [
            (&[1, 0], "truncated"),
            (&0i32.to_le_bytes(), "0 strands"),
            (&absurd, "more than its"),
            (&long_strand, "past the end"),
            (&good[..good.len() - 3], "past the end"),
            (&trailing, "5 bytes after"),
            (&write(&[vec![[0.0; 3]]]), "no strand"),
        ];
        for (bytes, expect) in cases {
            let e = read(bytes).unwrap_err().to_string();
            assert!(e.contains("h.data") && e.contains(expect), "{expect}: {e}");
        }
        let nan = write(&[vec![[0.0; 3], [f32::NAN, 0.0, 0.0]]]);
        assert!(read(&nan).is_err());
        let e = UscFile {
            radius: 0.0,
            ..UscFile::new("x.data")
        }
        .read()
        .unwrap_err()
        .to_string();
        assert!(e.contains("radius"), "{e}");
    }
}
