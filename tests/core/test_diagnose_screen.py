"""Tests of physinfer.discrepancy.screen: candidates no fit could name are left out before
they are refined, and the decisions about the others keep their levels.

The rule on synthetic embeddings, then a real diagnosis of a jittery pendulum (the bob shaken
by seeded noise, so the noise floor is not zero) with the real quadratic drag and an inert
effect that changes nothing.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from physinfer.discrepancy.decide import DecisionRule, final_verdict, misspecification
from physinfer.discrepancy.limit_rule import Threshold
from physinfer.discrepancy.screen import judge_rungs
from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.roles import Effect


def _cloud(rng, centre: float, spread: float, n: int = 6, dim: int = 8) -> np.ndarray:
    return centre + spread * rng.normal(size=(n, dim))


def test_a_rung_screens_only_when_its_shift_clears_no_threshold():
    rng = np.random.default_rng(0)
    base = _cloud(rng, 0.0, 1.0, n=8)
    floor = float(np.median([np.sum((a - b) ** 2) for i, a in enumerate(base) for b in base[i + 1 :]]))
    threshold = Threshold.of(floor, 1, DecisionRule(), n_candidates=2, n_seeds=8)
    # Clips like θ̂'s own: no signature at any rung.
    quiet = [_cloud(rng, 0.0, 1.0, n=2) for _ in range(3)]
    record = judge_rungs(quiet, base, threshold)
    assert record["screened"] and record["reason"].startswith("no signature"), record
    assert all(r["shift"] <= r["threshold"] for r in record["rungs"])
    # A strong signature at the top rung alone is enough to refine the effect.
    loud = [*quiet[:2], _cloud(rng, 4.0, 1.0, n=2)]
    assert not judge_rungs(loud, base, threshold)["screened"]
    # Shifted beyond a deterministic effect's threshold, but its own clips differ even more:
    # the augmented model would leave that noise too.
    wild = [_cloud(rng, 0.0, 1.0, n=2), _cloud(rng, 0.0, 1.0, n=2), np.array([[2.0] * 8, [-6.0] * 8])]
    record = judge_rungs(wild, base, threshold)
    assert record["rungs"][-1]["shift"] > threshold.at(), record["rungs"][-1]
    assert record["screened"] and record["reason"].startswith("hidden by its own randomness"), record
    # A rung that failed to simulate says nothing: the effect is refined.
    failed = [*quiet[:2], np.full((2, 8), np.nan)]
    assert not judge_rungs(failed, base, threshold)["screened"]


def test_screened_candidates_still_count_in_the_effect_test():
    """The one refined candidate at p = 0.02 would pass alone (0.05 / 1) but not as one of four
    candidates (0.05 / 4): screening the other three out must not lower the bar."""
    rule = DecisionRule()
    candidate = {"effect": "x", "significant": True, "p_value": 0.02, "gap": 1.0, "n_params": 1}
    gap = misspecification(1.0, 1.0, rule)  # the gap test does not fire
    assert final_verdict(gap, [candidate], rule)["misspecified"]
    assert not final_verdict(gap, [candidate], rule, n_candidates=4)["misspecified"]


# --------------------------------------------------------------------- a real diagnosis


class Inert(Effect):
    """An effect that changes nothing: no fit could name it."""

    name = "inert"
    description = "a term that is always zero"
    phenomenon = "pendulum_lab"
    parameter_space = ParameterSpace([ParameterSpec("inert_strength", (0.0, 1.0), default=0.0)])

    def term(self, state, params, t):
        return 0.0


def _jittery_simulator(effects=()):
    from pendulum_example.physics import PendulumSimulator

    class Jittery(PendulumSimulator):
        """The bob shaken sideways by seeded noise of 3 cm per frame (a shaky video)."""

        def simulate(self, params, *, seed=0):
            traj = super().simulate(params, seed=seed)
            shake = np.random.default_rng(seed).normal(0.0, 0.03, (traj.vertices.shape[0], 1, 1))
            vertices = traj.vertices.copy()
            vertices[..., :1] += shake.astype(np.float32)
            return dataclasses.replace(traj, vertices=vertices)

    return Jittery(effects=effects)


def _registry():
    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    jittery = dataclasses.replace(registry.phenomenon("pendulum_lab"), make_simulator=_jittery_simulator)
    test = registry.scoped("test")
    test.add_phenomenon("pendulum_jitter", lambda **_: jittery, "the pendulum, shaken")
    test.add_effect("inert", Inert, "pendulum_lab", Inert.description)
    return registry


@pytest.fixture(scope="module")
def target(tmp_path_factory) -> Path:
    from pendulum_example.physics import QuadraticDrag

    from physinfer.video import write_video

    registry = _registry()
    renderer = registry.phenomenon("pendulum_lab").make_renderer()
    truth = {"length": 1.1, "damping": 0.05, "amplitude": 50.0, "drag_quadratic": 1.5}
    clip = renderer.render(_jittery_simulator([QuadraticDrag()]).simulate(truth, seed=99), {"size": 48})
    renderer.close()
    return write_video(tmp_path_factory.mktemp("screen") / "target.mp4", clip)


def _diagnose(out: Path, target: Path, screen: bool, **kw) -> dict:
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.discrepancy.workflow import run_diagnosis

    # Ridge starts off (tests/core/test_diagnose_ridge.py checks them): they would double each run.
    kw = {"limits": False, "workers": 1, "ridge_starts": False, **kw}
    settings = DiagnoseSettings(
        plugin="pendulum_jitter", out=out, target_path=target, render_set={"size": 48}, steps=3,
        optimizer="random", floor_samples=4, calibration_runs=1, videos=False,
        effects=("quadratic_drag", "inert"), screen=screen, **kw,
    )  # fmt: skip
    return run_diagnosis(_registry(), settings)


def test_a_diagnosis_leaves_out_the_effect_no_fit_could_name(tmp_path: Path, target: Path):
    report = _diagnose(tmp_path / "screened", target, screen=True)
    assert [c["effect"] for c in report["screened"]] == ["inert"], report["screened"]
    assert report["screened"][0]["reason"].startswith("no signature")
    assert [c["effect"] for c in report["candidates"]] == ["quadratic_drag"]
    assert not (tmp_path / "screened" / "effect-inert").exists()
    assert "inert: screened out, not refined (no signature" in (tmp_path / "screened" / "report.html").read_text()
    assert (tmp_path / "screened" / "screen.json").is_file() and "screen" in report["timing"]["stages_s"]
    # The drag's signature clears its threshold at the strongest rung: only that rung was simulated.
    import json

    screens = json.loads((tmp_path / "screened" / "screen.json").read_text())["effects"]
    assert [r["fraction"] for r in screens["quadratic_drag"]["rungs"]] == [1.0]
    assert [r["fraction"] for r in screens["inert"]["rungs"]] == [0.125, 0.25, 0.5, 1.0]
    # --no-screen refines both, and the stages both ran have the same trials.
    every = _diagnose(tmp_path / "all", target, screen=False)
    assert every["screened"] == [] and [c["effect"] for c in every["candidates"]] == ["quadratic_drag", "inert"]
    from physinfer.rundir import RunDirectory

    for stage in ("baseline", "control", "effect-quadratic_drag"):
        one, two = (RunDirectory(tmp_path / run / stage).read_trials() for run in ("screened", "all"))
        assert [(t.params, t.distance) for t in one] == [(t.params, t.distance) for t in two], stage
    # Resumed with the screen, a diagnosis whose effect stage already finished uses it.
    resumed = _diagnose(tmp_path / "all", target, screen=True)
    assert resumed["screened"] == [] and [c["effect"] for c in resumed["candidates"]] == ["quadratic_drag", "inert"]
    # A re-run resumes the screen from screen.json (nothing re-simulated, the same verdict).
    again = _diagnose(tmp_path / "screened", target, screen=True)
    assert again["screened"] == report["screened"] and again["named_effect"] == report["named_effect"]


# Slow (50-65 s on 2 cores): two diagnoses with limits. The default run keeps workers through
# test_diagnose.py's pool test and the screen through the test above.
@pytest.mark.slow
def test_the_screen_and_limits_on_workers_are_those_of_one_process(tmp_path: Path, target: Path):
    """On two workers every clip of the screen's rungs and of the limits' chains is a job of
    its own (physinfer.discrepancy.clip_jobs): the same screen and limits as in one process."""
    import json

    one = _diagnose(tmp_path / "one", target, screen=True, limits=True)
    two = _diagnose(tmp_path / "two", target, screen=True, limits=True, workers=2, registry_factory=_registry)
    assert two["timing"]["workers"] == 2 and one["timing"]["workers"] == 1
    screens = [json.loads((tmp_path / run / "screen.json").read_text()) for run in ("one", "two")]
    assert screens[0] == screens[1] and screens[0]["effects"]["inert"]["screened"]
    limits = [json.loads((tmp_path / run / "limits.json").read_text())["limits"] for run in ("one", "two")]
    for record in limits:
        record.pop("wall_time_s")
    assert limits[0] == limits[1] and limits[0]["simulations"] > 0
    assert two["screened"] == one["screened"] and two["named_effect"] == one["named_effect"]


def test_a_deterministic_phenomenon_is_never_screened(tmp_path: Path):
    """Noise floor 0: any shift clears a zero threshold, so nothing is simulated or left out."""
    from physinfer.discrepancy.screen import screen_effects
    from physinfer.discrepancy.settings import DiagnoseSettings

    settings = DiagnoseSettings(plugin="pendulum_lab", out=tmp_path)
    identical = np.zeros((4, 8))
    assert screen_effects(settings, None, {}, {}, identical, {"inert": Inert()}, print) == {}
    assert not (tmp_path / "screen.json").exists()
