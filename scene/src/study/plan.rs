//! The plan: the study resolved against its file, `--quick` and the caller's settings; seeds
//! and hashes.

use super::file::{Reference, References, SceneRef, Study};
use crate::integrators::IntegratorDesc;
use crate::metrics::Rect;
use crate::paths::resolve;
use crate::scene_desc::{self, SceneDesc};
use anyhow::{anyhow, Context, Result};
use std::path::PathBuf;
use tress_core::rng::hash_words;

/// How to run a study: what `tress study` takes on its command line.
#[derive(Clone, Debug)]
pub struct StudySettings {
    /// The study file (RON).
    pub study: PathBuf,
    /// Scaled-down run for smoke tests: the study's `quick` section, or by default spp ≤ 16, at
    /// most 3 repetitions, lighter references and films of at most 64 pixels a side.
    pub quick: bool,
    /// Output folder (default: the study's `output`, else ./<study name>_study; `_quick` is
    /// appended for `quick`).
    pub out: Option<PathBuf>,
    /// Worker threads (default: all cores). Images do not depend on it.
    pub threads: Option<usize>,
    /// Report what happens (renders redone, tables built) and the closing summary; warnings
    /// are reported either way.
    pub verbose: bool,
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

impl Plan {
    pub(super) fn new(study: Study, settings: &StudySettings) -> Result<Plan> {
        let path = &settings.study;
        let here = |what: String| anyhow!("{}: {what}", path.display());
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "study".into());

        if study.scenes.is_empty() {
            return Err(here("scenes: the list is empty".into()));
        }
        if study.integrators.is_empty() {
            return Err(here("integrators: the list is empty".into()));
        }
        let check_spp = |field: &str, spp: &[u32]| -> Result<()> {
            if spp.is_empty() {
                return Err(here(format!("{field}: the list is empty")));
            }
            if spp[0] == 0 || spp.windows(2).any(|w| w[0] >= w[1]) {
                return Err(here(format!(
                    "{field}: {spp:?} must be positive and strictly increasing"
                )));
            }
            Ok(())
        };
        check_spp("spp", &study.spp)?;
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
        let mut region_names: Vec<String> = Vec::new();
        for r in &study.regions {
            if !valid_name(&r.name) {
                return Err(here(format!(
                    "regions: name '{}' must be letters, digits, '_' or '-'",
                    r.name
                )));
            }
            if region_names.contains(&r.name) {
                return Err(here(format!("regions: '{}' is defined twice", r.name)));
            }
            if r.w == 0 || r.h == 0 {
                return Err(here(format!("regions: '{}' is empty", r.name)));
            }
            region_names.push(r.name.clone());
        }
        if let Some(h) = study.heatmap_spp {
            if !study.spp.contains(&h) {
                return Err(here(format!(
                    "heatmap_spp = {h} is not one of spp {:?}",
                    study.spp
                )));
            }
        }

        // --quick: scaled-down settings.
        let q = &study.quick;
        let quick = settings.quick;
        let spp = match (&q.spp, quick) {
            (Some(s), true) => {
                check_spp("quick.spp", s)?;
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
            (Some(0), true) => return Err(here("quick.repetitions must be at least 1".into())),
            (Some(r), true) => r,
            (None, true) => study.repetitions.min(3),
            (_, false) => study.repetitions,
        };
        let max_spp = *spp.last().unwrap_or(&1);
        let quick_ref = |full: u32, set: Option<u32>| -> u32 {
            match (set, quick) {
                (Some(s), true) => s,
                (None, true) => full.min((16 * max_spp).max(64)),
                (_, false) => full,
            }
        };
        let reference = match study.reference {
            Reference::Render { integrator, spp } => {
                let spp = quick_ref(spp, q.reference_spp);
                if spp == 0 {
                    return Err(here("reference: spp must be at least 1".into()));
                }
                let label = integrator.name().to_string();
                PlanReference::Render {
                    integrator: plan_integrator(integrator, label),
                    spp,
                }
            }
            Reference::Exr(p) => PlanReference::Exr(p),
        };
        let own_spp = match study.references {
            References::Common => None,
            References::PerIntegrator { spp } => {
                let spp = quick_ref(spp, q.per_integrator_spp);
                if spp == 0 {
                    return Err(here(
                        "references: PerIntegrator spp must be at least 1".into(),
                    ));
                }
                Some(spp)
            }
        };
        let heatmap_spp = match study.heatmap_spp {
            Some(h) if spp.contains(&h) => h,
            _ => middle_spp(&spp),
        };

        // Integrator labels: the short name, numbered when several share it.
        let names: Vec<&str> = study.integrators.iter().map(|d| d.name()).collect();
        let integrators: Vec<PlanIntegrator> = study
            .integrators
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
                return Err(here(format!("integrators: {} is listed twice", i.ron)));
            }
            seen.push(&i.ron);
        }

