//! Hardening of the `tress` binary: every bad input fails with a message that names the file and
//! the problem and leaves no output behind; long renders stop at a time limit or on Ctrl-C with
//! a valid image of the samples finished; waves, partial images and sample-range passes do not
//! change the image by a single bit.

use crate::common::*;
use std::path::Path;
use std::time::{Duration, Instant};

/// Runs `tress args` in `dir` and checks that it fails cleanly: exit status 1, the message holds
/// every string of `expect`, no panic, and no file was added to `dir`.
fn assert_fails_in(dir: &Path, args: &[&str], expect: &[&str]) {
    let before = files_in(dir);
    let o = tress(args, dir);
    let err = stderr(&o);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{args:?}: expected failure: {err}"
    );
    for e in expect {
        assert!(err.contains(e), "{args:?}: message lacks '{e}': {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(files_in(dir), before, "{args:?}: output left behind");
}

/// Writes `dir/scene.ron`: [`SCENE`] with `source` as its hair.
fn write_hair_scene(dir: &Path, source: &str) {
    let text = SCENE.replace(
        "Procedural(style: Ball, strands: 300, radius: 0.01)",
        source,
    );
    std::fs::write(dir.join("scene.ron"), text).unwrap();
}

/// A scene whose only hair object is `source`, rendered and inspected: both must fail.
fn assert_bad_hair(dir: &Path, source: &str, expect: &[&str]) {
    write_hair_scene(dir, source);
    let mut e = expect.to_vec();
    e.push("scene.ron");
    assert_fails_in(
        dir,
        &["render", "scene.ron", "--out", "o.exr", "--quiet"],
        &e,
    );
    assert_fails_in(dir, &["info", "scene.ron"], &e);
}

/// Each of `cases` (file name, bytes, expected message) in turn as the only hair file: it must
/// fail with the expected message and the file's name.
fn assert_bad_hair_files(dir: &Path, cases: Vec<(&str, Vec<u8>, &[&str])>) {
    for (name, bytes, expect) in cases {
        std::fs::write(dir.join(name), bytes).unwrap();
        let mut e = expect.to_vec();
        e.push(name);
        assert_bad_hair(dir, &format!("File(\"{name}\")"), &e);
        std::fs::remove_file(dir.join(name)).unwrap();
    }
}

fn write_hair(
    magic: &[u8; 4],
    strands: u32,
    points: &[[f32; 3]],
    segments: Option<&[u16]>,
    thickness: Option<&[f32]>,
    default_thickness: f32,
) -> Vec<u8> {
    let flags = 2 | u32::from(segments.is_some()) | if thickness.is_some() { 4 } else { 0 };
    let mut b = magic.to_vec();
    for v in [strands, points.len() as u32, flags, 2] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in [default_thickness, 0.5, 0.1, 0.2, 0.3] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.resize(128, 0);
    for s in segments.unwrap_or(&[]) {
        b.extend_from_slice(&s.to_le_bytes());
    }
    for v in points.iter().flatten().chain(thickness.unwrap_or(&[])) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b
}

fn nine_points() -> Vec<[f32; 3]> {
    (0..9)
        .map(|i| [0.1 * i as f32, 0.05 * i as f32, 0.02])
        .collect()
}

#[test]
fn bad_hair_files_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let segs: &[u16] = &[1, 3, 2];
    let good = write_hair(
        b"HAIR",
        3,
        &nine_points(),
        Some(segs),
        Some(&[0.01; 9]),
        0.01,
    );
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        ("header.hair", good[..50].to_vec(), &["truncated header"]),
        (
            "arrays.hair",
            good[..good.len() - 20].to_vec(),
            &["truncated"],
        ),
        ("empty.hair", Vec::new(), &["truncated header"]),
        (
            "magic.hair",
            write_hair(b"RIAH", 3, &nine_points(), Some(segs), None, 0.01),
            &["not a HAIR file"],
        ),
        (
            "nostrands.hair",
            write_hair(b"HAIR", 0, &[], None, None, 0.01),
            &["no strands"],
        ),
        (
            "nan.hair",
            {
                let mut p = nine_points();
                p[4][1] = f32::NAN;
                write_hair(b"HAIR", 3, &p, Some(segs), None, 0.01)
            },
            &["non-finite"],
        ),
        (
            "inf.hair",
            {
                let mut p = nine_points();
                p[8][2] = f32::NEG_INFINITY;
                write_hair(b"HAIR", 3, &p, Some(segs), None, 0.01)
            },
            &["non-finite"],
        ),
        (
            "negative.hair",
            {
                let mut t = [0.01f32; 9];
                t[5] = -0.01;
                write_hair(b"HAIR", 3, &nine_points(), Some(segs), Some(&t), 0.01)
            },
            &["radius", "positive"],
        ),
        (
            "zero.hair",
            write_hair(b"HAIR", 3, &nine_points(), Some(segs), None, 0.0),
            &["radius 0"],
        ),
        (
            "nan_radius.hair",
            write_hair(b"HAIR", 3, &nine_points(), Some(segs), None, f32::NAN),
            &["radius NaN"],
        ),
    ];
    assert_bad_hair_files(d, cases);
    // Header counts far beyond the file: refused from the header, before allocating.
    for (at, expect) in [(4, "strands but only"), (8, "truncated")] {
        let mut huge = good.clone();
        huge[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        std::fs::write(d.join("huge.hair"), huge).unwrap();
        assert_bad_hair(d, "File(\"huge.hair\")", &["huge.hair", expect]);
    }
    // Segment counts that disagree with the points.
    let bad_segments = write_hair(b"HAIR", 3, &nine_points(), Some(&[1, 3, 9]), None, 0.01);
    std::fs::write(d.join("segs.hair"), bad_segments).unwrap();
    assert_bad_hair(d, "File(\"segs.hair\")", &["segs.hair", "header says 9"]);
    std::fs::remove_file(d.join("segs.hair")).unwrap();
    // A missing file and a folder in place of a file.
    assert_bad_hair(d, "File(\"absent.hair\")", &["absent.hair"]);
    std::fs::create_dir(d.join("folder.hair")).unwrap();
    assert_bad_hair(d, "File(\"folder.hair\")", &["folder.hair"]);
    std::fs::write(d.join("model.obj"), "").unwrap();
    assert_bad_hair(d, "File(\"model.obj\")", &["model.obj", "extension"]);
}

fn write_tfx(version: f32, strands: u32, per: u32, thickness: Option<&[f32]>) -> Vec<u8> {
    let mut b = vec![0u8; 160];
    b[0..4].copy_from_slice(&version.to_le_bytes());
    b[4..8].copy_from_slice(&strands.to_le_bytes());
    b[8..12].copy_from_slice(&per.to_le_bytes());
    b[12..16].copy_from_slice(&160u32.to_le_bytes());
    for i in 0..strands * per {
        for v in [0.1 * i as f32, 0.05 * (i % per) as f32, 0.0, 1.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    if let Some(t) = thickness {
        let at = b.len() as u32;
        b[24..28].copy_from_slice(&at.to_le_bytes());
        t.iter().for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
    }
    b
}

#[test]
fn bad_tressfx_files_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good = write_tfx(4.0, 2, 4, Some(&[1.0, 0.5]));
    let set = |b: &[u8], at: usize, v: [u8; 4]| {
        let mut b = b.to_vec();
        b[at..at + 4].copy_from_slice(&v);
        b
    };
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        ("header.tfx", good[..100].to_vec(), &["truncated header"]),
        (
            "positions.tfx",
            write_tfx(4.0, 2, 4, None)[..200].to_vec(),
            &["truncated", "vertex positions"],
        ),
        (
            "version.tfx",
            set(&good, 0, f32::NAN.to_le_bytes()),
            &["not a TressFX file"],
        ),
        (
            "negative_version.tfx",
            set(&good, 0, (-3.0f32).to_le_bytes()),
            &["not a TressFX file"],
        ),
        (
            "strands.tfx",
            set(&good, 4, u32::MAX.to_le_bytes()),
            &["vertices"],
        ),
        (
            "per_strand.tfx",
            set(&good, 8, u32::MAX.to_le_bytes()),
            &["vertices"],
        ),
        (
            "offset.tfx",
            set(&good, 12, u32::MAX.to_le_bytes()),
            &["do not fit"],
        ),
        (
            "no_positions.tfx",
            set(&good, 12, [0; 4]),
            &["no vertex positions"],
        ),
        ("nostrands.tfx", write_tfx(4.0, 0, 4, None), &["no strands"]),
        (
            "nan.tfx",
            set(&good, 160 + 16 * 3 + 4, f32::NAN.to_le_bytes()),
            &["non-finite"],
        ),
        (
            "inf.tfx",
            set(&good, 160 + 16 * 6, f32::INFINITY.to_le_bytes()),
            &["non-finite"],
        ),
        (
            "zero_thickness.tfx",
            write_tfx(4.0, 2, 4, Some(&[1.0, 0.0])),
            &["radius 0"],
        ),
        (
            "negative_thickness.tfx",
            write_tfx(4.0, 2, 4, Some(&[-1.0, 1.0])),
            &["radius", "positive"],
        ),
    ];
    assert_bad_hair_files(d, cases);
    std::fs::write(d.join("good.tfx"), &good).unwrap();
    assert_bad_hair(
        d,
        "Tfx(path: \"good.tfx\", radius: -0.01)",
        &["good.tfx", "radius"],
    );
    assert_bad_hair(
        d,
        "Tfx(path: \"good.tfx\", radius: 0)",
        &["good.tfx", "radius"],
    );
}

/// A scene edit that must fail with a message holding `expect`.
fn assert_bad_scene(text: &str, expect: &[&str]) {
    let (dir, _) = scene_dir(text);
    let mut e = expect.to_vec();
    e.push("scene.ron");
    assert_fails_in(
        dir.path(),
        &["render", "scene.ron", "--out", "o.exr", "--quiet"],
        &e,
    );
}

