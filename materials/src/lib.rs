//! tress-materials: hair fiber scattering models behind [`tress_core::Bcsdf`].
//!
//! [`HairModel`] is THE registry of models. Adding a model is one new file (a `Params` struct
//! with serde defaults implementing [`ModelParams`], a type implementing `Bcsdf` with
//! `new(&Params) -> Result<_, ParamError>`, and `test_instances()`), its `pub mod` line and one
//! line in the `hair_models!` invocation below; nothing else names the models one by one. A
//! model that precomputes tables marks its line `(prepared)` and has
//! `prepared(&Params, &Preparation)` instead, which takes them from the run's
//! [`Preparation`] ([`HairModel::build`]). The
//! statistical test suite (`tests/bcsdf_statistics.rs`: white furnace, sampling, χ², …), the
//! registry's own tests below and the dual-scattering tables' tests then cover the new model
//! automatically.

#![warn(missing_docs)]

use pigment::Pigment;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use tress_core::prepare::Preparation;
use tress_core::Bcsdf;

pub mod chiang;
mod cost_inputs;
pub mod deon;
pub mod dual_scattering;
pub mod dual_scattering_sampling;
pub mod fiber_medium;
pub mod fur;
pub mod huang;
pub mod lambertian_fiber;
pub mod marschner;
pub mod model_params;
mod parallel;
mod params;
pub mod pigment;
pub(crate) mod simd_math;
pub mod strand_variation;
#[cfg(test)]
mod test_util;

pub use cost_inputs::CostInputs;
pub use model_params::ModelParams;
pub(crate) use parallel::parallel_map;
pub use params::{check_range, ParamError, TestInstance};

/// One model of the registry built: `new(p)`, or `prepared(p, prep)` for a line marked
/// `(prepared)`.
macro_rules! build_model {
    ($module:ident :: $ty:ident, $p:ident, $prep:ident) => {
        $module::$ty::new($p)
    };
    ($module:ident :: $ty:ident, $p:ident, $prep:ident, prepared) => {
        $module::$ty::prepared($p, $prep)
    };
}

macro_rules! hair_models {
    ($($variant:ident => $module:ident :: $ty:ident $(($how:ident))?),* $(,)?) => {
        /// A hair scattering model and its parameters, as written in scene files.
        #[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
        pub enum HairModel {
            $(
                #[doc = concat!(
                    "The [`", stringify!($ty), "`](", stringify!($module), "::", stringify!($ty),
                    ") model and its parameters."
                )]
                $variant($module::Params),
            )*
        }

        impl HairModel {
            /// Validates the parameters and builds the BCSDF. What a model precomputes (the
            /// fur's medulla tables) it takes from the run's `prep`: built once per key in the
            /// run, and read from or stored in `prep`'s table folder if it has one
            /// ([`Preparation::get_or_build_stored`]). Other models ignore `prep`.
            pub fn build(&self, prep: &Preparation) -> Result<Arc<dyn Bcsdf>, ParamError> {
                match self {
                    $(HairModel::$variant(p) => {
                        Ok(Arc::new(build_model!($module::$ty, p, prep $(, $how)?)?))
                    })*
                }
            }

            /// The registered model names, in registration order.
            pub fn names() -> &'static [&'static str] {
                &[$(stringify!($variant),)*]
            }

            /// Representative instances of every registered model; every statistical test
            /// loops over this list.
            pub fn test_instances() -> Vec<TestInstance<HairModel>> {
                let mut all = Vec::new();
                $(
                    all.extend($module::test_instances().into_iter().map(|t| TestInstance {
                        name: format!("{}/{}", stringify!($variant), t.name),
                        params: HairModel::$variant(t.params),
                        white_furnace: t.white_furnace,
                    }));
                )*
                all
            }

            /// The model's pigment, with the azimuthal roughness β_n at which it converts a
            /// [`Pigment::Color`] (Chiang's fit); `None` for a model without one.
            pub fn pigment(&self) -> Option<(&Pigment, f32)> {
                match self {
                    $(HairModel::$variant(p) => p.pigment(),)*
                }
            }

            /// The same model with `pigment` in place of its own; `None` for a model without
            /// one.
            pub fn with_pigment(&self, pigment: Pigment) -> Option<HairModel> {
                let mut model = self.clone();
                let own = match &mut model {
                    $(HairModel::$variant(p) => p.pigment_mut(),)*
                };
                *own? = pigment;
                Some(model)
            }

            /// The same model with its roughness multiplied by `scale`, clamped to the model's
            /// range ([`ModelParams::scale_roughness`]).
            pub fn with_roughness_scale(&self, scale: f32) -> HairModel {
                let mut model = self.clone();
                match &mut model {
                    $(HairModel::$variant(p) => p.scale_roughness(scale),)*
                }
                model
            }

            /// The registered models that have a pigment, in registration order.
            pub fn names_with_pigment() -> Vec<&'static str> {
                let mut names = Vec::new();
                $(
                    if <$module::Params as Default>::default().pigment().is_some() {
                        names.push(stringify!($variant));
                    }
                )*
                names
            }
        }
    };
}

