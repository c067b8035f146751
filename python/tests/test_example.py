"""The example runs (at a tiny size) and writes its image."""

import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "hair_colours.py"


def test_example_runs(tmp_path):
    out = tmp_path / "colours.ppm"
    done = subprocess.run(
        [sys.executable, str(EXAMPLE), "--size", "8", "--spp", "1", "--out", str(out)],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "blond" in done.stdout and "wrote" in done.stdout
    data = out.read_bytes()
    assert data.startswith(b"P6 24 8 255\n")
    assert len(data) == len(b"P6 24 8 255\n") + 24 * 8 * 3
