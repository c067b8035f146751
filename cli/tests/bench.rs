//! `tress bench --quick` end to end: the table's columns and sections, the CSV beside it, and
//! clear errors. No timing is checked (the machine is shared and noisy).

use crate::common::{stderr, tress};
use std::collections::BTreeSet;

const COLUMNS: [&str; 7] = [
    "model", "section", "metric", "threads", "value", "unit", "note",
];

/// Splits one CSV line (quoted fields may hold commas and doubled quotes).
fn csv_fields(line: &str) -> Vec<String> {
    let mut fields = vec![String::new()];
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                fields.last_mut().unwrap().push('"');
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(String::new()),
            _ => fields.last_mut().unwrap().push(c),
        }
    }
    fields
}

#[test]
fn quick_bench_prints_and_writes_the_table() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such.hair");
    let out = tress(
        &[
            "bench",
            "--quick",
            "--threads",
            "2",
            "--csv",
            "bench.csv",
            "--hair-file",
            missing.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let header: Vec<&str> = stdout.lines().next().unwrap().split_whitespace().collect();
    assert_eq!(header, COLUMNS);

    let csv = std::fs::read_to_string(dir.path().join("bench.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), COLUMNS.join(","));
    let rows: Vec<Vec<String>> = lines.map(csv_fields).collect();
    // The printed table and the CSV hold the same rows.
    assert_eq!(rows.len() + 1, stdout.lines().count());
    let mut metrics = BTreeSet::new();
    for row in &rows {
        assert_eq!(row.len(), COLUMNS.len(), "{row:?}");
        let (model, section, metric, threads, value) =
            (&row[0], &row[1], &row[2], &row[3], &row[4]);
        assert!(!model.is_empty() && !metric.is_empty(), "{row:?}");
        assert!(
            ["build", "raw", "integrator", "scaling", "bcsdf"].contains(&section.as_str()),
            "{row:?}"
        );
        assert!(
            threads.is_empty() || ["1", "2"].contains(&threads.as_str()),
            "{row:?}"
        );
        if value.is_empty() {
            // Only notes carry no value: here, the missing hair file.
            assert_eq!(metric, "skipped", "{row:?}");
            assert!(row[6].contains("no-such.hair"), "{row:?}");
        } else {
            let v: f64 = value.parse().unwrap_or_else(|_| panic!("{row:?}"));
            assert!(v.is_finite() && v >= 0.0, "{row:?}");
        }
        metrics.insert((
            model.clone(),
            section.clone(),
            metric.clone(),
            threads.clone(),
        ));
    }
    let has = |model: &str, section: &str, metric: &str, threads: &str| {
        metrics.contains(&(model.into(), section.into(), metric.into(), threads.into()))
    };
    for model in ["1k", "10k"] {
        for m in [
            "load",
            "bvh",
            "grid",
            "load+bvh+grid",
            "accel_bytes_per_segment",
        ] {
            assert!(has(model, "build", m, ""), "{model} {m}");
        }
        for threads in ["1", "2"] {
            for kind in ["camera", "bounce", "shadow"] {
                for mode in ["embree1", "embree8", "accel"] {
                    assert!(has(model, "raw", &format!("{kind}/{mode}"), threads));
                }
            }
            assert!(has(model, "raw", "bounce/embree1-excl", threads));
            for integrator in ["path", "dual-uniform", "dual-mis"] {
                for m in [
                    "samples_per_s",
                    "rays_per_s",
                    "mix_shadow",
                    "ratio_vs_embree1",
                ] {
                    assert!(has(
                        model,
                        "integrator",
                        &format!("{integrator}/{m}"),
                        threads
                    ));
                }
            }
        }
        assert!(has(model, "scaling", "path/speedup", "2"));
    }
    assert!(has("10k/1k", "scaling", "path/time_per_sample_ratio", "1"));
    for model in ["Chiang", "DEon", "Marschner", "LambertianFiber"] {
        let evals = rows
            .iter()
            .filter(|r| r[0].starts_with(&format!("{model}/")) && r[2] == "eval")
            .count();
        assert_eq!(evals, 1, "{model}");
    }
    // The mix fractions of a render add up to one.
    let mix: f64 = rows
        .iter()
        .filter(|r| r[0] == "10k" && r[3] == "1" && r[2].starts_with("path/mix_"))
        .map(|r| r[4].parse::<f64>().unwrap())
        .sum();
    assert!((mix - 1.0).abs() < 1e-3, "{mix}");
}

#[test]
fn zero_threads_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = tress(&["bench", "--quick", "--threads", "0"], dir.path());
    assert!(!out.status.success());
    assert!(stderr(&out).contains("--threads"));
}

#[test]
fn a_scene_is_benchmarked_against_embree_alone_on_its_own_rays() {
    let dir = tempfile::tempdir().unwrap();
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/demo.ron");
    let out = tress(
        &[
            "bench",
            "--quick",
            "--threads",
            "2",
            "--scene",
            scene.to_str().unwrap(),
            "--spp",
            "1",
            "--csv",
            "scene.csv",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let csv = std::fs::read_to_string(dir.path().join("scene.csv")).unwrap();
    let rows: Vec<Vec<String>> = csv.lines().skip(1).map(csv_fields).collect();
    let value = |metric: &str, threads: &str| -> f64 {
        let row = rows
            .iter()
            .find(|r| {
                r[0] == "demo.ron" && r[1] == "integrator" && r[2] == metric && r[3] == threads
            })
            .unwrap_or_else(|| panic!("no {metric} on {threads} thread(s) in\n{csv}"));
        row[4].parse().unwrap()
    };
    for threads in ["1", "2"] {
        // The scene's own integrator: the demo's path tracer.
        assert!(value("path/samples_per_s", threads) > 0.0);
        for mode in [
            "plain",
            "plain-past-fiber",
            "embree1",
            "embree1-excl",
            "accel",
        ] {
            let ratio = value(&format!("path/ratio_vs_replay_{mode}"), threads);
            assert!(ratio.is_finite() && ratio > 0.0, "{mode}: {ratio}");
        }
        // The demo's sky is sampled by next-event estimation: shadow rays are in the mix.
        let mix: Vec<f64> = ["camera", "bounce", "shadow"]
            .iter()
            .map(|k| value(&format!("path/mix_{k}"), threads))
            .collect();
        assert!((mix.iter().sum::<f64>() - 1.0).abs() < 1e-3, "{mix:?}");
        assert!(mix.iter().all(|&m| m > 0.0), "{mix:?}");
    }
    // Only the scene is measured: no built-in model, no BCSDF table.
    assert!(rows.iter().all(|r| r[0] == "demo.ron"), "{csv}");

    let missing = tress(&["bench", "--scene", "no-such.ron"], dir.path());
    assert!(!missing.status.success());
    assert!(
        stderr(&missing).contains("no-such.ron"),
        "{}",
        stderr(&missing)
    );
}
