"""Names that moved to another module, found at their old path with a warning.

Code written before a name moved keeps working: the old module's ``__getattr__`` (PEP 562,
called only for a name the module does not hold) looks the old path up in :data:`MOVED`,
warns with a :class:`DeprecationWarning` that names the new path, and returns the object
itself, so ``isinstance``, ``is`` and pickles see one class. Python's default filters show
the warning once per place that uses the old path (and hide it outside ``__main__`` and test
runs). A plugin keeps its own map and passes it to :func:`moved_names`.

Inside physinfer every name is imported from the module that defines it
(``tests/core/test_moved_names.py`` holds that and checks every entry here).
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any


def _entries(old: str, new: str, names: str) -> dict[str, str]:
    return {f"{old}.{name}": f"{new}.{name}" for name in names.split()}


#: Old path → new path of every name that moved out of a module still imported by its old
#: path (issue 47: records and helpers moved below the code that uses them).
MOVED: Mapping[str, str] = MappingProxyType({
    **_entries("physinfer.loop", "physinfer.evaluation",
               "NON_FINITE NON_FINITE_DISTANCE ClipEmbedder Pipeline evaluate_mean make_clips "
               "simulate_and_embed simulate_many simulate_one"),
    **_entries("physinfer.resimulation", "physinfer.loop",
               "SELECTION_SEED_SALT final_noise_floor observation_noise select_best"),
    **_entries("physinfer.loop", "physinfer.rundir", "RunDirectory"),
    "physinfer.loop.RefineConfig": "physinfer.refinement.SearchSpec",
    "physinfer.refinement.RefineConfig": "physinfer.refinement.SearchSpec",
    **_entries("physinfer.pipeline", "physinfer.evaluation",
               "EffectParameterError build_pipeline effect_parameters fixed_by_user full_parameter_space "
               "make_simulator naming_effects target_duration"),
    **_entries("physinfer.noise", "physinfer.evaluation",
               "DEFAULT_SEED_SALT NoiseFloor measure_noise_floor noise_seeds"),
    **_entries("physinfer.session", "physinfer.evaluation",
               "EffectParameterError effect_parameters make_simulator"),
    **_entries("physinfer.session", "physinfer.refinement", "default_budget"),
    **_entries("physinfer.specs", "physinfer.refinement", "default_budget"),
    **_entries("physinfer.specs", "physinfer.session", "ExecutionSpec ModelSpec RefineRequest TargetSpec"),
    **_entries("physinfer.video", "physinfer.target",
               "STATIC_LEVELS TARGET_MAX_BYTES TARGET_MAX_SIDE TARGET_MIN_SIDE check_motion read_target_video"),
    **_entries("physinfer.discrepancy.workflow", "physinfer.discrepancy.settings", "DiagnoseSettings"),
    **_entries("physinfer.discrepancy.workflow", "physinfer.discrepancy.stages", "Stage calibration_seeds"),
    **_entries("physinfer.discrepancy.limits", "physinfer.discrepancy.settings", "LimitConfig"),
    **_entries("physinfer.discrepancy.limits", "physinfer.discrepancy.ladder",
               "LimitInputs ProbeFactory strength_path values_at"),
    **_entries("physinfer.discrepancy.limits", "physinfer.discrepancy.limit_rule",
               "interpolate_limit required_gap"),
    **_entries("physinfer.discrepancy.limits", "physinfer.discrepancy.limit_text", "limit_line reveal_phrase"),
    **_entries("physinfer.discrepancy.needed_calibration", "physinfer.discrepancy.self_consistency",
               "Signature limits_scale_note next_to_refine null_scale_words scale_bounds settled"),
    "physinfer.discrepancy.needed_calibration.CalibrationRun": "physinfer.discrepancy.self_consistency.SelfConsistencyRun",
    **_entries("physinfer.discrepancy.calibration_stage", "physinfer.discrepancy.self_consistency",
               "Judge limit_scale one_round_of_controls scale_text with_idle_controls"),
    "physinfer.discrepancy.calibration_stage.calibrate": "physinfer.discrepancy.self_consistency.run_self_consistency",
    "physinfer.discrepancy.calibration_stage.first_calibration_jobs":
        "physinfer.discrepancy.self_consistency.first_self_consistency_jobs",
    **_entries("physinfer.datasets.engine", "physinfer.datasets.resume", "GenerateProgress"),
    **_entries("physinfer.datasets.engine", "physinfer.datasets.executors", "default_workers"),
    **_entries("physinfer.posterior.estimator", "physinfer.posterior.flows", "EDGE FlowEnsemble to_unbounded"),
})  # fmt: skip


def moved_names(module: str, moved: Mapping[str, str] = MOVED) -> Callable[[str], Any]:
    """The ``__getattr__`` of the old module ``module``: ``__getattr__ = moved_names(__name__)``.

    Args:
        module: The old module's dotted name.
        moved: Old path → new path (``"package.old.Name"`` → ``"package.new.Name"``).

    Returns:
        A function that returns a moved name's object (warning once per place that asks) and
        raises :class:`AttributeError` for any other name, as a module without it would.
    """
    prefix = f"{module}."

    def __getattr__(name: str) -> Any:
        new = moved.get(prefix + name)
        if new is None:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        warnings.warn(
            f"{prefix}{name} moved to {new}: import it from {new.rpartition('.')[0]}",
            DeprecationWarning,
            stacklevel=2,  # the line that imports or reads the old path
        )
        return resolve(new)

    return __getattr__


def resolve(path: str) -> Any:
    """The object at a dotted ``path`` (``"package.module.Name"``), importing its module."""
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)
