"""``physinfer refine --plugin flag`` end to end through the CLI (short budgets)."""

import json

import numpy as np
import pytest

from physinfer.rundir import RunDirectory
from physinfer.types import Clip
from physinfer.video import center_crop_resize, read_video, resample, write_video

FAST = ["--optimizer", "random", "--noise-samples", "2", "--floor-samples", "2", "--json"]


@pytest.fixture
def cli(physinfer_cli):
    """Run a command in this process; it must succeed; its JSON."""

    def run(*args):
        proc = physinfer_cli(*args)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return proc.json()

    return run


def test_flag_refine_writes_outputs_and_resumes(tmp_path, cli):
    out = tmp_path / "run"
    data = cli("refine", "--plugin", "flag", "--steps", "2", "--out", str(out), *FAST)
    assert data["n_trials"] == 2 and len(data["best_params"]) == 17
    assert {"wind_speed", "area_weight"} <= set(data["abs_errors"]), "the embedded target knows its truth"
    floor = data["noise_floor"]
    assert floor["n"] == 2 and floor["floor"] >= 0 and floor["gap"] > 0
    for name in ("refinement.png", "side_by_side.mp4", "best_trajectory.npz", "target.mp4", "noise_prior.json"):
        assert (out / name).stat().st_size > 0, name
    trials = RunDirectory(out).read_trials()
    # the shipped posterior estimator: its intervals reported, the search started at its median
    assert data["posterior_source"]["kind"] == "amortized"
    assert data["posterior"]["wind_speed"]["label"] == "identified"
    assert data["posterior"]["bend_0deg_c00"]["label"] == "not identified"
    medians = {name: m["median"] for name, m in data["posterior"].items()}
    assert trials[0].params == pytest.approx(medians, rel=1e-6), "the first trial is the posterior median"

    resumed = cli("refine", "--plugin", "flag", "--steps", "3", "--out", str(out), "--resume", *FAST)
    assert resumed["n_trials"] == 3
    assert [t.x for t in RunDirectory(out).read_trials()[:2]] == [t.x for t in trials]

    plain = cli("refine", "--plugin", "flag", "--steps", "1", "--no-posterior", "--out", str(tmp_path / "plain"),
                "--optimizer", "random", "--noise-samples", "0", "--floor-samples", "0", "--json")
    assert "posterior" not in plain
    assert RunDirectory(tmp_path / "plain").read_trials()[0].x == [0.0] * 17, "without it, the centre"


def test_colour_640x360_30fps_target_with_truth(tmp_path, cli):
    """A user's video: colour, 16:9, 30 fps; --truth gives abs_errors for those names only."""
    from physinfer_flag.phenomenon import default_target

    clip = resample(default_target().clip, 30.0)
    square = center_crop_resize(clip.frames, 360)
    if square.shape[-1] == 1:
        square = np.repeat(square, 3, axis=-1)
    square[..., 0] = np.clip(square[..., 0].astype(int) + 30, 0, 255)  # not gray
    canvas = np.zeros((square.shape[0], 360, 640, 3), dtype=np.uint8)
    canvas[:, :, 140:500] = square
    video = write_video(tmp_path / "my_flag.mp4", Clip(frames=canvas, fps=30.0))
    assert read_video(video).frames.shape[1:] == (360, 640, 3)

    data = cli("refine", "--plugin", "flag", "--target", str(video), "--truth", "wind_speed=6.5",
               "--steps", "2", "--out", str(tmp_path / "run"), *FAST)
    assert set(data["abs_errors"]) == {"wind_speed"}
    assert data["ground_truth"] == {"wind_speed": 6.5}


# Slow (33 s in make test): the batch solver and embed_many each equal their single runs in
# test_cloth.py, test_cloth_reproducible.py and test_sdn_frontend.py, which stay in the default run.
@pytest.mark.slow
def test_a_batch_of_flags_gives_the_distances_of_single_trials(tmp_path):
    """q = 2 goes through the numba batch solver and embed_many; the distances are the sequential ones."""
    from physinfer.plugins import load_registry
    from physinfer.session import refine

    registry, _ = load_registry()
    quick = dict(plugin="flag", steps=3, optimizer="random", progress=False, noise_samples=0, floor_samples=0)
    single = refine(registry, out=tmp_path / "q1", **quick)
    batched = refine(registry, out=tmp_path / "q2", batch_size=2, **quick)
    assert [t.x for t in batched.trials] == [t.x for t in single.trials]
    assert [t.distance for t in batched.trials] == pytest.approx([t.distance for t in single.trials], rel=1e-4)


