//! What `tress render` writes: sample sums only on request, alpha and AOV layers, the header
//! (version, camera matrices, typed attributes) and the tone-mapped sRGB PNG.

use crate::common::*;
use tress_core::image_io::{read_exr_attributes, Attribute};
use tress_core::math::Vec3;

fn channel(p: &Pixels, name: &str) -> Vec<f32> {
    let bits = &p.channels.iter().find(|c| c.0 == name).unwrap().1;
    bits.iter().map(|b| f32::from_bits(*b)).collect()
}

#[test]
fn sample_sums_are_written_only_when_asked() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    // 15 spp: four sample blocks, the case that made the files grow.
    render_ok(&["--spp", "15", "--out", "plain.exr", "--quiet"], d);
    render_ok(
        &["--spp", "15", "--out", "sums.exr", "--sums", "--quiet"],
        d,
    );
    let (plain, sums) = (pixels(&d.join("plain.exr")), pixels(&d.join("sums.exr")));
    assert_eq!(channel_names(&plain), ["B", "G", "R"]);
    assert_eq!(
        sums.channels.len(),
        3 + 4 * 3 * 2,
        "{:?}",
        channel_names(&sums)
    );
    assert!(channel_names(&sums).contains(&"tress.sum003.Rlo"));
    // The pixels are the same either way.
    assert_eq!(plain.channels[..], sums.channels[..3]);
    assert_eq!(attribute(&d.join("plain.exr"), "tress:sums"), None);
    assert_eq!(
        attribute(&d.join("sums.exr"), "tress:sums").as_deref(),
        Some("dyadic-f64-blocks-2")
    );
    let size = |f: &str| std::fs::metadata(d.join(f)).unwrap().len();
    assert!(
        size("sums.exr") > 2 * size("plain.exr"),
        "{} vs {}",
        size("sums.exr"),
        size("plain.exr")
    );
    // Merging needs the sums, and says how to get them.
    render_ok(
        &[
            "--spp",
            "15",
            "--spp-offset",
            "15",
            "--out",
            "more.exr",
            "--quiet",
        ],
        d,
    );
    let o = tress(&["merge", "out.exr", "plain.exr", "more.exr"], d);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("plain.exr") && err.contains("tress render --sums"),
        "{err}"
    );
    assert!(!d.join("out.exr").exists());
}

#[test]
fn alpha_and_aov_layers_are_written_and_independent_of_threads_and_crop() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let outputs = [
        "--alpha",
        "--aov",
        "depth,albedo",
        "--aov",
        "tangent,variance",
    ];
    let run = |out: &str, extra: &[&str]| {
        render_ok(
            &[&outputs[..], &["--out", out, "--quiet"], extra].concat(),
            d,
        );
        pixels(&d.join(out))
    };
    let one = run("one.exr", &["--threads", "1"]);
    assert_eq!(channel_names(&one), EVERY_OUTPUT_CHANNEL);
    assert_eq!(run("two.exr", &["--threads", "2"]), one);
    // The radiance is the plain render's.
    render_ok(&["--out", "plain.exr", "--quiet"], d);
    assert_eq!(
        pixels(&d.join("plain.exr")).channels[..],
        one.channels[1..4]
    );
    let crop = run("crop.exr", &["--crop", "3,4,17,15", "--threads", "2"]);
    for ((name, c), (_, full)) in crop.channels.iter().zip(&one.channels) {
        for y in 4..15usize {
            for x in 3..17usize {
                assert_eq!(
                    c[(y - 4) * 14 + (x - 3)],
                    full[y * 24 + x],
                    "{name} ({x}, {y})"
                );
            }
        }
    }
    // Coverage: the hair ball fills the middle, the sky the corners; depth is +inf where
    // nothing was hit.
    let (alpha, depth) = (channel(&one, "A"), channel(&one, "depth.Z"));
    assert_eq!(alpha[10 * 24 + 12], 1.0);
    assert_eq!(alpha[0], 0.0);
    for (a, z) in alpha.iter().zip(&depth) {
        assert!((0.0..=1.0).contains(a));
        assert_eq!(*a == 0.0, *z == f32::INFINITY, "alpha {a}, depth {z}");
    }
    // Bad lists are refused before rendering.
    let o = tress(
        &["render", "scene.ron", "--aov", "depth,normal", "--quiet"],
        d,
    );
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("unknown AOV 'normal'") && err.contains("depth, tangent, albedo, variance"),
        "{err}"
    );
}

