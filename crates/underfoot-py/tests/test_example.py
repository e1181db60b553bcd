"""The example notebook (examples/gravel.py) runs whole and draws its figures."""

import os
import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "gravel.py"
FIGURES = ["gravel-response.png", "gravel-walk.png", "gravel-steps.png"]


def test_the_gravel_example_runs_and_writes_its_figures(tmp_path, data_dir):
    # data_dir: the example reads the shared recordings; without them this skips (or
    # fails under UNDERFOOT_REQUIRE_DATA=1) rather than failing inside the script.
    env = dict(os.environ, MPLBACKEND="Agg", UNDERFOOT_EXAMPLE_OUT=str(tmp_path))
    done = subprocess.run(
        [sys.executable, str(EXAMPLE)], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 0, f"{EXAMPLE.name} failed:\n{done.stdout}\n{done.stderr}"
    # A warning (a tight layout that failed, a log of zero) is a figure drawn wrong.
    assert "Warning" not in done.stderr, done.stderr
    for name in FIGURES:
        figure = tmp_path / name
        assert figure.is_file(), f"{name} not written; the example printed:\n{done.stdout}"
        data = figure.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, f"{name}: {len(data)} bytes"
