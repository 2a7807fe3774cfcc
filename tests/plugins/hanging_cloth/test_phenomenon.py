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
