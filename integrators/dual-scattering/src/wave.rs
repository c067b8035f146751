//! The wave form of the dual-scattering estimator ([`Integrator::li_wave`]): the camera
//! samples of a wave are cut into groups of [`GROUP`], and each step of the estimator runs
//! for the whole group before the next starts — the camera rays traced as one batch
//! ([`Scene::intersect_many`]), the counts of fibers behind the hair points as one
//! ([`FiberDensity::fibers_crossed_many`], which fetches the voxel records of all its walks
//! ahead of reading them), the points' light directions drawn, their shadow rays traced as one
//! batch ([`Scene::occluded_many`]), the counts toward the blocked directions as one, and then
//! F evaluated. Samples whose camera ray does not end in a dual-scattering gather (a surface, a
//! miss, `path_bounces` > 0) take the single-sample path from their traced first hit. Every
//! sample draws its numbers and adds its terms as [`Integrator::li`] does: the images are
//! `li`'s, bit for bit.
//!
//! [`Integrator::li_wave`]: tress_core::Integrator::li_wave
//! [`Integrator::li`]: tress_core::Integrator::li
//! [`FiberDensity::fibers_crossed_many`]: tress_core::FiberDensity::fibers_crossed_many

use crate::{DirectionSampling, DualScattering, HairPoint};
use tress_core::integrator::WaveSample;
use tress_core::math::Vec3;
use tress_core::{Hit, Ray, Rgb, Scene, ShadingPoint};

/// Camera samples advanced together.
pub(crate) const GROUP: usize = 128;

/// The scratch space of a wave, reused from group to group.
#[derive(Default)]
pub(crate) struct Buffers {
    rays: Vec<Ray>,
    hits: Vec<Option<Hit>>,
    /// Per gather: its sample in the group, its material.
    gathers: Vec<(u32, u32)>,
    /// The counts behind the gathers that take one: per gather the index of its query.
    behind_of: Vec<Option<u32>>,
    queries: Vec<(Ray, f32)>,
    counts: Vec<f32>,
    /// Per gather: its estimate, where its direction sampling has no wave form.
    estimated: Vec<Option<Rgb>>,
    /// The directions of all gathers, in the order each gather weighs them.
    directions: Vec<Direction>,
    shadow_rays: Vec<Ray>,
    /// Per shadow ray: its direction.
    shadow_of: Vec<u32>,
    blocked: Vec<bool>,
    /// Per count toward a light: its direction.
    count_of: Vec<u32>,
}

/// A direction of a gather, on its way to a term.
#[derive(Clone, Copy, Debug)]
struct Direction {
    /// The gather.
    gather: u32,
    wi: Vec3,
    w: f32,
    /// All lights at infinity along `wi`.
    le: Rgb,
    /// What the shadow rays and the grid found; `Unknown` while they have not.
    seen: Seen,
}

/// What a direction's visibility resolved to ([`HairPoint::transport`]).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Seen {
    Unknown,
    /// Nothing blocks it.
    Open,
    /// A surface blocks it: nothing arrives.
    Surface,
    /// Hair blocks it: the light arrives through this many fibers.
    Fibers(f32),
}

