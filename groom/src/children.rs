//! Child strands: dense hair grown from sparse guide strands (TressFX and other simulation
//! grooms carry only guides — Sintel's hair is 228 strands).
//!
//! Each guide gets a rotation-minimising frame along it (double reflection, Wang et al. 2008):
//! a tangent and two normals that turn as little as possible from root to tip. A child is
//! rooted at a random point of the disc of radius `radius` in its guide's normal plane at the
//! root, and is carried along the guide at that frame offset, scaled by 1 − clump·v (v the
//! arc-length fraction, 0 at the root, 1 at the tip). With `blend: 1` (the default) that is
//! all: the child stays in its guide's normal plane within `radius` of it, the child hair
//! forming a clump around the guide.
//!
//! With `blend: k > 1` the child follows the k guides whose roots are nearest its root: each
//! of them carries the child's root offset (taken in that guide's root frame) along itself,
//! and the child is the weighted mean of these k paths, with the modified Shepard weights of
//! Franke and Nielson (1980), ((d₊ − d) / (d₊·d))² for root distance d, d₊ being the distance
//! to the next nearest guide root: a child rooted at a guide follows it alone, and a guide's
//! weight falls to zero just as it leaves the k nearest, so children vary continuously across
//! the scalp. Children then fill the space between guides instead of clumping; it assumes
//! neighbouring guides grow alike — across a parting, keep `blend: 1`.
//!
//! Children take their guide's point count and radii, times a radius jitter; `thinning`
//! shortens each child to a random fraction of its length, so the hair thins toward the tips.
//! Everything is drawn from a generator seeded by (seed, guide, child): the result does not
//! depend on threads or on the other children.

use crate::error::{Error, Result};
use crate::geometry::{HairAttribute, HairGeometry};
use rayon::prelude::*;
use rstar::primitives::GeomWithData;
use rstar::RTree;
use serde::{Deserialize, Serialize};
use std::f32::consts::TAU;
use tress_core::limits::Limits;
use tress_core::math::Vec3;
use tress_core::rng::{hash_words, Pcg32};

/// Most guides a child may blend: more only averages the shape away.
const MAX_BLEND: u32 = 16;

/// Child strands added around every guide strand of a hair object (hair option `children`;
/// scene files omit the inner parentheses of `Some`, plain RON writes `Some((…))`):
///
/// ```ron
/// children: Some(per_guide: 8, radius: 0.05, seed: 1)
/// children: Some(per_guide: 16, radius: 0.8, blend: 3, clump: 0.3, thinning: 0.2, radius_jitter: 0.2)
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ChildStrands {
    /// Children grown per guide (at least 1). The guides are kept.
    pub per_guide: u32,
    /// Largest distance of a child's root from its guide's root, in scene units (after the
    /// object's transform).
    pub radius: f32,
    /// Seed of the children's random offsets, lengths and radii (default 0).
    #[serde(default)]
    pub seed: u64,
    /// How many nearest guides each child follows (default 1: its own guide only, a clump
    /// around it; 3–4 fill the space between guides). At most 16.
    #[serde(default = "one")]
    pub blend: u32,
    /// How much children close in on their guides toward the tip, in [0, 1]: the offset is
    /// scaled by 1 − clump·v (default 0: constant offset).
    #[serde(default)]
    pub clump: f32,
    /// Random shortening, in [0, 1): each child keeps a fraction of its guide's length drawn
    /// uniformly from [1 − thinning, 1] (default 0).
    #[serde(default)]
    pub thinning: f32,
    /// Radius jitter, in [0, 1): each child's radii are multiplied by a factor drawn uniformly
    /// from [1 − radius_jitter, 1 + radius_jitter] (default 0).
    #[serde(default)]
    pub radius_jitter: f32,
}

fn one() -> u32 {
    1
}

