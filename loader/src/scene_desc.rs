//! Scene files: RON descriptions deserialised with serde, then built into a renderable
//! [`tress_core::Scene`].
//!
//! All enums are externally tagged (RON's native `Variant(...)` syntax), every struct denies
//! unknown fields, and relative paths resolve against the scene file's folder.

use crate::error::{Error, Result};
use crate::geometry::{self, ObjectDesc};
use crate::integrators::IntegratorDesc;
use crate::lights::{build_light, LightDesc};
use crate::materials::MaterialDesc;
use crate::paths::resolve;
use crate::placeholders::{substitute, Defines};
use crate::ron_format::SyntaxError;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tress_accel::{EmbreeAccel, SceneBuilder};
use tress_core::film::FilmSettings;
use tress_core::output_file::Inputs;
use tress_core::prepare::Preparation;
use tress_core::{Accel, Camera, Material, Scene};

/// A whole scene file.
#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SceneDesc {
    /// The view the image is taken from.
    pub camera: CameraDesc,
    /// Resolution, samples per pixel, seed and crop window.
    pub film: FilmSettings,
    /// How light transport is computed (default `Path` with its default settings).
    #[serde(default)]
    pub integrator: IntegratorDesc,
    /// Named materials, referred to by objects; a name given twice is an error.
    #[serde(deserialize_with = "unique_names")]
    pub materials: BTreeMap<String, MaterialDesc>,
    /// Hair, meshes and spheres, each naming its material.
    pub objects: Vec<ObjectDesc>,
    /// The light sources.
    pub lights: Vec<LightDesc>,
}

impl SceneDesc {
    /// Every file the scene reads (hair and the files a pbrt groom includes, meshes,
    /// environment maps), resolved against `scene_path` as [`build`] resolves them.
    pub fn referenced_files(&self, scene_path: &Path) -> Result<Vec<PathBuf>> {
        let mut files = Vec::new();
        for object in &self.objects {
            match object {
                ObjectDesc::Hair { source, .. } => {
                    let mut source = source.clone();
                    if let Some(p) = source.path_mut() {
                        *p = resolve(scene_path, p);
                    }
                    files.extend(source.files().map_err(|source| Error::HairFiles {
                        scene: scene_path.to_owned(),
                        source,
                    })?);
                }
                ObjectDesc::Mesh { file, .. } => {
                    files.push(resolve(scene_path, file));
                }
                ObjectDesc::Sphere { .. } => {}
            }
        }
        for light in &self.lights {
            if let LightDesc::Environment { file, .. } = light {
                files.push(resolve(scene_path, file));
            }
        }
        Ok(files)
    }

    /// The scene file at `scene_path` and every file it reads
    /// ([`referenced_files`](Self::referenced_files)): what the outputs of a command rendering
    /// it may not replace.
    pub fn inputs(&self, scene_path: &Path) -> Result<Inputs> {
        let mut inputs: Inputs = self.referenced_files(scene_path)?.into_iter().collect();
        inputs.add(scene_path);
        Ok(inputs)
    }

    /// A hash of the contents of every file the scene reads
    /// ([`referenced_files`](Self::referenced_files)): part of the keys of study caches and of
    /// the scene hash that merged pieces must share, so that renders of a file's old contents
    /// are not taken for renders of its new ones.
    pub fn files_hash(&self, scene_path: &Path) -> Result<u64> {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for f in self.referenced_files(scene_path)? {
            let bytes = tress_core::files::read_regular(&f).map_err(|source| Error::Input {
                scene: scene_path.to_owned(),
                file: f.clone(),
                source,
            })?;
            for b in bytes.iter().chain(b"|") {
                h = (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
        Ok(h)
    }
}

/// A map that refuses a key given twice (serde's own keeps the last silently).
fn unique_names<'de, D, V>(d: D) -> std::result::Result<BTreeMap<String, V>, D::Error>
where
    D: serde::Deserializer<'de>,
    V: Deserialize<'de>,
{
    struct Unique<V>(std::marker::PhantomData<V>);
    impl<'de, V: Deserialize<'de>> serde::de::Visitor<'de> for Unique<V> {
        type Value = BTreeMap<String, V>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a map of names")
        }
        fn visit_map<A: serde::de::MapAccess<'de>>(
            self,
            mut map: A,
        ) -> std::result::Result<Self::Value, A::Error> {
            let mut out = BTreeMap::new();
            while let Some((name, value)) = map.next_entry::<String, V>()? {
                if out.contains_key(&name) {
                    return Err(serde::de::Error::custom(format!(
                        "material \"{name}\" is defined twice"
                    )));
                }
                out.insert(name, value);
            }
            Ok(out)
        }
    }
    d.deserialize_map(Unique(std::marker::PhantomData))
}

/// Perspective camera.
#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CameraDesc {
    /// Camera position, in world space.
    #[schemars(with = "[f32; 3]")]
    pub look_from: Vec3,
    /// Point the camera looks at (the image centre).
    #[schemars(with = "[f32; 3]")]
    pub look_at: Vec3,
    /// Direction that appears upwards in the image (default +y).
    #[serde(default = "default_up")]
    #[schemars(with = "[f32; 3]")]
    pub up: Vec3,
    /// Vertical field of view in degrees, in (0, 180).
    #[serde(default = "default_fov")]
    pub fov: f32,
    /// Thin-lens aperture radius in scene units; 0 is a pinhole.
    #[serde(default)]
    pub lens_radius: f32,
    /// Distance to the plane in focus; default: the distance to `look_at`.
    #[serde(default)]
    pub focus_distance: Option<f32>,
}

fn default_up() -> Vec3 {
    Vec3::Y
}