#[test]
fn bad_scenes_give_clear_errors() {
    // Syntax and types (beyond cli.rs): unterminated text, unknown variants, a bad crop shape.
    assert_bad_scene(&SCENE[..SCENE.len() / 2], &["scene.ron:"]);
    assert_bad_scene("", &["scene.ron:1:"]);
    // (text of SCENE, its replacement, what the message must say)
    let edits: [(&str, &str, &[&str]); 42] = [
        (
            r#""grey": Diffuse"#,
            r#""hair": Diffuse(albedo: (0.5, 0.5, 0.5)), "grey": Diffuse"#,
            &["\"hair\" is defined twice"],
        ),
        // Films that would not fit in memory (they allocated until the process aborted).
        (
            "width: 24, height: 20",
            "width: 65536, height: 65536",
            &["GiB", "TRESS_MEMORY_LIMIT_GIB"],
        ),
        (
            "width: 24, height: 20",
            "width: 20000, height: 20000",
            &["62.6 GiB", "tress farm"],
        ),
        // Ray-producing quantities that passed validation and made Embree abort.
        (
            "look_from: (0, 0, 4)",
            "look_from: (0, 0, 1.9e18)",
            &["camera positions", "1e16"],
        ),
        ("fov: 35", "fov: 35, lens_radius: 3e38", &["lens_radius"]),
        (
            "fov: 35",
            "fov: 35, lens_radius: 0.5, focus_distance: Some(NaN)",
            &["focus_distance"],
        ),
        (
            "fov: 35",
            "fov: 35, lens_radius: 0.5, focus_distance: Some(inf)",
            &["focus_distance"],
        ),
        (
            "fov: 35",
            "fov: 35, focus_distance: Some(0)",
            &["focus_distance"],
        ),
        (
            "fov: 35",
            "fov: 35, focus_distance: Some(-5)",
            &["focus_distance"],
        ),
        (
            "direction: (0, -1, -1)",
            "direction: (0, 0, 0)",
            &["direction", "non-zero"],
        ),
        ("Path(max_depth: 20)", "Bogus()", &["Bogus"]),
        ("Sky()", "Moon()", &["Moon"]),
        ("seed: 3", "seed: 3, crop: Some(1, 2)", &["crop"]),
        ("spp: 6", "spp: 4.5", &["spp"]),
        ("width: 24", "width: 99999999999", &["width"]),
        // Out-of-range values.
        ("height: 20", "height: 0", &["film", "empty"]),
        ("width: 24", "width: 70000", &["film", "exceeds"]),
        ("spp: 6", "spp: 0", &["spp must be at least 1"]),
        (
            "seed: 3",
            "seed: 3, crop: Some(0, 0, 30, 10)",
            &["crop window"],
        ),
        ("fov: 35", "fov: 0", &["fov"]),
        ("fov: 35", "fov: -20", &["fov"]),
        ("fov: 35", "fov: 35, lens_radius: -1", &["lens_radius"]),
        ("look_at: (0, 0, 0)", "look_at: (0, 0, 4)", &["look_at"]),
        ("beta_n: 0.3", "beta_n: -0.1", &["beta_n"]),
        (
            "Chiang(beta_m: 0.3, beta_n: 0.3, pigment: Melanin(eumelanin: 1.0))",
            "DEon(longitudinal_roughness: 1.5)",
            &["longitudinal_roughness"],
        ),
        (
            "Melanin(eumelanin: 1.0)",
            "Melanin(eumelanin: -1.0)",
            &["eumelanin"],
        ),
        (
            "Melanin(eumelanin: 1.0)",
            "SigmaA(0.2, -0.1, 0.3)",
            &["sigma_a"],
        ),
        (
            "albedo: (0.5, 0.5, 0.5)",
            "albedo: (0.5, -0.5, 0.5)",
            &["albedo"],
        ),
        (
            "albedo: (0.5, 0.5, 0.5)",
            "albedo: (1.5, 0.5, 0.5)",
            &["albedo"],
        ),
        ("radius: 1,", "radius: -1,", &["radius"]),
        (
            "angular_radius: 0.5",
            "angular_radius: 95",
            &["angular_radius"],
        ),
        (
            "irradiance: (2, 2, 2)",
            "irradiance: (2, -2, 2)",
            &["irradiance"],
        ),
        ("Sky()", "Sky(scale: -1)", &["scale"]),
        // Finite values that overflow once scaled or converted (the image came out black).
        (
            "Sky()",
            "Sky(scale: 1e37)",
            &["built-in sky", "is beyond 1e30"],
        ),
        (
            "irradiance: (2, 2, 2)",
            "irradiance: (3e38, 3e38, 3e38)",
            &["irradiance", "beyond 1e30"],
        ),
        // Finite products that overflowed along paths: samples dropped, the image biased dark.
        (
            "Sky()",
            "Sky(scale: 1e35)",
            &["built-in sky", "is beyond 1e30", "overflows f32"],
        ),
        (
            "irradiance: (2, 2, 2), angular_radius: 0.5",
            "irradiance: (1e26, 1e26, 1e26), angular_radius: 0.1",
            &["irradiance", "a radiance of", "beyond 1e30"],
        ),
        (
            "Sky()",
            "Constant(radiance: (1e31, 1, 1))",
            &["radiance", "is beyond 1e30", "scale the lights down"],
        ),
        ("Sky()", "Constant(radiance: (1, 1, -1))", &["radiance"]),
        ("strands: 300", "strands: 0", &["strands"]),
        (
            "material: \"hair\")",
            "material: \"hair\", options: (strand_fraction: 0))",
            &["strand_fraction"],
        ),
        // Missing referenced files.
        (
            "Sphere(center: (0, -2, 0), radius: 1, material: \"grey\")",
            "Mesh(file: \"head.obj\", material: \"grey\")",
            &["head.obj"],
        ),
    ];
    for (from, to, expect) in edits {
        assert!(SCENE.contains(from), "{from}");
        assert_bad_scene(&SCENE.replace(from, to), expect);
    }
}

/// Writes an RGB EXR of `w`×`h` (ZIP compression) for the environment-map cases.
fn write_env_exr(path: &Path, w: u32, h: u32) {
    let img = tress_core::Image::from_fn(w, h, |_, _| tress_core::Rgb::splat(0.5));
    to_file(path, |o| tress_core::image_io::write_exr(o, &img, &[])).unwrap();
}

#[test]
fn unreadable_and_unsupported_images_give_clear_errors() {
    let env = |file: &str| SCENE.replace("Sky()", &format!("Environment(file: \"{file}\")"));
    let (dir, _) = scene_dir(&env("map.exr"));
    let d = dir.path();
    let render = ["render", "scene.ron", "--out", "o.exr", "--quiet"];
    // An EXR compression the decoder does not support (HTJ2K): named, with a remedy. A ZIP
    // file of one 16-line block is relabelled, which keeps its chunk table valid.
    write_env_exr(&d.join("map.exr"), 16, 16);
    let mut bytes = std::fs::read(d.join("map.exr")).unwrap();
    let key = b"compression\0compression\0\x01\0\0\0";
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len();
    assert_eq!(bytes[at], 3, "expected ZIP compression");
    bytes[at] = 11;
    std::fs::write(d.join("map.exr"), &bytes).unwrap();
    assert_fails_in(d, &render, &["map.exr", "HTJ2K32", "re-save"]);
    // Truncated and garbage images.
    write_env_exr(&d.join("map.exr"), 64, 64);
    let bytes = std::fs::read(d.join("map.exr")).unwrap();
    std::fs::write(d.join("map.exr"), &bytes[..bytes.len() / 2]).unwrap();
    assert_fails_in(d, &render, &["map.exr", "corrupt or truncated"]);
    std::fs::write(d.join("map.exr"), b"definitely not an image").unwrap();
    assert_fails_in(d, &render, &["map.exr", "OpenEXR"]);
    std::fs::remove_file(d.join("map.exr")).unwrap();
    // A folder where an image should be, an unsupported format, a truncated HDR.
    std::fs::write(d.join("scene.ron"), env("maps")).unwrap();
    std::fs::create_dir(d.join("maps")).unwrap();
    assert_fails_in(d, &render, &["maps", "unsupported image format"]);
    std::fs::write(d.join("scene.ron"), env("folder.hdr")).unwrap();
    std::fs::create_dir(d.join("folder.hdr")).unwrap();
    assert_fails_in(d, &render, &["folder.hdr"]);
    std::fs::write(d.join("scene.ron"), env("sky.hdr")).unwrap();
    std::fs::write(
        d.join("sky.hdr"),
        b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 64 +X 64\n\x02\x02\x00",
    )
    .unwrap();
    assert_fails_in(d, &render, &["sky.hdr", "Radiance HDR"]);
    // A well-formed map stored bottom-up or mirrored: the orientation is named.
    std::fs::write(
        d.join("sky.hdr"),
        b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n+Y 2 -X 2\n\x80\x80\x80\x81\x80\x80\x80\x81\x80\x80\x80\x81\x80\x80\x80\x81",
    )
    .unwrap();
    assert_fails_in(
        d,
        &render,
        &["sky.hdr", "`+Y 2 -X 2`", "-Y height +X width"],
    );
    // The scene file itself: not UTF-8, a folder.
    std::fs::write(d.join("scene.ron"), [0xff, 0xfe, 0x00, 0x28]).unwrap();
    assert_fails_in(d, &render, &["scene.ron"]);
    std::fs::remove_file(d.join("scene.ron")).unwrap();
    std::fs::create_dir(d.join("scene.ron")).unwrap();
    assert_fails_in(d, &render, &["scene.ron"]);
}

#[test]
fn bad_arguments_give_clear_errors() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let run = |extra: &[&str], expect: &[&str]| {
        let mut args = vec!["render", "scene.ron", "--out", "o.exr", "--quiet"];
        args.extend_from_slice(extra);
        let before = files_in(d);
        let o = tress(&args, d);
        let err = stderr(&o);
        assert!(!o.status.success(), "{extra:?}: expected failure");
        assert!(!err.contains("panicked"), "{err}");
        for e in expect {
            assert!(err.contains(e), "{extra:?}: message lacks '{e}': {err}");
        }
        assert_eq!(files_in(d), before, "{extra:?}: output left behind");
    };
    run(&["--spp", "0"], &["scene.ron", "spp must be at least 1"]);
    run(&["--spp", "-3"], &["'-3'"]);
    run(
        &["--spp-offset", "18446744073709551615"],
        &["--spp-offset", "exceeds"],
    );
    run(&["--time-limit", "-1"], &["--time-limit", "seconds"]);
    run(&["--time-limit", "NaN"], &["--time-limit", "seconds"]);
    run(&["--time-limit", "1e300"], &["--time-limit", "more than"]);
    // Refused before rendering: they wrote the EXR, then failed on the PNG.
    run(&["--exposure", "NaN"], &["--exposure", "stops"]);
    run(&["--exposure", "inf"], &["--exposure", "stops"]);
    run(&["--crop", "5,5,5,9"], &["scene.ron", "crop window"]);
    run(&["--crop", "1,2,3"], &["--crop", "x0,y0,x1,y1"]);
    run(&["--integrator", "Path(max_depth: -1)"], &["max_depth"]);
    // The furnace tool: a step too small looped forever growing memory; no samples printed NaN.
    let model = "Chiang(beta_m: 0.3, beta_n: 0.3)";
    for (args, expect) in [
        (["--step", "1e-30"], "--step"),
        (["--samples", "0"], "--samples"),
        (["--samples", "1"], "--samples"),
    ] {
        let o = tress(
            &[&["bcsdf", "furnace", "--model", model], &args[..]].concat(),
            d,
        );
        assert!(
            o.status.code() == Some(1) && stderr(&o).contains(expect),
            "{args:?}: {}",
            stderr(&o)
        );
    }
    let o = tress(&["render", "scene.ron", "--out", "o.png", "--quiet"], d);
    assert!(
        !o.status.success() && stderr(&o).contains("o.png"),
        "{}",
        stderr(&o)
    );
    // An output folder that cannot be created.
    std::fs::write(d.join("file"), "").unwrap();
    let o = tress(
        &["render", "scene.ron", "--out", "file/o.exr", "--quiet"],
        d,
    );
    assert!(
        !o.status.success() && stderr(&o).contains("file"),
        "{}",
        stderr(&o)
    );
    assert_eq!(files_in(d), ["file", "scene.ron"]);
}

