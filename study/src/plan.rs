//! The plan: the study resolved against its file, `--quick` and the caller's settings; seeds
//! and hashes.

use crate::error::{Error, Result, SceneError};
use crate::file::{FilmOverride, Reference, References, RegionDesc, SceneRef, Study};
use crate::metrics::Rect;
use std::path::{Path, PathBuf};
use tress_core::output_file::Inputs;
use tress_core::rng::hash_words;
use tress_loader::integrators::IntegratorDesc;
use tress_loader::paths::resolve;
use tress_loader::scene_desc::{self, SceneDesc};

/// How to run a study: what `tress study` takes on its command line.
#[derive(Clone, Debug)]
pub struct StudySettings {
    /// The study file (RON).
    pub study: PathBuf,
    /// Scaled-down run for smoke tests: the study's `quick` section, or by default spp ≤ 16, at
    /// most 3 repetitions, lighter references and films of at most 64 pixels a side.
    pub quick: bool,
    /// Output folder (default: the study's `output`, else `./<study name>_study`; `_quick` is
    /// appended for `quick`).
    pub out: Option<PathBuf>,
    /// Worker threads (default: all cores). Images do not depend on it.
    pub threads: Option<usize>,
    /// Report what happens (renders redone, tables built) and the closing summary; warnings
    /// are reported either way.
    pub verbose: bool,
    /// Memory and table-work limits of the run (the front ends read them from the environment).
    pub limits: tress_core::limits::Limits,
    /// Where precomputed tables (the fur's medulla tables) are kept between runs; `None`:
    /// nowhere ([`tress_core::prepare::Preparation::with_table_dir`]).
    pub table_dir: Option<PathBuf>,
}

/// A scene of the study, with the study's film applied.
pub struct PlanScene {
    /// Its name in file names and reports: the file stem, or the inline scene's name.
    pub name: String,
    /// Where it came from, for messages.
    pub source: String,
    /// The scene, with the study's film size (spp, seed and crop are each render's own).
    pub desc: SceneDesc,
    /// Relative paths of the scene resolve against this file's folder.
    pub base: PathBuf,
    /// Hash of everything that determines its images, for the render cache.
    pub content: u64,
    /// Regions of interest in this scene's film, in the order of [`Plan::region_names`].
    pub regions: Vec<Rect>,
}

/// An integrator of the study.
pub struct PlanIntegrator {
    /// Its settings.
    pub desc: IntegratorDesc,
    /// Its name in tables, plots and file names: the integrator's name, numbered when several
    /// share it.
    pub label: String,
    /// Its settings as RON, as reports and render headers show them.
    pub ron: String,
}

/// The common reference every render is compared with.
pub enum PlanReference {
    /// Rendered once per scene.
    Render {
        /// The reference's integrator.
        integrator: PlanIntegrator,
        /// Its samples per pixel.
        spp: u32,
    },
    /// An EXR per scene; `{scene}` in the path is replaced by the scene name.
    Exr(String),
}

/// A study resolved against its file, `quick` and the settings: what it renders, compares and
/// writes.
pub struct Plan {
    /// Report title.
    pub title: String,
    /// The study file.
    pub study_path: PathBuf,
    /// The command that runs it, for the report.
    pub command: String,
    /// The output folder.
    pub out: PathBuf,
    /// The scenes, in the study's order.
    pub scenes: Vec<PlanScene>,
    /// The integrators compared; the first is the baseline.
    pub integrators: Vec<PlanIntegrator>,
    /// Samples per pixel, strictly increasing.
    pub spp: Vec<u32>,
    /// Repetitions with independent seeds per scene, integrator and spp.
    pub reps: u32,
    /// Base seed of every derived seed.
    pub seed: u64,
    /// The common reference.
    pub reference: PlanReference,
    /// Samples per pixel of each integrator's own reference, if the study asks for them.
    pub own_spp: Option<u32>,
    /// Names of the regions of interest (each scene's rectangles are in [`PlanScene::regions`]).
    pub region_names: Vec<String>,
    /// The spp of the error heat maps.
    pub heatmap_spp: u32,
    /// The relMSE of the report's "time to reach" tables.
    pub target_relmse: f64,
    /// Exposure of the crops, as a factor (2^stops).
    pub gain: f32,
    /// Every file the study reads (the study, its scenes and what they read, EXR references),
    /// which none of its outputs may replace.
    pub inputs: Inputs,
}

