"""A refinement's records: how it searches (:class:`SearchSpec`) and what it found
(:class:`RefineResult`), with what it reports beside the best fit in typed sections
(:class:`NoiseReport`, :class:`FitPlace`, :class:`TargetReport`, :class:`TargetPosterior`).

Below the loop (:mod:`physinfer.loop`), so that the loop, the commands and the diagnosis read
them from one place. ``RefineConfig``, the loop's settings before they became the search's one
record, is found here with a warning (:data:`physinfer.moved.MOVED`).
"""

from __future__ import annotations

import copy
import functools
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.evaluation import noise_seeds
from physinfer.moved import moved_names
from physinfer.plotting import refinement_figure
from physinfer.rundir import TrialRecord

__getattr__ = moved_names(__name__)


def default_budget(phenomenon: Any, steps: int | None, *, from_posterior: bool) -> int:
    """The trials of a refinement: ``steps`` when given; otherwise the phenomenon's default,
    or its ``default_steps_with_posterior`` when the search starts from a posterior estimator."""
    if steps is not None:
        return steps
    if from_posterior and phenomenon.default_steps_with_posterior is not None:
        return int(phenomenon.default_steps_with_posterior)
    return int(phenomenon.default_steps)


@dataclass(frozen=True)
class SearchSpec:
    """How a refinement searches: the budget, the optimizer, the noise handling, the final
    selection and the posterior estimator the search may start from.

    One record from the command to the loop: the refine command fills it from its options
    (its defaults are the command's), resolves the budget (:meth:`with_budget`) once it knows
    whether the search starts from a posterior, and the loop reads it. A diagnosis' stage
    gives every field it relies on.

    Attributes:
        steps: Total number of trials (including the centre trial and resumed ones);
            ``None``: :func:`default_budget`, resolved by the command before the loop runs.
        optimizer: Registered optimizer name.
        seed: Seed of the optimizer and of every simulation (so a θ maps to one clip).
        noise_samples: Before optimising, re-simulate the centre θ under this many extra
            seeds and tell the optimizer the spread of the objective as its standard error
            (0: do not measure). Ignored when ``noise_sem`` is given.
        seeds_per_trial: Average the distance of each trial over this many simulation
            seeds (the run seed first), trading steps for less noise per observation.
        floor_samples: After the run, re-simulate the best θ under this many seeds and
            report the noise floor and the gap in ``result.json`` (0: skip).
        select_top: After the run, re-simulate the best ``M`` trials (distinct θ) under
            ``select_seeds`` fresh seeds each and report the one with the lowest mean
            fresh distance as the best (0: the lowest logged distance; see
            :func:`physinfer.loop.select_best`).
        select_seeds: Fresh seeds per finalist of the selection.
        batch_size: Trials proposed per optimizer step and simulated as one batch (q);
            1 proposes, simulates and tells one trial at a time (the paper's loop).
        posterior: Posterior estimator file the command starts from (``None``: the
            phenomenon's shipped one).
        use_posterior: Use an estimator at all (``False``: a best fit only).
        noise_sem: Standard error of the objective told to the optimizer for every
            observation; ``None``: measured (``noise_samples`` > 0) or inferred by the
            optimizer.
        log_objective: Tell the optimizer ``log(D)`` instead of ``D``. The minimiser is the
            same, but the landscape is far smoother (distances span orders of magnitude),
            which suits a GP surrogate; results always report ``D`` itself.
    """

    steps: int | None = None
    optimizer: str = "ax"
    seed: int = 0
    noise_samples: int = 3
    seeds_per_trial: int = 1
    floor_samples: int = 4
    select_top: int = 0
    select_seeds: int = 3
    batch_size: int = 1
    posterior: Path | None = None
    use_posterior: bool = True
    noise_sem: float | None = None
    log_objective: bool = True

    def with_budget(self, phenomenon: Any, *, from_posterior: bool) -> SearchSpec:
        """This search with its budget resolved (:func:`default_budget`): what the loop runs."""
        return replace(self, steps=default_budget(phenomenon, self.steps, from_posterior=from_posterior))

    def objective(self, distance: float | None) -> float | None:
        """The value told to the optimizer for a distance (``None`` stays ``None``)."""
        if distance is None or not self.log_objective:
            return distance
        return float(np.log(distance + 1e-12))

    def validate(self) -> None:
        """Raise :class:`UserInputError` for a non-positive budget or a count out of range
        (``steps`` ``None``, not yet resolved, passes)."""
        if self.steps is not None and self.steps < 1:
            raise UserInputError(f"--steps must be at least 1, got {self.steps}")
        if self.seeds_per_trial < 1:
            raise UserInputError(f"--seeds-per-trial must be at least 1, got {self.seeds_per_trial}")
        if self.noise_samples < 0 or self.noise_samples == 1:
            raise UserInputError(f"--noise-samples must be 0 or at least 2, got {self.noise_samples}")
        if self.floor_samples < 0 or self.floor_samples == 1:
            raise UserInputError(f"--floor-samples must be 0 or at least 2, got {self.floor_samples}")
        if self.select_top < 0 or self.select_top == 1:
            raise UserInputError(f"--select-top must be 0 or at least 2, got {self.select_top}")
        if self.select_seeds < 1:
            raise UserInputError(f"--select-seeds must be at least 1, got {self.select_seeds}")
        if self.batch_size < 1:
            raise UserInputError(f"--batch-size must be at least 1, got {self.batch_size}")
        if self.noise_sem is not None and not self.noise_sem >= 0:
            raise UserInputError(f"the noise standard error must be non-negative, got {self.noise_sem}")

    def trial_seeds(self) -> list[int]:
        """The seeds every trial is simulated with (the run seed first)."""
        return [self.seed, *noise_seeds(self.seed, self.seeds_per_trial - 1)]


