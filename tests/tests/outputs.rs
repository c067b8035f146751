//! Alpha and the AOVs over real geometry and every registered integrator: they leave the
//! radiance bit for bit unchanged, are bit-identical for any thread count and crop (a crop of
//! an integrator that learns from its pixels equals that crop rendered alone), and hold
//! plausible values; and what recording them costs.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tress_core::film::{Aov, FilmSettings, Outputs};
use tress_core::light::{EnvironmentMap, Light};
use tress_core::render::{camera_sample, render, render_outputs, SampleSums};
use tress_core::Scene;
use tress_loader::integrators::IntegratorDesc;
use tress_materials::HairModel;
use tress_tests::{film, hair_ball_scene, learns_from_film, on_threads, shared_data};

fn scene() -> Scene {
    let model = HairModel::Chiang(Default::default())
        .build(&Default::default())
        .unwrap();
    let sky = EnvironmentMap::builtin_sky(30.0, 1.0).unwrap();
    hair_ball_scene(Arc::clone(&model), 1500, vec![Light::Environment(sky)])
}

fn everything() -> Outputs {
    Outputs {
        alpha: true,
        aovs: Aov::ALL.into_iter().collect(),
    }
}

/// Renders on a fresh pool of `threads` workers, as the CLI does.
fn render_with(threads: usize, integrator: &IntegratorDesc, film: &FilmSettings) -> SampleSums {
    on_threads(threads, || {
        let scene = scene();
        let integrator = integrator.build(&scene, &Default::default()).unwrap();
        let never = AtomicBool::new(false);
        let samples = 0..film.spp as u64;
        render_outputs(
            &scene,
            integrator.as_ref(),
            film,
            &everything(),
            samples,
            &never,
            &|_| {},
        )
        .unwrap()
        .sums
    })
}

