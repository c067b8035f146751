//! THE registry of integrators: one line per integrator crate, in `integrators!` at the end
//! of this file. Each line names the crate's [`IntegratorKind`] type; the table generates
//! [`IntegratorDesc`] (the scene-file and command-line form), its names,
//! its builder and [`IntegratorDesc::all`], which the CLI, `tress bench`, studies and the
//! cross-crate tests iterate, so a new integrator is covered everywhere without other edits.

use serde::{Deserialize, Serialize};
use tress_core::integrator::BuildError;
use tress_core::prepare::Preparation;
use tress_core::{Integrator, IntegratorKind, Scene};

macro_rules! integrators {
    ($($(#[$doc:meta])* $variant:ident => $kind:ty,)+) => {
        /// An integrator and its settings, as written in scene files
        /// (`integrator: Path(max_depth: 64)`) or on the command line (`--integrator path`,
        /// `--integrator 'Path(max_depth: 8)'`).
        #[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
        pub enum IntegratorDesc {
            $($(#[$doc])* $variant(#[serde(default)] <$kind as IntegratorKind>::Settings),)+
        }

        impl IntegratorDesc {
            /// Command-line names, in registration order.
            pub const NAMES: &'static [&'static str] =
                &[$(<$kind as IntegratorKind>::NAME),+];

            /// Every registered integrator with its default settings, in registration order.
            pub fn all() -> Vec<IntegratorDesc> {
                vec![$(IntegratorDesc::$variant(Default::default())),+]
            }

            /// Every registered integrator with settings that run quickly in tests.
            pub fn all_for_tests() -> Vec<IntegratorDesc> {
                vec![$(IntegratorDesc::$variant(<$kind as IntegratorKind>::test_settings())),+]
            }

            /// The short name used in file names, reports and EXR headers.
            pub fn name(&self) -> &'static str {
                match self {
                    $(IntegratorDesc::$variant(_) => <$kind as IntegratorKind>::NAME,)+
                }
            }

            /// Whether the images converge to the exact solution (see
            /// [`IntegratorKind::UNBIASED`]).
            pub fn unbiased(&self) -> bool {
                match self {
                    $(IntegratorDesc::$variant(_) => <$kind as IntegratorKind>::UNBIASED,)+
                }
            }

            /// Builds the integrator for `scene`; precomputations (dual-scattering tables)
            /// come from, or go into, the run's `prep`.
            pub fn build(
                &self,
                scene: &Scene,
                prep: &Preparation,
            ) -> Result<Box<dyn Integrator>, IntegratorError> {
                let built = match self {
                    $(IntegratorDesc::$variant(s) =>
                        <$kind as IntegratorKind>::build(s, scene, prep),)+
                };
                built.map_err(|source| IntegratorError { name: self.name(), source })
            }
        }
    };
}

/// Why an integrator could not be built for a scene.
#[derive(Debug, thiserror::Error)]
#[error("integrator {name}")]
pub struct IntegratorError {
    /// The integrator's name.
    pub name: &'static str,
    /// The integrator's own error.
    #[source]
    pub source: BuildError,
}

impl Default for IntegratorDesc {
    fn default() -> Self {
        IntegratorDesc::all().remove(0)
    }
}

impl IntegratorDesc {
    /// Default settings for a command-line name (case-insensitive; `-` and `_` are equivalent).
    pub fn from_name(name: &str) -> Option<Self> {
        let name = name.to_ascii_lowercase().replace('_', "-");
        Self::all().into_iter().find(|d| d.name() == name)
    }

    /// Parses `--integrator`: a registered name or a RON value of this enum.
    pub fn parse_arg(arg: &str) -> Result<Self, String> {
        if let Some(d) = Self::from_name(arg.trim()) {
            return Ok(d);
        }
        crate::ron_format::options().from_str(arg).map_err(|e| {
            format!("unknown integrator '{arg}': expected one of {} or a RON value such as 'Path(max_depth: 8)' ({e})", Self::NAMES.join(", "))
        })
    }
}

integrators! {
    /// Brute-force path tracing with MIS: the ground truth.
    Path => tress_path::PathTracer,
    /// Dual scattering (Zinke et al. 2008), light directions sampled uniformly.
    DualUniform => tress_dual_uniform::UniformDirections,
    /// Dual scattering with MIS of light sampling and shading-function sampling.
    DualMis => tress_dual_mis::MisDirections,
    /// Path tracing that gathers its neighbours' light from a radiance cache trained on the
    /// film's own paths.
    RadianceCache => tress_radiance_cache::RadianceCacheIntegrator,
    /// Path tracing whose continuations are drawn from a mixture of the light learned from
    /// the film's own training paths and the fibers' own sampling: unbiased.
    Guided => tress_guided::GuidedPathTracer,
    /// The path tracer's estimator with the paths of many camera samples advanced together,
    /// their rays traced in batches: the same image as `Path`, bit for bit.
    Wavefront => tress_wavefront::WavefrontPathTracer,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_ron_parse() {
        assert_eq!(IntegratorDesc::all().len(), IntegratorDesc::NAMES.len());
        for (name, desc) in IntegratorDesc::NAMES.iter().zip(IntegratorDesc::all()) {
            let d = IntegratorDesc::parse_arg(name).unwrap();
            assert_eq!(d.name(), *name);
            assert_eq!(d, desc);
            // The RON form round-trips.
            let text = crate::ron_format::options().to_string(&d).unwrap();
            assert_eq!(IntegratorDesc::parse_arg(&text).unwrap(), d, "{text}");
        }
        assert_eq!(
            IntegratorDesc::parse_arg("DUAL_MIS").unwrap().name(),
            "dual-mis"
        );
        let d = IntegratorDesc::parse_arg("Path(max_depth: 8)").unwrap();
        assert_eq!(
            d,
            IntegratorDesc::Path(tress_path::PathSettings {
                max_depth: 8,
                ..Default::default()
            })
        );
        assert!(IntegratorDesc::parse_arg("bogus")
            .unwrap_err()
            .contains("path"));
    }
}
