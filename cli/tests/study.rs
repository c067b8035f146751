//! `tress study` and `tress diff` end to end: outputs, resumption, determinism, convergence,
//! hand-computed metrics and clear errors for bad input.

use crate::common::{stderr, to_file, tress};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Output;
use tress_core::image_io;
use tress_core::Image;

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A small inline scene: a ball of hair under the built-in sky.
const SCENE: &str = r#"(
    camera: (look_from: (0, 0, 4), look_at: (0, 0, 0), fov: 35),
    film: (width: 20, height: 20),
    materials: {
        "hair": Hair(Chiang(beta_m: 0.3, beta_n: 0.3, pigment: Melanin(eumelanin: 0.2))),
    },
    objects: [Hair(source: Procedural(style: Ball, strands: 200, radius: 0.012), material: "hair")],
    lights: [Sky()],
)"#;

/// A path-tracer-only study with a truncated (biased: light hair scatters many times) path
/// tracer beside the full one.
fn study_text(extra: &str) -> String {
    format!(
        r#"(
    name: "test study",
    scenes: [Inline(name: "ball", scene: {SCENE})],
    integrators: [Path(max_depth: 20), Path(max_depth: 1)],
    spp: [1, 4, 16, 64],
    repetitions: 3,
    seed: 5,
    reference: Render(integrator: Path(max_depth: 20), spp: 512),
    references: PerIntegrator(spp: 512),
    regions: [(name: "centre", x: 6, y: 6, w: 8, h: 8)],
    {extra}
)"#
    )
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// results.csv as (header, rows of fields).
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_owned)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    (header, rows)
}

fn column(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
}

/// `rendered N, reused M` from the summary line.
fn counts(o: &Output) -> (usize, usize) {
    let e = stderr(o);
    let num = |key: &str| -> usize {
        let i = e.find(key).unwrap_or_else(|| panic!("no '{key}' in {e}")) + key.len();
        e[i..]
            .chars()
            .take_while(char::is_ascii_digit)
            .collect::<String>()
            .parse()
            .unwrap()
    };
    (num("rendered "), num("reused "))
}

fn modified_times(dir: &Path) -> BTreeMap<PathBuf, std::time::SystemTime> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path();
            let t = std::fs::metadata(&p).unwrap().modified().unwrap();
            (p, t)
        })
        .collect()
}