fn bits(channels: &[(&'static str, Vec<f32>)]) -> Vec<(&'static str, Vec<u32>)> {
    channels
        .iter()
        .map(|(n, v)| (*n, v.iter().map(|x| x.to_bits()).collect()))
        .collect()
}

#[test]
fn outputs_leave_the_radiance_alone_and_are_identical_for_any_threads_and_crop() {
    let f = film(32, 32, 4, 5);
    for integrator in &IntegratorDesc::all_for_tests() {
        let name = integrator.name();
        let one = render_with(1, integrator, &f);
        let channels = one.channels();
        // The radiance is the radiance of a plain render.
        let plain = {
            let scene = scene();
            let built = integrator.build(&scene, &Default::default()).unwrap();
            render(&scene, built.as_ref(), &f, &|_| {}).image
        };
        for (c, (channel, values)) in channels[..3].iter().enumerate() {
            let want: Vec<u32> = plain.pixels.iter().map(|p| p[c].to_bits()).collect();
            let got: Vec<u32> = values.iter().map(|v| v.to_bits()).collect();
            assert_eq!(got, want, "{name}: {channel}");
        }
        for threads in [2, 3] {
            let other = render_with(threads, integrator, &f);
            assert_eq!(
                bits(&other.channels()),
                bits(&channels),
                "{name}, {threads} threads"
            );
        }
        let mut cropped = f.clone();
        cropped.crop = Some([5, 9, 27, 30]);
        let crop = render_with(2, integrator, &cropped).channels();
        // An integrator that learns from the crop's own pixels renders the crop as the crop
        // alone, for any threads; the others render the full render's window.
        let learns = on_threads(1, || {
            let scene = scene();
            let built = integrator.build(&scene, &Default::default()).unwrap();
            learns_from_film(built.as_ref(), &scene, &cropped)
        });
        if learns {
            let alone = render_with(1, integrator, &cropped).channels();
            assert_eq!(bits(&crop), bits(&alone), "{name}: crop, 1 and 2 threads");
            continue;
        }
        for ((channel, c), (_, full)) in crop.iter().zip(&channels) {
            for y in 9..30usize {
                for x in 5..27usize {
                    assert_eq!(
                        c[(y - 9) * 22 + (x - 5)].to_bits(),
                        full[y * 32 + x].to_bits(),
                        "{name}: {channel} at ({x}, {y})"
                    );
                }
            }
        }
    }
}

#[test]
fn hair_ball_outputs_are_plausible() {
    let f = film(32, 32, 8, 2);
    let path = IntegratorDesc::all_for_tests()
        .into_iter()
        .find(|i| i.name() == "path")
        .unwrap();
    let channels = render_with(2, &path, &f).channels();
    let get = |name: &str| &channels.iter().find(|c| c.0 == name).unwrap().1;
    let (alpha, depth) = (get("A"), get("depth.Z"));
    let centre = 16 * 32 + 16;
    assert_eq!(alpha[centre], 1.0, "the ball covers the centre");
    assert_eq!(alpha[0], 0.0, "the corner sees only sky");
    assert!(
        alpha.iter().any(|a| *a > 0.0 && *a < 1.0),
        "no partial coverage"
    );
    for (p, (a, d)) in alpha.iter().zip(depth).enumerate() {
        assert!((0.0..=1.0).contains(a), "alpha {a} at {p}");
        if *a == 0.0 {
            assert_eq!(*d, f32::INFINITY, "depth where nothing was hit, at {p}");
        } else {
            // The camera is 4 from the centre of a ball of hair reaching out to radius 3.
            assert!(*d > 0.5 && *d < 7.0, "depth {d} at {p}");
        }
    }
    // The front of the ball is nearer than its centre.
    assert!(depth[centre] < 4.0, "{}", depth[centre]);
    let (tx, ty, tz) = (get("tangent.X"), get("tangent.Y"), get("tangent.Z"));
    for p in 0..alpha.len() {
        let length = (tx[p].powi(2) + ty[p].powi(2) + tz[p].powi(2)).sqrt();
        assert!(length <= 1.0 + 1e-5, "tangent length {length} at {p}");
        assert_eq!(length == 0.0, alpha[p] == 0.0, "tangent at {p}");
    }
    // Chiang fibers with the default melanin: energy conserving and absorbing.
    for name in ["albedo.R", "albedo.G", "albedo.B"] {
        let values = get(name);
        assert!(
            values.iter().all(|v| (0.0..=1.0 + 1e-4).contains(v)),
            "{name}"
        );
        assert!(values[centre] > 0.0, "{name}");
    }
    // Brighter colour channels of a brown fiber reflect more.
    assert!(get("albedo.R")[centre] > get("albedo.B")[centre]);
    for name in ["variance.R", "variance.G", "variance.B"] {
        assert!(
            get(name).iter().all(|v| *v >= 0.0 && v.is_finite()),
            "{name}"
        );
    }
}

/// What alpha's extra query costs: the time of one occlusion query per camera ray against the
/// time of the integrator's sample, measured interleaved pixel by pixel (so that other load on
/// the machine weighs on both alike) on `scenes/straight_venice.ron`. Prints the
/// ratios; run with `cargo test --release -p tress-tests --test integration -- --ignored
/// --nocapture outputs::`.
#[test]
#[ignore = "a measurement, not a check; needs ../shared/data"]
fn measure_the_cost_of_the_alpha_query() {
    shared_data("hair/straight.hair");
    let scene_file =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/straight_venice.ron");
    let desc = tress_loader::scene_desc::load(&scene_file).unwrap();
    let built = tress_loader::scene_desc::build(&desc, &scene_file, &Default::default()).unwrap();
    let scene = &built.scene;
    let (width, height) = (desc.film.width, desc.film.height);
    for name in ["path", "dual-mis"] {
        let integrator = IntegratorDesc::parse_arg(name)
            .unwrap()
            .build(scene, &Default::default())
            .unwrap();
        let (mut shading, mut occlusion, mut closest) =
            (Duration::ZERO, Duration::ZERO, Duration::ZERO);
        let (mut samples, mut occluded, mut hits) = (0u64, 0u64, 0u64);
        // Every other pixel of the whole film (hair and sky), 4 samples each.
        for y in (0..height).step_by(2) {
            for x in (0..width).step_by(2) {
                let rays: Vec<_> = (0..4u64)
                    .map(|s| camera_sample(&scene.camera, &desc.film, x, y, s))
                    .collect();
                let t0 = Instant::now();
                for (ray, sampler) in &rays {
                    std::hint::black_box(integrator.li(ray, scene, &mut sampler.clone()));
                }
                let t1 = Instant::now();
                for (ray, _) in &rays {
                    occluded += u64::from(std::hint::black_box(scene.occluded(ray)));
                }
                let t2 = Instant::now();
                for (ray, _) in &rays {
                    hits += u64::from(std::hint::black_box(scene.intersect(ray)).is_some());
                }
                let t3 = Instant::now();
                shading += t1 - t0;
                occlusion += t2 - t1;
                closest += t3 - t2;
                samples += rays.len() as u64;
            }
        }
        assert_eq!(occluded, hits, "both queries see the same geometry");
        let micros = |d: Duration| d.as_secs_f64() * 1e6 / samples as f64;
        let share = |d: Duration| 100.0 * d.as_secs_f64() / shading.as_secs_f64();
        eprintln!(
            "{name}: {samples} samples of {:.2} µs; occlusion query {:.3} µs = {:.2} %, \
             closest hit {:.3} µs = {:.2} %; {:.0} % of the camera rays hit",
            micros(shading),
            micros(occlusion),
            share(occlusion),
            micros(closest),
            share(closest),
            100.0 * hits as f64 / samples as f64
        );
    }
}