impl ChildStrands {
    /// Checks the ranges; errors name `object` and the field.
    pub fn validate(&self, object: &str) -> Result<()> {
        let bad = |field: &'static str, reason: String| {
            Error::InvalidOption(crate::InvalidOption {
                object: object.to_owned(),
                field,
                reason,
            })
        };
        if self.per_guide == 0 {
            return Err(bad("children.per_guide", "must be at least 1".into()));
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(bad(
                "children.radius",
                format!("must be finite and positive, got {}", self.radius),
            ));
        }
        if !(1..=MAX_BLEND).contains(&self.blend) {
            return Err(bad(
                "children.blend",
                format!("must be in 1..={MAX_BLEND}, got {}", self.blend),
            ));
        }
        if !(0.0..=1.0).contains(&self.clump) {
            return Err(bad(
                "children.clump",
                format!("must be in [0, 1], got {}", self.clump),
            ));
        }
        for (field, value) in [
            ("children.thinning", self.thinning),
            ("children.radius_jitter", self.radius_jitter),
        ] {
            if !(0.0..1.0).contains(&value) {
                return Err(bad(field, format!("must be in [0, 1), got {value}")));
            }
        }
        Ok(())
    }

    /// `guides` followed by their children: guide `g`'s children are strands
    /// `G + g·per_guide ..` (G guides), in order. `scale` is the object transform's scale, by
    /// which `radius` (scene units) is divided to work in the guides' own units. Guides of
    /// zero length get no children.
    pub fn grow(&self, guides: &HairGeometry, scale: f32, limits: &Limits) -> Result<HairGeometry> {
        let frames: Vec<Option<GuideFrames>> = (0..guides.strand_count())
            .into_par_iter()
            .map(|g| GuideFrames::new(&guides.points[guides.strand(g)]))
            .collect();
        let total = guides.point_count() as u64 * (1 + self.per_guide as u64);
        if total > u32::MAX as u64 {
            return Err(Error::InvalidGeometry(crate::InvalidGeometry {
                object: guides.name.clone(),
                reason: format!(
                    "{} children per guide would make {total} points, more than 2^32",
                    self.per_guide
                ),
            }));
        }
        crate::geometry::check_point_memory(
            &guides.name,
            "children.per_guide",
            &format!(
                "{} children on each of {} guides",
                self.per_guide,
                guides.strand_count()
            ),
            total as f64,
            limits,
        )?;
        let roots = (self.blend > 1).then(|| {
            RTree::bulk_load(
                frames
                    .iter()
                    .enumerate()
                    .filter_map(|(g, f)| {
                        Some(GeomWithData::new(f.as_ref()?.points[0].to_array(), g))
                    })
                    .collect(),
            )
        });
        let radius = self.radius / scale;
        let children: Vec<(Vec<Vec3>, Vec<f32>)> = (0..guides.strand_count())
            .into_par_iter()
            .flat_map_iter(|g| {
                let frames = &frames;
                let roots = roots.as_ref();
                (0..self.per_guide).filter_map(move |j| {
                    let own = frames[g].as_ref()?;
                    let mut rng = Pcg32::new(hash_words(&[self.seed, g as u64, j as u64]), 0);
                    let [u1, u2, u3, u4] = std::array::from_fn(|_| rng.next_f32());
                    let (rho, phi) = (radius * u1.sqrt(), TAU * u2);
                    let root = own.points[0]
                        + rho * (phi.cos() * own.normals[0] + phi.sin() * own.binormals[0]);
                    let length = 1.0 - self.thinning * u3;
                    let jitter = 1.0 + self.radius_jitter * (2.0 * u4 - 1.0);
                    let followed = match roots {
                        Some(tree) => nearest_guides(tree, root, self.blend, g, frames),
                        None => vec![(g, 1.0)],
                    };
                    let radii_g = &guides.radii[guides.strand(g)];
                    let (points, radii) = own
                        .fractions
                        .iter()
                        .map(|&v| {
                            let v = v * length;
                            let shrink = 1.0 - self.clump * v;
                            let p = followed
                                .iter()
                                .map(|&(k, w)| {
                                    let guide = frames[k].as_ref().expect("guides with frames");
                                    w * guide.carry(root, v, shrink)
                                })
                                .sum::<Vec3>();
                            (p, own.lerp_radius(radii_g, v) * jitter)
                        })
                        .unzip();
                    Some((points, radii))
                })
            })
            .collect();

        let mut out = guides.clone();
        // Which guide each child strand came from, for the per-strand and per-point
        // attributes.
        let parents: Vec<usize> = (0..guides.strand_count())
            .flat_map(|g| {
                let n = if frames[g].is_some() {
                    self.per_guide as usize
                } else {
                    0
                };
                std::iter::repeat_n(g, n)
            })
            .collect();
        for (points, radii) in &children {
            out.points.extend_from_slice(points);
            out.radii.extend_from_slice(radii);
            out.strand_offsets.push(out.points.len() as u32);
        }
        out.colors = guides.colors.as_ref().map(|c| inherit(c, guides, &parents));
        out.orientations = (guides.orientations.as_ref()).map(|o| inherit(o, guides, &parents));
        out.transparency = guides
            .transparency
            .as_ref()
            .map(|t| inherit(t, guides, &parents));
        out.validate()?;
        Ok(out)
    }
}

