//! Scene objects (hair, meshes, spheres) and building the Embree accelerator from them.

use crate::error::{Error, ObjectError, Result, VariationError};
use crate::materials::MaterialDesc;
use crate::paths::resolve;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tress_accel::{EmbreeAccel, HairOptions, SceneBuilder, TriangleMesh};
use tress_core::prepare::Preparation;
use tress_core::Material;
use tress_groom::{HairAttribute, HairGeometry, HairSource, Transform};
use tress_materials::pigment::Pigment;
use tress_materials::strand_variation::{quantise_variants, StrandVariation};

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

/// Builds the accelerator for the scene's objects with `builder`, whose limits the hair is
/// loaded and built within; returns it with a summary (`tress info`).
/// `materials` holds the built materials of `descriptions` (in `material_index` order); hair
/// objects with a `variation` append their variants to it, built through the run's `prep`.
pub fn build_accel(
    objects: &[ObjectDesc],
    scene_path: &Path,
    descriptions: &BTreeMap<String, MaterialDesc>,
    material_index: &BTreeMap<String, u32>,
    materials: &mut Vec<Material>,
    mut builder: SceneBuilder,
    prep: &Preparation,
) -> Result<(EmbreeAccel, String)> {
    let here = |index: usize, source: ObjectError| Error::Object {
        scene: scene_path.to_owned(),
        index,
        source: Box::new(source),
    };
    // Hair keeps its fibers' orientation only for a model that reads it (variants of a model
    // share its answer).
    if (materials.iter()).any(|m| matches!(m, Material::Hair(b) if b.uses_orientation())) {
        builder = builder.with_fiber_orientation();
    }
    let mut notes = Vec::new();
    let mut reads = SharedReads::new(objects, scene_path);
    for (i, object) in objects.iter().enumerate() {
        let name = object.material();
        let &material = material_index.get(name).ok_or_else(|| {
            here(
                i,
                ObjectError::UnknownMaterial {
                    name: name.to_owned(),
                    defined: material_index.keys().cloned().collect(),
                },
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
                            ObjectError::NotHairMaterial {
                                name: name.to_owned(),
                            },
                        ))
                    }
                };
                let hair = match reads.take(i) {
                    Some(hair) => hair,
                    None => {
                        // Loaded within what the objects before it (and the files kept for
                        // later ones) leave of the memory limit.
                        let hair = resolved(source, scene_path)
                            .load(&builder.limits())
                            .map_err(|e| here(i, e.into()))?;
                        reads.keep(i, hair)
                    }
                };
                builder.hold_beside(reads.kept_bytes());
                match variation {
                    None => builder
                        .add_hair(&hair, options, material)
                        .map_err(|e| here(i, e.into()))?,
                    Some(variation) => {
                        let (builder, note) = add_varied_hair(
                            builder, &hair, options, variation, model, materials, prep,
                        )
                        .map_err(|source| {
                            here(
                                i,
                                ObjectError::Variation {
                                    material: name.to_owned(),
                                    source,
                                },
                            )
                        })?;
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
                        ObjectError::NotSurfaceMaterial {
                            kind: "meshes",
                            name: name.to_owned(),
                        },
                    ));
                }
                let mesh = TriangleMesh::load_obj(&resolve(scene_path, file))
                    .map_err(|e| here(i, e.into()))?;
                builder
                    .add_mesh(&mesh, transform, material)
                    .map_err(|e| here(i, e.into()))?
            }
            ObjectDesc::Sphere { center, radius, .. } => {
                if is_hair_material {
                    return Err(here(
                        i,
                        ObjectError::NotSurfaceMaterial {
                            kind: "spheres",
                            name: name.to_owned(),
                        },
                    ));
                }
                builder
                    .add_sphere(*center, *radius, material)
                    .map_err(|e| here(i, e.into()))?
            }
        };
    }
    if reads.read_once > 0 {
        notes.push(format!(
            "{} objects reused a file read for an earlier object",
            reads.read_once
        ));
    }
    drop(reads);
    let accel = builder.build().map_err(|source| Error::Accel {
        scene: scene_path.to_owned(),
        source,
    })?;
    let mut summary = accel.info().to_string();
    for note in notes {
        summary.push('\n');
        summary.push_str(&note);
    }
    Ok((accel, summary))
}

