"""Every value is checked (issue 45, item 3): a frame rate outside 0.1-1000 fps is refused
instead of written as 24 fps; a seed outside 0..2**32-1 is one line for every command, plugin
commands included, and for the library, not a traceback.
"""

from __future__ import annotations

import numpy as np
import pytest

import physinfer.api as pi
from physinfer.errors import UserInputError
from physinfer.video import read_video, write_video


def one_error(ran) -> str:
    """The one ``{"error": ...}`` a refused ``--json`` command printed (exit 2, one stderr line)."""
    assert ran.returncode == 2, ran.stderr
    assert " ".join(ran.stderr.split()).count("error:") == 1 and "Traceback" not in ran.stderr
    return ran.json()["error"]


# ------------------------------------------------------------------------- frame rates


@pytest.mark.parametrize("fps", ["1e-9", "0.05", "5000"])
def test_render_refuses_a_frame_rate_outside_the_range_it_can_write(physinfer_cli, tmp_path, fps):
    trajectory = tmp_path / "t.npz"
    np.savez(trajectory, vertices=np.zeros((3, 3, 3), np.float32), faces=np.array([[0, 1, 2]], np.int32),
             fps=np.float64(25))  # fmt: skip
    ran = physinfer_cli("render", "--plugin", "flag", "--trajectory", trajectory, "--fps", fps,
                        "--out", tmp_path / "x.mp4", "--json")  # fmt: skip
    assert one_error(ran) == f"--fps {float(fps):g}: give a frame rate from 0.1 to 1000 frames per second"
    assert not (tmp_path / "x.mp4").exists()


def test_a_trajectory_file_at_an_unwritable_frame_rate_is_refused(tmp_path):
    from physinfer.meshio import load_trajectory

    trajectory = tmp_path / "t.npz"
    np.savez(trajectory, vertices=np.zeros((3, 3, 3), np.float32), faces=np.array([[0, 1, 2]], np.int32),
             fps=np.float64(1e-9))  # fmt: skip
    with pytest.raises(UserInputError, match=r"t.npz records 1e-09 fps; give --fps from 0.1 to 1000"):
        load_trajectory(trajectory)


def test_a_target_frame_rate_outside_the_range_is_refused(tmp_path):
    with pytest.raises(UserInputError, match=r"--fps 2000: give a frame rate from 0.1 to 1000"):
        read_video(tmp_path / "any.mp4", fps=2000.0)


def test_write_video_never_writes_another_frame_rate_than_the_clips(tmp_path):
    frames = np.zeros((2, 16, 16, 3), np.uint8)
    with pytest.raises(ValueError, match="cannot write 1e-09 fps"):
        write_video(tmp_path / "x.mp4", frames, fps=1e-9)
    assert not (tmp_path / "x.mp4").exists()
    write_video(tmp_path / "y.mp4", frames, fps=0.5)
    assert read_video(tmp_path / "y.mp4").fps == pytest.approx(0.5)


# --------------------------------------------------------------------------------- seeds


@pytest.mark.parametrize("seed", ["-1", str(2**32), "99999999999999999999"])
@pytest.mark.parametrize(
    "command",
    [
        ("simulate", "--plugin", "flag", "--out", "x.mp4"),
        ("refine", "--plugin", "flag", "--out", "run"),
        ("diagnose", "--plugin", "flag", "--out", "diag"),
        ("infer", "--plugin", "flag"),
        ("posterior", "train", "--plugin", "flag", "--data", "d", "--out", "w.safetensors"),
        ("dataset", "generate", "--plugin", "flag", "--out", "d"),
        ("train", "--plugin", "flag", "--data", "d", "--out", "m"),  # a plugin's command
    ],
    ids=lambda c: " ".join(c[:2]),
)
def test_a_seed_outside_0_to_2_32_is_one_line_for_every_command(physinfer_cli, tmp_path, command, seed):
    ran = physinfer_cli(*command, "--seed", seed, "--json", cwd=tmp_path)
    error = one_error(ran)
    assert error == f"--seed {seed}: give a whole number from 0 to 4294967295"
    assert not list(tmp_path.iterdir())


def test_the_library_checks_seeds_as_the_cli_does():
    for seed in (-1, 2**32, 1.5, True):
        with pytest.raises(UserInputError, match="give a whole number from 0 to 4294967295"):
            pi.simulate("flag", seed=seed, out="x.mp4")