pub(super) fn valid_name(s: &str) -> bool {
    !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// A stable 64-bit hash of a string (FNV-1a, then mixed), for seeds and cache keys.
pub(super) fn str_hash(s: &str) -> u64 {
    bytes_hash(s.as_bytes())
}

/// The hash of an image's pixel values (bits), recorded in cached renders.
pub(super) fn pixels_hash(image: &tress_core::Image) -> String {
    let bytes: Vec<u8> = image
        .pixels
        .iter()
        .flat_map(|p| p.to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    format!("{:016x}", bytes_hash(&bytes))
}

/// [`str_hash`] of any bytes (files' contents for the cache key).
pub(super) fn bytes_hash(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
    }
    tress_core::rng::mix64(h)
}

/// Seeds: tags keep test renders and references apart.
pub(super) const TAG_TEST: u64 = 0x7e57;
pub(super) const TAG_REFERENCE: u64 = 0x5ef0;

pub(super) fn test_seed(base: u64, scene: &str, ron: &str, spp: u32, rep: u32) -> u64 {
    hash_words(&[
        base,
        str_hash(scene),
        str_hash(ron),
        spp as u64,
        rep as u64,
        TAG_TEST,
    ])
}

pub(super) fn reference_seed(base: u64, scene: &str, ron: &str, spp: u32) -> u64 {
    hash_words(&[
        base,
        str_hash(scene),
        str_hash(ron),
        spp as u64,
        TAG_REFERENCE,
    ])
}

pub(super) fn plan_integrator(desc: IntegratorDesc, label: String) -> PlanIntegrator {
    let ron = ron::to_string(&desc).unwrap_or_else(|_| format!("{desc:?}"));
    PlanIntegrator { desc, label, ron }
}

/// Middle of the spp list on a log scale.
pub(super) fn middle_spp(spp: &[u32]) -> u32 {
    spp[spp.len() / 2]
}

/// An error about the study file `path`.
fn error_at(path: &Path, message: String) -> Error {
    Error::Invalid {
        path: path.to_owned(),
        message,
    }
}

/// An error of the study's scene at `place` (`scenes[i]`, `scene 'name'`).
fn scene_error(path: &Path, place: String, source: SceneError) -> Error {
    Error::Scene {
        path: path.to_owned(),
        place,
        source: Box::new(source),
    }
}

/// Refuses an spp list that is empty, or not positive and strictly increasing.
fn check_spp(path: &Path, field: &str, spp: &[u32]) -> Result<()> {
    if spp.is_empty() {
        return Err(error_at(path, format!("{field}: the list is empty")));
    }
    if spp[0] == 0 || spp.windows(2).any(|w| w[0] >= w[1]) {
        return Err(error_at(
            path,
            format!("{field}: {spp:?} must be positive and strictly increasing"),
        ));
    }
    Ok(())
}

/// Checks what the study file sets apart from its scenes, `quick` and references; returns the
/// names of its regions.
fn check_study(study: &Study, path: &Path) -> Result<Vec<String>> {
    let here = |what: String| error_at(path, what);
    if study.scenes.is_empty() {
        return Err(here("scenes: the list is empty".into()));
    }
    if study.integrators.is_empty() {
        return Err(here("integrators: the list is empty".into()));
    }
    check_spp(path, "spp", &study.spp)?;
    if study.repetitions == 0 {
        return Err(here("repetitions must be at least 1".into()));
    }
    if !(study.target_relmse.is_finite() && study.target_relmse > 0.0) {
        return Err(here(format!(
            "target_relmse = {} must be finite and positive",
            study.target_relmse
        )));
    }
    if !study.exposure.is_finite() {
        return Err(here(format!(
            "exposure = {} must be finite",
            study.exposure
        )));
    }
    let region_names = check_regions(&study.regions, path)?;
    if let Some(h) = study.heatmap_spp {
        if !study.spp.contains(&h) {
            return Err(here(format!(
                "heatmap_spp = {h} is not one of spp {:?}",
                study.spp
            )));
        }
    }
    Ok(region_names)
}

/// The names of the regions, each checked: a valid name, given once, not empty.
fn check_regions(regions: &[RegionDesc], path: &Path) -> Result<Vec<String>> {
    let mut names: Vec<String> = Vec::new();
    for r in regions {
        if !valid_name(&r.name) {
            return Err(error_at(
                path,
                format!(
                    "regions: name '{}' must be letters, digits, '_' or '-'",
                    r.name
                ),
            ));
        }
        if names.contains(&r.name) {
            return Err(error_at(
                path,
                format!("regions: '{}' is defined twice", r.name),
            ));
        }
        if r.w == 0 || r.h == 0 {
            return Err(error_at(path, format!("regions: '{}' is empty", r.name)));
        }
        names.push(r.name.clone());
    }
    Ok(names)
}

/// The spp and repetitions a run uses: the study's, or under `--quick` its scaled-down ones.
struct Scale {
    quick: bool,
    spp: Vec<u32>,
    reps: u32,
}

impl Scale {
    fn new(study: &Study, quick: bool, path: &Path) -> Result<Scale> {
        let q = &study.quick;
        let spp = match (&q.spp, quick) {
            (Some(s), true) => {
                check_spp(path, "quick.spp", s)?;
                s.clone()
            }
            (None, true) => {
                let small: Vec<u32> = study.spp.iter().copied().filter(|&s| s <= 16).collect();
                if small.len() >= 2 {
                    small
                } else {
                    study.spp.iter().copied().take(3).collect()
                }
            }
            (_, false) => study.spp.clone(),
        };
        let reps = match (q.repetitions, quick) {
            (Some(0), true) => {
                return Err(error_at(
                    path,
                    "quick.repetitions must be at least 1".into(),
                ))
            }
            (Some(r), true) => r,
            (None, true) => study.repetitions.min(3),
            (_, false) => study.repetitions,
        };
        Ok(Scale { quick, spp, reps })
    }

    /// A reference's spp: `full`, or under `--quick` the `quick` section's (`set`) or a
    /// lighter one.
    fn reference_spp(&self, full: u32, set: Option<u32>) -> u32 {
        let max_spp = *self.spp.last().unwrap_or(&1);
        match (set, self.quick) {
            (Some(s), true) => s,
            (None, true) => full.min((16 * max_spp).max(64)),
            (_, false) => full,
        }
    }
}

/// The common reference, its spp scaled.
fn plan_reference(
    reference: Reference,
    scale: &Scale,
    quick_spp: Option<u32>,
    path: &Path,
) -> Result<PlanReference> {
    Ok(match reference {
        Reference::Render { integrator, spp } => {
            let spp = scale.reference_spp(spp, quick_spp);
            if spp == 0 {
                return Err(error_at(path, "reference: spp must be at least 1".into()));
            }
            let label = integrator.name().to_string();
            PlanReference::Render {
                integrator: plan_integrator(integrator, label),
                spp,
            }
        }
        Reference::Exr(p) => PlanReference::Exr(p),
    })
}

/// The spp of the integrators' own references, if the study wants them.
fn own_reference_spp(
    references: &References,
    scale: &Scale,
    quick_spp: Option<u32>,
    path: &Path,
) -> Result<Option<u32>> {
    match *references {
        References::Common => Ok(None),
        References::PerIntegrator { spp } => {
            let spp = scale.reference_spp(spp, quick_spp);
            if spp == 0 {
                return Err(error_at(
                    path,
                    "references: PerIntegrator spp must be at least 1".into(),
                ));
            }
            Ok(Some(spp))
        }
    }
}

/// The integrators, labelled by their short name, numbered when several share it; the same
/// settings listed twice are refused.
fn plan_integrators(descs: &[IntegratorDesc], path: &Path) -> Result<Vec<PlanIntegrator>> {
    let names: Vec<&str> = descs.iter().map(|d| d.name()).collect();
    let integrators: Vec<PlanIntegrator> = descs
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let name = names[i];
            let label = if names.iter().filter(|n| **n == name).count() > 1 {
                let k = names[..=i].iter().filter(|n| **n == name).count();
                format!("{name}-{k}")
            } else {
                name.to_string()
            };
            plan_integrator(d.clone(), label)
        })
        .collect();
    let mut seen: Vec<&str> = Vec::new();
    for i in &integrators {
        if seen.contains(&i.ron.as_str()) {
            return Err(error_at(
                path,
                format!("integrators: {} is listed twice", i.ron),
            ));
        }
        seen.push(&i.ron);
    }
    Ok(integrators)
}