/// `source` with its file path resolved against the scene file's folder.
fn resolved(source: &HairSource, scene_path: &Path) -> HairSource {
    let mut source = source.clone();
    if let Some(p) = source.path_mut() {
        *p = resolve(scene_path, p);
    }
    source
}

/// Hair files that several objects name (the same file with the same reader options, each
/// object with its own transform and options): read once, and kept from the first object
/// that names them to the last, counted against the memory limit meanwhile
/// ([`SceneBuilder::hold_beside`]). A file named once is never kept.
struct SharedReads {
    /// Per object: the key of its file source, if another object names the same.
    keys: Vec<Option<String>>,
    /// Per key: the objects still to come that name it.
    uses_left: HashMap<String, usize>,
    /// Per key: the file read, while objects still to come name it.
    kept: HashMap<String, Arc<HairGeometry>>,
    /// Bytes of the files in `kept`, kept as a running total: summing them for every object
    /// would be quadratic in a scene of many files each named twice.
    kept_total: usize,
    /// Objects that took a file read for an earlier object.
    read_once: usize,
}

impl SharedReads {
    fn new(objects: &[ObjectDesc], scene_path: &Path) -> Self {
        // The resolved source's description is its key: the same path with other reader
        // options is another read. Generated hair is cheap to make again and never kept.
        let keys: Vec<Option<String>> = objects
            .iter()
            .map(|object| match object {
                ObjectDesc::Hair { source, .. } if source.path().is_some() => {
                    Some(format!("{:?}", resolved(source, scene_path)))
                }
                _ => None,
            })
            .collect();
        let mut uses_left = HashMap::new();
        for key in keys.iter().flatten() {
            *uses_left.entry(key.clone()).or_insert(0usize) += 1;
        }
        let keys = keys
            .into_iter()
            .map(|key| key.filter(|k| uses_left[k] > 1))
            .collect();
        SharedReads {
            keys,
            uses_left,
            kept: HashMap::new(),
            kept_total: 0,
            read_once: 0,
        }
    }

    /// The file object `i` names, if an earlier object read it; counts object `i`'s use.
    fn take(&mut self, i: usize) -> Option<Arc<HairGeometry>> {
        let key = self.keys[i].as_ref()?;
        let left = self.uses_left.get_mut(key)?;
        *left -= 1;
        let hair = if *left == 0 {
            let last = self.kept.remove(key);
            self.kept_total -= last.as_ref().map_or(0, |h| h.heap_bytes());
            last
        } else {
            self.kept.get(key).cloned()
        };
        self.read_once += usize::from(hair.is_some());
        hair
    }

    /// Keeps `hair`, just read for object `i`, if objects after it name the same file.
    fn keep(&mut self, i: usize, hair: HairGeometry) -> Arc<HairGeometry> {
        let hair = Arc::new(hair);
        if let Some(key) = &self.keys[i] {
            if self.uses_left[key] > 0 {
                self.kept_total += hair.heap_bytes();
                self.kept.insert(key.clone(), Arc::clone(&hair));
            }
        }
        hair
    }

    /// Bytes of the files kept.
    fn kept_bytes(&self) -> f64 {
        self.kept_total as f64
    }
}

/// Adds a hair object whose material varies (`variation`): every segment's absorption and
/// roughness scale from the variation, quantised to at most `variation.variants` values, each a
/// copy of `model` with that absorption and roughness appended to `materials`. Returns the
/// builder and a line for the summary.
fn add_varied_hair(
    builder: SceneBuilder,
    hair: &tress_groom::HairGeometry,
    options: &HairOptions,
    variation: &StrandVariation,
    model: &tress_materials::HairModel,
    materials: &mut Vec<Material>,
    prep: &Preparation,
) -> Result<(SceneBuilder, String), VariationError> {
    let varied = variation.for_model(model)?;
    if varied.uses_file_colors() {
        match &hair.colors {
            Some(HairAttribute::PerStrand(_) | HairAttribute::PerPoint(_)) => {}
            Some(HairAttribute::Uniform(color)) => {
                return Err(VariationError::UniformFileColor {
                    hair: hair.name.clone(),
                    color: *color,
                })
            }
            None => {
                return Err(VariationError::NoFileColors {
                    hair: hair.name.clone(),
                })
            }
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
            .ok_or(VariationError::NoPigment)?
            .with_roughness_scale(v.roughness);
        let bcsdf = variant
            .build(prep)
            .map_err(|source| VariationError::Variant {
                sigma_a: sigma,
                roughness: v.roughness,
                source,
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
