//! The dual-scattering estimator (Zinke, Yuksel, Weber & Keyser 2008) that both
//! dual-scattering integrators share: [`DualScattering`], parameterised by how it chooses light
//! directions ([`DirectionSampling`]): `tress-dual-uniform` uniformly, `tress-dual-mis` by
//! multiple importance sampling.
//!
//! At a hair hit x seen from ω_o the outgoing radiance is
//! `L_o = ∫ L(ω_d) F(ω_o, ω_d; n(ω_d), V(ω_d)) dω_d` (+ the delta lights' terms), where
//! - n(ω_d) is the expected number of fibers crossed from x toward ω_d, from the voxel
//!   density grid of the scene's hair ([`density`], built once per run through
//!   `Scene::fiber_density`);
//! - V(ω_d) is a shadow ray: unoccluded ⇒ the light arrives directly (direct fraction 1, n = 0);
//!   blocked by hair only ⇒ it arrives forward-scattered through n fibers (direct fraction 0);
//!   blocked by a surface (a head, an occluder) ⇒ nothing arrives;
//! - with the fiber-medium tables (the default), the fibers behind the point along the ray
//!   that found it, from the grid too: the depth of hair that returns the local
//!   back-scattering (see `HairPoint`);
//! - F is the shading function of `tress_materials::dual_scattering`.
//!
//! Surfaces that are not hair shade as in the path tracer (next-event estimation plus a
//! continued path, MIS on lights at infinity); a path that reaches hair ends there with the
//! dual-scattering estimate — or, with `path_bounces: k`, shades its first k hair hits the
//! same way and ends with the estimate at the next one. Lights are the scene's lights at
//! infinity (environment, constant, distant with a disc), sampled by the direction strategy,
//! and delta lights (point, distant without a disc), evaluated directly.
//!
//! Settings ([`DualSettings`]), in RON: `DualUniform(d_f: None, d_b: None, grid_resolution:
//! None, tables: (multiple_scattering: FiberMedium), path_bounces: 0)` — `d_f`/`d_b` default
//! to the tables' model (1 for `FiberMedium`, the paper's 0.7 for `Paper`).

#![warn(missing_docs)]

pub mod density;

use density::{DensityGrid, DensitySettings};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use tress_core::integrator::{direct_light, escaped_light, scatter};
use tress_core::prepare::Preparation;
use tress_core::shading::Scattering;
use tress_core::{FiberDensity, Integrator, Material, Ray, Rgb, Sampler, Scene, ShadingPoint};
use tress_materials::dual_scattering::{
    fingerprint, DensityFactors, DualScatteringError, DualScatteringSettings,
    DualScatteringShading, DualScatteringTables,
};

/// Settings shared by both dual-scattering integrators.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DualSettings {
    /// Forward density factor d_f; `None`: the default of the tables' multiple-scattering model
    /// (`DensityFactors::for_model`: 0.7 for the paper's closed forms, 1 for the fiber medium).
    pub d_f: Option<f32>,
    /// Backward density factor d_b; `None` as for d_f.
    pub d_b: Option<f32>,
    /// Voxels along the longest side of the hair's bounds; `None` chooses from the hair.
    pub grid_resolution: Option<u32>,
    /// Resolution of the precomputed tables.
    pub tables: DualScatteringSettings,
    /// Bounces on non-hair surfaces (and hair hits traced by `path_bounces`) before a path
    /// ends.
    pub max_depth: u32,
    /// Hair hits shaded as the path tracer shades them (next-event estimation and a sampled
    /// continuation) before dual scattering shades the next one: 0 (the paper's estimator)
    /// shades the first hair hit a camera ray finds. 1 traces the light reflected between
    /// neighbouring fibers, which dual scattering returns only about half of: on the study's
    /// grooms dark and brown hair come within 1 % of the path tracer at about the same cost,
    /// light hair 1.3–4.7 points darker than with 0 (the book's research notes, "Dual
    /// scattering: accuracy").
    pub path_bounces: u32,
}

impl Default for DualSettings {
    fn default() -> Self {
        DualSettings {
            d_f: None,
            d_b: None,
            grid_resolution: None,
            tables: DualScatteringSettings::default(),
            max_depth: 16,
            path_bounces: 0,
        }
    }
}