/// A scene of the study as written: its name, where it came from (for messages), its
/// description and the file its relative paths resolve against.
struct SceneSource {
    name: String,
    source: String,
    desc: SceneDesc,
    base: PathBuf,
}

/// Loads scene `i` of the study file `path`, or takes it inline.
fn scene_source(i: usize, scene: SceneRef, path: &Path) -> Result<SceneSource> {
    Ok(match scene {
        SceneRef::File(p) => {
            let file = resolve(path, &p);
            let desc = scene_desc::load(&file)
                .map_err(|e| scene_error(path, format!("scenes[{i}]"), e.into()))?;
            let name: String = file
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
                .chars()
                .map(|c| if valid_name(&c.to_string()) { c } else { '_' })
                .collect();
            SceneSource {
                name,
                source: file.display().to_string(),
                desc,
                base: file,
            }
        }
        SceneRef::Inline { name, scene } => {
            if !valid_name(&name) {
                return Err(error_at(
                    path,
                    format!("scenes[{i}]: name '{name}' must be letters, digits, '_' or '-'"),
                ));
            }
            let source = format!("{} (inline scene '{name}')", path.display());
            SceneSource {
                name,
                source,
                desc: *scene,
                base: path.to_path_buf(),
            }
        }
    })
}

/// How the study sets the film of its scenes.
struct FilmPlan {
    /// The study's `film`: every scene's size.
    size: Option<FilmOverride>,
    /// Under `--quick`: the `quick` section's film, and whether an EXR reference fixes the
    /// resolution.
    quick: Option<(Option<FilmOverride>, bool)>,
}

