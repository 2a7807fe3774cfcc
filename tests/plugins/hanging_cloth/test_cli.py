"""``physinfer dataset bouman``, ``physinfer evaluate bouman`` and ``refine --plugin hanging_cloth``.

Commands run in process (typer's CliRunner); one subprocess test checks that the installed
CLI mounts both commands under their groups.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from physinfer_hanging_cloth.cli import dataset_bouman_cmd, evaluate_bouman_cmd

BIN = Path(sys.executable).parent / "physinfer"


@pytest.fixture(scope="module")
def app():
    cli = typer.Typer()
    evaluate, dataset = typer.Typer(), typer.Typer()
    evaluate.command("bouman")(evaluate_bouman_cmd)
    dataset.command("bouman")(dataset_bouman_cmd)
    cli.add_typer(evaluate, name="evaluate")
    cli.add_typer(dataset, name="dataset")
    return cli


def invoke(app, *args: str, code: int = 0) -> dict:
    """Run a command with --json; check its exit status; return its one JSON object."""
    result = CliRunner().invoke(app, [*args, "--json"])
    assert result.exit_code == code, f"exit {result.exit_code}: {result.output}\n{result.exception!r}"
    lines = [line for line in result.stdout.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one JSON line on stdout, got {result.stdout!r}"
    return json.loads(lines[0])


@pytest.fixture(scope="module")
def data(app, tmp_path_factory):
    root = tmp_path_factory.mktemp("bouman") / "data"
    summary = invoke(app, "dataset", "bouman", "--out", str(root), "--fabrics", "4", "--frames", "32",
                     "--size", "48", "--seed", "1")
    assert summary["n_videos"] == 12 and summary["written"] == 12
    return root


def test_evaluate_end_to_end_with_the_spectral_embedder(app, data, tmp_path):
    out = tmp_path / "eval"
    summary = invoke(app, "evaluate", "bouman", "--data", str(data), "--embedder", "spectral",
                     "--device", "cpu", "--out", str(out))
    assert summary.keys() >= {"pearson_stiffness", "pearson_area_weight", "n_videos", "n_fabrics"}
    assert summary["n_videos"] == 12 and summary["n_fabrics"] == 4
    assert -1.0 <= summary["pearson_stiffness"] <= 1.0 and -1.0 <= summary["pearson_area_weight"] <= 1.0
    assert summary["pca_dims"] == 8  # 9 training videos per fold: at most 8 components
    assert (out / "bouman.png").read_bytes()[:4] == b"\x89PNG"
    assert json.loads((out / "result.json").read_text())["n_videos"] == 12
    rows = (out / "predictions.csv").read_text().splitlines()
    assert len(rows) == 13 and rows[1].startswith("fabric01_W1.mp4,fabric01,W1,")


def test_evaluate_reports_user_errors_with_status_2(app, data, tmp_path):
    missing = invoke(app, "evaluate", "bouman", "--data", str(tmp_path / "nope"), "--embedder", "spectral", code=2)
    assert "does not exist" in missing["error"]
    unknown = invoke(app, "evaluate", "bouman", "--data", str(data), "--embedder", "nope", code=2)
    assert "unknown embedder 'nope'" in unknown["error"]
    weights = invoke(app, "evaluate", "bouman", "--data", str(data), "--embedder", "sdn",
                     "--model", str(tmp_path / "none.safetensors"), "--device", "cpu", code=2)
    assert "none.safetensors" in weights["error"]
    bad = invoke(app, "evaluate", "bouman", "--data", str(data), "--pca-dims", "0", code=2)
    assert "--pca-dims" in bad["error"]


def test_sdn_without_shipped_weights_says_what_to_do(app, data, tmp_path):
    from physinfer_flag.sdn.weights import DEFAULT_WEIGHTS

    if DEFAULT_WEIGHTS.is_file():
        pytest.skip("the SDN default weights are shipped")
    error = invoke(app, "evaluate", "bouman", "--data", str(data), "--device", "cpu", code=2)["error"]
    assert "weights are missing" in error and "--embedder spectral" in error


def test_dataset_refuses_bad_settings(app, tmp_path):
    error = invoke(app, "dataset", "bouman", "--out", str(tmp_path / "d"), "--fabrics", "2", code=2)["error"]
    assert "fabrics" in error


def test_refine_runs_on_the_hanging_cloth(tmp_path):
    from physinfer.cli.app import app as main_app

    out = tmp_path / "run"
    result = CliRunner().invoke(
        main_app,
        ["refine", "--plugin", "hanging_cloth", "--steps", "2", "--optimizer", "random", "--device", "cpu",
         "--noise-samples", "0", "--floor-samples", "0", "--out", str(out), "--json"],
    )
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    assert summary["n_trials"] == 2 and summary["n_failed"] == 0
    assert set(summary["best_params"]) == {"bending_multiplier", "area_weight"}
    assert summary["ground_truth"] == {"bending_multiplier": 12.0, "area_weight": 0.12}
    assert (out / "side_by_side.mp4").is_file()


def test_installed_cli_mounts_both_commands():
    for group in ("evaluate", "dataset"):
        done = subprocess.run([str(BIN), group, "--help"], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0 and "bouman" in done.stdout
