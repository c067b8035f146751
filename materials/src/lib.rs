//! tress-materials: hair fiber scattering models behind [`tress_core::Bcsdf`].
//!
//! [`HairModel`] is THE registry of models. Adding a model is one new file (a `Params` struct
//! with serde defaults, a type implementing `Bcsdf` with `new(&Params) -> Result<_, ParamError>`,
//! and `test_instances()`) plus one line in the `hair_models!` invocation below; the statistical
//! test suite (`tests/bcsdf_statistics.rs`) then covers the new model automatically.

#![warn(missing_docs)]

use serde::{Deserialize, Serialize};
use std::sync::Arc;
use tress_core::Bcsdf;

pub mod chiang;
pub mod deon;
pub mod dual_scattering;
pub mod dual_scattering_sampling;
pub mod fiber_medium;
pub mod lambertian_fiber;
pub mod marschner;
mod parallel;
mod params;
pub mod pigment;
#[cfg(test)]
mod test_util;

pub use params::{check_range, ParamError, TestInstance};
pub(crate) use parallel::parallel_map;

macro_rules! hair_models {
    ($($variant:ident => $module:ident :: $ty:ident),* $(,)?) => {
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
            /// Validates the parameters and builds the BCSDF.
            pub fn build(&self) -> Result<Arc<dyn Bcsdf>, ParamError> {
                match self {
                    $(HairModel::$variant(p) => Ok(Arc::new($module::$ty::new(p)?)),)*
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
        }
    };
}

// THE registry: one line per model.
hair_models! {
    LambertianFiber => lambertian_fiber::LambertianFiber,
    Marschner => marschner::Marschner,
    DEon => deon::DEon,
    Chiang => chiang::Chiang,
}