/// Why a dual-scattering integrator could not be set up for a scene.
#[derive(Debug, thiserror::Error)]
pub enum DualError {
    /// The scene has hair materials but no hair geometry to build the density grid from.
    #[error(
        "dual scattering shades hair from a density grid of the scene's hair objects, but the \
         scene has hair materials and no hair object: add a `Hair(source: …)` object, or \
         render it with `path`"
    )]
    NoHairGeometry,
    /// The density grid could not be built (e.g. too large for the memory limit); the
    /// message says "density grid: …".
    #[error("{0}")]
    DensityGrid(tress_core::accel::BuildError),
    /// The tables could not be built: invalid table settings, or a non-finite BCSDF value.
    // Causes are in the messages, not also `source`s: chains printed with `{:#}` said them
    // two or three times ("d_f = 1.5: must lie in [0, 1]: d_f = 1.5: …").
    #[error("{0}")]
    Tables(DualScatteringError),
    /// A density factor `d_f` or `d_b` lies outside [0, 1].
    #[error("dual-scattering settings: {0}")]
    Param(tress_materials::ParamError),
}

impl From<DualScatteringError> for DualError {
    fn from(e: DualScatteringError) -> Self {
        DualError::Tables(e)
    }
}

impl From<tress_materials::ParamError> for DualError {
    fn from(e: tress_materials::ParamError) -> Self {
        DualError::Param(e)
    }
}

/// A hair point being shaded: everything a [`DirectionSampling`] needs.
pub struct HairPoint<'a> {
    /// The hit, with its fiber frame and hair BCSDF.
    pub sp: ShadingPoint<'a>,
    /// The dual-scattering shading function F of the point's material.
    pub shading: &'a DualScatteringShading,
    /// The scene's hair density: fibers crossed toward a light.
    pub density: &'a dyn FiberDensity,
    /// `wo` in the local fiber frame.
    pub wo_local: tress_core::math::Vec3,
    /// Offset across the fiber in [−1, 1] (see `tress_core::bcsdf`).
    pub h: f32,
    frame: tress_core::FiberFrame,
    /// Fibers behind the point as seen along the ray that found it: the depth of hair that
    /// returns the local back-scattering. Back-scattering reaches the viewer from lights on its
    /// side, for which "behind, away from the light" and "behind, away from the viewer" are
    /// nearly the same line, and this one is shared by every light direction.
    behind: f32,
}

impl HairPoint<'_> {
    /// World direction from local.
    pub fn to_world(&self, v: tress_core::math::Vec3) -> tress_core::math::Vec3 {
        self.frame.to_world(v)
    }

    /// Local direction from world.
    pub fn to_local(&self, v: tress_core::math::Vec3) -> tress_core::math::Vec3 {
        self.frame.to_local(v)
    }

    /// F(ω_o, ω) for light from world direction `wi` at distance `distance`, with its
    /// visibility resolved by shadow rays and the fibers crossed from the density grid.
    pub fn transport(&self, scene: &Scene, wi: tress_core::math::Vec3, distance: f32) -> Rgb {
        let ray = self.sp.spawn(wi).with_t_max(distance);
        // One ray for the directions that reach the light; a second only for the blocked ones,
        // to tell a surface (nothing arrives) from hair (scattered light arrives).
        let (n, direct) = if !scene.occluded(&ray) {
            (0.0, 1.0)
        } else if scene.occluded_by_surfaces(&ray) {
            return Rgb::ZERO;
        } else {
            let limit = self.shading.tables().settled_counts().toward_light;
            (self.density.fibers_crossed_up_to(&ray, limit), 0.0)
        };
        self.shading.eval_layered(
            self.wo_local,
            self.to_local(wi),
            self.h,
            n,
            self.behind,
            direct,
        )
    }

    /// Radiance from all lights at infinity along `wi`, times F.
    pub fn radiance_from(&self, scene: &Scene, wi: tress_core::math::Vec3) -> Rgb {
        let le = scene.escaped_radiance(wi);
        if le == Rgb::ZERO {
            return Rgb::ZERO;
        }
        le * self.transport(scene, wi, f32::INFINITY)
    }
}

