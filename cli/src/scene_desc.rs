//! Scene files: RON descriptions deserialised with serde, then built into a renderable
//! [`tress_core::Scene`].
//!
//! All enums are externally tagged (RON's native `Variant(...)` syntax), every struct denies
//! unknown fields, and relative paths resolve against the scene file's folder.

pub use crate::geometry::resolve;
use crate::integrators::IntegratorDesc;
use anyhow::{anyhow, bail, Context, Result};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tress_core::film::FilmSettings;
use tress_core::light::{EnvironmentMap, Light};
use tress_core::{Camera, Material, Scene};
use tress_materials::HairModel;

/// A whole scene file.
#[derive(Clone, Debug, Serialize, Deserialize)]
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
    pub objects: Vec<crate::geometry::ObjectDesc>,
    /// The light sources.
    pub lights: Vec<LightDesc>,
}

impl SceneDesc {
    /// Every file the scene reads (hair, meshes, environment maps), resolved against
    /// `scene_path` as [`build`] resolves them.
    pub fn referenced_files(&self, scene_path: &Path) -> Vec<PathBuf> {
        let objects = self.objects.iter().filter_map(|o| match o {
            crate::geometry::ObjectDesc::Hair { source, .. } => source.path(),
            crate::geometry::ObjectDesc::Mesh { file, .. } => Some(file.as_path()),
            crate::geometry::ObjectDesc::Sphere { .. } => None,
        });
        let lights = self.lights.iter().filter_map(|l| match l {
            LightDesc::Environment { file, .. } => Some(file.as_path()),
            _ => None,
        });
        objects
            .chain(lights)
            .map(|p| resolve(scene_path, p))
            .collect()
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
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraDesc {
    /// Camera position, in world space.
    pub look_from: Vec3,
    /// Point the camera looks at (the image centre).
    pub look_at: Vec3,
    /// Direction that appears upwards in the image (default +y).
    #[serde(default = "default_up")]
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

/// A material: a hair model for fibers, or a diffuse surface for meshes and spheres.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum MaterialDesc {
    /// A hair scattering model, for hair objects.
    Hair(HairModel),
    /// A Lambertian surface, for meshes and spheres.
    Diffuse {
        /// Reflectance per channel, in [0, 1].
        albedo: Vec3,
    },
}

/// A light source.
#[derive(Clone, Debug, Serialize, Deserialize)]
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
        radiance: Vec3,
    },
    /// A distant light (sun) shining along `direction`, delivering `irradiance` perpendicular to
    /// it, from a disc of angular radius `angular_radius` degrees (0: a delta light).
    Distant {
        /// Direction the light travels (from the sun into the scene); any non-zero length.
        direction: Vec3,
        /// Irradiance per channel on a surface facing the light, ≥ 0.
        irradiance: Vec3,
        /// Angular radius of the sun's disc in degrees, in [0, 90) (default 0: a delta light).
        #[serde(default)]
        angular_radius: f32,
    },
    /// A point light of the given intensity (W/sr).
    Point {
        /// Position of the light, in world space.
        position: Vec3,
        /// Radiant intensity per channel, in W/sr, ≥ 0.
        intensity: Vec3,
    },
}

fn one() -> f32 {
    1.0
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
    let text = tress_core::files::read_regular_text(path)
        .with_context(|| format!("cannot read scene file {}", path.display()))?;
    parse(&text).map_err(|e| anyhow!("{}:{e}", path.display()))
}

/// Parses scene text; the error is `line:column: message`, followed by the offending line with a
/// caret under the column.
pub fn parse(text: &str) -> std::result::Result<SceneDesc, String> {
    crate::ron_options()
        .from_str::<SceneDesc>(text)
        .map_err(|e| {
            let p = e.span.start;
            let mut msg = format!("{}:{}: {}", p.line, p.col, e.code);
            if let Some(line) = text.lines().nth(p.line.saturating_sub(1)) {
                let (shown, caret) = excerpt(line, p.col.saturating_sub(1));
                msg.push_str(&format!("\n    {shown}\n    {}^", " ".repeat(caret)));
            }
            msg
        })
}

