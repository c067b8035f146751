//! The `tress` binary end to end: rendering, outputs, and clear errors for bad input.

use crate::common::{files_in, pixels, render_ok, scene_dir, stderr, tress, SCENE};
use std::path::Path;

#[test]
fn renders_exr_and_png_with_metadata() {
    let (dir, _) = scene_dir(SCENE);
    let o = tress(
        &["render", "scene.ron", "--out", "out/img.exr", "--quiet"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let (image, attrs) = tress_core::image_io::read_exr(dir.path().join("out/img.exr")).unwrap();
    assert_eq!((image.width, image.height), (24, 20));
    assert!(image.mean() > 0.0);
    let get = |k: &str| attrs.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
    assert_eq!(get("tress:spp").as_deref(), Some("6"));
    assert_eq!(get("tress:seed").as_deref(), Some("3"));
    assert!(get("tress:integrator").unwrap().contains("Path"));
    assert!(get("tress:render_time_s").is_some());
    assert!(dir.path().join("out/img.png").exists());
}

#[test]
fn command_line_overrides_and_crop() {
    let (dir, _) = scene_dir(SCENE);
    let o = tress(
        &[
            "render",
            "scene.ron",
            "--out",
            "c.exr",
            "--spp",
            "3",
            "--seed",
            "9",
            "--crop",
            "4,2,20,18",
            "--threads",
            "1",
            "--integrator",
            "Path(max_depth: 5)",
            "--quiet",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let (image, attrs) = tress_core::image_io::read_exr(dir.path().join("c.exr")).unwrap();
    assert_eq!(
        (image.x0, image.y0, image.width, image.height),
        (4, 2, 16, 16)
    );
    assert_eq!((image.full_width, image.full_height), (24, 20));
    assert!(attrs.iter().any(|(k, v)| k == "tress:spp" && v == "3"));
}

#[test]
fn film_size_overrides() {
    let (dir, _) = scene_dir(SCENE);
    render_ok(
        &[
            "--out", "w.exr", "--width", "40", "--height", "10", "--quiet",
        ],
        dir.path(),
    );
    let (image, _) = tress_core::image_io::read_exr(dir.path().join("w.exr")).unwrap();
    assert_eq!((image.width, image.height), (40, 10));
    // Overridden sizes are validated as scene ones are.
    let o = tress(
        &[
            "render",
            "scene.ron",
            "--out",
            "z.exr",
            "--width",
            "0",
            "--quiet",
        ],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("empty"), "{}", stderr(&o));
}

#[test]
fn info_describes_the_scene() {
    let (dir, _) = scene_dir(SCENE);
    let o = tress(&["info", "scene.ron"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("300 strands"), "{out}");
    assert!(out.contains("bounds"), "{out}");
}

/// Each bad scene must fail with a message naming the file and containing `expect`, and must
/// leave no output behind.
fn assert_fails(scene: &str, expect: &[&str]) {
    let (dir, _) = scene_dir(scene);
    let o = tress(
        &["render", "scene.ron", "--out", "bad.exr", "--quiet"],
        dir.path(),
    );
    let err = stderr(&o);
    assert!(!o.status.success(), "expected failure, got success");
    assert!(
        err.contains("scene.ron"),
        "message does not name the file: {err}"
    );
    for e in expect {
        assert!(err.contains(e), "message lacks '{e}': {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        left,
        vec![std::ffi::OsString::from("scene.ron")],
        "output left behind"
    );
}

#[test]
fn bad_scenes_give_clear_errors() {
    // Syntax error: file, line and column.
    assert_fails(&SCENE.replace("fov: 35),", "fov: 35"), &["scene.ron:3:"]);
    // Unknown field.
    assert_fails(&SCENE.replace("seed: 3", "seed: 3, sed: 4"), &["sed"]);
    // Wrong type.
    assert_fails(&SCENE.replace("spp: 6", "spp: \"many\""), &["spp"]);
    // Negative spp does not fit an unsigned count.
    assert_fails(
        &SCENE.replace("spp: 6", "spp: -4"),
        &["out of bounds", "spp"],
    );
    // Zero-size film.
    assert_fails(&SCENE.replace("width: 24", "width: 0"), &["film", "empty"]);
    // fov out of range.
    assert_fails(&SCENE.replace("fov: 35", "fov: 190"), &["fov"]);
    // Roughness outside its domain.
    assert_fails(&SCENE.replace("beta_m: 0.3", "beta_m: 1.7"), &["beta_m"]);
    // Negative absorption.
    assert_fails(
        &SCENE.replace("Melanin(eumelanin: 1.0)", "SigmaA(-0.5, 0.1, 0.1)"),
        &["sigma_a"],
    );
    // Unknown material name.
    assert_fails(
        &SCENE.replace("material: \"grey\"", "material: \"gray\""),
        &["gray"],
    );
    // Missing referenced files.
    assert_fails(
        &SCENE.replace(
            "Procedural(style: Ball, strands: 300, radius: 0.01)",
            "File(\"nowhere.hair\")",
        ),
        &["nowhere.hair"],
    );
    assert_fails(
        &SCENE.replace("Sky()", "Environment(file: \"missing.hdr\")"),
        &["missing.hdr"],
    );
    // Unsupported image.
    let (dir, _) = scene_dir(&SCENE.replace("Sky()", "Environment(file: \"junk.exr\")"));
    std::fs::write(dir.path().join("junk.exr"), b"not an exr").unwrap();
    let o = tress(
        &["render", "scene.ron", "--out", "bad.exr", "--quiet"],
        dir.path(),
    );
    assert!(
        !o.status.success() && stderr(&o).contains("junk.exr"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn bad_arguments_give_clear_errors() {
    let (dir, _) = scene_dir(SCENE);
    let o = tress(
        &["render", "scene.ron", "--integrator", "bogus", "--quiet"],
        dir.path(),
    );
    assert!(
        !o.status.success() && stderr(&o).contains("unknown integrator 'bogus'"),
        "{}",
        stderr(&o)
    );
    let o = tress(
        &["render", "scene.ron", "--crop", "0,0,99,99", "--quiet"],
        dir.path(),
    );
    assert!(
        !o.status.success() && stderr(&o).contains("crop"),
        "{}",
        stderr(&o)
    );
    let o = tress(&["render", "missing.ron"], dir.path());
    assert!(
        !o.status.success() && stderr(&o).contains("missing.ron"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn bcsdf_tools_work() {
    let dir = tempfile::tempdir().unwrap();
    let model = "Chiang(beta_m: 0.3, beta_n: 0.3, pigment: SigmaA(0, 0, 0))";
    let o = tress(
        &[
            "bcsdf",
            "furnace",
            "--model",
            model,
            "--samples",
            "20000",
            "--step",
            "45",
            "--csv",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = String::from_utf8_lossy(&o.stdout);
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 5);
    for r in rows {
        let albedo: f64 = r.split(',').nth(1).unwrap().parse().unwrap();
        assert!((albedo - 1.0).abs() < 0.01, "{r}");
    }
    std::fs::write(
        dir.path().join("dirs.csv"),
        "h,wi_x,wi_y,wi_z,wo_x,wo_y,wo_z\n0.3,0.1,-0.5,0.2,-0.2,0.1,0.9\n",
    )
    .unwrap();
    let o = tress(
        &[
            "bcsdf", "eval", "--model", model, "--input", "dirs.csv", "--output", "f.csv",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = std::fs::read_to_string(dir.path().join("f.csv")).unwrap();
    assert!(
        out.starts_with("f_r,f_g,f_b,pdf\n") && out.lines().count() == 2,
        "{out}"
    );
    let o = tress(
        &[
            "bcsdf",
            "plot",
            "--model",
            model,
            "--theta-o",
            "-20",
            "--out",
            "lobes.png",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.path().join("lobes.png").exists() && dir.path().join("lobes.svg").exists());
    let o = tress(
        &["bcsdf", "furnace", "--model", "Chiang(beta_m: 2)"],
        dir.path(),
    );
    assert!(
        !o.status.success() && stderr(&o).contains("beta_m"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn output_extension_case_does_not_matter() {
    let (dir, _) = scene_dir(SCENE);
    let o = tress(
        &["render", "scene.ron", "--out", "IMG.EXR", "--quiet"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.path().join("IMG.EXR").exists() && dir.path().join("IMG.png").exists());
}

#[test]
fn calibrate_fits_the_density_factors_and_writes_them() {
    let (dir, _) = scene_dir(SCENE);
    let small_tables = "DualMis(tables: (theta_nodes: 16, h_nodes: 8, theta_quad: 16, \
                        phi_quad: 24, walks: 512))";
    // Calibrates with small tables and few samples, writing `out`: stdout, the file's text and
    // the dual-mis settings it holds.
    let calibrate = |extra: &[&str], out: &str| {
        let mut args = vec![
            "calibrate",
            "scene.ron",
            "--integrator",
            small_tables,
            "--reference-spp",
            "16",
            "--spp",
            "8",
            "--out",
            out,
            "--quiet",
        ];
        args.extend_from_slice(extra);
        let o = tress(&args, dir.path());
        assert!(o.status.success(), "{}", stderr(&o));
        let text = std::fs::read_to_string(dir.path().join(out)).unwrap();
        let fitted: tress_loader::integrators::IntegratorDesc = tress_loader::ron_options()
            .from_str(&text)
            .unwrap_or_else(|e| panic!("{e}: {text}"));
        let tress_loader::integrators::IntegratorDesc::DualMis(s) = fitted else {
            panic!("{text}");
        };
        (String::from_utf8_lossy(&o.stdout).into_owned(), text, s)
    };
    let (stdout, text, s) = calibrate(&[], "fit.ron");
    assert!(
        stdout.contains("hair pixels") && stdout.contains("fitted"),
        "{stdout}"
    );
    // Both candidate numbers of traced hair bounces are fitted, and one of them is kept.
    assert!(
        stdout.contains("path_bounces = 0:") && stdout.contains("path_bounces = 1:"),
        "{stdout}"
    );
    for d in [s.d_f.unwrap(), s.d_b.unwrap()] {
        assert!((0.0..=1.0).contains(&d), "{text}");
    }
    assert_eq!(s.tables.walks, 512, "the other settings are kept");
    assert!(
        stdout.contains(&format!("fitted  path_bounces = {}", s.path_bounces)),
        "{stdout}\n{text}"
    );

    // A single candidate is the one kept.
    let (_, text, s) = calibrate(&["--path-bounces", "2"], "fit2.ron");
    assert_eq!(s.path_bounces, 2, "{text}");

    // The path tracer is not what calibration fits; a window with no hair has nothing to fit.
    let o = tress(
        &["calibrate", "scene.ron", "--integrator", "path"],
        dir.path(),
    );
    assert!(!o.status.success() && stderr(&o).contains("dual-scattering integrator"));
    let o = tress(
        &["calibrate", "scene.ron", "--crop", "0,0,2,2", "--quiet"],
        dir.path(),
    );
    assert!(
        !o.status.success() && stderr(&o).contains("no pixel"),
        "{}",
        stderr(&o)
    );
}

/// A fur scene rendered twice with `--table-cache` in a temporary folder: the first run builds
/// the medulla's table and stores it, the second reads it and says so, and both images are the
/// one rendered with `--no-table-cache`, bit for bit. A damaged table file is a warning, printed
/// even with `--quiet`, and is rebuilt.
#[test]
fn render_keeps_the_fur_table_in_the_table_cache() {
    let fur = SCENE.replace(
        "Chiang(beta_m: 0.3, beta_n: 0.3, pigment: Melanin(eumelanin: 1.0))",
        "Fur(medulla_ratio: 0.5, medulla_sigma_s: 3.0, pigment: Melanin(eumelanin: 1.0))",
    );
    assert_ne!(fur, SCENE);
    let (dir, _) = scene_dir(&fur);
    let cache = dir.path().join("tables");
    let cache = cache.to_str().unwrap();
    let run = |args: &[&str], out: &str| {
        let log = render_ok(&[args, &["--out", out]].concat(), dir.path());
        (log, pixels(&dir.path().join(out)))
    };
    let (first, built) = run(&["--table-cache", cache], "first.exr");
    assert!(
        first.contains("fur-medulla table built in") && first.contains(", stored in "),
        "{first}"
    );
    let stored = files_in(Path::new(cache));
    assert!(
        stored.len() == 1 && stored[0].starts_with("fur-medulla-v"),
        "{stored:?}"
    );
    let (second, read) = run(&["--table-cache", cache], "second.exr");
    assert!(second.contains("fur-medulla table read from"), "{second}");
    assert!(!second.contains("table built"), "{second}");
    let (none, uncached) = run(&["--no-table-cache"], "none.exr");
    assert!(
        none.contains("fur-medulla table built in") && !none.contains("stored"),
        "{none}"
    );
    assert_eq!(read, built);
    assert_eq!(uncached, built);

    let file = Path::new(cache).join(&stored[0]);
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..bytes.len() - 100]).unwrap();
    let (quiet, rebuilt) = run(&["--table-cache", cache, "--quiet"], "rebuilt.exr");
    assert!(
        quiet.starts_with("warning: ignoring") && quiet.contains("truncated"),
        "{quiet}"
    );
    assert_eq!(rebuilt, built);
    assert_eq!(std::fs::read(&file).unwrap(), bytes, "stored again");
    let o = tress(
        &[
            "render",
            "scene.ron",
            "--table-cache",
            cache,
            "--no-table-cache",
        ],
        dir.path(),
    );
    assert!(
        !o.status.success() && stderr(&o).contains("cannot be used with"),
        "{}",
        stderr(&o)
    );
}

/// A sun disc narrower than f32 can resolve is a point: with 1e-5°…0.01° (and 1e-30°) the image
/// was black or infinite; now it matches the delta light, and a wide disc stays close to it.
#[test]
fn tiny_sun_discs_render_like_a_point_sun() {
    let mean_with = |radius: &str| {
        let text = SCENE
            .replace("angular_radius: 0.5", &format!("angular_radius: {radius}"))
            .replace("lights: [Sky(), ", "lights: [");
        let (dir, _) = scene_dir(&text);
        let o = tress(
            &[
                "render",
                "scene.ron",
                "--spp",
                "16",
                "--out",
                "o.exr",
                "--quiet",
            ],
            dir.path(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let (image, _) = tress_core::image_io::read_exr(dir.path().join("o.exr")).unwrap();
        image.mean()
    };
    let point = mean_with("0");
    assert!(point > 0.0 && point.is_finite());
    for radius in ["1e-30", "1e-5", "0.001", "0.01"] {
        assert_eq!(mean_with(radius), point, "angular_radius {radius}");
    }
    let disc = mean_with("0.5");
    assert!((disc - point).abs() < 0.05 * point, "{disc} vs {point}");
}

#[test]
fn init_writes_a_starter_scene_that_renders() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = tress(&["init"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = tress(&["info", "scene.ron"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = tress(
        &[
            "render",
            "scene.ron",
            "--spp",
            "1",
            "--width",
            "32",
            "--height",
            "32",
            "--quiet",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("scene.exr").exists() && d.join("scene.png").exists());
    // It does not overwrite.
    let o = tress(&["init"], d);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("not overwritten"), "{}", stderr(&o));
}
