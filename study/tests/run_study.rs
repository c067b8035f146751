//! `tress_study::run` without figures, as the Python bindings run studies.

// Test code is not library code: it writes its fixtures and reads its settings (clippy.toml's
// rules are for the library).
#![allow(clippy::disallowed_methods)]

use tress_study::{self as study, NotesOnStderr, StudySettings};

#[test]
fn run_study_says_where_the_study_wrote_and_what_it_rendered() {
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("tiny.ron");
    std::fs::write(
        &study,
        r#"(
    scenes: [Inline(name: "ball", scene: (
        camera: (look_from: (0, 0, 4), look_at: (0, 0, 0)),
        film: (width: 6, height: 6),
        materials: {"hair": Hair(Chiang())},
        objects: [Hair(source: Procedural(style: Ball, strands: 50), material: "hair")],
        lights: [Sky()],
    ))],
    integrators: [Path(max_depth: 2)],
    spp: [1, 2],
    repetitions: 2,
    reference: Render(integrator: Path(max_depth: 2), spp: 8),
)"#,
    )
    .unwrap();
    let out = dir.path().join("out");
    let settings = StudySettings {
        study: study.clone(),
        quick: false,
        out: Some(out.clone()),
        threads: Some(1),
        verbose: false,
        limits: Default::default(),
        table_dir: None,
    };
    let first = study::run(&settings, &NotesOnStderr, None).unwrap();
    assert_eq!(first.folder, out);
    assert_eq!(first.report, out.join("report.md"));
    assert_eq!(first.results_csv, out.join("results.csv"));
    for file in [&first.report, &first.results_csv, &first.summary_csv] {
        assert!(file.is_file(), "{} is missing", file.display());
    }
    // Two spp x two repetitions, and the reference; then all of it read back.
    assert_eq!((first.rendered, first.reused), (5, 0));
    let report = std::fs::read_to_string(&first.report).unwrap();
    assert!(
        report.contains("No figures") && !report.contains(".png"),
        "{report}"
    );
    let again = study::run(&settings, &NotesOnStderr, None).unwrap();
    assert_eq!((again.rendered, again.reused), (0, 5));
}
