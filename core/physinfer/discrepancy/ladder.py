"""The detection-limit ladder: an effect switched on at a few strengths at θ̂, and its distances.

Part of :mod:`physinfer.discrepancy.limits` (the method is described there). This module holds
what the ladder is given (:class:`LimitInputs`, which the reveal reads too) and measures: which effect parameters a ladder moves (:func:`strength_path`),
simulating and embedding at the target's ζ (:class:`Probe`), the rungs themselves
(:func:`run_ladder`) and the two distance summaries every decision reads — the median distance
between two sets of clips (:func:`cross_median`) and within one (:func:`pairwise_median`, a
noise floor).

Multi-parameter effects: the ladder moves the parameters whose *off* value lies on a bound
(magnitudes, e.g. a gust intensity) and holds those with an interior default at it (shapes,
e.g. the gusts' time scale, 1 s); when none lies on a bound, all move.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from physinfer import video
from physinfer.discrepancy.decide import DecisionRule
from physinfer.evaluation import Pipeline, noise_seeds, simulate_many, squared_distance
from physinfer.parameters import ParameterSpace


def strength_path(space: ParameterSpace) -> tuple[dict[str, tuple[float, float]], dict[str, float]]:
    """Which parameters a ladder moves, from where to where (normalised), and which it holds.

    Returns:
        ``moved`` (name → (off, on) in ``[-1, 1]``: off is the declared default or the low
        bound, on the bound farthest from it) and ``held`` (name → physical off value).
    """
    ends = {}
    for spec in space:
        off = float(spec.default) if spec.default is not None else float(spec.bounds[0])
        u_off = float(spec.to_unit(off))
        ends[spec.name] = (u_off, -1.0 if u_off > 0 else 1.0, off)
    on_bound = [n for n, (u, _, _) in ends.items() if abs(abs(u) - 1.0) < 1e-9]
    moving = on_bound or list(ends)
    moved = {n: (ends[n][0], ends[n][1]) for n in moving}
    held = {n: ends[n][2] for n in ends if n not in moving}
    return moved, held


def values_at(
    space: ParameterSpace,
    moved: Mapping[str, tuple[float, float]],
    held: Mapping[str, float],
    fraction: float,
) -> dict[str, float]:
    """The effect's physical parameters ``fraction`` of the way along its path."""
    values = dict(held)
    for name, (u_off, u_on) in moved.items():
        values[name] = float(space[name].from_unit(u_off + fraction * (u_on - u_off)))
    return values


def moved_values(effect_space: ParameterSpace, fraction: float) -> dict[str, float]:
    """The moved parameters' values ``fraction`` of the way along the path (``detectable_from``)."""
    moved, held = strength_path(effect_space)
    return {k: v for k, v in values_at(effect_space, moved, held, fraction).items() if k in moved}


class Probe:
    """Simulate (batched), render and embed at the target's ζ; counts its simulations.

    :meth:`clips` is what the ladders and refits call; a pooled probe
    (:class:`~physinfer.discrepancy.clip_jobs.PooledProbe`) runs it on the diagnosis'
    workers instead, one clip per job.
    """

    def __init__(self, base: Pipeline, render_params: Mapping[str, Any]) -> None:
        self.base = base
        self.render_params = dict(render_params)
        self.simulations = 0
        #: Seconds a simulated clip records (``None`` until one succeeds).
        self.clip_seconds: float | None = None

    def clips(
        self, model: Pipeline, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
    ) -> tuple[np.ndarray, list[Any]]:
        """``model``'s clips of ``params[j]`` under ``seeds[j]``, embedded at ζ: ``(N, D)``
        embeddings (a row of NaN for a failed simulation) and the trajectories."""
        trajectories = self.trajectories(model.simulator, params, seeds)
        return self.embed(trajectories), trajectories

    def trajectories(
        self, simulator: Any, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
    ) -> list[Any]:
        """One batch through the simulator's engine (``None`` for a failed simulation)."""
        self.simulations += len(params)
        trajectories = [t for t, _ in simulate_many(simulator, list(params), [int(s) for s in seeds])]
        if self.clip_seconds is None:
            self.clip_seconds = next((t.duration for t in trajectories if t is not None), None)
        return trajectories

    def embed(
        self,
        trajectories: Sequence[Any],
        render_params: Mapping[str, Any] | None = None,
        embedder: Any = None,
        *,
        encoded: bool = False,
    ) -> np.ndarray:
        """``(N, D)`` embeddings (a row of NaN for a failed simulation); ``encoded``: each
        clip through the video encoder and back first (:func:`physinfer.video.round_trip`)."""
        zeta = self.render_params if render_params is None else render_params
        embedder = embedder or self.base.embedder

        def clip(traj: Any) -> Any:
            rendered = self.base.renderer.render(traj, zeta)
            return video.round_trip(rendered) if encoded else rendered

        return stack_rows(
            [None if traj is None else np.asarray(embedder.embed(clip(traj)), dtype=np.float64) for traj in trajectories]
        )

    def encoded_clips(
        self, model: Pipeline, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
    ) -> tuple[np.ndarray, list[Any]]:
        """As :meth:`clips`, here, each clip through the video encoder and back before it is
        embedded (:func:`physinfer.video.round_trip`): a rung that stands for a target read
        from a file."""
        trajectories = self.trajectories(model.simulator, params, seeds)
        return self.embed(trajectories, encoded=True), trajectories