#[test]
fn time_limit_stops_after_the_wave_that_crosses_it() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let err = render_ok(
        &["--spp", "64", "--time-limit", "0", "--out", "limited.exr"],
        d,
    );
    assert!(err.contains("1 of 64 spp (time limit"), "{err}");
    let path = d.join("limited.exr");
    assert_eq!(attribute(&path, "tress:spp").as_deref(), Some("1"));
    assert_eq!(
        attribute(&path, "tress:spp_requested").as_deref(),
        Some("64")
    );
    assert_eq!(
        attribute(&path, "tress:status").as_deref(),
        Some("time-limit")
    );
    // The image is exactly the one-sample render.
    render_ok(&["--spp", "1", "--out", "one.exr", "--quiet"], d);
    assert_eq!(pixels(&path), pixels(&d.join("one.exr")));
    // A generous limit changes nothing.
    render_ok(&["--time-limit", "600", "--out", "all.exr", "--quiet"], d);
    assert_eq!(
        attribute(&d.join("all.exr"), "tress:status").as_deref(),
        Some("complete")
    );
    assert_eq!(
        attribute(&d.join("all.exr"), "tress:spp").as_deref(),
        Some("6")
    );
}

/// An integrator's training (a radiance cache's) is render time: `--time-limit` counts it, and
/// SIGTERM stops it within a chunk of training paths, writing nothing.
#[cfg(unix)]
#[test]
fn training_counts_toward_the_time_limit_and_stops_on_a_signal() {
    use std::process::{Command, Stdio};
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    // About a second of training on an idle machine; all 64 samples take a tenth of it.
    let cache = "RadianceCache(training_spp: 512)";
    let err = render_ok(
        &["--integrator", cache, "--spp", "64", "--time-limit", "0.2"],
        d,
    );
    assert!(err.contains("of 64 spp (time limit"), "{err}");
    // A million training paths per pixel would take hours: a signal must stop them.
    let mut child = Command::new(env!("CARGO_BIN_EXE_tress"))
        .args(["render", "scene.ron", "--quiet", "--out", "never.exr"])
        .args(["--integrator", "RadianceCache(training_spp: 4096)"])
        .current_dir(d)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let kill = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let sent = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            sent.elapsed() < Duration::from_secs(10),
            "training did not stop"
        );
        std::thread::sleep(Duration::from_millis(5));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(143), "{err}");
    assert!(err.contains("nothing written"), "{err}");
    assert!(!d.join("never.exr").exists());
}

/// A crop learns from its own pixels: a 4×4 window of a 4096² film trains as 16 pixels do
/// (the whole film's training, 2^24 pixels × 256 paths for each integrator, would take days).
/// The deadline turns a whole-film training into a failure, not a hang.
#[test]
fn a_crop_trains_on_its_own_pixels() {
    use std::process::{Command, Stdio};
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    for (integrator, out) in [
        ("RadianceCache(training_spp: 256)", "cache.exr"),
        ("Guided(training_spp: 256)", "guided.exr"),
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_tress"))
            .args([
                "render",
                "scene.ron",
                "--quiet",
                "--out",
                out,
                "--spp",
                "16",
            ])
            .args([
                "--width",
                "4096",
                "--height",
                "4096",
                "--crop",
                "2046,2046,2050,2050",
            ])
            .args(["--integrator", integrator])
            .current_dir(d)
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let started = Instant::now();
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            if started.elapsed() > Duration::from_secs(120) {
                child.kill().unwrap();
                panic!("{integrator}: a 4x4 crop still training after 120 s");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        assert!(status.success(), "{integrator}: {status}");
        let image = pixels(&d.join(out));
        assert_eq!(image.data_window, ([2046, 2046], [4, 4]), "{integrator}");
        assert_eq!(image.display, [4096, 4096], "{integrator}");
    }
}

#[test]
fn waves_and_partial_images_do_not_change_the_image() {
    let (dir, scene) = scene_dir(SCENE);
    let d = dir.path();
    for (out, extra) in [("plain.exr", None), ("partial.exr", Some("--partial"))] {
        let mut args = vec!["--spp", "13", "--out", out, "--quiet"];
        args.extend(extra);
        render_ok(&args, d);
    }
    let plain = pixels(&d.join("plain.exr"));
    assert_eq!(plain, pixels(&d.join("partial.exr")));
    assert_eq!(
        files_in(d),
        [
            "partial.exr",
            "partial.png",
            "plain.exr",
            "plain.png",
            "scene.ron"
        ]
    );
    // The binary renders in waves (1, 2, 4, 8, 13 samples); the library call renders all 13 in
    // one pass. Same bits.
    let mut desc = tress_loader::scene_desc::load(&scene).unwrap();
    desc.film.spp = 13;
    let built = tress_loader::scene_desc::build(&desc, &scene, &Default::default()).unwrap();
    let integrator = desc
        .integrator
        .build(&built.scene, &Default::default())
        .unwrap();
    let once = tress_core::render::render(&built.scene, integrator.as_ref(), &desc.film, &|_| {});
    let (waves, _) = tress_core::image_io::read_exr(d.join("plain.exr")).unwrap();
    assert!(once.image.mean() > 0.0);
    assert_eq!(waves.pixels.len(), once.image.pixels.len());
    for (a, b) in waves.pixels.iter().zip(&once.image.pixels) {
        assert_eq!(
            a.to_array().map(f32::to_bits),
            b.to_array().map(f32::to_bits)
        );
    }
    // The PNG preview can be left out.
    render_ok(&["--out", "bare.exr", "--no-preview", "--quiet"], d);
    assert!(d.join("bare.exr").exists() && !d.join("bare.png").exists());
}

#[test]
fn sample_range_passes_merge_into_the_single_render() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let render = |out: &str, offset: &str, spp: &str| {
        render_ok(
            &[
                "--spp-offset",
                offset,
                "--spp",
                spp,
                "--out",
                out,
                "--sums",
                "--quiet",
            ],
            d,
        );
    };
    render("whole.exr", "0", "12");
    render("a.exr", "0", "5");
    render("b.exr", "5", "2");
    render("c.exr", "7", "5");
    assert_eq!(
        attribute(&d.join("c.exr"), "tress:spp_offset").as_deref(),
        Some("7")
    );
    // Any order of arguments; merging a merge works too.
    let merge = |args: &[&str]| {
        let mut a = vec!["merge"];
        a.extend_from_slice(args);
        a.push("--quiet");
        let o = tress(&a, d);
        assert!(o.status.success(), "{}", stderr(&o));
    };
    merge(&["m1.exr", "c.exr", "a.exr", "b.exr", "--sums"]);
    merge(&["ab.exr", "a.exr", "b.exr", "--sums"]);
    merge(&["m2.exr", "ab.exr", "c.exr", "--expect-spp", "12", "--sums"]);
    let whole = pixels(&d.join("whole.exr"));
    assert_eq!(
        whole.channels.len(),
        3 + 6 * 2,
        "12 samples = blocks [0, 8) and [8, 12)"
    );
    assert_eq!(pixels(&d.join("m1.exr")), whole);
    assert_eq!(pixels(&d.join("m2.exr")), whole);
    assert_eq!(
        attribute(&d.join("m2.exr"), "tress:spp").as_deref(),
        Some("12")
    );
    // Samples 5..7 alone differ from 0..2: the offset really moves the seed stream.
    render("first2.exr", "0", "2");
    assert_ne!(
        pixels(&d.join("b.exr")).channels,
        pixels(&d.join("first2.exr")).channels
    );
}

/// Sends `signal` to a render in progress: it stops promptly, writes the image of the waves it
/// finished, says so, and exits with 128 + the signal's number, as shells report it.
#[cfg(unix)]
fn signal_writes_the_finished_samples_and_exits_cleanly(signal: &str, exit_code: i32) {
    use std::process::{Command, Stdio};
    let (dir, _) = scene_dir(&SCENE.replace("width: 24, height: 20", "width: 8, height: 8"));
    let d = dir.path();
    let out = d.join("slow.exr");
    let mut child = Command::new(env!("CARGO_BIN_EXE_tress"))
        .args([
            "render",
            "scene.ron",
            "--spp",
            "1000000000",
            "--partial",
            "--quiet",
        ])
        .args(["--out", "slow.exr", "--threads", "2"])
        .current_dir(d)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The first partial image appears after the first wave.
    let t0 = Instant::now();
    while !out.exists() {
        assert!(t0.elapsed() < Duration::from_secs(60), "no partial image");
        std::thread::sleep(Duration::from_millis(5));
    }
    let kill = Command::new("kill")
        .args([&format!("-{signal}"), &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let sent = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(sent.elapsed() < Duration::from_secs(20), "did not stop");
        std::thread::sleep(Duration::from_millis(5));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(exit_code), "SIG{signal}: {err}");
    assert!(
        err.contains("interrupted") && err.contains("wrote slow.exr"),
        "{err}"
    );
    assert!(!err.contains("panicked") && !err.contains("error"), "{err}");
    assert_eq!(
        attribute(&out, "tress:status").as_deref(),
        Some("interrupted")
    );
    let spp = attribute(&out, "tress:spp").unwrap();
    let n: u64 = spp.parse().unwrap();
    assert!(n.is_power_of_two() && n < 1_000_000_000, "{spp}");
    assert_eq!(
        files_in(d),
        ["scene.ron", "slow.exr", "slow.png"],
        "temporary files left"
    );
    // What was written is exactly the render of the samples it reports.
    render_ok(&["--spp", &spp, "--out", "same.exr", "--quiet"], d);
    assert_eq!(pixels(&out), pixels(&d.join("same.exr")));
}

#[cfg(unix)]
#[test]
fn ctrl_c_writes_the_finished_samples_and_exits_cleanly() {
    signal_writes_the_finished_samples_and_exits_cleanly("INT", 130);
}

/// Render farms stop jobs with SIGTERM: it must behave as Ctrl-C does.
#[cfg(unix)]
#[test]
fn sigterm_writes_the_finished_samples_and_exits_cleanly() {
    signal_writes_the_finished_samples_and_exits_cleanly("TERM", 143);
}

/// Outputs whose final rename fails (the path is a directory): a clear error that says so
/// once, and no temporary file left beside it.
#[test]
fn outputs_onto_directories_fail_cleanly_without_temporary_files() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    render_ok(&["--out", "a.exr", "--sums", "--quiet"], d);
    std::fs::create_dir(d.join("taken.exr")).unwrap();
    std::fs::create_dir(d.join("taken.png")).unwrap();
    std::fs::create_dir(d.join("png_taken.png")).unwrap();
    // Render refuses before rendering (the EXR, or the PNG beside it, is a directory); the
    // others fail at the rename.
    let cases: [(&[&str], &str); 5] = [
        (
            &["render", "scene.ron", "--out", "taken.exr", "--quiet"],
            "is a directory",
        ),
        (
            &["render", "scene.ron", "--out", "png_taken.exr", "--quiet"],
            "is a directory",
        ),
        (&["merge", "taken.exr", "a.exr"], "is a directory"),
        (
            &["diff", "a.exr", "a.exr", "--map", "taken.png"],
            "is a directory",
        ),
        (
            &["bcsdf", "plot", "--model", "Chiang()", "--out", "taken.png"],
            "is a directory",
        ),
    ];
    for (args, cause) in cases {
        let before = files_in(d);
        let o = tress(args, d);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains("taken."), "{args:?}: {err}");
        assert_eq!(
            err.matches(cause).count(),
            1,
            "{args:?}: the cause once: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(files_in(d), before, "{args:?}: files left behind");
    }
}

