"""Tests of the ridge starts (physinfer.discrepancy.ridge) and of the ``unnamed`` report
(physinfer.discrepancy.verdict), on the bouncing-ball test plugin: quadratic drag and the
restitution both take height off each bounce, so the drag model's search from the baseline's
fit alone stays in the baseline's basin (issue 46).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))  # the test plugin beside this file (importlib mode)

from bouncing_ball_plugin import AirDrag, ball_registry, ball_target  # noqa: E402
from spring_friction_plugin import TRUTH as BLOCK  # noqa: E402
from spring_friction_plugin import (  # noqa: E402
    BlockSimulator,
    DryFriction,
    friction_registry,
    friction_target,
)

from physinfer import video
from physinfer.discrepancy.candidates import augmented_pipeline
from physinfer.discrepancy.ladder import Probe
from physinfer.discrepancy.refit import polished_start
from physinfer.discrepancy.ridge import effect_paths
from physinfer.discrepancy.stages import deterministic
from physinfer.discrepancy.starts import search_starts
from physinfer.discrepancy.verdict import LEAD_RATIO, closest_lead, closest_unnamed, search_end
from physinfer.discrepancy.warmstart import WarmStartOptimizer
from physinfer.evaluation import build_pipeline, squared_distance
from physinfer.optimizers.random import RandomOptimizer
from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.testing import check_phenomenon

#: The issue's target: drag 0.8 1/m hidden behind a restitution of 0.8.
TRUTH = {"restitution": 0.8, "height": 1.5, "drag_k": 0.8}


def test_extra_starts_follow_the_warm_start_and_are_not_proposed_again_on_resume():
    start, extra = np.array([0.2, -1.0]), [np.array([0.5, 0.0]), np.array([0.7, 1.0])]
    opt = WarmStartOptimizer(RandomOptimizer(dim=2, seed=3), start, extra=extra)
    first = opt.attach(np.zeros(2))
    asked = opt.ask(3)
    np.testing.assert_allclose(first.x, start)
    np.testing.assert_allclose(asked[0].x, extra[0], atol=1e-12)
    np.testing.assert_allclose(asked[1].x, extra[1], atol=1e-12)
    # A resumed run replays the logged trials: the extra points are not proposed again.
    again = WarmStartOptimizer(RandomOptimizer(dim=2, seed=3), start, extra=extra)
    for trial in [first, *asked[:2]]:
        again.attach(trial.x)
    nxt = again.ask(1)[0]
    assert not any(np.allclose(nxt.x, e) for e in extra)
    # Replayed only in part, the rest still comes first.
    part = WarmStartOptimizer(RandomOptimizer(dim=2, seed=3), start, extra=extra)
    part.attach(first.x)
    part.attach(asked[0].x)
    np.testing.assert_allclose(part.ask(1)[0].x, extra[1], atol=1e-12)


def test_a_signed_effect_is_searched_both_ways():
    one_sided = ParameterSpace([ParameterSpec("k", (0.0, 1.5), default=0.0)])
    signed = ParameterSpace([ParameterSpec("yaw", (-60.0, 60.0), default=0.0)])
    assert len(effect_paths(one_sided)) == 1
    paths = effect_paths(signed)
    assert sorted(moved["yaw"][1] for moved, _ in paths) == [-1.0, 1.0]


def test_search_starts_begin_at_the_closest_point(tmp_path: Path):
    theta = {"restitution": 0.5, "height": 1.5}
    off = {**theta, "drag_k": 0.0}
    assert search_starts(tmp_path, "ball_drag", theta, off, 20) is None  # no ridge.json: as before
    ridge = {"key": {"theta": theta}, "effects": {"ball_drag": {"baseline_distance": 7.0, "starts": [
        {"params": {"restitution": 0.78, "height": 1.5, "drag_k": 0.75}, "distance": 0.1},
        {"params": {"restitution": 0.6, "height": 1.45, "drag_k": 0.37}, "distance": 3.0},
        {"params": {"restitution": 0.9, "height": 1.5, "drag_k": 1.5}, "distance": 9.0},
    ]}}}  # fmt: skip
    (tmp_path / "ridge.json").write_text(json.dumps(ridge))
    start, extra = search_starts(tmp_path, "ball_drag", theta, off, 20)
    assert start["drag_k"] == 0.75 and [p["drag_k"] for p in extra] == [0.37, 0.0, 1.5]
    _, few = search_starts(tmp_path, "ball_drag", theta, off, 8)  # a quarter of the budget at most
    assert len(few) == 2
    assert search_starts(tmp_path, "ball_drag", {**theta, "height": 1.4}, off, 20) is None  # another θ̂


def test_unnamed_says_which_came_closest_and_whether_its_search_was_trapped():
    space = ParameterSpace([ParameterSpec("e", (0.3, 0.95)), ParameterSpec("k", (0.0, 1.5), default=0.0)])
    start = {"e": 0.5, "k": 0.0}
    trapped = search_end(space, {"e": 0.501, "k": 0.0}, start, ["k"])
    assert trapped["at_baseline"] and trapped["effect_off"]
    moved = search_end(space, {"e": 0.7, "k": 0.6}, start, ["k"])
    assert not moved["at_baseline"] and not moved["effect_off"]
    cand = {"effect": "drag", "ratio": 1.0, "checks": {"beats_seed_noise": False, "beats_null_scale": False,
                                                       "pays_for_parameters": False}}  # fmt: skip
    record = closest_unnamed([cand], {"drag": trapped}, misspecified=True, named=None, baseline_best={"e": 0.5},
                             effect_steps=20, clip_seconds=4.0)  # fmt: skip
    assert record["trapped"] and record["ended_at_baseline"] and record["effect"] == "drag"
    assert "--effect-steps 40" in record["message"] and "--duration 8" in record["message"]
    assert "\n" not in record["message"]
    limited = {**cand, "limit": {"mimicked_by": [], "reveal": [{"kind": "fix", "parameter": "e", "factor": 1.5}]}}
    record = closest_unnamed([limited], {"drag": trapped}, misspecified=True, named=None, baseline_best={"e": 0.5},
                             effect_steps=20)  # fmt: skip
    assert record["trades_off_with"] == ["e"] and "--fix e=<its measured value>" in record["message"]
    # Nothing to say when something was named, or when the model is not misspecified.
    assert closest_unnamed([cand], {}, misspecified=True, named="drag", baseline_best={}, effect_steps=20) is None
    assert closest_unnamed([cand], {}, misspecified=False, named=None, baseline_best={}, effect_steps=20) is None


def test_a_lead_is_reported_when_not_misspecified_but_one_candidate_took_most_of_the_gap():
    """The flag's 32° yaw on a 2.4-s clip: the yaw model took 64 % of the gap, within the null
    scale. Not a name; a lead, with what would settle it. Clean targets leave x0.98 or more."""
    space = ParameterSpace([ParameterSpec("w", (0.0, 10.0)), ParameterSpec("yaw", (-60.0, 60.0), default=0.0)])
    start = {"w": 6.0, "yaw": 0.0}
    on = search_end(space, {"w": 6.3, "yaw": -26.0}, start, ["yaw"])
    off = search_end(space, {"w": 6.9, "yaw": 0.0}, start, ["yaw"])
    yaw = {"effect": "wind_yaw", "ratio": 0.36, "effect_params": {"yaw": -26.0},
           "checks": {"beats_seed_noise": True, "beats_null_scale": False, "pays_for_parameters": True}}  # fmt: skip
    other = {"effect": "gusts", "ratio": 1.0, "checks": {}}
    lead = closest_lead([other, yaw], {"wind_yaw": on}, misspecified=False, named=None, effect_steps=20,
                        clip_seconds=2.4)  # fmt: skip
    assert lead["effect"] == "wind_yaw" and lead["effect_params"] == {"yaw": -26.0}
    assert "yaw = -26" in lead["message"] and "--duration 4.8" in lead["message"]
    assert lead["failed"] == ["its improvement is within the null scale"] and "\n" not in lead["message"]
    # No lead: a misspecified model (that is ``unnamed``), a name, a small share, the effect left off.
    assert closest_lead([yaw], {}, misspecified=True, named=None, effect_steps=20) is None
    assert closest_lead([yaw], {}, misspecified=False, named="wind_yaw", effect_steps=20) is None
    weak = {**yaw, "ratio": LEAD_RATIO + 0.01}
    assert closest_lead([weak], {}, misspecified=False, named=None, effect_steps=20) is None
    assert closest_lead([yaw], {"wind_yaw": off}, misspecified=False, named=None, effect_steps=20) is None
    assert "--duration" not in closest_lead([yaw], {}, misspecified=False, named=None, effect_steps=20)["message"]
    # A user's video cannot be lengthened by --duration (the simulations last as long as it does).
    filmed = closest_lead([yaw], {"wind_yaw": on}, misspecified=False, named=None, effect_steps=20, clip_seconds=25.6,
                          user_video=True)["message"]  # fmt: skip
    assert "a longer video of the same scene (about 51.2 s)" in filmed and "--duration" not in filmed
    # Shown under the verdict, on the page and in the terminal.
    from physinfer.cli.diagnose_cmd import _named_lines
    from physinfer.report.diagnose_page import verdict

    report = {"misspecified": False, "named_effect": None, "unnamed": None, "lead": lead}
    assert "but a lead: wind_yaw" in verdict(report)
    assert any("but a lead: wind_yaw" in line for line in _named_lines(report, Path("out")))


# --------------------------------------------------------------------- real diagnoses


@pytest.fixture(scope="module")
def drag_target(tmp_path_factory) -> Path:
    return ball_target(TRUTH, tmp_path_factory.mktemp("ball") / "drag.mp4")


def _diagnose(out: Path, target: Path, ridge: bool, **kw) -> dict:
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.discrepancy.workflow import run_diagnosis

    settings = DiagnoseSettings(
        plugin="bouncing_ball", out=out, target_path=target, seed=1, workers=1, videos=False, ridge_starts=ridge,
        floor_samples=4, calibration_runs=1, **kw,
    )  # fmt: skip
    return run_diagnosis(ball_registry(), settings)


def test_the_ridge_probe_finds_the_drag_behind_the_restitution(tmp_path: Path, drag_target: Path):
    """At the baseline's fit (restitution about 0.5, drag off) the probe switches the drag on
    and refits the base to the video: its closest point is near the truth, far closer than θ̂."""
    from physinfer.discrepancy.ridge import ridge_starts
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.evaluation import build_pipeline
    from physinfer.video import read_video

    registry = ball_registry()
    base = build_pipeline(registry, "bouncing_ball")
    target = base.embedder.embed(read_video(drag_target, fps=25.0))
    settings = DiagnoseSettings(plugin="bouncing_ball", out=tmp_path)
    theta = {"restitution": 0.5, "height": 1.5}
    found = ridge_starts(settings, base, {"size": 64}, theta, target, 0.0, {"ball_drag": AirDrag()}, print)
    best = found["ball_drag"]["starts"][0]
    assert best["distance"] < 0.1 * found["ball_drag"]["baseline_distance"], found
    assert abs(best["params"]["drag_k"] - 0.8) < 0.4 and abs(best["params"]["restitution"] - 0.8) < 0.1, best
    assert (tmp_path / "ridge.json").is_file()
    # Read back, not simulated again.
    again = ridge_starts(settings, base, {"size": 64}, theta, target, 0.0, {"ball_drag": AirDrag()}, print)
    assert again == found


@pytest.mark.slow
def test_a_drag_behind_the_restitution_is_named_with_ridge_starts_and_trapped_without(tmp_path: Path,
                                                                                     drag_target: Path):  # fmt: skip
    """The issue's case end to end (20 trials a stage, real Ax): without ridge starts the drag
    model's search ends at the baseline's fit with the drag off and nothing is named, and the
    report says so; with them the drag is named near its true strength."""
    before = _diagnose(tmp_path / "before", drag_target, ridge=False, limits=False)
    assert before["misspecified"] and before["named_effect"] is None
    assert before["unnamed"]["effect"] == "ball_drag" and before["unnamed"]["trapped"], before["unnamed"]
    after = _diagnose(tmp_path / "after", drag_target, ridge=True, limits=False)
    assert after["named_effect"] == "ball_drag" and after["unnamed"] is None
    drag = after["candidates"][0]["effect_params"]["drag_k"]
    assert abs(drag - 0.8) < 0.3, after["candidates"][0]
    run = json.loads((tmp_path / "after" / "effect-ball_drag" / "run.json").read_text())
    assert run["start"]["drag_k"] > 0 and run["extra_starts"], run


def test_a_checked_limit_replaces_the_local_one_and_says_so():
    from physinfer.discrepancy.limit_check import apply_checks
    from physinfer.discrepancy.limit_text import limit_line

    cand = {"effect": "ball_drag", "detectable_from": {"drag_k": 0.13}, "limit": {"reason": None, "reveal": []}}
    check = {"checks": [{"named": False}, {"named": True}], "detectable_from": {"drag_k": 0.26}, "fraction": 0.17,
             "local": {"drag_k": 0.13}, "reason": None}  # fmt: skip
    apply_checks([cand], {"ball_drag": check})
    assert cand["detectable_from"] == {"drag_k": 0.26} and cand["limit"]["local_detectable_from"] == {"drag_k": 0.13}
    line = limit_line(cand, None, 4.0)
    assert "could reveal drag_k ≥ 0.26" in line and "the local refit said drag_k ≥ 0.13" in line, line
    # Not named at either strength: no limit, and the reason says the search does not reach it.
    cand = {"effect": "ball_drag", "detectable_from": {"drag_k": 0.13}, "limit": {"reason": None, "reveal": []}}
    missed = {**check, "detectable_from": None, "fraction": None, "reason": "reachable only from a start ..."}
    apply_checks([cand], {"ball_drag": missed})
    assert cand["detectable_from"] is None and "reachable only" in limit_line(cand, None, 4.0)


def test_a_checked_limit_halves_the_bracket_the_doubling_left():
    """Doubled from the stated limit until named, then the bracket's geometric midpoint: a
    search that names from 0.2 of the range, stated 0.05, is checked at 0.05, 0.1, 0.2 and
    0.141 (named only at 0.2) and its limit read as 0.2, not rounded up to the next doubling;
    one that names from 0.12 is checked at 0.05, 0.1, 0.2, 0.141 and read as 0.141."""
    from physinfer.discrepancy.limit_check import bracket_search

    def search_naming_from(start: float):
        return lambda f: {"fraction": f, "named": f >= start - 1e-12}

    tried = bracket_search(search_naming_from(0.2), 0.05)
    assert [round(r["fraction"], 3) for r in tried] == [0.05, 0.1, 0.2, 0.141]
    assert min(r["fraction"] for r in tried if r["named"]) == pytest.approx(0.2)
    tried = bracket_search(search_naming_from(0.12), 0.05)
    assert min(r["fraction"] for r in tried if r["named"]) == pytest.approx(np.sqrt(0.02))
    # Named at the stated limit: that check alone; named nowhere: the doublings to the far end.
    assert [r["fraction"] for r in bracket_search(search_naming_from(0.01), 0.05)] == [0.05]
    assert [r["fraction"] for r in bracket_search(search_naming_from(2.0), 0.3)] == [0.3, 0.6, 1.0]


def test_the_second_ridge_plugin_keeps_the_contracts():
    """The block on a spring (benchmarks/bench_diagnose_ridge.py --case friction) is a valid
    plugin: its default target re-simulates exactly, dry friction is off at mu_g = 0, and at
    a strong friction the block comes to rest while the viscous model's keeps swinging."""
    registry = friction_registry()
    embedder = build_pipeline(registry, "spring_block").embedder
    check_phenomenon(registry.phenomenon("spring_block"), embedder, registry=registry)
    held = BlockSimulator([DryFriction()]).positions({**BLOCK, "mu_g": 0.6})
    free = BlockSimulator().positions(BLOCK)
    assert np.ptp(held[-25:]) < 1e-5 and np.ptp(free[-25:]) > 0.2


