//! Hair geometry as flat arrays, per-object transforms and strand subsampling.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use tress_core::limits::Limits;
use tress_core::math::{Aabb, Rgb, Vec3};
use tress_core::rng::Pcg32;

/// What one hair point costs once loaded and built: its position, radius and colour, and
/// Embree's curve segment and BVH share (a pbrt groom of 20.5 M segments took 2.5 GB).
pub const BYTES_PER_POINT: f64 = 128.0;

/// Refuses hair that `points` points would make too large for the memory limit of `limits`,
/// with what the scene's objects before it take ([`Limits::scene_gib`]), before any is
/// allocated. `how` says what makes that many (`strands × points_per_strand`) for the message.
pub fn check_point_memory(
    object: &str,
    field: &'static str,
    how: &str,
    points: f64,
    limits: &Limits,
) -> Result<()> {
    let need_gib = points * BYTES_PER_POINT / (1u64 << 30) as f64;
    limits.check_scene_memory(need_gib).map_err(|reason| {
        Error::InvalidOption(crate::InvalidOption {
            object: object.to_owned(),
            field,
            reason: format!("{how}: {points:.3e} hair points, {reason}"),
        })
    })
}

/// A per-hair-object attribute that a file may store once, per strand or per point.
#[derive(Clone, Debug, PartialEq)]
pub enum HairAttribute<T> {
    /// One value for every point.
    Uniform(T),
    /// One value per strand.
    PerStrand(Vec<T>),
    /// One value per point.
    PerPoint(Vec<T>),
}

impl<T: Copy> HairAttribute<T> {
    /// The value at point `point` of strand `strand`.
    pub fn at(&self, strand: usize, point: usize) -> T {
        match self {
            HairAttribute::Uniform(v) => *v,
            HairAttribute::PerStrand(v) => v[strand],
            HairAttribute::PerPoint(v) => v[point],
        }
    }

    fn check_len(&self, what: &str, strands: usize, points: usize) -> Result<(), String> {
        let (got, want, per) = match self {
            HairAttribute::Uniform(_) => return Ok(()),
            HairAttribute::PerStrand(v) => (v.len(), strands, "strand"),
            HairAttribute::PerPoint(v) => (v.len(), points, "point"),
        };
        if got == want {
            Ok(())
        } else {
            Err(format!(
                "{what} array has {got} entries, expected one per {per} ({want})"
            ))
        }
    }

    /// The attribute restricted to the given strands (subsampling).
    fn select(&self, keep: &[u32], src: &HairGeometry) -> Self {
        match self {
            HairAttribute::Uniform(v) => HairAttribute::Uniform(*v),
            HairAttribute::PerStrand(v) => {
                HairAttribute::PerStrand(keep.iter().map(|&s| v[s as usize]).collect())
            }
            HairAttribute::PerPoint(v) => HairAttribute::PerPoint(
                keep.iter()
                    .flat_map(|&s| v[src.strand(s as usize)].iter().copied())
                    .collect(),
            ),
        }
    }
}

/// Hair as flat arrays: strand `i` is `points[strand_offsets[i]..strand_offsets[i + 1]]`,
/// ordered root → tip.
#[derive(Clone, Debug, PartialEq)]
pub struct HairGeometry {
    /// Where the hair came from (a file path or a generator description), used in errors.
    pub name: String,
    /// Points of all strands, concatenated (see `strand_offsets`).
    pub points: Vec<Vec3>,
    /// Fiber radius at each point (world units).
    pub radii: Vec<f32>,
    /// `strand_count + 1` offsets into `points`, starting at 0 and ending at `points.len()`.
    pub strand_offsets: Vec<u32>,
    /// Linear RGB colour stored in the file, if any.
    pub colors: Option<HairAttribute<Rgb>>,
    /// Transparency (0 opaque … 1 invisible) stored in the file, if any.
    pub transparency: Option<HairAttribute<f32>>,
    /// The fibers' orientation about their axes stored in the file (USD `normals`), if any:
    /// a direction across the fiber, the major axis of an elliptical one.
    pub orientations: Option<HairAttribute<Vec3>>,
}

impl HairGeometry {
    /// No strands yet, and no colours or transparency: what readers fill strand by strand.
    pub fn empty(name: impl Into<String>) -> Self {
        HairGeometry {
            name: name.into(),
            points: Vec::new(),
            radii: Vec::new(),
            strand_offsets: vec![0],
            colors: None,
            transparency: None,
            orientations: None,
        }
    }

    /// Appends a strand through `points` (root → tip), every point of radius `radius`: hair
    /// built in code. Per-point colours or transparency, where the hair has them, are the
    /// caller's to extend.
    pub fn push_strand(&mut self, points: &[Vec3], radius: f32) {
        self.points.extend_from_slice(points);
        self.radii.resize(self.points.len(), radius);
        self.strand_offsets.push(self.points.len() as u32);
    }

