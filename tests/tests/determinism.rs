//! Same scene + seed ⇒ the bit-identical image, whatever the integrator, the thread count, the
//! crop window (except for integrators that learn from the crop's pixels) or the run.

use std::ops::Range;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use tress_core::light::{EnvironmentMap, Light};
use tress_core::render::{render, render_samples};
use tress_core::Scene;
use tress_loader::integrators::IntegratorDesc;
use tress_materials::pigment::Pigment;
use tress_materials::HairModel;
use tress_tests::{assert_bit_identical, film, hair_ball_scene, learns_from_film, on_threads};

/// Dark hair under a sky so dim (scale 1e-36) that most radiance values are denormal floats, so
/// any thread computing in another floating-point mode (flush-to-zero) shows in the bits.
fn scene() -> Scene {
    let model = HairModel::Chiang(tress_materials::chiang::Params {
        pigment: Pigment::Melanin {
            eumelanin: 8.0,
            pheomelanin: 0.5,
            tint: tress_materials::pigment::NO_TINT,
        },
        ..Default::default()
    })
    .build(&Default::default())
    .unwrap();
    let sky = EnvironmentMap::builtin_sky(30.0, 1e-36).unwrap();
    hair_ball_scene(Arc::clone(&model), 1500, vec![Light::Environment(sky)])
}

/// Every registered integrator, with its quick test settings.
fn integrators() -> Vec<IntegratorDesc> {
    IntegratorDesc::all_for_tests()
}

/// Builds the scene and the integrator on a fresh pool of `threads` workers — as the CLI does,
/// so that whatever building leaves behind on a worker thread is part of the test — and renders
/// there.
fn render_with(
    threads: usize,
    integrator: &IntegratorDesc,
    film: &tress_core::film::FilmSettings,
) -> tress_core::Image {
    on_threads(threads, || {
        let scene = scene();
        let integrator = integrator.build(&scene, &Default::default()).unwrap();
        render(&scene, integrator.as_ref(), film, &|_| {}).image
    })
}

#[test]
fn image_is_identical_for_any_thread_count_and_run() {
    let f = film(40, 40, 4, 5);
    for integrator in &integrators() {
        let name = integrator.name();
        let one = render_with(1, integrator, &f);
        assert!(one.mean() > 0.0, "{name}: black image");
        for (threads, run) in [(2, 1), (2, 2), (3, 1)] {
            let other = render_with(threads, integrator, &f);
            assert_bit_identical(
                &one,
                &other,
                &format!("{name}, {threads} threads, run {run}"),
            );
        }
    }
}

/// A crop renders each of its pixels as the whole film does, bit for bit — except for an
/// integrator that learns from the film's pixels (it prepares per film, [`Integrator::for_film`]):
/// that one learns from the crop's pixels alone, so its crop is the same for any threads but not
/// the full render's window (it agrees in expectation: its convergence tests render crops).
///
/// [`Integrator::for_film`]: tress_core::Integrator::for_film
#[test]
fn crop_window_equals_the_same_window_of_the_full_render() {
    let (mut plain, mut learning) = (0, 0);
    for integrator in &integrators() {
        let name = integrator.name();
        let full = render_with(2, integrator, &film(40, 40, 4, 5));
        let mut cropped_film = film(40, 40, 4, 5);
        cropped_film.crop = Some([7, 13, 29, 31]);
        let crop = render_with(3, integrator, &cropped_film);
        assert_eq!((crop.x0, crop.y0, crop.width, crop.height), (7, 13, 22, 18));
        let learns = on_threads(1, || {
            let scene = scene();
            let built = integrator.build(&scene, &Default::default()).unwrap();
            learns_from_film(built.as_ref(), &scene, &cropped_film)
        });
        if learns {
            learning += 1;
            let again = render_with(1, integrator, &cropped_film);
            assert_bit_identical(&crop, &again, &format!("{name}: crop, 1 and 3 threads"));
            assert!(crop.mean() > 0.0, "{name}: black crop");
            continue;
        }
        plain += 1;
        for y in 0..crop.height {
            for x in 0..crop.width {
                let a = crop.get(x, y);
                let b = full.get(x + 7, y + 13);
                assert_eq!(
                    a.to_array().map(f32::to_bits),
                    b.to_array().map(f32::to_bits),
                    "{name}: pixel ({x}, {y})"
                );
            }
        }
    }
    assert!(
        plain > 0 && learning > 0,
        "{plain} plain, {learning} learning integrators"
    );
}

#[test]
fn a_sample_range_is_the_same_whether_or_not_the_ranges_before_it_were_rendered() {
    // As `--spp-offset` passes split a render: a pass from sample 6 (the radiance cache's
    // third block under its test settings, its records coarsened to their budget) learns from
    // nothing, where an integrator that rendered 0..6 goes on from what it learned then.
    let f = film(40, 40, 14, 5);
    let never = AtomicBool::new(false);
    for integrator in &integrators() {
        let name = integrator.name();
        let (alone, after) = on_threads(2, || {
            let scene = scene();
            let sums = |built: &dyn tress_core::Integrator, samples: Range<u64>| {
                let out = render_samples(&scene, built, &f, samples, &never, &|_| {}).unwrap();
                out.sums
                    .sums
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            };
            let fresh = integrator.build(&scene, &Default::default()).unwrap();
            let alone = sums(fresh.as_ref(), 6..14);
            let built = integrator.build(&scene, &Default::default()).unwrap();
            sums(built.as_ref(), 0..6);
            (alone, sums(built.as_ref(), 6..14))
        });
        assert!(alone == after, "{name}: samples 6..14 differ after 0..6");
    }
}

#[test]
fn a_different_seed_gives_a_different_image() {
    for integrator in &integrators() {
        let name = integrator.name();
        let a = render_with(2, integrator, &film(24, 24, 2, 1));
        let b = render_with(2, integrator, &film(24, 24, 2, 2));
        assert_ne!(a.pixels, b.pixels, "{name}");
    }
}
