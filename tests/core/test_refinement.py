"""A refinement's result: typed sections, laid out flat as ``result.json`` has always had them."""

from __future__ import annotations

import dataclasses
import json
import warnings

import pytest

from physinfer.refinement import FitPlace, NoiseReport, RefineResult, TargetPosterior, TargetReport

BEST_FIT = dict(
    best_params={"length": 1.2, "phase": 0.3}, best_distance=0.02, best_step=3, ground_truth=None,
    abs_errors=None, n_trials=8, n_failed=0, wall_time_s=1.5, timings={"simulate_s": 0.1}, run_dir="runs/x",
)  # fmt: skip


def full_result() -> RefineResult:
    return RefineResult(
        **BEST_FIT,
        noise=NoiseReport(observation_sem=0.01, floor={"floor": 0.002, "ratio": 1.1}),
        place=FitPlace(at_bounds={"length": "upper"}, nuisance={"phase": 0.3}),
        selection={"chosen_step": 3},
        adequacy={"reproduces": True},
        fixed={"damping": 0.05},
        target=TargetReport(scene={"pinning": "hoist"}, conditions={"prepared": {}}, video_estimate={"period": 2.0}),
        executor={"kind": "inline"},
        target_posterior=TargetPosterior(
            marginals={"length": {"median": 1.2}}, correlations=[], amortized={"length": {"median": 1.1}},
            source={"kind": "refined"},
        ),
        outputs={"result.json": "runs/x/result.json"},
    )  # fmt: skip


def test_to_dict_keys_the_sections_in_the_order_runs_wrote_them():
    result = full_result()
    out = result.to_dict()
    assert list(out) == [
        *BEST_FIT, "observation_sem", "nuisance", "at_bounds", "selection", "noise_floor", "adequacy", "fixed",
        "scene", "target_conditions", "video_estimate", "executor", "posterior", "correlations",
        "posterior_amortized", "posterior_source", "outputs",
    ]  # fmt: skip
    assert out["noise_floor"] == {"floor": 0.002, "ratio": 1.1} and out["posterior_source"] == {"kind": "refined"}
    json.dumps(out)
    # A copy: changing it changes nothing in the result.
    out["at_bounds"]["length"] = "lower"
    assert result.place.at_bounds == {"length": "upper"}


def test_a_section_not_measured_leaves_its_keys_out():
    result = RefineResult(
        **BEST_FIT, noise=NoiseReport(observation_sem=None), place=FitPlace(at_bounds={}),
        fixed={}, target=TargetReport(scene=None, conditions={}), target_posterior=TargetPosterior(note="no estimator"),
    )  # fmt: skip
    out = result.to_dict()
    # As the loop wrote them: observation_sem and at_bounds always, an empty nuisance never.
    assert list(out)[len(BEST_FIT) :] == ["observation_sem", "at_bounds", "posterior_note"]
    assert out["observation_sem"] is None and out["at_bounds"] == {}
    assert result.posterior == {} and RefineResult(**BEST_FIT).to_dict() == BEST_FIT


def test_the_old_extra_still_reads_and_fills_the_sections_with_a_warning():
    result = full_result()
    with pytest.warns(DeprecationWarning, match=r"RefineResult.extra is deprecated.*result.noise"):
        extra = result.extra
    assert extra == {k: v for k, v in result.to_dict().items() if k not in BEST_FIT}
    with pytest.warns(DeprecationWarning, match=r"RefineResult\(extra=...\) is deprecated"):
        again = RefineResult(**BEST_FIT, extra=extra)
    assert again.to_dict() == result.to_dict() and again.target_posterior == result.target_posterior
    with pytest.raises(TypeError, match="no section for bogus"), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        RefineResult(**BEST_FIT, extra={"bogus": 1})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # copying a result does not read the old spelling
        moved = dataclasses.replace(result, best_step=4)
    assert moved.to_dict() == {**result.to_dict(), "best_step": 4}