@dataclass(frozen=True)
class NoiseReport:
    """The target's noise as the refinement met it.

    Attributes:
        observation_sem: The standard error told to the optimizer with each distance
            (``result.json`` ``observation_sem``; ``None``: left to the optimizer).
        floor: The noise floor at the best fit: its re-simulations' distances, the gap and
            their ratio (``noise_floor``; ``None``: not measured, ``floor_samples`` 0).
    """

    observation_sem: float | None = None
    floor: dict[str, Any] | None = None


@dataclass(frozen=True)
class FitPlace:
    """Where the best fit lies in the parameter space.

    Attributes:
        at_bounds: The physical parameters on a bound of their range, and which bound
            (``at_bounds``).
        nuisance: The nuisance parameters' best values, reported apart from the physics
            (``nuisance``; empty: the phenomenon declares none).
    """

    at_bounds: dict[str, str] = field(default_factory=dict)
    nuisance: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class TargetReport:
    """What the refine command learnt of its target beside the clip.

    Attributes:
        scene: The resolved scene the model was built for (``scene``; ``None``: the default).
        conditions: What conditioning did to a user's video (``target_conditions``).
        video_estimate: What the video told directly, where the search started
            (``video_estimate``).
    """

    scene: dict[str, Any] | None = None
    conditions: dict[str, Any] | None = None
    video_estimate: dict[str, Any] | None = None


@dataclass(frozen=True)
class TargetPosterior:
    """The target's posterior reported beside the best fit, or why there is none.

    Attributes:
        marginals: Per parameter ``median``, ``ci50``, ``ci90`` and ``label``: the refined
            posterior when the trials give one, else the amortized one (``posterior``).
        correlations: Its strongest pairs ``[{a, b, r}]`` (``correlations``).
        amortized: The amortized posterior's marginals, to compare (``posterior_amortized``).
        source: Which of the two ``marginals`` is, the estimator, the search box
            (``posterior_source``).
        note: Why no estimator applied (``posterior_note``; then the others are ``None``).
    """

    marginals: dict[str, dict[str, Any]] | None = None
    correlations: list[dict[str, Any]] | None = None
    amortized: dict[str, dict[str, Any]] | None = None
    source: dict[str, Any] | None = None
    note: str | None = None