impl FilmPlan {
    /// Sets the film of `scene` (named `name`): the study's size, then `--quick`'s; returns the
    /// size before `--quick`, which region coordinates refer to.
    fn apply(&self, desc: &mut SceneDesc, name: &str, path: &Path) -> Result<(u32, u32)> {
        let film = &mut desc.film;
        if let Some(f) = self.size {
            film.width = f.width;
            film.height = f.height;
        }
        film.crop = None;
        film.spp = 1;
        film.seed = 0;
        film.validate()
            .map_err(|e| scene_error(path, format!("scene '{name}'"), SceneError::Film(e)))?;
        let (w0, h0) = (film.width, film.height);
        if let Some((quick_film, exr_reference)) = self.quick {
            match quick_film {
                Some(f) => {
                    film.width = f.width;
                    film.height = f.height;
                }
                None if !exr_reference && w0.max(h0) > 64 => {
                    let s = 64.0 / w0.max(h0) as f64;
                    film.width = ((w0 as f64 * s).round() as u32).max(1);
                    film.height = ((h0 as f64 * s).round() as u32).max(1);
                }
                None => {}
            }
            film.validate().map_err(|source| Error::QuickFilm {
                path: path.to_owned(),
                source,
            })?;
        }
        Ok((w0, h0))
    }
}

/// The regions in the film of scene `name`, `(w, h)`: their coordinates refer to the study's
/// film `(w0, h0)`, and `--quick` scales them along.
fn scene_regions(
    regions: &[RegionDesc],
    (w0, h0): (u32, u32),
    (w, h): (u32, u32),
    name: &str,
    path: &Path,
) -> Result<Vec<Rect>> {
    let mut rects = Vec::new();
    for r in regions {
        let sx = |v: u32| (v as u64 * w as u64 / w0 as u64) as u32;
        let sy = |v: u32| (v as u64 * h as u64 / h0 as u64) as u32;
        let rect = Rect {
            x: sx(r.x),
            y: sy(r.y),
            w: sx(r.w).max(1),
            h: sy(r.h).max(1),
        };
        if rect.x as u64 + rect.w as u64 > w as u64 || rect.y as u64 + rect.h as u64 > h as u64 {
            return Err(error_at(
                path,
                format!(
                    "regions: '{}' ({rect}) is not inside scene '{name}''s {w}x{h} film",
                    r.name
                ),
            ));
        }
        rects.push(rect);
    }
    Ok(rects)
}

/// The hash of everything that determines a scene's images but the integrator: its
/// description, where its paths resolve, the contents of the files it reads and tress's version
/// (replacing an environment map, or updating tress, must not reuse renders of the old one).
fn content_hash(desc: &SceneDesc, base: &Path, name: &str, path: &Path) -> Result<u64> {
    let mut keyed = desc.clone();
    keyed.integrator = IntegratorDesc::default();
    let files = desc
        .files_hash(base)
        .map_err(|e| scene_error(path, format!("scene '{name}'"), e.into()))?;
    Ok(str_hash(&format!(
        "{}|{}|{files:016x}|tress {}",
        ron::to_string(&keyed).unwrap_or_else(|_| format!("{keyed:?}")),
        base.display(),
        env!("CARGO_PKG_VERSION")
    )))
}

/// The scenes of the study, with the film and regions planned.
fn plan_scenes(
    scenes: Vec<SceneRef>,
    film: &FilmPlan,
    regions: &[RegionDesc],
    path: &Path,
) -> Result<Vec<PlanScene>> {
    let mut planned: Vec<PlanScene> = Vec::new();
    for (i, s) in scenes.into_iter().enumerate() {
        let SceneSource {
            name,
            source,
            mut desc,
            base,
        } = scene_source(i, s, path)?;
        if planned.iter().any(|o| o.name == name) {
            return Err(error_at(
                path,
                format!(
                    "scenes[{i}]: a scene named '{name}' is already in the study; scene names \
                     (file stems) must differ"
                ),
            ));
        }
        let study_size = film.apply(&mut desc, &name, path)?;
        let size = (desc.film.width, desc.film.height);
        let regions = scene_regions(regions, study_size, size, &name, path)?;
        let content = content_hash(&desc, &base, &name, path)?;
        planned.push(PlanScene {
            name,
            source,
            desc,
            base,
            content,
            regions,
        });
    }
    Ok(planned)
}

