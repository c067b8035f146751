//! The guided path tracer is unbiased: whatever it learned, its images converge to the path
//! tracer's. Its mixtures (with a fixed and with learned probabilities of drawing from the
//! guide), and the roulette and splitting driven by the learned radiance, are held to the path
//! tracer's mean within the noise of independent renders.

use std::sync::Arc;
use tress_core::light::{EnvironmentMap, Light};
use tress_core::render::render;
use tress_core::{IntegratorKind, Scene};
use tress_guided::{GuidedPathTracer, GuidedSettings};
use tress_materials::pigment::{Pigment, NO_TINT};
use tress_materials::HairModel;
use tress_path::{PathSettings, PathTracer};
use tress_tests::{film, hair_ball_scene, mean_and_standard_error};

/// Blond hair under a sky with a bright sun-like region.
fn blond_ball() -> Scene {
    let bcsdf = HairModel::Chiang(tress_materials::chiang::Params {
        pigment: Pigment::Melanin {
            eumelanin: 0.3,
            pheomelanin: 0.0,
            tint: NO_TINT,
        },
        ..Default::default()
    })
    .build(&Default::default())
    .unwrap();
    let sky = EnvironmentMap::builtin_sky(60.0, 1.0).unwrap();
    hair_ball_scene(Arc::clone(&bcsdf), 2000, vec![Light::Environment(sky)])
}

/// Per-channel means of the centre of `renders` independent renders (seeds 100, 101, …),
/// with their standard errors.
fn channel_means(
    scene: &Scene,
    integrator: &dyn tress_core::Integrator,
    renders: u64,
) -> [(f64, f64); 3] {
    let per_render: Vec<[f64; 3]> = (0..renders)
        .map(|seed| {
            let mut f = film(32, 32, 128, 100 + seed);
            f.crop = Some([8, 8, 24, 24]);
            render(scene, integrator, &f, &|_| {}).image.mean_rgb()
        })
        .collect();
    [0, 1, 2].map(|k| {
        let values: Vec<f64> = per_render.iter().map(|m| m[k]).collect();
        mean_and_standard_error(&values)
    })
}

#[test]
fn its_mixtures_converge_to_the_path_tracer() {
    let scene = blond_ball();
    let renders = 8;
    let path = channel_means(&scene, &PathTracer::new(PathSettings::default()), renders);
    // The bounds detect a 5 % bias.
    let noise = 0.008;
    for (name, learn_probability, adjoint_roulette) in [
        ("mixture, fixed probability", false, false),
        ("mixture, learned probabilities", true, false),
        (
            "mixture, adjoint-driven roulette and splitting",
            false,
            true,
        ),
    ] {
        let settings = GuidedSettings {
            learn_probability,
            adjoint_roulette,
            min_records: 32,
            ..Default::default()
        };
        let guided = GuidedPathTracer::build(&settings, &scene, &Default::default()).unwrap();
        let means = channel_means(&scene, guided.as_ref(), renders);
        for k in 0..3 {
            let ((g, g_se), (p, p_se)) = (means[k], path[k]);
            let z = (g - p) / (g_se * g_se + p_se * p_se).sqrt();
            eprintln!(
                "{name}, channel {k}: guided {g:.5} ± {g_se:.5}, path {p:.5} ± {p_se:.5}, z {z:.2}"
            );
            assert!(z.abs() < 4.0, "{name}, channel {k}: z = {z:.2}");
            // Tight enough to mean something.
            assert!(
                g_se / g < noise,
                "{name}, channel {k}: too noisy to test ({g_se})"
            );
        }
    }
}
