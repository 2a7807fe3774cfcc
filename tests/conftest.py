"""Shared test set-up: headless OpenGL for every test process."""

import os

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("PYGLET_HEADLESS", "1")  # pyrender imports pyglet: no X display
os.environ.setdefault("MPLBACKEND", "Agg")
if os.environ.get("PYTEST_XDIST_WORKER"):
    # Each of make test's workers has a core: OpenMP and BLAS threads of their own would spin on
    # the other's (a toy flow's training took 142 s beside a busy worker, 13 s alone).
    for _threads in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_threads, "1")


import json  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402


@dataclass
class Ran:
    """What a CLI command run in-process returned."""

    returncode: int
    stdout: str
    stderr: str

    def json(self) -> dict:
        """The one JSON object a ``--json`` command printed."""
        lines = [ln for ln in self.stdout.splitlines() if ln.strip()]
        assert len(lines) == 1, (
            f"exit {self.returncode}; stdout {self.stdout!r}; stderr {self.stderr[-2000:]}"
        )
        return json.loads(lines[0])


def _run_in_process(*args: str, cwd: Path | None = None) -> Ran:
    from typer.testing import CliRunner

    from physinfer.cli.app import mounted_app

    here = Path.cwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        result = CliRunner().invoke(mounted_app(), [str(a) for a in args])
    finally:
        os.chdir(here)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return Ran(result.exit_code, result.stdout, result.stderr)


@pytest.fixture(scope="session")
def physinfer_cli():
    """``physinfer ARGS...`` run in this process (no interpreter start-up, numba and torch already
    loaded): ``physinfer_cli("refine", "--plugin", "pendulum_lab", ..., cwd=None) -> Ran``. The
    console script's own start-up is tested with subprocesses in tests/core/test_cli.py."""
    return _run_in_process
