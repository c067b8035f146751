//! Scene objects (hair, meshes, spheres) and building the Embree accelerator from them.

use crate::scene_desc::MaterialDesc;
use anyhow::{anyhow, Result};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tress_accel::{
    EmbreeAccel, HairAttribute, HairOptions, HairSource, SceneBuilder, Transform, TriangleMesh,
};
use tress_core::Material;
use tress_materials::pigment::{quantise_variants, Pigment, StrandVariation};

/// An object of the scene, referring to a material by name.
#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum ObjectDesc {
    /// Hair: `Hair(source: File("straight.hair"), material: "brown", options: (...),
    /// variation: Some(random: 0.3))`.
    Hair {
        /// Where the strands come from: a file or a generator.
        source: HairSource,
        /// Name of a `Hair(...)` material in the scene's `materials`.
        material: String,
        /// How the strands become curves, and their transform (defaults if omitted).
        #[serde(default)]
        options: HairOptions,
        /// Per-strand variation of the material's pigment: random melanin, a root-to-tip
        /// gradient, the file's colours (default none: every strand has the material's
        /// pigment). The object then uses up to `variants` copies of its material.
        #[serde(default)]
        variation: Option<StrandVariation>,
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
/// `materials` holds the built materials of `descriptions` (in `material_index` order); hair
/// objects with a `variation` append their variants to it.
pub fn build_accel(
    objects: &[ObjectDesc],
    scene_path: &Path,
    descriptions: &BTreeMap<String, MaterialDesc>,
    material_index: &BTreeMap<String, u32>,
    materials: &mut Vec<Material>,
) -> Result<(EmbreeAccel, String)> {
    let here = |i: usize, what: String| anyhow!("{}: objects[{i}]: {what}", scene_path.display());
    let mut builder = SceneBuilder::new()?;
    let mut notes = Vec::new();
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
                source,
                options,
                variation,
                ..
            } => {
                let model = match descriptions.get(name) {
                    Some(MaterialDesc::Hair(model)) if is_hair_material => model,
                    _ => {
                        return Err(here(
                            i,
                            format!("hair needs a Hair(...) material, but '{name}' is not one"),
                        ))
                    }
                };
                let mut source = source.clone();
                if let Some(p) = source.path_mut() {
                    *p = resolve(scene_path, p);
                }
                let hair = source.load().map_err(|e| here(i, e.to_string()))?;
                match variation {
                    None => builder
                        .add_hair(&hair, options, material)
                        .map_err(|e| here(i, e.to_string()))?,
                    Some(variation) => {
                        let (builder, note) =
                            add_varied_hair(builder, &hair, options, variation, model, materials)
                                .map_err(|e| here(i, format!("material '{name}': {e}")))?;
                        notes.push(format!("objects[{i}]: {note}"));
                        builder
                    }
                }
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
    let mut summary = accel.info().to_string();
    for note in notes {
        summary.push('\n');
        summary.push_str(&note);
    }
    Ok((accel, summary))
}

/// Adds a hair object whose material varies (`variation`): every segment's absorption and
/// roughness scale from the variation, quantised to at most `variation.variants` values, each a
/// copy of `model` with that absorption and roughness appended to `materials`. Returns the
/// builder and a line for the summary.
fn add_varied_hair(
    builder: SceneBuilder,
    hair: &tress_accel::HairGeometry,
    options: &HairOptions,
    variation: &StrandVariation,
    model: &tress_materials::HairModel,
    materials: &mut Vec<Material>,
) -> Result<(SceneBuilder, String)> {
    let varied = variation.for_model(model)?;
    if varied.uses_file_colors() {
        match &hair.colors {
            Some(HairAttribute::PerStrand(_) | HairAttribute::PerPoint(_)) => {}
            Some(HairAttribute::Uniform(c)) => anyhow::bail!(
                "variation.file_colors: {} stores no colour per strand or per point, only the \
                 default colour {c} for all",
                hair.name
            ),
            None => anyhow::bail!("variation.file_colors: {} stores no colours", hair.name),
        }
    }
    let first = materials.len() as u32;
    let mut palette = Vec::new();
    let builder = builder.add_hair_varied(hair, options, |segments| {
        let values = segments
            .iter()
            .map(|s| {
                varied
                    .variant(s.strand, s.v, s.color)
                    .map_err(|e| match s.color {
                        Some(c) if varied.uses_file_colors() => {
                            format!("variation: strand {}, file colour {c}: {e}", s.strand)
                        }
                        _ => format!("variation: strand {}: {e}", s.strand),
                    })
            })
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let (representatives, index) = quantise_variants(&values, varied.variants() as usize);
        palette = representatives;
        Ok(index.into_iter().map(|k| first + k).collect())
    })?;
    for v in &palette {
        let sigma = v.sigma_a;
        let variant = model
            .with_pigment(Pigment::SigmaA((sigma.x, sigma.y, sigma.z)))
            .ok_or_else(|| anyhow!("variation: the model has no pigment"))?
            .with_roughness_scale(v.roughness);
        let bcsdf = variant.build().map_err(|e| {
            anyhow!(
                "variation: variant σ_a = {sigma}, roughness × {}: {e}",
                v.roughness
            )
        })?;
        materials.push(Material::Hair(bcsdf));
    }
    let note = match palette.len() {
        1 => format!("1 pigment variant (material {first})"),
        n => format!(
            "{n} pigment variants (materials {first}–{})",
            materials.len() - 1
        ),
    };
    Ok((builder, note))
}

#[cfg(test)]
mod tests {
    use crate::scene_desc::{build, parse};
    use std::path::Path;
    use tress_core::Material;

    /// A scene of procedural hair with material `model` and the object's `variation` (RON).
    fn scene(model: &str, variation: &str) -> String {
        format!(
            r#"(
                camera: (look_from: (0, 0, 4), look_at: (0, 0, 0)),
                film: (width: 8, height: 8, spp: 1, seed: 1),
                materials: {{ "hair": Hair({model}) }},
                objects: [Hair(source: Procedural(style: Ball, strands: 200, seed: 2),
                               material: "hair", {variation})],
                lights: [Sky()],
            )"#
        )
    }

    fn build_text(text: &str) -> anyhow::Result<crate::scene_desc::BuiltScene> {
        build(
            &parse(text).map_err(|e| anyhow::anyhow!("{e}"))?,
            Path::new("v.ron"),
        )
    }

    #[test]
    fn the_documented_variation_forms_parse() {
        let source = include_str!("../../materials/src/pigment.rs");
        let start = source.find("/// ```ron\n/// (random").expect("the example");
        let block: Vec<&str> = source[start..]
            .lines()
            .skip(1)
            .take_while(|l| !l.contains("```"))
            .map(|l| l.trim_start_matches("///").trim())
            .collect();
        assert_eq!(block.len(), 4);
        for line in block {
            crate::ron_format::options()
                .from_str::<tress_materials::pigment::StrandVariation>(line)
                .unwrap_or_else(|e| panic!("{line}: {e}"));
        }
    }

    #[test]
    fn a_varied_object_adds_its_variants_to_the_materials() {
        let built = build_text(&scene(
            "Chiang(pigment: Melanin(eumelanin: 1.3))",
            "variation: Some(random: 0.5, seed: 3, variants: 6, \
             gradient: Some(tip: Scale(0.3), start: 0.6))",
        ))
        .unwrap();
        // The named material, then its 6 variants.
        assert_eq!(built.scene.materials.len(), 7);
        assert!(built
            .scene
            .materials
            .iter()
            .all(|m| matches!(m, Material::Hair(_))));
        assert!(
            built
                .summary
                .contains("objects[0]: 6 pigment variants (materials 1–6)"),
            "{}",
            built.summary
        );
        assert!(
            built.summary.contains("(materials 1–6)"),
            "{}",
            built.summary
        );
        // Without variation: one material, as before.
        let plain = build_text(&scene("Chiang()", "")).unwrap();
        assert_eq!(plain.scene.materials.len(), 1);
        // A variation that varies nothing: one variant, the material's own absorption.
        let one = build_text(&scene("Chiang()", "variation: Some()")).unwrap();
        assert_eq!(one.scene.materials.len(), 2);
        let (Material::Hair(a), Material::Hair(b)) =
            (&one.scene.materials[0], &one.scene.materials[1])
        else {
            panic!("hair materials expected")
        };
        use tress_materials::dual_scattering::fingerprint;
        assert_eq!(fingerprint(a.as_ref()), fingerprint(b.as_ref()));
    }

    #[test]
    fn bad_variations_are_errors_naming_the_object_and_field() {
        let cases = [
            (
                "Chiang()",
                "variation: Some(random: 1.5)",
                "variation.random = 1.5",
            ),
            (
                "Chiang()",
                "variation: Some(random: NaN)",
                "variation.random = NaN",
            ),
            (
                "Chiang()",
                "variation: Some(variants: 0)",
                "variation.variants = 0",
            ),
            (
                "Chiang()",
                "variation: Some(variants: 100000)",
                "must lie in [1, 256]",
            ),
            (
                "Chiang()",
                "variation: Some(gradient: Some(tip: Scale(-1)))",
                "variation.gradient.tip = -1",
            ),
            (
                "Chiang()",
                "variation: Some(gradient: Some(tip: Scale(0.5), start: 1))",
                "variation.gradient.start = 1",
            ),
            (
                "Chiang()",
                "variation: Some(file_colors: true)",
                "variation.file_colors: procedural",
            ),
            (
                "Chiang()",
                "variation: Some(random_roughness: 1)",
                "variation.random_roughness = 1: must lie in [0, 1)",
            ),
            (
                "Chiang()",
                "variation: Some(darken_roots: Some(amount: -1))",
                "variation.darken_roots.amount = -1",
            ),
            (
                "Chiang()",
                "variation: Some(darken_roots: Some(amount: 1, length: 0))",
                "variation.darken_roots.length = 0: must lie in (0, 1]",
            ),
            (
                "LambertianFiber()",
                "variation: Some(random: 0.2)",
                "has no pigment to vary",
            ),
        ];
        for (model, variation, expect) in cases {
            let e = build_text(&scene(model, variation))
                .err()
                .unwrap_or_else(|| panic!("{variation}: accepted"))
                .to_string();
            assert!(
                e.starts_with("v.ron: objects[0]: material 'hair': ") && e.contains(expect),
                "{variation}: {e}"
            );
        }
        // Misspelt fields are refused by the parser.
        for (typo, name) in [
            ("variation: Some(randm: 0.5)", "randm"),
            (
                "variation: Some(gradient: Some(tip: Scale(0.5), strat: 0.2))",
                "strat",
            ),
            (
                "variation: Some(gradient: Some(tip: Bleach(0.5)))",
                "Bleach",
            ),
            (
                "variation: Some(darken_roots: Some(amount: 1, lenght: 0.2))",
                "lenght",
            ),
        ] {
            let e = parse(&scene("Chiang()", typo)).expect_err("a parse error");
            assert!(e.starts_with("6:") && e.contains(name), "{typo}: {e}");
        }
    }
}
