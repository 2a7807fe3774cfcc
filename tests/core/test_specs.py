"""The refine command's specs (``physinfer.session``): each setting declared once, as a field
of one spec, and carried from the API's options and the command's keywords by its name."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from physinfer.api import RefineOptions
from physinfer.api import _refine_request as refine_request
from physinfer.refinement import SearchSpec
from physinfer.session import ExecutionSpec, ModelSpec, RefineRequest, TargetSpec

SPECS = (ModelSpec, TargetSpec, SearchSpec, ExecutionSpec)


def _names(kind: type) -> set[str]:
    return {f.name for f in dataclasses.fields(kind)}


def test_no_setting_is_declared_by_two_specs():
    names = [name for kind in SPECS for name in _names(kind)]
    assert len(names) == len(set(names))


def test_the_keywords_go_to_the_spec_that_declares_them():
    request = RefineRequest.from_keywords(
        plugin="pendulum_lab", out=Path("run"), model=Path("model.json"), fixed=["length=1"], truth=["length=1"],
        select_top=4, workers=2,
    )  # fmt: skip
    assert request.model.model_file == Path("model.json") and request.model.fixed == ("length=1",)
    assert request.target.truth == ("length=1",)
    assert request.search.select_top == 4 and request.execution.workers == 2
    with pytest.raises(TypeError, match="select_tpo"):
        RefineRequest.from_keywords(plugin="pendulum_lab", out=Path("run"), select_tpo=4)
    with pytest.raises(TypeError, match="out"):
        RefineRequest.from_keywords(plugin="pendulum_lab")


def test_the_loop_runs_the_search_record_itself_with_its_budget_resolved():
    class Phenomenon:
        default_steps, default_steps_with_posterior = 20, 8

    search = SearchSpec(optimizer="random", seed=7, select_top=3, batch_size=4)
    assert search.steps is None
    assert search.with_budget(Phenomenon, from_posterior=True) == dataclasses.replace(search, steps=8)
    assert search.with_budget(Phenomenon, from_posterior=False).steps == 20
    assert dataclasses.replace(search, steps=5).with_budget(Phenomenon, from_posterior=True).steps == 5
    # The command's options declare every search setting but the engine's own two.
    options = {f.name for f in dataclasses.fields(RefineOptions)}
    assert _names(SearchSpec) - options - {"use_posterior"} == {"noise_sem", "log_objective"}


def test_the_api_fills_every_spec_from_the_options():
    options = RefineOptions(
        effects=("quadratic_drag",), embedder="spectral", weights="w.safetensors", device="cpu",
        fix={"length": 1.0}, duration=4.0, embedder_frames=30, render_set={"size": 64},
        scene_set={"a": 1}, seed=3, target="v.mp4", fps=25.0, truth={"length": 1.0}, steps=8,
        optimizer="random", floor_samples=0, select_top=2, select_seeds=4, batch_size=2, out="run",
        resume=True, model="model.json", noise_samples=0, seeds_per_trial=2, workers=2,
        scheduler="tcp://x:1", posterior="p.safetensors", no_posterior=True, no_prepare=True,
    )  # fmt: skip
    request = refine_request("pendulum_lab", options)
    assert request.model == ModelSpec(
        "pendulum_lab", ("quadratic_drag",), "spectral", Path("w.safetensors"), "cpu", ("length=1.0",), 4.0, 30,
        {"a": 1}, Path("model.json"),
    )  # fmt: skip
    assert (request.target.target_path, request.target.fps, request.target.truth) == (Path("v.mp4"), 25.0, ("length=1.0",))
    assert request.target.render_set == {"size": 64} and request.target.conditioning.prepare is False
    assert request.search == SearchSpec(8, "random", 3, 0, 2, 0, 2, 4, 2, Path("p.safetensors"), False)
    assert request.execution == ExecutionSpec(Path("run"), True, False, 2, "tcp://x:1")
