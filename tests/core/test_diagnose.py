"""Tests of physinfer.discrepancy: localisation, decisions, warm starts, model files, and the
workflow end to end on the pendulum example (hidden drag; no effect)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physinfer.discrepancy.candidates import off_values, warm_start
from physinfer.discrepancy.decide import (
    DecisionRule,
    effect_significance,
    final_verdict,
    misspecification,
    name_effect,
    null_scale,
    rank_test_less,
    self_consistency_gap,
)
from physinfer.discrepancy.localise import LocaliseConfig, localise
from physinfer.discrepancy.model import model_for_refine, read_model, write_model
from physinfer.discrepancy.warmstart import WarmStartOptimizer, warm_start_factory
from physinfer.errors import UserInputError
from physinfer.optimizers.cma import CMAOptimizer
from physinfer.optimizers.random import RandomOptimizer
from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.rundir import RunDirectory
from physinfer.types import Clip


def _grating(freq_map: np.ndarray, fps: float = 25.0, n: int = 64, size: int = 64, amp=None) -> Clip:
    """Pixels flickering at a per-region frequency: ``freq_map`` ``(G, G)`` Hz."""
    g = freq_map.shape[0]
    cell = size // g
    f = np.kron(freq_map, np.ones((cell, cell)))
    a = np.ones_like(f) if amp is None else np.kron(amp, np.ones((cell, cell)))
    t = np.arange(n)[:, None, None] / fps
    gray = 0.5 + 0.4 * a * np.sin(2 * np.pi * f * t)
    frames = np.repeat((gray * 255).astype(np.uint8)[..., None], 3, axis=-1)
    return Clip(frames, fps)


# ------------------------------------------------------------------------ localisation


def test_localise_ranks_the_region_that_moves_differently_first():
    base = np.full((4, 4), 2.0)
    other = base.copy()
    other[1, 2] = 5.0
    numbers, t_maps, f_maps = localise(_grating(other), _grating(base), LocaliseConfig(size=64, grid=4))
    top = numbers["regions"][0]
    assert (top["row"], top["col"]) == (1, 2)
    assert top["freq_target_hz"] == pytest.approx(5.0, abs=0.5)
    assert top["freq_fit_hz"] == pytest.approx(2.0, abs=0.5)
    assert numbers["regions"][1]["score"] < 0.1 * top["score"]
    assert t_maps.dominant.shape == (64, 64)


def test_localise_finds_amplitude_and_nonstationarity_differences():
    amp = np.ones((2, 2))
    amp_t = amp.copy()
    amp_t[0, 0] = 0.2
    numbers, _, _ = localise(_grating(np.full((2, 2), 3.0), amp=amp_t), _grating(np.full((2, 2), 3.0), amp=amp),
                             LocaliseConfig(size=32, grid=2))
    top = numbers["regions"][0]
    assert (top["row"], top["col"]) == (0, 0) and top["log10_power_ratio"] < -1.0
    # A clip whose motion dies half-way is non-stationary; a steady one is not.
    steady = _grating(np.full((2, 2), 3.0))
    frames = steady.frames.copy()
    frames[32:] = frames[32:].mean(axis=0, keepdims=True).astype(np.uint8)
    numbers, _, _ = localise(Clip(frames, 25.0), steady, LocaliseConfig(size=32, grid=2))
    g = numbers["global"]
    assert g["nonstationarity_target"] > 0.5 > g["nonstationarity_fit"]


def test_identical_clips_have_no_discrepancy():
    clip = _grating(np.array([[1.0, 2.0], [3.0, 4.0]]))
    numbers, _, _ = localise(clip, clip, LocaliseConfig(size=32, grid=2))
    assert max(r["score"] for r in numbers["regions"]) == pytest.approx(0.0, abs=1e-9)


# --------------------------------------------------------------------------- decisions


def test_self_consistency_gap_summaries():
    assert self_consistency_gap([2.36, 0.2, 0.3]) == pytest.approx(2.36)  # max, the default
    assert self_consistency_gap([2.36, 0.2, 0.3], "median") == pytest.approx(0.3)
    assert self_consistency_gap([0.4, float("nan"), 0.6], "median") == pytest.approx(0.5)
    assert self_consistency_gap([0.4, float("nan"), 0.6]) == pytest.approx(0.6)
    assert self_consistency_gap([]) is None
    assert null_scale(0.25, 0.4, self_consistency_gap([0.1, 0.2, 0.3], "median")) == pytest.approx(0.25)
    with pytest.raises(UserInputError, match="--calibration-summary must be one of max, median"):
        DecisionRule(calibration_summary="mean").validate()


def test_calibration_seeds_keep_the_single_runs_seeds_and_differ():
    from physinfer.discrepancy.stages import calibration_seeds
    from physinfer.evaluation import noise_seeds

    for seed in (0, 3, 41):
        pairs = calibration_seeds(seed, 4)
        # Run 0 is the calibration of earlier versions (an old run directory resumes).
        assert pairs[0] == (noise_seeds(seed + 7, 1)[0], seed + 1)
        assert len({t for t, _ in pairs}) == 4 and len({o for _, o in pairs}) == 4
        assert all(o != seed for _, o in pairs)
    # Neighbouring diagnosis seeds do not share calibration optimizer seeds.
    assert not {o for _, o in calibration_seeds(0, 3)} & {o for _, o in calibration_seeds(1, 3)}


def test_calibration_runs_must_be_positive(tmp_path: Path):
    from physinfer.discrepancy.settings import DiagnoseSettings

    with pytest.raises(UserInputError, match="--calibration-runs must be at least 1"):
        DiagnoseSettings(plugin="pendulum_lab", out=tmp_path, calibration_runs=0).validate()
    with pytest.raises(UserInputError, match="--select-top must be 0 or at least 2"):
        DiagnoseSettings(plugin="pendulum_lab", out=tmp_path, select_top=1).validate()
    with pytest.raises(UserInputError, match="--batch-size must be at least 1"):
        DiagnoseSettings(plugin="pendulum_lab", out=tmp_path, batch_size=0).validate()


def test_null_scale_and_misspecification():
    # Without self-consistency runs: the floor's q95; with them: medians only.
    assert null_scale(0.5, 1.0, None) == 1.0
    assert null_scale(0.5, 1.0, 3.0) == 3.0
    assert null_scale(0.5, 4.0, 0.8) == 0.8  # a tail of the floor does not set the scale
    assert null_scale(0.9, 4.0, 0.8) == 0.9  # the floor median is the least a model leaves
    rule = DecisionRule(misspecified_factor=2.0)
    assert misspecification(7.0, 3.0, rule)["misspecified"]
    assert not misspecification(5.0, 3.0, rule)["misspecified"]


def test_rank_test_is_one_sided_and_handles_deterministic_samples():
    assert rank_test_less([1.0] * 4, [2.0] * 4) < 0.05  # deterministic, separated
    assert rank_test_less([2.0] * 4, [1.0] * 4) > 0.5
    assert rank_test_less([1.0] * 4, [1.0] * 4) == 1.0
    rng = np.random.default_rng(0)
    a, b = rng.normal(1.0, 0.1, 6), rng.normal(1.0, 0.1, 6)
    assert rank_test_less(a, b) > 0.01


def test_effect_significance_needs_all_three_checks():
    rule = DecisionRule(alpha=0.05, per_parameter_factor=0.8)
    good = effect_significance(distances=[1.0] * 6, baseline_distances=[10.0] * 6, gap=1.0, gap_before=10.0,
                               n_params=2, scale=2.0, rule=rule)
    assert good["significant"] and good["improvement"] == 9.0 and good["ratio"] == 0.1
    small = effect_significance(distances=[9.0] * 6, baseline_distances=[10.0] * 6, gap=9.0, gap_before=10.0,
                                n_params=1, scale=0.5, rule=rule)
    assert small["checks"]["beats_seed_noise"] and small["checks"]["beats_null_scale"]
    assert not small["checks"]["pays_for_parameters"] and not small["significant"]
    noisy = effect_significance(distances=[5.0, 12.0, 4.0, 11.0], baseline_distances=[10.0, 6.0, 9.0, 7.0],
                                gap=8.0, gap_before=8.5, n_params=1, scale=0.1, rule=rule)
    assert not noisy["checks"]["beats_seed_noise"]


def test_name_effect_only_when_misspecified():
    cands = [
        {"effect": "a", "gap": 2.0, "n_params": 1, "significant": True},
        {"effect": "b", "gap": 1.0, "n_params": 2, "significant": True},
        {"effect": "c", "gap": 0.5, "n_params": 1, "significant": False},
    ]
    assert name_effect(cands, misspecified=True) == "b"
    assert name_effect(cands, misspecified=False) is None
    assert name_effect(cands[2:], misspecified=True) is None


def test_a_significant_effect_is_evidence_of_misspecification_unless_the_gap_test_is_required():
    gap_short = misspecification(5.0, 3.0, DecisionRule())  # 5 < 2 x 3: the gap test does not fire
    significant = [{"effect": "a", "gap": 1.0, "n_params": 1, "significant": True, "p_value": 0.03}]
    unconvincing = [{"effect": "a", "gap": 4.5, "n_params": 1, "significant": False, "p_value": 0.3}]
    both = final_verdict(misspecification(7.0, 3.0, DecisionRule()), significant, DecisionRule())
    assert both["misspecified"] and both["evidence"] == ["gap", "effect"] and both["gap_test"]
    by_effect = final_verdict(gap_short, significant, DecisionRule())
    assert by_effect["misspecified"] and by_effect["evidence"] == ["effect"] and not by_effect["gap_test"]
    assert name_effect(significant, by_effect["misspecified"]) == "a"
    strict = final_verdict(gap_short, significant, DecisionRule(effect_evidence=False))
    assert not strict["misspecified"] and strict["evidence"] == []
    assert name_effect(significant, strict["misspecified"]) is None
    neither = final_verdict(gap_short, unconvincing, DecisionRule())
    assert not neither["misspecified"] and neither["threshold"] == 6.0
    # Two candidates are two tests: p = 0.03 is not below 0.05 / 2 (Bonferroni), 0.01 is.
    two = [*significant, {"effect": "b", "gap": 4.0, "n_params": 1, "significant": False, "p_value": 0.4}]
    assert not final_verdict(gap_short, two, DecisionRule())["misspecified"]
    two[0] = {**two[0], "p_value": 0.01}
    assert final_verdict(gap_short, two, DecisionRule())["evidence"] == ["effect"]


def test_decision_rule_validates():
    with pytest.raises(UserInputError):
        DecisionRule(misspecified_factor=0.5).validate()
    with pytest.raises(UserInputError):
        DecisionRule(alpha=0.7).validate()


# ------------------------------------------------------------------------- warm starts


def test_warm_start_first_trial_and_coordinate_map():
    start = np.array([0.5, -1.0, 0.2])
    opt = warm_start_factory(RandomOptimizer, start)(dim=3, seed=0, names=["a", "b", "c"])
    first = opt.attach(np.zeros(3))
    np.testing.assert_allclose(first.x, start)
    for trial in opt.ask(20):
        assert np.all(np.abs(trial.x) <= 1.0)
    z = np.array([0.3, 0.4, -0.9])
    np.testing.assert_allclose(opt.to_z(opt.to_x(z)), z)
    np.testing.assert_allclose(opt.to_x(np.ones(3)), np.ones(3))
    np.testing.assert_allclose(opt.to_x(-np.ones(3)), -np.ones(3))


def test_a_warm_start_on_a_bound_does_not_collapse_the_search_onto_it():
    # The pendulum's case: damping at its upper bound, the effect's drag off at its lower one.
    start = np.array([1.0, -1.0, 0.2])
    opt = WarmStartOptimizer(RandomOptimizer(dim=3, seed=0), start)
    np.testing.assert_allclose(opt.attach(np.zeros(3)).x, start)  # the first trial is the start
    xs = np.array([t.x for t in opt.ask(400)])
    on_bound = np.mean(np.isclose(np.abs(xs[:, :2]), 1.0), axis=0)
    assert np.all(on_bound < 0.02)  # centred exactly on the bound this was one half
    assert np.all(np.mean(xs[:, :2] > 0, axis=0) > 0.2) and np.all(np.mean(xs[:, :2] < 0, axis=0) > 0.2)
    z = np.array([0.7, -0.3, 0.1])
    np.testing.assert_allclose(opt.to_z(opt.to_x(z)), z)


def test_warm_started_cma_searches_around_the_start():
    start = np.array([0.8, -0.6])
    opt = WarmStartOptimizer(CMAOptimizer(dim=2, seed=0), start)
    opt.attach(np.zeros(2))
    xs = np.array([t.x for t in opt.ask(6)])
    plain = np.array([t.x for t in CMAOptimizer(dim=2, seed=0).ask(6)])
    assert np.linalg.norm(xs.mean(axis=0) - start) < np.linalg.norm(plain.mean(axis=0) - start)


def test_resume_replays_the_warm_start_exactly():
    start = np.array([0.3, -0.2])
    first = WarmStartOptimizer(RandomOptimizer(dim=2, seed=1), start)
    x0 = first.attach(np.zeros(2)).x
    replay = WarmStartOptimizer(RandomOptimizer(dim=2, seed=1), start)
    np.testing.assert_allclose(replay.attach(x0).x, x0)


def test_effect_parameters_start_off():
    space = ParameterSpace([ParameterSpec("c", (0.0, 2.0)), ParameterSpec("yaw", (-60.0, 60.0), default=0.0)])
    assert off_values(space) == {"c": 0.0, "yaw": 0.0}

    class FakeEffect:
        parameter_space = space

    assert warm_start({"length": 1.0}, [FakeEffect()]) == {"length": 1.0, "c": 0.0, "yaw": 0.0}


# -------------------------------------------------------------------------- model file


def test_model_file_round_trip_and_checks(tmp_path: Path):
    space = ParameterSpace([ParameterSpec("length", (0.4, 1.6)), ParameterSpec("drag_quadratic", (0.0, 2.0))])
    write_model(tmp_path / "model.json", plugin="pendulum_lab", effects=["quadratic_drag"], space=space,
                values={"length": 1.1, "drag_quadratic": 0.9}, gap=0.5)
    model = read_model(tmp_path / "model.json")
    assert model.effects == ("quadratic_drag",) and model.extra["gap"] == 0.5
    assert model.start_for(space) == {"length": 1.1, "drag_quadratic": 0.9}
    assert model_for_refine(tmp_path / "model.json", "pendulum_lab", []).plugin == "pendulum_lab"
    with pytest.raises(UserInputError, match="not of --plugin"):
        model_for_refine(tmp_path / "model.json", "flag", [])
    with pytest.raises(UserInputError, match="contradicts"):
        model_for_refine(tmp_path / "model.json", "pendulum_lab", ["other"])
    with pytest.raises(UserInputError, match="do not match"):
        model.start_for(ParameterSpace([ParameterSpec("length", (0.4, 1.6))]))
    (tmp_path / "bad.json").write_text(json.dumps({"plugin": "pendulum_lab"}))
    with pytest.raises(UserInputError, match="not a physinfer model file"):
        read_model(tmp_path / "bad.json")
    with pytest.raises(UserInputError, match="no such file"):
        read_model(tmp_path / "missing.json")


def test_refine_model_takes_the_scene_the_model_was_fitted_on(tmp_path: Path):
    """``model.json`` records the diagnosis' scene: ``refine --model`` refines on it and
    refuses another ``--scene-set`` before simulating anything."""
    from physinfer.discrepancy.model import check_model_scene
    from physinfer.plugins import load_registry
    from physinfer.session import refine

    registry, _ = load_registry()
    flag = registry.get("phenomena", "flag").load()
    space = ParameterSpace([ParameterSpec("wind_speed", (0.0, 10.0))])
    scene = {"flag_length": 3.0, "flag_height": 2.0, "pinning": "hoist", "pole_height": 3.5}
    write_model(tmp_path / "big.json", plugin="flag", effects=[], space=space, values={"wind_speed": 4.0},
                scene=scene)
    write_model(tmp_path / "plain.json", plugin="flag", effects=[], space=space, values={"wind_speed": 4.0})
    big, plain = read_model(tmp_path / "big.json"), read_model(tmp_path / "plain.json")
    check_model_scene(big, tmp_path / "big.json", flag, scene)  # its own scene: accepted
    check_model_scene(plain, tmp_path / "plain.json", flag, None)
    with pytest.raises(UserInputError, match="fitted on the default scene"):
        check_model_scene(plain, tmp_path / "plain.json", flag, {**scene, "flag_length": 2.0})
    with pytest.raises(UserInputError, match="fitted on flag_length=3.*drop --scene-set"):
        refine(registry, plugin="flag", model=tmp_path / "big.json", scene_set={"flag_length": "1.5"},
               steps=1, out=tmp_path / "run", progress=False)


# ---------------------------------------------------------------------- end to end (pendulum)


def _pendulum_target(tmp_path: Path, effect: str | None) -> Path:
    from physinfer.evaluation import build_pipeline
    from physinfer.plugins import load_registry
    from physinfer.video import write_video

    registry, _ = load_registry()
    pipeline = build_pipeline(registry, "pendulum_lab", effects=[effect] if effect else [], embedder="")
    truth = {"length": 1.1, "damping": 0.05, "amplitude": 50.0}
    if effect:
        truth["drag_quadratic"] = 1.0
    clip = pipeline.renderer.render(pipeline.simulator.simulate(truth), {"size": 48})
    pipeline.renderer.close()
    return write_video(tmp_path / f"{effect or 'none'}.mp4", clip)


def _diagnose(tmp_path: Path, target: Path, steps: int, optimizer: str, **kw):
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.discrepancy.workflow import run_diagnosis
    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    kw.setdefault("workers", 1)  # tiny stages: starting workers would cost more than they save
    settings = DiagnoseSettings(
        plugin="pendulum_lab", out=tmp_path / f"diag-{target.stem}", target_path=target, render_set={"size": 48},
        steps=steps, optimizer=optimizer, floor_samples=4, videos=False, **kw,
    )
    return run_diagnosis(registry, settings)


# Slow (60-90 s on 2 cores): every stage's trials on workers against one process. The default
# run keeps workers through test_diagnose_screen's screen-and-limits test and the pool test below.
@pytest.mark.slow
def test_stages_on_workers_give_the_trials_and_decisions_of_one_process(tmp_path: Path):
    target = _pendulum_target(tmp_path, "quadratic_drag")
    # (Ax's trials were checked the same way by hand: a default pendulum diagnosis, 9 stages.)
    kw = {"steps": 3, "optimizer": "random", "calibration_runs": 2, "select_top": 2, "select_seeds": 2}
    alone = _diagnose(tmp_path / "alone", target, workers=1, **kw)
    side_by_side = _diagnose(tmp_path / "workers", target, workers=2, **kw)
    assert side_by_side["timing"]["workers"] == 2 and alone["timing"]["workers"] == 1
    # The same stages ran (the self-consistency runs the decisions needed) with the same trials.
    stages = sorted(p.name for p in (tmp_path / "alone" / "diag-quadratic_drag").iterdir() if p.is_dir())
    assert stages == sorted(p.name for p in (tmp_path / "workers" / "diag-quadratic_drag").iterdir() if p.is_dir())
    assert {"baseline", "calibration-0", "calibration-1", "control", "effect-quadratic_drag"} <= set(stages)
    assert set(side_by_side["timing"]["stages_s"]) >= {"baseline", "side_by_side", "calibration-0", "control"}
    for stage in stages:
        one, two = (RunDirectory(tmp_path / run / "diag-quadratic_drag" / stage).read_trials()
                    for run in ("alone", "workers"))  # fmt: skip
        assert [(t.params, t.distance) for t in one] == [(t.params, t.distance) for t in two], stage
    for key in ("misspecified", "named_effect", "gap_before", "gap_after", "null_scale", "self_consistency_gaps"):
        assert side_by_side[key] == alone[key], key
    # The baseline's selection and gap, re-simulated on the workers there, equal this process' own.
    one, two = (tmp_path / run / "diag-quadratic_drag" / "baseline" for run in ("alone", "workers"))
    assert json.loads((one / "selection.json").read_text())["finalists"] == json.loads(
        (two / "selection.json").read_text())["finalists"]  # fmt: skip
    here, there = (np.load(d / "gap.npz", allow_pickle=False)["embeddings"] for d in (one, two))
    assert here.dtype == there.dtype and np.array_equal(here, there)
    # The detection-limit ladders ran on the workers too (one job per effect), to the same limits.
    assert "limits" in side_by_side["timing"]["stages_s"]
    for key in ("detectable_from", "limit"):
        assert [c[key] for c in side_by_side["candidates"]] == [c[key] for c in alone["candidates"]], key
    assert side_by_side["limits"]["simulations"] == alone["limits"]["simulations"]


def test_diagnose_runs_end_to_end_and_resumes(tmp_path: Path):
    """A tiny budget: every output is written, the JSON has its keys, a re-run resumes."""
    target = _pendulum_target(tmp_path, "quadratic_drag")
    report = _diagnose(tmp_path, target, steps=2, optimizer="random", calibrate_all=True)
    for key in ("misspecified", "named_effect", "gap_before", "gap_after", "noise_floor", "candidates", "regions"):
        assert key in report
    (cand,) = report["candidates"]
    assert cand["effect"] == "quadratic_drag"
    assert set(cand) >= {"effect", "gap", "improvement", "significant"}
    assert report["noise_floor"] == pytest.approx(0.0, abs=1e-9)  # the pendulum is deterministic
    assert len(report["regions"]) == 16 and report["regions"][0]["score"] >= report["regions"][-1]["score"]
    out = tmp_path / "diag-quadratic_drag"
    for name in ("diagnosis.json", "model.json", "maps.png", "gaps.png"):
        assert (out / name).is_file()
    # The augmented run's first trial is its warm start: the closest to the target of the
    # baseline's best with the drag off and the ridge's points (physinfer.discrepancy.ridge).
    first = json.loads((out / "effect-quadratic_drag" / "trials.jsonl").read_text().splitlines()[0])
    start = json.loads((out / "effect-quadratic_drag" / "run.json").read_text())["start"]
    assert first["params"] == pytest.approx(start)
    ridge = json.loads((out / "ridge.json").read_text())["effects"]["quadratic_drag"]
    closest = min([ridge["baseline_distance"], *(p["distance"] for p in ridge["starts"])])
    if start["drag_quadratic"] == 0.0:
        assert start["length"] == pytest.approx(report["baseline"]["best_params"]["length"])
        assert ridge["baseline_distance"] == closest
    else:
        assert next(p["distance"] for p in ridge["starts"] if p["params"] == pytest.approx(start)) == closest
    again = _diagnose(tmp_path, target, steps=2, optimizer="random", calibrate_all=True)
    assert again["gap_before"] == report["gap_before"]
    model = read_model(out / "model.json")
    assert model.plugin == "pendulum_lab"
    # Three calibration runs (all refined: calibrate_all), each a stage with its own control; the null scale
    # uses the largest of their gaps, and the test uses the best baseline fit's gap.
    gaps = report["self_consistency_gaps"]
    assert len(gaps) == 3 and report["self_consistency_gap"] == pytest.approx(max(gaps))
    for r, run in enumerate(report["calibration"]):
        assert (out / f"calibration-{r}" / "trials.jsonl").is_file()
        assert len((out / f"calibration-{r}-control" / "trials.jsonl").read_text().splitlines()) == 2
        assert run["gap"] == min(run["gap_run"], run["gap_control"])
    assert len({run["target_seed"] for run in report["calibration"]}) == 3
    assert report["tested_gap"] == report["gap_before"]
    assert report["settings"]["calibration_runs"] == 3 and report["settings"]["calibration_control"]
    # The detection limit of every candidate (physinfer.discrepancy.limits), cached for the re-run.
    assert set(cand) >= {"detectable_from", "limit"}
    assert cand["detectable_from"] is None or set(cand["detectable_from"]) == {"drag_quadratic"}
    assert (cand["detectable_from"] is None) == (cand["limit"]["reason"] is not None)
    assert set(cand["limit"]) >= {"fraction", "reason", "mimicked_by", "rungs", "threshold", "reveal"}
    assert set(report["limits"]) >= {"seeds", "simulations", "diagnosis_simulations", "share", "clip_seconds"}
    assert report["limits"]["clip_seconds"] == pytest.approx(4.0)  # 100 frames at 25 fps
    assert (out / "limits.json").is_file() and again["candidates"][0]["limit"] == cand["limit"]
    # The API's result object draws the same gap figure from the report alone.
    from physinfer.api import Diagnosis

    figure = Diagnosis.from_report(report, out).plot()
    assert len(figure.axes[0].patches) == 2  # one bar for the baseline, one for the candidate


# Slow (40 s): a layout of runs from before --calibration-runs (2026-11).
@pytest.mark.slow
def test_an_old_single_calibration_is_reused_as_run_zero(tmp_path: Path):
    """A diagnosis from before --calibration-runs (one ``calibration/``) continues without redoing it."""
    target = _pendulum_target(tmp_path, None)
    first = _diagnose(tmp_path, target, steps=2, optimizer="random", calibration_runs=1, calibration_control=False)
    out = tmp_path / "diag-none"
    (out / "calibration-0").rename(out / "calibration")  # the layout of the older version
    trials = (out / "calibration" / "trials.jsonl").read_text()
    again = _diagnose(tmp_path, target, steps=2, optimizer="random", calibration_runs=2, calibration_control=False)
    assert not (out / "calibration").exists()
    assert (out / "calibration-0" / "trials.jsonl").read_text() == trials  # resumed, not rerun
    assert again["self_consistency_gaps"][0] == first["self_consistency_gaps"][0]
    assert len(again["self_consistency_gaps"]) == 2
    # Without calibration controls the test uses the baseline stage's own gap.
    assert again["tested_gap"] == again["baseline"]["gap"]
    assert again["calibration"][0]["gap_control"] is None


def test_a_duration_the_phenomenon_cannot_record_is_refused_before_anything_is_written(tmp_path: Path):
    target = _pendulum_target(tmp_path, None)
    with pytest.raises(UserInputError, match="records a fixed length"):
        _diagnose(tmp_path, target, steps=2, optimizer="random", duration_s=3.0)
    assert not (tmp_path / "diag-none").exists()


def test_fixed_parameters_stay_fixed_in_every_model_and_in_the_model_file(tmp_path: Path):
    """``--fix``: known values are held in the baseline, the calibration runs and the augmented
    models alike, and ``refine --model`` holds them again."""
    from physinfer.plugins import load_registry
    from physinfer.rundir import RunDirectory
    from physinfer.session import refine

    target = _pendulum_target(tmp_path, "quadratic_drag")
    report = _diagnose(tmp_path, target, steps=2, optimizer="random", calibration_runs=1,
                       calibration_control=False, fixed=("damping=0.05",), limits=False)
    assert report["settings"]["fixed"] == {"damping": 0.05}
    out = tmp_path / "diag-quadratic_drag"
    for stage in ("baseline", "calibration-0", "control", "effect-quadratic_drag"):
        assert json.loads((out / stage / "run.json").read_text())["fixed"] == {"damping": 0.05}, stage
        assert all("damping" not in t.params for t in RunDirectory(out / stage).read_trials()), stage
    model = read_model(out / "model.json")
    assert model.values["damping"] == 0.05 and model.extra["fixed"] == {"damping": 0.05}
    registry, _ = load_registry()
    refine(registry, plugin="pendulum_lab", model=out / "model.json", target_path=target, steps=1, optimizer="random",
           render_set={"size": 48}, noise_samples=0, floor_samples=0, out=tmp_path / "again", progress=False)
    assert json.loads((tmp_path / "again" / "run.json").read_text())["fixed"] == {"damping": 0.05}


@pytest.mark.slow
def test_hidden_drag_is_named_and_the_gap_shrinks(tmp_path: Path):
    report = _diagnose(tmp_path, _pendulum_target(tmp_path, "quadratic_drag"), steps=16, optimizer="ax")
    assert report["misspecified"]
    assert report["named_effect"] == "quadratic_drag"
    assert report["gap_after"] <= 0.5 * report["gap_before"]


@pytest.mark.slow
def test_no_effect_is_not_misspecified(tmp_path: Path):
    report = _diagnose(tmp_path, _pendulum_target(tmp_path, None), steps=16, optimizer="ax")
    assert not report["misspecified"]
    assert report["named_effect"] is None


def test_every_stage_proposes_its_trials_in_batches(tmp_path: Path, pendulum_batch_sizes):
    report = _diagnose(tmp_path, _pendulum_target(tmp_path, "quadratic_drag"), steps=5, optimizer="random",
                       batch_size=2, calibration_runs=1, calibration_control=False, ridge_starts=False, screen=False)
    assert report["settings"]["batch_size"] == 2
    # Per stage of 5 trials: batches of 2, 2 and a lone trial; the floors' batches hold 4 seeds.
    assert pendulum_batch_sizes.count(2) >= 2 * 3, pendulum_batch_sizes
    trials = (tmp_path / "diag-quadratic_drag" / "effect-quadratic_drag" / "trials.jsonl").read_text().splitlines()
    assert len(trials) == 5


def test_a_wide_video_is_framed_before_every_stage(tmp_path: Path):
    """As refine does: a target that is not square is cropped to the renderer's framing first."""
    from physinfer.video import read_video, write_video

    square = read_video(_pendulum_target(tmp_path, "quadratic_drag"))
    frames = square.frames
    wide = np.concatenate([np.repeat(frames[:, :, :1], 48, axis=2), frames, np.repeat(frames[:, :, -1:], 48, axis=2)],
                          axis=2)  # fmt: skip
    target = write_video(tmp_path / "wide.mp4", Clip(np.ascontiguousarray(wide), square.fps))
    from physinfer.conditioning import Conditioning

    report = _diagnose(tmp_path, target, steps=2, optimizer="random", calibration_runs=1, calibration_control=False,
                       limits=False, ridge_starts=False, screen=False, conditioning=Conditioning())  # fmt: skip
    prepared = report["target_conditions"]["prepared"]
    assert "skipped" not in prepared, prepared
    x, y, w, h = prepared["box"]
    assert 30 <= x + w / 2 <= 114, prepared  # around the pendulum, in the wide frame's pixels


