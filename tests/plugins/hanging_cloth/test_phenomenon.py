"""The hanging_cloth phenomenon through the registry: contract checks and its default target."""

from __future__ import annotations

from physinfer.testing import check_phenomenon
from physinfer_hanging_cloth.phenomenon import DEFAULT_TRUTH


def test_registered_with_its_parts(physinfer_registry):
    phenomenon = physinfer_registry.phenomenon("hanging_cloth")
    assert phenomenon.name == "hanging_cloth"
    assert phenomenon.parameter_space.names == ["bending_multiplier", "area_weight"]
    assert phenomenon.default_embedder == "spectral"
    assert physinfer_registry.get("embedders", phenomenon.default_embedder)
    assert set(physinfer_registry.by_plugin("hanging_cloth")["commands"]) == {"evaluate bouman", "dataset bouman"}


def test_contract_and_default_target(physinfer_registry):
    phenomenon = physinfer_registry.phenomenon("hanging_cloth")
    embedder = physinfer_registry.embedder("spectral", model=None, device="cpu")
    check_phenomenon(phenomenon, embedder)
    target = phenomenon.default_target()
    assert target.truth == DEFAULT_TRUTH
    assert target.clip.n_frames >= embedder.n_frames


def test_records_as_long_as_a_dataset_or_simulate_asks(physinfer_registry):
    """``dataset generate`` with its default 60-frame clips asks the simulator for 2.4 s; the
    default clip stays 32 frames (the embedded target and Bouman's protocol)."""
    phenomenon = physinfer_registry.phenomenon("hanging_cloth")
    assert phenomenon.make_simulator().config.n_frames == 32
    assert phenomenon.make_simulator(duration_s=60 / 25).config.n_frames == 60
    scene = {"cloth_width": 0.5, "cloth_height": 0.7, "fan": "W3"}
    config = phenomenon.make_simulator(duration_s=3.0, scene=scene).config
    assert (config.n_frames, config.width, config.height, config.fan_level) == (75, 0.5, 0.7, "W3")


def test_its_shipped_estimator_answers_infer_on_the_default_target(physinfer_registry, tmp_path):
    """The shipped estimator loads for this phenomenon and scene, and its 90 % interval of the
    area weight holds the embedded target's truth (the bending is not identified by 1.3 s)."""
    from pathlib import Path

    from physinfer.posterior.estimator import PosteriorEstimator
    from physinfer.posterior.infer_workflow import infer

    phenomenon = physinfer_registry.phenomenon("hanging_cloth")
    estimator = PosteriorEstimator.load(Path(phenomenon.default_posterior))
    estimator.check_for("hanging_cloth", phenomenon.parameter_space)
    estimator.check_scene(phenomenon, None)
    assert estimator.config.targets and estimator.config.targets["as_given"]  # trained as users give videos
    report = infer(physinfer_registry, plugin="hanging_cloth", out=tmp_path / "infer", n_samples=500, check=False)
    low, high = report.marginals["area_weight"]["ci90"]
    assert low <= DEFAULT_TRUTH["area_weight"] <= high
