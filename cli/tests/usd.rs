//! Hostile USD grooms through the binary: every one fails with status 1 and a short message
//! naming the groom and the problem (a line and column for text), never a panic, an abort, a
//! hang or a run-to-run difference.

use crate::common::*;
use std::path::Path;
use std::process::{Command, Output};

/// A linear groom of one strand with a constant width and colour.
const GROOM: &str = r#"#usda 1.0
def BasisCurves "Hair"
{
    uniform token type = "linear"
    int[] curveVertexCounts = [3]
    point3f[] points = [(0, 0, 0), (0, 1, 0), (0, 2, 0)]
    float[] widths = [0.1] (interpolation = "constant")
    color3f[] primvars:displayColor = [(0.5, 0.3, 0.1)] (interpolation = "constant")
}
"#;

/// `tress args` in `dir` with the memory limit `gib`.
fn tress_with_limit(args: &[&str], dir: &Path, gib: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tress"))
        .args(args)
        .current_dir(dir)
        .env("TRESS_MEMORY_LIMIT_GIB", gib)
        .output()
        .expect("run tress")
}

/// Writes `scene.ron` reading `groom` in `dir`.
fn write_scene(dir: &Path, groom: &str) {
    let scene = SCENE.replace(
        "Procedural(style: Ball, strands: 300, radius: 0.01)",
        &format!("File(\"{groom}\")"),
    );
    std::fs::write(dir.join("scene.ron"), scene).unwrap();
}

/// `tress info` and `tress render` of a scene reading `groom` both fail cleanly, their
/// messages holding every one of `expect`, the groom's name and the scene's, in few lines.
fn assert_refused(dir: &Path, groom: &str, gib: &str, expect: &[&str]) {
    write_scene(dir, groom);
    let before = files_in(dir);
    for args in [
        &["info", "scene.ron"][..],
        &["render", "scene.ron", "--out", "o.exr", "--quiet"],
    ] {
        let o = tress_with_limit(args, dir, gib);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{groom} {args:?}: {err}");
        for e in expect.iter().chain(&[groom, "scene.ron"]) {
            assert!(err.contains(e), "{groom} {args:?}: lacks '{e}': {err}");
        }
        assert!(
            !err.contains("panicked") && !err.contains("library failed"),
            "{err}"
        );
        assert!(err.len() < 2000, "{} bytes: {}", err.len(), &err[..2000]);
        assert_eq!(files_in(dir), before, "{args:?}: output left behind");
    }
}

#[test]
fn hostile_usd_text_is_refused_by_class() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("other.usda"), "#usda 1.0\ndef \"X\" {}\n").unwrap();
    let arc = |arc: &str| {
        GROOM.replace(
            "def BasisCurves \"Hair\"",
            &format!("def BasisCurves \"Hair\" ({arc})"),
        )
    };
    let nested = |n: usize| {
        format!(
            "#usda 1.0\n{}{}",
            "def Xform \"a\" {\n".repeat(n),
            "}\n".repeat(n)
        )
    };
    let cases: Vec<(String, Vec<&str>)> = vec![
        // Tuples shorter or longer than their type: read from uninitialised memory before.
        (
            GROOM.replace("(0, 2, 0)]", "(0, 2)]"),
            vec!["line 6, column", "tuple has 2 elements, expected 3"],
        ),
        (
            GROOM.replace("(0, 1, 0),", "(),"),
            vec!["line 6", "tuple has 0 elements"],
        ),
        (
            GROOM.replace("[(0.5, 0.3, 0.1)]", "[(0.5, 0.3)]"),
            vec!["line 8"],
        ),
        (
            GROOM.replace("(0, 2, 0)]", "(0, 2, 0, 4)]"),
            vec!["too many elements"],
        ),
        // Nesting: 6,000 prims overflowed the stack, dictionaries and arrays alike.
        (nested(6000), vec!["nested more than 256 deep"]),
        (
            format!(
                "#usda 1.0\ndef \"A\" (customData = {}1{})\n{{\n}}\n",
                "{ dictionary d = ".repeat(3000),
                "}".repeat(3000)
            ),
            vec!["nested more than 256 deep"],
        ),
        // A megabyte token is not echoed whole.
        (
            GROOM.replace("(0, 0, 0), ", &format!("{}, ", "y".repeat(1 << 20))),
            vec!["line 6", "characters"],
        ),
        // Missing layers, prims and ops: dropped without a word before.
        (arc("references = @missing.usda@</X>"), vec!["missing.usda"]),
        (arc("payload = @missing.usda@</X>"), vec!["missing.usda"]),
        (arc("references = @other.usda@</Nope>"), vec!["</Nope>"]),
        (arc("references = </Nowhere>"), vec!["</Nowhere>"]),
        // Paths and names outside SdfPath's grammar: a reference path running on over lines
        // (a fuzzer's find) made the composition walk up its ancestors without end.
        (
            arc("references = </Proto\n)\n}\n\ndef \"B\" (\n references = </Proto>"),
            vec!["line 2, column", "not a valid path"],
        ),
        (
            GROOM.replace("\"Hair\"", "\"Ha}r\""),
            vec!["not a valid prim name"],
        ),
        (
            GROOM.replace("#usda 1.0", "#usda 1.0\n(subLayers = [@gone.usda@])"),
            vec!["gone.usda"],
        ),
        (
            GROOM.replace(
                "uniform token type",
                "uniform token[] xformOpOrder = [\"xformOp:scale\"]\n    uniform token type",
            ),
            vec!["xformOpOrder names \"xformOp:scale\""],
        ),
    ];
    for (i, (text, expect)) in cases.iter().enumerate() {
        let name = format!("groom{i}.usda");
        std::fs::write(d.join(&name), text).unwrap();
        assert_refused(d, &name, "16", expect);
        std::fs::remove_file(d.join(&name)).unwrap();
    }
}

