//! Shared helpers for the cross-crate tests in `tests/tests/`: small scenes built in code.

use std::path::PathBuf;
use std::sync::Arc;
use tress_accel::{HairOptions, SceneBuilder};
use tress_core::film::FilmSettings;
use tress_core::light::Light;
use tress_core::math::{Rgb, Vec3};
use tress_core::{Bcsdf, Camera, Material, Scene};
use tress_groom::{HairStyle, ProceduralHair};

/// A ball of `strands` fibers of radius 0.01 around the origin (radius 1), seen from +z, with
/// `bcsdf` and the given lights.
pub fn hair_ball_scene(bcsdf: Arc<dyn Bcsdf>, strands: u32, lights: Vec<Light>) -> Scene {
    hair_scene(&hair_ball(strands), &HairOptions::default(), bcsdf, lights)
}

/// `hair` drawn as `options` say, with `bcsdf` and the given lights, seen from (0, 0, 4)
/// looking at the origin with a 35° field of view.
pub fn hair_scene(
    hair: &tress_groom::HairGeometry,
    options: &HairOptions,
    bcsdf: Arc<dyn Bcsdf>,
    lights: Vec<Light>,
) -> Scene {
    let accel = SceneBuilder::new()
        .and_then(|b| b.add_hair(hair, options, 0))
        .and_then(|b| b.build())
        .expect("embree scene");
    Scene::new(
        Camera::perspective(
            Vec3::new(0.0, 0.0, 4.0),
            Vec3::ZERO,
            Vec3::Y,
            35.0,
            0.0,
            None,
        ),
        Box::new(accel),
        vec![Material::Hair(bcsdf)],
        lights.into(),
    )
}

/// Runs `f` on a fresh pool of `threads` workers, as the CLI builds and renders: whatever
/// building leaves behind on a worker thread is then part of a test.
pub fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Whether `integrator` learns from the pixels of `film` (it prepares for the film,
/// [`tress_core::Integrator::for_film`]): its crops learn from their own pixels, so a crop is
/// not bit for bit the same window of the full render.
pub fn learns_from_film(
    integrator: &dyn tress_core::Integrator,
    scene: &Scene,
    film: &FilmSettings,
) -> bool {
    let never = std::sync::atomic::AtomicBool::new(false);
    integrator
        .for_film(scene, film, 0..film.spp as u64, &never, &|_| {})
        .is_some()
}

/// A constant white environment of radiance 1.
pub fn white_environment() -> Vec<Light> {
    vec![Light::Constant { radiance: Rgb::ONE }]
}

pub fn film(width: u32, height: u32, spp: u32, seed: u64) -> FilmSettings {
    FilmSettings {
        width,
        height,
        spp,
        seed,
        crop: None,
    }
}

/// A file of the real data set, `../shared/data` beside the workspace. The tests that read one
/// are ignored; run without the data, they fail here.
pub fn shared_data(rel: &str) -> PathBuf {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data")
        .join(rel);
    assert!(
        p.exists(),
        "{} is absent: this test needs the real data set beside the workspace (../shared/data)",
        p.display()
    );
    p
}

/// The hair ball of [`hair_ball_scene`], as geometry.
pub fn hair_ball(strands: u32) -> tress_groom::HairGeometry {
    ProceduralHair {
        style: HairStyle::Ball,
        seed: 3,
        strands,
        points_per_strand: 16,
        radius: 0.01,
        length: 2.0,
        center: Vec3::ZERO,
        sphere_radius: 1.0,
    }
    .generate(&tress_core::limits::Limits::default())
    .expect("procedural hair")
}

/// Mean and sample variance (n − 1 in the denominator) of `values`.
pub fn mean_and_variance(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, var)
}

/// Mean and standard error of `values`.
pub fn mean_and_standard_error(values: &[f64]) -> (f64, f64) {
    let (mean, var) = mean_and_variance(values);
    (mean, (var / values.len() as f64).sqrt())
}

/// Asserts that two images of one size hold the same bits in every pixel (`what` names the
/// comparison in the message).
pub fn assert_bit_identical(a: &tress_core::Image, b: &tress_core::Image, what: &str) {
    assert_eq!(a.pixels.len(), b.pixels.len());
    for (i, (p, q)) in a.pixels.iter().zip(&b.pixels).enumerate() {
        assert_eq!(
            p.to_array().map(f32::to_bits),
            q.to_array().map(f32::to_bits),
            "{what}: pixel {i}"
        );
    }
}
