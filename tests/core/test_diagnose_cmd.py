"""Tests of the ``physinfer diagnose`` command and of ``physinfer refine --model``."""

from __future__ import annotations

import json
from pathlib import Path


def test_diagnose_json_then_refine_with_the_model(tmp_path: Path, physinfer_cli):
    target = tmp_path / "drag.mp4"
    sim = physinfer_cli("simulate", "--plugin", "pendulum_lab", "--effect", "quadratic_drag", "--set", "drag_quadratic=1.0",
               "--render-set", "size=48", "--out", str(target))
    assert sim.returncode == 0, sim.stderr
    out = tmp_path / "diag"
    proc = physinfer_cli("diagnose", "--plugin", "pendulum_lab", "--target", str(target), "--render-set", "size=48",
                "--steps", "2", "--optimizer", "random", "--floor-samples", "4", "--no-video", "--workers", "0",
                "--no-limits", "--no-ridge-starts", "--calibration-runs", "1", "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1
    report = json.loads(lines[0])
    assert report["candidates"][0]["effect"] == "quadratic_drag"
    assert isinstance(report["misspecified"], bool)
    assert report["adequacy"]["at"] in ("best baseline fit", "model with quadratic_drag")  # refine's verdict
    # Hand-edit the model file to the augmented model: refine --model switches drag in and
    # starts from the file's values.
    model = json.loads((out / "model.json").read_text())
    model["effects"] = ["quadratic_drag"]
    model["values"] = {**report["baseline"]["best_params"], "drag_quadratic": 0.7}
    (out / "model.json").write_text(json.dumps(model))
    run_dir = tmp_path / "refined"
    proc = physinfer_cli("refine", "--plugin", "pendulum_lab", "--target", str(target), "--render-set", "size=48",
                "--model", str(out / "model.json"), "--steps", "2", "--optimizer", "random",
                "--out", str(run_dir), "--json")
    assert proc.returncode == 0, proc.stderr
    first = json.loads((run_dir / "trials.jsonl").read_text().splitlines()[0])
    assert first["params"]["drag_quadratic"] == 0.7
    assert json.loads((run_dir / "run.json").read_text())["effects"] == ["quadratic_drag"]


def test_an_effect_s_significant_improvement_shows_misspecification_the_gap_test_missed(tmp_path: Path, physinfer_cli):
    """With a gap-test threshold no gap reaches, the drag model's significant improvement alone
    makes the model misspecified and names drag; ``--require-gap-test`` (re-run on the same
    stages) names nothing."""
    target = tmp_path / "drag.mp4"
    sim = physinfer_cli("simulate", "--plugin", "pendulum_lab", "--effect", "quadratic_drag", "--set", "drag_quadratic=1.4",
               "--set", "amplitude=50", "--render-set", "size=48", "--out", str(target))
    assert sim.returncode == 0, sim.stderr
    args = ["diagnose", "--plugin", "pendulum_lab", "--target", str(target), "--render-set", "size=48", "--steps", "8",
            "--effect-steps", "16", "--optimizer", "cma", "--floor-samples", "4", "--calibration-runs", "1",
            "--threshold", "1000", "--no-video", "--no-ridge-starts", "--workers", "0", "--out", str(tmp_path / "diag")]
    proc = physinfer_cli(*args)
    assert proc.returncode == 0, proc.stderr
    report = json.loads((tmp_path / "diag" / "diagnosis.json").read_text())
    assert not report["gap_test"] and report["gap_before"] < report["threshold"]
    assert report["misspecified"] and report["misspecified_by"] == ["effect"]
    assert report["named_effect"] == "quadratic_drag" and report["candidates"][0]["significant"]
    assert report["named_leaves"] is None  # the drag model's gap passes the gap test
    assert "misspecified True (by an effect's significant improvement)" in " ".join(proc.stderr.split())
    # One line per candidate with its detection limit on this clip.
    assert "quadratic_drag: named; this 4-s clip could" in " ".join(proc.stderr.split())
    assert "took " in proc.stderr and "effect-quadratic_drag" in report["timing"]["stages_s"]
    strict = physinfer_cli(*args, "--require-gap-test", "--json", "--no-limits")  # the decision alone
    assert strict.returncode == 0, strict.stderr
    report = json.loads(strict.stdout)
    assert report["settings"]["rule"]["effect_evidence"] is False
    assert report["candidates"][0]["significant"]  # the same stages, resumed
    assert not report["misspecified"] and report["misspecified_by"] == [] and report["named_effect"] is None


def test_refine_model_errors(tmp_path: Path, physinfer_cli):
    proc = physinfer_cli("refine", "--plugin", "pendulum_lab", "--model", str(tmp_path / "none.json"), "--steps", "1",
                "--out", str(tmp_path / "r"))
    assert proc.returncode == 2 and "no such file" in proc.stderr
    bad = tmp_path / "flag_model.json"
    bad.write_text(json.dumps({"format": "physinfer-model/1", "plugin": "flag", "effects": [], "parameters": [],
                               "values": {}}))
    proc = physinfer_cli("refine", "--plugin", "pendulum_lab", "--model", str(bad), "--steps", "1", "--out", str(tmp_path / "r"))
    assert proc.returncode == 2 and "not of --plugin 'pendulum_lab'" in proc.stderr


def test_diagnose_refuses_too_few_floor_samples(tmp_path: Path, physinfer_cli):
    proc = physinfer_cli("diagnose", "--plugin", "pendulum_lab", "--floor-samples", "2", "--out", str(tmp_path / "d"), "--json")
    assert proc.returncode == 2
    assert "floor-samples" in json.loads(proc.stdout)["error"]


def test_diagnose_refuses_zero_calibration_runs(tmp_path: Path, physinfer_cli):
    proc = physinfer_cli("diagnose", "--plugin", "pendulum_lab", "--calibration-runs", "0", "--out", str(tmp_path / "d"), "--json")
    assert proc.returncode == 2
    assert "--calibration-runs must be at least 1" in json.loads(proc.stdout)["error"]


def test_refine_reports_a_fit_that_ended_on_a_bound(tmp_path: Path, physinfer_cli):
    """A one-step refinement warm-started on the length's upper bound ends there: result.json
    and the printed result say so (a fit stopped by its search range is not an answer)."""
    model = tmp_path / "model.json"
    model.write_text(json.dumps({
        "format": "physinfer-model/1", "plugin": "pendulum_lab", "effects": [],
        "parameters": [{"name": "length", "bounds": [0.4, 1.6]}, {"name": "damping", "bounds": [0.0, 0.6]},
                       {"name": "amplitude", "bounds": [10.0, 60.0]}],
        "values": {"length": 1.6, "damping": 0.2, "amplitude": 30.0},
    }))
    run_dir = tmp_path / "run"
    proc = physinfer_cli("refine", "--plugin", "pendulum_lab", "--model", str(model), "--steps", "1", "--optimizer", "random",
                "--render-set", "size=48", "--noise-samples", "0", "--floor-samples", "0", "--out", str(run_dir))
    assert proc.returncode == 0, proc.stderr
    assert json.loads((run_dir / "result.json").read_text())["at_bounds"] == {"length": "upper"}
    length_line = next(line for line in proc.stderr.splitlines() if line.startswith("  length = 1.6"))
    assert length_line.endswith("(at its upper bound)")
    assert not any("damping" in line and "bound" in line for line in proc.stderr.splitlines())
    assert "length ended on a bound of the search range" in proc.stderr


def test_a_diagnosis_continued_with_other_settings_is_refused_in_diagnose_s_words(tmp_path: Path, physinfer_cli):
    """Refine's remedy (``--overwrite``) is an option diagnose does not have."""
    target = tmp_path / "clean.mp4"
    sim = physinfer_cli("simulate", "--plugin", "pendulum_lab", "--render-set", "size=48", "--out", str(target))
    assert sim.returncode == 0, sim.stderr
    out = tmp_path / "diag"
    args = ["diagnose", "--plugin", "pendulum_lab", "--target", str(target), "--render-set", "size=48",
            "--steps", "2", "--optimizer", "random", "--floor-samples", "4", "--no-video", "--workers", "0",
            "--no-limits", "--no-ridge-starts", "--calibration-runs", "1", "--out", str(out)]
    assert physinfer_cli(*args).returncode == 0
    proc = physinfer_cli(*args, "--seed", "5")
    assert proc.returncode == 2
    message = " ".join(proc.stderr.split())
    assert f"{out} holds a diagnosis made otherwise (its baseline stage: --seed: run 0, now 5)" in message
    assert "--overwrite" not in message and "Traceback" not in proc.stderr