/// How a dual-scattering integrator chooses light directions at a hair point: the one thing
/// the two integrators do differently.
pub trait DirectionSampling: Send + Sync + std::fmt::Debug {
    /// One-sample estimate of `∫ L(ω) F(ω) dω` over the lights at infinity.
    fn estimate(&self, point: &HairPoint, scene: &Scene, sampler: &mut Sampler) -> Rgb;
}

/// The dual-scattering estimator, parameterised by its direction sampling.
pub struct DualScattering<D: DirectionSampling> {
    settings: DualSettings,
    /// Per scene material: the shading function, for hair materials.
    shading: Vec<Option<DualScatteringShading>>,
    /// The scene's hair density (`None` without hair materials, when nothing reads it).
    density: Option<Arc<dyn FiberDensity>>,
    directions: D,
}

impl<D: DirectionSampling> std::fmt::Debug for DualScattering<D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DualScattering")
            .field("settings", &self.settings)
            .field("shading", &self.shading)
            .field("density", &self.density.as_ref().map(|d| d.describe()))
            .field("directions", &self.directions)
            .finish()
    }
}

impl<D: DirectionSampling> DualScattering<D> {
    /// Builds the tables of every hair material of `scene`, or fetches them from `prep` where
    /// an integrator of the run already built them (keyed by the model's [`fingerprint`] and
    /// the table settings, by value).
    pub fn new(
        settings: DualSettings,
        scene: &Scene,
        directions: D,
        prep: &Preparation,
    ) -> Result<Self, DualError> {
        let defaults = DensityFactors::for_model(settings.tables.multiple_scattering);
        let factors = DensityFactors {
            d_f: settings.d_f.unwrap_or(defaults.d_f),
            d_b: settings.d_b.unwrap_or(defaults.d_b),
        };
        let has_hair = scene
            .materials
            .iter()
            .any(|m| matches!(m, Material::Hair(_)));
        let density = if has_hair {
            let grid = scene
                .fiber_density(prep, settings.grid_resolution, |curves, limits| {
                    let settings = DensitySettings {
                        resolution: settings.grid_resolution,
                        ..Default::default()
                    };
                    Ok(Arc::new(DensityGrid::build(curves, &settings, limits)?))
                })
                .map_err(DualError::DensityGrid)?;
            Some(grid.ok_or(DualError::NoHairGeometry)?)
        } else {
            None
        };
        let shading = scene
            .materials
            .iter()
            .map(|m| match m {
                Material::Hair(b) => {
                    let tables = prep
                        .get_or_build((fingerprint(b.as_ref()), settings.tables.clone()), || {
                            DualScatteringTables::new(b.as_ref(), &settings.tables, prep.limits())
                        })?;
                    Ok(Some(DualScatteringShading::new(
                        Arc::clone(b),
                        tables,
                        factors,
                    )?))
                }
                Material::Diffuse { .. } => Ok(None),
            })
            .collect::<Result<Vec<_>, DualError>>()?;
        Ok(DualScattering {
            settings,
            shading,
            density,
            directions,
        })
    }

    fn hair_radiance(
        &self,
        sp: ShadingPoint,
        material: u32,
        scene: &Scene,
        sampler: &mut Sampler,
    ) -> Rgb {
        let (Scattering::Fiber { frame, h, .. }, Some(Some(shading))) =
            (sp.scattering, self.shading.get(material as usize))
        else {
            return Rgb::ZERO;
        };
        let Some(density) = self.density.as_deref() else {
            return Rgb::ZERO;
        };
        let behind = if shading.uses_depth_behind() {
            let limit = shading.tables().settled_counts().behind;
            density.fibers_crossed_up_to(&sp.spawn(-sp.wo), limit)
        } else {
            f32::INFINITY
        };
        let point = HairPoint {
            wo_local: frame.to_local(sp.wo),
            sp,
            shading,
            density,
            h,
            frame,
            behind,
        };
        let mut radiance = self.directions.estimate(&point, scene, sampler);
        // Delta lights have one direction each: evaluate them all.
        for light in scene.lights.delta() {
            if let Some(ls) = light.sample_li(point.sp.p, tress_core::math::Vec2::ZERO) {
                radiance += ls.radiance * point.transport(scene, ls.wi, ls.distance * (1.0 - 1e-4));
            }
        }
        radiance
    }
}

