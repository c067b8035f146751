//! Dual scattering's wave form (`li_wave`: the camera rays, the counts behind, the shadow rays
//! and the counts toward the light of many samples each as one batch) computes the single
//! sample's estimator (`li`), sample for sample: its images are `li`'s bit for bit — under an
//! environment map with a sun, a constant sky and a delta sun, with a surface behind the hair
//! (whose samples take `li`'s path, and whose shadow rays the hair's blocked directions test),
//! with `path_bounces` (every sample on `li`'s path), and whatever the wave a sample shares.
//! The determinism, crop and merge tests cover the wave form through the registry.

use tress_accel::{HairOptions, SceneBuilder};
use tress_core::integrator::WaveSample;
use tress_core::light::{EnvironmentMap, Light};
use tress_core::math::Vec3;
use tress_core::render::{camera_sample, render};
use tress_core::{Camera, Integrator, Material, Ray, Rgb, Sampler, Scene};
use tress_dual_mis::{DualMis, MisDirections};
use tress_dual_uniform::{DualSettings, DualUniform, UniformDirections};
use tress_materials::pigment::{Pigment, NO_TINT};
use tress_materials::HairModel;
use tress_tests::{assert_bit_identical, film, hair_ball};

/// The integrator it wraps, one sample at a time (`li_wave`'s default, which calls `li`).
#[derive(Debug)]
struct OneByOne<'a>(&'a dyn Integrator);

impl Integrator for OneByOne<'_> {
    fn li(&self, ray: &Ray, scene: &Scene, sampler: &mut Sampler) -> Rgb {
        self.0.li(ray, scene, sampler)
    }
}

/// A blond hair ball, with a diffuse sphere behind it when `surface`.
fn scene(lights: Vec<Light>, surface: bool) -> Scene {
    let bcsdf = HairModel::Chiang(tress_materials::chiang::Params {
        pigment: Pigment::Melanin {
            eumelanin: 0.3,
            pheomelanin: 0.1,
            tint: NO_TINT,
        },
        ..Default::default()
    })
    .build()
    .unwrap();
    let mut builder = SceneBuilder::new()
        .and_then(|b| b.add_hair(&hair_ball(1500), &HairOptions::default(), 0))
        .unwrap();
    if surface {
        builder = builder
            .add_sphere(Vec3::new(0.6, 0.0, -1.4), 0.9, 1)
            .unwrap();
    }
    Scene::new(
        Camera::perspective(
            Vec3::new(0.0, 0.0, 4.0),
            Vec3::ZERO,
            Vec3::Y,
            40.0,
            0.0,
            None,
        ),
        Box::new(builder.build().unwrap()),
        vec![
            Material::Hair(bcsdf),
            Material::Diffuse {
                albedo: Rgb::new(0.6, 0.5, 0.4),
            },
        ],
        lights.into(),
    )
}

fn lights() -> Vec<(&'static str, Vec<Light>)> {
    let sun = Light::distant(Vec3::new(-1.0, -0.5, -1.0), Rgb::splat(2.0), 0.0).unwrap();
    vec![
        (
            "sky with a sun",
            vec![Light::Environment(
                EnvironmentMap::builtin_sky(40.0, 1.0).unwrap(),
            )],
        ),
        (
            "constant sky and a delta sun",
            vec![Light::constant(Rgb::splat(0.5)).unwrap(), sun],
        ),
    ]
}

fn settings(path_bounces: u32) -> DualSettings {
    DualSettings {
        path_bounces,
        ..DualSettings::for_tests()
    }
}

#[test]
fn the_wave_form_renders_the_single_samples_image_bit_for_bit() {
    for (light_name, lights) in lights() {
        for surface in [false, true] {
            let scene = scene(lights.clone(), surface);
            let prep = Default::default();
            for path_bounces in [0, 1] {
                let mis =
                    DualMis::new(settings(path_bounces), &scene, MisDirections, &prep).unwrap();
                // Dual-uniform has no wave form of its directions: it estimates in place.
                let uniform =
                    DualUniform::new(settings(path_bounces), &scene, UniformDirections, &prep)
                        .unwrap();
                for (name, integrator) in [
                    ("dual-mis", &mis as &dyn Integrator),
                    ("dual-uniform", &uniform),
                ] {
                    for seed in [1, 2] {
                        let f = film(24, 24, 8, seed);
                        let one = render(&scene, &OneByOne(integrator), &f, &|_| {}).image;
                        let wave = render(&scene, integrator, &f, &|_| {}).image;
                        assert!(one.mean() > 0.0);
                        assert_bit_identical(
                            &one,
                            &wave,
                            &format!(
                                "{name}, {light_name}, surface {surface}, path_bounces \
                                 {path_bounces}, seed {seed}"
                            ),
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn a_samples_radiance_does_not_depend_on_its_wave() {
    let (_, lights) = lights().remove(0);
    let scene = scene(lights, true);
    let f = film(16, 16, 4, 7);
    let mis = DualMis::new(settings(0), &scene, MisDirections, &Default::default()).unwrap();
    // More samples than a group, so that the wave is cut.
    let samples: Vec<WaveSample> = (0..16u32)
        .flat_map(|x| (0..16u32).map(move |y| (x, y)))
        .map(|(x, y)| {
            let s = u64::from(y % 4);
            let (ray, sampler) = camera_sample(&scene.camera, &f, x, y, s);
            WaveSample {
                ray,
                sampler,
                sample_index: s,
                radiance: Rgb::ZERO,
            }
        })
        .collect();
    let mut whole = samples.clone();
    mis.li_wave(&scene, &mut whole);
    assert!(whole.iter().any(|w| w.radiance != Rgb::ZERO));
    // The same samples alone, and in a wave of the others reversed.
    let mut reversed: Vec<WaveSample> = samples.iter().rev().cloned().collect();
    mis.li_wave(&scene, &mut reversed);
    for (i, w) in whole.iter().enumerate() {
        let mut alone = [samples[i].clone()];
        mis.li_wave(&scene, &mut alone);
        let other = &reversed[samples.len() - 1 - i];
        for r in [alone[0].radiance, other.radiance] {
            assert_eq!(
                r.to_array().map(f32::to_bits),
                w.radiance.to_array().map(f32::to_bits),
                "sample {i}"
            );
        }
    }
}