#[test]
fn the_header_records_version_camera_and_typed_numbers() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    render_ok(&["--out", "img.exr", "--quiet"], d);
    let attributes = read_exr_attributes(d.join("img.exr")).unwrap();
    let get = |n: &str| {
        attributes
            .iter()
            .find(|a| a.0 == n)
            .map(|a| a.1.clone())
            .unwrap_or_else(|| panic!("no {n}"))
    };
    assert_eq!(
        get("software"),
        Attribute::Text(format!("tress {}", env!("CARGO_PKG_VERSION")))
    );
    assert_eq!(get("tress:spp"), Attribute::Int(6));
    assert_eq!(get("tress:spp_offset"), Attribute::Int(0));
    assert_eq!(get("tress:seed"), Attribute::Int(3));
    assert!(matches!(get("tress:render_time_s"), Attribute::Double(t) if t > 0.0));
    assert!(matches!(get("tress:rays"), Attribute::Double(r) if r >= 24.0 * 20.0 * 6.0));
    assert_eq!(get("tress:dropped_samples"), Attribute::Double(0.0));
    assert!(matches!(get("tress:integrator"), Attribute::Text(t) if t.contains("Path")));
    // The scene's camera: at (0, 0, 4) looking at the origin, 35° vertical field of view, on
    // a 24x20 film.
    let Attribute::Matrix(to_camera) = get("worldToCamera") else {
        panic!("worldToCamera is not a matrix")
    };
    let Attribute::Matrix(to_ndc) = get("worldToNDC") else {
        panic!("worldToNDC is not a matrix")
    };
    let close = |a: Vec3, b: Vec3| (a - b).length() < 1e-5;
    assert!(close(
        to_camera.transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 0.0, 4.0)
    ));
    assert!(close(
        to_camera.transform_point3(Vec3::new(0.0, 0.0, 4.0)),
        Vec3::ZERO
    ));
    assert!(close(
        to_camera.transform_point3(Vec3::X),
        Vec3::new(1.0, 0.0, 4.0)
    ));
    assert!(close(
        to_ndc.project_point3(Vec3::ZERO).truncate().extend(0.0),
        Vec3::new(0.5, 0.5, 0.0)
    ));
    // A point on the upper edge of the view, 4 ahead: NDC y = 0.
    let top = Vec3::new(0.0, 4.0 * 17.5f32.to_radians().tan(), 0.0);
    assert!(to_ndc.project_point3(top).y.abs() < 1e-5);
}

#[test]
fn previews_are_tone_mapped_as_asked_and_marked_srgb() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    render_ok(&["--out", "filmic.exr", "--quiet"], d);
    render_ok(&["--out", "clamp.exr", "--tonemap", "clamp", "--quiet"], d);
    let (filmic, clamp) = (
        std::fs::read(d.join("filmic.png")).unwrap(),
        std::fs::read(d.join("clamp.png")).unwrap(),
    );
    assert_ne!(filmic, clamp);
    for png in [&filmic, &clamp] {
        // The sRGB chunk: length 1, type, rendering intent 0 (perceptual).
        let chunk = [0u8, 0, 0, 1, b's', b'R', b'G', b'B', 0];
        assert!(
            png.windows(chunk.len()).any(|w| w == chunk),
            "no sRGB chunk"
        );
    }
    assert_eq!(pixels(&d.join("filmic.exr")), pixels(&d.join("clamp.exr")));
    let o = tress(&["render", "scene.ron", "--tonemap", "aces", "--quiet"], d);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("clamp or filmic"), "{}", stderr(&o));
}
