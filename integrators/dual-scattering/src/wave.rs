//! The wave form of the dual-scattering estimator ([`Integrator::li_wave`]): the camera
//! samples of a wave are cut into groups of [`GROUP`], and each step of the estimator runs
//! for the whole group before the next starts — the camera rays traced as one batch
//! ([`Scene::intersect_many`]), the gathers sorted by the fiber segment they hit, the fibers
//! behind each counted, the light table entries that every gather's first draws pick asked
//! for before any is read, the directions drawn, their shadow rays traced as one batch
//! ([`Scene::occluded_many`]), the fibers toward the blocked directions counted, and then F
//! evaluated. Samples whose camera ray does not end in a dual-scattering gather (a surface, a
//! miss, `path_bounces` > 0) take the single-sample path from their traced first hit. Every
//! sample draws its numbers and adds its terms as [`Integrator::li`] does: the images are
//! `li`'s, bit for bit.
//!
//! The counts walk the grid one ray at a time. Walking a group's rays together, with each
//! round's voxel records prefetched for all walks before any is read, or with a first pass
//! over each walk's first voxels that only prefetches, made a count slower (1.09–1.32× on
//! straight.hair; the book's performance notes, "Where a dual-mis sample goes").
//!
//! [`Integrator::li_wave`]: tress_core::Integrator::li_wave
//! [`Integrator::li`]: tress_core::Integrator::li

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
    /// Per gather: its estimate, where its direction sampling has no wave form.
    estimated: Vec<Option<Rgb>>,
    /// The directions of all gathers, in the order each gather weighs them.
    directions: Vec<Direction>,
    shadow_rays: Vec<Ray>,
    /// Per shadow ray: its direction.
    shadow_of: Vec<u32>,
    blocked: Vec<bool>,
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

        // Gathers at the same fiber segment one after another: the own strand that each
        // count behind takes out is read once for all of them.
        b.gathers.sort_unstable_by_key(|&(i, _)| {
            let prim = b.hits[i as usize]
                .as_ref()
                .expect("a gather has a hit")
                .prim;
            (prim.geom, prim.prim, i)
        });

        // Every gather's point, with the fibers behind it counted.
        let mut points: Vec<Option<HairPoint>> = Vec::with_capacity(b.gathers.len());
        for &(i, material) in &b.gathers {
            let i = i as usize;
            let hit = b.hits[i].as_ref().expect("a gather has a hit");
            let sp = ShadingPoint::new(hit, &group[i].ray, &scene.materials);
            points.push(
                self.hair_shading(&sp, material)
                    .map(|(shading, density, frame, h)| HairPoint {
                        wo_local: frame.to_local(sp.wo),
                        sp,
                        shading,
                        density,
                        h,
                        frame,
                        behind: Self::behind_query(shading, &sp)
                            .map_or(f32::INFINITY, |(ray, limit)| {
                                density.fibers_crossed_up_to(&ray, limit)
                            }),
                    }),
            );
        }

        // The light's table entries that every gather's first draws pick (if it draws them),
        // asked for before any is read.
        if scene.lights.sampling_reads_tables() {
            for (point, &(i, _)) in points.iter().zip(&b.gathers) {
                if point.is_some() {
                    let mut ahead = group[i as usize].sampler.clone();
                    let (u_select, u_light) = (ahead.next_1d(), ahead.next_2d());
                    if let Some((light, _)) = scene.lights.choose_non_delta(u_select) {
                        light.prefetch_sample(u_light);
                    }
                }
            }
        }
        // Every gather's directions, drawn in its sample's order, with the lights' radiance
        // along each asked for.
        b.estimated.clear();
        b.directions.clear();
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
                scene.lights.infinite().for_each(|l| l.prefetch_le(wi));
                b.directions.push(Direction {
                    gather: k as u32,
                    wi,
                    w,
                    le: Rgb::ZERO,
                    seen: Seen::Unknown,
                });
            }
        }
        // The shadow rays of the directions the lights shine along.
        b.shadow_rays.clear();
        b.shadow_of.clear();
        for (d, direction) in b.directions.iter_mut().enumerate() {
            direction.le = scene.escaped_radiance(direction.wi);
            if direction.le != Rgb::ZERO {
                let point = points[direction.gather as usize]
                    .as_ref()
                    .expect("a direction's gather has a point");
                b.shadow_rays
                    .push(point.sp.spawn(direction.wi).with_t_max(f32::INFINITY));
                b.shadow_of.push(d as u32);
            }
        }

        // The shadow rays together; then, for those hair blocks, the fibers crossed.
        b.blocked.clear();
        b.blocked.resize(b.shadow_rays.len(), true);
        scene.occluded_many(&b.shadow_rays, &mut b.blocked);
        for ((ray, &blocked), &d) in b.shadow_rays.iter().zip(&b.blocked).zip(&b.shadow_of) {
            let direction = &mut b.directions[d as usize];
            let point = points[direction.gather as usize]
                .as_ref()
                .expect("a direction's gather has a point");
            direction.seen = if !blocked {
                Seen::Open
            } else if scene.occluded_by_surfaces(ray) {
                Seen::Surface
            } else {
                let limit = point.shading.tables().settled_counts().toward_light;
                Seen::Fibers(point.density.fibers_crossed_up_to(ray, limit))
            };
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