def test_a_polished_start_refits_the_base_to_the_target_and_is_kept(tmp_path: Path):
    """A control's polished start (deterministic phenomena): from a fit off by a few percent
    the Gauss–Newton refit lands closer to the target than the fit; it is kept in the stage's
    folder and read back; at the truth itself there is nothing to polish."""
    registry = friction_registry()
    base = build_pipeline(registry, "spring_block")
    goal = np.asarray(base.embedder.embed(friction_target(BLOCK)))
    off = {"freq_hz": 0.78, "damping": 0.19, "offset": 0.57}
    found = polished_start(base, {"size": 64}, off, goal, (0,), {}, tmp_path / "control")
    assert found is not None and abs(found["freq_hz"] - 0.8) < abs(off["freq_hz"] - 0.8)
    stored = json.loads((tmp_path / "control" / "polish.json").read_text())
    before = squared_distance(goal, base.embedder.embed(friction_target(off)))
    assert stored["start"] == found and stored["distance"] < 0.5 * before
    assert polished_start(base, {"size": 64}, off, goal, (0,), {}, tmp_path / "control") == found
    assert polished_start(base, {"size": 64}, BLOCK, goal, (0,), {}, tmp_path / "exact") is None


def test_only_a_deterministic_baseline_polishes_its_controls(tmp_path: Path):
    """The baseline's gap record decides: a noise floor of 0 polishes, any other none."""
    for floor, expected in ((0.0, True), (0.3, False)):
        out = tmp_path / str(floor)
        (out / "baseline").mkdir(parents=True)
        (out / "baseline" / "gap.json").write_text(json.dumps({"key": {}, "summary": {"floor": floor}}))
        assert deterministic(out) is expected
    assert deterministic(tmp_path / "no-baseline-yet") is False


