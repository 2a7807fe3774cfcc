"""``physinfer train`` and ``physinfer evaluate triplets|wind`` (physinfer_flag.cli).

The commands run in process (typer's CliRunner) on a tiny dataset written by the real
dataset engine: oscillating stripes whose temporal frequency is ``wind_speed``. One
subprocess test checks that the installed CLI mounts them and refuses other plugins.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from physinfer import ParameterSpace, ParameterSpec, Trajectory
from physinfer.datasets import (
    ClipFormat,
    DatasetGenerator,
    DatasetPreset,
    SplitCounts,
    generate_dataset,
)
from physinfer.types import Clip
from physinfer_flag.cli import evaluate_triplets_cmd, evaluate_wind_cmd, train_cmd

BIN = Path(sys.executable).parent / "physinfer"
SMALL = ["--frames", "16", "--size", "32"]


class StripesGenerator(DatasetGenerator):
    """θ: the stripes' temporal frequency (``wind_speed``, Hz); ζ: contrast and phase."""

    phenomenon = "stripes"
    parameter_space = ParameterSpace(
        [ParameterSpec("wind_speed", (1.0, 8.0), "Hz"), ParameterSpec("tilt", (0.0, 1.0), "")]
    )

    def simulate_batch(self, params, seeds, *, clip):
        faces = np.array([[0, 1, 2]], dtype=np.int32)
        return [
            Trajectory(
                np.zeros((clip.n_frames, 3, 3), np.float32),
                faces,
                clip.fps,
                {"theta": np.array([p["wind_speed"], p["tilt"]])},
            )
            for p in params
        ]

    def sample_render_params(self, rng):
        return {"contrast": float(rng.uniform(0.2, 0.45)), "phase": float(rng.uniform(0, 2 * np.pi))}

    def render(self, trajectory, render_params, *, clip):
        freq, tilt = trajectory.extras["theta"]
        t = np.arange(clip.n_frames)[:, None, None] / clip.fps
        y, x = np.mgrid[0 : clip.height, 0 : clip.width]
        angle = 2 * np.pi * ((x + tilt * y) / 10.0 - freq * t) + render_params["phase"]
        frames = 0.5 + render_params["contrast"] * np.sin(angle)
        return Clip((np.clip(frames, 0, 1) * 255).astype(np.uint8)[..., None], clip.fps)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("stripes") / "data"
    preset = DatasetPreset(
        name="tiny",
        sims=SplitCounts(10, 4, 5),
        renders=SplitCounts(30, 12, 15),
        clip=ClipFormat(n_frames=20, fps=25.0, height=32, width=32, channels=1),
    )
    generate_dataset(StripesGenerator(), root, preset=preset, seed=3, workers=0)
    return root


@pytest.fixture(scope="module")
def app():
    cli = typer.Typer()
    cli.command("train")(train_cmd)
    evaluate = typer.Typer()
    evaluate.command("triplets")(evaluate_triplets_cmd)
    evaluate.command("wind")(evaluate_wind_cmd)
    cli.add_typer(evaluate, name="evaluate")
    return cli


