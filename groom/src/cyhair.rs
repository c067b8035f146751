//! Reader for Cem Yuksel's HAIR format (`.hair`).
//!
//! Layout (little-endian): a 128-byte header — `"HAIR"`, u32 strand count, u32 total point
//! count, u32 flags, u32 default segment count, f32 default thickness, f32 default
//! transparency, 3×f32 default colour, 88-byte info string — then, in this order and only if
//! the flag bit is set: bit 0 u16 segments per strand, bit 1 3×f32 points, bit 2 f32 thickness
//! per point, bit 3 f32 transparency per point, bit 4 3×f32 colour per point. A strand with `s`
//! segments has `s + 1` points. Thickness is a *diameter*: radius = thickness / 2.

use crate::error::{format_error, Result};
use crate::geometry::{HairAttribute, HairGeometry};
use crate::le_bytes::{f32_at, u32_at, vec3_at};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use tress_core::math::{Rgb, Vec3};

pub(crate) const HEADER_BYTES: usize = 128;
pub(crate) const FLAG_SEGMENTS: u32 = 1 << 0;
pub(crate) const FLAG_POINTS: u32 = 1 << 1;
pub(crate) const FLAG_THICKNESS: u32 = 1 << 2;
pub(crate) const FLAG_TRANSPARENCY: u32 = 1 << 3;
pub(crate) const FLAG_COLOR: u32 = 1 << 4;

/// A `.hair` file to load.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct HairFile {
    /// Path of the `.hair` file, used as given (resolve relative paths first).
    pub path: PathBuf,
    /// Rotate Z-up data to tress's Y-up world ((x, y, z) → (x, z, −y)). Cem Yuksel's published
    /// models are Z-up, so this defaults to true.
    #[serde(default = "yes")]
    pub z_up: bool,
}

fn yes() -> bool {
    true
}

impl HairFile {
    /// The file at `path`, converted from Z-up (the default).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        HairFile {
            path: path.into(),
            z_up: true,
        }
    }

    /// Reads and validates the file.
    pub fn read(&self) -> Result<HairGeometry> {
        let bytes =
            tress_core::files::read_regular(&self.path).map_err(|source| crate::Error::Io {
                path: self.path.clone(),
                source,
            })?;
        let mut hair = parse(&bytes, &self.path)?;
        if self.z_up {
            hair.z_up_to_y_up();
        }
        Ok(hair)
    }
}

/// The header fields, as stored.
#[derive(Clone, Debug, PartialEq)]
struct Header {
    strands: u32,
    points: u32,
    flags: u32,
    default_segments: u32,
    default_thickness: f32,
    default_transparency: f32,
    default_color: Rgb,
}

