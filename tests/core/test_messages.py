"""Messages that help (issue 25, item 6): say what to do, in the CLI's own words.

An effect's parameter given without its effect names the effect to add; an invalid
``--fps`` says the value given is invalid; ``train``'s resume errors name ``--no-resume``; an
unknown command (one a blocked plugin would add) is one line and, under ``--json``, one JSON
object.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from physinfer.errors import UserInputError
from physinfer.video import read_video

BIN = Path(sys.executable).parent / "physinfer"
ADD_DRAG = "belongs to the effect quadratic_drag: add --effect quadratic_drag"


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (
            ("simulate", "--set", "drag_quadratic=1", "--out", "x.mp4"),
            f"drag_quadratic (in --set) {ADD_DRAG}",
        ),
        (("refine", "--fix", "drag_*=1", "--out", "r"), f"drag_* (in --fix) {ADD_DRAG}"),
        (
            ("refine", "--truth", "drag_quadratic=1", "--out", "r"),
            f"drag_quadratic (in --truth) {ADD_DRAG}",
        ),
        (
            ("diagnose", "--fix", "drag_quadratic=1", "--out", "d"),
            "drag_quadratic (in --fix) belongs to the effect quadratic_drag, which diagnose tries itself",
        ),
    ],
)
def test_an_effects_parameter_without_its_effect_names_the_effect(
    physinfer_cli, tmp_path, args, expected
):
    ran = physinfer_cli(args[0], "--plugin", "pendulum_lab", *args[1:], "--json", cwd=tmp_path)
    assert ran.returncode == 2, ran.stderr
    assert ran.json()["error"].startswith(expected)
    assert list(tmp_path.iterdir()) == [], "refused before anything is written"


def test_an_unknown_name_that_is_no_effects_still_lists_the_known_ones(physinfer_cli, tmp_path):
    ran = physinfer_cli(
        "simulate",
        "--plugin",
        "pendulum_lab",
        "--set",
        "lenght=1",
        "--out",
        "x.mp4",
        "--json",
        cwd=tmp_path,
    )
    assert (
        ran.returncode == 2
        and "unknown parameter 'lenght'; known parameters: length" in ran.json()["error"]
    )


@pytest.mark.parametrize("fps", [0.0, float("nan"), -25.0, float("inf")])
def test_an_invalid_fps_is_named_as_invalid_not_missing(tmp_path, fps):
    with pytest.raises(
        UserInputError, match=rf"--fps {fps:g} is not a frame rate; give a positive number"
    ):
        read_video(tmp_path / "target.mp4", fps=fps)


def test_train_resume_errors_name_the_cli_option(tmp_path):
    from physinfer_flag.sdn.training import _check_resumable, read_checkpoint

    broken = tmp_path / "checkpoint.safetensors"
    broken.write_bytes(b"not a checkpoint")
    with pytest.raises(UserInputError, match="delete it or pass --no-resume$"):
        read_checkpoint(broken)
    stored = {
        "model_config": {"size": 32},
        "train_config": {"epochs": 1, "batch_size": 12, "lr": 0.01},
    }
    other_size = {**stored, "model_config": {"size": 64}}
    with pytest.raises(
        UserInputError,
        match=r"model config \(--frames, --size\); use another --out, or pass --no-resume",
    ):
        _check_resumable(stored, other_size, broken)
    other_batch = {**stored, "train_config": {"epochs": 3, "batch_size": 16, "lr": 0.01}}
    with pytest.raises(UserInputError) as info:
        _check_resumable(stored, other_batch, broken)
    assert "other settings (--batch-size); only --epochs may change" in str(info.value)
    assert "resume=False" not in str(info.value)


def test_a_blocked_plugins_command_under_json_is_one_json_error(tmp_path):
    env = {**os.environ, "PHYSINFER_DISABLED_PLUGINS": "flag"}
    proc = subprocess.run(
        [str(BIN), "train", "--json"],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=120,
    )
    assert proc.returncode == 2 and "Usage" not in proc.stderr and "Traceback" not in proc.stderr
    error = json.loads(proc.stdout)["error"]
    assert (
        error
        == "no such command 'train'; PHYSINFER_DISABLED_PLUGINS=flag blocks those plugins and their commands"
    )


def test_a_user_error_may_keep_its_remedy_apart():
    from physinfer.errors import UserInputError

    error = UserInputError("the file is damaged", remedy="generate it again")
    assert str(error) == "the file is damaged; generate it again"
    assert (error.reason, error.remedy) == ("the file is damaged", "generate it again")
    plain = UserInputError("one line; with its remedy")
    assert (str(plain), plain.reason, plain.remedy) == ("one line; with its remedy", "one line; with its remedy", None)
