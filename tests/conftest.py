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


#: The modules whose tests took longest in ``make test`` (seconds of their slowest tests under
#: two workers, 2026-11-29): each xdist worker runs its share of them first.
LONGEST_MODULES = {
    "tests/plugins/pendulum/test_pendulum.py": 330,
    "tests/core/test_diagnose.py": 160,
    "tests/core/test_refine.py": 155,
    "tests/core/test_diagnose_cmd.py": 145,
    "tests/plugins/flag/test_flag_refine.py": 80,
    "tests/core/test_scene_ranges.py": 75,
    "tests/core/test_posterior.py": 65,
    "tests/core/test_posterior_as_given.py": 60,
    "tests/core/test_fault_injection.py": 45,
}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under ``make test``'s xdist workers, start each worker's share with its longest modules.

    The worksteal scheduler gives each of N workers a contiguous 1/N of the collected tests and
    lets an idle worker steal from the end of another's queue. In collection order the
    pendulum's real-footage tests (330 s) came last, so one worker ran them while the other
    sat idle for a minute or more; with each share's longest modules first, what is left to
    steal at the end are short tests. The order within a module is kept (its fixtures are
    built once), and every test runs as before: only when, on which worker.
    """
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0"))
    if workers < 2 or not items:
        return
    root = Path(__file__).resolve().parents[1]

    def weight(item: pytest.Item) -> int:
        path = Path(str(item.path)).resolve()
        return -LONGEST_MODULES.get(path.relative_to(root).as_posix() if path.is_relative_to(root) else "", 0)

    ordered, start = [], 0
    for share in range(workers):  # the scheduler's split: len(pending) // workers remaining, in turn
        size = (len(items) - start) // (workers - share)
        ordered.extend(sorted(items[start : start + size], key=weight))  # stable
        start += size
    items[:] = ordered
