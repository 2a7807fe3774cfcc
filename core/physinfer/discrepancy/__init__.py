"""The discrepancy workflow (``physinfer diagnose``): where a refined simulation and the
measurement disagree, which registered effect the model is missing, and how much adding
it shrinks the gap. See ``docs/discrepancy.md`` and :func:`run_diagnosis`.

The names are imported on first use: importing any module of this package runs this face
first, and the engine's modules here (the model file, the warm start) must not bring the
diagnosis with them.
"""

from __future__ import annotations

from typing import Any

__all__ = ["DecisionRule", "DiagnoseSettings", "LocaliseConfig", "read_model", "run_diagnosis"]


def __getattr__(name: str) -> Any:
    if name == "DiagnoseSettings":
        from physinfer.discrepancy.settings import DiagnoseSettings

        return DiagnoseSettings
    if name == "run_diagnosis":
        from physinfer.discrepancy.workflow import run_diagnosis

        return run_diagnosis
    if name == "DecisionRule":
        from physinfer.discrepancy.decide import DecisionRule

        return DecisionRule
    if name == "LocaliseConfig":
        from physinfer.discrepancy.localise import LocaliseConfig

        return LocaliseConfig
    if name == "read_model":
        from physinfer.discrepancy.model import read_model

        return read_model
    raise AttributeError(name)
