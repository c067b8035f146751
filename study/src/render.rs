//! Rendering the jobs, with the cache of EXRs in the output folder.

use crate::cost::timed;
use crate::error::{Error, Result};
use crate::plan::{pixels_hash, str_hash, PlanIntegrator, PlanScene};
use crate::progress::Progress;
use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::path::PathBuf;
use tress_core::film::FilmSettings;
use tress_core::image_io;
use tress_core::output_file::{Batch, Inputs};
use tress_core::rng::hash_words;
use tress_core::{Image, Integrator};
use tress_loader::scene_desc::{self, BuiltScene};

/// One image to obtain.
pub(super) struct Job<'a> {
    pub(super) integrator: &'a PlanIntegrator,
    pub(super) spp: u32,
    pub(super) seed: u64,
    pub(super) exr: PathBuf,
}

pub(super) struct Rendered {
    pub(super) image: Image,
    /// The render's cost: CPU seconds of the render threads (wall seconds where the kernel
    /// does not report CPU time), so that other load on the machine does not skew equal-time
    /// comparisons.
    pub(super) time_s: f64,
    pub(super) wall_s: f64,
    /// Wall seconds of the integrator's per-film precomputation, included in both times.
    pub(super) precompute_s: f64,
    pub(super) rays: u64,
}

pub(super) enum Cached {
    Missing,
    Stale(String),
    Hit(Rendered),
}

/// The study's render loop over one scene: builds the scene and integrators only when a render
/// is actually needed, so a fully cached rerun reads images only.
pub(super) struct SceneRunner<'a> {
    pub(super) scene: &'a PlanScene,
    /// The scene, once a job needs it (density grids are the integrators' business, built
    /// per resolution in `prep`, so every integrator shares one scene and BVH).
    pub(super) built: Option<BuiltScene>,
    pub(super) integrators: HashMap<String, Box<dyn Integrator>>,
    /// The study's preparation context (tables shared by all its integrators).
    pub(super) prep: &'a tress_core::prepare::Preparation,
    pub(super) pool: &'a rayon::ThreadPool,
    /// The files the study reads, which its renders may not replace.
    pub(super) inputs: &'a Inputs,
    pub(super) progress: &'a dyn Progress,
    pub(super) verbose: bool,
    pub(super) rendered: usize,
    pub(super) reused: usize,
    pub(super) render_seconds: f64,
}

pub(super) fn attribute<'a>(attrs: &'a [(String, String)], key: &str) -> Option<&'a str> {
    attrs
        .iter()
        .find(|(n, _)| n == key)
        .map(|(_, v)| v.as_str())
}