/// Warnings carry no colour codes or timestamps when stderr is not a terminal (logs, CI).
#[test]
fn warnings_are_plain_text_off_a_terminal() {
    let (dir, _) = scene_dir(&SCENE.replace(
        "Procedural(style: Ball, strands: 300, radius: 0.01)",
        "File(\"tail.hair\")",
    ));
    let d = dir.path();
    let mut bytes = write_hair(b"HAIR", 3, &nine_points(), Some(&[1, 3, 2]), None, 0.01);
    bytes.extend_from_slice(&[0; 7]);
    std::fs::write(d.join("tail.hair"), bytes).unwrap();
    let o = tress(&["info", "scene.ron"], d);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("7 trailing bytes"))
        .unwrap_or_else(|| panic!("no warning: {err}"));
    assert!(!err.contains('\x1b'), "colour codes: {err:?}");
    assert!(
        line.starts_with(" WARN") || line.starts_with("WARN"),
        "{line:?}"
    );
}

/// Tiny hair under dual scattering: the density grid refuses it with a message (it panicked on
/// `min > max`). Hair reaching beyond 1e18 is refused for every integrator
/// (`geometry_beyond_what_f32_can_square_is_refused`).
#[test]
fn extreme_hair_extents_under_dual_scattering_give_clear_errors() {
    let dual = "DualMis(tables: (theta_nodes: 8, h_nodes: 4, theta_quad: 8, phi_quad: 8, \
                walks: 64))";
    let ball =
        r#"Hair(source: Procedural(style: Ball, strands: 300, radius: 0.01), material: "hair")"#;
    let tiny = ball.replace(
        "radius: 0.01)",
        "radius: 0.01), options: (transform: (scale: 1e-30))",
    );
    let (dir, _) = scene_dir(&SCENE.replace(ball, &tiny));
    assert_fails_in(
        dir.path(),
        &[
            "render",
            "scene.ron",
            "--integrator",
            dual,
            "--out",
            "o.exr",
            "--quiet",
        ],
        &[
            "scene.ron: integrator dual-mis: density grid: the hair",
            "spans 1.97",
            "scale the hair",
        ],
    );
}

/// `tress diff` on an image holding NaN fails naming the file (it printed NaN metrics with
/// success); `tress merge` refuses to overwrite one of its own pieces.
#[test]
fn diff_of_nan_images_and_merge_onto_a_piece_are_refused() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let mut img = tress_core::Image::new(4, 3);
    img.pixels
        .iter_mut()
        .for_each(|p| *p = tress_core::Rgb::splat(0.5));
    to_file(d.join("fine.exr"), |o| {
        tress_core::image_io::write_exr(o, &img, &[])
    })
    .unwrap();
    img.pixels[5] = tress_core::Rgb::new(f32::NAN, 0.5, 0.5);
    to_file(d.join("nan.exr"), |o| {
        tress_core::image_io::write_exr(o, &img, &[])
    })
    .unwrap();
    for args in [
        ["diff", "nan.exr", "fine.exr"],
        ["diff", "fine.exr", "nan.exr"],
    ] {
        assert_fails_in(d, &args, &["nan.exr", "1 pixels are NaN or infinite"]);
    }
    render_ok(&["--out", "piece.exr", "--quiet"], d);
    assert_fails_in(
        d,
        &["merge", "piece.exr", "piece.exr"],
        &["piece.exr", "an input of this command"],
    );
    assert_fails_in(
        d,
        &["merge", "./piece.exr", "piece.exr"],
        &["an input of this command"],
    );
}

/// Special files given as inputs are refused by name: a symlink to /dev/zero as a hair file
/// grew the process to 13.6 GB.
#[cfg(unix)]
#[test]
fn special_files_as_inputs_are_refused() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    for name in ["zero.hair", "zero.tfx", "zero.obj", "zero.hdr", "zero.ron"] {
        std::os::unix::fs::symlink("/dev/zero", d.join(name)).unwrap();
    }
    for name in ["zero.hair", "zero.tfx"] {
        assert_bad_hair(
            d,
            &format!("File(\"{name}\")"),
            &[name, "not a regular file"],
        );
    }
    let scene = |from: &str, to: &str| {
        assert!(SCENE.contains(from));
        std::fs::write(d.join("scene.ron"), SCENE.replace(from, to)).unwrap();
    };
    scene(
        "Sphere(center: (0, -2, 0), radius: 1, material: \"grey\")",
        "Mesh(file: \"zero.obj\", material: \"grey\")",
    );
    assert_fails_in(
        d,
        &["info", "scene.ron"],
        &["zero.obj", "not a regular file"],
    );
    scene("Sky()", "Environment(file: \"zero.hdr\")");
    assert_fails_in(
        d,
        &["info", "scene.ron"],
        &["zero.hdr", "not a regular file"],
    );
    assert_fails_in(
        d,
        &["info", "zero.ron"],
        &["zero.ron", "not a regular file"],
    );
}

/// A camera 1e-30 from what it looks at is valid (the check was absolute, and the f32 view
/// vector's square underflowed); coinciding points and an up parallel to the view are not.
#[test]
fn camera_checks_are_relative() {
    let (dir, _) = scene_dir(&SCENE.replace("look_from: (0, 0, 4)", "look_from: (0, 0, 1e-30)"));
    let d = dir.path();
    let err = render_ok(&["--out", "tiny.exr", "--quiet"], d);
    assert!(!err.contains("NaN"), "{err}");
    let (image, _) = tress_core::image_io::read_exr(d.join("tiny.exr")).unwrap();
    assert!(image.pixels.iter().all(|p| p.is_finite()));
    assert!(image.mean() > 0.0);
    for (from, to, expect) in [
        (
            "look_at: (0, 0, 0)",
            "look_at: (0, 0, 4)",
            "must differ from look_from",
        ),
        (
            "look_at: (0, 0, 0)",
            "look_at: (0, 0, 0), up: (0, 0, 1)",
            "not parallel",
        ),
        (
            "look_at: (0, 0, 0)",
            "look_at: (0, 0, 0), up: (0, 0, 0)",
            "non-zero",
        ),
    ] {
        assert_bad_scene(&SCENE.replace(from, to), &[expect]);
    }
}

/// Two renders writing the same outputs at once leave the EXR and the PNG of one of them, not
/// one of each (they take turns on a lock of the output folder). Eight races of two renders
/// with different seeds; after each, the PNG must be the preview of the EXR.
#[test]
fn concurrent_renders_to_one_output_leave_a_consistent_pair() {
    use std::process::Command;
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    for round in 0..8 {
        let children: Vec<_> = [1, 2]
            .map(|seed| {
                Command::new(env!("CARGO_BIN_EXE_tress"))
                    .args(["render", "scene.ron", "--out", "same.exr", "--quiet"])
                    .args(["--seed", &(10 * round + seed).to_string()])
                    .current_dir(d)
                    .spawn()
                    .unwrap()
            })
            .into_iter()
            .collect();
        for mut c in children {
            assert!(c.wait().unwrap().success());
        }
        let (image, attributes) = tress_core::image_io::read_exr(d.join("same.exr")).unwrap();
        assert!(attributes
            .iter()
            .any(|(k, v)| k == "tress:dropped_samples" && v == "0"));
        to_file(d.join("check.png"), |o| {
            tress_core::image_io::write_png_tonemapped(
                o,
                &image,
                0.0,
                tress_core::image_io::ToneMap::Filmic,
            )
        })
        .unwrap();
        assert_eq!(
            std::fs::read(d.join("same.png")).unwrap(),
            std::fs::read(d.join("check.png")).unwrap(),
            "round {round}: the PNG is not the EXR's preview"
        );
    }
    assert_eq!(
        files_in(d),
        ["check.png", "same.exr", "same.png", "scene.ron"],
        "temporary files left"
    );
}

