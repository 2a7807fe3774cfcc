"""The refine command's specs (``physinfer.specs``): each setting declared once, as a field
of one spec, and carried from the API's options and the command's keywords by its name."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from physinfer.api import RefineOptions
from physinfer.api import _refine_request as refine_request
from physinfer.refinement import RefineConfig
from physinfer.specs import ExecutionSpec, ModelSpec, RefineRequest, SearchSpec, TargetSpec

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


def test_the_loop_takes_every_search_setting_it_has_by_name():
    search = SearchSpec(optimizer="random", seed=7, noise_samples=0, seeds_per_trial=2, floor_samples=0,
                        select_top=3, select_seeds=5, batch_size=4)  # fmt: skip
    shared = (_names(RefineConfig) & _names(SearchSpec)) - {"steps"}
    assert shared == {"optimizer", "seed", "noise_samples", "seeds_per_trial", "floor_samples", "select_top",
                      "select_seeds", "batch_size"}  # fmt: skip
    assert search.config(9) == RefineConfig(steps=9, **{name: getattr(search, name) for name in shared})


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
