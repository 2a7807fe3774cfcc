"""Augmented models: the baseline with one effect switched in, warm-started from its fit.

An effect's parameters are *off* at their declared default, or — when a parameter
declares none — at its low bound (the :class:`~physinfer.roles.Effect` convention). The
warm start of an augmented model is therefore the baseline's best θ plus the effect's
parameters off: its first trial reproduces the baseline fit.
"""

from __future__ import annotations

from collections.abc import Mapping

from physinfer.evaluation import Pipeline, make_simulator
from physinfer.fixed import FixedParameters
from physinfer.parameters import ParameterSpace
from physinfer.roles import Effect


def off_values(space: ParameterSpace) -> dict[str, float]:
    """Each effect parameter at its "off" value: the declared default, else the low bound."""
    return {s.name: float(s.default) if s.default is not None else float(s.bounds[0]) for s in space}


def augmented_pipeline(
    base: Pipeline, effects: list[Effect], duration_s: float | None = None, fixed: Mapping[str, float] | None = None
) -> Pipeline:
    """The baseline's renderer and embedder with a simulator that has ``effects`` switched in.

    ``duration_s`` and ``fixed`` must be the baseline's (its clip length, ``None`` for the
    phenomenon's default, and the values ``--fix`` holds), so that both models are compared
    on the same clips with the same known values.
    """
    simulator = make_simulator(base.phenomenon, effects, duration_s)
    if fixed:
        simulator = FixedParameters(simulator, fixed)
    return Pipeline(base.phenomenon, simulator, base.renderer, base.embedder, list(effects))


def warm_start(baseline_best: Mapping[str, float], effects: list[Effect]) -> dict[str, float]:
    """The baseline's best θ with every effect parameter off."""
    start = dict(baseline_best)
    for effect in effects:
        start.update(off_values(effect.parameter_space))
    return start
