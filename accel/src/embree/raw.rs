//! Raw Embree queries over an [`EmbreeAccel`]'s scene, for `tress bench`: the same BVH and
//! context filter as [`Accel`](tress_core::Accel) queries, but no hit construction (no
//! tangent, `h`, `v` or material), so their throughput is the baseline the renderer is
//! measured against.
//!
//! Single rays run either with tress's self-intersection rule ([`Exclusion::Tress`], what
//! [`Accel::intersect`](tress_core::Accel::intersect) pays for) or without it
//! ([`Exclusion::Off`]: no filter callback at all, so a ray leaving a fiber may hit it or its
//! neighbours from inside). 8-wide packets always run without it: the excluded primitive
//! travels in the intersection context, which a packet's lanes share. A scene built with
//! [`SceneBuilder::without_filters`](crate::SceneBuilder::without_filters) has no filter
//! support at all: the baseline of Embree alone.
//!
//! It is a child of the `embree` module because it builds the private intersection context the
//! filter reads.

use super::{EmbreeAccel, Exclude};
use embree3::{Hit8, IntersectContextExt, Ray8, RayHit, RayHit8, ValidMask, ValidMaskN};
use tress_core::accel::PrimId;
use tress_core::math::Ray;

/// A ray for the raw queries: tress's ray and the distance the query starts at.
#[derive(Clone, Copy, Debug)]
pub struct RawRay {
    /// The ray; its `exclude` is honoured only under [`Exclusion::Tress`].
    pub ray: Ray,
    /// Start of the query interval `(t_near, ray.t_max)`.
    pub t_near: f32,
}

/// Whether a raw query applies tress's self-intersection rule to `ray.exclude`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exclusion {
    /// The capsule rule of the context filter, exactly as in `Accel` queries.
    Tress,
    /// None: no filter callback; `ray.exclude` is ignored.
    Off,
}

/// Lanes in a packet.
pub const PACKET: usize = 8;

/// Embree reads the 8-lane validity mask with 32-byte aligned loads, but `ValidMaskN` is only
/// 16-byte aligned: over-align it (the mask is the first and only field).
#[repr(C, align(32))]
struct Valid8(ValidMaskN<PACKET>);

fn context(accel: &EmbreeAccel, ray: &Ray, exclusion: Exclusion) -> IntersectContextExt<Exclude> {
    match exclusion {
        Exclusion::Tress => accel.context(ray),
        Exclusion::Off => accel.unfiltered_context(),
    }
}

/// The SoA packet of up to [`PACKET`] rays and its validity mask (lanes past the slice are
/// inactive).
fn packet(accel: &EmbreeAccel, rays: &[RawRay]) -> (Ray8, Valid8) {
    assert!(rays.len() <= PACKET, "a packet holds at most {PACKET} rays");
    let mut p = Ray8::empty();
    let mut lanes = [ValidMask::Invalid; PACKET];
    for (i, r) in rays.iter().enumerate() {
        let e = accel.embree_ray_from(&r.ray, r.t_near);
        [p.org_x[i], p.org_y[i], p.org_z[i]] = [e.org_x, e.org_y, e.org_z];
        [p.dir_x[i], p.dir_y[i], p.dir_z[i]] = [e.dir_x, e.dir_y, e.dir_z];
        p.tnear[i] = e.tnear;
        p.tfar[i] = e.tfar;
        lanes[i] = ValidMask::Valid;
    }
    (p, Valid8(ValidMaskN::new(lanes)))
}

impl EmbreeAccel {
    /// Where `ray`, leaving a fiber, leaves that fiber (the far end of the strand's capsules it
    /// starts in); 0 for rays leaving nothing or another primitive. A raw query started there
    /// needs no rule to skip the fiber it leaves: Embree alone, asked the question the rule
    /// answers, without the callbacks.
    pub fn fiber_exit(&self, ray: &Ray) -> f32 {
        ray.exclude
            .map_or(0.0, |ex| match self.geoms.get(ex.geom as usize) {
                Some(super::GeomData::Hair(c)) => c.fiber_exit(ex.prim, ray.origin, ray.dir),
                _ => 0.0,
            })
    }

    /// One `rtcIntersect1`: the primitive hit and its distance.
    pub fn raw_intersect(&self, r: &RawRay, exclusion: Exclusion) -> Option<(PrimId, f32)> {
        let mut ctx = context(self, &r.ray, exclusion);
        let mut rh = RayHit::from(self.embree_ray_from(&r.ray, r.t_near));
        self.scene.intersect(&mut ctx, &mut rh);
        rh.hit.is_valid().then_some((
            PrimId {
                geom: rh.hit.geomID,
                prim: rh.hit.primID,
            },
            rh.ray.tfar - self.origin_shift,
        ))
    }

