"""examples/notebook_refine.py, the notebook-style walk through the Python API, runs as a script."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "notebook_refine.py"


def _run(tmp_path: Path, *args: str) -> str:
    done = subprocess.run(
        [sys.executable, str(EXAMPLE), "--out", str(tmp_path), *args],
        capture_output=True, text=True, timeout=900, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_the_pendulum_part_runs_and_plots(tmp_path):
    stdout = _run(tmp_path, "--steps", "4", "--plugins", "pendulum_lab")
    assert stdout.count("pendulum ") == 3
    for name in ("pendulum_target.mp4", "pendulum_frames.png", "pendulum_refinement.png"):
        assert (tmp_path / name).stat().st_size > 1000


@pytest.mark.slow
def test_the_whole_notebook_runs_with_the_flag_posterior(tmp_path):
    stdout = _run(tmp_path, "--steps", "4")
    assert "flag wind_speed" in stdout and "identified" in stdout
    assert (tmp_path / "flag_refinement.png").stat().st_size > 1000
