//! THE registry of integrators: one enum variant per integrator crate.

use serde::{Deserialize, Serialize};
use tress_accel::DensitySettings;
use tress_core::{Integrator, Scene};
use tress_dual_uniform::DualSettings;

/// An integrator and its settings, as written in scene files (`integrator: Path(max_depth: 64)`)
/// or on the command line (`--integrator path`, `--integrator 'Path(max_depth: 8)'`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub enum IntegratorDesc {
    /// Brute-force path tracing with MIS: the ground truth.
    Path(#[serde(default)] tress_path::PathSettings),
    /// Dual scattering (Zinke et al. 2008), light directions sampled uniformly.
    DualUniform(#[serde(default)] DualSettings),
    /// Dual scattering with MIS of light sampling and shading-function sampling.
    DualMis(#[serde(default)] DualSettings),
}

impl Default for IntegratorDesc {
    fn default() -> Self {
        IntegratorDesc::Path(Default::default())
    }
}

impl IntegratorDesc {
    /// Command-line names, in registration order.
    pub const NAMES: &'static [&'static str] = &["path", "dual-uniform", "dual-mis"];

    /// The short name used in file names, reports and EXR headers.
    pub fn name(&self) -> &'static str {
        match self {
            IntegratorDesc::Path(_) => "path",
            IntegratorDesc::DualUniform(_) => "dual-uniform",
            IntegratorDesc::DualMis(_) => "dual-mis",
        }
    }

    /// Default settings for a command-line name (case-insensitive; `-` and `_` are equivalent).
    pub fn from_name(name: &str) -> Option<Self> {
        match name.to_ascii_lowercase().replace('_', "-").as_str() {
            "path" => Some(IntegratorDesc::Path(Default::default())),
            "dual-uniform" => Some(IntegratorDesc::DualUniform(Default::default())),
            "dual-mis" => Some(IntegratorDesc::DualMis(Default::default())),
            _ => None,
        }
    }

    /// Parses `--integrator`: a registered name or a RON value of this enum.
    pub fn parse_arg(arg: &str) -> Result<Self, String> {
        if let Some(d) = Self::from_name(arg.trim()) {
            return Ok(d);
        }
        crate::ron_options().from_str(arg).map_err(|e| {
            format!("unknown integrator '{arg}': expected one of {} or a RON value such as 'Path(max_depth: 8)' ({e})", Self::NAMES.join(", "))
        })
    }

    /// The hair density grid the integrator needs in the scene, if any.
    pub fn density_grid(&self) -> Option<DensitySettings> {
        match self {
            IntegratorDesc::Path(_) => None,
            IntegratorDesc::DualUniform(s) | IntegratorDesc::DualMis(s) => Some(DensitySettings {
                resolution: s.grid_resolution,
                ..Default::default()
            }),
        }
    }

    /// Builds the integrator for `scene` (dual scattering precomputes its tables here).
    pub fn build(&self, scene: &Scene) -> anyhow::Result<Box<dyn Integrator>> {
        Ok(match self {
            IntegratorDesc::Path(s) => Box::new(tress_path::PathTracer::new(s.clone())),
            IntegratorDesc::DualUniform(s) => Box::new(tress_dual_uniform::DualUniform::new(
                s.clone(),
                scene,
                tress_dual_uniform::UniformDirections,
            )?),
            IntegratorDesc::DualMis(s) => Box::new(tress_dual_mis::DualMis::new(
                s.clone(),
                scene,
                tress_dual_mis::MisDirections,
            )?),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_ron_parse() {
        for name in IntegratorDesc::NAMES {
            let d = IntegratorDesc::parse_arg(name).unwrap();
            assert_eq!(d.name(), *name);
        }
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