impl Plan {
    pub(super) fn new(study: Study, settings: &StudySettings) -> Result<Plan> {
        let path = &settings.study;
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "study".into());
        let region_names = check_study(&study, path)?;
        let quick = settings.quick;
        let scale = Scale::new(&study, quick, path)?;
        let q = &study.quick;
        let reference = plan_reference(study.reference, &scale, q.reference_spp, path)?;
        let own_spp = own_reference_spp(&study.references, &scale, q.per_integrator_spp, path)?;
        let heatmap_spp = match study.heatmap_spp {
            Some(h) if scale.spp.contains(&h) => h,
            _ => middle_spp(&scale.spp),
        };
        let integrators = plan_integrators(&study.integrators, path)?;
        let film = FilmPlan {
            size: study.film,
            quick: quick.then_some((q.film, matches!(reference, PlanReference::Exr(_)))),
        };
        let scenes = plan_scenes(study.scenes, &film, &study.regions, path)?;
        let out = match (&settings.out, &study.output) {
            (Some(o), _) => o.clone(),
            (None, Some(o)) => suffix(resolve(path, o), quick),
            (None, None) => suffix(PathBuf::from(format!("{stem}_study")), quick),
        };
        let mut inputs = Inputs::default();
        inputs.add(path);
        for scene in &scenes {
            // The scene file (or, for an inline scene, the study again) and what it reads.
            inputs.add(&scene.base);
            inputs.extend(scene.desc.referenced_files(&scene.base)?);
            if let PlanReference::Exr(template) = &reference {
                inputs.add(reference_exr(path, template, &scene.name));
            }
        }
        let command = format!(
            "tress study {}{}",
            path.display(),
            if quick { " --quick" } else { "" }
        );
        Ok(Plan {
            title: study.name.unwrap_or(stem),
            study_path: path.clone(),
            command,
            out,
            scenes,
            integrators,
            spp: scale.spp,
            reps: scale.reps,
            seed: study.seed,
            reference,
            own_spp,
            region_names,
            heatmap_spp,
            target_relmse: study.target_relmse,
            gain: study.exposure.exp2(),
            inputs,
        })
    }

    /// The EXR reference of `scene`: `template` with `{scene}` replaced, relative to the study.
    pub(super) fn reference_exr(&self, template: &str, scene: &PlanScene) -> PathBuf {
        reference_exr(&self.study_path, template, &scene.name)
    }

    /// Samples of all renders, for the progress bar.
    pub(super) fn total_samples(&self) -> u64 {
        let n = self.integrators.len() as u64;
        let per_pixel = self.spp.iter().map(|&s| s as u64).sum::<u64>() * self.reps as u64 * n
            + match &self.reference {
                PlanReference::Render { spp, .. } => *spp as u64,
                PlanReference::Exr(_) => 0,
            }
            + self.own_spp.map_or(0, |s| s as u64 * n);
        self.scenes
            .iter()
            .map(|s| s.desc.film.width as u64 * s.desc.film.height as u64 * per_pixel)
            .sum()
    }
}

/// The EXR reference of scene `name` of the study at `study`: `template` with `{scene}`
/// replaced, relative to the study.
fn reference_exr(study: &Path, template: &str, name: &str) -> PathBuf {
    resolve(study, Path::new(&template.replace("{scene}", name)))
}

pub(super) fn suffix(p: PathBuf, quick: bool) -> PathBuf {
    if !quick {
        return p;
    }
    let mut s = p.into_os_string();
    s.push("_quick");
    PathBuf::from(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_are_distinct_and_stable() {
        let a = test_seed(1, "s", "Path(())", 4, 0);
        assert_eq!(a, test_seed(1, "s", "Path(())", 4, 0));
        let others = [
            test_seed(2, "s", "Path(())", 4, 0),
            test_seed(1, "t", "Path(())", 4, 0),
            test_seed(1, "s", "Path((max_depth:8))", 4, 0),
            test_seed(1, "s", "Path(())", 8, 0),
            test_seed(1, "s", "Path(())", 4, 1),
            reference_seed(1, "s", "Path(())", 4),
        ];
        assert!(others.iter().all(|&o| o != a));
    }
}