@pytest.mark.slow
def test_flag_trials_on_worker_processes_match_the_in_process_batch(tmp_path, cli):
    """Numba simulation and EGL rendering in spawned workers give this process's distances."""
    quick = ["--steps", "4", "--batch-size", "2", "--optimizer", "random", "--noise-samples", "0",
             "--floor-samples", "0", "--json"]
    cli("refine", "--plugin", "flag", "--out", str(tmp_path / "here"), *quick)
    data = cli("refine", "--plugin", "flag", "--out", str(tmp_path / "workers"), "--workers", "2", *quick)
    assert data["executor"]["kind"] == "processes"
    here, there = (RunDirectory(tmp_path / name).read_trials() for name in ("here", "workers"))
    assert [t.distance for t in there] == pytest.approx([t.distance for t in here], rel=1e-9)


def test_longer_clips_for_the_spectral_embedder(tmp_path, cli, physinfer_cli):
    """``--duration`` records longer clips, ``--embedder-frames`` has the spectral embedder read them all."""
    target = tmp_path / "long.mp4"
    made = cli("simulate", "--plugin", "flag", "--set", "wind_speed=4", "--duration", "4", "--seed", "5",
               "--out", str(target), "--json")
    assert read_video(target).frames.shape[0] == 100 and made["params"]["wind_speed"] == 4
    out = tmp_path / "run"
    common = ["refine", "--plugin", "flag", "--target", str(target), "--duration", "4", "--embedder", "spectral",
              "--noise-samples", "0", "--floor-samples", "0", "--optimizer", "random", "--out", str(out)]
    data = cli(*common, "--steps", "2", "--embedder-frames", "100", "--json")
    assert data["n_trials"] == 2 and data["n_failed"] == 0
    run = json.loads((out / "run.json").read_text())
    assert run["duration_s"] == 4 and run["embedder_frames"] == 100
    other = physinfer_cli(*common, "--steps", "3", "--embedder-frames", "60", "--resume")
    assert other.returncode != 0 and "embedder-frames: run 100, now 60" in " ".join(other.stderr.split())


def test_embedder_frames_need_a_parameter_free_embedder(tmp_path, physinfer_cli):
    proc = physinfer_cli("refine", "--plugin", "flag", "--embedder-frames", "100", "--steps", "2",
                         "--out", str(tmp_path / "r"))
    assert proc.returncode != 0 and "an SDN's are set by its weights" in " ".join(proc.stderr.split())
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
def test_diagnose_compares_every_model_on_the_longer_clips(tmp_path, cli):
    """``diagnose --duration`` reaches every stage: the augmented model records as long as the baseline.

    The spectral embedder reads 80 frames, so a stage simulating the default 2.4 s (60 frames)
    would fail every trial; the effect stage's trials must all succeed.
    """
    target = tmp_path / "long.mp4"
    cli("simulate", "--plugin", "flag", "--set", "wind_speed=5", "--duration", "3.2", "--seed", "2",
        "--out", str(target), "--json")
    out = tmp_path / "diag"
    report = cli("diagnose", "--plugin", "flag", "--target", str(target), "--duration", "3.2", "--embedder",
                 "spectral", "--embedder-frames", "80", "--effect", "wind_yaw", "--steps", "2", "--optimizer",
                 "random", "--calibration-runs", "1", "--no-calibration-control", "--floor-samples", "4",
                 "--no-video", "--out", str(out), "--json")
    assert report["settings"]["duration_s"] == 3.2 and report["settings"]["embedder_frames"] == 80
    (candidate,) = report["candidates"]
    assert np.isfinite(candidate["gap"])
    for stage in ("baseline", "calibration-0", "control", "effect-wind_yaw"):
        run = json.loads((out / stage / "run.json").read_text())
        assert run["duration_s"] == 3.2 and run["embedder_frames"] == 80, stage
        assert all(t.status == "ok" for t in RunDirectory(out / stage).read_trials()), stage
    model = json.loads((out / "model.json").read_text())
    assert model["duration_s"] == 3.2 and model["embedder_frames"] == 80
    # refine --model simulates the diagnosis's clip length unless told otherwise.
    again = tmp_path / "again"
    data = cli("refine", "--plugin", "flag", "--model", str(out / "model.json"), "--target", str(target),
               "--embedder", "spectral", "--embedder-frames", "80", "--steps", "1", "--noise-samples", "0",
               "--floor-samples", "0", "--optimizer", "random", "--out", str(again), "--json")
    assert data["n_failed"] == 0 and json.loads((again / "run.json").read_text())["duration_s"] == 3.2
