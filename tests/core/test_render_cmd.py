"""``physinfer render --trajectory`` and the trajectory readers of :mod:`physinfer.meshio`."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.meshio import load_trajectory, read_obj, write_obj_sequence
from physinfer.types import Trajectory
from physinfer.video import read_video

BIN = Path(sys.executable).parent / "physinfer"
SMALL = ["--render-set", "image_size=64"]


def run_cli(*args, cwd=None):
    return subprocess.run([str(BIN), *args], capture_output=True, text=True, timeout=300, cwd=cwd)


def json_out(proc):
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected one JSON line, got {proc.stdout!r} / {proc.stderr}"
    return json.loads(lines[0])


@pytest.fixture(scope="module")
def flag_run(tmp_path_factory):
    """A short flag simulation, as ``simulate`` writes it: its video and its trajectory NPZ."""
    folder = tmp_path_factory.mktemp("flag")
    proc = run_cli(
        "simulate",
        "--plugin",
        "flag",
        "--duration",
        "0.2",
        "--seed",
        "3",
        "--set",
        "wind_speed=7",
        *SMALL,
        "--out",
        str(folder / "sim.mp4"),
        "--trajectory-out",
        str(folder / "t.npz"),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    return folder


def test_render_of_a_simulated_trajectory_gives_simulates_pixels(flag_run, tmp_path):
    out = tmp_path / "again.mp4"
    proc = run_cli(
        "render",
        "--plugin",
        "flag",
        "--trajectory",
        str(flag_run / "t.npz"),
        *SMALL,
        "--out",
        str(out),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    data = json_out(proc)
    assert (
        data["source"] == "npz"
        and data["n_frames"] == 5
        and data["render_params"]["image_size"] == 64
    )
    simulated, rendered = read_video(flag_run / "sim.mp4").frames, read_video(out).frames
    assert simulated.shape == rendered.shape == (5, 64, 64, 3)
    # Same trajectory, same ζ, same encoder: the decoded frames agree exactly.
    assert np.array_equal(simulated, rendered)


def test_an_obj_sequence_renders_like_the_trajectory_it_came_from(flag_run, tmp_path):
    from physinfer_flag.render import FlagRenderer

    trajectory = Trajectory.load(flag_run / "t.npz")
    write_obj_sequence(trajectory, tmp_path / "objs")
    loaded = load_trajectory(tmp_path / "objs", fps=25)
    assert np.array_equal(loaded.vertices, trajectory.vertices) and np.array_equal(
        loaded.faces, trajectory.faces
    )
    assert np.array_equal(loaded.extras["uv"], trajectory.extras["uv"])
    # OBJ carries no pole: compare with the trajectory without it (the renderer derives one).
    without_pole = Trajectory(
        trajectory.vertices, trajectory.faces, 25.0, {"uv": trajectory.extras["uv"]}
    )
    renderer = FlagRenderer()
    try:
        zeta = {"image_size": 64}
        assert np.array_equal(
            renderer.render(loaded, zeta).frames, renderer.render(without_pole, zeta).frames
        )
    finally:
        renderer.close()
    proc = run_cli(
        "render",
        "--plugin",
        "flag",
        "--trajectory",
        str(tmp_path / "objs"),
        "--fps",
        "25",
        *SMALL,
        "--out",
        str(tmp_path / "objs.mp4"),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    assert json_out(proc)["source"] == "obj" and read_video(tmp_path / "objs.mp4").n_frames == 5


def test_the_pendulum_renders_a_trajectory_file_too(tmp_path):
    from pendulum_example.physics import make_simulator

    trajectory = make_simulator().simulate({"length": 0.8, "damping": 0.1, "amplitude": 30.0})
    Trajectory(trajectory.vertices[:6], trajectory.faces, trajectory.fps, trajectory.extras).save(
        tmp_path / "p.npz"
    )
    proc = run_cli(
        "render",
        "--plugin",
        "pendulum_lab",
        "--trajectory",
        str(tmp_path / "p.npz"),
        "--render-set",
        "size=48",
        "--out",
        str(tmp_path / "p.mp4"),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    assert read_video(tmp_path / "p.mp4").frames.shape == (6, 48, 48, 3)


QUAD = "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nvt 0 0\nvt 2 0\nvt 2 4\nvt 0 4\nf 1/1 2/2 3/3 4/4\n"


def test_obj_quads_are_triangulated_and_uv_normalised(tmp_path):
    path = tmp_path / "q.obj"
    path.write_text(QUAD)
    mesh = read_obj(path)
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert mesh.uv.tolist() == [[0, 0], [1, 0], [1, 1], [0, 1]]
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 0 1\nf -3 -2 -1\n")  # relative indices, no vt
    mesh = read_obj(path)
    assert mesh.faces.tolist() == [[0, 1, 2]] and mesh.uv is None


def test_arcsim_names_order_by_the_frame_number(tmp_path):
    # ArcSim writes FRAME_CLOTH.obj; name order is not frame order past 9.
    for frame in (10, 9, 8):
        (tmp_path / f"{frame:d}_00.obj").write_text(QUAD.replace("v 1 0 1", f"v 1 0 {frame}"))
    loaded = load_trajectory(tmp_path, fps=25)
    assert loaded.vertices[:, 2, 2].tolist() == [8, 9, 10]


def _sequence(folder, texts):
    folder.mkdir()
    for name, text in texts.items():
        (folder / name).write_text(text)
    return folder


def _object_npz(path):
    np.savez(
        path,
        vertices=np.zeros((2, 3, 3), np.float32),
        faces=np.array([[0, 1, 2]]),
        fps=np.array(25.0),
        extra_meta=np.array([{"a": 1}], dtype=object),
    )
    return path


def _nan_npz(path):
    vertices = np.zeros((3, 3, 3), np.float32)
    vertices[2, 1, 0] = np.nan
    Trajectory(vertices, np.array([[0, 1, 2]], np.int32), 25.0).save(path)
    return path


BAD = {
    "varying vertex counts": (
        lambda d: _sequence(d, {"f_0.obj": QUAD, "f_1.obj": QUAD + "v 5 5 5\n"}),
        "f_1.obj has 5 vertices but f_0.obj has 4",
    ),
    "missing frame": (
        lambda d: _sequence(d, {"f_0.obj": QUAD, "f_1.obj": QUAD, "f_3.obj": QUAD}),
        "frames 2..2 are missing between f_1.obj and f_3.obj",
    ),
    "no obj files": (lambda d: _sequence(d, {"notes.txt": "x"}), "the folder holds no .obj files"),
    "face out of range": (
        lambda d: _sequence(d, {"f_0.obj": QUAD + "f 1 2 7\n"}),
        "face 2 indexes vertex 7 (1-based) but the file has 4",
    ),
    "non-finite obj vertex": (
        lambda d: _sequence(d, {"f_0.obj": QUAD, "f_1.obj": QUAD.replace("v 1 0 0", "v nan 0 0")}),
        "f_1.obj: a vertex coordinate is NaN or infinite",
    ),
    "object arrays": (lambda d: _object_npz(d.with_suffix(".npz")), "holds object arrays"),
    "a video given as the trajectory": (
        lambda d: _write(d.with_suffix(".mp4"), b"\x00\x00\x00\x18ftypmp42"),
        "is not an NPZ file: a trajectory is the NPZ",
    ),
    "non-finite npz vertex": (
        lambda d: _nan_npz(d.with_suffix(".npz")),
        "frame 2 has a NaN or infinite vertex",
    ),
}


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_trajectories_are_refused_with_one_line(tmp_path, case):
    make, message = BAD[case]
    path = make(tmp_path / "in")
    with pytest.raises(UserInputError) as info:
        load_trajectory(path, fps=25)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_frame_rate_that_is_not_positive_is_refused(flag_run):
    for fps in (0, -1.0, float("nan"), float("inf")):
        with pytest.raises(UserInputError, match="is not a frame rate; give a positive number"):
            load_trajectory(flag_run / "t.npz", fps=fps)
    proc = run_cli(
        "render",
        "--plugin",
        "flag",
        "--trajectory",
        str(flag_run / "t.npz"),
        "--fps",
        "nan",
        "--out",
        "x.mp4",
        "--json",
    )
    error = json_out(proc)["error"]  # refused by the options' type check before the renderer's
    assert proc.returncode == 2 and error.startswith("--fps nan") and "finite number" in error


def test_cli_refusals_exit_2_before_rendering(tmp_path):
    _object_npz(tmp_path / "o.npz")
    proc = run_cli(
        "render",
        "--plugin",
        "flag",
        "--trajectory",
        str(tmp_path / "o.npz"),
        "--out",
        str(tmp_path / "o.mp4"),
        "--json",
    )
    assert proc.returncode == 2 and "holds object arrays" in json_out(proc)["error"]
    _sequence(tmp_path / "objs", {"f_0.obj": QUAD})
    proc = run_cli(
        "render",
        "--plugin",
        "flag",
        "--trajectory",
        str(tmp_path / "objs"),
        "--out",
        str(tmp_path / "o.mp4"),
    )
    assert (
        proc.returncode == 2
        and "pass it with --fps" in proc.stderr
        and "Traceback" not in proc.stderr
    )
    assert not (tmp_path / "o.mp4").exists()


def test_the_api_renders_a_trajectory_file_and_returns_the_clip(tmp_path):
    from pendulum_example.physics import make_simulator

    import physinfer

    trajectory = make_simulator().simulate({"length": 0.8, "damping": 0.1, "amplitude": 30.0})
    Trajectory(trajectory.vertices[:4], trajectory.faces, trajectory.fps, trajectory.extras).save(
        tmp_path / "p.npz"
    )
    rendering = physinfer.render("pendulum_lab", trajectory=tmp_path / "p.npz", render_set={"size": 32})
    assert rendering.clip.frames.shape == (4, 32, 32, 3) and rendering.paths == {}
    assert rendering.to_dict()["n_frames"] == 4 and rendering.to_dict()["source"] == "npz"
    assert len(rendering.plot(n=2).axes) == 2
