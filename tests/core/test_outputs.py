"""Every command owns what it writes (issue 45, item 1).

``simulate``, ``prepare`` and ``posterior train`` refuse an existing output file unless
``--overwrite`` is given, before any work; ``--trajectory-out`` must name an ``.npz``; an output
in a folder that cannot be written is refused before any work. (Checked values, seeds and
frame rates: ``test_checked_values.py``.)
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import physinfer.api as pi
from physinfer.errors import UserInputError
from physinfer.io import check_output_file
from physinfer.types import Clip
from physinfer.video import read_video, write_video

MINE = b"the user's own file, not to be written over"


#: The worked example's phenomenon: fast to simulate.
PENDULUM = "pendulum_lab"


def mine(path: Path) -> Path:
    path.write_bytes(MINE)
    return path


def one_error(ran) -> str:
    """The one ``{"error": ...}`` a refused ``--json`` command printed (exit 2, one stderr line)."""
    assert ran.returncode == 2, ran.stderr
    assert " ".join(ran.stderr.split()).count("error:") == 1 and "Traceback" not in ran.stderr
    return ran.json()["error"]


# ------------------------------------------------------------------------------ simulate


@pytest.mark.parametrize("option", ["--out", "--trajectory-out"])
def test_simulate_refuses_an_existing_output_before_simulating(physinfer_cli, tmp_path, option):
    existing = mine(tmp_path / ("mine.mp4" if option == "--out" else "mine.npz"))
    # The flag would simulate for seconds: refused before, so nothing is simulated.
    ran = physinfer_cli("simulate", "--plugin", "flag", option, existing, "--json")
    error = one_error(ran)
    assert error == f"{option} {existing} exists; give --overwrite to replace it, or another name"
    assert existing.read_bytes() == MINE


def test_simulate_with_overwrite_replaces_both_outputs(physinfer_cli, tmp_path):
    video, trajectory = mine(tmp_path / "mine.mp4"), mine(tmp_path / "mine.npz")
    ran = physinfer_cli(
        "simulate", "--plugin", PENDULUM, "--render-set", "size=32", "--out", video,
        "--trajectory-out", trajectory, "--overwrite", "--json",
    )  # fmt: skip
    assert ran.returncode == 0, ran.stderr
    assert ran.json()["video"] == str(video) and ran.json()["trajectory"] == str(trajectory)
    assert read_video(video).n_frames > 1
    with np.load(trajectory) as data:
        assert data["vertices"].ndim == 3


def test_trajectory_out_must_be_an_npz_and_not_the_video(physinfer_cli, tmp_path):
    for args, expected in (
        (("--trajectory-out", tmp_path / "t.mp4"), f"--trajectory-out {tmp_path / 't.mp4'}: name the trajectory file *.npz"),
        (("--out", tmp_path / "x.mp4", "--trajectory-out", tmp_path / "x.mp4"),
         f"--trajectory-out {tmp_path / 'x.mp4'}: name the trajectory file *.npz"),
        (("--out", tmp_path / "x.npz", "--trajectory-out", tmp_path / "x.npz"),
         f"--out {tmp_path / 'x.npz'}: write a .mp4 or .gif file"),
    ):  # fmt: skip
        assert one_error(physinfer_cli("simulate", "--plugin", "flag", *args, "--json")) == expected
    assert not list(tmp_path.iterdir())


def test_simulate_refuses_an_out_it_cannot_write(physinfer_cli, tmp_path):
    mine(tmp_path / "notes.txt")
    error = one_error(
        physinfer_cli("simulate", "--plugin", "flag", "--out", tmp_path / "notes.txt" / "a.mp4", "--json")
    )
    assert error == f"--out {tmp_path / 'notes.txt' / 'a.mp4'}: {tmp_path / 'notes.txt'} is a file, so nothing can be written under it"
    error = one_error(physinfer_cli("simulate", "--plugin", "flag", "--trajectory-out", "/proc/t.npz", "--json"))
    assert error.startswith("--trajectory-out /proc/t.npz: cannot write in /proc (")


def test_the_api_refuses_an_existing_output_and_overwrites_when_told(tmp_path):
    video = mine(tmp_path / "mine.mp4")
    with pytest.raises(UserInputError, match="exists; give --overwrite"):
        pi.simulate("flag", out=video)
    sim = pi.simulate(PENDULUM, out=video, render_set={"size": 32}, overwrite=True)
    assert sim.paths["video"] == str(video) and video.read_bytes() != MINE


# ------------------------------------------------------------------------------- prepare


def moving_video(path: Path) -> Path:
    """A small clip with a moving patch (enough for ``prepare`` to find a subject)."""
    rng = np.random.default_rng(0)
    frames = np.tile(rng.integers(60, 90, (1, 96, 160, 3), dtype=np.uint8), (20, 1, 1, 1))
    for t in range(20):
        x = 60 + t
        frames[t, 30:60, x : x + 25] = (220, 120, 60)
    write_video(path, Clip(frames, 25.0), lossless=True)
    return path


@pytest.mark.parametrize("which", ["prepared.mp4", "prepared.json", "prepared_overlay.png"])
def test_prepare_refuses_to_write_over_its_out_or_the_files_beside_it(physinfer_cli, tmp_path, which):
    target = moving_video(tmp_path / "in.mp4")
    existing = mine(tmp_path / which)
    ran = physinfer_cli("prepare", "--plugin", "flag", "--target", target, "--out", tmp_path / "prepared.mp4",
                        "--json")  # fmt: skip
    out = tmp_path / "prepared.mp4"
    shown = f"--out {out}" if existing == out else f"--out {out}: {existing}"
    assert one_error(ran) == f"{shown} exists; give --overwrite to replace it, or another name"
    assert existing.read_bytes() == MINE
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({"in.mp4", which})


def test_prepare_with_overwrite_replaces_all_three(physinfer_cli, tmp_path):
    target = moving_video(tmp_path / "in.mp4")
    for name in ("prepared.mp4", "prepared.json", "prepared_overlay.png"):
        mine(tmp_path / name)
    ran = physinfer_cli("prepare", "--plugin", PENDULUM, "--target", target, "--out", tmp_path / "prepared.mp4",
                        "--no-render-estimate", "--overwrite", "--json")  # fmt: skip
    assert ran.returncode == 0, ran.stderr
    assert json.loads((tmp_path / "prepared.json").read_text())["video"] == str(tmp_path / "prepared.mp4")
    assert (tmp_path / "prepared_overlay.png").read_bytes()[:4] == b"\x89PNG"
    assert read_video(tmp_path / "prepared.mp4").n_frames > 1


def test_prepare_never_writes_over_its_target_even_with_overwrite(physinfer_cli, tmp_path):
    target = moving_video(tmp_path / "in.mp4")
    ran = physinfer_cli("prepare", "--plugin", "flag", "--target", target, "--out", target, "--overwrite", "--json")
    assert "would overwrite --target" in one_error(ran)


# ----------------------------------------------------------------------- posterior train


@pytest.fixture
def no_training(monkeypatch):
    """Training that fails the test if it starts: a refusal must come before it."""
    import physinfer.posterior.train_workflow as workflow

    def train(*args, **kwargs):
        raise AssertionError("training started")

    monkeypatch.setattr(workflow, "train_posterior", train)


def test_posterior_train_refuses_an_existing_estimator_before_training(physinfer_cli, tmp_path, no_training):
    weights = mine(tmp_path / "w.safetensors")
    ran = physinfer_cli("posterior", "train", "--plugin", "flag", "--data", tmp_path, "--out", weights, "--json")
    assert one_error(ran) == f"--out {weights} exists; give --overwrite to replace it, or another name"
    assert weights.read_bytes() == MINE
    with pytest.raises(AssertionError, match="training started"):  # --overwrite goes on to train
        pi.train_posterior("flag", data=tmp_path, out=weights, overwrite=True)


@pytest.mark.parametrize(
    ("out", "expected"),
    [
        ("notes.txt/w.safetensors", "notes.txt is a file, so nothing can be written under it"),
        ("/proc/w.safetensors", "cannot write in /proc ("),
        ("w.pt", "name the estimator file *.safetensors"),
        ("folder.safetensors", "is a directory; give a file name"),
    ],
)
def test_posterior_train_refuses_an_out_it_cannot_write_before_training(tmp_path, no_training, out, expected):
    mine(tmp_path / "notes.txt")
    (tmp_path / "folder.safetensors").mkdir()
    path = out if out.startswith("/") else tmp_path / out
    with pytest.raises(UserInputError, match=None) as info:
        pi.train_posterior("flag", data=tmp_path, out=path)
    assert expected in str(info.value)


# ------------------------------------------------------------------------------- helper


def test_check_output_file_says_what_is_wrong(tmp_path):
    mine(tmp_path / "a.npz")
    with pytest.raises(UserInputError, match="exists; give --overwrite"):
        check_output_file(tmp_path / "a.npz", "--x")
    assert check_output_file(tmp_path / "a.npz", "--x", overwrite=True) == tmp_path / "a.npz"
    assert check_output_file(tmp_path / "new" / "deeper" / "b.npz", "--x") == tmp_path / "new" / "deeper" / "b.npz"
    assert not (tmp_path / "new").exists()  # checking makes nothing
    with pytest.raises(UserInputError, match=r"--x .*c.txt: name the thing \*.npz"):
        check_output_file(tmp_path / "c.txt", "--x", suffixes=(".npz",), what="the thing")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz"]  # no probe left behind
