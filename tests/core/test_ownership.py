"""Every command owns what it writes (issue 45, item 1): a folder of the user's own files is
refused by every writer, an existing output file is replaced only with ``--overwrite``, and
``--overwrite`` removes only what the command wrote (``DIR/.physinfer.json`` says what)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.outputs import MANIFEST_FILE, OutputFolder, read_manifest
from physinfer.types import Trajectory

#: What a user keeps in a folder: the very names the writers use, and one of their own.
USERS_FILES = {
    "report.html": "<p>my report</p>",
    "posterior.json": '{"mine": true}',
    "samples.npz": "my samples",
    "history.json": '{"mine": true}',
    "sdn.safetensors": "my weights",
    "result.json": '{"mine": true}',
    "calibration.json": '{"mine": true}',
    "predictions.csv": "mine",
    "synthetic.json": '{"mine": true}',
    "notes.txt": "mine",
}


def _users_folder(path: Path) -> Path:
    path.mkdir(parents=True)
    for name, text in USERS_FILES.items():
        (path / name).write_text(text)
    return path


def _unchanged(path: Path) -> bool:
    return {p.name: p.read_text() for p in path.iterdir()} == USERS_FILES


def _writers(tmp_path: Path, out: Path) -> dict[str, tuple[str, ...]]:
    data = tmp_path / "no-data"
    return {
        "infer": ("infer", "--plugin", "pendulum_lab", "--out", out),
        "evaluate calibration": (
            "evaluate", "calibration", "--plugin", "pendulum_lab", "--data", data, "--out", out,
        ),
        "evaluate bouman": ("evaluate", "bouman", "--data", data, "--out", out, "--device", "cpu"),
        "dataset bouman": ("dataset", "bouman", "--out", out, "--fabrics", "1", "--frames", "2", "--size", "32"),
        "train": ("train", "--plugin", "flag", "--data", data, "--out", out),
        "refine": ("refine", "--plugin", "pendulum_lab", "--steps", "1", "--out", out),
        "refine --overwrite": ("refine", "--plugin", "pendulum_lab", "--steps", "1", "--out", out, "--overwrite"),
        "diagnose": ("diagnose", "--plugin", "pendulum_lab", "--out", out),
        "report": ("report", out),
    }  # fmt: skip


WRITERS = sorted(_writers(Path("."), Path(".")))


@pytest.mark.parametrize("command", WRITERS)
def test_every_writer_refuses_a_folder_of_the_users_files(command, tmp_path, physinfer_cli):
    out = _users_folder(tmp_path / "mine")
    ran = physinfer_cli(*_writers(tmp_path, out)[command], "--json")
    assert ran.returncode == 2, (command, ran.stderr[-1500:])
    error = ran.json()["error"]
    assert str(out) in error and ("physinfer" in error), (command, error)
    assert "not empty" in error or "not a physinfer run" in error, (command, error)
    assert _unchanged(out), command
    assert not (out / MANIFEST_FILE).exists()


def test_a_run_json_of_the_users_is_not_a_run_even_with_overwrite(tmp_path, physinfer_cli):
    """A ``run.json`` naming a plugin made any folder a run: ``refine --overwrite`` then
    replaced the user's ``result.json``; and ``report`` wrote over their ``report.html``."""
    out = tmp_path / "mine"
    out.mkdir()
    (out / "run.json").write_text('{"plugin": "pendulum_lab"}')
    (out / "result.json").write_text("mine")
    (out / "report.html").write_text("mine")
    for args in (("--overwrite",), ("--resume",), ()):
        ran = physinfer_cli("refine", "--plugin", "pendulum_lab", "--steps", "1", "--out", out, *args, "--json")
        assert ran.returncode == 2 and "did not write" in ran.json()["error"], (args, ran.stderr[-1500:])
    ran = physinfer_cli("report", out, "--json")
    assert ran.returncode == 2 and "not a physinfer run" in ran.json()["error"]
    assert {p.name: p.read_text() for p in out.iterdir()} == {
        "run.json": '{"plugin": "pendulum_lab"}', "result.json": "mine", "report.html": "mine",
    }  # fmt: skip


