//! White-furnace scenes: non-absorbing fibers under a constant environment of radiance 1 must
//! render an image whose every pixel, and so whose mean, is 1 — whatever the multiple
//! scattering — when the integrator is unbiased and the fiber model conserves energy.

use tress_core::render::render;
use tress_core::Integrator;
use tress_materials::HairModel;
use tress_path::{PathSettings, PathTracer};
use tress_tests::{film, hair_ball_scene, white_environment};

fn furnace_mean(model: &str) -> f64 {
    let model: HairModel = ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES)
        .from_str(model)
        .unwrap();
    let scene = hair_ball_scene(model.build().unwrap(), 3000, white_environment());
    // Deep paths: the furnace only balances if the walk is not cut short (RR keeps it unbiased).
    let integrator: Box<dyn Integrator> = Box::new(PathTracer::new(PathSettings {
        max_depth: 10_000,
        rr_depth: 5,
    }));
    let out = render(
        &scene,
        integrator.as_ref(),
        &film(48, 48, spp(), 11),
        &|_| {},
    );
    assert_eq!(out.stats.nonfinite_samples, 0);
    let mean = out.image.mean();
    eprintln!(
        "{model:?}: furnace image mean {mean:.5} ({} rays)",
        out.stats.rays
    );
    mean
}

#[test]
fn lambertian_fibers_in_a_white_furnace_average_one() {
    let m = furnace_mean("LambertianFiber(albedo: (1, 1, 1))");
    assert!((m - 1.0).abs() < 0.01, "mean {m}");
}

#[test]
fn chiang_fibers_in_a_white_furnace_average_one() {
    let m = furnace_mean("Chiang(beta_m: 0.3, beta_n: 0.3, alpha: 2.0, pigment: SigmaA(0, 0, 0))");
    assert!((m - 1.0).abs() < 0.01, "mean {m}");
}

#[test]
fn absorbing_fibers_are_darker_than_the_furnace() {
    // The test must be able to fail: absorption has to show.
    let m = furnace_mean("LambertianFiber(albedo: (0.5, 0.5, 0.5))");
    assert!(m < 0.95, "mean {m}");
}

fn spp() -> u32 {
    std::env::var("FURNACE_SPP")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(32)
}