/// The guides a child rooted at `root` follows, with weights summing to 1: the `k` guides
/// with the nearest roots, weighted by ((d₊ − d) / (d₊·d))², d₊ the distance to the next
/// root (Franke and Nielson's modified Shepard weights).
fn nearest_guides(
    tree: &RTree<GeomWithData<[f32; 3], usize>>,
    root: Vec3,
    k: u32,
    own: usize,
    frames: &[Option<GuideFrames>],
) -> Vec<(usize, f32)> {
    let near: Vec<(usize, f32)> = tree
        .nearest_neighbor_iter(root.to_array())
        .take(k as usize + 1)
        .map(|n| {
            let g = n.data;
            let d = frames[g]
                .as_ref()
                .map_or(0.0, |f| f.points[0].distance(root));
            (g, d)
        })
        .collect();
    // Fewer guides than k + 1: the farthest bounds the falloff from a little beyond.
    let reach = if near.len() > k as usize {
        near[k as usize].1
    } else {
        near.last().map_or(0.0, |n| n.1) * 2.0
    };
    // A child rooted exactly on a guide follows it alone (its weight would be infinite).
    if let Some(&(g, _)) = near.iter().find(|n| n.1 == 0.0) {
        return vec![(g, 1.0)];
    }
    let mut weights: Vec<(usize, f32)> = near
        .iter()
        .take(k as usize)
        .map(|&(g, d)| (g, ((reach - d).max(0.0) / (reach * d)).powi(2)))
        .filter(|&(_, w)| w > 0.0)
        .collect();
    let total: f32 = weights.iter().map(|w| w.1).sum();
    if total <= 0.0 {
        // Every candidate as far as the next one: fall back to the child's own guide.
        return vec![(own, 1.0)];
    }
    weights.iter_mut().for_each(|w| w.1 /= total);
    weights
}

/// A guide's points with a rotation-minimising frame at each, and their arc-length fractions.
#[derive(Debug)]
struct GuideFrames {
    points: Vec<Vec3>,
    tangents: Vec<Vec3>,
    normals: Vec<Vec3>,
    binormals: Vec<Vec3>,
    /// Arc length from the root over total length: 0 at the root, 1 at the tip.
    fractions: Vec<f32>,
}