    /// Number of strands.
    pub fn strand_count(&self) -> usize {
        self.strand_offsets.len().saturating_sub(1)
    }

    /// Number of points over all strands.
    pub fn point_count(&self) -> usize {
        self.points.len()
    }

    /// Bytes its arrays hold: what keeping it in memory costs.
    pub fn heap_bytes(&self) -> usize {
        fn attribute<T>(a: &Option<HairAttribute<T>>) -> usize {
            match a {
                Some(HairAttribute::PerStrand(v) | HairAttribute::PerPoint(v)) => {
                    std::mem::size_of_val(v.as_slice())
                }
                Some(HairAttribute::Uniform(_)) | None => 0,
            }
        }
        std::mem::size_of_val(self.points.as_slice())
            + std::mem::size_of_val(self.radii.as_slice())
            + std::mem::size_of_val(self.strand_offsets.as_slice())
            + attribute(&self.colors)
            + attribute(&self.transparency)
            + attribute(&self.orientations)
    }

    /// Polyline segments: one fewer than the points of each strand.
    pub fn segment_count(&self) -> usize {
        (0..self.strand_count())
            .map(|i| self.strand(i).len().saturating_sub(1))
            .sum()
    }

    /// The point range of strand `i`.
    pub fn strand(&self, i: usize) -> Range<usize> {
        self.strand_offsets[i] as usize..self.strand_offsets[i + 1] as usize
    }

    /// Bounds of the points (not padded by the radii).
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for &p in &self.points {
            b.grow(p);
        }
        b
    }

    /// Mean polyline length of the strands.
    pub fn mean_strand_length(&self) -> f32 {
        let n = self.strand_count();
        if n == 0 {
            return 0.0;
        }
        let total: f64 = (0..n)
            .map(|i| {
                self.points[self.strand(i)]
                    .windows(2)
                    .map(|w| w[0].distance(w[1]) as f64)
                    .sum::<f64>()
            })
            .sum();
        (total / n as f64) as f32
    }

    /// Checks the layout and values: at least one strand, consistent offsets and array lengths,
    /// finite coordinates, and finite positive radii.
    pub fn validate(&self) -> Result<()> {
        let fail = |reason: String| {
            Error::InvalidGeometry(crate::InvalidGeometry {
                object: self.name.clone(),
                reason,
            })
        };
        let strands = self.strand_count();
        if strands == 0 {
            return Err(fail("has no strands".into()));
        }
        if self.strand_offsets[0] != 0 {
            return Err(fail(format!(
                "strand offsets must start at 0, not {}",
                self.strand_offsets[0]
            )));
        }
        if let Some(i) = self.strand_offsets.windows(2).position(|w| w[1] < w[0]) {
            return Err(fail(format!("strand {i} has a negative point count")));
        }
        let last = self.strand_offsets[strands] as usize;
        if last != self.points.len() {
            return Err(fail(format!(
                "strand offsets end at {last} but there are {} points",
                self.points.len()
            )));
        }
        if self.radii.len() != self.points.len() {
            return Err(fail(format!(
                "{} radii for {} points",
                self.radii.len(),
                self.points.len()
            )));
        }
        if let Some(i) = self.points.iter().position(|p| !p.is_finite()) {
            return Err(fail(format!(
                "point {i} has a non-finite coordinate {:?}",
                self.points[i]
            )));
        }
        if let Some(i) = self.radii.iter().position(|r| !(r.is_finite() && *r > 0.0)) {
            return Err(fail(format!(
                "point {i} has radius {} (must be finite and positive)",
                self.radii[i]
            )));
        }
        if let Some(c) = &self.colors {
            c.check_len("colour", strands, self.points.len())
                .map_err(fail)?;
        }
        if let Some(t) = &self.transparency {
            t.check_len("transparency", strands, self.points.len())
                .map_err(fail)?;
        }
        if let Some(o) = &self.orientations {
            o.check_len("orientation", strands, self.points.len())
                .map_err(fail)?;
        }
        if self.segment_count() == 0 {
            return Err(fail("no strand has two or more points".into()));
        }
        Ok(())
    }

    /// Rotates Z-up data to tress's Y-up world: (x, y, z) → (x, z, −y), a −90° turn about x.
    pub fn z_up_to_y_up(&mut self) {
        for p in &mut self.points {
            *p = Vec3::new(p.x, p.z, -p.y);
        }
        let turn = |v: &mut Vec3| *v = Vec3::new(v.x, v.z, -v.y);
        match &mut self.orientations {
            None => {}
            Some(HairAttribute::Uniform(v)) => turn(v),
            Some(HairAttribute::PerStrand(v) | HairAttribute::PerPoint(v)) => {
                v.iter_mut().for_each(turn)
            }
        }
    }

    /// A deterministic subset of the strands: `round(fraction · strands)` of them (at least
    /// one), chosen by a partial Fisher–Yates shuffle seeded by `seed`, kept in their original
    /// order. Returns the subset and the original index of each kept strand.
    pub fn subsample(&self, fraction: f32, seed: u64) -> (HairGeometry, Vec<u32>) {
        let n = self.strand_count();
        let k = ((fraction as f64 * n as f64).round() as usize).clamp(1, n.max(1));
        let mut order: Vec<u32> = (0..n as u32).collect();
        if k < n {
            let mut rng = Pcg32::new(seed, 0x5eed_5eed);
            for i in 0..k {
                let j = i + ((rng.next_u32() as u64 * (n - i) as u64) >> 32) as usize;
                order.swap(i, j);
            }
            order.truncate(k);
            order.sort_unstable();
        }
        let mut out = HairGeometry {
            name: self.name.clone(),
            points: Vec::new(),
            radii: Vec::new(),
            strand_offsets: vec![0],
            colors: self.colors.as_ref().map(|c| c.select(&order, self)),
            transparency: self.transparency.as_ref().map(|t| t.select(&order, self)),
            orientations: self.orientations.as_ref().map(|o| o.select(&order, self)),
        };
        for &s in &order {
            let r = self.strand(s as usize);
            out.points.extend_from_slice(&self.points[r.clone()]);
            out.radii.extend_from_slice(&self.radii[r]);
            out.strand_offsets.push(out.points.len() as u32);
        }
        (out, order)
    }
}

