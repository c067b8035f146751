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
            (
                HitKind::Fiber {
                    tangent,
                    h,
                    orientation,
                    ..
                },
                Some(Material::Hair(bcsdf)),
            ) => Scattering::Fiber {
                bcsdf: bcsdf.as_ref(),
                // Round models see the view-facing frame, exactly as before orientation existed.
                frame: if bcsdf.uses_orientation() {
                    FiberFrame::oriented(tangent, orientation, wo)
                } else {
                    FiberFrame::new(tangent, wo)
                },
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bcsdf::BcsdfSample;
    use std::sync::Arc;

    /// Returns the local `wo` it is handed, so a test sees the frame the shading point built.
    #[derive(Debug)]
    struct Probe {
        oriented: bool,
    }

    impl Bcsdf for Probe {
        fn eval(&self, wo: Vec3, _wi: Vec3, _h: f32) -> Rgb {
            wo
        }
        fn sample(&self, _wo: Vec3, _h: f32, _u: [f32; 4]) -> Option<BcsdfSample> {
            None
        }
        fn pdf(&self, _wo: Vec3, _wi: Vec3, _h: f32) -> f32 {
            0.0
        }
        fn uses_orientation(&self) -> bool {
            self.oriented
        }
    }

    fn local_wo(oriented: bool, orientation: Vec3) -> Vec3 {
        let materials = [Material::Hair(Arc::new(Probe { oriented }))];
        let ray = Ray::new(
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::new(0.1, 0.2, -1.0).normalize(),
        );
        let hit = Hit {
            t: 5.0,
            p: Vec3::ZERO,
            prim: PrimId { geom: 0, prim: 0 },
            material: 0,
            kind: HitKind::Fiber {
                tangent: Vec3::X,
                h: 0.3,
                radius: 0.01,
                strand: 0,
                v: 0.5,
                orientation,
            },
        };
        ShadingPoint::new(&hit, &ray, &materials).eval(Vec3::Y)
    }

    #[test]
    fn only_models_that_use_the_orientation_see_it() {
        // Round models: the view-facing frame, bit for bit, whatever the orientation.
        let facing = local_wo(false, Vec3::Y);
        assert_eq!(facing, local_wo(false, Vec3::Z));
        assert!(facing.y.abs() < 1e-6 && facing.z > 0.0, "{facing}");
        // Oriented models: z is the orientation, so wo's components follow it.
        let wo = -Vec3::new(0.1, 0.2, -1.0).normalize();
        let along_y = local_wo(true, Vec3::Y);
        assert!((along_y.z - wo.y).abs() < 1e-6, "{along_y}");
        let along_z = local_wo(true, Vec3::new(0.3, 0.0, 2.0));
        assert!((along_z.z - wo.z).abs() < 1e-6 && (along_z.x - wo.x).abs() < 1e-6);
    }
}
