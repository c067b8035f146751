//! A hair object's curves as the accelerator keeps them: per segment its control points, strand
//! record and bounding capsule, from which a curve hit becomes a fiber hit, self-intersections
//! are filtered (see "Self-intersection" in the crate docs) and the density grid is built.

use crate::curves::{Capsule, CurveBasis, CurveShape, Overlaps};
use glam::Vec4;
use tress_core::accel::{HairCurves, HitKind};
use tress_core::bcsdf::FiberFrame;
use tress_core::math::{Ray, Rgb, Vec3};

/// Everything needed to turn a curve hit into a fiber hit and to filter self-intersections.
#[derive(Debug)]
pub(crate) struct CurveData {
    pub(crate) basis: CurveBasis,
    /// Ribbons or tubes: a ribbon hit is moved to the depth of the tube's wall.
    pub(crate) shape: CurveShape,
    /// Whether rays that start inside one of these fibers may hit it ([`Overlaps`]).
    pub(crate) overlaps: Overlaps,
    pub(crate) materials: SegmentMaterials,
    /// The strands' control points (position and radius), strand after strand: Embree's
    /// vertex buffer, shared with it rather than copied, so the accelerator holds them once.
    pub(crate) cps: Vec<Vec4>,
    /// Per primitive (segment): the index in `cps` of its first control point, Embree's index
    /// buffer (shared likewise). A hit reads its control points through it.
    pub(crate) first_cp: Vec<u32>,
    /// Per primitive: its strand slot (the segment's place in the strand's polyline is its
    /// first control point's offset from the strand's).
    pub(crate) strand_of: Vec<u32>,
    /// Per primitive, for cubic bases only: a capsule containing the fiber swept by the
    /// segment. A linear segment's capsule is its two control points and their larger radius,
    /// computed when needed rather than stored (28 bytes a segment).
    pub(crate) capsules: Vec<Capsule>,
    /// Per control point (aligned with `cps`), the fiber's orientation at the polyline point
    /// it stands for ([`crate::FiberOrientation`]), interpolated along a segment at a hit.
    /// Only kept when the scene asks for it ([`crate::SceneBuilder::with_fiber_orientation`]):
    /// the models that read it are rare, and the other scenes should not pay 12 bytes a point.
    pub(crate) orientations: Option<Vec<Vec3>>,
    /// Per strand slot: what hits and the filter need of a strand, in one record.
    pub(crate) strands: Vec<StrandRecord>,
}

/// Which material each primitive of a hair object has.
#[derive(Debug)]
pub(crate) enum SegmentMaterials {
    /// One material for the whole object.
    Uniform(u32),
    /// One per primitive (per-strand variation): a separate array, so hair without variation
    /// pays nothing for it.
    PerSegment(Vec<u32>),
}

/// A curve segment of a hair object, as [`crate::SceneBuilder::add_hair_varied`] shows it to the
/// caller choosing the segment's material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HairSegment {
    /// The strand's index in the hair object, as hits report it (`HitKind::Fiber::strand`):
    /// its index in the file, children following the file's strands, also when strands are
    /// subsampled.
    pub strand: u32,
    /// Where the middle of the segment lies along the strand: 0 at the root, 1 at the tip.
    pub v: f32,
    /// The colour the file stores there (the mean of the segment's two end points' colours
    /// when it stores them per point), or `None` when it stores none.
    pub color: Option<Rgb>,
}

