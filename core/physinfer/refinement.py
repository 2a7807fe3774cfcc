"""A refinement's records: its settings (:class:`RefineConfig`) and what it found
(:class:`RefineResult`).

Below the loop (:mod:`physinfer.loop`, which re-exports them) and its re-simulations
(:mod:`physinfer.resimulation`), so that both, the commands and the diagnosis read them
from one place.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.noise import noise_seeds
from physinfer.plotting import refinement_figure
from physinfer.rundir import TrialRecord


@dataclass(frozen=True)
class RefineConfig:
    """Settings of one refinement.

    Attributes:
        steps: Total number of trials (including the centre trial and resumed ones).
        optimizer: Registered optimizer name.
        seed: Seed of the optimizer and of every simulation (so a θ maps to one clip).
        noise_sem: Standard error of the objective told to the optimizer for every
            observation; ``None``: measured (``noise_samples`` > 0) or inferred by the
            optimizer.
        noise_samples: Before optimising, re-simulate the centre θ under this many extra
            seeds and tell the optimizer the spread of the objective as its standard error
            (0: do not measure). Ignored when ``noise_sem`` is given.
        seeds_per_trial: Average the distance of each trial over this many simulation
            seeds (the run seed first), trading steps for less noise per observation.
        floor_samples: After the run, re-simulate the best θ under this many seeds and
            report the noise floor and the gap in ``result.json`` (0: skip).
        log_objective: Tell the optimizer ``log(D)`` instead of ``D``. The minimiser is the
            same, but the landscape is far smoother (distances span orders of magnitude),
            which suits a GP surrogate; results always report ``D`` itself.
        select_top: After the run, re-simulate the best ``M`` trials (distinct θ) under
            ``select_seeds`` fresh seeds each and report the one with the lowest mean
            fresh distance as the best (0: the lowest logged distance; see
            :func:`physinfer.resimulation.select_best`).
        select_seeds: Fresh seeds per finalist of the selection.
        batch_size: Trials proposed per optimizer step and simulated as one batch (q);
            1 proposes, simulates and tells one trial at a time (the paper's loop).
    """

    steps: int = 40
    optimizer: str = "ax"
    seed: int = 0
    noise_sem: float | None = None
    noise_samples: int = 0
    seeds_per_trial: int = 1
    floor_samples: int = 0
    log_objective: bool = True
    select_top: int = 0
    select_seeds: int = 3
    batch_size: int = 1

    def objective(self, distance: float | None) -> float | None:
        """The value told to the optimizer for a distance (``None`` stays ``None``)."""
        if distance is None or not self.log_objective:
            return distance
        return float(np.log(distance + 1e-12))

    def validate(self) -> None:
        """Raise :class:`UserInputError` for a non-positive budget."""
        if self.steps < 1:
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


@dataclass
class RefineResult:
    """What a refinement found.

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
    extra: dict[str, Any] = field(default_factory=dict)
    trials: list[TrialRecord] = field(default_factory=list, repr=False)

    def summary(self) -> dict[str, Any]:
        """The JSON-ready result (without the per-trial list)."""
        out = asdict(self)
        out.pop("trials")
        out.update(out.pop("extra"))
        return out

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer refine --json`` prints (``result.json``)."""
        return self.summary()

    @property
    def posterior(self) -> dict[str, dict[str, Any]]:
        """Per parameter: ``median``, ``ci50``, ``ci90`` and ``label`` (identified, weakly
        identified, not identified); ``{}`` when no posterior estimator applied."""
        return dict(self.extra.get("posterior") or {})

    def plot(self, max_params: int = 17) -> Any:
        """Distance and every parameter against the step, with the 90 % intervals shaded and
        the truth dashed where known (a matplotlib figure; ``refinement.png`` is the same)."""
        return refinement_figure(self.trials, self.ground_truth, max_params=max_params, bands=self.posterior or None)