        // Scenes, with the film override and --quick resolution applied.
        let mut scenes: Vec<PlanScene> = Vec::new();
        for (i, s) in study.scenes.into_iter().enumerate() {
            let (name, source, mut desc, base) = match s {
                SceneRef::File(p) => {
                    let file = resolve(path, &p);
                    let desc = scene_desc::load(&file)
                        .with_context(|| format!("{}: scenes[{i}]", path.display()))?;
                    let name: String = file
                        .file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_default()
                        .chars()
                        .map(|c| if valid_name(&c.to_string()) { c } else { '_' })
                        .collect();
                    (name, file.display().to_string(), desc, file)
                }
                SceneRef::Inline { name, scene } => {
                    if !valid_name(&name) {
                        return Err(here(format!(
                            "scenes[{i}]: name '{name}' must be letters, digits, '_' or '-'"
                        )));
                    }
                    let source = format!("{} (inline scene '{name}')", path.display());
                    (name, source, *scene, path.clone())
                }
            };
            if scenes.iter().any(|o| o.name == name) {
                return Err(here(format!(
                    "scenes[{i}]: a scene named '{name}' is already in the study; scene names \
                     (file stems) must differ"
                )));
            }
            if let Some(f) = study.film {
                desc.film.width = f.width;
                desc.film.height = f.height;
            }
            desc.film.crop = None;
            desc.film.spp = 1;
            desc.film.seed = 0;
            desc.film
                .validate()
                .map_err(|e| here(format!("scene '{name}': film: {e}")))?;
            let (w0, h0) = (desc.film.width, desc.film.height);
            if quick {
                // An EXR reference fixes the resolution.
                let exr_ref = matches!(reference, PlanReference::Exr(_));
                match q.film {
                    Some(f) => {
                        desc.film.width = f.width;
                        desc.film.height = f.height;
                    }
                    None if !exr_ref && w0.max(h0) > 64 => {
                        let s = 64.0 / w0.max(h0) as f64;
                        desc.film.width = ((w0 as f64 * s).round() as u32).max(1);
                        desc.film.height = ((h0 as f64 * s).round() as u32).max(1);
                    }
                    None => {}
                }
                desc.film
                    .validate()
                    .map_err(|e| here(format!("quick.film: {e}")))?;
            }
            let (w, h) = (desc.film.width, desc.film.height);
            let mut regions = Vec::new();
            for r in &study.regions {
                // Region coordinates refer to the study's film; --quick scales them along.
                let sx = |v: u32| (v as u64 * w as u64 / w0 as u64) as u32;
                let sy = |v: u32| (v as u64 * h as u64 / h0 as u64) as u32;
                let rect = Rect {
                    x: sx(r.x),
                    y: sy(r.y),
                    w: sx(r.w).max(1),
                    h: sy(r.h).max(1),
                };
                let film = Rect { x: 0, y: 0, w, h };
                if rect.x as u64 + rect.w as u64 > w as u64
                    || rect.y as u64 + rect.h as u64 > h as u64
                {
                    return Err(here(format!(
                        "regions: '{}' ({rect}) is not inside scene '{name}''s {}x{} film",
                        r.name, film.w, film.h
                    )));
                }
                regions.push(rect);
            }
            let mut keyed = desc.clone();
            keyed.integrator = IntegratorDesc::default();
            // The files' contents and tress's version too: replacing an environment map (or
            // updating tress) must not reuse renders of the old one.
            let files = desc
                .files_hash(&base)
                .map_err(|e| here(format!("scene '{name}': {e}")))?;
            let content = str_hash(&format!(
                "{}|{}|{files:016x}|tress {}",
                ron::to_string(&keyed).unwrap_or_else(|_| format!("{keyed:?}")),
                base.display(),
                env!("CARGO_PKG_VERSION")
            ));
            scenes.push(PlanScene {
                name,
                source,
                desc,
                base,
                content,
                regions,
            });
        }

        let out = match (&settings.out, &study.output) {
            (Some(o), _) => o.clone(),
            (None, Some(o)) => suffix(resolve(path, o), quick),
            (None, None) => suffix(PathBuf::from(format!("{stem}_study")), quick),
        };
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
            spp,
            reps,
            seed: study.seed,
            reference,
            own_spp,
            region_names,
            heatmap_spp,
            target_relmse: study.target_relmse,
            gain: study.exposure.exp2(),
        })
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