def _pendulum_under_another_name():
    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    pendulum = registry.phenomenon("pendulum_lab")
    registry.scoped("test").add_phenomenon("pendulum_alias", lambda **_: pendulum, "the pendulum, renamed")
    return registry


def test_workers_find_the_effects_of_a_phenomenon_registered_under_another_name(tmp_path: Path):
    """bench_diagnose's flag_lite is the flag under another name: its effects are the flag's."""
    from physinfer.discrepancy.parallel import usable_workers
    from physinfer.discrepancy.settings import DiagnoseSettings

    settings = DiagnoseSettings(plugin="pendulum_alias", out=tmp_path, workers=2,
                                registry_factory=_pendulum_under_another_name)  # fmt: skip
    assert usable_workers(settings, 3, ["quadratic_drag"]) == (2, None)
    not_installed = DiagnoseSettings(plugin="pendulum_alias", out=tmp_path, workers=2)
    workers, why = usable_workers(not_installed, 3, ["quadratic_drag"])
    assert workers == 1 and "not installed" in why


def test_a_calibration_target_is_encoded_once_and_read_back(tmp_path: Path, monkeypatch):
    """The encoder does not repeat itself: a self-consistency target encoded again (the main
    process reading a worker's stage, a resumed diagnosis) gave its stage another embedding,
    whose resume was refused. It is encoded once and read back after; another θ re-encodes."""
    import physinfer.video as video
    from physinfer.discrepancy.stages import calibration_target
    from physinfer.evaluation import build_pipeline
    from physinfer.plugins import load_registry
    from physinfer.roles import Target

    registry, _ = load_registry()
    pipeline = build_pipeline(registry, "pendulum_lab", embedder="")
    target = Target(None, None, {"size": 48}, "test")
    theta = {"length": 1.0, "damping": 0.1, "amplitude": 40.0}
    writes = []
    write = video.write_video
    monkeypatch.setattr(video, "write_video", lambda *a, **k: writes.append(a[0]) or write(*a, **k))
    first = calibration_target(pipeline, theta, target, 7, tmp_path / "calibration-0")
    again = calibration_target(pipeline, theta, target, 7, tmp_path / "calibration-0")
    assert len(writes) == 1
    np.testing.assert_array_equal(first.clip.frames, again.clip.frames)
    assert again.clip.fps == first.clip.fps
    calibration_target(pipeline, {**theta, "length": 1.2}, target, 7, tmp_path / "calibration-0")
    assert len(writes) == 2
    pipeline.renderer.close()


