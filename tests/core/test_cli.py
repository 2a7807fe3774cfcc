import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from physinfer.types import Clip
from physinfer.video import write_video

BIN = Path(sys.executable).parent / "physinfer"


def run_cli(*args, check=True, timeout=300):
    proc = subprocess.run([str(BIN), *args], capture_output=True, text=True, timeout=timeout)
    if check and proc.returncode != 0:
        raise AssertionError(f"exit {proc.returncode}\nstdout: {proc.stdout}\nstderr: {proc.stderr}")
    return proc


def json_out(proc):
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected exactly one JSON line on stdout, got: {proc.stdout!r}"
    return json.loads(lines[0])


def test_help_imports_no_heavy_library():
    """What keeps ``--help`` fast (its time is in benchmarks/bench_cli_startup.py: a wall-time
    assertion here failed on a loaded machine)."""
    run_cli("--help")
    code = (
        "import sys; from physinfer.cli.app import _mount_plugin_commands; _mount_plugin_commands(); "
        "heavy = [m for m in ('torch', 'pyrender', 'ax', 'botorch', 'OpenGL') if m in sys.modules]; print(heavy)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", f"--help imports heavy modules: {out}"


def test_plugins_json_lists_example_and_optimizers():
    data = json_out(run_cli("plugins", "--json"))
    by_name = {p["name"]: p for p in data["plugins"]}
    assert by_name["pendulum_lab"]["phenomena"] == ["pendulum_lab"]
    assert by_name["pendulum_lab"]["effects"] == ["quadratic_drag"]
    assert by_name["pendulum_lab"]["distribution"] == "physinfer-pendulum-example"
    assert set(by_name["builtins"]["optimizers"]) == {"ax", "random", "cma"}
    for key in ("name", "distribution", "version", "phenomena", "optimizers", "embedders", "effects", "error"):
        assert key in by_name["builtins"]


def test_simulate_writes_video_and_trajectory(tmp_path):
    out, traj = tmp_path / "p.mp4", tmp_path / "p.npz"
    data = json_out(
        run_cli("simulate", "--plugin", "pendulum_lab", "--set", "length=0.8", "--out", str(out),
                "--trajectory-out", str(traj), "--json")
    )
    assert data["params"]["length"] == 0.8 and out.stat().st_size > 1000
    with np.load(traj, allow_pickle=False) as z:
        assert z["vertices"].shape[0] == data["n_frames"] and z["faces"].shape[1] == 3


@pytest.mark.parametrize(
    "args,message",
    [
        (["refine", "--plugin", "nope"], "unknown plugin/phenomenon 'nope'; installed:"),
        (["simulate", "--plugin", "pendulum_lab", "--set", "length=9", "--out", "x.mp4"],
         "length=9 is outside its bounds [0.4, 1.6] m"),
        (["simulate", "--plugin", "pendulum_lab", "--set", "lenght=1", "--out", "x.mp4"],
         "unknown parameter 'lenght'; known parameters: length, damping, amplitude"),
        (["refine", "--plugin", "pendulum_lab", "--target", "missing.mp4"], "does not exist"),
        (["refine", "--plugin", "pendulum_lab", "--optimizer", "sgd"], "unknown optimizer 'sgd'; installed: ax, cma, random"),
        (["simulate", "--plugin", "pendulum_lab", "--effect", "gusts", "--out", "x.mp4"], "unknown effect 'gusts'"),
    ],
)
def test_bad_input_gives_one_clear_line(tmp_path, args, message):
    proc = subprocess.run([str(BIN), *args, "--json"], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert message in " ".join(proc.stderr.split()), proc.stderr
    assert "Traceback" not in proc.stderr
    assert message in json_out(proc)["error"]


def test_unreadable_and_too_short_targets(tmp_path):
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video at all")
    proc = run_cli("refine", "--plugin", "pendulum_lab", "--target", str(bad), "--out", str(tmp_path / "r"), check=False)
    assert proc.returncode == 2 and "cannot decode the video" in proc.stderr
    short = tmp_path / "short.mp4"
    noise = np.random.default_rng(0).integers(0, 255, (10, 64, 64, 3), dtype=np.uint8)  # moving, too short
    write_video(short, Clip(noise, 25.0))
    proc = run_cli("refine", "--plugin", "pendulum_lab", "--target", str(short), "--out", str(tmp_path / "r"), check=False)
    assert proc.returncode == 2
    assert "too short" in proc.stderr and "needs at least 100 frames" in " ".join(proc.stderr.split())
    assert not (tmp_path / "r").exists(), "a refused target must leave no run directory"


def test_unknown_render_setting_fails_before_simulating(tmp_path):
    proc = subprocess.run(
        [str(BIN), "simulate", "--plugin", "pendulum_lab", "--render-set", "sise=64", "--out", str(tmp_path / "p.mp4"), "--json"],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 2
    assert "sise" in json.loads(proc.stdout)["error"] and "size" in proc.stderr
    assert not (tmp_path / "p.mp4").exists()


def test_refine_suggests_more_search_only_when_the_fit_is_well_above_the_noise_floor():
    from physinfer.cli.app import NOISE_RATIO_HINT, noise_ratio_hint

    assert noise_ratio_hint(None) is None and noise_ratio_hint(0.9) is None
    assert noise_ratio_hint(NOISE_RATIO_HINT) is None
    hint = noise_ratio_hint(2.84)
    assert "noise ratio 2.84" in hint and "--resume --steps" in hint and "physinfer diagnose" in hint


#: Makes the pendulum's simulator raise a bug (not a user error) in the CLI's process.
PLUGIN_BUG = """
import pendulum_example.physics as physics

def broken(self, params, *, seed=0):
    raise ZeroDivisionError("a bug in the plugin")

physics.PendulumSimulator.simulate = broken
"""


def test_an_internal_error_is_one_line_with_a_saved_traceback_outside_out(tmp_path):
    hooks = tmp_path / "hooks"
    hooks.mkdir()
    (hooks / "sitecustomize.py").write_text(PLUGIN_BUG)
    path = os.pathsep.join(filter(None, [str(hooks), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": path, "TMPDIR": str(tmp_path / "tmp")}
    (tmp_path / "tmp").mkdir()
    out = tmp_path / "clip.mp4"
    for as_json in (False, True):
        proc = subprocess.run(
            [str(BIN), "simulate", "--plugin", "pendulum_lab", "--out", str(out), *(["--json"] if as_json else [])],
            capture_output=True, text=True, timeout=300, env=env,
        )  # fmt: skip
        assert proc.returncode == 1, proc.stderr
        assert "Traceback" not in proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1, proc.stderr
        match = re.fullmatch(
            r"error: internal error \(ZeroDivisionError: a bug in the plugin\); traceback saved to (\S+)", lines[0]
        )
        assert match, lines[0]
        saved = Path(match.group(1))
        assert saved.parent == tmp_path / "tmp" / "physinfer-errors"
        assert "Traceback" in saved.read_text() and "def broken" not in proc.stderr
        if as_json:
            reply = json_out(proc)
            assert reply == {"error": lines[0].removeprefix("error: "), "traceback": str(saved)}
        else:
            assert proc.stdout == ""
    assert not out.exists()


def test_dataset_generate_takes_the_one_error_path(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from physinfer.cli import dataset_cmd

    command = ["generate", "-p", "nope", "--out", str(tmp_path / "d"), "--json"]
    result = CliRunner().invoke(dataset_cmd.dataset_app, command)
    assert result.exit_code == 2 and "unknown plugin/phenomenon 'nope'" in json.loads(result.stdout)["error"]

    def bug(**_kwargs):
        raise KeyError("units")

    monkeypatch.setattr(dataset_cmd, "_generate", bug)  # a fault injected where the work starts
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    result = CliRunner().invoke(dataset_cmd.dataset_app, command)
    assert result.exit_code == 1, result.output
    reply = json.loads(result.stdout)
    assert reply["error"].startswith("internal error (KeyError: 'units'); traceback saved to ")
    assert Path(reply["traceback"]).parent == tmp_path / "physinfer-errors"
    assert "KeyError: 'units'" in Path(reply["traceback"]).read_text()