impl GuideFrames {
    /// The frames of a polyline, or `None` if it has no length.
    fn new(points: &[Vec3]) -> Option<Self> {
        let n = points.len();
        if n < 2 {
            return None;
        }
        let mut fractions = Vec::with_capacity(n);
        let mut length = 0.0f32;
        for i in 0..n {
            if i > 0 {
                length += points[i].distance(points[i - 1]);
            }
            fractions.push(length);
        }
        if length <= 0.0 {
            return None;
        }
        fractions.iter_mut().for_each(|s| *s /= length);
        // Tangents by central differences, one-sided at the ends; a run of repeated points
        // takes the previous tangent.
        let mut tangents: Vec<Vec3> = Vec::with_capacity(n);
        for i in 0..n {
            let t = (points[(i + 1).min(n - 1)] - points[i.saturating_sub(1)]).normalize_or_zero();
            let fallback = tangents.last().copied().unwrap_or(Vec3::ZERO);
            tangents.push(if t == Vec3::ZERO { fallback } else { t });
        }
        // Leading repeated points: take the first real tangent.
        let first = tangents.iter().copied().find(|t| *t != Vec3::ZERO)?;
        for t in tangents.iter_mut().take_while(|t| **t == Vec3::ZERO) {
            *t = first;
        }
        // Double reflection (Wang, Jüttler, Zheng, Liu 2008), renormalised against drift.
        let mut normals = Vec::with_capacity(n);
        normals.push(tangents[0].any_orthonormal_vector());
        for i in 0..n - 1 {
            let r = normals[i];
            let v1 = points[i + 1] - points[i];
            let c1 = v1.length_squared();
            let next = if c1 == 0.0 {
                r
            } else {
                let r_l = r - (2.0 / c1) * v1.dot(r) * v1;
                let t_l = tangents[i] - (2.0 / c1) * v1.dot(tangents[i]) * v1;
                let v2 = tangents[i + 1] - t_l;
                let c2 = v2.length_squared();
                if c2 == 0.0 {
                    r_l
                } else {
                    r_l - (2.0 / c2) * v2.dot(r_l) * v2
                }
            };
            let t = tangents[i + 1];
            let next = (next - next.dot(t) * t).normalize_or_zero();
            normals.push(if next == Vec3::ZERO {
                t.any_orthonormal_vector()
            } else {
                next
            });
        }
        let binormals = tangents
            .iter()
            .zip(&normals)
            .map(|(t, r)| t.cross(*r))
            .collect();
        Some(GuideFrames {
            points: points.to_vec(),
            tangents,
            normals,
            binormals,
            fractions,
        })
    }