#: The fields :meth:`RefineResult.summary` writes first, in this order.
_BEST_FIT = (
    "best_params", "best_distance", "best_step", "ground_truth", "abs_errors", "n_trials", "n_failed",
    "wall_time_s", "timings", "run_dir",
)  # fmt: skip

#: ``result.json``'s keys beside the best fit, in the order a run has always written them,
#: each with where its value lives (``section attribute``, ``field`` or ``None`` for the
#: value itself) and when it is written: ``"always"`` (its section is there), ``"set"`` (the
#: value is not ``None``) or ``"non-empty"``. A key whose section is ``None`` is left out.
_REPORTED = (
    ("observation_sem", "noise", "observation_sem", "always"),
    ("nuisance", "place", "nuisance", "non-empty"),
    ("at_bounds", "place", "at_bounds", "always"),
    ("selection", "selection", None, "set"),
    ("noise_floor", "noise", "floor", "set"),
    ("adequacy", "adequacy", None, "set"),
    ("fixed", "fixed", None, "non-empty"),
    ("scene", "target", "scene", "set"),
    ("target_conditions", "target", "conditions", "non-empty"),
    ("video_estimate", "target", "video_estimate", "set"),
    ("executor", "executor", None, "set"),
    ("posterior", "target_posterior", "marginals", "set"),
    ("correlations", "target_posterior", "correlations", "set"),
    ("posterior_amortized", "target_posterior", "amortized", "set"),
    ("posterior_source", "target_posterior", "source", "set"),
    ("posterior_note", "target_posterior", "note", "set"),
    ("outputs", "outputs", None, "set"),
)


#: The sections that hold several of ``result.json``'s keys, by attribute.
_SECTIONS = {"noise": NoiseReport, "place": FitPlace, "target": TargetReport, "target_posterior": TargetPosterior}


def _warn_extra(spelling: str, stacklevel: int) -> None:
    warnings.warn(
        f"{spelling} is deprecated: a refinement's reports are typed sections now (result.noise, "
        ".place, .selection, .adequacy, .fixed, .target, .executor, .target_posterior, .outputs); "
        "result.to_dict() keys them as result.json does",
        DeprecationWarning,
        stacklevel=stacklevel,  # the line that reads or passes the old spelling
    )


def _extra(self: RefineResult) -> dict[str, Any]:
    """The reports beside the best fit as one dict keyed as in ``result.json`` (the old
    spelling: read the typed sections; a copy, so writing to it changes nothing)."""
    _warn_extra("RefineResult.extra", stacklevel=3)
    return self._reported()


def _old_extra_spelling(cls: type[RefineResult]) -> type[RefineResult]:
    """Keep the old ``extra`` for one release: ``RefineResult(..., extra={...})`` fills the
    sections from ``result.json``-style keys and ``result.extra`` reads them back, each with a
    :class:`DeprecationWarning`. (Set on the class, not declared in it: a field or ``InitVar``
    named ``extra`` would turn the property into a default, and ``dataclasses.replace`` would
    read it and warn.)"""
    init = cls.__init__

    @functools.wraps(init)
    def __init__(self: RefineResult, *args: Any, extra: Mapping[str, Any] | None = None, **kwargs: Any) -> None:
        init(self, *args, **kwargs)
        if extra:
            _warn_extra("RefineResult(extra=...)", stacklevel=3)
            self._take_reported(extra)

    cls.__init__ = __init__  # type: ignore[method-assign]
    cls.extra = property(_extra)  # type: ignore[attr-defined]
    return cls


