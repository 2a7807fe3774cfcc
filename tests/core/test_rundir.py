"""The run directory is the unit of safety: no user file is written over, one writer at a time.

On the pendulum example plugin (a refusal costs no simulation; a run of 2 trials, a second).
"""

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from physinfer.discrepancy.settings import DiagnoseSettings
from physinfer.discrepancy.workflow import run_diagnosis
from physinfer.errors import UserInputError
from physinfer.locking import LOCK_FILE, DirectoryLock
from physinfer.outputs import MANIFEST_FILE
from physinfer.plugins import load_registry
from physinfer.rundir import RUN_OUTPUTS, RunDirectory
from physinfer.session import refine
from physinfer.video import write_video

BIN = Path(sys.executable).parent / "physinfer"
QUICK = {"plugin": "pendulum_lab", "steps": 2, "optimizer": "random", "progress": False, "noise_samples": 0,
         "floor_samples": 0}


@pytest.fixture(scope="module")
def registry():
    return load_registry()[0]


@pytest.fixture
def users_folder(registry, tmp_path):
    """A folder of the user's: their target video and a result.json of their own."""
    work = tmp_path / "work"
    work.mkdir()
    write_video(work / "target.mp4", registry.phenomenon("pendulum_lab").default_target().clip)
    (work / "result.json").write_text('{"mine": true}')
    return work


def contents(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def test_refine_into_a_folder_of_the_users_files_is_refused_and_writes_nothing(registry, users_folder):
    before = contents(users_folder)
    with pytest.raises(UserInputError, match="target.mp4 is a file the run writes into --out"):
        refine(registry, target_path=users_folder / "target.mp4", out=users_folder, **QUICK)
    for overwrite in (False, True):
        with pytest.raises(UserInputError, match="is not empty .* holds no physinfer run"):
            refine(registry, out=users_folder, overwrite=overwrite, **QUICK)
    assert contents(users_folder) == before


def test_refine_cli_refuses_a_target_inside_out_with_one_line(users_folder):
    before = contents(users_folder)
    proc = subprocess.run(
        [str(BIN), "refine", "--plugin", "pendulum_lab", "--target", str(users_folder / "target.mp4"),
         "--out", str(users_folder), "--steps", "2", "--json"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "is a file the run writes" in json.loads(proc.stdout)["error"]
    assert contents(users_folder) == before


def test_out_that_is_a_file_is_refused_before_any_work(registry, tmp_path):
    out = tmp_path / "notes.txt"
    out.write_text("mine")
    with pytest.raises(UserInputError, match="is a file; give a directory"):
        refine(registry, out=out, **QUICK)
    assert out.read_text() == "mine"


def test_a_target_the_run_would_write_is_refused(registry, tmp_path):
    out = tmp_path / "run"
    refine(registry, out=out, **QUICK)
    with pytest.raises(UserInputError, match="is a file the run writes"):
        refine(registry, target_path=out / "target.mp4", out=out, overwrite=True, **QUICK)


def test_overwrite_removes_the_old_runs_files_and_nothing_else(tmp_path):
    run_dir = RunDirectory(tmp_path / "run")
    run_dir.create({"plugin": "pendulum_lab", "parameters": {}})
    for name in RUN_OUTPUTS[1:]:
        (run_dir.path / name).write_text("old")
    (run_dir.path / "notes.txt").write_text("mine")
    run_dir.create({"plugin": "pendulum_lab", "parameters": {}, "seed": 1}, overwrite=True)
    left = {p.name for p in run_dir.path.iterdir()}
    assert left == {"run.json", "trials.jsonl", "notes.txt", MANIFEST_FILE}, (
        "no output of the old run may sit beside the new one"
    )
    assert (run_dir.path / "notes.txt").read_text() == "mine"


def test_a_run_json_physinfer_did_not_write_is_not_a_run(tmp_path):
    run_dir = RunDirectory(tmp_path / "run")
    run_dir.create({"plugin": "pendulum_lab", "parameters": {}})
    (run_dir.path / "notes.txt").write_text("mine")
    run_dir.check_out(overwrite=True)  # physinfer's run, with a file of the user's beside it: accepted
    (tmp_path / "run.json").write_text('{"name": "my own run.json"}')
    with pytest.raises(UserInputError, match="did not write"):
        RunDirectory(tmp_path).check_out(overwrite=True)


def hold_lock(folder: Path) -> subprocess.Popen:
    """Another process holding ``folder``'s lock until killed."""
    code = (
        "import sys, time\nfrom physinfer.locking import DirectoryLock\n"
        f"assert DirectoryLock({str(folder)!r}).acquire()\nprint('locked', flush=True)\ntime.sleep(600)\n"
    )
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "locked"
    return holder


def test_a_second_writer_is_refused_naming_the_holder_and_a_killed_holder_frees_the_run(registry, tmp_path):
    out = tmp_path / "run"
    refine(registry, out=out, **QUICK)
    holder = hold_lock(out)
    try:
        for options in ({"resume": True, "steps": 3}, {"overwrite": True}, {}):
            with pytest.raises(UserInputError, match=f"being written by physinfer process {holder.pid}"):
                refine(registry, out=out, **{**QUICK, **options})
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    assert (out / LOCK_FILE).exists(), "the lock file stays; only the kernel's lock went with its process"
    result = refine(registry, out=out, resume=True, **{**QUICK, "steps": 3})
    assert result.n_trials == 3
    assert len(RunDirectory(out).read_trials()) == 3


def test_an_empty_folder_left_with_a_lock_file_is_usable(registry, tmp_path):
    out = tmp_path / "run"
    lock = DirectoryLock(out)
    assert lock.acquire()
    lock.release()
    assert refine(registry, out=out, **QUICK).n_trials == 2


def test_diagnose_refuses_a_folder_of_the_users_files_and_a_second_writer(registry, users_folder, tmp_path):
    before = contents(users_folder)
    with pytest.raises(UserInputError, match="is not empty .* holds no physinfer diagnosis"):
        run_diagnosis(registry, DiagnoseSettings(plugin="pendulum_lab", out=users_folder, steps=2))
    assert contents(users_folder) == before
    out = tmp_path / "diagnosis"
    holder = hold_lock(out)
    try:
        with pytest.raises(UserInputError, match=f"process {holder.pid}"):
            run_diagnosis(registry, DiagnoseSettings(plugin="pendulum_lab", out=out, steps=2))
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