#[cfg(unix)]
#[test]
fn usd_layers_that_are_fifos_or_devices_are_refused_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    assert!(Command::new("mkfifo")
        .arg(d.join("fifo.usda"))
        .status()
        .unwrap()
        .success());
    std::os::unix::fs::symlink("/dev/zero", d.join("zero.usdc")).unwrap();
    for (layer, named) in [("fifo.usda", "fifo.usda"), ("zero.usdc", "/dev/zero")] {
        for text in [
            GROOM.replace(
                "#usda 1.0",
                &format!("#usda 1.0\n(subLayers = [@{layer}@])"),
            ),
            GROOM.replace(
                "def BasisCurves \"Hair\"",
                &format!("def BasisCurves \"Hair\" (references = @{layer}@</X>)"),
            ),
        ] {
            std::fs::write(d.join("groom.usda"), text).unwrap();
            assert_refused(d, "groom.usda", "16", &[named, "not a regular file"]);
        }
    }
}

#[test]
fn nested_instancing_stops_at_the_memory_limit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut text = GROOM.replace(
        "def BasisCurves \"Hair\"",
        "class \"L0\" {\ndef BasisCurves \"C\"",
    ) + "}\n";
    for level in 1..9 {
        text += &format!("class \"L{level}\"\n{{\n");
        for i in 0..10 {
            text += &format!(
                "    def \"I{i}\" (instanceable = true\n        references = </L{}>) {{}}\n",
                level - 1
            );
        }
        text += "}\n";
    }
    text += "def \"Top\" (instanceable = true\n    references = </L8>) {}\n";
    // 10^8 instances from 5 KB: refused by the memory limit within seconds.
    std::fs::write(d.join("groom.usda"), &text).unwrap();
    let started = std::time::Instant::now();
    assert_refused(
        d,
        "groom.usda",
        "0.05",
        &["prims", "TRESS_MEMORY_LIMIT_GIB"],
    );
    assert!(started.elapsed().as_secs() < 120, "{:?}", started.elapsed());
}

/// One-byte changes of a binary groom, through the binary: each is read or refused with status
/// 1, and what is read is the same on every run (uninitialised memory made it vary).
#[test]
fn one_byte_changes_of_a_usdc_are_read_or_refused() {
    let original = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../groom/tests/data/usd_linear.usdc"),
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_scene(d, "groom.usdc");
    for i in (0..original.len()).step_by(37) {
        let mut bytes = original.clone();
        bytes[i] ^= 0xff;
        std::fs::write(d.join("groom.usdc"), &bytes).unwrap();
        let runs: Vec<Output> = (0..2).map(|_| tress(&["info", "scene.ron"], d)).collect();
        for o in &runs {
            let err = stderr(o);
            assert!(matches!(o.status.code(), Some(0 | 1)), "byte {i}: {err}");
            assert!(
                !err.contains("panicked") && !err.contains("library failed"),
                "byte {i}: {err}"
            );
            if o.status.code() == Some(1) {
                assert!(err.contains("groom.usdc"), "byte {i}: {err}");
            }
        }
        // The geometry `info` reports (not its timings) is the same on both runs.
        let geometry = |o: &Output| -> Vec<String> {
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .filter(|l| l.contains("points") || l.contains("bounds"))
                .map(str::to_string)
                .collect()
        };
        assert_eq!(geometry(&runs[0]), geometry(&runs[1]), "byte {i}");
    }
}