/// Parses a whole `.hair` file held in memory; `path` is only used in errors.
fn parse(bytes: &[u8], path: &Path) -> Result<HairGeometry> {
    let fail = |reason: String| format_error(path, reason);
    if bytes.len() < HEADER_BYTES {
        return Err(fail(format!(
            "truncated header: the file has {} bytes, a HAIR header needs {HEADER_BYTES}",
            bytes.len()
        )));
    }
    if &bytes[0..4] != b"HAIR" {
        return Err(fail(format!(
            "not a HAIR file: signature is {:?}, expected \"HAIR\"",
            String::from_utf8_lossy(&bytes[0..4])
        )));
    }
    let h = Header {
        strands: u32_at(bytes, 4),
        points: u32_at(bytes, 8),
        flags: u32_at(bytes, 12),
        default_segments: u32_at(bytes, 16),
        default_thickness: f32_at(bytes, 20),
        default_transparency: f32_at(bytes, 24),
        default_color: vec3_at(bytes, 28),
    };
    if h.flags & !0x1f != 0 {
        tracing::warn!(
            "{}: unknown HAIR flag bits {:#x} ignored",
            path.display(),
            h.flags & !0x1f
        );
    }
    if h.strands == 0 {
        return Err(fail("the header says the file has no strands".into()));
    }
    if h.strands > h.points {
        return Err(fail(format!(
            "the header says {} strands but only {} points (every strand has at least one)",
            h.strands, h.points
        )));
    }
    if h.flags & FLAG_POINTS == 0 {
        return Err(fail(
            "the file has no points array (flag bit 1 is not set)".into(),
        ));
    }

    // Sizes in u64 so that absurd header counts cannot overflow; they are checked against the
    // file length before anything is allocated.
    let (s, p) = (h.strands as u64, h.points as u64);
    let has = |bit: u32| h.flags & bit != 0;
    let mut offset = HEADER_BYTES as u64;
    let mut take = |present: bool, bytes_each: u64, count: u64| -> Option<usize> {
        present.then(|| {
            let at = offset;
            offset += bytes_each * count;
            at as usize
        })
    };
    let seg_at = take(has(FLAG_SEGMENTS), 2, s);
    let pts_at = take(true, 12, p);
    let thick_at = take(has(FLAG_THICKNESS), 4, p);
    let transp_at = take(has(FLAG_TRANSPARENCY), 4, p);
    let color_at = take(has(FLAG_COLOR), 12, p);
    let needed = offset;
    if (bytes.len() as u64) < needed {
        return Err(fail(format!(
            "truncated: the header ({} strands, {} points, flags {:#x}) needs {needed} bytes, the file has {}",
            h.strands,
            h.points,
            h.flags,
            bytes.len()
        )));
    }
    if bytes.len() as u64 > needed {
        tracing::warn!(
            "{}: {} trailing bytes after the HAIR arrays ignored",
            path.display(),
            bytes.len() as u64 - needed
        );
    }

    // Strand offsets from the segments array or the default segment count.
    let mut strand_offsets = Vec::with_capacity(h.strands as usize + 1);
    strand_offsets.push(0u32);
    let mut total = 0u64;
    for i in 0..h.strands as usize {
        let segs = match seg_at {
            Some(at) => u16::from_le_bytes([bytes[at + 2 * i], bytes[at + 2 * i + 1]]) as u64,
            None => h.default_segments as u64,
        };
        total += segs + 1;
        if total > p {
            break;
        }
        strand_offsets.push(total as u32);
    }
    if total != p {
        return Err(fail(format!(
            "the strands have {}{} points in total (segments {}), but the header says {}",
            if total > p { "at least " } else { "" },
            total,
            if seg_at.is_some() {
                "array".to_string()
            } else {
                format!("default {}", h.default_segments)
            },
            h.points
        )));
    }

    let n = p as usize;
    let pts_at = pts_at.unwrap_or(HEADER_BYTES);
    let points: Vec<Vec3> = (0..n).map(|i| vec3_at(bytes, pts_at + 12 * i)).collect();
    let radii: Vec<f32> = match thick_at {
        Some(at) => (0..n).map(|i| 0.5 * f32_at(bytes, at + 4 * i)).collect(),
        None => vec![0.5 * h.default_thickness; n],
    };
    let transparency = Some(match transp_at {
        Some(at) => HairAttribute::PerPoint((0..n).map(|i| f32_at(bytes, at + 4 * i)).collect()),
        None => HairAttribute::Uniform(h.default_transparency),
    });
    let colors = Some(match color_at {
        Some(at) => HairAttribute::PerPoint((0..n).map(|i| vec3_at(bytes, at + 12 * i)).collect()),
        None => HairAttribute::Uniform(h.default_color),
    });
    let hair = HairGeometry {
        name: path.display().to_string(),
        points,
        radii,
        strand_offsets,
        colors,
        transparency,
        orientations: None,
    };
    hair.validate()?;
    Ok(hair)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{hair_file_bytes, shared_data, HairArrays};

    fn nine_points() -> Vec<[f32; 3]> {
        (0..9)
            .map(|i| [i as f32, 2.0 * i as f32, -(i as f32)])
            .collect()
    }

    fn every_array() -> HairArrays {
        HairArrays {
            segments: Some(vec![1, 3, 2]),
            thickness: Some((0..9).map(|i| 0.1 * (i + 1) as f32).collect()),
            transparency: Some((0..9).map(|i| 0.05 * i as f32).collect()),
            colors: Some((0..9).map(|i| [i as f32 / 10.0, 0.5, 1.0]).collect()),
        }
    }

    #[test]
    fn every_flag_is_honoured() {
        let bytes = hair_file_bytes(3, &nine_points(), &every_array(), 99);
        let g = parse(&bytes, Path::new("synthetic.hair")).unwrap();
        assert_eq!(g.strand_offsets, vec![0, 2, 6, 9]);
        assert_eq!(g.points[5], Vec3::new(5.0, 10.0, -5.0));
        assert!(
            (g.radii[4] - 0.25).abs() < 1e-6,
            "radius is half the thickness"
        );
        assert_eq!(
            g.transparency,
            Some(HairAttribute::PerPoint(
                (0..9).map(|i| 0.05 * i as f32).collect()
            ))
        );
        assert_eq!(g.colors.as_ref().unwrap().at(0, 7), Rgb::new(0.7, 0.5, 1.0));

        // Without the optional arrays the header defaults apply.
        let plain = HairArrays::default();
        let g = parse(
            &hair_file_bytes(3, &nine_points(), &plain, 2),
            Path::new("d.hair"),
        )
        .unwrap();
        assert_eq!(g.strand_offsets, vec![0, 3, 6, 9]);
        assert!(g.radii.iter().all(|&r| (r - 0.125).abs() < 1e-7));
        assert_eq!(g.transparency, Some(HairAttribute::Uniform(0.5)));
        assert_eq!(
            g.colors,
            Some(HairAttribute::Uniform(Rgb::new(0.1, 0.2, 0.3)))
        );
    }

    #[test]
    fn z_up_conversion_on_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("z.hair");
        std::fs::write(&path, hair_file_bytes(3, &nine_points(), &every_array(), 0)).unwrap();
        let g = HairFile::new(&path).read().unwrap();
        assert_eq!(g.points[5], Vec3::new(5.0, -5.0, -10.0));
        let raw = HairFile {
            path: path.clone(),
            z_up: false,
        }
        .read()
        .unwrap();
        assert_eq!(raw.points[5], Vec3::new(5.0, 10.0, -5.0));
        let missing = HairFile::new(dir.path().join("nope.hair"))
            .read()
            .unwrap_err();
        assert!(missing.to_string().contains("nope.hair"), "{missing}");
    }

    #[test]
    fn malformed_files_are_errors_not_panics() {
        let good = hair_file_bytes(3, &nine_points(), &every_array(), 0);
        for len in 0..good.len() {
            let e = parse(&good[..len], Path::new("cut.hair"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("cut.hair") && e.contains("truncated"),
                "{len}: {e}"
            );
        }
        let mut bad = good.clone();
        bad[0..4].copy_from_slice(b"RIAH");
        let e = parse(&bad, Path::new("x.hair")).unwrap_err().to_string();
        assert!(e.contains("signature"), "{e}");
        // Huge counts in the header are refused before allocating.
        for at in [4, 8] {
            let mut huge = good.clone();
            huge[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
            assert!(parse(&huge, Path::new("h.hair")).is_err());
        }
        // Huge strand or default segment counts with no segments array.
        for at in [4, 16] {
            let mut huge = hair_file_bytes(9, &nine_points(), &HairArrays::default(), 0);
            huge[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
            assert!(parse(&huge, Path::new("h.hair")).is_err());
        }
        // Segment counts that disagree with the point count.
        let mut a = every_array();
        a.segments = Some(vec![1, 3, 3]);
        let e = parse(
            &hair_file_bytes(3, &nine_points(), &a, 0),
            Path::new("s.hair"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("header says 9"), "{e}");
        // Bad values are caught by validation, naming the file.
        let mut a = every_array();
        a.thickness.as_mut().unwrap()[3] = -1.0;
        let e = parse(
            &hair_file_bytes(3, &nine_points(), &a, 0),
            Path::new("t.hair"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("t.hair") && e.contains("radius"), "{e}");
        let mut pts = nine_points();
        pts[2][1] = f32::NAN;
        assert!(parse(
            &hair_file_bytes(3, &pts, &every_array(), 0),
            Path::new("n.hair")
        )
        .is_err());
        // No strands, no points array.
        assert!(parse(
            &hair_file_bytes(0, &[], &HairArrays::default(), 0),
            Path::new("e.hair")
        )
        .is_err());
        let mut nopts = good.clone();
        nopts[12..16].copy_from_slice(&FLAG_SEGMENTS.to_le_bytes());
        assert!(parse(&nopts, Path::new("p.hair")).is_err());
    }

    /// The real file holds what its README says: the reader reads a file another tool wrote.
    #[test]
    #[ignore = "needs ../shared/data (the real groom): CI runs it with --ignored"]
    fn shared_data_straight_hair_matches_its_readme() {
        let g = HairFile {
            path: shared_data("straight.hair"),
            z_up: false,
        }
        .read()
        .unwrap();
        assert_eq!(g.strand_count(), 10_000);
        assert_eq!(g.point_count(), 160_000);
        assert!((0..10_000).all(|i| g.strand(i).len() == 16));
        assert!(g.radii.iter().all(|&r| r == 0.05), "default thickness 0.1");
        match g.transparency {
            Some(HairAttribute::Uniform(t)) => assert!((t - 0.35578).abs() < 1e-5, "{t}"),
            ref other => panic!("expected a default transparency, got {other:?}"),
        }
        match g.colors.as_ref().unwrap() {
            HairAttribute::PerPoint(c) => {
                assert_eq!(c.len(), 160_000);
                let want = Rgb::new(1.0, 0.92549, 0.56863);
                assert!(c.iter().all(|&x| (x - want).abs().max_element() < 1e-5));
            }
            other => panic!("expected a colour array, got {other:?}"),
        }
        let b = g.bounds();
        let close = |a: f32, b: f32| (a - b).abs() < 0.01;
        assert!(close(b.min.x, -32.50) && close(b.max.x, 30.90), "{b:?}");
        assert!(close(b.min.y, -33.90) && close(b.max.y, 24.07), "{b:?}");
        assert!(close(b.min.z, -22.71) && close(b.max.z, 63.68), "{b:?}");
        assert!((g.mean_strand_length() - 78.2).abs() < 0.1);
        // Roots near z ≈ 60 (Z up).
        let mean_root_z: f32 = (0..10_000)
            .map(|i| g.points[g.strand(i).start].z)
            .sum::<f32>()
            / 10_000.0;
        assert!(mean_root_z > 45.0, "{mean_root_z}");
    }
}