// THE registry: one line per model; `(prepared)`: built by `prepared(&Params, &Preparation)`.
hair_models! {
    LambertianFiber => lambertian_fiber::LambertianFiber,
    Marschner => marschner::Marschner,
    DEon => deon::DEon,
    Chiang => chiang::Chiang,
    Fur => fur::Fur (prepared),
    Huang => huang::Huang,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{brown, chiang};

    #[test]
    fn models_expose_and_replace_their_pigment() {
        let m = chiang(brown());
        assert_eq!(m.pigment(), Some((&brown(), 0.4)));
        let blond = Pigment::Color((0.8, 0.6, 0.4));
        let swapped = m.with_pigment(blond.clone()).unwrap();
        assert_eq!(swapped.pigment(), Some((&blond, 0.4)));
        let HairModel::Chiang(p) = &swapped else {
            panic!("{swapped:?}")
        };
        assert_eq!((p.beta_m, p.alpha), (0.3, 2.0));
        let marschner = HairModel::Marschner(Default::default());
        assert_eq!(marschner.pigment().unwrap().1, 0.3);
        let deon = HairModel::DEon(Default::default());
        assert!(deon.with_pigment(brown()).is_some());
        let lambert = HairModel::LambertianFiber(Default::default());
        assert!(lambert.pigment().is_none() && lambert.with_pigment(brown()).is_none());
    }

    #[test]
    fn a_roughness_scale_scales_each_models_roughness_within_its_range() {
        let HairModel::Chiang(p) = chiang(brown()).with_roughness_scale(1.5) else {
            panic!()
        };
        assert_eq!((p.beta_m, p.beta_n), (0.3 * 1.5, 0.4 * 1.5));
        let rough = HairModel::Chiang(crate::chiang::Params {
            beta_m: 0.9,
            ..Default::default()
        });
        let HairModel::Chiang(p) = rough.with_roughness_scale(1.5) else {
            panic!()
        };
        assert_eq!(p.beta_m, 1.0, "clamped to the model's range");
        let deon = HairModel::DEon(Default::default()).with_roughness_scale(0.5);
        let HairModel::DEon(p) = deon else { panic!() };
        assert_eq!(
            (p.longitudinal_roughness, p.azimuthal_roughness),
            (0.05, 0.15)
        );
        let marschner = HairModel::Marschner(Default::default()).with_roughness_scale(2.0);
        let HairModel::Marschner(p) = marschner else {
            panic!()
        };
        assert_eq!(p.beta_r, 15.0);
        // A scale of 1 changes nothing.
        let m = chiang(brown());
        assert_eq!(m.with_roughness_scale(1.0), m);
    }

    #[test]
    fn every_model_keeps_its_pigment_and_roughness_consistent() {
        let blond = Pigment::Color((0.8, 0.6, 0.4));
        for inst in HairModel::test_instances() {
            let m = &inst.params;
            let name = &inst.name;
            match m.pigment() {
                Some((_, beta_n)) => {
                    assert!((0.0..=1.0).contains(&beta_n), "{name}: β_n = {beta_n}");
                    let swapped = m.with_pigment(blond.clone()).expect(name);
                    assert_eq!(swapped.pigment(), Some((&blond, beta_n)), "{name}");
                }
                None => assert!(m.with_pigment(blond.clone()).is_none(), "{name}"),
            }
            assert_eq!(
                &m.with_roughness_scale(1.0),
                m,
                "{name}: a scale of 1 changes nothing"
            );
        }
        let names = HairModel::names_with_pigment();
        assert!(names.iter().all(|n| HairModel::names().contains(n)));
        assert!(names.contains(&"Chiang") && !names.contains(&"LambertianFiber"));
    }
}
