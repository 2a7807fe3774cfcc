"""Refinement trials simulated and rendered on worker processes and on a real Dask cluster."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from physinfer.errors import UserInputError
from physinfer.plugins import load_registry
from physinfer.session import refine

BIN = Path(sys.executable).parent / "physinfer"
QUICK = dict(plugin="pendulum_lab", steps=5, optimizer="random", progress=False, noise_samples=0, floor_samples=0)


def cli(*args):
    proc = subprocess.run([str(BIN), *args], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """The reference: q = 2, two seeds per trial, everything in this process."""
    registry, _ = load_registry()
    return refine(registry, out=tmp_path_factory.mktemp("ref") / "r", batch_size=2, seeds_per_trial=2, **QUICK)


def test_local_worker_processes_log_the_same_trials(tmp_path, in_process):
    out = tmp_path / "r"
    data = cli("refine", "--plugin", "pendulum_lab", "--steps", "5", "--optimizer", "random", "--noise-samples", "0",
               "--floor-samples", "0", "--batch-size", "2", "--seeds-per-trial", "2", "--workers", "2",
               "--out", str(out), "--json")
    assert data["executor"] == {"kind": "processes", "workers": 2, "threads": 1, "address": None}
    trials = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    assert [t["x"] for t in trials] == [t.x for t in in_process.trials]
    assert [t["distance"] for t in trials] == pytest.approx([t.distance for t in in_process.trials], rel=1e-9)
    assert all(t["timings"]["simulate"] > 0 and t["timings"]["render"] > 0 for t in trials)
    assert json.loads((out / "result.json").read_text())["executor"]["kind"] == "processes"


def test_a_dask_cluster_runs_the_trials(tmp_path, in_process):
    distributed = pytest.importorskip("distributed")
    registry, _ = load_registry()
    with distributed.LocalCluster(
        n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None
    ) as cluster:
        result = refine(registry, out=tmp_path / "r", batch_size=2, seeds_per_trial=2,
                        scheduler=cluster.scheduler_address, **QUICK)
    assert result.extra["executor"]["kind"] == "dask" and result.extra["executor"]["workers"] == 2
    assert [t.distance for t in result.trials] == pytest.approx([t.distance for t in in_process.trials], rel=1e-9)


def test_negative_workers_are_refused(tmp_path):
    registry, _ = load_registry()
    with pytest.raises(UserInputError, match="--workers must be 0"):
        refine(registry, out=tmp_path / "r", workers=-1, **QUICK)