impl<D: DirectionSampling> DualScattering<D> {
    /// The radiance of every sample of `group`, with `b` as scratch space.
    pub(crate) fn advance(&self, scene: &Scene, group: &mut [WaveSample], b: &mut Buffers) {
        b.rays.clear();
        b.rays.extend(group.iter().map(|w| w.ray));
        b.hits.clear();
        b.hits.resize(group.len(), None);
        scene.intersect_many(&b.rays, &mut b.hits);

        // Which samples end in a gather at their first hit; the others take `li`'s path.
        b.gathers.clear();
        for (i, (w, hit)) in group.iter_mut().zip(&b.hits).enumerate() {
            if let Some(hit) = hit {
                if self.settings.path_bounces == 0
                    && ShadingPoint::new(hit, &w.ray, &scene.materials).is_fiber()
                {
                    b.gathers.push((i as u32, hit.material));
                    continue;
                }
            }
            w.radiance = self.li_from(&w.ray, *hit, scene, &mut w.sampler);
        }

        // The fibers behind every gather, counted together.
        let shading_point = |&(i, _): &(u32, u32)| {
            let i = i as usize;
            let hit = b.hits[i].as_ref().expect("a gather has a hit");
            ShadingPoint::new(hit, &group[i].ray, &scene.materials)
        };
        b.behind_of.clear();
        b.queries.clear();
        for g in &b.gathers {
            let sp = shading_point(g);
            let query = self
                .hair_shading(&sp, g.1)
                .and_then(|(shading, ..)| Self::behind_query(shading, &sp));
            b.behind_of.push(query.map(|q| {
                b.queries.push(q);
                (b.queries.len() - 1) as u32
            }));
        }
        b.counts.clear();
        b.counts.resize(b.queries.len(), 0.0);
        if let Some(density) = self.density.as_deref() {
            density.fibers_crossed_many(&b.queries, &mut b.counts);
        }
        let mut points: Vec<Option<HairPoint>> = Vec::with_capacity(b.gathers.len());
        for (g, behind_of) in b.gathers.iter().zip(&b.behind_of) {
            let sp = shading_point(g);
            points.push(
                self.hair_shading(&sp, g.1)
                    .map(|(shading, density, frame, h)| HairPoint {
                        wo_local: frame.to_local(sp.wo),
                        sp,
                        shading,
                        density,
                        h,
                        frame,
                        behind: behind_of.map_or(f32::INFINITY, |q| b.counts[q as usize]),
                    }),
            );
        }

        // Every gather's directions, drawn in its sample's order; the shadow rays of those
        // the lights at infinity shine along.
        b.estimated.clear();
        b.directions.clear();
        b.shadow_rays.clear();
        b.shadow_of.clear();
        for (k, (point, &(i, _))) in points.iter().zip(&b.gathers).enumerate() {
            let Some(point) = point else {
                b.estimated.push(None);
                continue;
            };
            let sampler = &mut group[i as usize].sampler;
            let Some(directions) = self.directions.weighed_directions(point, scene, sampler) else {
                b.estimated
                    .push(Some(self.directions.estimate(point, scene, sampler)));
                continue;
            };
            b.estimated.push(None);
            for (wi, w) in directions.into_iter().flatten() {
                let le = scene.escaped_radiance(wi);
                if le != Rgb::ZERO {
                    b.shadow_rays
                        .push(point.sp.spawn(wi).with_t_max(f32::INFINITY));
                    b.shadow_of.push(b.directions.len() as u32);
                }
                b.directions.push(Direction {
                    gather: k as u32,
                    wi,
                    w,
                    le,
                    seen: Seen::Unknown,
                });
            }
        }

        // The shadow rays together; then, for those hair blocks, the fibers crossed together.
        b.blocked.clear();
        b.blocked.resize(b.shadow_rays.len(), true);
        scene.occluded_many(&b.shadow_rays, &mut b.blocked);
        b.queries.clear();
        b.count_of.clear();
        for ((ray, &blocked), &d) in b.shadow_rays.iter().zip(&b.blocked).zip(&b.shadow_of) {
            let direction = &mut b.directions[d as usize];
            direction.seen = if !blocked {
                Seen::Open
            } else if scene.occluded_by_surfaces(ray) {
                Seen::Surface
            } else {
                let point = points[direction.gather as usize]
                    .as_ref()
                    .expect("a direction's gather has a point");
                let limit = point.shading.tables().settled_counts().toward_light;
                b.queries.push((*ray, limit));
                b.count_of.push(d);
                Seen::Unknown
            };
        }
        b.counts.clear();
        b.counts.resize(b.queries.len(), 0.0);
        if let Some(density) = self.density.as_deref() {
            density.fibers_crossed_many(&b.queries, &mut b.counts);
        }
        for (&n, &d) in b.counts.iter().zip(&b.count_of) {
            b.directions[d as usize].seen = Seen::Fibers(n);
        }

        // F of every direction, added to its gather's estimate in order (as `weigh` adds them),
        // then the delta lights, as `li` adds them.
        let mut directions = b.directions.iter().peekable();
        for (k, (point, &(i, _))) in points.iter().zip(&b.gathers).enumerate() {
            let hair = match point {
                None => Rgb::ZERO,
                Some(point) => {
                    let radiance = match b.estimated[k] {
                        Some(estimate) => estimate,
                        None => {
                            let mut radiance = Rgb::ZERO;
                            while let Some(d) = directions.next_if(|d| d.gather == k as u32) {
                                radiance += Self::term(point, d) * d.w;
                            }
                            radiance
                        }
                    };
                    Self::add_delta_lights(point, scene, radiance)
                }
            };
            // `li`'s sum for a path that ends at its first hit, with throughput 1.
            group[i as usize].radiance = Rgb::ZERO + Rgb::ONE * hair;
        }
    }

    /// `point.radiance_from(scene, d.wi)` of a direction whose visibility is resolved.
    fn term(point: &HairPoint, d: &Direction) -> Rgb {
        if d.le == Rgb::ZERO {
            return Rgb::ZERO;
        }
        let (n, direct) = match d.seen {
            Seen::Open => (0.0, 1.0),
            Seen::Surface => return d.le * Rgb::ZERO,
            Seen::Fibers(n) => (n, 0.0),
            Seen::Unknown => unreachable!("every shadow ray is traced"),
        };
        d.le * point.shading.eval_layered(
            point.wo_local,
            point.to_local(d.wi),
            point.h,
            n,
            point.behind,
            direct,
        )
    }
}