/// Dual-scattering settings beyond what is sane, and scenes it cannot shade, are refused before
/// any long build, saying what is wrong once and how to go on.
#[test]
fn dual_scattering_settings_and_scenes_are_checked_up_front() {
    let dual = |settings: &str| SCENE.replace("Path(max_depth: 20)", settings);
    // theta_nodes: 4096 built for 78 s without a word.
    let t0 = Instant::now();
    assert_bad_scene(
        &dual("DualMis(tables: (theta_nodes: 4096))"),
        &["tables", "× the default", "TRESS_ALLOW_SLOW_TABLES"],
    );
    assert!(t0.elapsed() < Duration::from_secs(20), "{:?}", t0.elapsed());
    // 1024³ voxels with orientations could take 28 GiB.
    assert_bad_scene(
        &dual("DualMis(grid_resolution: Some(1024))"),
        &["grid_resolution", "GiB", "TRESS_MEMORY_LIMIT_GIB"],
    );
    // A hair material but no hair object: say so (it said "the scene has no density grid").
    let no_hair = dual("DualUniform()").replace(
        "Hair(source: Procedural(style: Ball, strands: 300, radius: 0.01), material: \"hair\"),",
        "",
    );
    assert_bad_scene(&no_hair, &["no hair object", "`path`"]);
    // The cause once ("d_f = 1.5: must lie in [0, 1]: d_f = 1.5: …" before).
    let (dir, _) = scene_dir(&dual("DualMis(d_f: Some(1.5))"));
    let o = tress(
        &["render", "scene.ron", "--out", "o.exr", "--quiet"],
        dir.path(),
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(err.matches("d_f = 1.5").count(), 1, "{err}");
}

/// A parse error on a 400 KB line shows an excerpt around the error, not the line.
#[test]
fn parse_errors_show_an_excerpt_of_long_lines() {
    let long = format!("({}bogus: 1)", " ".repeat(400_000));
    let (dir, _) = scene_dir(&long);
    let o = tress(&["info", "scene.ron"], dir.path());
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{}", &err[..err.len().min(500)]);
    assert!(err.len() < 1000, "{} bytes of message", err.len());
    assert!(
        err.contains("scene.ron:1:") && err.contains('…') && err.contains('^'),
        "{err}"
    );
    let caret = err.lines().last().unwrap();
    let shown = err.lines().nth_back(1).unwrap();
    // The caret sits under the offending identifier.
    let col = caret.chars().count() - 1;
    assert!(
        shown
            .chars()
            .skip(col)
            .collect::<String>()
            .starts_with("bogus"),
        "{shown}\n{caret}"
    );
}

/// USC-HairSalon `.data` files load by extension, and a broken one fails naming the file.
#[test]
fn usc_hairsalon_files_load_and_broken_ones_are_named() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let mut bytes = 2i32.to_le_bytes().to_vec();
    for strand in [
        [[0.0f32, 0.5, 0.0], [0.0, 0.0, 0.1]],
        [[0.2, 0.5, 0.0], [0.2, 0.0, 0.1]],
    ] {
        bytes.extend(2i32.to_le_bytes());
        bytes.extend(strand.iter().flatten().flat_map(|v| v.to_le_bytes()));
    }
    std::fs::write(d.join("style.data"), &bytes).unwrap();
    let scene = SCENE.replace(
        "Procedural(style: Ball, strands: 300, radius: 0.01)",
        "Usc(path: \"style.data\", radius: 0.01)",
    );
    std::fs::write(d.join("scene.ron"), &scene).unwrap();
    let o = tress(&["info", "scene.ron"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("2 strands"), "{out}");
    std::fs::write(d.join("style.data"), &bytes[..bytes.len() - 5]).unwrap();
    assert_bad_hair(d, "File(\"style.data\")", &["style.data", "past the end"]);
}

/// `tress args` in `dir`, killed and reported if it runs longer than `secs` (a hang).
fn tress_within(
    args: &[&str],
    dir: &Path,
    env: &[(&str, &str)],
    secs: u64,
) -> std::process::Output {
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_tress"))
        .args(args)
        .envs(env.iter().copied())
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(secs) {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("{args:?}: still running after {secs} s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// As [`assert_fails_in`], but a hang fails the test instead of blocking it.
fn assert_fails_within(dir: &Path, args: &[&str], env: &[(&str, &str)], expect: &[&str]) {
    let before = files_in(dir);
    let o = tress_within(args, dir, env, 60);
    let err = stderr(&o);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{args:?}: expected failure: {err}"
    );
    for e in expect {
        assert!(err.contains(e), "{args:?}: message lacks '{e}': {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(files_in(dir), before, "{args:?}: output left behind");
}

/// Printing into a pipe whose reader is gone ends the command quietly, as it does other Unix
/// tools (`tress info scene.ron | true` panicked "failed printing to stdout: Broken pipe").
#[cfg(unix)]
#[test]
fn closed_stdout_pipes_end_commands_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    std::fs::write(d.join("dirs.csv"), "0.2,0,0,1,0.5,0,1\n").unwrap();
    render_ok(&["--out", "a.exr", "--quiet"], d);
    let model = "Chiang(beta_m: 0.3, beta_n: 0.3)";
    for args in [
        &["info", "scene.ron"][..],
        &["farm", "scene.ron", "--tiles", "2"],
        &[
            "bcsdf",
            "furnace",
            "--model",
            model,
            "--csv",
            "--samples",
            "1000",
        ],
        &["bcsdf", "eval", "--model", model, "--input", "dirs.csv"],
        &["diff", "a.exr", "a.exr"],
    ] {
        // The reading end is closed before tress starts, so its first write meets EPIPE.
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_tress"))
            .args(args)
            .current_dir(d)
            .stdout(writer)
            .output()
            .unwrap();
        let err = stderr(&o);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(
            o.status.success() || o.status.signal() == Some(libc::SIGPIPE),
            "{args:?}: {:?} {err}",
            o.status
        );
    }
}

/// FIFOs given as any input are refused at once (opening one waited for a writer forever):
/// hair files of every format, OBJ meshes, scenes, pbrt includes, study files, `bcsdf eval`
/// inputs and `merge` pieces.
#[cfg(unix)]
#[test]
fn fifos_as_inputs_are_refused_without_blocking() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    for name in [
        "f.hair",
        "f.tfx",
        "f.ply",
        "f.obj",
        "f.ron",
        "f.pbrt",
        "study.ron",
        "dirs.csv",
        "f.exr",
    ] {
        let made = std::process::Command::new("mkfifo")
            .arg(d.join(name))
            .status()
            .unwrap();
        assert!(made.success());
    }
    for name in ["f.hair", "f.tfx", "f.ply"] {
        write_hair_scene(d, &format!("File(\"{name}\")"));
        assert_fails_within(
            d,
            &["info", "scene.ron"],
            &[],
            &[name, "not a regular file"],
        );
    }
    std::fs::write(d.join("main.pbrt"), "Include \"f.pbrt\"\n").unwrap();
    write_hair_scene(d, "File(\"main.pbrt\")");
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &[],
        &["f.pbrt", "not a regular file"],
    );
    std::fs::write(
        d.join("scene.ron"),
        SCENE.replace(
            "Sphere(center: (0, -2, 0), radius: 1, material: \"grey\")",
            "Mesh(file: \"f.obj\", material: \"grey\")",
        ),
    )
    .unwrap();
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &[],
        &["f.obj", "not a regular file"],
    );
    std::fs::write(d.join("scene.ron"), SCENE).unwrap();
    let model = "Chiang(beta_m: 0.3, beta_n: 0.3)";
    render_ok(&["--out", "piece.exr", "--quiet", "--sums"], d);
    for (args, name) in [
        (&["info", "f.ron"][..], "f.ron"),
        (&["render", "f.ron", "--quiet"], "f.ron"),
        (&["study", "study.ron", "--quiet"], "study.ron"),
        (
            &["bcsdf", "eval", "--model", model, "--input", "dirs.csv"],
            "dirs.csv",
        ),
        (&["merge", "m.exr", "piece.exr", "f.exr"], "f.exr"),
        (&["diff", "piece.exr", "f.exr"], "f.exr"),
    ] {
        assert_fails_within(d, args, &[], &[name, "not a regular file"]);
    }
}

/// Inputs that multiply or never end are bounded: a binary PLY element with no properties and
/// 2^64 − 1 records, pbrt `Include` fan-out, and thread counts far beyond the machine.
#[test]
fn endless_and_multiplying_inputs_are_bounded() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let hair_scene = |source: &str| write_hair_scene(d, source);
    // Two strands of two points each, then an element with no properties: its records take no
    // bytes, so they are read (as nothing) at once, in both byte orders.
    for (format, name) in [
        ("binary_little_endian", "le.ply"),
        ("binary_big_endian", "be.ply"),
    ] {
        let mut ply = format!(
            "ply\nformat {format} 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
             property float z\nelement junk 18446744073709551615\nelement strand 2\n\
             property int vertex_count\nend_header\n"
        )
        .into_bytes();
        let big = format == "binary_big_endian";
        let put = |ply: &mut Vec<u8>, v: [u8; 4]| ply.extend(v);
        for p in [
            [0.0f32, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
        ] {
            for c in p {
                put(
                    &mut ply,
                    if big {
                        c.to_be_bytes()
                    } else {
                        c.to_le_bytes()
                    },
                );
            }
        }
        for n in [2i32, 2] {
            put(
                &mut ply,
                if big {
                    n.to_be_bytes()
                } else {
                    n.to_le_bytes()
                },
            );
        }
        std::fs::write(d.join(name), ply).unwrap();
        hair_scene(&format!("File(\"{name}\")"));
        let o = tress_within(&["info", "scene.ron"], d, &[], 60);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        assert!(
            String::from_utf8_lossy(&o.stdout).contains("2 strands"),
            "{name}"
        );
    }
    // 8 levels of 10 includes each of one small file: 10^8 reads. Imports fan out alike.
    let curve = "Shape \"curve\" \"point3 P\" [0 0 0 0 1 0 0 2 0 0 3 0] \"float width\" 0.01\n";
    std::fs::write(d.join("leaf.pbrt"), curve.repeat(20)).unwrap();
    for keyword in ["Include", "Import"] {
        for level in 0..8 {
            let next = if level == 7 {
                "leaf.pbrt".to_string()
            } else {
                format!("l{}.pbrt", level + 1)
            };
            std::fs::write(
                d.join(format!("l{level}.pbrt")),
                format!("{keyword} \"{next}\"\n").repeat(10),
            )
            .unwrap();
        }
        hair_scene("File(\"l0.pbrt\")");
        assert_fails_within(
            d,
            &["info", "scene.ron"],
            &[],
            &[
                "l",
                ".pbrt",
                "more than 10000 `Include`/`Import` statements",
            ],
        );
    }
    // A few includes of a large file fan out too: the text read in all is bounded (by the
    // memory limit, here 1 MiB: 20 includes of 100 kB).
    std::fs::write(
        d.join("big.pbrt"),
        format!("#{}\n", "x".repeat(99)).repeat(1000),
    )
    .unwrap();
    std::fs::write(d.join("l0.pbrt"), "Include \"big.pbrt\"\n".repeat(20)).unwrap();
    hair_scene("File(\"l0.pbrt\")");
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &[("TRESS_MEMORY_LIMIT_GIB", "0.001")],
        &["big.pbrt", "GiB of text in all"],
    );
    hair_scene("Procedural(style: Ball, strands: 300, radius: 0.01)");
    for args in [
        &[
            "render",
            "scene.ron",
            "--out",
            "o.exr",
            "--threads",
            "10000",
        ][..],
        &["calibrate", "scene.ron", "--threads", "100000"],
        &["study", "scene.ron", "--threads", "4096"],
    ] {
        let o = tress_within(args, d, &[], 60);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            stderr(&o).contains("worker threads: at most"),
            "{args:?}: {}",
            stderr(&o)
        );
    }
}

/// Outputs that belong together are written together or not at all: `merge`'s EXR and PNG,
/// `bcsdf plot`'s PNG and SVG (either path failing left the other file behind).
#[test]
fn outputs_that_belong_together_are_all_or_nothing() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    render_ok(&["--out", "piece.exr", "--sums", "--quiet"], d);
    std::fs::create_dir(d.join("m.png")).unwrap();
    assert_fails_in(d, &["merge", "m.exr", "piece.exr", "--quiet"], &["m.png"]);
    std::fs::remove_dir(d.join("m.png")).unwrap();
    let model = "Chiang(beta_m: 0.3, beta_n: 0.3)";
    for (blocked, other) in [("lobes.svg", "lobes.png"), ("lobes.png", "lobes.svg")] {
        std::fs::create_dir(d.join(blocked)).unwrap();
        assert_fails_in(
            d,
            &["bcsdf", "plot", "--model", model, "--out", "lobes.png"],
            &[blocked],
        );
        assert!(!d.join(other).exists(), "{other} left behind");
        std::fs::remove_dir(d.join(blocked)).unwrap();
    }
    // With both paths free, both are written.
    let o = tress(
        &["bcsdf", "plot", "--model", model, "--out", "lobes.png"],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("lobes.png").is_file() && d.join("lobes.svg").is_file());
}

