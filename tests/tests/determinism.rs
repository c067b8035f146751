//! Same scene + seed ⇒ the bit-identical image, whatever the thread count or crop window.

use std::sync::Arc;
use tress_core::light::{EnvironmentMap, Light};
use tress_core::render::render;
use tress_core::Scene;
use tress_materials::HairModel;
use tress_path::{PathSettings, PathTracer};
use tress_tests::{film, hair_ball_scene};

fn scene() -> Scene {
    let model = HairModel::Chiang(Default::default()).build().unwrap();
    let sky = EnvironmentMap::builtin_sky(30.0, 1.0).unwrap();
    hair_ball_scene(Arc::clone(&model), 1500, vec![Light::Environment(sky)])
}

fn render_with(
    scene: &Scene,
    threads: usize,
    film: &tress_core::film::FilmSettings,
) -> tress_core::Image {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let integrator = PathTracer::new(PathSettings::default());
    pool.install(|| render(scene, &integrator, film, &|_| {}))
        .image
}

#[test]
fn image_is_identical_for_any_thread_count() {
    let scene = scene();
    let f = film(40, 40, 4, 5);
    let one = render_with(&scene, 1, &f);
    let four = render_with(&scene, 4, &f);
    assert!(one.mean() > 0.0);
    assert_eq!(one.pixels.len(), four.pixels.len());
    for (a, b) in one.pixels.iter().zip(&four.pixels) {
        assert_eq!(
            a.to_array().map(f32::to_bits),
            b.to_array().map(f32::to_bits)
        );
    }
}

#[test]
fn crop_window_equals_the_same_window_of_the_full_render() {
    let scene = scene();
    let full = render_with(&scene, 2, &film(40, 40, 4, 5));
    let mut cropped_film = film(40, 40, 4, 5);
    cropped_film.crop = Some([7, 13, 29, 31]);
    let crop = render_with(&scene, 3, &cropped_film);
    assert_eq!((crop.x0, crop.y0, crop.width, crop.height), (7, 13, 22, 18));
    for y in 0..crop.height {
        for x in 0..crop.width {
            let a = crop.get(x, y);
            let b = full.get(x + 7, y + 13);
            assert_eq!(
                a.to_array().map(f32::to_bits),
                b.to_array().map(f32::to_bits),
                "pixel ({x}, {y})"
            );
        }
    }
}

#[test]
fn a_different_seed_gives_a_different_image() {
    let scene = scene();
    let a = render_with(&scene, 2, &film(24, 24, 2, 1));
    let b = render_with(&scene, 2, &film(24, 24, 2, 2));
    assert_ne!(a.pixels, b.pixels);
}
