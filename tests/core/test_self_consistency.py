"""Only the self-consistency runs that can change a decision are refined
(physinfer.discrepancy.self_consistency), and the decisions are those of refining them all."""

from __future__ import annotations

import math
from html import escape as html_escape
from pathlib import Path

import numpy as np
import pytest

from physinfer.discrepancy.decide import null_scale, self_consistency_gap
from physinfer.discrepancy.self_consistency import SelfConsistencyRun, next_to_refine, scale_bounds


def _signature(breakpoints):
    """Decisions that flip, one by one, as the null scale passes each breakpoint (monotone)."""
    return lambda scale: tuple(scale < b for b in breakpoints)


def _settle(a, b, floor, q95, breakpoints, summary="max", workers=None):
    """Run the procedure against known gaps: ``a[r]`` the run's own, ``b[r]`` its control's;
    with ``workers``, a round's controls as the workflow picks them (no more than ``workers``)."""
    from physinfer.discrepancy.self_consistency import one_round_of_controls

    runs = [SelfConsistencyRun(r) for r in range(len(a))]
    signature = _signature(breakpoints)
    refined = []
    while True:
        todo, with_control = next_to_refine(runs, floor, q95, summary, signature)
        if not todo:
            break
        if with_control and workers is not None:
            todo = one_round_of_controls(todo, runs, workers)
        for r in todo:
            runs[r].update({"gap_run": a[r], "gap_control": b[r] if with_control else None}, final=with_control)
            refined.append((r, with_control))
    lo, hi = scale_bounds(runs, floor, q95, summary)
    true_scale = null_scale(floor, q95, self_consistency_gap([min(x, y) for x, y in zip(a, b, strict=True)], summary))
    return runs, refined, (lo, hi), signature(lo) == signature(true_scale)


@pytest.mark.parametrize("workers", [None, 1, 2])
@pytest.mark.parametrize("summary", ["max", "median"])
def test_the_decisions_are_those_of_every_run_refined(summary, workers):
    rng = np.random.default_rng(0)
    for _ in range(400):
        n = int(rng.integers(1, 5))
        a = rng.uniform(0, 10, n)
        b = a * rng.uniform(0.1, 1.2, n)  # a control may end worse than its run: the gap is the smaller
        floor = float(rng.uniform(0, 5)) * (rng.uniform() < 0.8)  # a deterministic phenomenon's floor is 0
        breakpoints = sorted(rng.uniform(0, 12, int(rng.integers(0, 4))))
        runs, _, (lo, hi), same = _settle(a, b, floor, floor * 1.5, breakpoints, summary, workers)
        assert same, (a, b, floor, breakpoints)
        assert lo <= hi


def test_a_round_refines_no_more_controls_than_workers_the_largest_first_stage_gaps_first():
    from physinfer.discrepancy.self_consistency import one_round_of_controls

    runs = [SelfConsistencyRun(r, gap_run=g) for r, g in enumerate([5.0, 0.5, 3.3, 9.0])]
    assert one_round_of_controls([0, 1, 2, 3], runs, 2) == [0, 3]
    assert one_round_of_controls([0, 1, 2], runs, 2) == [0, 2]
    assert one_round_of_controls([1, 2], runs, 4) == [1, 2]
    assert one_round_of_controls([0, 1, 2, 3], runs, 1) == [3]  # in one process: one at a time
    assert one_round_of_controls([0, 1, 2, 3], runs, 0) == [3]


def test_a_deterministic_phenomenon_sends_every_first_stage_with_the_control_and_effects():
    """A noise floor of 0 leaves the null scale anywhere from 0 up: every run's first stage is
    needed, and goes with the first round; otherwise only where a worker would idle."""
    from physinfer.discrepancy.self_consistency import first_self_consistency_jobs
    from physinfer.discrepancy.settings import DiagnoseSettings

    settings = DiagnoseSettings(plugin="pendulum_lab", out=Path("unused"), calibration_runs=3)
    assert first_self_consistency_jobs(settings, ["drag"], 2, floor=0.0) == [(0, False), (1, False), (2, False)]
    assert first_self_consistency_jobs(settings, ["drag"], 2, floor=0.3) == []  # control + drag fill the round
    assert first_self_consistency_jobs(settings, ["drag", "yaw"], 2, floor=0.3) == [(0, False)]
    every = DiagnoseSettings(plugin="pendulum_lab", out=Path("unused"), calibration_runs=2, calibrate_all=True)
    assert first_self_consistency_jobs(every, ["drag"], 2, floor=0.0) == [(0, True), (1, True)]
    none = DiagnoseSettings(plugin="pendulum_lab", out=Path("unused"), calibrate=False)
    assert first_self_consistency_jobs(none, ["drag"], 2, floor=0.0) == []


