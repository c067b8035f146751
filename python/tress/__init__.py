"""tress: a physically based hair renderer, from Python.

Scenes are the scene files of the ``tress`` command line (RON), or the same structure as a
dict; renders come back as NumPy arrays of linear radiance::

    import tress
    scene = tress.load_scene("scenes/demo.ron")
    image = scene.render(spp=16, seed=1, integrator="dual-mis")   # float32, (height, width, 3)

Hair scattering models can be evaluated and sampled over arrays of directions
(:class:`HairModel`), and comparative studies run as ``tress study`` does, without its figures
(:func:`study`).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Optional, Union

from ._tress import HAIR_MODELS, INTEGRATORS, HairModel, Scene, __version__, load_scene
from ._tress import run_study as _run_study

__all__ = [
    "HAIR_MODELS",
    "INTEGRATORS",
    "HairModel",
    "Scene",
    "StudyResult",
    "__version__",
    "load_scene",
    "study",
]


@dataclass
class StudyResult:
    """Where a study wrote its results (see ``tress study``), and its summary table."""

    folder: Path
    """The output folder: the CSVs, the report and the renders (EXR and PNG preview each)."""
    report: Path
    """``report.md``: the settings and every table of ``tress study``'s report, without its
    figures (plots, error heat maps, crop sheets)."""
    results_csv: Path
    """``results.csv``: one row per render."""
    summary_csv: Path
    """``summary.csv``: one row per scene, integrator, spp and reference."""
    rendered: int
    """Renders done by this run."""
    reused: int
    """Finished renders of an earlier run that were read back instead."""
    summary: list[dict[str, Union[str, int, float, None]]] = field(default_factory=list)
    """The rows of ``summary.csv``, numbers as numbers and empty cells as ``None``."""


def _cell(text: str) -> Union[str, int, float, None]:
    if text == "":
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def study(
    path: Union[str, PathLike],
    quick: bool = False,
    out: Optional[Union[str, PathLike]] = None,
    threads: Optional[int] = None,
    verbose: bool = False,
    table_cache: Optional[Union[str, PathLike]] = None,
) -> StudyResult:
    """Runs the study file ``path`` as ``tress study`` does, but draws no figures.

    It renders (or reads back), measures and tabulates exactly as the command does, writing
    ``results.csv``, ``summary.csv`` and ``report.md`` into the output folder; the report has
    every table but no plots, error heat maps or crop sheets, since this module links no
    plotting library. To add them, run ``tress study`` on the same study file and output folder
    (with ``--quick`` if ``quick`` was set): it reads these renders back and renders nothing
    again. Or plot ``results.csv`` / :attr:`StudyResult.summary` yourself.

    ``quick`` is ``--quick`` (the study's scaled-down settings), ``out`` the output folder
    (default: the study's ``output``, else ``<study name>_study`` in the current folder),
    ``threads`` the worker threads (default: all cores); ``verbose`` prints the summary lines
    the command prints and notes on renders redone (warnings are printed either way);
    ``table_cache`` a folder where precomputed tables (the fur model's medulla tables) are read
    from and stored, as ``tress study --table-cache`` (default: none). Finished
    renders in the output folder are reused, as on the command line. Raises ``ValueError`` for
    a malformed study and ``OSError`` for files that cannot be read or written.
    """
    outputs = _run_study(
        path, quick=quick, out=out, threads=threads, verbose=verbose, table_cache=table_cache
    )
    with open(outputs["summary_csv"], newline="", encoding="utf-8") as f:
        rows = [{k: _cell(v) for k, v in row.items()} for row in csv.DictReader(f)]
    return StudyResult(
        folder=Path(outputs["folder"]),
        report=Path(outputs["report"]),
        results_csv=Path(outputs["results_csv"]),
        summary_csv=Path(outputs["summary_csv"]),
        rendered=outputs["rendered"],
        reused=outputs["reused"],
        summary=rows,
    )
