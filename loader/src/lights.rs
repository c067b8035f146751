//! Light sources as scene files write them, and building them.

use crate::error::{Error, Result};
use crate::paths::resolve;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use tress_core::light::{EnvironmentMap, Light};

/// A light source.
#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum LightDesc {
    /// Equirectangular HDR environment (Radiance .hdr or OpenEXR).
    Environment {
        /// The map, relative to the scene file's folder.
        file: PathBuf,
        /// Rotation about +y, degrees.
        #[serde(default)]
        rotation: f32,
        /// Multiplies the map's radiance; finite and ≥ 0 (default 1).
        #[serde(default = "one")]
        scale: f32,
    },
    /// The built-in procedural sky with a sun (needs no files).
    Sky {
        /// Rotation about +y, in degrees (default 0).
        #[serde(default)]
        rotation: f32,
        /// Multiplies the sky's radiance; finite and ≥ 0 (default 1).
        #[serde(default = "one")]
        scale: f32,
    },
    /// Uniform radiance from all directions.
    Constant {
        /// Radiance per channel, ≥ 0.
        #[schemars(with = "[f32; 3]")]
        radiance: Vec3,
    },
    /// A distant light (sun) shining along `direction`, delivering `irradiance` perpendicular to
    /// it, from a disc of angular radius `angular_radius` degrees (0: a delta light).
    Distant {
        /// Direction the light travels (from the sun into the scene); any non-zero length.
        #[schemars(with = "[f32; 3]")]
        direction: Vec3,
        /// Irradiance per channel on a surface facing the light, ≥ 0.
        #[schemars(with = "[f32; 3]")]
        irradiance: Vec3,
        /// Angular radius of the sun's disc in degrees, in [0, 90) (default 0: a delta light).
        #[serde(default)]
        angular_radius: f32,
    },
    /// A point light of the given intensity (W/sr).
    Point {
        /// Position of the light, in world space.
        #[schemars(with = "[f32; 3]")]
        position: Vec3,
        /// Radiant intensity per channel, in W/sr, ≥ 0.
        #[schemars(with = "[f32; 3]")]
        intensity: Vec3,
    },
}

fn one() -> f32 {
    1.0
}

/// Builds light `lights[index]` of the scene at `scene_path`; relative paths resolve against
/// its folder.
pub fn build_light(index: usize, l: &LightDesc, scene_path: &Path) -> Result<Light> {
    let map_error = |source| Error::EnvironmentMap {
        scene: scene_path.to_owned(),
        index,
        source,
    };
    let light_error = |source| Error::Light {
        scene: scene_path.to_owned(),
        index,
        source,
    };
    match l {
        LightDesc::Environment {
            file,
            rotation,
            scale,
        } => EnvironmentMap::from_file(resolve(scene_path, file), *rotation, *scale)
            .map(Light::Environment)
            .map_err(map_error),
        LightDesc::Sky { rotation, scale } => EnvironmentMap::builtin_sky(*rotation, *scale)
            .map(Light::Environment)
            .map_err(map_error),
        LightDesc::Constant { radiance } => Light::constant(*radiance).map_err(light_error),
        LightDesc::Distant {
            direction,
            irradiance,
            angular_radius,
        } => Light::distant(*direction, *irradiance, *angular_radius).map_err(light_error),
        LightDesc::Point {
            position,
            intensity,
        } => Light::point(*position, *intensity).map_err(light_error),
    }
}
