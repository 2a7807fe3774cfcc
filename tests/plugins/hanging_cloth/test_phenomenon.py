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