@_old_extra_spelling
@dataclass
class RefineResult:
    """What a refinement found.

    The loop fills the best fit and its trials, the noise, the fit's place and the
    selection; the refine command adds the adequacy verdict, the held values, the target's
    report, the executor, the posterior and the files written. :meth:`to_dict` lays them
    out flat, as ``result.json`` has always had them; ``result.extra``, the old flat dict of
    them, still reads them for one release (with a :class:`DeprecationWarning`).

    Attributes:
        best_params: Physical values of the best trial.
        best_distance: Its distance.
        best_step: Its step.
        ground_truth: Truth of the target where known.
        abs_errors: ``|best - truth|`` per parameter where truth is known.
        n_trials: Trials logged (successful and failed).
        n_failed: Failed trials.
        wall_time_s: Wall time of this invocation.
        timings: Seconds summed over all trials per phase.
        run_dir: The run directory.
        trials: All trial records (not in the JSON summary).
        noise: The observation noise and the noise floor at the best fit.
        place: The best fit's parameters at a bound, and its nuisance values.
        selection: The finalists re-simulated under fresh seeds (``select_top``).
        adequacy: Whether the best fit reproduces the video (the refine command's verdict).
        fixed: The values ``--fix`` held, by parameter.
        target: The scene, the target's conditioning and what the video told directly.
        executor: Where the trials ran (``--workers``, ``--scheduler``).
        target_posterior: The target's posterior, or why there is none.
        outputs: The files the refine command wrote, by name.
    """

    best_params: dict[str, float]
    best_distance: float
    best_step: int
    ground_truth: dict[str, float] | None
    abs_errors: dict[str, float] | None
    n_trials: int
    n_failed: int
    wall_time_s: float
    timings: dict[str, float]
    run_dir: str
    trials: list[TrialRecord] = field(default_factory=list, repr=False)
    noise: NoiseReport | None = None
    place: FitPlace | None = None
    selection: dict[str, Any] | None = None
    adequacy: dict[str, Any] | None = None
    fixed: dict[str, float] | None = None
    target: TargetReport | None = None
    executor: dict[str, Any] | None = None
    target_posterior: TargetPosterior | None = None
    outputs: dict[str, str] | None = None

    def summary(self) -> dict[str, Any]:
        """The JSON-ready result (without the per-trial list)."""
        out = {name: getattr(self, name) for name in _BEST_FIT}
        out.update(self._reported())
        return copy.deepcopy(out)  # the caller's to change, as asdict's copy was

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer refine --json`` prints (``result.json``)."""
        return self.summary()

    @property
    def posterior(self) -> dict[str, dict[str, Any]]:
        """Per parameter: ``median``, ``ci50``, ``ci90`` and ``label`` (identified, weakly
        identified, not identified); ``{}`` when no posterior estimator applied."""
        found = self.target_posterior
        return dict((found.marginals if found is not None else None) or {})

    def plot(self, max_params: int = 17) -> Any:
        """Distance and every parameter against the step, with the 90 % intervals shaded and
        the truth dashed where known (a matplotlib figure; ``refinement.png`` is the same)."""
        return refinement_figure(self.trials, self.ground_truth, max_params=max_params, bands=self.posterior or None)

    def _reported(self) -> dict[str, Any]:
        """What is reported beside the best fit, keyed as in ``result.json``."""
        out: dict[str, Any] = {}
        for key, attribute, name, written in _REPORTED:
            section = getattr(self, attribute)
            if section is None:
                continue
            value = section if name is None else getattr(section, name)
            if written == "always" or (value if written == "non-empty" else value is not None):
                out[key] = value
        return out

    def _take_reported(self, reported: Mapping[str, Any]) -> None:
        """Fill the sections from ``result.json``-style keys (the old ``extra``)."""
        unknown = set(reported) - {key for key, *_ in _REPORTED}
        if unknown:
            raise TypeError(f"RefineResult has no section for {', '.join(sorted(unknown))}")
        sections: dict[str, dict[str, Any]] = {}
        for key, attribute, name, _ in _REPORTED:
            if key not in reported:
                continue
            if name is None:
                setattr(self, attribute, reported[key])
            else:
                sections.setdefault(attribute, {})[name] = reported[key]
        for attribute, values in sections.items():
            setattr(self, attribute, _SECTIONS[attribute](**values))

