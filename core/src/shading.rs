//! A hit turned into something integrators can shade, in world space: the one place that maps a
//! [`Hit`] and its [`Material`] to a local frame and a scattering function.

use crate::accel::{Hit, HitKind, PrimId};
use crate::bcsdf::{Bcsdf, FiberFrame};
use crate::math::{Frame, Ray, Rgb, Vec3};
use crate::sampling::sample_cosine_hemisphere;
use crate::scene::Material;
use std::f32::consts::FRAC_1_PI;

/// The scattering function at a shading point, with its local frame.
#[derive(Clone, Copy, Debug)]
pub enum Scattering<'a> {
    /// A hair fiber with a hair material.
    Fiber {
        /// The fiber's scattering model.
        bcsdf: &'a dyn Bcsdf,
        /// Local fiber frame at the hit (x the tangent, z toward the viewer).
        frame: FiberFrame,
        /// Offset across the fiber in [−1, 1] (see `tress_core::bcsdf`).
        h: f32,
    },
    /// A surface with a diffuse material.
    Diffuse {
        /// Diffuse reflectance per channel, in [0, 1].
        albedo: Rgb,
        /// Frame whose z axis is the geometric normal, facing the incoming ray.
        frame: Frame,
    },
    /// A material that does not apply to the geometry it was put on; absorbs everything.
    Black,
}

/// A world-space direction sampled at a shading point.
#[derive(Clone, Copy, Debug)]
pub struct ScatterSample {
    /// Sampled incident direction, unit, in world space.
    pub wi: Vec3,
    /// Scattering value including the cosine factor (see `tress_core::bcsdf`).
    pub f: Rgb,
    /// Solid-angle density of `wi`.
    pub pdf: f32,
}

/// A hit point ready to shade.
#[derive(Clone, Copy, Debug)]
pub struct ShadingPoint<'a> {
    /// Hit point, in world space.
    pub p: Vec3,
    /// The primitive hit, excluded by rays leaving the point.
    pub prim: PrimId,
    /// Unit world direction toward where the light goes (back along the incoming ray).
    pub wo: Vec3,
    /// How the point scatters, with its local frame.
    pub scattering: Scattering<'a>,
}

impl<'a> ShadingPoint<'a> {
    /// Shading point for `hit`, seen along `ray`, with the scene's `materials`.
    pub fn new(hit: &Hit, ray: &Ray, materials: &'a [Material]) -> Self {
        let wo = -ray.dir;
        let material = materials.get(hit.material as usize);
        let scattering = match (hit.kind, material) {
            (HitKind::Fiber { tangent, h, .. }, Some(Material::Hair(bcsdf))) => Scattering::Fiber {
                bcsdf: bcsdf.as_ref(),
                frame: FiberFrame::new(tangent, wo),
                h,
            },
            (HitKind::Surface { normal }, Some(Material::Diffuse { albedo })) => {
                Scattering::Diffuse {
                    albedo: *albedo,
                    frame: Frame::from_z(normal),
                }
            }
            _ => Scattering::Black,
        };
        ShadingPoint {
            p: hit.p,
            prim: hit.prim,
            wo,
            scattering,
        }
    }

    /// Whether the point is on a hair fiber with a hair material.
    pub fn is_fiber(&self) -> bool {
        matches!(self.scattering, Scattering::Fiber { .. })
    }

    /// Scattering value toward world direction `wi` (cosine included).
    pub fn eval(&self, wi: Vec3) -> Rgb {
        match self.scattering {
            Scattering::Fiber { bcsdf, frame, h } => {
                bcsdf.eval(frame.to_local(self.wo), frame.to_local(wi), h)
            }
            Scattering::Diffuse { albedo, frame } => {
                albedo * (frame.z.dot(wi).max(0.0) * FRAC_1_PI)
            }
            Scattering::Black => Rgb::ZERO,
        }
    }

    /// Solid-angle density of [`ShadingPoint::sample`] producing `wi`.
    pub fn pdf(&self, wi: Vec3) -> f32 {
        match self.scattering {
            Scattering::Fiber { bcsdf, frame, h } => {
                bcsdf.pdf(frame.to_local(self.wo), frame.to_local(wi), h)
            }
            Scattering::Diffuse { frame, .. } => frame.z.dot(wi).max(0.0) * FRAC_1_PI,
            Scattering::Black => 0.0,
        }
    }

    /// `(eval(wi), pdf(wi))` at once: cheaper than the two calls for models that share work.
    pub fn eval_pdf(&self, wi: Vec3) -> (Rgb, f32) {
        match self.scattering {
            Scattering::Fiber { bcsdf, frame, h } => {
                bcsdf.eval_pdf(frame.to_local(self.wo), frame.to_local(wi), h)
            }
            _ => (self.eval(wi), self.pdf(wi)),
        }
    }

    /// Importance-samples an incident direction.
    pub fn sample(&self, u: [f32; 4]) -> Option<ScatterSample> {
        match self.scattering {
            Scattering::Fiber { bcsdf, frame, h } => {
                let s = bcsdf.sample(frame.to_local(self.wo), h, u)?;
                Some(ScatterSample {
                    wi: frame.to_world(s.wi),
                    f: s.f,
                    pdf: s.pdf,
                })
            }
            Scattering::Diffuse { albedo, frame } => {
                let local = sample_cosine_hemisphere(glam::Vec2::new(u[0], u[1]));
                let pdf = local.z * FRAC_1_PI;
                (pdf > 0.0).then(|| ScatterSample {
                    wi: frame.to_world(local),
                    f: albedo * pdf,
                    pdf,
                })
            }
            Scattering::Black => None,
        }
    }

    /// Importance-samples an incident direction (world space) with a Monte Carlo weight of the
    /// same expectation as [`ShadingPoint::sample`]'s `f / pdf`, without its density
    /// ([`Bcsdf::sample_weight`]).
    pub fn sample_weight(&self, u: [f32; 4]) -> Option<(Vec3, Rgb)> {
        match self.scattering {
            Scattering::Fiber { bcsdf, frame, h } => {
                let (wi, weight) = bcsdf.sample_weight(frame.to_local(self.wo), h, u)?;
                Some((frame.to_world(wi), weight))
            }
            // Cosine sampling weighs every direction by the albedo.
            Scattering::Diffuse { albedo, frame } => {
                let local = sample_cosine_hemisphere(glam::Vec2::new(u[0], u[1]));
                (local.z > 0.0).then(|| (frame.to_world(local), albedo))
            }
            Scattering::Black => None,
        }
    }

    /// A ray leaving this point in direction `dir`.
    pub fn spawn(&self, dir: Vec3) -> Ray {
        Ray::leaving(self.p, dir, self.prim)
    }
}
