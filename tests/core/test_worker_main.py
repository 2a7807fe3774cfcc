"""Worker processes never run the user's script again (issue 45): a plain script without an
``if __name__ == "__main__":`` guard that starts physinfer's worker processes prints its
top-level marker once, not once more in every worker."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = """
import os
print("MARKER", os.getpid(), flush=True)
from physinfer.datasets.executors import open_executor

with open_executor(workers=2, threads_per_worker=1) as (pool, info):
    workers = {f.result() for f in [pool.submit(os.getpid) for _ in range(4)]}
print("DONE", info.kind, len(workers - {os.getpid()}) >= 1, flush=True)
"""


@pytest.mark.parametrize("how", ["path", "module"])
def test_a_script_without_a_main_guard_runs_once_with_worker_processes(tmp_path: Path, how: str) -> None:
    script = tmp_path / "plain_script.py"
    script.write_text(SCRIPT)
    args = [str(script)] if how == "path" else ["-m", "plain_script"]
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    ran = subprocess.run(
        [sys.executable, *args], cwd=tmp_path, capture_output=True, text=True, timeout=300, env=env
    )
    assert ran.returncode == 0, ran.stderr[-3000:]
    assert ran.stdout.count("MARKER") == 1, ran.stdout
    assert "DONE processes True" in ran.stdout
