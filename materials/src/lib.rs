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
pub mod pigment;
#[cfg(test)]
mod test_util;

/// An invalid model parameter.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
#[error("{field} = {value}: {reason}")]
pub struct ParamError {
    /// Name of the parameter, as written in scene files.
    pub field: &'static str,
    /// The rejected value, as text.
    pub value: String,
    /// What the value must be, e.g. `must lie in [0, 1]`.
    pub reason: String,
}

impl ParamError {
    /// An error saying that `field` = `value` breaks `reason`.
    pub fn new(
        field: &'static str,
        value: impl std::fmt::Display,
        reason: impl Into<String>,
    ) -> Self {
        ParamError {
            field,
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}

/// `f(0), …, f(n − 1)` on all cores: thread j computes j, j + threads, … (interleaving balances
/// cheap and expensive items), so the result does not depend on the thread count.
pub(crate) fn parallel_map<T: Send>(n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |c| c.get())
        .min(n)
        .max(1);
    let mut out: Vec<Option<T>> = (0..n).map(|_| None).collect();
    std::thread::scope(|s| {
        let f = &f;
        let handles: Vec<_> = (0..threads)
            .map(|j| {
                s.spawn(move || {
                    (j..n)
                        .step_by(threads)
                        .map(|k| (k, f(k)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for h in handles {
            for (k, v) in h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)) {
                out[k] = Some(v);
            }
        }
    });
    out.into_iter().flatten().collect()
}

/// Checks that `value` lies in `[lo, hi]` (and is finite).
pub fn check_range(field: &'static str, value: f32, lo: f32, hi: f32) -> Result<(), ParamError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(ParamError::new(
            field,
            value,
            format!("must lie in [{lo}, {hi}]"),
        ))
    }
}

/// A named parameter set used by the statistical tests of every model.
#[derive(Clone, Debug)]
pub struct TestInstance<P> {
    /// Short name of the instance, used in test messages.
    pub name: String,
    /// The model's parameters.
    pub params: P,
    /// Non-absorbing and energy conserving: the white-furnace oracle applies.
    pub white_furnace: bool,
}

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
