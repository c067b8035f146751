//! Measurements: errors against the references over the regions, for every job.

use super::*;

/// Errors of one render against one reference over one region.
#[derive(Clone, Copy, Debug)]
pub(super) struct Errors {
    pub(super) mse: f64,
    pub(super) relmse: f64,
    pub(super) mean: f64,
    pub(super) ref_mean: f64,
}

impl From<&diff::Metrics> for Errors {
    fn from(m: &diff::Metrics) -> Self {
        Errors {
            mse: m.mse_all(),
            relmse: m.relmse_all(),
            mean: m.mean_a_all(),
            ref_mean: m.mean_b_all(),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(super) enum RefKind {
    Common,
    Own,
}

impl RefKind {
    pub(super) fn name(self) -> &'static str {
        match self {
            RefKind::Common => "common",
            RefKind::Own => "own",
        }
    }
}

/// One line of results.csv.
pub(super) struct Row {
    pub(super) scene: usize,
    pub(super) integrator: usize,
    pub(super) spp: u32,
    pub(super) rep: u32,
    pub(super) seed: u64,
    pub(super) time_s: f64,
    pub(super) wall_s: f64,
    pub(super) precompute_s: f64,
    pub(super) rays: u64,
    pub(super) reference: RefKind,
    pub(super) whole: Errors,
    pub(super) regions: Vec<Errors>,
}

/// Errors of `img` against `reference` over the whole image and each region.
pub(super) fn measure(img: &Image, reference: &Image, regions: &[Rect]) -> (Errors, Vec<Errors>) {
    let whole = Errors::from(&diff::metrics(img, reference, Rect::window_of(img)));
    let regions = regions
        .iter()
        .map(|r| Errors::from(&diff::metrics(img, reference, *r)))
        .collect();
    (whole, regions)
}

/// A tone-mapped crop for the sheets.
pub(super) fn picture(img: &Image, r: Rect, gain: f32) -> Picture {
    let mut rgb = Vec::with_capacity(r.w as usize * r.h as usize * 3);
    for y in r.y..r.y + r.h {
        for x in r.x..r.x + r.w {
            let p = img.get(x - img.x0, y - img.y0);
            rgb.extend([p.x, p.y, p.z].map(|c| plot::srgb8(c, gain)));
        }
    }
    Picture {
        width: r.w,
        height: r.h,
        rgb,
    }
}

/// What the figures need from one scene.
pub(super) struct SceneFigures {
    /// Per integrator: the relative error map at `heatmap_spp`, repetition 0.
    pub(super) heat: Vec<Option<Vec<f32>>>,
    /// [sheet region][integrator][spp index]: crops of repetition 0.
    pub(super) crops: Vec<Vec<Vec<Option<Picture>>>>,
    /// [sheet region]: the common reference crop; [sheet region][integrator]: own reference crops.
    pub(super) ref_crops: Vec<Picture>,
    pub(super) own_crops: Vec<Vec<Option<Picture>>>,
}

pub(super) struct Results {
    pub(super) rows: Vec<Row>,
    /// MSE of the mean image of the repetitions, by (scene, integrator, spp, reference).
    pub(super) mean_mse: HashMap<(usize, usize, u32, RefKind), f64>,
    pub(super) figures: Vec<SceneFigures>,
    pub(super) rendered: usize,
    pub(super) reused: usize,
    pub(super) render_seconds: f64,
}

/// Sheet regions: the study's regions, or the whole film when it names none.
pub(super) fn sheet_regions(plan: &Plan, scene: &PlanScene) -> Vec<(String, Rect)> {
    if plan.region_names.is_empty() {
        let f = &scene.desc.film;
        vec![(
            "full".into(),
            Rect {
                x: 0,
                y: 0,
                w: f.width,
                h: f.height,
            },
        )]
    } else {
        plan.region_names
            .iter()
            .cloned()
            .zip(scene.regions.iter().copied())
            .collect()
    }
}

/// The render of a reference: its file name holds the integrator settings' hash, so the common
/// reference and an integrator's own reference with the same settings are one file.
pub(super) fn reference_job<'a>(
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

pub(super) fn execute(
    plan: &Plan,
    pool: &rayon::ThreadPool,
    bar: &ProgressBar,
    verbose: bool,
) -> Result<Results> {
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
    let prep = tress_core::prepare::Preparation::with_limits(crate::limits_from_env());
    for (si, scene) in plan.scenes.iter().enumerate() {
        let mut runner = SceneRunner {
            scene,
            built: None,
            integrators: HashMap::new(),
            prep: &prep,
            pool,
            bar,
            verbose,
            rendered: 0,
            reused: 0,
            render_seconds: 0.0,
        };
        let common = match &plan.reference {
            PlanReference::Render { integrator, spp } => {
                runner
                    .run(&reference_job(plan, scene, integrator, *spp))?
                    .image
            }
            PlanReference::Exr(template) => {
                let file = scene_desc::resolve(
                    &plan.study_path,
                    Path::new(&template.replace("{scene}", &scene.name)),
                );
                let (img, _) = image_io::read_exr(&file).with_context(|| {
                    format!(
                        "{}: reference of scene '{}'",
                        plan.study_path.display(),
                        scene.name
                    )
                })?;
                let film = &scene.desc.film;
                if (img.full_width, img.full_height, img.width, img.height)
                    != (film.width, film.height, film.width, film.height)
                {
                    bail!(
                        "reference {} is a window {} of a {}x{} film, but scene '{}' ({}) renders a full {}x{} film",
                        file.display(),
                        Rect::window_of(&img),
                        img.full_width,
                        img.full_height,
                        scene.name,
                        scene.source,
                        film.width,
                        film.height
                    );
                }
                crate::diff::check_finite(&img, &file).with_context(|| {
                    format!(
                        "{}: reference of scene '{}'",
                        plan.study_path.display(),
                        scene.name
                    )
                })?;
                img
            }
        };
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

        let sheets = sheet_regions(plan, scene);
        let mut fig = SceneFigures {
            heat: vec![None; plan.integrators.len()],
            crops: vec![vec![vec![None; plan.spp.len()]; plan.integrators.len()]; sheets.len()],
            ref_crops: sheets
                .iter()
                .map(|(_, r)| picture(&common, *r, plan.gain))
                .collect(),
            own_crops: sheets
                .iter()
                .map(|(_, r)| {
                    own.iter()
                        .map(|o| o.as_ref().map(|img| picture(img, *r, plan.gain)))
                        .collect()
                })
                .collect(),
        };
        let dir = plan.out.join("renders").join(&scene.name);
        for (ii, integrator) in plan.integrators.iter().enumerate() {
            for (k, &spp) in plan.spp.iter().enumerate() {
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
                    push(&common, RefKind::Common);
                    if let Some(o) = &own[ii] {
                        push(o, RefKind::Own);
                    }
                    if rep == 0 {
                        for (g, (_, rect)) in sheets.iter().enumerate() {
                            fig.crops[g][ii][k] = Some(picture(&r.image, *rect, plan.gain));
                        }
                        if spp == plan.heatmap_spp {
                            fig.heat[ii] = Some(diff::error_map(
                                &r.image,
                                &common,
                                Rect::window_of(&common),
                                diff::MapKind::Rel,
                            ));
                        }
                    }
                }
                if plan.reps > 1 {
                    let mut mean = common.clone();
                    let k = plan.reps as f64;
                    for (m, s) in mean.pixels.iter_mut().zip(&sum) {
                        *m = glam::Vec3::new(
                            (s[0] / k) as f32,
                            (s[1] / k) as f32,
                            (s[2] / k) as f32,
                        );
                    }
                    let window = Rect::window_of(&mean);
                    let mse = |r: &Image| diff::metrics(&mean, r, window).mse_all();
                    results
                        .mean_mse
                        .insert((si, ii, spp, RefKind::Common), mse(&common));
                    if let Some(o) = &own[ii] {
                        results.mean_mse.insert((si, ii, spp, RefKind::Own), mse(o));
                    }
                }
            }
        }
        results.figures.push(fig);
        results.rendered += runner.rendered;
        results.reused += runner.reused;
        results.render_seconds += runner.render_seconds;
    }
    Ok(results)
}