/// The interval `[t_in ≤ 0, t_out ≥ 0]` of the line `p + t·dir` inside the tube of `radius`
/// around the line through `axis` along `tangent` (`p` lies inside it), cut to the segment's
/// capsule `cap` so that it ends where the segment does; `None` where rounding puts `p` outside.
fn tube_chord(
    p: Vec3,
    dir: Vec3,
    axis: Vec3,
    tangent: Vec3,
    radius: f32,
    cap: &Capsule,
) -> Option<(f32, f32)> {
    let o = p - axis;
    let (o_perp, d_perp) = (
        o - tangent * o.dot(tangent),
        dir - tangent * dir.dot(tangent),
    );
    let (qa, qb, qc) = (
        d_perp.length_squared(),
        o_perp.dot(d_perp),
        o_perp.length_squared() - radius * radius,
    );
    if qc > 0.0 {
        return None;
    }
    let (mut t_in, mut t_out) = if qa > 0.0 {
        let s = (qb * qb - qa * qc).sqrt();
        ((-qb - s) / qa, (-qb + s) / qa)
    } else {
        (f32::NEG_INFINITY, f32::INFINITY)
    };
    if let Some((c_in, c_out)) = cap.line_interval(p, dir, 0.0) {
        (t_in, t_out) = (t_in.max(c_in), t_out.min(c_out));
    }
    (t_in.is_finite() && t_out.is_finite() && t_in <= 0.0 && t_out >= 0.0).then_some((t_in, t_out))
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct StrandRecord {
    /// The strand's primitives, `first_prim..end_prim` (consecutive), so the filter tells a
    /// hit on the strand a ray leaves from any other without reading the hit primitive's data
    /// (a cache miss per candidate hit).
    pub(crate) first_prim: u32,
    pub(crate) end_prim: u32,
    /// Polyline segment count.
    pub(crate) segments: u32,
    /// The index in `cps` of the strand's first control point.
    pub(crate) first_cp: u32,
    /// The strand's index in the hair object.
    pub(crate) id: u32,
}

impl CurveData {
    /// Whether a hit on primitive `hit` should be kept for a ray leaving primitive `from` of
    /// this geometry (see "Self-intersection" in the crate docs).
    #[inline]
    pub(crate) fn keep(&self, from: u32, hit: u32, org: Vec3, dir: Vec3) -> bool {
        if hit == from {
            return false;
        }
        let (s, k) = (from as usize, hit as usize);
        let Some(&strand) = self.strand_of.get(s) else {
            return true;
        };
        let strand = &self.strands[strand as usize];
        if !(strand.first_prim..strand.end_prim).contains(&hit) {
            return true;
        }
        !self.inside_fiber_until(s, k, org, dir)
    }

    /// Where a ray from `org` along `dir` leaving primitive `from` of this geometry leaves the
    /// fiber: the far end of the run of the strand's capsules around `from` (walking both ways
    /// along the strand) that the ray passes through from its origin without a gap, padded as
    /// [`Self::keep`] pads them. Hits on the strand before it are the fiber seen from inside.
    pub(crate) fn fiber_exit(&self, from: u32, org: Vec3, dir: Vec3) -> f32 {
        let s = from as usize;
        let Some(&strand) = self.strand_of.get(s) else {
            return 0.0;
        };
        let strand = &self.strands[strand as usize];
        let cap = &self.capsule(s);
        let round = 8.0 * f32::EPSILON * org.abs().max_element();
        let pad = |c: &Capsule| 1e-3 * c.r + round;
        let mut reach = cap
            .line_interval(org, dir, pad(cap))
            .map_or(0.0, |(_, out)| out.max(0.0));
        let mut walk = |prims: &mut dyn Iterator<Item = u32>| {
            for j in prims {
                let cap = &self.capsule(j as usize);
                match cap.line_interval(org, dir, pad(cap)) {
                    Some((t_in, t_out)) if t_in <= reach + pad(cap) => reach = reach.max(t_out),
                    _ => break,
                }
            }
        };
        walk(&mut (from + 1..strand.end_prim));
        walk(&mut (strand.first_prim..from).rev());
        reach + pad(cap)
    }

    /// Whether the ray stays inside the union of the capsules of segments `s..=k` (walking
    /// along the strand) from its origin until it enters capsule `k`: then a hit on `k` is the
    /// ray-facing ribbon seen from inside the fiber, not a fiber reached through free space.
    fn inside_fiber_until(&self, s: usize, k: usize, org: Vec3, dir: Vec3) -> bool {
        // Slack for rounding: the origin came from `o + t·d` and may sit slightly outside the
        // capsule it left; radii are padded by this much.
        let round = 8.0 * f32::EPSILON * org.abs().max_element();
        let pad = |c: &Capsule| 1e-3 * c.r + round;
        let cap = &self.capsule(s);
        let mut reach = cap
            .line_interval(org, dir, pad(cap))
            .map_or(0.0, |(_, out)| out.max(0.0));
        let mut j = s;
        while j != k {
            j = if k > s { j + 1 } else { j - 1 };
            let cap = &self.capsule(j);
            match cap.line_interval(org, dir, pad(cap)) {
                Some((t_in, t_out)) if t_in <= reach + pad(cap) => reach = reach.max(t_out),
                _ => return false,
            }
        }
        true
    }

    /// The fiber hit on primitive `prim` at curve parameter `u`, where Embree reports it at
    /// distance `t` along `ray`: the hit kind and the hit's distance. A ribbon is met at the
    /// depth of the curve axis; the hit is moved to where the ray enters the segment's tube
    /// (its capsule; where the ray starts inside it, where it leaves), at the same offset `h`.
    /// Rays then leave a fiber from its surface, as from a real fiber: from the axis plane, a
    /// ray leaving sideways meets the neighbours beside the fiber that a ray from its surface
    /// passes over (measured in a block of fibers that do not touch: ribbon hair 14 % darker
    /// than tube hair from the axis, equal to 0.1 % from the wall).
    pub(crate) fn fiber_hit(&self, prim: u32, u: f32, ray: &Ray, t: f32) -> (HitKind, f32) {
        let p = ray.at(t);
        let prim = prim as usize;
        let (axis, tangent) = self.axis_at(prim, u);
        let radius = axis.w.max(f32::MIN_POSITIVE);
        let frame = FiberFrame::new(tangent, -ray.dir);
        let h = ((p - axis.truncate()).dot(frame.width_axis()) / radius).clamp(-1.0, 1.0);
        let t = match self.shape {
            CurveShape::Flat => {
                t + tube_chord(
                    p,
                    ray.dir,
                    axis.truncate(),
                    tangent,
                    radius,
                    &self.capsule(prim),
                )
                .map_or(
                    0.0,
                    |(t_in, t_out)| if t + t_in >= 0.0 { t_in } else { t_out },
                )
            }
            CurveShape::Round => t,
        };
        let strand = &self.strands[self.strand_of[prim] as usize];
        let index = self.first_cp[prim] - strand.first_cp;
        let v = ((index as f32 + u) / strand.segments as f32).clamp(0.0, 1.0);
        let orientation = self.orientations.as_ref().map_or(Vec3::ZERO, |o| {
            // A cubic segment's first polyline point is its second control point.
            let k = self.first_cp[prim] as usize + usize::from(self.basis != CurveBasis::Linear);
            o[k].lerp(o[k + 1], u)
        });
        (
            HitKind::Fiber {
                tangent,
                h,
                radius,
                strand: strand.id,
                v,
                orientation,
            },
            t,
        )
    }

    /// The curve point (position and radius) of primitive `prim` at parameter `u`, and the
    /// unit tangent there (the segment's chord where the derivative vanishes).
    fn axis_at(&self, prim: usize, u: f32) -> (Vec4, Vec3) {
        let cps = self.control_points(prim);
        let (axis, deriv) = self.basis.eval(cps, u);
        let tangent = deriv
            .truncate()
            .try_normalize()
            .or_else(|| {
                let cap = self.capsule_of(prim, cps);
                (cap.b - cap.a).try_normalize()
            })
            .unwrap_or(Vec3::Y);
        (axis, tangent)
    }

    /// Whether the ray from `org` along `dir` that meets primitive `prim` at curve parameter
    /// `u` and distance `t` started inside the fiber there, so that the hit is where it leaves
    /// the fiber: on a tube, a wall facing away from the ray (a back face); on a ribbon, whose
    /// hit lies at the depth of the axis, a chord through the tube that begins behind `org`.
    pub(crate) fn leaves_from_inside(
        &self,
        prim: u32,
        u: f32,
        org: Vec3,
        dir: Vec3,
        t: f32,
    ) -> bool {
        let prim = prim as usize;
        let (axis, tangent) = self.axis_at(prim, u);
        let p = org + t * dir;
        match self.shape {
            // The outward normal of a swept sphere at `p` is `p − axis`.
            CurveShape::Round => (p - axis.truncate()).dot(dir) > 0.0,
            CurveShape::Flat => {
                let radius = axis.w.max(f32::MIN_POSITIVE);
                tube_chord(
                    p,
                    dir,
                    axis.truncate(),
                    tangent,
                    radius,
                    &self.capsule(prim),
                )
                .is_some_and(|(t_in, _)| t + t_in < 0.0)
            }
        }
    }

    /// The material of primitive `prim`.
    #[inline]
    pub(crate) fn material(&self, prim: u32) -> u32 {
        match &self.materials {
            SegmentMaterials::Uniform(m) => *m,
            SegmentMaterials::PerSegment(m) => m[prim as usize],
        }
    }

    pub(crate) fn memory_bytes(&self) -> usize {
        let materials = match &self.materials {
            SegmentMaterials::Uniform(_) => 0,
            SegmentMaterials::PerSegment(m) => m.len() * 4,
        };
        materials
            + self.cps.len() * std::mem::size_of::<Vec4>()
            + self.first_cp.len() * 4
            + self.strand_of.len() * 4
            + self.capsules.len() * std::mem::size_of::<Capsule>()
            + self.strands.len() * std::mem::size_of::<StrandRecord>()
            + self.orientations.as_ref().map_or(0, |o| o.len() * 12)
    }
}

impl CurveData {
    /// The control points (position, radius) of segment `prim`, `basis.order()` of them.
    #[inline]
    pub(crate) fn control_points(&self, prim: usize) -> &[Vec4] {
        let first = self.first_cp[prim] as usize;
        &self.cps[first..first + self.basis.order()]
    }

    /// A capsule containing the fiber swept by segment `prim`.
    #[inline]
    pub(crate) fn capsule(&self, prim: usize) -> Capsule {
        self.capsule_of(prim, self.control_points(prim))
    }

    /// [`Self::capsule`] of segment `prim`, whose control points `cps` the caller has read.
    #[inline]
    fn capsule_of(&self, prim: usize, cps: &[Vec4]) -> Capsule {
        match self.basis {
            CurveBasis::Linear => self.basis.capsule(cps),
            _ => self.capsules[prim],
        }
    }
}

/// Straight chords per cubic curve segment in [`HairCurves::for_each_piece`].
const CUBIC_PIECES: usize = 4;

impl HairCurves for CurveData {
    fn segments(&self) -> usize {
        self.first_cp.len()
    }

    fn for_each_piece(&self, prim: usize, f: &mut dyn FnMut(Vec4, Vec4)) {
        let cps = self.control_points(prim);
        match self.basis {
            CurveBasis::Linear => f(cps[0], cps[1]),
            basis => {
                let mut prev = basis.eval(cps, 0.0).0;
                for k in 1..=CUBIC_PIECES {
                    let next = basis.eval(cps, k as f32 / CUBIC_PIECES as f32).0;
                    f(prev, next);
                    prev = next;
                }
            }
        }
    }

    fn same_strand(&self, a: usize, b: usize) -> bool {
        self.strand_of[a] == self.strand_of[b]
    }
}