    /// The segment holding arc-length fraction `v` and the parameter within it.
    fn locate(&self, v: f32) -> (usize, f32) {
        let i = self
            .fractions
            .partition_point(|&s| s <= v)
            .clamp(1, self.fractions.len() - 1);
        let (s0, s1) = (self.fractions[i - 1], self.fractions[i]);
        let t = if s1 > s0 {
            ((v - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (i - 1, t)
    }

    /// Where this guide carries a child rooted at `root`: the root's offset from the guide's
    /// root, in the guide's root frame, re-expressed in the frame at fraction `v` and scaled
    /// by `shrink`, added to the guide's point there.
    fn carry(&self, root: Vec3, v: f32, shrink: f32) -> Vec3 {
        let d = root - self.points[0];
        let (a, b, c) = (
            d.dot(self.tangents[0]),
            d.dot(self.normals[0]),
            d.dot(self.binormals[0]),
        );
        let (i, t) = self.locate(v);
        let at = |x: &[Vec3]| x[i].lerp(x[i + 1], t);
        at(&self.points)
            + shrink * (a * at(&self.tangents) + b * at(&self.normals) + c * at(&self.binormals))
    }

    /// The guide's radius at fraction `v`, from its per-point `radii`.
    fn lerp_radius(&self, radii: &[f32], v: f32) -> f32 {
        let (i, t) = self.locate(v);
        radii[i] + (radii[i + 1] - radii[i]) * t
    }
}

/// `attr` of the guides extended to their children (`parents[c]` is child c's guide): a child
/// takes its guide's colour or transparency, point by point where the file has them per point
/// (a child has as many points as its guide).
fn inherit<T: Copy>(
    attr: &HairAttribute<T>,
    guides: &HairGeometry,
    parents: &[usize],
) -> HairAttribute<T> {
    match attr {
        HairAttribute::Uniform(v) => HairAttribute::Uniform(*v),
        HairAttribute::PerStrand(v) => HairAttribute::PerStrand(
            v.iter()
                .copied()
                .chain(parents.iter().map(|&g| v[g]))
                .collect(),
        ),
        HairAttribute::PerPoint(v) => HairAttribute::PerPoint(
            v.iter()
                .copied()
                .chain(
                    parents
                        .iter()
                        .flat_map(|&g| v[guides.strand(g)].iter().copied()),
                )
                .collect(),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{hair, line};

    /// Three wavy guides side by side along x, growing along +y.
    fn guides() -> HairGeometry {
        let strand = |x: f32| -> Vec<Vec3> {
            (0..24)
                .map(|i| {
                    let s = i as f32 / 23.0;
                    Vec3::new(x + 0.3 * (6.0 * s).sin(), 4.0 * s, 0.2 * (4.0 * s).cos())
                })
                .collect()
        };
        let mut g = hair(&[strand(0.0), strand(1.0), strand(2.0)], 0.01);
        g.radii
            .iter_mut()
            .enumerate()
            .for_each(|(i, r)| *r = 0.01 + 0.0001 * i as f32);
        g
    }

    fn options() -> ChildStrands {
        ChildStrands {
            per_guide: 8,
            radius: 0.2,
            seed: 1,
            blend: 1,
            clump: 0.0,
            thinning: 0.0,
            radius_jitter: 0.0,
        }
    }

    #[test]
    fn frames_are_orthonormal_and_rotation_minimising() {
        let g = guides();
        let f = GuideFrames::new(&g.points[g.strand(0)]).unwrap();
        for i in 0..f.points.len() {
            let (t, r, s) = (f.tangents[i], f.normals[i], f.binormals[i]);
            assert!((t.length() - 1.0).abs() < 1e-5 && (r.length() - 1.0).abs() < 1e-5);
            assert!(t.dot(r).abs() < 1e-5 && t.dot(s).abs() < 1e-5 && r.dot(s).abs() < 1e-5);
        }
        // Along a planar curve a rotation-minimising frame does not twist: the plane's normal
        // keeps its coordinates in the frame.
        let planar: Vec<Vec3> = (0..20)
            .map(|i| Vec3::new((i as f32 * 0.3).sin(), i as f32 * 0.2, 0.0))
            .collect();
        let f = GuideFrames::new(&planar).unwrap();
        let (n0, b0) = (f.normals[0].z, f.binormals[0].z);
        for (n, b) in f.normals.iter().zip(&f.binormals) {
            assert!(
                (n.z - n0).abs() < 1e-5 && (b.z - b0).abs() < 1e-5,
                "{n} {b}"
            );
        }
        assert!(GuideFrames::new(&[Vec3::ONE, Vec3::ONE]).is_none());
        assert!(GuideFrames::new(&[Vec3::ONE]).is_none());
        // Repeated points do not break the frames.
        let f = GuideFrames::new(&[
            Vec3::ZERO,
            Vec3::ZERO,
            Vec3::Y,
            Vec3::Y,
            Vec3::new(1.0, 2.0, 0.0),
        ])
        .unwrap();
        assert!(f
            .normals
            .iter()
            .all(|n| n.is_finite() && (n.length() - 1.0).abs() < 1e-5));
    }

    #[test]
    fn clumped_children_stay_in_the_guides_normal_plane_within_radius() {
        let g = guides();
        let o = ChildStrands {
            clump: 0.5,
            ..options()
        };
        let grown = o.grow(&g, 1.0, &Limits::default()).unwrap();
        assert_eq!(grown.strand_count(), 3 + 3 * 8);
        // The guides come first, untouched.
        assert_eq!(grown.points[..g.point_count()], g.points[..]);
        assert_eq!(grown.strand_offsets[..4], g.strand_offsets[..]);
        for c in 0..24 {
            let guide = c / 8;
            let gp = &g.points[g.strand(guide)];
            let f = GuideFrames::new(gp).unwrap();
            let cp = &grown.points[grown.strand(3 + c)];
            assert_eq!(cp.len(), gp.len());
            let root_offset = (cp[0] - gp[0]).length();
            assert!(root_offset <= 0.2 + 1e-6, "child {c}: {root_offset}");
            for i in 0..gp.len() {
                let d = cp[i] - gp[i];
                // In the normal plane, at the clumped distance.
                assert!(d.dot(f.tangents[i]).abs() < 1e-4, "child {c} point {i}");
                let expect = root_offset * (1.0 - 0.5 * f.fractions[i]);
                assert!((d.length() - expect).abs() < 1e-4, "child {c} point {i}");
            }
            // Radii follow the guide's.
            assert_eq!(grown.radii[grown.strand(3 + c)], g.radii[g.strand(guide)]);
        }
        // The radius is in scene units: a transform scale of 10 shrinks it in file units.
        let scaled = o.grow(&g, 10.0, &Limits::default()).unwrap();
        let far = (0..24)
            .map(|c| {
                (scaled.points[scaled.strand(3 + c).start] - g.points[g.strand(c / 8).start])
                    .length()
            })
            .fold(0.0f32, f32::max);
        assert!(far <= 0.02 + 1e-6 && far > 0.005, "{far}");
    }

    #[test]
    fn children_are_deterministic_and_seeded() {
        let g = guides();
        let o = ChildStrands {
            blend: 2,
            thinning: 0.3,
            radius_jitter: 0.2,
            ..options()
        };
        let a = o.grow(&g, 1.0, &Limits::default()).unwrap();
        assert_eq!(a, o.grow(&g, 1.0, &Limits::default()).unwrap());
        let b = ChildStrands {
            seed: 2,
            ..o.clone()
        }
        .grow(&g, 1.0, &Limits::default())
        .unwrap();
        assert_ne!(a.points, b.points);
        // A child depends on (seed, guide, child) only: more children per guide leave the
        // first ones as they were.
        let more = ChildStrands {
            per_guide: 9,
            ..o.clone()
        }
        .grow(&g, 1.0, &Limits::default())
        .unwrap();
        assert_eq!(a.points[a.strand(3)], more.points[more.strand(3)]);
    }

    #[test]
    fn thinning_and_jitter_stay_in_their_ranges() {
        let g = hair(&[line(Vec3::ZERO, Vec3::new(0.0, 10.0, 0.0), 11)], 0.5);
        let o = ChildStrands {
            per_guide: 200,
            thinning: 0.4,
            radius_jitter: 0.25,
            ..options()
        };
        let grown = o.grow(&g, 1.0, &Limits::default()).unwrap();
        let (mut shortest, mut longest) = (f32::MAX, 0.0f32);
        let (mut thinnest, mut thickest) = (f32::MAX, 0.0f32);
        for c in 1..=200 {
            let pts = &grown.points[grown.strand(c)];
            let length = pts[pts.len() - 1].y - pts[0].y;
            shortest = shortest.min(length);
            longest = longest.max(length);
            let r = grown.radii[grown.strand(c).start];
            thinnest = thinnest.min(r);
            thickest = thickest.max(r);
        }
        // Lengths in [6, 10] and radii in [0.375, 0.625], both ends nearly reached.
        assert!((6.0 - 1e-4..6.2).contains(&shortest), "{shortest}");
        assert!((9.8..=10.0 + 1e-4).contains(&longest), "{longest}");
        assert!((0.375 - 1e-6..0.39).contains(&thinnest), "{thinnest}");
        assert!((0.61..=0.625 + 1e-6).contains(&thickest), "{thickest}");
    }

    #[test]
    fn blended_children_follow_their_neighbours() {
        // Two parallel straight guides and a third bent one far away: a child between the
        // first two blends them, so it stays straight and parallel.
        let g = hair(
            &[
                line(Vec3::ZERO, Vec3::new(0.0, 5.0, 0.0), 6),
                line(Vec3::X, Vec3::new(1.0, 5.0, 0.0), 6),
                vec![
                    Vec3::new(50.0, 0.0, 0.0),
                    Vec3::new(50.0, 2.0, 0.0),
                    Vec3::new(55.0, 2.0, 0.0),
                ],
            ],
            0.01,
        );
        let o = ChildStrands {
            per_guide: 50,
            radius: 0.9,
            blend: 2,
            ..options()
        };
        let grown = o.grow(&g, 1.0, &Limits::default()).unwrap();
        for c in 0..100 {
            let pts = &grown.points[grown.strand(3 + c)];
            for p in pts {
                assert!(
                    (p.x - pts[0].x).abs() < 1e-4 && (p.z - pts[0].z).abs() < 1e-4,
                    "child {c}: {pts:?}"
                );
            }
            assert!((pts[pts.len() - 1].y - 5.0).abs() < 1e-4);
        }
        // The weights: the nearest guide dominates; a child on a guide follows it alone.
        let frames: Vec<_> = (0..3)
            .map(|s| GuideFrames::new(&g.points[g.strand(s)]))
            .collect();
        let tree = RTree::bulk_load(
            frames
                .iter()
                .enumerate()
                .map(|(s, f)| GeomWithData::new(f.as_ref().unwrap().points[0].to_array(), s))
                .collect(),
        );
        let w = nearest_guides(&tree, Vec3::new(0.1, 0.0, 0.0), 2, 0, &frames);
        assert_eq!(w.len(), 2);
        assert!((w.iter().map(|x| x.1).sum::<f32>() - 1.0).abs() < 1e-6);
        assert_eq!(w[0].0, 0);
        assert!(w[0].1 > 0.98, "{w:?}");
        assert_eq!(
            nearest_guides(&tree, Vec3::X, 2, 0, &frames),
            vec![(1, 1.0)]
        );
    }

    #[test]
    fn attributes_are_inherited_and_options_checked() {
        let mut g = guides();
        g.colors = Some(HairAttribute::PerStrand(vec![
            tress_core::math::Rgb::X,
            tress_core::math::Rgb::Y,
            tress_core::math::Rgb::Z,
        ]));
        g.transparency = Some(HairAttribute::PerPoint((0..72).map(|i| i as f32).collect()));
        let grown = options().grow(&g, 1.0, &Limits::default()).unwrap();
        let colors = grown.colors.as_ref().unwrap();
        let alpha = grown.transparency.as_ref().unwrap();
        for c in 0..24 {
            let s = 3 + c;
            assert_eq!(colors.at(s, 0), colors.at(c / 8, 0));
            let first = grown.strand(s).start;
            assert_eq!(alpha.at(s, first), (24 * (c / 8)) as f32);
        }
        options().validate("obj").unwrap();
        let cases = [
            (
                ChildStrands {
                    per_guide: 0,
                    ..options()
                },
                "per_guide",
            ),
            (
                ChildStrands {
                    radius: 0.0,
                    ..options()
                },
                "children.radius",
            ),
            (
                ChildStrands {
                    blend: 0,
                    ..options()
                },
                "blend",
            ),
            (
                ChildStrands {
                    blend: 17,
                    ..options()
                },
                "blend",
            ),
            (
                ChildStrands {
                    clump: 1.5,
                    ..options()
                },
                "clump",
            ),
            (
                ChildStrands {
                    thinning: 1.0,
                    ..options()
                },
                "thinning",
            ),
            (
                ChildStrands {
                    radius_jitter: -0.1,
                    ..options()
                },
                "radius_jitter",
            ),
        ];
        for (o, field) in cases {
            let e = o.validate("obj").unwrap_err().to_string();
            assert!(e.contains("obj") && e.contains(field), "{e}");
        }
        // A guide of zero length is kept and gets no children.
        let g = hair(
            &[vec![Vec3::ONE, Vec3::ONE], line(Vec3::ZERO, Vec3::Y, 3)],
            0.1,
        );
        let grown = options().grow(&g, 1.0, &Limits::default()).unwrap();
        assert_eq!(grown.strand_count(), 2 + 8);
    }
}
