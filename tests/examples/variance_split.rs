//! How much of the path tracer's variance lies beyond a path's vertex number `d`: renders a
//! scene's film where each camera sample traces its path to vertex `d` once and averages `k`
//! independent continuations from there, for `k` = 1 and `k` = `--branches`. With `S` samples
//! per pixel, an image's error against a converged reference is about (A + B / k) / S, where A
//! is the variance of the light the path's first `d` vertices see (which no estimator that
//! changes only what happens beyond vertex d can remove) and B the variance of the
//! continuations; the two runs solve for both, and B / (A + B) is the share beyond vertex `d`.
//! Cost is measured the same way: the rays traced before and beyond the split.
//!
//!   cargo run --release -p tress-tests --example variance_split -- SCENE.ron REFERENCE.exr \
//!       [--depth 0] [--spp 16] [--branches 16] [--window x,y,w,h]
//!
//! Errors are relMSE over the window (ε = 1e-2, as `tress diff`).

// A program of its own, not library code: it reads its command line (clippy.toml).
#![allow(clippy::disallowed_methods)]

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use std::path::PathBuf;
use tress_core::integrator::{continue_path, trace_path};
use tress_core::render::camera_sample;
use tress_core::rng::hash_words;
use tress_core::{Ray, Rgb, Sampler, Scene};
use tress_path::PathSettings;

struct Args {
    scene: PathBuf,
    reference: PathBuf,
    depth: u32,
    spp: u32,
    branches: u32,
    window: Option<[u32; 4]>,
}

fn parse() -> Result<Args> {
    let mut args = std::env::args().skip(1);
    let mut positional = Vec::new();
    let (mut depth, mut spp, mut branches, mut window) = (0, 16, 16, None);
    while let Some(a) = args.next() {
        let mut value = || args.next().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--depth" => depth = value()?.parse()?,
            "--spp" => spp = value()?.parse()?,
            "--branches" => branches = value()?.parse()?,
            "--window" => {
                let v: Vec<u32> = value()?
                    .split(',')
                    .map(str::parse)
                    .collect::<Result<_, _>>()?;
                let [x, y, w, h] = v[..] else {
                    bail!("--window takes x,y,w,h")
                };
                window = Some([x, y, x + w, y + h]);
            }
            _ => positional.push(PathBuf::from(a)),
        }
    }
    let [scene, reference] = <[PathBuf; 2]>::try_from(positional)
        .map_err(|_| anyhow::anyhow!("usage: variance_split SCENE.ron REFERENCE.exr [options]"))?;
    Ok(Args {
        scene,
        reference,
        depth,
        spp,
        branches,
        window,
    })
}

/// One camera sample: its path traced to vertex `split`, then `branches` continuations from
/// there averaged (each the path tracer's, with a sampler of its own). Returns the estimate,
/// and the rays traced before and beyond the split.
fn sample(
    scene: &Scene,
    camera_ray: Ray,
    mut sampler: Sampler,
    split: u32,
    branches: u32,
    stream: u64,
) -> (Rgb, u64, u64) {
    // The path tracer's settings: `Path()`'s defaults.
    let PathSettings {
        max_depth,
        rr_depth,
    } = PathSettings::default();
    let before = scene.rays_traced_on_this_thread();
    let mut beyond = 0;
    let radiance = trace_path(scene, &camera_ray, max_depth, rr_depth, &mut sampler, |v| {
        if v.depth < split {
            return None;
        }
        let start = scene.rays_traced_on_this_thread();
        let mut sum = Rgb::ZERO;
        for b in 0..branches {
            let mut branch = Sampler::from_seed(hash_words(&[stream, b as u64]));
            sum += continue_path(scene, *v, max_depth, rr_depth, &mut branch, |_| None);
        }
        beyond = scene.rays_traced_on_this_thread() - start;
        Some(sum / branches as f32)
    });
    let total = scene.rays_traced_on_this_thread() - before;
    (radiance, total - beyond, beyond)
}

/// relMSE over `window` of `image` (rows of the full film) against `reference`.
fn rel_mse(image: &[Rgb], reference: &tress_core::Image, window: [u32; 4]) -> f64 {
    let [x0, y0, x1, y1] = window;
    let mut sum = 0.0;
    let mut n = 0.0;
    for y in y0..y1 {
        for x in x0..x1 {
            let a = image[(y * reference.full_width + x) as usize];
            let b = reference.pixels
                [((y - reference.y0) * reference.width + (x - reference.x0)) as usize];
            for c in 0..3 {
                let d = (a[c] - b[c]) as f64;
                sum += d * d / ((b[c] as f64).powi(2) + 1e-2);
                n += 1.0;
            }
        }
    }
    sum / n
}

fn main() -> Result<()> {
    let args = parse()?;
    let desc = tress_loader::scene_desc::load(&args.scene)?;
    let built = tress_loader::scene_desc::build(&desc, &args.scene, &Default::default())?;
    let scene = &built.scene;
    let film = &desc.film;
    let (reference, _) = tress_core::image_io::read_exr(&args.reference)
        .with_context(|| format!("reading {}", args.reference.display()))?;
    let window = args.window.unwrap_or([0, 0, film.width, film.height]);
    let mut results = Vec::new();
    for branches in [1, args.branches] {
        let start = std::time::Instant::now();
        let pixels: Vec<(Rgb, u64, u64)> = (0..film.width * film.height)
            .into_par_iter()
            .map(|p| {
                let (x, y) = (p % film.width, p / film.width);
                let mut total = (Rgb::ZERO, 0, 0);
                for s in 0..args.spp as u64 {
                    let (ray, sampler) = camera_sample(&scene.camera, film, x, y, s);
                    let stream = hash_words(&[film.seed, x as u64, y as u64, s, branches as u64]);
                    let (l, a, b) = sample(scene, ray, sampler, args.depth, branches, stream);
                    total = (total.0 + l, total.1 + a, total.2 + b);
                }
                (total.0 / args.spp as f32, total.1, total.2)
            })
            .collect();
        let image: Vec<Rgb> = pixels.iter().map(|p| p.0).collect();
        let prefix: u64 = pixels.iter().map(|p| p.1).sum();
        let beyond: u64 = pixels.iter().map(|p| p.2).sum();
        let error = rel_mse(&image, &reference, window);
        println!(
            "k = {branches:3}: relMSE {error:.4e}, rays before the split {prefix}, beyond it \
             {beyond} ({:.1} s)",
            start.elapsed().as_secs_f64()
        );
        results.push((error, prefix, beyond));
    }
    let k = args.branches as f64;
    let ((v1, prefix, beyond), (vk, _, _)) = (results[0], results[1]);
    // v1 = A + B, vk = A + B / k (both per sample, times 1 / S).
    let b = (v1 - vk) * k / (k - 1.0);
    let a = v1 - b;
    println!(
        "vertex {}: variance before the split {:.1} %, beyond it {:.1} %; rays beyond it {:.1} % \
         of a path's",
        args.depth,
        100.0 * a / v1,
        100.0 * b / v1,
        100.0 * beyond as f64 / (prefix + beyond) as f64
    );
    Ok(())
}