fn default_fov() -> f32 {
    40.0
}

/// A scene built from its description, with a human-readable summary of what it holds.
pub struct BuiltScene {
    /// The renderable scene.
    pub scene: Scene,
    /// What was built and how long it took, printed by `tress info` and by verbose renders.
    pub summary: String,
}

/// Reads and parses a scene file; errors name the file, line and column.
pub fn load(path: &Path) -> Result<SceneDesc> {
    load_with(path, &Defines::new())
}

/// Reads a scene file, replaces its placeholders with `defines` ([`substitute`]) and parses it;
/// errors name the file, line and column.
pub fn load_with(path: &Path, defines: &Defines) -> Result<SceneDesc> {
    let text = tress_core::files::read_regular_text(path).map_err(|source| Error::Read {
        path: path.to_owned(),
        source,
    })?;
    let text = substitute(&text, defines).map_err(|message| Error::Placeholder {
        path: path.to_owned(),
        message,
    })?;
    parse(&text).map_err(|error| Error::Syntax {
        path: path.to_owned(),
        error: Box::new(error),
    })
}

/// Parses scene text; the error says where (line and column) and shows the offending line.
pub fn parse(text: &str) -> std::result::Result<SceneDesc, SyntaxError> {
    crate::ron_format::options()
        .from_str::<SceneDesc>(text)
        .map_err(|e| SyntaxError::new(text, e))
}

/// Builds the renderable scene, its hair within the limits of the run's `prep`, and its hair
/// models through `prep` (what they precompute is shared by the run and kept in its table
/// folder, if it has one: [`tress_materials::HairModel::build`]).
pub fn build(desc: &SceneDesc, scene_path: &Path, prep: &Preparation) -> Result<BuiltScene> {
    build_wrapped(desc, scene_path, prep, |accel| Box::new(accel))
}

/// The scene's geometry alone, built without Embree's filter support: Embree's own speed on the
/// scene's curves, without tress's self-intersection rule (`tress bench --scene` traces the
/// rays of a render again on it).
pub fn build_plain_accel(
    desc: &SceneDesc,
    scene_path: &Path,
    prep: &Preparation,
) -> Result<EmbreeAccel> {
    let (mut materials, material_index) = build_materials(desc, scene_path, prep)?;
    let builder = new_builder(scene_path)?
        .with_limits(*prep.limits())
        .without_filters();
    let (accel, _) = geometry::build_accel(
        &desc.objects,
        scene_path,
        &desc.materials,
        &material_index,
        &mut materials,
        builder,
        prep,
    )?;
    Ok(accel)
}

/// The scene's materials, in a stable order (objects refer to them by index), and the index of
/// each name.
fn build_materials(
    desc: &SceneDesc,
    scene_path: &Path,
    prep: &Preparation,
) -> Result<(Vec<Material>, BTreeMap<String, u32>)> {
    let mut material_index = BTreeMap::new();
    let mut materials = Vec::new();
    for (name, m) in &desc.materials {
        let built = match m {
            MaterialDesc::Hair(model) => {
                Material::Hair(model.build(prep).map_err(|source| Error::HairMaterial {
                    scene: scene_path.to_owned(),
                    name: name.clone(),
                    source,
                })?)
            }
            MaterialDesc::Diffuse { albedo } => {
                if !(albedo.min_element() >= 0.0 && albedo.max_element() <= 1.0) {
                    return Err(Error::Albedo {
                        scene: scene_path.to_owned(),
                        name: name.clone(),
                        albedo: *albedo,
                    });
                }
                Material::Diffuse { albedo: *albedo }
            }
        };
        material_index.insert(name.clone(), materials.len() as u32);
        materials.push(built);
    }
    Ok((materials, material_index))
}

/// [`build`], with the accelerator handed to `wrap` to become the scene's (benchmarks wrap it
/// to count and record queries).
pub fn build_wrapped(
    desc: &SceneDesc,
    scene_path: &Path,
    prep: &Preparation,
    wrap: impl FnOnce(EmbreeAccel) -> Box<dyn Accel>,
) -> Result<BuiltScene> {
    let c = &desc.camera;
    let camera = Camera::new(
        c.look_from,
        c.look_at,
        c.up,
        c.fov,
        c.lens_radius,
        c.focus_distance,
    )
    .map_err(|source| Error::Camera {
        scene: scene_path.to_owned(),
        source,
    })?;

    let t0 = Instant::now();
    let (mut materials, material_index) = build_materials(desc, scene_path, prep)?;
    let material_time = t0.elapsed();

    let lights = desc
        .lights
        .iter()
        .enumerate()
        .map(|(index, l)| build_light(index, l, scene_path))
        .collect::<Result<Vec<_>>>()?;

    let t1 = Instant::now();
    let (accel, geometry_summary) = geometry::build_accel(
        &desc.objects,
        scene_path,
        &desc.materials,
        &material_index,
        &mut materials,
        new_builder(scene_path)?.with_limits(*prep.limits()),
        prep,
    )?;
    let geometry_time = t1.elapsed();
    let summary = format!(
        "{geometry_summary}\nmaterials: {} built in {:.1} ms; lights: {}; geometry built in {:.2} s",
        materials.len(),
        material_time.as_secs_f64() * 1e3,
        lights.len(),
        geometry_time.as_secs_f64()
    );
    Ok(BuiltScene {
        scene: Scene::new(camera, wrap(accel), materials, lights.into()),
        summary,
    })
}

/// A new Embree scene builder for the scene at `scene_path`.
fn new_builder(scene_path: &Path) -> Result<SceneBuilder> {
    SceneBuilder::new().map_err(|source| Error::Accel {
        scene: scene_path.to_owned(),
        source,
    })
}
