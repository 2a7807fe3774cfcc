"""Fault injection (issue 25, item 7): ``kill -9`` at seeded random moments, then resume.

Each command is started as the real console script, sent SIGKILL at a moment drawn from a
seeded generator (after some completed units of work, plus a random delay, so a kill lands
anywhere: during start-up, inside a trial, between two appends), and continued; the
finished run must equal an uninterrupted run of the same seed — the same trial log (θ,
coordinates, distances; no trial twice, none missing), the same dataset files, the same
final weights. The default run kills refine, diagnose, dataset generate and train once each
on their cheapest settings; the ``slow`` test kills every command at least ten times,
resuming in between.

``dataset generate`` also runs worker processes: they must die with their killed parent.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from physinfer import ParameterSpace, ParameterSpec, Trajectory
from physinfer.datasets import (
    ClipFormat,
    DatasetGenerator,
    DatasetPreset,
    SplitCounts,
    generate_dataset,
)
from physinfer.rundir import RunDirectory
from physinfer.types import Clip

BIN = Path(sys.executable).parent / "physinfer"
#: Timing keys (seconds, throughput) that differ between any two runs.
TIMING_KEYS = {
    "timings",
    "seconds",
    "wall_time_s",
    "renders_per_minute",
    "worker_seconds",
    "selection_s",
    "stages_s",
}


# ------------------------------------------------------------------------------ harness


@dataclass
class Command:
    """A command to kill and resume.

    Attributes:
        args: ``physinfer`` arguments; ``{out}`` stands for the output directory.
        progress: Units of work completed in an output directory (trials, units, epochs).
        resume: Extra arguments that continue a run (refine's ``--resume``).
        same: Asserts two finished output directories are the same run.
    """

    args: list[str]
    progress: Callable[[Path], int]
    same: Callable[[Path, Path], None]
    resume: list[str] = field(default_factory=list)

    def argv(self, out: Path, *, resume: bool) -> list[str]:
        args = [a.replace("{out}", str(out)) for a in self.args]
        return [*args, *(self.resume if resume else [])]


def lines(path: Path) -> int:
    """Complete lines of a file (0 if missing)."""
    try:
        return path.read_bytes().count(b"\n")
    except OSError:
        return 0


def descendants(pid: int) -> list[int]:
    """PIDs of the processes started (directly or not) by ``pid`` (read from /proc)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            parents[int(entry.name)] = int(stat.rsplit(")", 1)[1].split()[1])
    found, frontier = [], [pid]
    while frontier:
        children = [child for child, parent in parents.items() if parent in frontier]
        found += children
        frontier = children
    return found


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def kill_at_random_moment(
    command: Command, out: Path, rng: np.random.Generator, *, resume: bool
) -> bool:
    """Start the command, SIGKILL it at a seeded moment; ``False`` if it finished first.

    The moment: once ``progress`` has grown by 0 or 1 unit, plus 0-0.6 s. Every process the
    command started must be gone within a few seconds of the kill (workers die with it).
    """
    wanted = command.progress(out) + int(rng.integers(0, 2))
    delay = float(rng.uniform(0.0, 0.6))
    proc = subprocess.Popen(
        [str(BIN), *command.argv(out, resume=resume)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )  # fmt: skip
    deadline = time.monotonic() + 300
    while proc.poll() is None and command.progress(out) < wanted and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(delay)
    children = descendants(proc.pid)
    if proc.poll() is not None:
        assert proc.returncode == 0, f"the command failed on its own (exit {proc.returncode})"
        return False
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    try:
        _wait_gone(children, seconds=10.0)
    finally:  # never leave strays behind, whatever the verdict
        for pid in children:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
    return True


def _wait_gone(pids: list[int], seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while any(alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = [pid for pid in pids if alive(pid)]
    assert not left, f"processes {left} outlived their killed parent"


def finish(cli, command: Command, out: Path, *, resume: bool) -> None:
    ran = cli(*command.argv(out, resume=resume), "--json")
    assert ran.returncode == 0, ran.stderr[-3000:]


def kill_and_resume(cli, command: Command, tmp_path: Path, *, kills: int, seed: int) -> int:
    """Kill the command ``kills`` times (resuming in between), finish it, compare it with an
    uninterrupted run; return how many kills landed before it finished."""
    rng = np.random.default_rng(seed)
    out, reference = tmp_path / "killed", tmp_path / "uninterrupted"
    landed = 0
    for k in range(kills):
        if not kill_at_random_moment(
            command, out, rng, resume=k > 0 and (out / "run.json").exists()
        ):
            break
        landed += 1
    finish(cli, command, out, resume=bool(command.resume) and (out / "run.json").exists())
    finish(cli, command, reference, resume=False)
    command.same(reference, out)
    return landed


# ------------------------------------------------------------------------- comparisons


def without_timings(obj):
    """``obj`` with every timing entry dropped, recursively."""
    if isinstance(obj, dict):
        return {k: without_timings(v) for k, v in obj.items() if k not in TIMING_KEYS}
    if isinstance(obj, list):
        return [without_timings(v) for v in obj]
    return obj


def trial_log(run: Path) -> list[tuple]:
    """Each logged trial's step, index, coordinates, θ, distance and status."""
    return [
        (t.step, t.index, t.x, t.params, t.distance, t.status, t.error)
        for t in RunDirectory(run).read_trials()
    ]


def same_refinement(a: Path, b: Path) -> None:
    log_a, log_b = trial_log(a), trial_log(b)
    assert [t[0] for t in log_b] == list(range(len(log_b))), "a trial twice or one missing"
    assert log_a == log_b
    result_a, result_b = (json.loads((run / "result.json").read_text()) for run in (a, b))
    for key in ("best_params", "best_distance", "best_step", "n_trials"):
        assert result_a[key] == result_b[key], key


def same_diagnosis(a: Path, b: Path) -> None:
    stages = sorted(p.parent.name for p in a.glob("*/trials.jsonl"))
    assert stages == sorted(p.parent.name for p in b.glob("*/trials.jsonl"))
    for stage in stages:
        assert trial_log(a / stage) == trial_log(b / stage), stage
    diag_a, diag_b = (
        without_timings(json.loads((d / "diagnosis.json").read_text())) for d in (a, b)
    )
    diag_a.get("settings", {}).pop("out", None), diag_b.get("settings", {}).pop("out", None)
    assert json.dumps(diag_a, sort_keys=True) == json.dumps(diag_b, sort_keys=True).replace(
        str(b), str(a)
    )


def same_dataset(a: Path, b: Path) -> None:
    from physinfer.datasets.storage import file_digest, npz_digest

    assert (a / "manifest.jsonl").read_bytes() == (b / "manifest.jsonl").read_bytes()
    for folder, digest in (("shards", file_digest), ("trajectories", npz_digest)):
        names = sorted(p.name for p in (a / folder).iterdir())
        assert names == sorted(p.name for p in (b / folder).iterdir()), folder
        assert [digest(a / folder / n) for n in names] == [digest(b / folder / n) for n in names], (
            folder
        )


def same_weights(a: Path, b: Path) -> None:
    from safetensors.numpy import load_file

    history_a, history_b = (
        without_timings(json.loads((r / "history.json").read_text())) for r in (a, b)
    )
    assert history_a == history_b
    weights_a, weights_b = load_file(a / "sdn.safetensors"), load_file(b / "sdn.safetensors")
    assert sorted(weights_a) == sorted(weights_b)
    for name in weights_a:
        assert np.array_equal(weights_a[name], weights_b[name]), name


# ---------------------------------------------------------------------------- commands


def refine_command(steps: int, noise_samples: int = 0) -> Command:
    return Command(
        ["refine", "--plugin", "pendulum_lab", "--steps", str(steps), "--optimizer", "cma", "--seed", "5",
         "--noise-samples", str(noise_samples), "--floor-samples", "0", "--render-set", "size=32", "--out", "{out}"],
        progress=lambda out: lines(out / "trials.jsonl"),
        same=same_refinement,
        resume=["--resume"],
    )  # fmt: skip


def diagnose_command(steps: int, limits: bool = True) -> Command:
    return Command(
        ["diagnose", "--plugin", "pendulum_lab", "--steps", str(steps), "--effect-steps", "2", "--optimizer", "random",
         "--no-calibrate", "--render-set", "size=48", "--no-video", *([] if limits else ["--no-limits"]),
         "--out", "{out}"],
        progress=lambda out: sum(lines(p) for p in out.glob("*/trials.jsonl")),
        same=same_diagnosis,
    )  # fmt: skip


def dataset_command(sims: str, workers: int) -> Command:
    return Command(
        ["dataset", "generate", "--plugin", "pendulum_lab", "--sims", sims, "--renders-per-sim", "1", "--frames", "10",
         "--size", "32", "--sims-per-unit", "1", "--workers", str(workers), "--seed", "7", "--out", "{out}"],
        progress=lambda out: len(list((out / "units").glob("*.json"))) if (out / "units").is_dir() else 0,
        same=same_dataset,
    )  # fmt: skip


def train_command(data: Path, epochs: int) -> Command:
    def epochs_done(out: Path) -> int:
        try:
            return len(json.loads((out / "history.json").read_text())["history"])
        except (OSError, ValueError, KeyError):
            return 0

    return Command(
        ["train", "--plugin", "flag", "--data", str(data), "--epochs", str(epochs), "--batch-size", "12",
         "--frames", "16", "--size", "32", "--threads", "1", "--no-progress", "--out", "{out}"],
        progress=epochs_done,
        same=same_weights,
    )  # fmt: skip


class Stripes(DatasetGenerator):
    """A tiny dataset for the SDN: stripes whose temporal frequency is ``wind_speed``."""

    phenomenon = "stripes"
    parameter_space = ParameterSpace(
        [ParameterSpec("wind_speed", (1.0, 8.0), "Hz"), ParameterSpec("tilt", (0.0, 1.0), "")]
    )

    def simulate_batch(self, params, seeds, *, clip):
        faces = np.array([[0, 1, 2]], dtype=np.int32)
        theta = [np.array([p["wind_speed"], p["tilt"]]) for p in params]
        return [
            Trajectory(np.zeros((clip.n_frames, 3, 3), np.float32), faces, clip.fps, {"theta": t})
            for t in theta
        ]

    def sample_render_params(self, rng):
        return {"phase": float(rng.uniform(0, 2 * np.pi))}

    def render(self, trajectory, render_params, *, clip):
        freq, tilt = trajectory.extras["theta"]
        t = np.arange(clip.n_frames)[:, None, None] / clip.fps
        y, x = np.mgrid[0 : clip.height, 0 : clip.width]
        frames = 0.5 + 0.4 * np.sin(
            2 * np.pi * ((x + tilt * y) / 10.0 - freq * t) + render_params["phase"]
        )
        return Clip((np.clip(frames, 0, 1) * 255).astype(np.uint8)[..., None], clip.fps)


@pytest.fixture(scope="module")
def stripes(tmp_path_factory):
    root = tmp_path_factory.mktemp("stripes") / "data"
    preset = DatasetPreset(
        name="tiny",
        sims=SplitCounts(8, 4, 4),
        renders=SplitCounts(24, 12, 12),
        clip=ClipFormat(n_frames=20, fps=25.0, height=32, width=32, channels=1),
    )
    generate_dataset(Stripes(), root, preset=preset, seed=3, workers=0)
    return root


# ------------------------------------------------------------------------------- tests


def test_refine_killed_once_resumes_to_the_uninterrupted_run(physinfer_cli, tmp_path):
    kill_and_resume(physinfer_cli, refine_command(steps=4), tmp_path, kills=1, seed=0)


# Slow (65-90 s on 2 cores): the default run keeps refine's kill test above and diagnose's resume
# (test_diagnose.py); the ten seeded kills below kill diagnose too.
@pytest.mark.slow
def test_diagnose_killed_once_resumes_to_the_uninterrupted_run(physinfer_cli, tmp_path):
    # Without the detection limits (half the time); the ten-kill test below kills them too.
    kill_and_resume(physinfer_cli, diagnose_command(steps=3, limits=False), tmp_path, kills=1, seed=0)


def test_dataset_generate_killed_once_resumes_and_its_workers_die_with_it(physinfer_cli, tmp_path):
    kill_and_resume(physinfer_cli, dataset_command("2,1,1", workers=1), tmp_path, kills=1, seed=0)


def test_train_killed_once_resumes_to_the_same_weights(physinfer_cli, stripes, tmp_path):
    kill_and_resume(physinfer_cli, train_command(stripes, epochs=2), tmp_path, kills=1, seed=0)


def test_train_killed_after_its_last_checkpoint_leaves_the_full_history(physinfer_cli, stripes, tmp_path):
    """The window a seeded kill once hit: the checkpoint holds every epoch, history.json the
    one before; the resumed run trains nothing and must still write the full history."""
    command = train_command(stripes, epochs=2)
    out = tmp_path / "killed"
    finish(physinfer_cli, command, out, resume=False)
    full = json.loads((out / "history.json").read_text())
    (out / "history.json").write_text(json.dumps({"history": full["history"][:1], "best": full["history"][0]}))
    finish(physinfer_cli, command, out, resume=True)
    assert without_timings(json.loads((out / "history.json").read_text())) == without_timings(full)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1])
@pytest.mark.parametrize("name", ["refine", "diagnose", "dataset", "train"])
def test_ten_seeded_kills_per_command_resume_to_the_uninterrupted_run(
    physinfer_cli, stripes, tmp_path, name, seed
):
    command = {
        "refine": lambda: refine_command(steps=30, noise_samples=2),
        "diagnose": lambda: diagnose_command(steps=12),
        "dataset": lambda: dataset_command("16,4,4", workers=2),
        "train": lambda: train_command(stripes, epochs=14),
    }[name]()
    landed = kill_and_resume(physinfer_cli, command, tmp_path, kills=12, seed=seed)
    assert landed >= 10, f"only {landed} kills landed before the run finished"