def test_nothing_is_refined_when_no_scale_above_the_floor_changes_a_decision():
    # Every decision flips below the floor (e.g. a clean target: "nothing" at any scale).
    runs, refined, (lo, hi), same = _settle([5.0, 6.0, 7.0], [4.0, 5.0, 6.0], 3.0, 4.0, [1.0, 2.5])
    assert refined == [] and same
    assert lo == 3.0 and hi == math.inf
    assert all(r.to_dict("not needed")["skipped"] == "not needed" for r in runs)


def test_only_controls_whose_run_crosses_a_decision_are_refined():
    # The decision flips at 5: runs 0 and 2 (own gaps 4 and 4.5) cannot reach it, run 1 (8) can.
    runs, refined, (lo, hi), same = _settle([4.0, 8.0, 4.5], [3.0, 2.0, 4.4], 1.0, 2.0, [5.0])
    assert refined == [(0, False), (1, False), (2, False), (1, True)]
    assert same and (lo, hi) == (2.0, 4.5)
    assert [r.done for r in runs] == [False, True, False]
    assert runs[1].gap == 2.0 and runs[0].bounds() == (0.0, 4.0)


def test_every_run_is_refined_when_the_decision_sits_between_their_gaps():
    _, refined, (lo, hi), same = _settle([9.0, 9.5, 9.8], [6.0, 3.0, 2.5], 1.0, 2.0, [5.0])
    assert sorted(refined) == [(0, False), (0, True), (1, False), (1, True), (2, False), (2, True)]
    assert same and lo == hi == 6.0


def test_idle_workers_take_controls_only_where_first_stages_need_two_rounds_anyway():
    from physinfer.discrepancy.self_consistency import with_idle_controls

    # Three first stages on two workers take two rounds: one run's control fits in the idle slot.
    assert with_idle_controls([0, 1, 2], False, 2) == [(0, True), (1, False), (2, False)]
    # One round (or one process): a control would add a round, so none is added.
    assert with_idle_controls([0, 1], False, 2) == [(0, False), (1, False)]
    assert with_idle_controls([0], False, 2) == [(0, False)]
    assert with_idle_controls([0, 1, 2], False, 1) == [(0, False), (1, False), (2, False)]
    # Controls asked for stay asked for.
    assert with_idle_controls([1, 2, 0], True, 2) == [(1, True), (2, True), (0, True)]


def test_limits_at_the_upper_end_of_a_range_say_so_in_the_verdict_and_on_the_page():
    from physinfer.discrepancy.self_consistency import limits_scale_note
    from physinfer.report.diagnose_page import detection_limits

    candidate = {"effect": "quadratic_drag", "detectable_from": {"drag_quadratic": 0.5},
                 "limit": {"fraction": 0.25, "reason": None, "mimicked_by": [], "reveal": []}}  # fmt: skip
    exact = {"named_effect": None, "candidates": [candidate],
             "limits": {"clip_seconds": 4.0, "null_scale": 0.8, "null_scale_exact": True}}  # fmt: skip
    assert limits_scale_note(exact) is None
    html = detection_limits(exact)
    assert "Detection limits" in html and "quadratic_drag: not named; this 4-s clip" in html
    ranged = {**exact, "limits": {**exact["limits"], "null_scale": 2.608, "null_scale_exact": False}}
    note = limits_scale_note(ranged)
    assert note and "2.608" in note and "--calibrate-all" in note
    assert html_escape(note) in detection_limits(ranged)
    assert "--no-limits" in detection_limits({**exact, "limits": None})
    # Where the range's lower end reads another limit, the line gives it too.
    low = {"detectable_from": None, "reason": "mimicked by damping", "threshold": 0.1}
    ranged["candidates"] = [{**candidate, "limit": {**candidate["limit"], "at_lower_scale": low}}]
    assert html_escape("[at the null scale's lower end: could not reveal it") in detection_limits(ranged)


# ------------------------------------------------------------------ the workflow on the pendulum


