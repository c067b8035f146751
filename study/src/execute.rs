//! Running the study: every job rendered (or read back), measured against the references.

use crate::error::{Error, Result};
use crate::metrics::{self, Rect};
use crate::picture::Picture;
use crate::plan::{
    reference_seed, str_hash, test_seed, Plan, PlanIntegrator, PlanReference, PlanScene,
    StudySettings,
};
use crate::progress::Progress;
use crate::render::{Job, SceneRunner};
use crate::results::{sheet_regions, Errors, RefKind, Results, Row, SceneFigures};
use std::collections::HashMap;
use tress_core::image_io;
use tress_core::Image;

/// Errors of `img` against `reference` over the whole image and each region.
fn measure(img: &Image, reference: &Image, regions: &[Rect]) -> (Errors, Vec<Errors>) {
    let whole = Errors::from(&metrics::metrics(img, reference, Rect::window_of(img)));
    let regions = regions
        .iter()
        .map(|r| Errors::from(&metrics::metrics(img, reference, *r)))
        .collect();
    (whole, regions)
}

/// The render of a reference: its file name holds the integrator settings' hash, so the common
/// reference and an integrator's own reference with the same settings are one file.
fn reference_job<'a>(
    plan: &Plan,
    scene: &PlanScene,
    integrator: &'a PlanIntegrator,
    spp: u32,
) -> Job<'a> {
    Job {
        integrator,
        spp,
        seed: reference_seed(plan.seed, &scene.name, &integrator.ron, spp),
        exr: plan.out.join("references").join(&scene.name).join(format!(
            "{}_{spp}spp_{:08x}.exr",
            integrator.desc.name(),
            str_hash(&integrator.ron) as u32
        )),
    }
}

/// Renders (or reads back) every job of the study and measures it.
pub(super) fn execute(
    plan: &Plan,
    pool: &rayon::ThreadPool,
    progress: &dyn Progress,
    settings: &StudySettings,
) -> Result<Results> {
    let verbose = settings.verbose;
    let mut results = Results {
        rows: Vec::new(),
        mean_mse: HashMap::new(),
        figures: Vec::new(),
        rendered: 0,
        reused: 0,
        render_seconds: 0.0,
    };
    // One preparation context for the whole study: every scene and integrator that needs the
    // same tables shares them.
    let prep = tress_core::prepare::Preparation::with_limits(settings.limits)
        .with_table_dir(settings.table_dir.clone());
    for (si, scene) in plan.scenes.iter().enumerate() {
        let mut runner = SceneRunner {
            scene,
            built: None,
            integrators: HashMap::new(),
            prep: &prep,
            pool,
            inputs: &plan.inputs,
            progress,
            verbose,
            rendered: 0,
            reused: 0,
            render_seconds: 0.0,
        };
        let common = common_reference(plan, scene, &mut runner)?;
        let mut own: Vec<Option<Image>> = Vec::new();
        for integrator in &plan.integrators {
            own.push(match plan.own_spp {
                Some(spp) => Some(
                    runner
                        .run(&reference_job(plan, scene, integrator, spp))?
                        .image,
                ),
                None => None,
            });
        }
        let references = References { common, own };
        let mut figures = scene_figures(plan, scene, &references);
        for ii in 0..plan.integrators.len() {
            for k in 0..plan.spp.len() {
                let setting = Setting { si, ii, k };
                measure_setting(
                    plan,
                    setting,
                    &mut runner,
                    &references,
                    &mut figures,
                    &mut results,
                )?;
            }
        }
        results.figures.push(figures);
        results.rendered += runner.rendered;
        results.reused += runner.reused;
        results.render_seconds += runner.render_seconds;
    }
    Ok(results)
}

/// The references of one scene: the common one, and each integrator's own when the study asks
/// for them.
struct References {
    common: Image,
    own: Vec<Option<Image>>,
}

/// The common reference of `scene`: rendered, or read from the study's EXR and checked to fit
/// the scene's film.
fn common_reference(plan: &Plan, scene: &PlanScene, runner: &mut SceneRunner) -> Result<Image> {
    let template = match &plan.reference {
        PlanReference::Render { integrator, spp } => {
            return Ok(runner
                .run(&reference_job(plan, scene, integrator, *spp))?
                .image)
        }
        PlanReference::Exr(template) => template,
    };
    let file = plan.reference_exr(template, scene);
    let (img, _) = image_io::read_exr(&file).map_err(|source| Error::ReadReference {
        study: plan.study_path.clone(),
        scene: scene.name.clone(),
        source,
    })?;
    let film = &scene.desc.film;
    if (img.full_width, img.full_height, img.width, img.height)
        != (film.width, film.height, film.width, film.height)
    {
        return Err(Error::ReferenceWindow {
            path: file,
            window: Rect::window_of(&img),
            full_width: img.full_width,
            full_height: img.full_height,
            scene: scene.name.clone(),
            source_file: scene.source.clone(),
            width: film.width,
            height: film.height,
        });
    }
    metrics::check_finite(&img, &file).map_err(|source| Error::NotFiniteReference {
        study: plan.study_path.clone(),
        scene: scene.name.clone(),
        source,
    })?;
    Ok(img)
}