#[test]
fn study_end_to_end_resumable_and_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "s.ron", &study_text(""));
    let o = tress(&["study", "s.ron", "--out", "a"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    // 2 integrators × 4 spp × 3 repetitions, plus the common reference and two own references
    // (the full path tracer's own reference is the common one).
    assert_eq!(counts(&o), (2 + 24, 1));
    let out = dir.path().join("a");

    // One row per render and reference kind, with the region's columns.
    let (header, rows) = read_csv(&out.join("results.csv"));
    for c in [
        "scene",
        "integrator",
        "spp",
        "rep",
        "seed",
        "cpu_s",
        "wall_s",
        "precompute_s",
        "rays",
        "reference",
    ] {
        column(&header, c);
    }
    for c in [
        "mse",
        "relmse",
        "mean",
        "centre_mse",
        "centre_relmse",
        "centre_mean",
    ] {
        column(&header, c);
    }
    assert_eq!(rows.len(), 2 * 4 * 3 * 2);
    assert!(rows.iter().all(|r| r.len() == header.len()));
    let (ci, cs, cr, ck) = (
        column(&header, "integrator"),
        column(&header, "spp"),
        column(&header, "rep"),
        column(&header, "reference"),
    );
    let mut combos: Vec<String> = rows
        .iter()
        .map(|r| format!("{} {} {} {}", r[ci], r[cs], r[cr], r[ck]))
        .collect();
    combos.sort();
    combos.dedup();
    assert_eq!(combos.len(), rows.len(), "duplicate rows");
    assert!(rows
        .iter()
        .all(|r| ["path-1", "path-2"].contains(&r[ci].as_str())));
    // Independent seeds for every render.
    let cseed = column(&header, "seed");
    let mut seeds: Vec<&str> = rows
        .iter()
        .filter(|r| r[ck] == "common")
        .map(|r| r[cseed].as_str())
        .collect();
    seeds.sort();
    seeds.dedup();
    assert_eq!(seeds.len(), 24);

    // The path tracer's MSE (mean over repetitions) falls with spp, about as 1/N.
    let cmse = column(&header, "mse");
    let mean_mse = |integrator: &str, spp: &str| -> f64 {
        let v: Vec<f64> = rows
            .iter()
            .filter(|r| r[ci] == integrator && r[cs] == spp && r[ck] == "common")
            .map(|r| r[cmse].parse().unwrap())
            .collect();
        assert_eq!(v.len(), 3);
        v.iter().sum::<f64>() / 3.0
    };
    let m: Vec<f64> = ["1", "4", "16", "64"]
        .iter()
        .map(|s| mean_mse("path-1", s))
        .collect();
    assert!(m.windows(2).all(|w| w[0] > w[1]), "MSE by spp: {m:?}");
    // From 4 spp: at 1 spp three repetitions under the sky's sun are too heavy-tailed to
    // average (1 → 64 spp measured 15× with these seeds, 42× with twelve repetitions).
    assert!(
        m[1] / m[3] > 8.0,
        "16× the samples should cut the MSE well below an 8th: {m:?}"
    );

    // Report, summary, plots, heat map and crop sheets.
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    for needle in [
        "## Scene `ball`",
        "## Summary",
        "| ball | path-2 |",
        "MSE ratio at equal spp",
        "MSE ratio at equal time",
        "efficiency",
        "Convergence verdicts",
        "relMSE = mean (I − R)² / (R² + ε) with ε = 0.01",
    ] {
        assert!(
            report.contains(needle),
            "report lacks '{needle}':\n{report}"
        );
    }
    // The full path tracer is unbiased: its verdict may be flat or, with 3 repetitions of
    // heavy-tailed light paths, excess variance, but never bias…
    assert!(
        report.contains("`path-1` vs common reference: ")
            && !report.contains("`path-1` vs common reference: **bias**"),
        "{report}"
    );
    // …while single scattering misses the light hair's multiple scattering: flagged as bias.
    assert!(
        report.contains("`path-2` vs common reference: **bias**"),
        "{report}"
    );
    assert!(out.join("summary.csv").exists());
    for f in [
        "plots/ball_convergence",
        "plots/ball_convergence_own",
        "plots/ball_centre_convergence",
    ] {
        for ext in ["png", "svg"] {
            let p = out.join(format!("{f}.{ext}"));
            assert!(p.exists(), "{} missing", p.display());
        }
    }
    for f in ["plots/ball_heatmap_16spp.png", "sheets/ball_centre.png"] {
        let bytes = std::fs::read(out.join(f)).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{f} is not a PNG");
    }

    // The renders carry their cost, and a rerun reads every one back without rendering.
    let renders = out.join("renders/ball");
    let (_, attrs) = image_io::read_exr(renders.join("path-1_00004spp_rep02.exr")).unwrap();
    for key in ["tress:render_time_s", "tress:render_cpu_s", "tress:rays"] {
        assert!(attrs.iter().any(|(k, _)| k == key), "{key} missing");
    }
    let before = modified_times(&renders);
    let o = tress(&["study", "s.ron", "--out", "a"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(counts(&o), (0, 27));
    assert_eq!(before, modified_times(&renders));
    let (_, rows_again) = read_csv(&out.join("results.csv"));
    assert_eq!(
        rows, rows_again,
        "reused renders must give the same results"
    );

    // A missing render is redone, alone.
    std::fs::remove_file(renders.join("path-2_00016spp_rep01.exr")).unwrap();
    let o = tress(&["study", "s.ron", "--out", "a", "--quiet"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(renders.join("path-2_00016spp_rep01.exr").exists());
    let (_, rows_again) = read_csv(&out.join("results.csv"));
    let timings = [
        column(&header, "cpu_s"),
        column(&header, "wall_s"),
        column(&header, "precompute_s"),
    ];
    let strip = |rows: &[Vec<String>]| -> Vec<Vec<String>> {
        rows.iter()
            .map(|r| {
                let mut r = r.clone();
                for c in timings {
                    r[c].clear();
                }
                r
            })
            .collect()
    };
    assert_eq!(strip(&rows), strip(&rows_again), "re-render differs");

    // A fresh run elsewhere gives identical errors (only the timings differ).
    let o = tress(&["study", "s.ron", "--out", "b", "--quiet"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let (_, fresh) = read_csv(&dir.path().join("b/results.csv"));
    assert_eq!(strip(&rows), strip(&fresh), "fresh run differs");

    // Changed settings invalidate exactly the affected renders: one more repetition…
    let more = study_text("").replace("repetitions: 3", "repetitions: 4");
    write(dir.path(), "s.ron", &more);
    let o = tress(&["study", "s.ron", "--out", "a"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(counts(&o), (2 * 4, 27));
    // …or other settings for the second integrator: its renders and its own reference.
    write(
        dir.path(),
        "s.ron",
        &more.replace("Path(max_depth: 1)", "Path(max_depth: 2)"),
    );
    let o = tress(&["study", "s.ron", "--out", "a"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(counts(&o), (4 * 4 + 1, 4 * 4 + 2));
    assert!(
        stderr(&o).contains("made with other settings"),
        "{}",
        stderr(&o)
    );
}

/// Ignored by default: building the two dual-scattering integrators' tables takes seconds.
#[test]
#[ignore]
fn shipped_quick_study_runs() {
    let dir = tempfile::tempdir().unwrap();
    let study = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/studies/quick.ron");
    let o = tress(
        &["study", study.to_str().unwrap(), "--out", "q", "--quick"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = dir.path().join("q");
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("## Scene `ball`"), "{report}");
    let (header, rows) = read_csv(&out.join("results.csv"));
    // --quick keeps at most 3 of the 4 repetitions.
    let cr = column(&header, "rep");
    assert!(rows.iter().all(|r| r[cr].parse::<u32>().unwrap() < 3));
    assert!(out.join("plots/ball_heatmap_4spp.png").exists());
}

/// The hair-colour studies under the sunset (with the default dual scattering, with a traced
/// hair bounce, and the light hair taken to 256 spp) and under a directional light: every
/// colour and groom renders and reaches the report. This checks plumbing, so each study runs as
/// a copy lighter than its own quick variant (`lighter_study`): 89 CPU-s for the four as
/// shipped, 14 so.
/// Needs ../shared/data for straight.hair and the sunset's map.
#[test]
#[ignore = "needs ../shared/data (the real groom): CI runs it with --ignored"]
fn shared_data_hair_colour_quick_studies_run() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let data = root.join("../shared/data");
    assert!(
        data.exists(),
        "{} is absent: this test needs the real data set beside the workspace",
        data.display()
    );
    let studies = root.join("scenes/studies");
    let all_colours: &[&str] = &["platinum", "blond", "brown", "dark"];
    for (name, colours) in [
        ("hair_colour", all_colours),
        ("hair_colour_sun", all_colours),
        ("hair_colour_path_bounces", all_colours),
        ("hair_colour_light_256", &["platinum", "blond"][..]),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let shipped = std::fs::read_to_string(studies.join(format!("{name}.ron"))).unwrap();
        write(dir.path(), "study.ron", &lighter_study(&shipped, &studies));
        let o = tress(
            &["study", "study.ron", "--out", "hc", "--quick", "--quiet"],
            dir.path(),
        );
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let report = std::fs::read_to_string(dir.path().join("hc/report.md")).unwrap();
        for groom in ["straight", "head"] {
            for colour in colours {
                assert!(
                    report.contains(&format!("## Scene `{groom}_{colour}`")),
                    "{name}: {groom}_{colour} missing"
                );
            }
        }
        let (header, rows) = read_csv(&dir.path().join("hc/summary.csv"));
        let integrator = column(&header, "integrator");
        assert!(rows.iter().any(|r| r[integrator] == "dual-mis"), "{name}");
    }
}

/// `study`, the text of a study file in `dir`, made cheap to run with `--quick` from another
/// folder: its scene files named by absolute path, its quick section replaced by 12² films, 1
/// and 2 spp and references of 8 spp, and its dual-scattering integrators given coarse tables
/// (16 θ nodes, 1024 walks; building the default ones took most of the time, and tress-materials
/// checks the defaults against the table limits).
fn lighter_study(study: &str, dir: &Path) -> String {
    let open = study
        .find("quick: (")
        .expect("the study has a quick section")
        + "quick: ".len();
    let mut depth = 0;
    let close = study[open..]
        .char_indices()
        .find_map(|(i, c)| {
            depth += match c {
                '(' => 1,
                ')' => -1,
                _ => 0,
            };
            (depth == 0).then_some(open + i)
        })
        .expect("the quick section closes");
    let quick = "(spp: [1, 2], repetitions: 2, reference_spp: 8, per_integrator_spp: 8, \
                 film: (width: 12, height: 12))";
    let coarse = "tables: (theta_nodes: 16, walks: 1024), ";
    format!("{}{quick}{}", &study[..open], &study[close + 1..])
        .replace("DualMis(", &format!("DualMis({coarse}"))
        .replace("DualUniform(", &format!("DualUniform({coarse}"))
        .replace("File(\"", &format!("File(\"{}/", dir.display()))
}

#[test]
fn quick_flag_scales_the_study_down() {
    let dir = tempfile::tempdir().unwrap();
    // Single scattering only, to keep it fast.
    let text = study_text("film: (width: 96, height: 72),")
        .replace("spp: [1, 4, 16, 64]", "spp: [1, 4, 16, 64, 256]")
        .replace("repetitions: 3", "repetitions: 8")
        .replace("spp: 512)", "spp: 4096)")
        .replace("Path(max_depth: 20)", "Path(max_depth: 1)")
        .replace(
            "integrators: [Path(max_depth: 1), Path(max_depth: 1)]",
            "integrators: [Path(max_depth: 1)]",
        )
        .replace("x: 6, y: 6, w: 8, h: 8", "x: 48, y: 36, w: 30, h: 18");
    write(dir.path(), "big.ron", &text);
    let o = tress(&["study", "big.ron", "--quick", "--quiet"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    // Default output folder, marked as quick.
    let out = dir.path().join("big_study_quick");
    let (header, rows) = read_csv(&out.join("results.csv"));
    let (cs, cr) = (column(&header, "spp"), column(&header, "rep"));
    let mut spp: Vec<u32> = rows.iter().map(|r| r[cs].parse().unwrap()).collect();
    spp.dedup();
    assert_eq!(spp, [1, 4, 16]);
    assert!(rows.iter().all(|r| r[cr].parse::<u32>().unwrap() < 3));
    // Films shrink to 64 pixels a side, and the region with them.
    let (img, attrs) =
        image_io::read_exr(out.join("renders/ball/path_00001spp_rep00.exr")).unwrap();
    assert_eq!((img.width, img.height), (64, 48));
    let refs: Vec<PathBuf> = std::fs::read_dir(out.join("references/ball"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "exr"))
        .collect();
    // The common reference is also the integrator's own.
    assert_eq!(refs.len(), 1, "{refs:?}");
    for r in &refs {
        let (_, attrs) = image_io::read_exr(r).unwrap();
        let spp = attrs.iter().find(|(k, _)| k == "tress:spp").unwrap();
        assert_eq!(spp.1, "256", "quick reference spp: min(4096, 16 × 16)");
    }
    assert!(attrs.iter().any(|(k, v)| k == "tress:spp" && v == "1"));
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("centre (20x12 at (32, 24))"), "{report}");
}

#[test]
fn exr_reference_and_mismatches() {
    let dir = tempfile::tempdir().unwrap();
    // A reference rendered by `tress render` for the scene "ball".
    let scene = SCENE.replace(
        "film: (width: 20, height: 20)",
        "film: (width: 20, height: 20, spp: 64, seed: 99)",
    );
    write(dir.path(), "ball.ron", &scene);
    let o = tress(
        &["render", "ball.ron", "--out", "refs/ball.exr", "--quiet"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let text = r#"(
    scenes: [File("ball.ron")],
    integrators: [Path()],
    spp: [1, 2],
    repetitions: 2,
    reference: Exr("refs/{scene}.exr"),
)"#
    .to_string();
    write(dir.path(), "exr.ron", &text);
    let o = tress(&["study", "exr.ron", "--out", "o", "--quiet"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let (_, rows) = read_csv(&dir.path().join("o/results.csv"));
    assert_eq!(rows.len(), 4);

    // A film override that no longer matches the reference: both files are named.
    write(
        dir.path(),
        "exr.ron",
        &text.replace(
            "repetitions: 2,",
            "repetitions: 2, film: (width: 16, height: 20),",
        ),
    );
    let o = tress(&["study", "exr.ron", "--out", "o"], dir.path());
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("refs/ball.exr") && e.contains("ball.ron") && e.contains("16x20"),
        "{e}"
    );
}

fn constant_image(w: u32, h: u32, c: [f32; 3]) -> Image {
    Image::from_fn(w, h, |_, _| glam::Vec3::from(c))
}

/// The numbers of the `all` row of `tress diff`: MSE, relMSE, PSNR, mean(A−B), mean(A), mean(B).
fn diff_all(o: &Output) -> Vec<f64> {
    let out = stdout(o);
    let line = out
        .lines()
        .find(|l| l.starts_with("all"))
        .unwrap_or_else(|| panic!("no 'all' row in:\n{out}"));
    // The SSIM column after them reads "n/a" for images under its 11x11 window.
    line.split_whitespace()
        .skip(1)
        .take(6)
        .map(|v| v.parse().unwrap())
        .collect()
}

#[test]
fn diff_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    // B: 1 everywhere; A: B + 0.5 in the red channel of the left column only.
    let b = constant_image(2, 2, [1.0, 1.0, 1.0]);
    let mut a = b.clone();
    a.set(0, 0, glam::Vec3::new(1.5, 1.0, 1.0));
    a.set(0, 1, glam::Vec3::new(1.5, 1.0, 1.0));
    to_file(p("a.exr"), |o| image_io::write_exr(o, &a, &[])).unwrap();
    to_file(p("b.exr"), |o| image_io::write_exr(o, &b, &[])).unwrap();

    let o = tress(&["diff", "b.exr", "b.exr"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let all = diff_all(&o);
    assert_eq!((all[0], all[1], all[3]), (0.0, 0.0, 0.0));
    assert!(all[2].is_infinite(), "PSNR of identical images: {all:?}");

    let o = tress(
        &[
            "diff",
            "a.exr",
            "b.exr",
            "--map",
            "map.png",
            "--map-kind",
            "rel",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let all = diff_all(&o);
    // Two of the 12 pixel-channels are off by 0.5: MSE = 2 · 0.25 / 12.
    let mse = 2.0 * 0.25 / 12.0;
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-6 * y.abs().max(1e-12);
    assert!(close(all[0], mse), "{all:?}");
    assert!(close(all[1], mse / 1.01), "{all:?}");
    // PSNR is printed to 1e-3 dB.
    assert!(
        (all[2] - 10.0 * (1.0 / mse).log10()).abs() < 1e-3,
        "{all:?}"
    );
    assert!(close(all[3], 2.0 * 0.5 / 12.0), "{all:?}");
    let red = stdout(&o)
        .lines()
        .find(|l| l.starts_with('R'))
        .map(|l| l.split_whitespace().nth(1).unwrap().parse::<f64>().unwrap())
        .unwrap();
    assert!(close(red, 0.125), "red MSE {red}");
    let png = std::fs::read(p("map.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");

    // The right column only: no difference.
    let o = tress(
        &["diff", "a.exr", "b.exr", "--region", "1,0,1,2"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(diff_all(&o)[0], 0.0);

    // Mismatches name both files.
    to_file(p("c.exr"), |o| {
        image_io::write_exr(o, &constant_image(3, 2, [1.0; 3]), &[])
    })
    .unwrap();
    let o = tress(&["diff", "a.exr", "c.exr"], dir.path());
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("a.exr") && e.contains("c.exr") && e.contains("3x2"),
        "{e}"
    );
    let o = tress(
        &["diff", "a.exr", "b.exr", "--region", "1,1,2,2"],
        dir.path(),
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("region 2x2 at (1, 1)"),
        "{}",
        stderr(&o)
    );
    let o = tress(&["diff", "a.exr", "missing.exr"], dir.path());
    assert!(!o.status.success());
    assert!(stderr(&o).contains("missing.exr"), "{}", stderr(&o));
}

#[test]
fn bad_study_files_are_reported_with_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = study_text("");
    // (text replaced in the good study, its replacement, what the message must say)
    let cases = [
        ("seed: 5,", "seed: 5, colour: 3,", "colour"),
        ("Path(max_depth: 1)", "Bogus()", "Bogus"),
        ("spp: [1, 4, 16, 64]", "spp: []", "spp: the list is empty"),
        ("spp: [1, 4, 16, 64]", "spp: [4, 1]", "strictly increasing"),
        ("spp: [1, 4, 16, 64]", "spp: [0, 1]", "strictly increasing"),
        ("repetitions: 3", "repetitions: 0", "repetitions"),
        (
            "x: 6, y: 6, w: 8, h: 8",
            "x: 16, y: 6, w: 8, h: 8",
            "'centre'",
        ),
        (
            "regions: [",
            r#"regions: [(name: "centre", x: 0, y: 0, w: 1, h: 1), "#,
            "defined twice",
        ),
        ("name: \"centre\"", "name: \"a b\"", "letters, digits"),
        ("seed: 5,", "seed: 5, heatmap_spp: 8,", "heatmap_spp = 8"),
        (
            r#"Inline(name: "ball", scene: "#,
            r#"File("nope.ron"), Inline(name: "ball", scene: "#,
            "nope.ron",
        ),
        ("Path(max_depth: 1)", "Path(max_depth: 20)", "listed twice"),
        ("spp: 512)", "spp: 0)", "spp must be at least 1"),
    ];
    for (i, (from, to, needle)) in cases.into_iter().enumerate() {
        let name = format!("bad{i}.ron");
        write(dir.path(), &name, &good.replace(from, to));
        let o = tress(&["study", &name, "--out", "o"], dir.path());
        assert!(!o.status.success(), "case {i} ({needle}) was accepted");
        let e = stderr(&o);
        assert!(
            e.contains(&name) && e.contains(needle),
            "case {i}: expected the file name and '{needle}' in: {e}"
        );
        assert!(!e.contains("panicked"), "case {i}: {e}");
    }
    let o = tress(&["study", "absent.ron"], dir.path());
    assert!(!o.status.success());
    assert!(stderr(&o).contains("absent.ron"));
}

/// The render cache is keyed on the contents of the files a scene reads: replacing an
/// environment map by another of the same name redoes every render (it reused them, and the
/// report showed the old numbers).
#[test]
fn the_cache_follows_the_contents_of_referenced_files() {
    let dir = tempfile::tempdir().unwrap();
    let write_env = |radiance: f32| {
        let mut img = Image::new(8, 4);
        img.pixels
            .iter_mut()
            .for_each(|p| *p = tress_core::Rgb::splat(radiance));
        to_file(dir.path().join("env.exr"), |o| {
            image_io::write_exr(o, &img, &[])
        })
        .unwrap();
    };
    write_env(1.0);
    let scene = SCENE.replace(
        "lights: [Sky()]",
        r#"lights: [Environment(file: "env.exr")]"#,
    );
    let text = format!(
        r#"(
    scenes: [Inline(name: "ball", scene: {scene})],
    integrators: [Path(max_depth: 5)],
    spp: [1, 2],
    repetitions: 2,
    reference: Render(integrator: Path(max_depth: 5), spp: 8),
)"#
    );
    write(dir.path(), "s.ron", &text);
    let run = || {
        let o = tress(&["study", "s.ron", "--out", "out"], dir.path());
        assert!(o.status.success(), "{}", stderr(&o));
        counts(&o)
    };
    let (made, _) = run();
    assert!(made > 0);
    assert_eq!(run().0, 0, "an unchanged study reuses every render");
    write_env(50.0);
    assert_eq!(
        run().0,
        made,
        "a replaced environment map redoes every render"
    );
    // A cached render whose pixels were edited, its attributes kept, is rendered again.
    let mut exrs = Vec::new();
    let mut stack = vec![dir.path().join("out")];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "exr") {
                exrs.push(p);
            }
        }
    }
    exrs.sort();
    let edited = exrs
        .iter()
        .find(|p| {
            image_io::read_exr(p)
                .unwrap()
                .1
                .iter()
                .any(|(k, _)| k == "tress:pixels_hash")
        })
        .expect("a cached render");
    let (mut img, attrs) = image_io::read_exr(edited).unwrap();
    img.pixels[0] *= 2.0;
    let attrs: Vec<(&str, String)> = attrs.iter().map(|(k, v)| (k.as_str(), v.clone())).collect();
    to_file(edited, |o| image_io::write_exr(o, &img, &attrs)).unwrap();
    assert_eq!(run().0, 1, "the edited render, and only it, is redone");
}