# Slow (50-80 s on 2 cores): two whole diagnoses. The default run keeps the rule's own tests above.
@pytest.mark.slow
def test_a_diagnosis_refining_only_the_needed_runs_decides_as_one_refining_all(tmp_path: Path, monkeypatch):
    from tests.core.test_diagnose import _diagnose, _pendulum_target

    # Each diagnosis encodes its self-consistency targets once; libx264 does not repeat itself
    # here (write_video's docstring), and two encodings of one clip moved the null scale by 6 %
    # (0.0849 against 0.0800) in 2 of 5 runs. Compared here is the logic, not the encoder.
    import physinfer.video

    lossy = physinfer.video.write_video
    monkeypatch.setattr(physinfer.video, "write_video", lambda path, frames, fps=None, **kw: lossy(path, frames, fps, lossless=True))

    target = _pendulum_target(tmp_path, "quadratic_drag")
    # Without ridge starts (their own tests check them): compared is which runs are refined.
    kw = {"steps": 3, "optimizer": "random", "limits": True, "workers": 1, "ridge_starts": False}
    needed = _diagnose(tmp_path / "needed", target, **kw)
    full = _diagnose(tmp_path / "all", target, calibrate_all=True, **kw)
    for key in ("misspecified", "misspecified_by", "gap_test", "named_effect", "gap_before", "tested_gap"):
        assert needed[key] == full[key], key
    assert [c["significant"] for c in needed["candidates"]] == [c["significant"] for c in full["candidates"]]
    lo, hi = needed["null_scale_range"]
    assert needed["null_scale"] == lo and lo <= full["null_scale"] <= (hi if hi is not None else math.inf)
    assert full["null_scale_range"] == [full["null_scale"]] * 2
    # The limits assume the range's upper end (the full calibration's own scale when exact).
    assert full["limits"]["null_scale"] == full["null_scale"] and full["limits"]["null_scale_exact"]
    assert needed["limits"]["null_scale_exact"] == (lo == hi)
    assert needed["limits"]["null_scale"] >= full["null_scale"]
    for c in needed["candidates"]:  # read at the lower end too, from the same ladder
        assert ("at_lower_scale" in c["limit"]) == (needed["limits"]["null_scale"] != lo)
    out = tmp_path / "needed" / "diag-quadratic_drag"
    for run in needed["calibration"]:
        r = run["run"]
        ran_control = (out / f"calibration-{r}-control" / "gap.json").is_file()
        assert ran_control == (run["gap_control"] is not None)
        assert ("skipped" in run) == (run["gap"] is None)
        if run["gap"] is not None:  # a finished run's gap is the one the full calibration found
            assert run["gap"] == full["calibration"][r]["gap"]
    # A re-run reads every stage back and decides the same without refining anything.
    again = _diagnose(tmp_path / "needed", target, **kw)
    assert again["calibration"] == needed["calibration"] and again["named_effect"] == needed["named_effect"]


# Slow (40 s): the rounds' scheduling; one process's equivalence is tested in test_diagnose.py.
@pytest.mark.slow
def test_on_workers_a_deterministic_diagnosis_refines_its_first_stages_beside_the_control(tmp_path: Path):
    """The pendulum's floor is 0: its three first stages run in the round of the control and
    the drag model (five jobs), a later round refines no more controls than there are workers,
    and the decisions are those of refining every run."""
    from tests.core.test_diagnose import _diagnose, _pendulum_target

    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.discrepancy.workflow import run_diagnosis
    from physinfer.plugins import load_registry

    target = _pendulum_target(tmp_path, "quadratic_drag")
    lines: list[str] = []
    settings = DiagnoseSettings(plugin="pendulum_lab", out=tmp_path / "w2", target_path=target, render_set={"size": 48},
                                steps=3, optimizer="random", floor_samples=4, videos=False, limits=False, workers=2)
    report = run_diagnosis(load_registry()[0], settings, log=lines.append)
    assert report["noise_floor"] == 0
    rounds = [line.strip() for line in lines if "run side by side" in line]
    assert rounds[0].startswith("5 jobs run side by side"), lines
    assert all(not r.startswith(("3 jobs", "4 jobs")) for r in rounds[1:]), rounds  # at most 2 controls a round
    full = _diagnose(tmp_path / "all", target, steps=3, optimizer="random", limits=False, calibrate_all=True)
    for key in ("misspecified", "gap_test", "named_effect", "tested_gap"):
        assert report[key] == full[key], key
    assert [c["significant"] for c in report["candidates"]] == [c["significant"] for c in full["candidates"]]
    for run in report["calibration"]:
        assert run["gap_run"] == full["calibration"][run["run"]]["gap_run"]  # every first stage ran, the same


def test_a_null_scale_set_by_the_baseline_fits_floor_says_so():
    from physinfer.discrepancy.self_consistency import null_scale_words

    # Hidden-yaw seed 4: the baseline stalled where the flag is chaotic (floor 139); the tested
    # fit (the control) has a floor of 64. Without the note "noise floor 64.4, null scale 139"
    # reads as a contradiction.
    report = {"null_scale": 139.0, "null_scale_range": [139.0, None], "noise_floor": 64.4, "baseline": {"floor": 139.0}}
    assert null_scale_words(report) == "null scale 139 (the noise floor at the baseline fit; any of 139–∞ gives these decisions)"
    # The tested fit is the baseline (one floor), or the scale is a self-consistency gap: no note.
    assert null_scale_words({**report, "noise_floor": 139.0}) == "null scale 139 (any of 139–∞ gives these decisions)"
    assert null_scale_words({**report, "null_scale": 150.0, "null_scale_range": [150.0, 150.0]}) == "null scale 150"