/// A rotation in a scene file: Euler angles or an axis and an angle, in degrees.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum Rotation {
    /// Rotate about x, then y, then z (fixed world axes), by these angles in degrees.
    #[schemars(with = "[f32; 3]")]
    Euler(Vec3),
    /// Rotate by `degrees` about `axis` (any non-zero length), right-handed.
    AxisAngle {
        /// Rotation axis, finite and non-zero.
        #[schemars(with = "[f32; 3]")]
        axis: Vec3,
        /// Angle in degrees.
        degrees: f32,
    },
}

impl Default for Rotation {
    fn default() -> Self {
        Rotation::Euler(Vec3::ZERO)
    }
}

/// A similarity transform applied to an object's points: scale, then rotate, then translate.
///
/// The scale is uniform so that fibers stay round: radii are multiplied by it too.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Transform {
    /// Uniform scale factor, finite and positive (default 1); multiplies the radii too.
    pub scale: f32,
    /// Rotation applied after the scale (default none).
    pub rotate: Rotation,
    /// Offset added last, in world units (default 0).
    #[schemars(with = "[f32; 3]")]
    pub translate: Vec3,
}

impl Default for Transform {
    fn default() -> Self {
        Transform {
            scale: 1.0,
            rotate: Rotation::default(),
            translate: Vec3::ZERO,
        }
    }
}