/// At most [`EXCERPT_CHARS`] characters of `line` around character `col`, with `…` where it
/// is cut, and the caret's column in that excerpt: a one-line file of 400 KB printed whole.
fn excerpt(line: &str, col: usize) -> (String, usize) {
    let chars: Vec<char> = line.chars().collect();
    if chars.len() <= EXCERPT_CHARS {
        return (line.to_owned(), col.min(chars.len()));
    }
    let col = col.min(chars.len());
    let start = col.saturating_sub(EXCERPT_CHARS / 2);
    let end = (start + EXCERPT_CHARS).min(chars.len());
    let start = end.saturating_sub(EXCERPT_CHARS);
    let mut shown: String = chars[start..end].iter().collect();
    let mut caret = col - start;
    if start > 0 {
        shown.insert(0, '…');
        caret += 1;
    }
    if end < chars.len() {
        shown.push('…');
    }
    (shown, caret)
}

/// Longest excerpt of a scene line shown under a parse error.
const EXCERPT_CHARS: usize = 120;

/// Builds the renderable scene.
pub fn build(desc: &SceneDesc, scene_path: &Path) -> Result<BuiltScene> {
    let here = |what: &str| format!("{}: {what}", scene_path.display());
    let c = &desc.camera;
    let camera = Camera::new(
        c.look_from,
        c.look_at,
        c.up,
        c.fov,
        c.lens_radius,
        c.focus_distance,
    )
    .map_err(|e| anyhow!("{}", here(&e.to_string())))?;

    // Materials, in a stable order; objects refer to them by index.
    let t0 = Instant::now();
    let mut material_index = BTreeMap::new();
    let mut materials = Vec::new();
    for (name, m) in &desc.materials {
        let built = match m {
            MaterialDesc::Hair(model) => Material::Hair(
                model
                    .build()
                    .map_err(|e| anyhow!("{}", here(&format!("material '{name}': {e}"))))?,
            ),
            MaterialDesc::Diffuse { albedo } => {
                if !(albedo.min_element() >= 0.0 && albedo.max_element() <= 1.0) {
                    bail!(
                        "{}",
                        here(&format!(
                            "material '{name}': albedo {albedo} must lie in [0, 1]"
                        ))
                    );
                }
                Material::Diffuse { albedo: *albedo }
            }
        };
        material_index.insert(name.clone(), materials.len() as u32);
        materials.push(built);
    }
    let material_time = t0.elapsed();

    let lights = desc
        .lights
        .iter()
        .enumerate()
        .map(|(i, l)| {
            build_light(l, scene_path)
                .map_err(|e| anyhow!("{}", here(&format!("lights[{i}]: {e:#}"))))
        })
        .collect::<Result<Vec<_>>>()?;

    let t1 = Instant::now();
    let (accel, geometry_summary) =
        crate::geometry::build_accel(&desc.objects, scene_path, &material_index, &materials)?;
    let geometry_time = t1.elapsed();
    let summary = format!(
        "{geometry_summary}\nmaterials: {} built in {:.1} ms; lights: {}; geometry built in {:.2} s",
        materials.len(),
        material_time.as_secs_f64() * 1e3,
        lights.len(),
        geometry_time.as_secs_f64()
    );
    Ok(BuiltScene {
        scene: Scene::new(camera, Box::new(accel), materials, lights.into()),
        summary,
    })
}

fn build_light(l: &LightDesc, scene_path: &Path) -> Result<Light> {
    Ok(match l {
        LightDesc::Environment {
            file,
            rotation,
            scale,
        } => Light::Environment(EnvironmentMap::from_file(
            resolve(scene_path, file),
            *rotation,
            *scale,
        )?),
        LightDesc::Sky { rotation, scale } => {
            Light::Environment(EnvironmentMap::builtin_sky(*rotation, *scale)?)
        }
        LightDesc::Constant { radiance } => Light::constant(*radiance)?,
        LightDesc::Distant {
            direction,
            irradiance,
            angular_radius,
        } => Light::distant(*direction, *irradiance, *angular_radius)?,
        LightDesc::Point {
            position,
            intensity,
        } => Light::point(*position, *intensity)?,
    })
}