#: Makes a probe whose clips run on the diagnosis' workers, one job per clip
#: (:class:`~physinfer.discrepancy.clip_jobs.PooledProbe`); its argument: keep the trajectories.
ProbeFactory = Callable[[bool], Probe]


@dataclass
class LimitInputs:
    """What the ladder needs from the diagnosis.

    Attributes:
        base: The baseline pipeline (its simulator holds ``--fix`` values).
        augmented: Effect name → the baseline with that effect switched in.
        theta: θ̂, the best baseline fit (base parameters).
        base_embeddings: ``(K, D_e)`` θ̂'s re-simulations from the gap measurement (reused).
        render_params: The target's ζ.
        scale: The null scale ``S``.
        scale_low: The lower end of its range when the diagnosis knows it only as a range
            (``scale`` is then the upper end), else ``None``.
        rule: The decision rule.
        floor_samples: ``K``.
        seed: The diagnosis seed (the ladder's seeds are derived from it).
        diagnosis_simulations: Simulations the diagnosis cost (for the budget).
        n_candidates: Candidates the rule counts when some are not in ``augmented`` (screened
            out: :mod:`physinfer.discrepancy.screen`); ``None``: those in ``augmented``.
        encoded: The target came from a file: a deterministic baseline's rungs make the round
            trip through the video encoder that a self-consistency target makes, since the
            codec's distance is then the floor of every gap the diagnosis measures.
        make_longer: ``None``, or a factory that, given the current clip's seconds, returns
            ``(base simulator, {effect: simulator}, embedder)`` recording twice as long (the
            longer-clip what-if); it raises :class:`UserInputError` where the phenomenon
            records a fixed length.
    """

    base: Pipeline
    augmented: Mapping[str, Pipeline]
    theta: Mapping[str, float]
    base_embeddings: np.ndarray
    render_params: Mapping[str, Any]
    scale: float
    rule: DecisionRule
    floor_samples: int
    seed: int
    diagnosis_simulations: int
    make_longer: Callable[[float], tuple[Any, dict[str, Any], Any]] | None = None
    scale_low: float | None = None
    encoded: bool = False
    n_candidates: int | None = None

    @property
    def candidates(self) -> int:
        """The candidates the rule counts: ``n_candidates``, or those in ``augmented``."""
        return len(self.augmented) if self.n_candidates is None else self.n_candidates


def stack_rows(rows: Sequence[np.ndarray | None]) -> np.ndarray:
    """``(N, D)`` from embeddings, a row of NaN for each ``None`` (a failed simulation)."""
    width = next((r.size for r in rows if r is not None), 0)
    return (
        np.stack([np.full(width, np.nan) if r is None else r for r in rows])
        if rows
        else np.zeros((0, 0))
    )


def cross_median(a: np.ndarray, b: np.ndarray) -> float:
    """Median squared distance between the rows of ``a`` and those of ``b`` (failed rows skipped)."""
    a, b = a[np.isfinite(a).all(axis=1)], b[np.isfinite(b).all(axis=1)]
    if len(a) == 0 or len(b) == 0:
        return float("nan")
    return float(np.median([squared_distance(x, y) for x in a for y in b]))


def pairwise(a: np.ndarray) -> list[float]:
    """Squared distances among the rows of ``a`` (failed rows skipped), each pair once."""
    a = a[np.isfinite(a).all(axis=1)]
    return [squared_distance(a[i], a[j]) for i in range(len(a)) for j in range(i + 1, len(a))]


def pairwise_median(a: np.ndarray) -> float:
    """Median squared distance among the rows of ``a`` (the noise floor of one θ)."""
    values = pairwise(a)
    return float(np.median(values)) if values else 0.0


@dataclass
class Ladder:
    """The simulations of one effect's ladder at θ̂ (everything a limit is computed from)."""

    fractions: list[float]
    values: list[dict[str, float]]
    embeddings: list[np.ndarray]  # per rung (n, D_e)
    trajectories: list[list[Any]]


def run_ladder(
    probe: Probe,
    augmented: Pipeline,
    theta: Mapping[str, float],
    effect_space: ParameterSpace,
    fractions: Sequence[float],
    seeds: Sequence[int],
    encoded: bool = False,
) -> Ladder:
    """Simulate every rung under ``seeds`` in one batch (``encoded``: each clip through the
    video encoder and back, here: :meth:`Probe.encoded_clips`)."""
    moved, held = strength_path(effect_space)
    values = [values_at(effect_space, moved, held, f) for f in fractions]
    jobs = [{**theta, **v} for v in values for _ in seeds]
    clips = probe.encoded_clips if encoded else probe.clips
    embeddings, trajs = clips(augmented, jobs, list(seeds) * len(values))
    n = len(seeds)
    rungs = range(len(values))
    return Ladder(list(fractions), values, [embeddings[i * n : (i + 1) * n] for i in rungs],
                  [trajs[i * n : (i + 1) * n] for i in rungs])  # fmt: skip


def ladder_seeds(seed: int, n: int) -> list[int]:
    """Seeds of the ladder, apart from the diagnosis's trial and re-simulation seeds."""
    return noise_seeds(seed + 11, n, salt=0x11D)