def invoke(app, *args: str, code: int = 0) -> dict:
    """Run a command with --json; check its exit status; return its one JSON object."""
    result = CliRunner().invoke(app, [*args, "--json"])
    assert result.exit_code == code, f"exit {result.exit_code}: {result.output}\n{result.exception!r}"
    lines = [line for line in result.stdout.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one JSON line on stdout, got {result.stdout!r}"
    return json.loads(lines[0])


@pytest.fixture(scope="module")
def model(app, data, tmp_path_factory):
    out = tmp_path_factory.mktemp("sdn") / "model"
    summary = invoke(
        app, "train", "-p", "flag", "--data", str(data), "--out", str(out), "--epochs", "2",
        "--batch-size", "12", "--no-progress", *SMALL,
    )  # fmt: skip
    return out, summary


def test_train_writes_weights_checkpoint_and_summary(model):
    out, summary = model
    assert summary["epochs_completed"] == 2 and len(summary["history"]) == 2
    assert 1 <= summary["best_epoch"] <= 2
    assert 0.0 <= summary["best"]["val_triplet_accuracy"] <= 1.0
    for name in ("sdn.safetensors", "checkpoint.safetensors", "history.json"):
        assert (out / name).is_file(), name
    assert summary["positives"] == "simulation"


def test_train_resumes_and_no_resume_starts_over(app, data, model, tmp_path):
    out, first = model
    copy = tmp_path / "copy"
    copy.mkdir()
    for f in out.iterdir():
        (copy / f.name).write_bytes(f.read_bytes())
    base = ["train", "-p", "flag", "--data", str(data), "--batch-size", "12", "--no-progress", *SMALL]
    resumed = invoke(app, *base, "--out", str(copy), "--epochs", "3")
    assert resumed["epochs_completed"] == 3
    # The first two epochs are the stored ones, not retrained.
    assert resumed["history"][:2] == first["history"]
    fresh = invoke(app, *base, "--out", str(copy), "--epochs", "1", "--no-resume")
    assert fresh["epochs_completed"] == 1
    changed = invoke(app, *base[:-4], "--frames", "12", "--size", "32", "--out", str(out), code=2)
    assert "different model config" in changed["error"]


def test_a_second_train_into_one_out_is_refused_naming_the_holder(app, data, tmp_path):
    import os

    from physinfer.locking import DirectoryLock

    lock = DirectoryLock(tmp_path / "m")
    assert lock.acquire()
    try:
        reply = invoke(app, "train", "-p", "flag", "--data", str(data), "--out", str(tmp_path / "m"), code=2)
    finally:
        lock.release()
    assert f"being written by physinfer process {os.getpid()}" in reply["error"]
    assert not (tmp_path / "m" / "checkpoint.safetensors").exists()


def test_evaluate_triplets_of_trained_model_and_spectral_baseline(app, data, model):
    out, _ = model
    scores = invoke(app, "evaluate", "triplets", "-p", "flag", "--data", str(data), "--model", str(out))
    assert scores["n_triplets"] == 15 and scores["split"] == "test"
    assert 0.0 <= scores["triplet_accuracy"] <= 1.0 and scores["embedder"] == "sdn"
    spectral = invoke(
        app, "evaluate", "triplets", "-p", "flag", "--data", str(data), "--embedder", "spectral",
        "--frames", "16", "--split", "val",
    )  # fmt: skip
    assert spectral["n_triplets"] == 12 and spectral["model"] == "spectral"
    # The stripes' frequency is θ: a spectral embedding must beat chance on them.
    assert spectral["triplet_accuracy"] > 0.5


def test_evaluate_wind_of_trained_model_and_baseline(app, data, model):
    out, _ = model
    scores = invoke(
        app, "evaluate", "wind", "-p", "flag", "--data", str(data), "--model", str(out / "sdn.safetensors"),
        "--head-epochs", "3",
    )  # fmt: skip
    assert scores["n"] == 15 and np.isfinite(scores["mse"]) and 0.0 <= scores["acc_at_0_5"] <= 1.0
    assert scores["target"] == "wind_speed"
    spectral = invoke(
        app, "evaluate", "wind", "-p", "flag", "--data", str(data), "--embedder", "spectral",
        "--frames", "16", "--head-epochs", "3", "--target", "tilt",
    )  # fmt: skip
    assert spectral["n"] == 15 and spectral["target"] == "tilt"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["train", "--data", "{missing}", "--out", "{tmp}/m"], "no such directory"),
        (["train", "--data", "{tmp}", "--out", "{tmp}/m"], "not a dataset"),
        (["train", "--data", "{data}", "--out", "{tmp}/m", "--positives", "seeds"], "'simulation' or 'parameters'"),
        (["train", "--data", "{data}", "--out", "{tmp}/m", "--epochs", "0"], "positive integer"),
        (["train", "--data", "{data}", "--out", "{tmp}/m", "--threads", "0"], "--threads must be a positive"),
        (["evaluate", "triplets", "--data", "{data}", "--model", "{tmp}/none.safetensors"], "no such file"),
        (["evaluate", "triplets", "--data", "{data}", "--embedder", "resnet18"], "choose one of sdn, spectral"),
        (["evaluate", "wind", "--data", "{data}", "--embedder", "spectral", "--model", "{tmp}"], "no weights file"),
        (["evaluate", "wind", "--data", "{data}", "--embedder", "spectral", "--target", "colour"], "colour"),
        (["evaluate", "wind", "--data", "{tmp}", "--embedder", "spectral"], "not a dataset"),
        (["evaluate", "triplets", "--data", "{data}", "--model", "{data}"], "no SDN weights"),
    ],
)
def test_bad_inputs_exit_2_with_one_json_error(app, data, tmp_path, args, message):
    fill = {"missing": str(tmp_path / "missing"), "tmp": str(tmp_path), "data": str(data)}
    command = [a.format(**fill) for a in args]
    reply = invoke(app, *command, "-p", "flag", code=2)
    assert message in reply["error"]


def test_installed_cli_mounts_the_commands_and_refuses_other_plugins(tmp_path):
    help_text = subprocess.run(
        [str(BIN), "evaluate", "--help"], capture_output=True, text=True, check=True
    ).stdout
    assert "triplets" in help_text and "wind" in help_text
    proc = subprocess.run(
        [str(BIN), "train", "--plugin", "pendulum_lab", "--data", str(tmp_path), "--out", str(tmp_path / "m"), "--json"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2, proc.stderr
    error = json.loads(proc.stdout)["error"]
    assert "flag" in error and "pendulum_lab" in error
    assert proc.stderr.startswith("error:") and "Traceback" not in proc.stderr