/// The figures' data of `scene`, with the references' crops; the renders' crops and heat maps
/// are filled in as they are measured.
fn scene_figures(plan: &Plan, scene: &PlanScene, references: &References) -> SceneFigures {
    let sheets = sheet_regions(plan, scene);
    SceneFigures {
        heat: vec![None; plan.integrators.len()],
        crops: vec![vec![vec![None; plan.spp.len()]; plan.integrators.len()]; sheets.len()],
        ref_crops: sheets
            .iter()
            .map(|(_, r)| Picture::crop(&references.common, *r, plan.gain))
            .collect(),
        own_crops: sheets
            .iter()
            .map(|(_, r)| {
                references
                    .own
                    .iter()
                    .map(|o| o.as_ref().map(|img| Picture::crop(img, *r, plan.gain)))
                    .collect()
            })
            .collect(),
    }
}

/// One setting of the study: scene `si`, integrator `ii`, spp `plan.spp[k]`.
#[derive(Clone, Copy)]
struct Setting {
    si: usize,
    ii: usize,
    k: usize,
}

/// Renders the repetitions of one setting and measures each against the references; the mean
/// of the repetitions gives the MSE of the bias estimate, the first one the figures.
fn measure_setting(
    plan: &Plan,
    Setting { si, ii, k }: Setting,
    runner: &mut SceneRunner,
    references: &References,
    figures: &mut SceneFigures,
    results: &mut Results,
) -> Result<()> {
    let scene = &plan.scenes[si];
    let integrator = &plan.integrators[ii];
    let spp = plan.spp[k];
    let common = &references.common;
    let own = &references.own[ii];
    let dir = plan.out.join("renders").join(&scene.name);
    // Sum of the repetitions, for the bias estimate from their mean image.
    let mut sum = vec![[0.0f64; 3]; common.pixels.len()];
    for rep in 0..plan.reps {
        let seed = test_seed(plan.seed, &scene.name, &integrator.ron, spp, rep);
        let job = Job {
            integrator,
            spp,
            seed,
            exr: dir.join(format!("{}_{spp:05}spp_rep{rep:02}.exr", integrator.label)),
        };
        let r = runner.run(&job)?;
        for (s, p) in sum.iter_mut().zip(&r.image.pixels) {
            for c in 0..3 {
                s[c] += p[c] as f64;
            }
        }
        let mut push = |reference: &Image, kind: RefKind| {
            let (whole, regions) = measure(&r.image, reference, &scene.regions);
            results.rows.push(Row {
                scene: si,
                integrator: ii,
                spp,
                rep,
                seed,
                time_s: r.time_s,
                wall_s: r.wall_s,
                precompute_s: r.precompute_s,
                rays: r.rays,
                reference: kind,
                whole,
                regions,
            });
        };
        push(common, RefKind::Common);
        if let Some(o) = own {
            push(o, RefKind::Own);
        }
        if rep == 0 {
            for (g, (_, rect)) in sheet_regions(plan, scene).iter().enumerate() {
                figures.crops[g][ii][k] = Some(Picture::crop(&r.image, *rect, plan.gain));
            }
            if spp == plan.heatmap_spp {
                figures.heat[ii] = Some(metrics::error_map(
                    &r.image,
                    common,
                    Rect::window_of(common),
                    metrics::MapKind::Rel,
                ));
            }
        }
    }
    if plan.reps > 1 {
        let mean = mean_image(common, &sum, plan.reps);
        let window = Rect::window_of(&mean);
        let mse = |r: &Image| metrics::metrics(&mean, r, window).mse_all();
        results
            .mean_mse
            .insert((si, ii, spp, RefKind::Common), mse(common));
        if let Some(o) = own {
            results.mean_mse.insert((si, ii, spp, RefKind::Own), mse(o));
        }
    }
    Ok(())
}

/// The mean of `reps` renders whose pixels sum to `sum`, on the film of `like`.
fn mean_image(like: &Image, sum: &[[f64; 3]], reps: u32) -> Image {
    let mut mean = like.clone();
    let k = reps as f64;
    for (m, s) in mean.pixels.iter_mut().zip(sum) {
        *m = glam::Vec3::new((s[0] / k) as f32, (s[1] / k) as f32, (s[2] / k) as f32);
    }
    mean
}