def test_a_polished_start_moves_the_effect_with_the_base(tmp_path: Path):
    """An effect's search is polished alike (base and effect parameters together): from the
    baseline's fit with the friction half what made the target, the refit lands closer to the
    target than its start, and moves the friction (to about what made the target) with the base."""
    registry = friction_registry()
    base = build_pipeline(registry, "spring_block")
    augmented = augmented_pipeline(base, [DryFriction()])
    truth = {**BLOCK, "mu_g": 0.6}
    goal = np.asarray(base.embedder.embed(friction_target(truth)))
    start = {**BLOCK, "damping": 0.2, "mu_g": 0.3}
    found = polished_start(augmented, {"size": 64}, start, goal, (0,), {}, tmp_path / "effect")
    assert found is not None and abs(found["mu_g"] - 0.6) < 0.05  # 0.595 measured
    before = squared_distance(goal, base.embedder.embed(friction_target(start)))
    after = squared_distance(goal, base.embedder.embed(friction_target(found)))
    assert after < 0.05 * before  # 0.97 -> 8e-5 measured


def test_a_rung_standing_for_a_file_makes_the_round_trip_through_the_encoder():
    """A deterministic baseline's ladder, for a target read from a file, embeds each rung as
    the file's clip would look (H.264 and back), not as rendered: the codec's distance is the
    floor of every gap measured against such a target (0.51 on the ball at the drag's off)."""
    base = build_pipeline(ball_registry(), "bouncing_ball")
    clean = {"restitution": 0.8, "height": 1.5}
    probe = Probe(base, {"size": 64})
    encoded, _ = probe.encoded_clips(base, [clean], [0])
    rendered, _ = probe.clips(base, [clean], [0])
    clip = ball_target(clean)
    expected = squared_distance(base.embedder.embed(video.round_trip(clip)), base.embedder.embed(clip))
    assert expected > 0.05
    assert squared_distance(encoded[0], rendered[0]) == pytest.approx(expected)
    assert video.round_trip(clip).frames.shape == np.asarray(clip.frames).shape[:3] + (3,)
