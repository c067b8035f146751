//! THE render loop: rayon over fixed tiles, per-pixel-sample seeding, box filter, statistics.
//!
//! Every pixel sample draws its random numbers from `Sampler::for_pixel_sample(x, y, index, seed)`
//! and every pixel accumulates its samples in index order, so the image is bit-identical for any
//! thread count, tile schedule and crop window.

use crate::film::{FilmSettings, Image};
use crate::integrator::Integrator;
use crate::math::Rgb;
use crate::rng::Sampler;
use crate::scene::{rays_traced_on_this_thread, Scene};
use rayon::prelude::*;
use std::time::{Duration, Instant};

/// Side of the square tiles the film is split into.
pub const TILE_SIZE: u32 = 16;

/// What a render cost.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    pub wall: Duration,
    /// Camera samples taken.
    pub samples: u64,
    /// Rays traced (closest-hit and shadow).
    pub rays: u64,
    /// Samples whose radiance was NaN or infinite; they were dropped (counted as black).
    pub nonfinite_samples: u64,
}

impl RenderStats {
    pub fn samples_per_second(&self) -> f64 {
        self.samples as f64 / self.wall.as_secs_f64().max(1e-9)
    }

    pub fn rays_per_second(&self) -> f64 {
        self.rays as f64 / self.wall.as_secs_f64().max(1e-9)
    }
}

/// A rendered image and its statistics.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    pub image: Image,
    pub stats: RenderStats,
}

struct TileResult {
    pixels: Vec<Rgb>,
    rays: u64,
    nonfinite: u64,
}

/// Renders the film window of `film` with `integrator`, calling `progress` with the number of
/// samples finished after each tile (from worker threads).
pub fn render(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> RenderOutput {
    let start = Instant::now();
    let window = film.window();
    let [x0, y0, x1, y1] = window;
    let tiles: Vec<[u32; 4]> = (y0..y1)
        .step_by(TILE_SIZE as usize)
        .flat_map(|ty| {
            (x0..x1)
                .step_by(TILE_SIZE as usize)
                .map(move |tx| [tx, ty, (tx + TILE_SIZE).min(x1), (ty + TILE_SIZE).min(y1)])
        })
        .collect();

    let results: Vec<TileResult> = tiles
        .par_iter()
        .map(|&tile| {
            let rays_before = rays_traced_on_this_thread();
            let (pixels, nonfinite) = render_tile(scene, integrator, film, tile);
            progress(pixels.len() as u64 * film.spp as u64);
            TileResult {
                pixels,
                rays: rays_traced_on_this_thread() - rays_before,
                nonfinite,
            }
        })
        .collect();

    let mut image = Image::window(window, film.width, film.height);
    let mut stats = RenderStats::default();
    for (tile, result) in tiles.iter().zip(&results) {
        let [tx0, ty0, tx1, _] = *tile;
        let tw = (tx1 - tx0) as usize;
        for (i, &c) in result.pixels.iter().enumerate() {
            let (px, py) = (tx0 + (i % tw) as u32, ty0 + (i / tw) as u32);
            image.set(px - x0, py - y0, c);
        }
        stats.rays += result.rays;
        stats.nonfinite_samples += result.nonfinite;
    }
    stats.samples = image.pixels.len() as u64 * film.spp as u64;
    stats.wall = start.elapsed();
    RenderOutput { image, stats }
}

fn render_tile(
    scene: &Scene,
    integrator: &dyn Integrator,
    film: &FilmSettings,
    tile: [u32; 4],
) -> (Vec<Rgb>, u64) {
    let [tx0, ty0, tx1, ty1] = tile;
    let mut pixels = Vec::with_capacity(((tx1 - tx0) * (ty1 - ty0)) as usize);
    let mut nonfinite = 0;
    for y in ty0..ty1 {
        for x in tx0..tx1 {
            let mut sum = [0.0f64; 3];
            for s in 0..film.spp as u64 {
                let mut sampler = Sampler::for_pixel_sample(x, y, s, film.seed);
                let jitter = sampler.next_2d();
                let lens = sampler.next_2d();
                let ray = scene.camera.generate_ray(
                    x as f32 + jitter.x,
                    y as f32 + jitter.y,
                    film.width,
                    film.height,
                    lens,
                );
                let l = integrator.li(&ray, scene, &mut sampler);
                if l.is_finite() {
                    sum[0] += l.x as f64;
                    sum[1] += l.y as f64;
                    sum[2] += l.z as f64;
                } else {
                    nonfinite += 1;
                }
            }
            let n = film.spp as f64;
            pixels.push(Rgb::new(
                (sum[0] / n) as f32,
                (sum[1] / n) as f32,
                (sum[2] / n) as f32,
            ));
        }
    }
    (pixels, nonfinite)
}
