//! Materials as scene files write them.

use glam::Vec3;
use serde::{Deserialize, Serialize};
use tress_materials::HairModel;

/// A material: a hair model for fibers, or a diffuse surface for meshes and spheres.
#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum MaterialDesc {
    /// A hair scattering model, for hair objects.
    Hair(HairModel),
    /// A Lambertian surface, for meshes and spheres.
    Diffuse {
        /// Reflectance per channel, in [0, 1].
        #[schemars(with = "[f32; 3]")]
        albedo: Vec3,
    },
}