/// Study caches and merged pieces are keyed on the content of every file a scene reads,
/// the files a pbrt groom includes and the layers a USD groom composes among them (the scene hash covered only the scene's text,
/// and the study cache only the files the scene names).
#[test]
fn caches_and_merges_key_on_every_file_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let strand = |x: f32| {
        format!(
            "Shape \"curve\" \"point3 P\" [{x} -0.5 0 {x} -0.2 0 {x} 0.2 0 {x} 0.5 0] \"float width\" 0.05\n"
        )
    };
    std::fs::write(d.join("main.pbrt"), "Include \"strand.pbrt\"\n").unwrap();
    std::fs::write(d.join("strand.pbrt"), strand(0.0)).unwrap();
    let scene = SCENE.replace(
        "Procedural(style: Ball, strands: 300, radius: 0.01)",
        "File(\"main.pbrt\")",
    );
    std::fs::write(d.join("scene.ron"), &scene).unwrap();
    let study = format!(
        "(scenes: [Inline(name: \"pbrt\", scene: {scene})], integrators: [Path(max_depth: 3)], \
         spp: [1, 2], repetitions: 1, reference: Render(integrator: Path(max_depth: 3), spp: 4))"
    );
    std::fs::write(d.join("study.ron"), study).unwrap();
    let rendered = || {
        let o = tress(&["study", "study.ron", "--out", "out"], d);
        assert!(o.status.success(), "{}", stderr(&o));
        let e = stderr(&o);
        let at = e.find("rendered ").unwrap_or_else(|| panic!("{e}")) + "rendered ".len();
        e[at..]
            .split(|c: char| !c.is_ascii_digit())
            .next()
            .unwrap()
            .parse::<usize>()
            .unwrap()
    };
    let made = rendered();
    assert!(made > 0);
    assert_eq!(rendered(), 0, "an unchanged study reuses its renders");
    std::fs::write(d.join("strand.pbrt"), strand(0.3)).unwrap();
    assert_eq!(
        rendered(),
        made,
        "a changed included file redoes every render"
    );
    // A USD groom whose curves sit in a sublayer and in a referenced layer: changing either
    // changes the renders (they were left out of every hash).
    let usd_curve = |x: f32| {
        format!(
            "#usda 1.0\ndef BasisCurves \"Hair\"\n{{\n    uniform token type = \"linear\"\n    \
             int[] curveVertexCounts = [2]\n    point3f[] points = [({x}, -50, 0), ({x}, 50, 0)]\n    \
             float[] widths = [5, 5]\n}}\n"
        )
        .into_bytes()
    };
    std::fs::write(d.join("sub.usda"), usd_curve(0.0)).unwrap();
    std::fs::write(d.join("ref.usda"), usd_curve(0.0)).unwrap();
    std::fs::write(
        d.join("groom.usda"),
        "#usda 1.0\n(\n    subLayers = [@./sub.usda@]\n)\n\
         def Xform \"Other\" (\n    references = @./ref.usda@</Hair>\n)\n{\n}\n",
    )
    .unwrap();
    let usd_scene = SCENE.replace(
        "Procedural(style: Ball, strands: 300, radius: 0.01)",
        "File(\"groom.usda\")",
    );
    std::fs::write(
        d.join("study.ron"),
        format!(
            "(scenes: [Inline(name: \"usd\", scene: {usd_scene})], integrators: [Path(max_depth: 3)], \
             spp: [1, 2], repetitions: 1, reference: Render(integrator: Path(max_depth: 3), spp: 4))"
        ),
    )
    .unwrap();
    let made = rendered();
    assert!(made > 0);
    for layer in ["sub.usda", "ref.usda"] {
        assert_eq!(rendered(), 0, "an unchanged study reuses its renders");
        std::fs::write(d.join(layer), usd_curve(0.2)).unwrap();
        assert_eq!(rendered(), made, "a changed {layer} redoes every render");
    }

    // Tiles rendered against different contents of one hair file are not merged, whether the
    // file is named by the scene or included by it.
    let tile = |window: &str, out: &str| {
        render_ok(&["--crop", window, "--sums", "--out", out, "--quiet"], d);
    };
    let hair_scene = SCENE.replace(
        "Procedural(style: Ball, strands: 300, radius: 0.01)",
        "File(\"h.hair\")",
    );
    let segs: &[u16] = &[1, 3, 2];
    for (scene, file, before, after) in [
        (
            hair_scene.as_str(),
            "h.hair",
            write_hair(b"HAIR", 3, &nine_points(), Some(segs), None, 0.01),
            write_hair(
                b"HAIR",
                3,
                &nine_points()[..]
                    .iter()
                    .map(|p| [p[0], p[1], 0.3])
                    .collect::<Vec<_>>(),
                Some(segs),
                None,
                0.01,
            ),
        ),
        (
            scene.as_str(),
            "strand.pbrt",
            strand(0.0).into_bytes(),
            strand(0.3).into_bytes(),
        ),
        (
            usd_scene.as_str(),
            "sub.usda",
            usd_curve(0.0),
            usd_curve(0.3),
        ),
        (
            usd_scene.as_str(),
            "ref.usda",
            usd_curve(0.0),
            usd_curve(0.3),
        ),
    ] {
        std::fs::write(d.join("scene.ron"), scene).unwrap();
        std::fs::write(d.join(file), &before).unwrap();
        tile("0,0,24,10", "top.exr");
        tile("0,10,24,20", "bottom.exr");
        let o = tress(&["merge", "m.exr", "top.exr", "bottom.exr", "--quiet"], d);
        assert!(o.status.success(), "{file}: {}", stderr(&o));
        std::fs::write(d.join(file), &after).unwrap();
        tile("0,10,24,20", "bottom.exr");
        assert_fails_in(
            d,
            &["merge", "m2.exr", "top.exr", "bottom.exr", "--quiet"],
            &["top.exr", "bottom.exr", "hash"],
        );
    }
}

/// Small inputs that would need more memory than the limit are refused by name before
/// anything is allocated (they grew to 5–12 GB and aborted, or read `/dev/zero` forever).
#[test]
fn memory_blowups_are_refused_before_allocating() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let hair_scene = |source: &str| write_hair_scene(d, source);
    hair_scene(
        "Procedural(style: Straight, strands: 200), options: (children: Some(per_guide: 40000, \
         radius: 0.05, seed: 1))",
    );
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &[],
        &["children.per_guide", "40000", "GiB"],
    );
    hair_scene("Procedural(style: Straight, strands: 1000000, points_per_strand: 1000)");
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &[],
        &[
            "strands × points_per_strand",
            "GiB",
            "TRESS_MEMORY_LIMIT_GIB",
        ],
    );
    // Thin curved curves split 1024-fold: 200 of them are 205 000 points, over 0.01 GiB.
    let curve = "Shape \"curve\" \"point3 P\" [0 0 0 1 1 0 -1 1 0 0 0 0.1] \"float width\" 1e-6\n";
    std::fs::write(d.join("thin.pbrt"), curve.repeat(200)).unwrap();
    hair_scene("File(\"thin.pbrt\")");
    let low = [("TRESS_MEMORY_LIMIT_GIB", "0.01")];
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &low,
        &["thin.pbrt", "Shape \"curve\"", "GiB"],
    );
    let o = tress_within(&["info", "scene.ron"], d, &[], 60);
    assert!(
        o.status.success(),
        "within the default limit: {}",
        stderr(&o)
    );
    // The same limit holds for every generator: 4000 × 24 points is 0.01 GiB.
    hair_scene("Procedural(style: Straight, strands: 4000)");
    assert_fails_within(d, &["info", "scene.ron"], &low, &["strands", "GiB"]);
    // A study reads only regular files too (`tress render` already refused this one).
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("/dev/zero", d.join("zero.hair")).unwrap();
        hair_scene("File(\"zero.hair\")");
        let scene = std::fs::read_to_string(d.join("scene.ron")).unwrap();
        std::fs::write(
            d.join("study.ron"),
            format!(
                "(scenes: [Inline(name: \"z\", scene: {scene})], integrators: [Path()], \
                 spp: [1], repetitions: 1, reference: Render(integrator: Path(), spp: 2))"
            ),
        )
        .unwrap();
        let o = tress_within(
            &["study", "study.ron", "--out", "out", "--quiet"],
            d,
            &[],
            60,
        );
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(stderr(&o).contains("zero.hair") && stderr(&o).contains("not a regular file"));
    }
}

/// The memory limit holds for the whole scene: objects that each fit but together do not are
/// refused at the one that crosses it, by name and with the totals, whatever their kind (four
/// 0.68 GiB objects passed a 1 GiB limit), and pbrt instances count their points.
#[test]
fn memory_limit_holds_for_the_whole_scene() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    // 0.01 GiB is 83 886 hair points at 128 bytes: 1500 strands × 24 points is 0.0043 GiB.
    let low = [("TRESS_MEMORY_LIMIT_GIB", "0.01")];
    let hair = "Hair(source: Procedural(style: Straight, strands: 1500), material: \"hair\")";
    let with_objects = |objects: &[String]| {
        let text = SCENE.replace(
            "Hair(source: Procedural(style: Ball, strands: 300, radius: 0.01), material: \"hair\"),",
            &format!("{},", objects.join(",\n")),
        );
        std::fs::write(d.join("scene.ron"), text).unwrap();
    };
    with_objects(&[hair.into(), hair.into()]);
    let o = tress_within(&["info", "scene.ron"], d, &low, 60);
    assert!(o.status.success(), "two fit: {}", stderr(&o));
    with_objects(&[hair.into(), hair.into(), hair.into()]);
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &low,
        &[
            "objects[2]",
            "GiB of the objects before it",
            "0.01 GiB limit for the whole scene",
        ],
    );
    // A mesh after the hair: 20 000 triangles.
    let mut obj = String::new();
    for i in 0..20_000 {
        let x = i as f32 * 1e-4;
        obj.push_str(&format!(
            "v {x} 0 0\nv {x} 1 0\nv {x} 0 1\nf {} {} {}\n",
            3 * i + 1,
            3 * i + 2,
            3 * i + 3
        ));
    }
    std::fs::write(d.join("m.obj"), obj).unwrap();
    with_objects(&[
        hair.into(),
        hair.into(),
        "Mesh(file: \"m.obj\", material: \"grey\")".into(),
    ]);
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &low,
        &[
            "objects[2]",
            "m.obj",
            "20000 triangles",
            "GiB of the objects before it",
        ],
    );
    // Spheres, many small objects: each counts.
    let spheres: Vec<String> = (0..20_000)
        .map(|i| format!("Sphere(center: ({i}, 0, 0), radius: 0.5, material: \"grey\")"))
        .collect();
    with_objects(&spheres);
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &[("TRESS_MEMORY_LIMIT_GIB", "0.001")],
        &["sphere #", "0.001 GiB limit for the whole scene"],
    );
    // pbrt instances count against what the objects before them left: alone the groom fits.
    let control: Vec<String> = (0..31)
        .map(|i| format!("0 {} 0", i as f32 * 0.01))
        .collect();
    let mut pbrt = format!(
        "ObjectBegin \"tuft\"\nShape \"curve\" \"point3 P\" [{}] \"float width\" 0.01\nObjectEnd\n",
        control.join(" ")
    );
    pbrt.push_str(&"ObjectInstance \"tuft\"\n".repeat(5000));
    std::fs::write(d.join("inst.pbrt"), pbrt).unwrap();
    let instanced = "Hair(source: File(\"inst.pbrt\"), material: \"hair\")".to_string();
    with_objects(std::slice::from_ref(&instanced));
    let o = tress_within(&["info", "scene.ron"], d, &low, 60);
    assert!(
        o.status.success(),
        "the instances alone fit: {}",
        stderr(&o)
    );
    with_objects(&[hair.into(), instanced]);
    assert_fails_within(
        d,
        &["info", "scene.ron"],
        &low,
        &[
            "objects[1]",
            "inst.pbrt (line",
            "instances of \"tuft\"",
            "objects before it",
        ],
    );
}