impl Transform {
    /// Checks that every number is finite, the scale positive and the rotation axis non-zero.
    pub fn validate(&self, object: &str) -> Result<()> {
        let bad = |reason: String| {
            Error::InvalidOption(crate::InvalidOption {
                object: object.to_owned(),
                field: "transform",
                reason,
            })
        };
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(bad(format!(
                "scale must be finite and positive, got {}",
                self.scale
            )));
        }
        if !self.translate.is_finite() {
            return Err(bad(format!(
                "translate must be finite, got {:?}",
                self.translate
            )));
        }
        match &self.rotate {
            Rotation::Euler(e) if !e.is_finite() => {
                Err(bad(format!("Euler angles must be finite, got {e:?}")))
            }
            Rotation::AxisAngle { axis, degrees }
                if !(degrees.is_finite() && tress_core::math::unit(*axis).is_some()) =>
            {
                Err(bad(format!(
                    "axis-angle needs a finite non-zero axis and a finite angle, got {axis:?}, {degrees}"
                )))
            }
            _ => Ok(()),
        }
    }

    /// The rotation as a unit quaternion.
    pub fn rotation(&self) -> glam::Quat {
        match &self.rotate {
            Rotation::Euler(e) => {
                glam::Quat::from_rotation_z(e.z.to_radians())
                    * glam::Quat::from_rotation_y(e.y.to_radians())
                    * glam::Quat::from_rotation_x(e.x.to_radians())
            }
            Rotation::AxisAngle { axis, degrees } => {
                // Any non-zero length: (1e-30, 0, 0) is as good an axis as (1, 0, 0).
                let axis = tress_core::math::unit(*axis).unwrap_or(Vec3::Y);
                glam::Quat::from_axis_angle(axis, degrees.to_radians())
            }
        }
    }

    /// The transform as a matrix (for points).
    pub fn matrix(&self) -> glam::Affine3A {
        glam::Affine3A::from_scale_rotation_translation(
            Vec3::splat(self.scale),
            self.rotation(),
            self.translate,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn three_strands() -> HairGeometry {
        HairGeometry {
            name: "test".into(),
            points: (0..9).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect(),
            radii: vec![0.1; 9],
            strand_offsets: vec![0, 2, 6, 9],
            colors: Some(HairAttribute::PerStrand(vec![Rgb::X, Rgb::Y, Rgb::Z])),
            transparency: Some(HairAttribute::PerPoint((0..9).map(|i| i as f32).collect())),
            orientations: None,
        }
    }

    #[test]
    fn pushed_strands_are_valid_hair_with_their_radii() {
        let mut g = HairGeometry::empty("built");
        g.push_strand(&[Vec3::ZERO, Vec3::X], 0.1);
        g.push_strand(&[Vec3::Y, Vec3::ONE, 2.0 * Vec3::ONE], 0.2);
        g.validate().unwrap();
        assert_eq!((g.strand_count(), g.segment_count()), (2, 3));
        assert_eq!(g.strand(1), 2..5);
        assert_eq!(g.radii, [0.1, 0.1, 0.2, 0.2, 0.2]);
    }

    #[test]
    fn validation_names_the_object_and_problem() {
        let mut g = three_strands();
        g.validate().unwrap();
        g.points[4].y = f32::NAN;
        let e = g.validate().unwrap_err().to_string();
        assert!(e.contains("test") && e.contains("point 4"), "{e}");
        let mut g = three_strands();
        g.radii[3] = -1.0;
        assert!(g.validate().unwrap_err().to_string().contains("radius -1"));
        let mut g = three_strands();
        g.radii[3] = 0.0;
        assert!(g.validate().is_err());
        let mut g = three_strands();
        g.strand_offsets = vec![0];
        assert!(g.validate().unwrap_err().to_string().contains("no strands"));
        let mut g = three_strands();
        g.colors = Some(HairAttribute::PerPoint(vec![Rgb::ONE; 3]));
        assert!(g.validate().unwrap_err().to_string().contains("colour"));
    }

    #[test]
    fn subsampling_is_deterministic_and_keeps_attributes_aligned() {
        let g = three_strands();
        let (a, ids_a) = g.subsample(0.67, 7);
        let (b, ids_b) = g.subsample(0.67, 7);
        assert_eq!(a, b);
        assert_eq!(ids_a, ids_b);
        assert_eq!(a.strand_count(), 2);
        a.validate().unwrap();
        for (slot, &orig) in ids_a.iter().enumerate() {
            assert_eq!(a.points[a.strand(slot)], g.points[g.strand(orig as usize)]);
            assert_eq!(
                a.colors.as_ref().unwrap().at(slot, 0),
                g.colors.as_ref().unwrap().at(orig as usize, 0)
            );
            let first = a.strand(slot).start;
            assert_eq!(
                a.transparency.as_ref().unwrap().at(slot, first),
                g.strand(orig as usize).start as f32
            );
        }
        let (all, ids) = g.subsample(1.0, 3);
        assert_eq!(all, g);
        assert_eq!(ids, vec![0, 1, 2]);
        // Different seeds eventually pick different subsets.
        let picks: std::collections::HashSet<Vec<u32>> =
            (0..20).map(|s| g.subsample(0.34, s).1).collect();
        assert!(picks.len() > 1);
    }

    #[test]
    fn transform_order_is_scale_rotate_translate() {
        let t = Transform {
            scale: 2.0,
            rotate: Rotation::AxisAngle {
                axis: Vec3::Z,
                degrees: 90.0,
            },
            translate: Vec3::new(0.0, 0.0, 5.0),
        };
        t.validate("t").unwrap();
        let p = t.matrix().transform_point3(Vec3::X);
        assert!((p - Vec3::new(0.0, 2.0, 5.0)).length() < 1e-5, "{p}");
        let e = Transform {
            rotate: Rotation::Euler(Vec3::new(90.0, 90.0, 0.0)),
            ..Default::default()
        };
        // x first: Y → Z; then y: Z → X.
        let q = e.matrix().transform_point3(Vec3::Y);
        assert!((q - Vec3::X).length() < 1e-5, "{q}");
        let bad = Transform {
            scale: 0.0,
            ..Default::default()
        };
        assert!(bad.validate("obj").unwrap_err().to_string().contains("obj"));
    }
}
