//! The per-object options that say how a hair object's strands become Embree curves.

use crate::curves::{CurveBasis, CurveShape, Overlaps};
use crate::error::Result;
use serde::{Deserialize, Serialize};
use tress_core::limits::Limits;
use tress_groom::{ChildStrands, HairGeometry, Transform};

/// How a hair object is turned into Embree curves (every field has a default).
///
/// ```ron
/// (basis: CatmullRom, curve: Round, radius_scale: 1.5, tip_scale: 0.3,
///  transform: (scale: 0.1, rotate: Euler(0, 90, 0), translate: (0, 1, 0)),
///  strand_fraction: 0.1, strand_seed: 7,
///  children: Some(per_guide: 8, radius: 0.05, seed: 1))
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct HairOptions {
    /// How polylines become curves: `Linear` (the default), `CatmullRom` or `BSpline`.
    pub basis: CurveBasis,
    /// Ray-facing ribbons (`Flat`, the default) or tubes (`Round`).
    pub curve: CurveShape,
    /// What a ray that starts inside another fiber meets of it: `PassThrough` (the default: it
    /// passes through that fiber, which conserves energy where fibers interpenetrate, as
    /// Mitsuba 3 does) or `Scatter` (it scatters where it leaves that fiber: the convention
    /// before, which traps light in the overlaps).
    pub overlaps: Overlaps,
    /// Multiplies every radius.
    pub radius_scale: f32,
    /// Root-to-tip taper: the radius is multiplied by `1 + (tip_scale − 1)·v` with v = 0 at the
    /// root and 1 at the tip (1 = no taper).
    pub tip_scale: f32,
    /// Applied after the reader's own axis conversion; its scale also scales the radii.
    pub transform: Transform,
    /// Keep this fraction of the strands, in (0, 1] (previews).
    pub strand_fraction: f32,
    /// Seed of the strand subset.
    pub strand_seed: u64,
    /// Child strands grown around every strand (taken as a guide) before the subset is drawn
    /// (default none); see [`ChildStrands`].
    pub children: Option<ChildStrands>,
    /// Where the fibers' orientation about their axes (an elliptical fiber's major axis) comes
    /// from: `Groom` (the default: the file's, e.g. USD `normals`, else `ScalpNormal`),
    /// `ScalpNormal` (a minimum-twist frame from the root, starting away from the centre of the
    /// object's roots) or `Fixed(x, y, z)` (toward a world direction). Only hair models that
    /// use it (Huang with an aspect ratio below 1) see it, and only scenes with such a model
    /// store it.
    pub orientation: crate::FiberOrientation,
}

impl Default for HairOptions {
    fn default() -> Self {
        HairOptions {
            basis: CurveBasis::Linear,
            curve: CurveShape::Flat,
            overlaps: Overlaps::PassThrough,
            radius_scale: 1.0,
            tip_scale: 1.0,
            transform: Transform::default(),
            strand_fraction: 1.0,
            strand_seed: 0,
            children: None,
            orientation: crate::FiberOrientation::Groom,
        }
    }
}

impl HairOptions {
    pub(crate) fn validate(&self, object: &str) -> Result<()> {
        let bad = |field: &'static str, reason: String| {
            crate::Error::InvalidOption(tress_groom::InvalidOption {
                object: object.to_owned(),
                field,
                reason,
            })
        };
        if !(self.radius_scale.is_finite() && self.radius_scale > 0.0) {
            return Err(bad(
                "radius_scale",
                format!("must be finite and positive, got {}", self.radius_scale),
            ));
        }
        if let Some(reason) = self.orientation.invalid() {
            return Err(bad("orientation", reason));
        }
        if !(self.tip_scale.is_finite() && self.tip_scale > 0.0) {
            return Err(bad(
                "tip_scale",
                format!("must be finite and positive, got {}", self.tip_scale),
            ));
        }
        if !(self.strand_fraction > 0.0 && self.strand_fraction <= 1.0) {
            return Err(bad(
                "strand_fraction",
                format!("must be in (0, 1], got {}", self.strand_fraction),
            ));
        }
        if let Some(children) = &self.children {
            children.validate(object)?;
        }
        Ok(self.transform.validate(object)?)
    }

    /// `hair` with the child strands of [`HairOptions::children`] added (unchanged without
    /// them), within the memory limit of `limits`. Children are grown in the hair's own units,
    /// before the object transform.
    pub(crate) fn with_children<'a>(
        &self,
        hair: &'a HairGeometry,
        limits: &Limits,
    ) -> Result<std::borrow::Cow<'a, HairGeometry>> {
        Ok(match &self.children {
            Some(children) => {
                std::borrow::Cow::Owned(children.grow(hair, self.transform.scale, limits)?)
            }
            None => std::borrow::Cow::Borrowed(hair),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_file_syntax_deserialises() {
        let o: HairOptions = ron::from_str(
            "(basis: CatmullRom, radius_scale: 1.5, tip_scale: 0.3,
              transform: (scale: 0.1, rotate: Euler((0, 90, 0)), translate: (0, 1, 0)),
              strand_fraction: 0.1, strand_seed: 7)",
        )
        .unwrap();
        assert_eq!(o.basis, CurveBasis::CatmullRom);
        assert_eq!(
            o.transform.rotate,
            tress_groom::Rotation::Euler(glam::Vec3::new(0.0, 90.0, 0.0))
        );
        assert_eq!(o.strand_seed, 7);
        let o: HairOptions =
            ron::from_str("(transform: (rotate: AxisAngle(axis: (0, 1, 0), degrees: 45)))")
                .unwrap();
        assert_eq!(o.transform.scale, 1.0);
        assert_eq!(
            ron::from_str::<HairOptions>("()").unwrap(),
            HairOptions::default()
        );
        assert!(ron::from_str::<HairOptions>("(basis: Bezier)").is_err());
        let o: HairOptions =
            ron::from_str("(children: Some((per_guide: 8, radius: 0.05, seed: 1)))").unwrap();
        assert_eq!(
            o.children,
            Some(ChildStrands {
                per_guide: 8,
                radius: 0.05,
                seed: 1,
                blend: 1,
                clump: 0.0,
                thinning: 0.0,
                radius_jitter: 0.0,
            })
        );
        assert!(ron::from_str::<HairOptions>("(children: Some((per_guide: 8)))").is_err());
        // Round trip.
        let text = ron::to_string(&o).unwrap();
        assert_eq!(ron::from_str::<HairOptions>(&text).unwrap(), o);
    }

    #[test]
    fn option_validation_names_object_and_field() {
        let o = HairOptions {
            strand_fraction: 0.0,
            ..Default::default()
        };
        let e = o.validate("head").unwrap_err().to_string();
        assert!(e.contains("head") && e.contains("strand_fraction"), "{e}");
        let o = HairOptions {
            tip_scale: -1.0,
            ..Default::default()
        };
        assert!(o.validate("head").is_err());
        HairOptions::default().validate("head").unwrap();
        let o = HairOptions {
            children: Some(ChildStrands {
                per_guide: 0,
                radius: 1.0,
                seed: 0,
                blend: 1,
                clump: 0.0,
                thinning: 0.0,
                radius_jitter: 0.0,
            }),
            ..Default::default()
        };
        let e = o.validate("head").unwrap_err().to_string();
        assert!(
            e.contains("head") && e.contains("children.per_guide"),
            "{e}"
        );
    }
}