/// Registers a [`DirectionSampling`] type (a unit struct) as the dual-scattering integrator
/// `$name`: implements `tress_core::IntegratorKind` for it, with [`DualSettings`], no bias
/// claim and quick test tables. The two dual-scattering
/// crates differ only in this name and their directions.
#[macro_export]
macro_rules! dual_scattering_integrator {
    ($directions:ident, $name:literal) => {
        impl $crate::__private::IntegratorKind for $directions {
            type Settings = $crate::DualSettings;
            const NAME: &'static str = $name;
            const UNBIASED: bool = false;

            fn build(
                settings: &$crate::DualSettings,
                scene: &$crate::__private::Scene,
                prep: &$crate::__private::Preparation,
            ) -> Result<Box<dyn $crate::__private::Integrator>, $crate::__private::BuildError> {
                settings.build_with(scene, $directions, prep)
            }

            fn test_settings() -> $crate::DualSettings {
                $crate::DualSettings::for_tests()
            }
        }
    };
}

/// What [`dual_scattering_integrator!`] expands to needs, by paths that work from any crate.
#[doc(hidden)]
pub mod __private {
    pub use tress_core::integrator::BuildError;
    pub use tress_core::prepare::Preparation;
    pub use tress_core::{Integrator, IntegratorKind, Scene};
}

impl DualSettings {
    /// Coarse tables (16 θ nodes) that build in a fraction of a second, for tests.
    pub fn for_tests() -> Self {
        DualSettings {
            tables: DualScatteringSettings {
                theta_nodes: 16,
                ..Default::default()
            },
            ..Default::default()
        }
    }

    /// The estimator with `directions`, boxed (for [`tress_core::IntegratorKind::build`]).
    pub fn build_with<D: DirectionSampling + 'static>(
        &self,
        scene: &Scene,
        directions: D,
        prep: &Preparation,
    ) -> Result<Box<dyn Integrator>, tress_core::integrator::BuildError> {
        Ok(Box::new(DualScattering::new(
            self.clone(),
            scene,
            directions,
            prep,
        )?))
    }
}

impl<D: DirectionSampling> Integrator for DualScattering<D> {
    fn li(&self, camera_ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        let select_pdf = scene.lights.non_delta_select_pdf();
        let mut radiance = Rgb::ZERO;
        let mut throughput = Rgb::ONE;
        let mut ray = *camera_ray;
        let mut scatter_pdf: Option<f32> = None;
        let mut hair_hits_traced = 0;
        for depth in 0..=self.settings.max_depth {
            let Some(hit) = scene.intersect(&ray) else {
                for light in scene.lights.non_delta() {
                    radiance += escaped_light(light, ray.dir, scatter_pdf, select_pdf, throughput);
                }
                break;
            };
            let sp = ShadingPoint::new(&hit, &ray, &scene.materials);
            if sp.is_fiber() {
                if hair_hits_traced == self.settings.path_bounces {
                    radiance += throughput * self.hair_radiance(sp, hit.material, scene, sampler);
                    break;
                }
                hair_hits_traced += 1;
            }
            if depth == self.settings.max_depth {
                break;
            }
            // A surface, or a hair hit before `path_bounces` ran out: next-event estimation as
            // in the path tracer. Light that hair blocks on its way here arrives instead, as
            // scattered light, through the continuation, which dual scattering ends at the next
            // hair hit.
            let (u_select, u_light) = (sampler.next_1d(), sampler.next_2d());
            // Every delta light (chosen with probability 1), and one of the others.
            for light in scene.lights.delta() {
                radiance += direct_light(scene, &sp, light, u_light, 1.0, throughput);
            }
            if let Some((light, select_pdf)) = scene.lights.choose_non_delta(u_select) {
                radiance += direct_light(scene, &sp, light, u_light, select_pdf, throughput);
            }
            // Every light with area is sampled directly here, so an escaping ray is weighed.
            let density_needed = scene.lights.non_delta().len() > 0;
            let Some((next, pdf)) = scatter(&sp, sampler, &mut throughput, density_needed) else {
                break;
            };
            scatter_pdf = pdf;
            ray = next;
        }
        radiance
    }
}