def test_report_writes_only_into_the_folder_of_a_refine_diagnose_or_infer(tmp_path, physinfer_cli):
    other = tmp_path / "calibration"
    folder = OutputFolder(other, "evaluate calibration", ("calibration.json", "report.html"))
    folder.claim()
    (other / "posterior.json").write_text("{}")
    ran = physinfer_cli("report", other, "--json")
    assert ran.returncode == 2 and "evaluate calibration" in ran.json()["error"]
    assert not (other / "report.html").exists()


# ------------------------------------------------------------- an earlier run of one's own


def _fake_infer(written: tuple[str, ...]):
    """Stands for the posterior workflow: writes ``written`` into ``out``."""

    def run(registry, *, out, **kwargs):
        out.mkdir(parents=True, exist_ok=True)
        for name in written:
            (out / name).write_text("new")
        return "report"

    return run


def test_infer_replaces_its_own_results_only_with_overwrite_and_removes_only_those(tmp_path, monkeypatch):
    import physinfer
    import physinfer.posterior.workflow as workflow

    out = tmp_path / "infer"
    monkeypatch.setattr(workflow, "infer", _fake_infer(("posterior.json", "samples.npz", "corner.png")))
    assert physinfer.infer("pendulum_lab", out=out) == "report"
    manifest = read_manifest(out)
    assert manifest["command"] == "infer" and "posterior.json" in manifest["outputs"]
    (out / "notes.txt").write_text("mine")
    with pytest.raises(UserInputError, match="earlier infer's results .*--overwrite"):
        physinfer.infer("pendulum_lab", out=out)
    assert (out / "posterior.json").read_text() == "new"
    monkeypatch.setattr(workflow, "infer", _fake_infer(("posterior.json",)))
    physinfer.infer("pendulum_lab", out=out, overwrite=True)
    # The old run's samples and plot are gone, the user's note stays.
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_FILE, "notes.txt", "posterior.json"]


def test_a_command_that_fails_leaves_no_claimed_folder_behind(tmp_path, monkeypatch):
    import physinfer
    import physinfer.posterior.workflow as workflow

    def refuse(registry, **kwargs):
        raise UserInputError("no estimator")

    monkeypatch.setattr(workflow, "infer", refuse)
    with pytest.raises(UserInputError, match="no estimator"):
        physinfer.infer("pendulum_lab", out=tmp_path / "new")
    assert not (tmp_path / "new").exists()


def test_another_commands_folder_is_refused(tmp_path):
    OutputFolder(tmp_path / "run", "refine", ("run.json",)).claim()
    (tmp_path / "run" / "run.json").write_text("{}")
    with pytest.raises(UserInputError, match="holds physinfer's refine output, not infer's"):
        OutputFolder(tmp_path / "run", "infer", ("posterior.json",)).check(overwrite=True)


def test_a_manifest_names_only_plain_names_it_may_remove(tmp_path):
    """A manifest edited to list ``../x`` or a name the command does not write removes nothing."""
    out = tmp_path / "run"
    folder = OutputFolder(out, "infer", ("posterior.json",))
    folder.claim()
    (tmp_path / "x").write_text("mine")
    (out / "kept.txt").write_text("mine")
    manifest = json.loads((out / MANIFEST_FILE).read_text())
    manifest["outputs"] += ["../x", "kept.txt"]
    (out / MANIFEST_FILE).write_text(json.dumps(manifest))
    folder.claim(overwrite=True)
    assert (tmp_path / "x").exists() and (out / "kept.txt").exists()


# ------------------------------------------------------------------------------ render --out


def test_render_refuses_an_existing_video_unless_overwrite(tmp_path, physinfer_cli):
    from pendulum_example.physics import make_simulator

    trajectory = make_simulator().simulate({"length": 0.8, "damping": 0.1, "amplitude": 30.0})
    Trajectory(trajectory.vertices[:3], trajectory.faces, trajectory.fps).save(tmp_path / "p.npz")
    video = tmp_path / "mine.mp4"
    video.write_bytes(b"my video")
    args = ("render", "--plugin", "pendulum_lab", "--trajectory", tmp_path / "p.npz",
            "--render-set", "size=32", "--out", video, "--json")  # fmt: skip
    ran = physinfer_cli(*args)
    assert ran.returncode == 2 and "exists; give --overwrite" in ran.json()["error"]
    assert video.read_bytes() == b"my video"
    ran = physinfer_cli(*args, "--overwrite")
    assert ran.returncode == 0, ran.stderr[-1500:]
    assert video.stat().st_size > 100
    assert np.asarray(ran.json()["n_frames"]) == 3
