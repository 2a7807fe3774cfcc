"""The path from ``physinfer refine`` to the simulator stays within the modules
docs/architecture.md counts (issue 47: at most 12 holding a concept)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))

from trace_command import NOT_CONCEPTS, trace  # noqa: E402

#: The modules holding the concepts of docs/architecture.md's refine table.
REFINE_CONCEPT_MODULES = {
    "physinfer.api.options", "physinfer.api", "physinfer.session", "physinfer.refinement",
    "physinfer.registry", "physinfer.roles", "physinfer.parameters", "physinfer.evaluation",
    "physinfer.target", "physinfer.rundir", "physinfer.loop", "physinfer.optimizers.ax",
}  # fmt: skip


@pytest.mark.slow  # 37 s: a whole refine under a profile hook
def test_refine_reaches_the_simulator_through_twelve_concept_modules(tmp_path: Path) -> None:
    found = trace(["refine", "--plugin", "pendulum_lab", "--steps", "2", "--out", str(tmp_path / "run")])
    assert found["reached"], "the trace never reached a trial's simulate"
    concepts = set(found["concept_modules"])
    # A module new on the path is either a concept of the table or classified in NOT_CONCEPTS.
    assert concepts == REFINE_CONCEPT_MODULES, sorted(concepts ^ REFINE_CONCEPT_MODULES)
    assert len(concepts) <= 12
    assert not set(NOT_CONCEPTS) & REFINE_CONCEPT_MODULES