/// Errors that used to mislead: pbrt `nan`/`inf` tokens, tiny non-zero directions called zero,
/// nested placeholder defaults, and a `-D` name given twice.
#[test]
fn misleading_errors_are_named() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    write_hair_scene(d, "File(\"h.pbrt\")");
    let curve = |p: &str, width: &str| {
        format!("Shape \"curve\" \"point3 P\" [{p}] \"float width\" {width}\n")
    };
    let good = "0 0 0 0 1 0 0 2 0 0 3 0";
    for (text, bad) in [
        (curve("0 nan 0 0 1 0 0 2 0 0 3 0", "0.01"), "`nan`"),
        (curve(good, "inf"), "`inf`"),
        (curve(good, "[ -Infinity ]"), "`-Infinity`"),
        (format!("Scale nan 1 1\n{}", curve(good, "0.01")), "`nan`"),
        (
            format!("Translate 1e999 0 0\n{}", curve(good, "0.01")),
            "`1e999`",
        ),
    ] {
        std::fs::write(d.join("h.pbrt"), &text).unwrap();
        assert_fails_in(
            d,
            &["info", "scene.ron"],
            &["h.pbrt", bad, "is not a finite number"],
        );
    }
    // Any non-zero length is a direction: 1e-30 squares to zero in f32.
    std::fs::write(
        d.join("h.pbrt"),
        format!("Rotate 30 1e-200 0 0\n{}", curve(good, "0.01")),
    )
    .unwrap();
    let o = tress(&["info", "scene.ron"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    for (from, to) in [
        ("direction: (0, -1, -1)", "direction: (0, -1e-30, -1e-30)"),
        (
            "radius: 0.01)",
            "radius: 0.01), options: (transform: (rotate: AxisAngle(axis: (1e-30, 0, 0), degrees: 30)))",
        ),
    ] {
        std::fs::write(d.join("scene.ron"), SCENE.replace(from, to)).unwrap();
        render_ok(&["--out", "o.exr", "--quiet"], d);
    }
    std::fs::write(d.join("dirs.csv"), "0.2,1e-30,0,0,0,0,1e-30\n").unwrap();
    let o = tress(
        &[
            "bcsdf",
            "eval",
            "--model",
            "Chiang(beta_m: 0.3, beta_n: 0.3)",
            "--input",
            "dirs.csv",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(String::from_utf8_lossy(&o.stdout).lines().count(), 2);
    std::fs::write(
        d.join("scene.ron"),
        SCENE.replace("spp: 6", "spp: ${a:-${b:-1}}"),
    )
    .unwrap();
    assert_fails_in(
        d,
        &["info", "scene.ron"],
        &["scene.ron", "${a:-…}", "nested defaults are not supported"],
    );
    std::fs::write(d.join("scene.ron"), SCENE.replace("spp: 6", "spp: ${spp}")).unwrap();
    for command in ["render", "info", "farm"] {
        assert_fails_in(
            d,
            &[command, "scene.ron", "-D", "spp=4", "-D", "spp=8"],
            &["-D spp is given twice", "spp=4", "spp=8"],
        );
    }
}

/// Geometry whose squared lengths overflow f32 is refused by name for every integrator: fibers
/// wider than about 1e20 vanished under the path tracer while dual scattering refused them.
#[test]
fn geometry_beyond_what_f32_can_square_is_refused() {
    let ball =
        r#"Hair(source: Procedural(style: Ball, strands: 300, radius: 0.01), material: "hair")"#;
    let sphere = r#"Sphere(center: (0, -2, 0), radius: 1, material: "grey")"#;
    for (from, to, name) in [
        (
            ball,
            ball.replace(
                "radius: 0.01)",
                "radius: 0.01), options: (radius_scale: 1e22)",
            ),
            "procedural ball hair",
        ),
        (
            ball,
            ball.replace(
                "radius: 0.01)",
                "radius: 0.01), options: (transform: (scale: 1e30))",
            ),
            "procedural ball hair",
        ),
        (
            ball,
            ball.replace(
                "radius: 0.01)",
                "radius: 0.01), options: (transform: (translate: (2e19, 0, 0)))",
            ),
            "procedural ball hair",
        ),
        (
            sphere,
            sphere.replace("radius: 1,", "radius: 1e20,"),
            "sphere #0",
        ),
        (
            sphere,
            sphere.replace("(0, -2, 0)", "(0, -2e19, 0)"),
            "sphere #0",
        ),
    ] {
        let (dir, _) = scene_dir(&SCENE.replace(from, &to));
        for integrator in ["path", "dual-mis"] {
            assert_fails_in(
                dir.path(),
                &[
                    "render",
                    "scene.ron",
                    "--integrator",
                    integrator,
                    "--out",
                    "o.exr",
                    "--quiet",
                ],
                &["scene.ron", name, "beyond the 1e18", "scale the scene down"],
            );
        }
    }
    // Meshes too, through their transform.
    let (dir, _) = scene_dir(&SCENE.replace(
        sphere,
        r#"Mesh(file: "t.obj", material: "grey", transform: (scale: 1e19))"#,
    ));
    std::fs::write(
        dir.path().join("t.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    assert_fails_in(
        dir.path(),
        &["info", "scene.ron"],
        &["t.obj", "beyond the 1e18"],
    );
}

/// A closed surface seen from inside lets no light in: rays leaving a sphere inwards used to
/// skip the whole sphere and reach the sky, and grazing ones to slip through Embree's f32
/// roots (meshes skip only the flat triangle they leave).
#[test]
fn closed_surfaces_seen_from_inside_are_dark() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    std::fs::write(
        d.join("box.obj"),
        "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n\
         f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n",
    )
    .unwrap();
    for (object, camera) in [
        (
            r#"Sphere(center: (0, 0, 0), radius: 1, material: "grey")"#,
            "(0, 0, 0)",
        ),
        (
            r#"Sphere(center: (0, 0, 0), radius: 1, material: "grey")"#,
            "(0.3, 0.5, -0.2)",
        ),
        (
            r#"Sphere(center: (1e3, 0, 0), radius: 1e3, material: "grey")"#,
            "(1, 0.1, 0)",
        ),
        (
            r#"Mesh(file: "box.obj", material: "grey")"#,
            "(0.2, 0.1, 0)",
        ),
    ] {
        let scene = format!(
            r#"(
    camera: (look_from: {camera}, look_at: (0, 0, -5), fov: 60),
    film: (width: 16, height: 16, spp: 16, seed: 3),
    materials: {{ "grey": Diffuse(albedo: (0.8, 0.8, 0.8)) }},
    objects: [{object}],
    lights: [Sky(), Distant(direction: (0, -1, -1), irradiance: (2, 2, 2), angular_radius: 0.5)],
)"#
        );
        std::fs::write(d.join("scene.ron"), scene).unwrap();
        render_ok(&["--out", "inside.exr", "--quiet"], d);
        let (image, _) = tress_core::image_io::read_exr(d.join("inside.exr")).unwrap();
        let lit = image
            .pixels
            .iter()
            .filter(|p| p.max_element() > 0.0)
            .count();
        assert_eq!(lit, 0, "{object} from {camera}: {lit} pixels see light");
    }
}

/// A study whose reference EXR holds NaN pixels is refused as `tress diff` refuses it (it wrote
/// NaN errors into summary.csv and report.md and exited 0).
#[test]
fn study_references_holding_nan_are_refused() {
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let mut img = tress_core::Image::new(24, 20);
    img.pixels
        .iter_mut()
        .for_each(|p| *p = tress_core::Rgb::splat(0.5));
    img.pixels[7] = tress_core::Rgb::new(0.5, f32::NAN, 0.5);
    to_file(d.join("ref.exr"), |o| {
        tress_core::image_io::write_exr(o, &img, &[])
    })
    .unwrap();
    img.pixels[7] = tress_core::Rgb::new(0.5, 0.5, f32::INFINITY);
    to_file(d.join("inf.exr"), |o| {
        tress_core::image_io::write_exr(o, &img, &[])
    })
    .unwrap();
    for reference in ["ref.exr", "inf.exr"] {
        std::fs::write(
            d.join("study.ron"),
            format!(
                "(scenes: [File(\"scene.ron\")], integrators: [Path(max_depth: 3)], spp: [1], \
                 repetitions: 1, reference: Exr(\"{reference}\"))"
            ),
        )
        .unwrap();
        let o = tress(&["study", "study.ron", "--out", "out", "--quiet"], d);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        let err = stderr(&o);
        assert!(
            err.contains(reference) && err.contains("1 pixels are NaN or infinite"),
            "{err}"
        );
        assert!(!d.join("out/summary.csv").exists() && !d.join("out/report.md").exists());
    }
}

/// Every property of a PLY layout that tress reads is read as declared or refused by name: a
/// list where one number is read was skipped silently (`x`, `radius`, strand ids: points at 0,
/// the default radius, one strand) or read as NaN (counts, edges, float index lists).
#[test]
fn ply_properties_are_read_as_declared_or_refused() {
    let (dir, _) = scene_dir(SCENE);
    let ply = |vertex_props: &str, vertex_rows: &str, rest: &str| -> Vec<u8> {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
             property float z\n{vertex_props}{rest}"
        )
        .replace("VERTS", vertex_rows)
        .into_bytes()
    };
    let counts = "element strand 2\nproperty int vertex_count\nend_header\nVERTS2\n2\n";
    let plain = "0 0 0\n0 1 0\n1 0 0\n1 1 0\n";
    let with = |extra: &str| {
        ["0 0 0", "0 1 0", "1 0 0", "1 1 0"]
            .map(|v| format!("{v} {extra}\n"))
            .concat()
    };
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        (
            "x.ply",
            b"ply\nformat ascii 1.0\nelement vertex 4\nproperty list uchar float x\n\
              property float y\nproperty float z\nelement strand 2\nproperty int vertex_count\n\
              end_header\n1 0 0 0\n1 0 1 0\n1 1 0 0\n1 1 1 0\n2\n2\n"
                .to_vec(),
            &["`vertex` element's `x`", "a list of Float", "one number"],
        ),
        (
            "radius.ply",
            ply("property list uchar float radius\n", &with("1 0.1"), counts),
            &["`radius`", "a list of Float", "one number"],
        ),
        (
            "strand.ply",
            ply(
                "property list uchar int strand\nend_header\n",
                &with("1 0"),
                "VERTS",
            ),
            &["`strand`", "a list of Int", "one number"],
        ),
        (
            "colour.ply",
            ply(
                "property list uchar uchar red\nproperty uchar green\nproperty uchar blue\n",
                &with("1 9 9 9"),
                counts,
            ),
            &["`red`", "a list of UChar", "one number"],
        ),
        (
            "count.ply",
            ply(
                "",
                plain,
                "element strand 2\nproperty list uchar int vertex_count\nend_header\nVERTS1 2\n1 2\n",
            ),
            &["`strand` element's `vertex_count`", "one number"],
        ),
        (
            "indices.ply",
            ply(
                "",
                plain,
                "element strand 2\nproperty list uchar float vertex_indices\nend_header\nVERTS2 0 1\n2 2 3\n",
            ),
            &["`vertex_indices`", "a list of Float", "a list of integers"],
        ),
        (
            "edge.ply",
            ply(
                "",
                plain,
                "element edge 2\nproperty list uchar int vertex1\nproperty int vertex2\nend_header\nVERTS1 0 1\n1 2 3\n",
            ),
            &["`edge` element's `vertex1`", "one number"],
        ),
    ];
    assert_bad_hair_files(dir.path(), cases);
    // The same files with the types tress reads load.
    let good = ply("property float radius\n", &with("0.1"), counts);
    std::fs::write(dir.path().join("good.ply"), good).unwrap();
    std::fs::write(
        dir.path().join("scene.ron"),
        SCENE.replace(
            "Procedural(style: Ball, strands: 300, radius: 0.01)",
            "File(\"good.ply\")",
        ),
    )
    .unwrap();
    let o = tress(&["info", "scene.ron"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
}

/// Makes a FIFO at `path`.
#[cfg(unix)]
fn mkfifo(path: &Path) {
    let made = std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .unwrap();
    assert!(made.success());
}

#[cfg(unix)]
fn is_symlink(path: &Path) -> bool {
    std::fs::symlink_metadata(path)
        .unwrap()
        .file_type()
        .is_symlink()
}

/// What an output path names decides how it is written, for every command: a character device
/// or FIFO, directly or through links, is written into and never replaced by a file (run as
/// root, `render --out /dev/null` replaced the machine's /dev/null); a FIFO nobody reads, and
/// a socket, are refused by name without blocking; a link to a file (or to nothing yet) is
/// followed, so the link survives. /dev/null is only ever reached through a link in the test's
/// folder, so a regression replaces the link, not the device.
#[cfg(unix)]
#[test]
fn outputs_write_into_devices_and_fifos_and_through_links_never_over_them() {
    use std::os::unix::fs::{symlink, FileTypeExt, OpenOptionsExt};
    let (dir, _) = scene_dir(SCENE);
    let d = dir.path();
    let null_is_a_device = || {
        std::fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device()
    };
    assert!(null_is_a_device());
    // A render into links to /dev/null (EXR and PNG): done, links and device unchanged.
    symlink("/dev/null", d.join("null.exr")).unwrap();
    symlink("/dev/null", d.join("null.png")).unwrap();
    render_ok(&["--out", "null.exr", "--quiet"], d);
    assert!(is_symlink(&d.join("null.exr")) && is_symlink(&d.join("null.png")));
    assert!(null_is_a_device());
    std::fs::write(d.join("dirs.csv"), "0.2,0,0,1,0.5,0,1\n").unwrap();
    let eval = |output: &str| {
        tress(
            &[
                "bcsdf", "eval", "--model", "Chiang()", "--input", "dirs.csv", "--output", output,
            ],
            d,
        )
    };
    // A FIFO without a reader, directly or through a link, as eval's and merge's output:
    // refused at once, by name, and still a FIFO.
    mkfifo(&d.join("fifo.csv"));
    symlink("fifo.csv", d.join("to_fifo.csv")).unwrap();
    mkfifo(&d.join("fifo.exr"));
    render_ok(&["--out", "piece.exr", "--sums", "--quiet"], d);
    let eval_into = |output| {
        vec![
            "bcsdf", "eval", "--model", "Chiang()", "--input", "dirs.csv", "--output", output,
        ]
    };
    for (args, name) in [
        (eval_into("fifo.csv"), "fifo.csv"),
        (eval_into("to_fifo.csv"), "to_fifo.csv"),
        (
            vec!["merge", "fifo.exr", "piece.exr", "--no-preview", "--quiet"],
            "fifo.exr",
        ),
    ] {
        assert_fails_in(d, &args, &[name, "no process is reading"]);
    }
    for fifo in ["fifo.csv", "fifo.exr"] {
        assert!(std::fs::metadata(d.join(fifo))
            .unwrap()
            .file_type()
            .is_fifo());
    }
    assert!(is_symlink(&d.join("to_fifo.csv")));
    // With a reader, the reader gets the whole output through the link.
    let mut reader = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(d.join("fifo.csv"))
        .unwrap();
    let o = eval("to_fifo.csv");
    assert!(o.status.success(), "{}", stderr(&o));
    let mut got = String::new();
    std::io::Read::read_to_string(&mut reader, &mut got).unwrap();
    assert!(
        got.starts_with("f_r,f_g,f_b,pdf\n") && got.lines().count() == 2,
        "{got}"
    );
    // `/dev/stdout` redirected to a file: written where the shell's own writes go, between
    // them (a rename, or opening the path again, lost or overwrote them).
    let log = d.join("log.txt");
    let ran = std::process::Command::new("sh")
        .arg("-c")
        .arg(
            "echo before; \"$0\" bcsdf eval --model 'Chiang()' --input dirs.csv \
             --output /dev/stdout; echo after",
        )
        .arg(env!("CARGO_BIN_EXE_tress"))
        .current_dir(d)
        .stdout(std::fs::File::create(&log).unwrap())
        .status()
        .unwrap();
    assert!(ran.success());
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(
        text.starts_with("before\nf_r,f_g,f_b,pdf\n") && text.ends_with("\nafter\n"),
        "{text}"
    );
    assert_eq!(text.lines().count(), 4, "{text}");
    // A socket is refused by name.
    let _socket = std::os::unix::net::UnixListener::bind(d.join("socket.csv")).unwrap();
    assert_fails_in(
        d,
        &[
            "bcsdf",
            "eval",
            "--model",
            "Chiang()",
            "--input",
            "dirs.csv",
            "--output",
            "socket.csv",
        ],
        &["socket.csv", "is a socket"],
    );
    // A link to a file replaces the file it names, beside it; a link to nothing yet creates it.
    std::fs::create_dir(d.join("kept")).unwrap();
    std::fs::write(d.join("kept/old.csv"), "old").unwrap();
    symlink("kept/old.csv", d.join("to_old.csv")).unwrap();
    symlink("kept/new.csv", d.join("to_new.csv")).unwrap();
    for link in ["to_old.csv", "to_new.csv"] {
        let o = eval(link);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(is_symlink(&d.join(link)));
    }
    for file in ["kept/old.csv", "kept/new.csv"] {
        let text = std::fs::read_to_string(d.join(file)).unwrap();
        assert!(text.starts_with("f_r,f_g,f_b,pdf\n"), "{file}: {text}");
    }
    assert_eq!(files_in(&d.join("kept")), ["new.csv", "old.csv"]);
    assert!(null_is_a_device());
}

/// No output replaces a file its own command reads, whatever the name it is given under: the
/// same path, `..` segments, a symbolic link or a hard link. Refused by name, before the work,
/// with the input unchanged and nothing written.
#[test]
fn outputs_never_replace_an_input_of_their_command() {
    let scene = SCENE
        .replace("Sky()", "Environment(file: \"maps/sky.exr\")")
        .replace(
            "Procedural(style: Ball, strands: 300, radius: 0.01)",
            "File(\"ball.hair\")",
        );
    let (dir, _) = scene_dir(&scene);
    let d = dir.path();
    std::fs::create_dir_all(d.join("maps/sub")).unwrap();
    write_env_exr(&d.join("maps/sky.exr"), 8, 4);
    let points = [
        [0.0, 0.0, 0.0],
        [0.0, 0.5, 0.0],
        [0.2, 0.0, 0.0],
        [0.2, 0.5, 0.0],
    ];
    let hair = write_hair(b"HAIR", 2, &points, Some(&[1, 1]), None, 0.01);
    std::fs::write(d.join("ball.hair"), hair).unwrap();
    std::fs::write(d.join("dirs.csv"), "0.2,0,0,1,0.5,0,1\n").unwrap();
    let o = tress(&["info", "scene.ron"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    render_ok(&["--out", "piece.exr", "--sums", "--quiet"], d);
    #[cfg(unix)]
    {
        std::fs::hard_link(d.join("scene.ron"), d.join("hard.csv")).unwrap();
        std::fs::hard_link(d.join("piece.exr"), d.join("twin.exr")).unwrap();
        std::os::unix::fs::symlink("scene.ron", d.join("scene_link.exr")).unwrap();
        std::os::unix::fs::symlink("ball.hair", d.join("hair_link.ron")).unwrap();
        std::os::unix::fs::symlink("piece.exr", d.join("piece_link.png")).unwrap();
    }
    let before: Vec<(&str, Vec<u8>)> = [
        "scene.ron",
        "maps/sky.exr",
        "ball.hair",
        "dirs.csv",
        "piece.exr",
    ]
    .into_iter()
    .map(|f| (f, std::fs::read(d.join(f)).unwrap()))
    .collect();
    let model = "Chiang()";
    let mut cases: Vec<(Vec<&str>, &str)> = vec![
        // The environment map, through `..`.
        (
            vec![
                "render",
                "scene.ron",
                "--out",
                "maps/sub/../sky.exr",
                "--quiet",
            ],
            "maps/sky.exr",
        ),
        (
            vec!["calibrate", "scene.ron", "--out", "scene.ron"],
            "scene.ron",
        ),
        (
            vec!["calibrate", "scene.ron", "--out", "./maps/../ball.hair"],
            "ball.hair",
        ),
        (
            vec!["bench", "--scene", "scene.ron", "--csv", "scene.ron"],
            "scene.ron",
        ),
        (
            vec![
                "bcsdf", "eval", "--model", model, "--input", "dirs.csv", "--output", "dirs.csv",
            ],
            "dirs.csv",
        ),
        (
            vec![
                "bcsdf",
                "eval",
                "--model",
                model,
                "--input",
                "maps/../dirs.csv",
                "--output",
                "./dirs.csv",
            ],
            "dirs.csv",
        ),
        (vec!["merge", "piece.exr", "piece.exr"], "piece.exr"),
        (
            vec!["merge", "./maps/../piece.exr", "piece.exr"],
            "piece.exr",
        ),
    ];
    #[cfg(unix)]
    cases.extend([
        // A hard link to the scene as bench's CSV, links to the scene, the hair and a piece.
        (
            vec!["bench", "--scene", "scene.ron", "--csv", "hard.csv"],
            "scene.ron",
        ),
        (
            vec!["render", "scene.ron", "--out", "scene_link.exr", "--quiet"],
            "scene.ron",
        ),
        (
            vec!["calibrate", "scene.ron", "--out", "hair_link.ron"],
            "ball.hair",
        ),
        (vec!["merge", "twin.exr", "piece.exr"], "piece.exr"),
        (
            vec!["diff", "piece.exr", "piece.exr", "--map", "piece_link.png"],
            "piece.exr",
        ),
    ]);
    for (args, input) in cases {
        let out = args[args
            .iter()
            .position(|a| a.starts_with("--out") || *a == "--csv" || *a == "--map")
            .map_or(1, |i| i + 1)];
        assert_fails_in(d, &args, &[out, input, "an input of this command"]);
        for (file, bytes) in &before {
            assert_eq!(
                &std::fs::read(d.join(file)).unwrap(),
                bytes,
                "{args:?} changed {file}"
            );
        }
    }
}
