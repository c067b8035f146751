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
    pub objects: Vec<crate::geometry::ObjectDesc>,
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
                crate::geometry::ObjectDesc::Hair { source, .. } => {
                    let mut source = source.clone();
                    if let Some(p) = source.path_mut() {
                        *p = resolve(scene_path, p);
                    }
                    files.extend(
                        source
                            .files()
                            .map_err(|e| anyhow!("{}: {e}", scene_path.display()))?,
                    );
                }
                crate::geometry::ObjectDesc::Mesh { file, .. } => {
                    files.push(resolve(scene_path, file));
                }
                crate::geometry::ObjectDesc::Sphere { .. } => {}
            }
        }
        for light in &self.lights {
            if let LightDesc::Environment { file, .. } = light {
                files.push(resolve(scene_path, file));
            }
        }
        Ok(files)
    }

    /// A hash of the contents of every file the scene reads ([`referenced_files`]
    /// (Self::referenced_files)): part of the keys of study caches and of the scene hash that
    /// merged pieces must share, so that renders of a file's old contents are not taken for
    /// renders of its new ones.
    pub fn files_hash(&self, scene_path: &Path) -> Result<u64> {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for f in self.referenced_files(scene_path)? {
            let bytes = tress_core::files::read_regular(&f)
                .map_err(|e| anyhow!("{}: {}: {e}", scene_path.display(), f.display()))?;
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

/// Values for a scene file's `${name}` placeholders, from `-D name=value` on the command line.
pub type Defines = BTreeMap<String, String>;

/// Reads a scene file, replaces its placeholders with `defines` ([`substitute`]) and parses it;
/// errors name the file, line and column.
pub fn load_with(path: &Path, defines: &Defines) -> Result<SceneDesc> {
    let text = tress_core::files::read_regular_text(path)
        .with_context(|| format!("cannot read scene file {}", path.display()))?;
    let text = substitute(&text, defines).map_err(|e| anyhow!("{}:{e}", path.display()))?;
    parse(&text).map_err(|e| anyhow!("{}:{e}", path.display()))
}

/// The `-D name=value` arguments as [`Defines`]: a name given twice is refused (the last
/// value was kept silently).
pub fn defines(args: &[(String, String)]) -> Result<Defines> {
    let mut defines = Defines::new();
    for (name, value) in args {
        if let Some(first) = defines.insert(name.clone(), value.clone()) {
            bail!("-D {name} is given twice ({name}={first} and {name}={value}): give it once");
        }
    }
    Ok(defines)
}

/// One `-D name=value` argument.
pub fn parse_define(arg: &str) -> std::result::Result<(String, String), String> {
    let (name, value) = arg
        .split_once('=')
        .ok_or_else(|| format!("'{arg}': write name=value"))?;
    if !is_placeholder_name(name) {
        return Err(format!(
            "'{name}': a name is a letter or _ followed by letters, digits or _"
        ));
    }
    if value.contains(['\n', '\r']) {
        return Err(format!("{name}: the value must be one line"));
    }
    Ok((name.to_owned(), value.to_owned()))
}

fn is_placeholder_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Replaces every `${name}` in a scene's text with `defines[name]`, and `${name:-default}`
/// with it or, when it is not defined, with `default` (Mitsuba's `$name` parameters, in shell
/// syntax, since `$` has no meaning in RON). Substitution is textual — it applies inside
/// comments too — so a placeholder may stand for a number, a string's contents or a whole
/// value: `spp: ${spp:-64}`, `File("${groom}.hair")`, `integrator: ${integrator:-DualMis()}`.
/// Errors (`line:column: message`): a placeholder with no value and no default, a malformed
/// one, and a define that the scene never uses (a misspelt name would otherwise be ignored).
pub fn substitute(text: &str, defines: &Defines) -> std::result::Result<String, String> {
    let mut out = String::with_capacity(text.len());
    let mut used = std::collections::BTreeSet::new();
    let mut rest = text;
    while let Some(at) = rest.find("${") {
        out.push_str(&rest[..at]);
        let offset = text.len() - rest.len() + at;
        let (line, col) = line_col(text, offset);
        let body = &rest[at + 2..];
        let end = body
            .find('}')
            .filter(|&e| !body[..e].contains('\n'))
            .ok_or_else(|| format!("{line}:{col}: '${{' without a closing '}}' on its line"))?;
        let (name, default) = match body[..end].split_once(":-") {
            Some((name, default)) => (name, Some(default)),
            None => (&body[..end], None),
        };
        if default.is_some_and(|d| d.contains("${")) {
            return Err(format!(
                "{line}:{col}: '${{{name}:-…}}': a default cannot hold another placeholder \
                 (nested defaults are not supported): write the value itself"
            ));
        }
        if !is_placeholder_name(name) {
            return Err(format!(
                "{line}:{col}: '${{{}}}': a placeholder is ${{name}} or ${{name:-default}}",
                &body[..end]
            ));
        }
        match (defines.get(name), default) {
            (Some(value), _) => {
                used.insert(name);
                out.push_str(value);
            }
            (None, Some(default)) => out.push_str(default),
            (None, None) => {
                return Err(format!(
                    "{line}:{col}: ${{{name}}} has no value: pass -D {name}=… or write \
                     ${{{name}:-default}}"
                ))
            }
        }
        rest = &body[end + 1..];
    }
    out.push_str(rest);
    if let Some(unused) = defines.keys().find(|k| !used.contains(k.as_str())) {
        return Err(format!(
            " -D {unused}: the scene has no ${{{unused}}} placeholder"
        ));
    }
    Ok(out)
}

/// 1-based line and column (in characters) of byte `offset` of `text`.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before[before.rfind('\n').map_or(0, |i| i + 1)..]
        .chars()
        .count()
        + 1;
    (line, col)
}

/// Parses scene text; the error is `line:column: message`, followed by the offending line with a
/// caret under the column.
pub fn parse(text: &str) -> std::result::Result<SceneDesc, String> {
    crate::ron_format::options()
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
    let (accel, geometry_summary) = crate::geometry::build_accel(
        &desc.objects,
        scene_path,
        &desc.materials,
        &material_index,
        &mut materials,
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

#[cfg(test)]
mod tests {
    use super::*;

    fn defines(pairs: &[(&str, &str)]) -> Defines {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn placeholders_take_defines_then_defaults() {
        let text = "film: (spp: ${spp:-64}, seed: ${seed}),\n// ${spp:-}\nfile: \"${groom}.hair\"";
        let d = defines(&[("seed", "7"), ("groom", "a/b"), ("spp", "16")]);
        assert_eq!(
            substitute(text, &d).unwrap(),
            "film: (spp: 16, seed: 7),\n// 16\nfile: \"a/b.hair\""
        );
        let d = defines(&[("seed", "7"), ("groom", "x")]);
        assert!(substitute(text, &d)
            .unwrap()
            .starts_with("film: (spp: 64, seed: 7)"));
        // A default may be empty or hold a whole value; text without placeholders is unchanged.
        assert_eq!(substitute("${a:-}", &Defines::new()).unwrap(), "");
        assert_eq!(
            substitute("i: ${i:-Path(max_depth: 8)}", &Defines::new()).unwrap(),
            "i: Path(max_depth: 8)"
        );
        assert_eq!(substitute("a $b {c}", &Defines::new()).unwrap(), "a $b {c}");
    }

    #[test]
    fn placeholder_errors_say_where_and_what() {
        let err = |text: &str, d: &[(&str, &str)]| substitute(text, &defines(d)).unwrap_err();
        let e = err("(\n  film: (spp: ${spp}),", &[]);
        assert!(
            e.starts_with("2:15: ${spp} has no value: pass -D spp="),
            "{e}"
        );
        let e = err("x: ${spp", &[]);
        assert!(e.starts_with("1:4:") && e.contains("closing"), "{e}");
        let e = err("x: ${s p}", &[]);
        assert!(e.contains("${name}"), "{e}");
        let e = err("x: ${spp:-1}", &[("sp", "2")]);
        assert!(e.contains("-D sp: the scene has no ${sp}"), "{e}");
    }

    #[test]
    fn define_arguments_are_name_equals_value() {
        assert_eq!(
            parse_define("spp=64").unwrap(),
            ("spp".to_string(), "64".to_string())
        );
        assert_eq!(parse_define("x=a=b").unwrap().1, "a=b");
        assert!(parse_define("spp").unwrap_err().contains("name=value"));
        assert!(parse_define("1x=2").is_err());
        assert!(parse_define("x=a\nb").is_err());
    }
}