def test_a_pool_starts_its_workers_with_their_model_before_the_first_round(tmp_path: Path):
    """The workers start while the baseline runs: each builds its model and an optimizer (a
    failure would only show in the first round's timing, so it is checked here)."""
    from physinfer.discrepancy.parallel import WorkerPool
    from physinfer.discrepancy.settings import DiagnoseSettings

    settings = DiagnoseSettings(plugin="pendulum_lab", out=tmp_path, workers=2, optimizer="ax")
    with WorkerPool(settings, ["quadratic_drag"], 3, print) as pool:
        warming = pool.warm_up()
        assert len(warming) == 2
        assert [f.result(timeout=300) for f in warming] == [None, None]
    alone = DiagnoseSettings(plugin="pendulum_lab", out=tmp_path, workers=1)
    with WorkerPool(alone, ["quadratic_drag"], 3, print) as pool:
        assert pool.warm_up() == [] and pool.size == 1


def test_the_baselines_resimulations_on_workers_are_this_process_own(tmp_path: Path):
    """The pooled clip embedder (the baseline's selection and gap) gives each clip's
    embedding as simulate_and_embed does here, failed simulations as None; with one worker
    there is none."""
    from physinfer.discrepancy.clip_jobs import pooled_clip_embedder
    from physinfer.discrepancy.parallel import WorkerPool
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.discrepancy.stages import build_base
    from physinfer.evaluation import simulate_and_embed
    from physinfer.plugins import load_registry

    settings = DiagnoseSettings(plugin="pendulum_lab", out=tmp_path, workers=2, optimizer="random")
    base = build_base(load_registry()[0], settings)
    zeta = {**base.renderer.default_render_params, "size": 32}
    theta = base.simulator.parameter_space.from_unit(np.zeros(len(base.simulator.parameter_space)))
    blown_up = {**theta, "length": float("nan")}
    said: list[str] = []
    with WorkerPool(settings, [], 3, said.append) as pool:
        embed = pooled_clip_embedder(pool, base, zeta, said.append)
        assert embed is not None
        there = embed([theta, theta, blown_up], [3, 4, 5])
    here = [simulate_and_embed(base, p, zeta, s)[0] for p, s in [(theta, 3), (theta, 4), (blown_up, 5)]]
    assert there[2] is None and here[2] is None and not said
    for a, b in zip(there[:2], here[:2], strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    with WorkerPool(DiagnoseSettings(plugin="pendulum_lab", out=tmp_path, workers=1), [], 3, print) as pool:
        assert pooled_clip_embedder(pool, base, zeta, print) is None
    base.renderer.close()


def test_the_batch_size_is_the_phenomenons_unless_given(tmp_path: Path):
    """The pendulum proposes two trials per GP fit in diagnose (its trials are mostly Ax's
    step), unless --batch-size says otherwise; the report records what ran."""
    target = _pendulum_target(tmp_path, "quadratic_drag")
    # Ridge starts and the screen are left out: what is checked is the batch each stage proposes.
    kw = {"steps": 3, "optimizer": "random", "calibrate": False, "limits": False, "ridge_starts": False, "screen": False}
    default = _diagnose(tmp_path / "default", target, **kw)
    assert default["settings"]["batch_size"] == 2
    one = _diagnose(tmp_path / "one", target, batch_size=1, **kw)
    assert one["settings"]["batch_size"] == 1
    with pytest.raises(UserInputError, match="--batch-size must be at least 1"):
        _diagnose(tmp_path / "zero", target, batch_size=0, **kw)


def test_a_name_whose_model_still_fails_the_gap_test_comes_with_a_warning():
    from physinfer.discrepancy.decide import remainder_after_naming
    from physinfer.report.diagnose_page import verdict

    # The power curves' case: gusts (screened out) stood in for by yaw, which left 353 > 181.
    leaves = remainder_after_naming("wind_yaw", 353.4, 180.9)
    assert leaves["effect"] == "wind_yaw" and leaves["gap"] == 353.4 and leaves["threshold"] == 180.9
    assert "still above the gap-test threshold 180.9" in leaves["message"]
    assert remainder_after_naming("wind_yaw", 17.4, 71.4) is None  # the named model passes
    assert remainder_after_naming(None, 353.4, 180.9) is None  # nothing named
    # No null scale measured (a deterministic phenomenon's threshold of 0): no warning from it.
    assert remainder_after_naming("quadratic_drag", 1.59, 0.0) is None
    page = verdict({"misspecified": True, "named_effect": "wind_yaw", "named_leaves": leaves})
    assert "named effect: wind_yaw" in page and "but wind_yaw leaves a gap of 353.4" in page
    assert "but " not in verdict({"misspecified": True, "named_effect": "wind_yaw", "named_leaves": None})
