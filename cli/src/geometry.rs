//! Scene objects (hair, meshes, spheres) and building the Embree accelerator from them.

use anyhow::{anyhow, Result};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tress_accel::{EmbreeAccel, HairOptions, HairSource, SceneBuilder, Transform, TriangleMesh};
use tress_core::Material;

/// An object of the scene, referring to a material by name.
#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum ObjectDesc {
    /// Hair: `Hair(source: File("straight.hair"), material: "brown", options: (...))`.
    Hair {
        /// Where the strands come from: a file or a generator.
        source: HairSource,
        /// Name of a `Hair(...)` material in the scene's `materials`.
        material: String,
        /// How the strands become curves, and their transform (defaults if omitted).
        #[serde(default)]
        options: HairOptions,
    },
    /// A triangle mesh from an OBJ file.
    Mesh {
        /// The OBJ file, relative to the scene file's folder.
        file: PathBuf,
        /// Name of a `Diffuse(...)` material in the scene's `materials`.
        material: String,
        /// Scale, rotation and translation applied to the vertices (none if omitted).
        #[serde(default)]
        transform: Transform,
    },
    /// A sphere.
    Sphere {
        /// Centre, in world space.
        #[schemars(with = "[f32; 3]")]
        center: Vec3,
        /// Radius, in scene units; finite and positive.
        radius: f32,
        /// Name of a `Diffuse(...)` material in the scene's `materials`.
        material: String,
    },
}

impl ObjectDesc {
    fn material(&self) -> &str {
        match self {
            ObjectDesc::Hair { material, .. }
            | ObjectDesc::Mesh { material, .. }
            | ObjectDesc::Sphere { material, .. } => material,
        }
    }
}

/// Resolves `p` against the folder holding the scene file.
pub fn resolve(scene_path: &Path, p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        scene_path.parent().unwrap_or(Path::new(".")).join(p)
    }
}

/// Builds the accelerator for the scene's objects; returns it with a summary (`tress info`).
pub fn build_accel(
    objects: &[ObjectDesc],
    scene_path: &Path,
    material_index: &BTreeMap<String, u32>,
    materials: &[Material],
) -> Result<(EmbreeAccel, String)> {
    let here = |i: usize, what: String| anyhow!("{}: objects[{i}]: {what}", scene_path.display());
    let mut builder = SceneBuilder::new()?;
    for (i, object) in objects.iter().enumerate() {
        let name = object.material();
        let &material = material_index.get(name).ok_or_else(|| {
            let known: Vec<&str> = material_index.keys().map(String::as_str).collect();
            here(
                i,
                format!("unknown material '{name}' (defined: {})", known.join(", ")),
            )
        })?;
        let is_hair_material = matches!(materials[material as usize], Material::Hair(_));
        builder = match object {
            ObjectDesc::Hair {
                source, options, ..
            } => {
                if !is_hair_material {
                    return Err(here(
                        i,
                        format!("hair needs a Hair(...) material, but '{name}' is not one"),
                    ));
                }
                let mut source = source.clone();
                if let Some(p) = source.path_mut() {
                    *p = resolve(scene_path, p);
                }
                let hair = source.load().map_err(|e| here(i, e.to_string()))?;
                builder
                    .add_hair(&hair, options, material)
                    .map_err(|e| here(i, e.to_string()))?
            }
            ObjectDesc::Mesh {
                file, transform, ..
            } => {
                if is_hair_material {
                    return Err(here(
                        i,
                        format!(
                            "meshes need a Diffuse(...) material, but '{name}' is a hair model"
                        ),
                    ));
                }
                let mesh = TriangleMesh::load_obj(&resolve(scene_path, file))
                    .map_err(|e| here(i, e.to_string()))?;
                builder
                    .add_mesh(&mesh, transform, material)
                    .map_err(|e| here(i, e.to_string()))?
            }
            ObjectDesc::Sphere { center, radius, .. } => {
                if is_hair_material {
                    return Err(here(
                        i,
                        format!(
                            "spheres need a Diffuse(...) material, but '{name}' is a hair model"
                        ),
                    ));
                }
                builder
                    .add_sphere(*center, *radius, material)
                    .map_err(|e| here(i, e.to_string()))?
            }
        };
    }
    let accel = builder
        .build()
        .map_err(|e| anyhow!("{}: {e}", scene_path.display()))?;
    let summary = accel.info().to_string();
    Ok((accel, summary))
}
