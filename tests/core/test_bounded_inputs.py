"""Bounded inputs (issue 45, item 3): a count, size or file that would take the machine's
memory is refused in one line before any planning, loading or simulating."""

from __future__ import annotations

import io
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.meshio import load_trajectory
from physinfer.types import Trajectory


def _refused(ran, *words: str) -> str:
    assert ran.returncode == 2, ran.stderr[-1500:]
    error = ran.json()["error"]
    for word in words:
        assert word in error, error
    return error


@pytest.mark.parametrize(
    ("option", "value", "words"),
    [
        ("--sims", "99999999999999", ("--sims", "at most")),
        ("--sims", "10,10,99999999999999", ("--sims", "at most")),
        ("--renders-per-sim", "99999999999", ("--renders-per-sim", "at most")),
        ("--size", "100000", ("--size", "at most")),
        ("--frames", "100000000", ("--frames", "at most")),
        ("--frames", "0", ("--frames",)),
    ],
)
def test_dataset_generate_refuses_counts_and_sizes_no_machine_holds(option, value, words, tmp_path, physinfer_cli):
    started = time.perf_counter()
    out = tmp_path / "set"
    ran = physinfer_cli("dataset", "generate", "--plugin", "pendulum_lab", option, value, "--out", out, "--json")
    _refused(ran, *words)
    assert time.perf_counter() - started < 20 and not out.exists()


def test_infer_refuses_a_sample_count_no_machine_holds(tmp_path, physinfer_cli):
    out = tmp_path / "infer"
    ran = physinfer_cli("infer", "--plugin", "pendulum_lab", "--samples", "2000000000", "--out", out, "--json")
    _refused(ran, "--samples 2000000000", "at most")
    assert not out.exists()
    ran = physinfer_cli("infer", "--plugin", "pendulum_lab", "--samples", "2e9", "--json")
    _refused(ran, "--samples")  # not an integer: the parse error, as one JSON object
    ran = physinfer_cli("evaluate", "calibration", "--plugin", "pendulum_lab", "--data", tmp_path,
                        "--samples", "2000000000", "--out", tmp_path / "cal", "--json")  # fmt: skip
    _refused(ran, "--samples 2000000000", "at most")


@pytest.mark.parametrize("frames", ["0", "-3", "100000000"])
def test_embedder_frames_outside_its_range_is_one_line(frames, tmp_path, physinfer_cli):
    for command in (
        ("refine", "--plugin", "pendulum_lab", "--steps", "1", "--out", tmp_path / "run"),
        ("diagnose", "--plugin", "pendulum_lab", "--out", tmp_path / "diagnosis"),
        ("posterior", "train", "--plugin", "pendulum_lab", "--data", tmp_path, "--out", tmp_path / "q.safetensors"),
    ):  # fmt: skip
        ran = physinfer_cli(*command, "--embedder-frames", frames, "--json")
        _refused(ran, f"--embedder-frames {frames}")
    assert not (tmp_path / "run").exists() and not (tmp_path / "diagnosis").exists()


# ------------------------------------------------------------------------ trajectory files


def _npz_declaring(path: Path, shape: tuple[int, ...], dtype: str = "<f4", payload: int = 64) -> Path:
    """An NPZ whose ``vertices.npy`` header declares ``shape`` but holds ``payload`` bytes."""
    header = io.BytesIO()
    np.lib.format.write_array_header_2_0(
        header, {"descr": dtype, "fortran_order": False, "shape": shape}
    )
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("vertices.npy", header.getvalue() + b"\0" * payload)
        for name, array in (("faces", np.array([[0, 1, 2]], np.int32)), ("fps", np.array(25.0))):
            buffer = io.BytesIO()
            np.save(buffer, array)
            zf.writestr(f"{name}.npy", buffer.getvalue())
    return path


def test_a_trajectory_declaring_a_huge_array_is_refused_from_its_header(tmp_path):
    path = _npz_declaring(tmp_path / "huge.npz", (2000, 100_000, 3))  # 2.4 GB declared
    assert path.stat().st_size < 10_000
    with pytest.raises(UserInputError, match=r"declares .*vertices.* 2\.4 GB.*at most"):
        load_trajectory(path)


def test_a_trajectory_whose_member_inflates_beyond_the_limit_is_refused(tmp_path, monkeypatch):
    import physinfer.meshio as meshio

    path = tmp_path / "zeros.npz"
    Trajectory(np.zeros((50, 1000, 3), np.float32), np.array([[0, 1, 2]], np.int32), 25.0).save(path)
    monkeypatch.setattr(meshio, "MAX_TRAJECTORY_BYTES", 100_000)
    with pytest.raises(UserInputError, match="at most"):
        load_trajectory(path)


def test_faces_must_be_integers_and_coordinates_sane(tmp_path):
    vertices = np.zeros((2, 3, 3), np.float32)
    vertices[:, 1, 0] = 1.0
    path = tmp_path / "float_faces.npz"
    np.savez(path, vertices=vertices, faces=np.array([[0.0, 1.5, 2.0]]), fps=np.array(25.0))
    with pytest.raises(UserInputError, match="faces must be integers"):
        load_trajectory(path)
    far = vertices.copy()
    far[1, 2, 2] = 3e7
    Trajectory(far, np.array([[0, 1, 2]], np.int32), 25.0).save(tmp_path / "far.npz")
    with pytest.raises(UserInputError, match=r"frame 1 .*1e\+06 m"):
        load_trajectory(tmp_path / "far.npz")
