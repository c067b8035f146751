//! `--log-format json`: every command ends with one JSON summary line on stdout, parsable and
//! carrying its results; the readable output stays the default.

use crate::common::{scene_dir, stderr, tress, SCENE};
use serde_json::Value;
use std::process::Output;

/// The last line of stdout as JSON; it must be the only line unless `alone` is false.
fn summary(o: &Output, alone: bool) -> Value {
    let out = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = out.lines().collect();
    if alone {
        assert_eq!(
            lines.len(),
            1,
            "stdout should hold only the summary:\n{out}"
        );
    }
    let last = lines
        .last()
        .unwrap_or_else(|| panic!("no stdout; stderr:\n{}", stderr(o)));
    serde_json::from_str(last).unwrap_or_else(|e| panic!("{e}: {last}"))
}

#[test]
fn diff_reports_its_metrics_as_one_json_line() {
    let (dir, _) = scene_dir(SCENE);
    for (spp, out) in [("2", "a.exr"), ("16", "b.exr")] {
        let o = tress(
            &[
                "render",
                "scene.ron",
                "--spp",
                spp,
                "--out",
                out,
                "--log-format",
                "json",
            ],
            dir.path(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        // No progress bar or readable summary on stderr in JSON mode.
        assert!(!stderr(&o).contains("rendered"), "{}", stderr(&o));
        let v = summary(&o, true);
        assert_eq!(
            (v["command"].as_str(), v["status"].as_str()),
            (Some("render"), Some("ok"))
        );
        assert_eq!(v["spp"].as_u64(), spp.parse().ok(), "{v}");
        assert_eq!(v["render_status"], "complete", "{v}");
        assert!(v["rays"].as_u64().unwrap() > 0, "{v}");
        assert!(v["time_s"].as_f64().unwrap() > 0.0, "{v}");
        assert_eq!(v["nonfinite_samples"], 0, "{v}");
        let outputs = v["outputs"].as_array().unwrap();
        assert!(outputs[0].as_str().unwrap().ends_with(out), "{v}");
        assert!(outputs[1].as_str().unwrap().ends_with(".png"), "{v}");
    }

    // The option is global: it may come before the command too.
    let o = tress(
        &["--log-format", "json", "diff", "a.exr", "b.exr"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v = summary(&o, true);
    assert_eq!(v["command"], "diff");
    assert_eq!(v["status"], "ok");
    for key in ["mse", "relmse", "psnr_db", "mean_diff", "ssim"] {
        assert!(v[key]["all"].is_number(), "{key} in {v}");
    }
    let ssim = v["ssim"]["all"].as_f64().unwrap();
    let flip = v["flip"]["mean"].as_f64().unwrap();
    assert!(ssim > 0.0 && ssim < 1.0, "{v}");
    assert!(flip > 0.0 && flip < 1.0, "{v}");
    assert_eq!(v["region"]["w"], 24);

    // The readable default: the table, with the perceptual metrics.
    let o = tress(&["diff", "a.exr", "b.exr"], dir.path());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("SSIM") && text.contains("FLIP (LDR"),
        "{text}"
    );
    assert!(serde_json::from_str::<Value>(text.lines().last().unwrap()).is_err());
}

#[test]
fn failures_end_with_an_error_summary() {
    let (dir, _) = scene_dir(SCENE);
    let o = tress(
        &["diff", "missing.exr", "b.exr", "--log-format", "json"],
        dir.path(),
    );
    assert!(!o.status.success());
    let v = summary(&o, true);
    assert_eq!(v["command"], "diff");
    assert_eq!(v["status"], "error");
    assert!(v["error"].as_str().unwrap().contains("missing.exr"), "{v}");
    // People still get the message on stderr.
    assert!(stderr(&o).contains("missing.exr"));
}

#[test]
fn commands_without_results_of_their_own_still_end_with_a_summary() {
    let (dir, _) = scene_dir(SCENE);
    let o = tress(
        &["farm", "scene.ron", "--tiles", "2", "--log-format", "json"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    // The job list is the command's product and comes first.
    let v = summary(&o, false);
    assert_eq!(
        (v["command"].as_str(), v["status"].as_str()),
        (Some("farm"), Some("ok"))
    );
}