    /// One `rtcOccluded1`.
    pub fn raw_occluded(&self, r: &RawRay, exclusion: Exclusion) -> bool {
        let mut ctx = context(self, &r.ray, exclusion);
        self.scene
            .occluded(&mut ctx, &mut self.embree_ray_from(&r.ray, r.t_near))
    }

    /// One `rtcIntersect8` over up to [`PACKET`] rays, without exclusion: per lane, the hit
    /// distance.
    ///
    /// # Panics
    /// If `rays` holds more than [`PACKET`] rays.
    pub fn raw_intersect8(&self, rays: &[RawRay]) -> [Option<f32>; PACKET] {
        let (ray, valid) = packet(self, rays);
        let mut rh = RayHit8 {
            ray,
            hit: Hit8::new(),
        };
        let mut ctx = self.unfiltered_context();
        self.scene.intersect8(&mut ctx, &mut rh, &valid.0);
        std::array::from_fn(|i| {
            (i < rays.len() && rh.hit.geomID[i] != u32::MAX)
                .then_some(rh.ray.tfar[i] - self.origin_shift)
        })
    }

    /// One `rtcOccluded8` over up to [`PACKET`] rays, without exclusion: per lane, whether the
    /// ray is blocked.
    ///
    /// # Panics
    /// If `rays` holds more than [`PACKET`] rays.
    pub fn raw_occluded8(&self, rays: &[RawRay]) -> [bool; PACKET] {
        let (mut ray, valid) = packet(self, rays);
        let mut ctx = self.unfiltered_context();
        self.scene.occluded8(&mut ctx, &mut ray, &valid.0);
        // Embree marks a blocked lane by setting its tfar to -inf.
        std::array::from_fn(|i| i < rays.len() && ray.tfar[i] == f32::NEG_INFINITY)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{HairOptions, SceneBuilder};
    use tress_core::math::Vec3;
    use tress_core::rng::Pcg32;
    use tress_core::{Accel, HitKind};
    use tress_groom::test_util::{line, rng_dir};
    use tress_groom::ProceduralHair;

    fn ball() -> EmbreeAccel {
        let hair = ProceduralHair {
            style: tress_groom::HairStyle::Ball,
            strands: 300,
            points_per_strand: 9,
            radius: 0.01,
            ..Default::default()
        }
        .generate(&tress_core::limits::Limits::default())
        .unwrap();
        SceneBuilder::new()
            .unwrap()
            .add_hair(&hair, &HairOptions::default(), 0)
            .unwrap()
            .build()
            .unwrap()
    }

    /// Rays from outside toward the ball, and rays leaving the fibers they hit.
    fn rays(accel: &EmbreeAccel) -> Vec<RawRay> {
        let mut rng = Pcg32::new(3, 0);
        let mut out = Vec::new();
        for _ in 0..400 {
            let o = 3.0 * rng_dir(&mut rng);
            let target = 0.8 * rng_dir(&mut rng);
            let ray = Ray::new(o, (target - o).normalize());
            out.push(RawRay { ray, t_near: 0.0 });
            if let Some(hit) = accel.intersect(&ray) {
                assert!(matches!(hit.kind, HitKind::Fiber { .. }));
                out.push(RawRay {
                    ray: Ray::leaving(hit.p, rng_dir(&mut rng), hit.prim),
                    t_near: 0.0,
                });
            }
        }
        out
    }

    #[test]
    fn tress_exclusion_matches_accel_queries() {
        let accel = ball();
        let rays = rays(&accel);
        let (mut leaving, mut hits) = (0, 0);
        for q in &rays {
            let expect = accel.intersect(&q.ray);
            let raw = accel.raw_intersect(q, Exclusion::Tress);
            assert_eq!(raw.map(|h| h.0), expect.as_ref().map(|h| h.prim));
            // Embree meets a ribbon at its axis; the hit reports the tube's wall, nearer (or,
            // from inside that tube, farther) by at most a segment (0.2 here).
            if let (Some((_, t_raw)), Some(hit)) = (raw, &expect) {
                assert!((t_raw - hit.t).abs() <= 0.21, "{t_raw} vs {}", hit.t);
            }
            assert_eq!(
                accel.raw_occluded(q, Exclusion::Tress),
                accel.occluded(&q.ray)
            );
            leaving += usize::from(q.ray.exclude.is_some());
            hits += usize::from(expect.is_some());
        }
        // The set exercises both kinds of ray and both outcomes.
        assert!(
            leaving > 100 && hits > 100 && hits < rays.len(),
            "{leaving} {hits}"
        );
    }

    #[test]
    fn without_exclusion_the_excluded_primitive_is_ignored() {
        let accel = ball();
        let (mut differ, mut leaving) = (0, 0);
        for r in rays(&accel) {
            let free = RawRay {
                ray: Ray {
                    exclude: None,
                    ..r.ray
                },
                ..r
            };
            let off = accel.raw_intersect(&r, Exclusion::Off);
            assert_eq!(off, accel.raw_intersect(&free, Exclusion::Off));
            assert_eq!(off, accel.raw_intersect(&free, Exclusion::Tress));
            assert_eq!(
                accel.raw_occluded(&r, Exclusion::Off),
                accel.raw_occluded(&free, Exclusion::Tress)
            );
            leaving += usize::from(r.ray.exclude.is_some());
            differ += usize::from(off != accel.raw_intersect(&r, Exclusion::Tress));
        }
        // Some rays leaving a fiber hit it (or its neighbours from inside) without the rule.
        assert!(differ > 0 && differ < leaving, "{differ} of {leaving}");
    }

    #[test]
    fn started_past_their_fiber_rays_find_what_the_rule_keeps() {
        let accel = ball();
        let (mut same, mut leaving, mut moved) = (0, 0, 0);
        for r in rays(&accel) {
            let exit = accel.fiber_exit(&r.ray);
            if r.ray.exclude.is_none() {
                assert_eq!(exit, 0.0);
                continue;
            }
            leaving += 1;
            // Past the wall opposite (0.01 is the fibers' radius), not just off the surface.
            moved += usize::from(exit > 0.01);
            let free = RawRay {
                ray: Ray {
                    exclude: None,
                    ..r.ray
                },
                t_near: exit,
            };
            let past = accel.raw_intersect(&free, Exclusion::Off).map(|h| h.0);
            same += usize::from(past == accel.raw_intersect(&r, Exclusion::Tress).map(|h| h.0));
        }
        // Every ray leaves its fiber's surface, half of them into it; the rule and the start
        // past the fiber differ only where another fiber crosses the one left.
        assert!(
            (0.3..0.7).contains(&(moved as f64 / leaving as f64)),
            "{moved} of {leaving} cross their fiber"
        );
        assert!(same as f64 >= 0.98 * leaving as f64, "{same} of {leaving}");
    }

    #[test]
    fn a_ray_leaves_a_straight_fiber_at_its_far_wall() {
        let (r, len) = (0.05, 1.0);
        let hair =
            tress_groom::test_util::hair(&[line(Vec3::ZERO, Vec3::new(4.0 * len, 0.0, 0.0), 5)], r);
        let options = HairOptions {
            curve: crate::CurveShape::Round,
            ..Default::default()
        };
        let accel = SceneBuilder::new()
            .unwrap()
            .add_hair(&hair, &options, 0)
            .unwrap()
            .build()
            .unwrap();
        let prim = |p: u32| tress_core::accel::PrimId { geom: 0, prim: p };
        let slack = 1e-3 * r + 1e-5;
        // Into the fiber, across it: the far wall, a diameter away.
        let down = Ray::leaving(Vec3::new(1.5, r, 0.0), -Vec3::Y, prim(1));
        assert!((accel.fiber_exit(&down) - 2.0 * r).abs() <= 2.0 * slack);
        // Out of it: at once.
        let up = Ray::leaving(Vec3::new(1.5, r, 0.0), Vec3::Y, prim(1));
        assert!(accel.fiber_exit(&up) <= 2.0 * slack);
        // Along it, from segment 1: through segments 2 and 3 to the strand's round end.
        let along = Ray::leaving(Vec3::new(1.5, 0.0, 0.0), Vec3::X, prim(1));
        assert!((accel.fiber_exit(&along) - (2.5 + r)).abs() <= 2.0 * slack);
    }

    #[test]
    fn packets_match_single_rays() {
        let accel = ball();
        let rays = rays(&accel);
        for chunk in rays.chunks(5).chain(rays.chunks(PACKET)) {
            let hits = accel.raw_intersect8(chunk);
            let blocked = accel.raw_occluded8(chunk);
            for (i, r) in chunk.iter().enumerate() {
                let single = accel.raw_intersect(r, Exclusion::Off).map(|(_, t)| t);
                // The packet and single-ray kernels round differently.
                let close = match (hits[i], single) {
                    (Some(a), Some(b)) => (a - b).abs() <= 1e-5 * b,
                    (a, b) => a == b,
                };
                assert!(close, "lane {i} of {r:?}: {:?} vs {single:?}", hits[i]);
                assert_eq!(blocked[i], accel.raw_occluded(r, Exclusion::Off));
            }
            assert!(hits[chunk.len()..].iter().all(Option::is_none));
            assert!(!blocked[chunk.len()..].iter().any(|&b| b));
        }
    }
}
