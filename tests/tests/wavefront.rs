//! The wavefront path tracer computes the path tracer's estimator, sample for sample: its
//! images are `path`'s bit for bit, under lights it samples directly (an environment map with
//! a sun, where every vertex sends a shadow ray) and under a constant sky (where escapes take
//! the whole weight), on ribbons and tubes, whatever the wave a sample shares.

use std::sync::Arc;
use tress_accel::{CurveShape, HairOptions};
use tress_core::integrator::WaveSample;
use tress_core::light::{EnvironmentMap, Light};
use tress_core::render::{camera_sample, render};
use tress_core::{Integrator, Rgb, Scene};
use tress_materials::pigment::{Pigment, NO_TINT};
use tress_materials::HairModel;
use tress_path::{PathSettings, PathTracer};
use tress_tests::{assert_bit_identical, film, hair_ball, hair_scene};
use tress_wavefront::{WavefrontPathTracer, WavefrontSettings};

fn scene(curve: CurveShape, light: Light) -> Scene {
    let bcsdf = HairModel::Chiang(tress_materials::chiang::Params {
        pigment: Pigment::Melanin {
            eumelanin: 0.3,
            pheomelanin: 0.1,
            tint: NO_TINT,
        },
        ..Default::default()
    })
    .build(&Default::default())
    .unwrap();
    let options = HairOptions {
        curve,
        ..Default::default()
    };
    hair_scene(&hair_ball(1500), &options, Arc::clone(&bcsdf), vec![light])
}

fn lights() -> Vec<(&'static str, Light)> {
    vec![
        (
            "sky with a sun",
            Light::Environment(EnvironmentMap::builtin_sky(40.0, 1.0).unwrap()),
        ),
        ("constant sky", Light::constant(Rgb::ONE).unwrap()),
    ]
}

#[test]
fn wavefront_renders_the_path_tracers_image_bit_for_bit() {
    // Short paths and deep ones: the depth limit ends paths in mid-wave.
    for settings in [
        PathSettings::default(),
        PathSettings {
            max_depth: 3,
            rr_depth: 1,
        },
    ] {
        let path = PathTracer::new(settings.clone());
        let wavefront = WavefrontPathTracer::new(WavefrontSettings {
            max_depth: settings.max_depth,
            rr_depth: settings.rr_depth,
            paths: 100,
        });
        for curve in [CurveShape::Flat, CurveShape::Round] {
            for (light_name, light) in lights() {
                let scene = scene(curve, light);
                for seed in [1, 2] {
                    let f = film(24, 24, 8, seed);
                    let a = render(&scene, &path, &f, &|_| {}).image;
                    let b = render(&scene, &wavefront, &f, &|_| {}).image;
                    assert!(a.mean() > 0.0);
                    assert_bit_identical(
                        &a,
                        &b,
                        &format!("{settings:?}, {curve:?}, {light_name}, seed {seed}"),
                    );
                }
            }
        }
    }
}

#[test]
fn a_samples_radiance_does_not_depend_on_its_wave() {
    let (_, light) = lights().remove(0);
    let scene = scene(CurveShape::Flat, light);
    let f = film(16, 16, 4, 7);
    let wavefront = WavefrontPathTracer::new(WavefrontSettings::default());
    let samples: Vec<WaveSample> = (0..16u32)
        .flat_map(|x| (0..4u64).map(move |s| (x, s)))
        .map(|(x, s)| {
            let (ray, sampler) = camera_sample(&scene.camera, &f, x, 8, s);
            WaveSample {
                ray,
                sampler,
                sample_index: s,
                radiance: Rgb::ZERO,
            }
        })
        .collect();
    let mut whole = samples.clone();
    wavefront.li_wave(&scene, &mut whole);
    assert!(whole.iter().any(|w| w.radiance != Rgb::ZERO));
    // The same samples alone, and in a wave of the others reversed.
    let mut reversed: Vec<WaveSample> = samples.iter().rev().cloned().collect();
    wavefront.li_wave(&scene, &mut reversed);
    for (i, w) in whole.iter().enumerate() {
        let mut alone = [samples[i].clone()];
        wavefront.li_wave(&scene, &mut alone);
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
