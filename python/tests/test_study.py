"""tress.study: a tiny study runs, writes its report, reads back as rows, and resumes."""

import os
import stat

import pytest

import tress

STUDY = """(
    name: "python smoke study",
    scenes: [
        Inline(
            name: "ball",
            scene: (
                camera: (look_from: (0, 0, 4), look_at: (0, 0, 0), fov: 35),
                film: (width: 12, height: 12),
                materials: {
                    "brown": Hair(Chiang(pigment: Melanin(eumelanin: 1.3))),
                },
                objects: [Hair(source: Procedural(style: Ball, strands: 200, radius: 0.012),
                               material: "brown")],
                lights: [Sky()],
            ),
        ),
    ],
    integrators: [Path(max_depth: 8), Path(max_depth: 1)],
    spp: [1, 2, 4],
    repetitions: 2,
    seed: 3,
    reference: Render(integrator: Path(max_depth: 8), spp: 64),
    quick: (spp: [1, 2], repetitions: 2, reference_spp: 16, film: (width: 8, height: 8)),
)
"""


@pytest.fixture
def study_file(tmp_path):
    path = tmp_path / "smoke.ron"
    path.write_text(STUDY)
    return path


def test_a_study_runs_writes_its_report_and_resumes(study_file, tmp_path):
    out = tmp_path / "results"
    result = tress.study(study_file, out=out, threads=2)
    assert result.folder == out
    assert result.report == out / "report.md"
    report = result.report.read_text()
    assert "python smoke study" in report
    # Every table, and no figures: the module draws none (`tress study` adds them).
    assert "### Time to relMSE" in report and "No figures" in report and ".png" not in report
    assert result.results_csv.is_file() and result.summary_csv.is_file()
    # 2 integrators x 3 spp x 2 repetitions, and the reference.
    assert (result.rendered, result.reused) == (13, 0)
    rows = result.summary
    # Two integrators of one name are told apart by their place in the list.
    assert sorted((r["integrator"], r["spp"]) for r in rows) == [
        (i, s) for i in ("path-1", "path-2") for s in (1, 2, 4)
    ]
    assert all(r["scene"] == "ball" and r["reference"] == "common" for r in rows)
    assert all(r["repetitions"] == 2 and isinstance(r["mse"], float) and r["mse"] > 0 for r in rows)
    # Run again: every render is read back.
    again = tress.study(study_file, out=out)
    assert (again.rendered, again.reused) == (0, 13)
    assert again.summary == rows


def test_quick_runs_the_quick_section_into_a_folder_of_its_own(study_file, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = tress.study(study_file, quick=True)
    assert result.folder.name == "smoke_study_quick"
    assert (result.rendered, result.reused) == (9, 0)
    assert {r["spp"] for r in result.summary} == {1, 2}


def test_study_errors(tmp_path, study_file):
    with pytest.raises(FileNotFoundError, match="missing.ron"):
        tress.study(tmp_path / "missing.ron")
    bad = tmp_path / "bad.ron"
    bad.write_text(STUDY.replace("repetitions: 2,\n    seed", "repetitions: 0,\n    seed"))
    with pytest.raises(ValueError, match="repetitions must be at least 1"):
        tress.study(bad, out=tmp_path / "bad")
    typo = tmp_path / "typo.ron"
    typo.write_text(STUDY.replace("spp: [1, 2, 4]", "sp: [1, 2, 4]"))
    with pytest.raises(ValueError, match=r"typo\.ron:\d+:\d+: .*sp"):
        tress.study(typo, out=tmp_path / "typo")


def test_study_exceptions_follow_the_kind_of_error(tmp_path, study_file):
    (tmp_path / "folder.ron").mkdir()
    with pytest.raises(IsADirectoryError, match="folder.ron"):
        tress.study(tmp_path / "folder.ron")
    # A folder in the place of a table: refused by name before any render.
    out = tmp_path / "blocked"
    (out / "summary.csv").mkdir(parents=True)
    with pytest.raises(IsADirectoryError, match="summary.csv: is a directory"):
        tress.study(study_file, out=out, quick=True)
    assert not (out / "renders").exists()


@pytest.mark.parametrize("link", [os.symlink, os.link], ids=["symlink", "hard link"])
def test_study_tables_never_replace_an_input(study_file, tmp_path, link):
    out = tmp_path / "guarded"
    out.mkdir()
    link(study_file, out / "report.md")
    before = study_file.read_text()
    # Refused by name before any render, the study file untouched.
    with pytest.raises(OSError, match="report.md: is .*smoke.ron, an input of this command"):
        tress.study(study_file, out=out, quick=True)
    assert study_file.read_text() == before
    assert [p.name for p in out.iterdir()] == ["report.md"]


def test_study_tables_go_into_devices_and_refuse_fifos_nobody_reads(study_file, tmp_path):
    out = tmp_path / "special"
    out.mkdir()
    os.mkfifo(out / "results.csv")
    with pytest.raises(OSError, match="results.csv: is a FIFO that no process is reading"):
        tress.study(study_file, out=out, quick=True)
    assert stat.S_ISFIFO(os.lstat(out / "results.csv").st_mode)
    # A link to /dev/null is written into: the link stays, and so does the device.
    (out / "results.csv").unlink()
    (out / "results.csv").symlink_to("/dev/null")
    result = tress.study(study_file, out=out, quick=True)
    assert result.rendered == 0 and result.summary
    assert (out / "results.csv").is_symlink()
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