impl SceneRunner<'_> {
    pub(super) fn key(&self, job: &Job) -> String {
        format!(
            "{:016x}",
            hash_words(&[
                self.scene.content,
                str_hash(&job.integrator.ron),
                job.spp as u64,
                job.seed
            ])
        )
    }

    pub(super) fn cached(&self, job: &Job, key: &str) -> Cached {
        if !job.exr.exists() {
            return Cached::Missing;
        }
        let (image, attrs) = match image_io::read_exr(&job.exr) {
            Ok(r) => r,
            Err(e) => return Cached::Stale(format!("unreadable ({e})")),
        };
        if attribute(&attrs, "tress:study_key") != Some(key) {
            return Cached::Stale("made with other settings".into());
        }
        // An image edited after the render (attributes kept) must not pass for the render.
        if attribute(&attrs, "tress:pixels_hash") != Some(pixels_hash(&image).as_str()) {
            return Cached::Stale("its pixels changed since it was rendered".into());
        }
        let film = &self.scene.desc.film;
        if (
            image.full_width,
            image.full_height,
            image.width,
            image.height,
        ) != (film.width, film.height, film.width, film.height)
        {
            return Cached::Stale("wrong size".into());
        }
        let number = |key| attribute(&attrs, key).and_then(|v| v.parse().ok());
        let time_s = number("tress:render_cpu_s");
        let wall_s = number("tress:render_time_s");
        let rays = attribute(&attrs, "tress:rays").and_then(|v| v.parse().ok());
        // Renders from before integrators could precompute per film had nothing to record.
        let precompute_s = number("tress:precompute_time_s").unwrap_or(0.0);
        match (time_s, wall_s, rays) {
            (Some(time_s), Some(wall_s), Some(rays)) => Cached::Hit(Rendered {
                image,
                time_s,
                wall_s,
                precompute_s,
                rays,
            }),
            _ => Cached::Stale("no render time or ray count".into()),
        }
    }

    pub(super) fn run(&mut self, job: &Job) -> Result<Rendered> {
        let film = FilmSettings {
            spp: job.spp,
            seed: job.seed,
            ..self.scene.desc.film.clone()
        };
        let samples = film.width as u64 * film.height as u64 * film.spp as u64;
        let key = self.key(job);
        match self.cached(job, &key) {
            Cached::Hit(r) => {
                self.reused += 1;
                self.progress.advance(samples);
                return Ok(r);
            }
            Cached::Stale(why) if self.verbose => {
                self.progress
                    .note(&format!("re-rendering {}: {why}", job.exr.display()));
            }
            _ => {}
        }

        let scene = &self.scene;
        let pool = self.pool;
        let built = match &mut self.built {
            Some(built) => built,
            slot => slot
                .insert(pool.install(|| scene_desc::build(&scene.desc, &scene.base, self.prep))?),
        };
        let integrator = match self.integrators.entry(job.integrator.ron.clone()) {
            Entry::Occupied(e) => e.into_mut(),
            Entry::Vacant(e) => e.insert(
                pool.install(|| job.integrator.desc.build(&built.scene, self.prep))
                    .inspect(|_| {
                        // What the scene's models and this integrator built or read; warnings
                        // (a stored table refused) are reported either way.
                        let built_now = self.prep.take_notes();
                        (built_now.iter())
                            .filter(|line| self.verbose || line.starts_with("warning"))
                            .for_each(|line| self.progress.note(line));
                    })
                    .map_err(|e| Error::Integrator {
                        scene: scene.source.clone(),
                        integrator: job.integrator.ron.clone(),
                        source: e.source,
                    })?,
            ),
        };
        let reporter = self.progress;
        let progress = |n: u64| reporter.advance(n);
        let (output, cost) = timed(|| {
            pool.install(|| {
                tress_core::render::render(&built.scene, integrator.as_ref(), &film, &progress)
            })
        });
        let stats = &output.stats;
        if stats.nonfinite_samples > 0 {
            reporter.note(&format!(
                "warning: {}: {} samples were NaN or infinite and were dropped",
                job.exr.display(),
                stats.nonfinite_samples
            ));
        }
        let wall_s = stats.wall.as_secs_f64();
        let time_s = cost.cpu.unwrap_or(wall_s);
        let attributes = [
            ("tress:scene", scene.source.clone()),
            ("tress:integrator", job.integrator.ron.clone()),
            ("tress:spp", job.spp.to_string()),
            ("tress:seed", job.seed.to_string()),
            ("tress:render_time_s", wall_s.to_string()),
            ("tress:render_cpu_s", time_s.to_string()),
            (
                "tress:precompute_time_s",
                stats.precompute.as_secs_f64().to_string(),
            ),
            ("tress:rays", stats.rays.to_string()),
            ("tress:study_key", key),
            ("tress:pixels_hash", pixels_hash(&output.image)),
        ];
        if let Some(dir) = job.exr.parent() {
            std::fs::create_dir_all(dir).map_err(|source| Error::CreateFolder {
                path: dir.to_owned(),
                source,
            })?;
        }
        // Both or neither: a cached EXR is read back on the next run, its PNG is not.
        let mut files = Batch::new(self.inputs);
        files.add(&job.exr, |out| {
            Ok::<_, Error>(image_io::write_exr(out, &output.image, &attributes)?)
        })?;
        files.add(&job.exr.with_extension("png"), |out| {
            Ok::<_, Error>(image_io::write_png(out, &output.image, 0.0)?)
        })?;
        files.commit()?;
        self.rendered += 1;
        self.render_seconds += time_s;
        Ok(Rendered {
            image: output.image,
            time_s,
            wall_s,
            precompute_s: stats.precompute.as_secs_f64(),
            rays: stats.rays,
        })
    }
}
