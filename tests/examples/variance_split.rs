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

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use std::path::PathBuf;
use tress_core::integrator::{direct_light, escaped_light, roulette, scatter};
use tress_core::render::camera_sample;
use tress_core::rng::hash_words;
use tress_core::{Hit, Ray, Rgb, Sampler, Scene, ShadingPoint};

/// The path tracer's settings (`Path()`'s defaults).
const MAX_DEPTH: u32 = 100;
const RR_DEPTH: u32 = 5;

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

/// The path tracer's estimate of the radiance leaving `hit` back along `ray`, for a path of
/// weight `throughput` arriving there at vertex number `depth` (the camera's vertex is 0);
/// `scatter_pdf` as the path tracer keeps it. Returns it with the rays traced.
fn continue_path(
    scene: &Scene,
    mut ray: Ray,
    mut hit: Hit,
    mut throughput: Rgb,
    mut depth: u32,
    sampler: &mut Sampler,
) -> (Rgb, u64) {
    let mut radiance = Rgb::ZERO;
    let mut rays = 0;
    let density_needed = scene.lights.weighs_escapes();
    loop {
        if depth >= MAX_DEPTH {
            break;
        }
        let sp = ShadingPoint::new(&hit, &ray, &scene.materials);
        let u_select = sampler.next_1d();
        let u_light = sampler.next_2d();
        if let Some((light, select_pdf)) = scene.lights.choose(u_select) {
            radiance += direct_light(scene, &sp, light, u_light, select_pdf, throughput);
            rays += 1;
        }
        let Some((next, pdf)) = scatter(&sp, sampler, &mut throughput, density_needed) else {
            break;
        };
        if roulette(depth, RR_DEPTH, &mut throughput, sampler).is_none() {
            break;
        }
        rays += 1;
        let Some(next_hit) = scene.intersect(&next) else {
            for light in scene.lights.infinite() {
                let select_pdf = scene.lights.select_pdf_of(light);
                radiance += escaped_light(light, next.dir, pdf, select_pdf, throughput);
            }
            break;
        };
        ray = next;
        hit = next_hit;
        depth += 1;
    }
    (radiance, rays)
}

/// One camera sample: its path traced to vertex `split`, then `branches` continuations from
/// there averaged. Returns the estimate, and the rays traced before and beyond the split.
fn sample(
    scene: &Scene,
    camera_ray: Ray,
    mut sampler: Sampler,
    split: u32,
    branches: u32,
    stream: u64,
) -> (Rgb, u64, u64) {
    let Some(mut hit) = scene.intersect(&camera_ray) else {
        let sky: Rgb = scene
            .lights
            .infinite()
            .map(|l| escaped_light(l, camera_ray.dir, None, 1.0, Rgb::ONE))
            .sum();
        return (sky, 1, 0);
    };
    let (mut radiance, mut throughput, mut ray) = (Rgb::ZERO, Rgb::ONE, camera_ray);
    let mut prefix_rays = 1;
    let density_needed = scene.lights.weighs_escapes();
    for depth in 0..split {
        let sp = ShadingPoint::new(&hit, &ray, &scene.materials);
        let u_select = sampler.next_1d();
        let u_light = sampler.next_2d();
        if let Some((light, select_pdf)) = scene.lights.choose(u_select) {
            radiance += direct_light(scene, &sp, light, u_light, select_pdf, throughput);
            prefix_rays += 1;
        }
        let Some((next, pdf)) = scatter(&sp, &mut sampler, &mut throughput, density_needed) else {
            return (radiance, prefix_rays, 0);
        };
        if roulette(depth, RR_DEPTH, &mut throughput, &mut sampler).is_none() {
            return (radiance, prefix_rays, 0);
        }
        prefix_rays += 1;
        match scene.intersect(&next) {
            Some(h) => (hit, ray) = (h, next),
            None => {
                for light in scene.lights.infinite() {
                    let select_pdf = scene.lights.select_pdf_of(light);
                    radiance += escaped_light(light, next.dir, pdf, select_pdf, throughput);
                }
                return (radiance, prefix_rays, 0);
            }
        }
    }
    let mut sum = Rgb::ZERO;
    let mut branch_rays = 0;
    for b in 0..branches {
        let mut branch = Sampler::from_seed(hash_words(&[stream, b as u64]));
        let (l, rays) = continue_path(scene, ray, hit, throughput, split, &mut branch);
        sum += l;
        branch_rays += rays;
    }
    (radiance + sum / branches as f32, prefix_rays, branch_rays)
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
    let desc = tress_scene::scene_desc::load(&args.scene)?;
    let built = tress_scene::scene_desc::build(&desc, &args.scene, &Default::default())?;
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
