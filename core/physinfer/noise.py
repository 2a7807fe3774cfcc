"""How far apart two realisations of the same θ are: the noise floor of the distance.

Many phenomena are chaotic or stochastic (a flag in the wind is both): simulating one θ
under another seed gives another clip, and so another embedding. A distance between a
target and a simulation is therefore only meaningful against the spread of distances
between re-simulations of one θ. :func:`measure_noise_floor` re-simulates θ under ``K``
seeds (each with its own render parameters if given), embeds every clip and returns the
pairwise distances among them and, when a target embedding is given, the distance from
each to the target. The refinement uses it twice: before optimising, to tell the optimizer
the observation noise, and after, to report how close the best fit is to the floor; the
discrepancy workflow uses it as its posterior-predictive check.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from physinfer.errors import SimulationFailed
from physinfer.evaluation import ClipEmbedder, Pipeline, simulate_many, squared_distance

#: Salt of :func:`noise_seeds` unless another is given.
DEFAULT_SEED_SALT = 0x5EED


def noise_seeds(base_seed: int, n: int, *, salt: int = DEFAULT_SEED_SALT) -> list[int]:
    """``n`` distinct seeds derived from ``base_seed``, none equal to it.

    Re-simulation seeds must differ from the seed every trial of a refinement uses, or the
    "re-simulation" would repeat the trial's own clip. Another ``salt`` gives another,
    independent set (for re-simulations whose seeds must not repeat those of others).
    """
    if n <= 0:
        return []
    state = np.random.SeedSequence([int(base_seed), int(salt)]).generate_state(4 * n + 4, dtype=np.uint32)
    seeds: list[int] = []
    for value in (int(v) % (2**31 - 1) for v in state):
        if value != base_seed and value not in seeds:
            seeds.append(value)
        if len(seeds) == n:
            break
    return seeds


@dataclass
class NoiseFloor:
    """Distances among re-simulations of one θ, and from each to a target.

    Attributes:
        params: The θ re-simulated (physical values by name).
        seeds: The seeds of the successful re-simulations, in order.
        embeddings: ``(K, D)`` embeddings of the re-simulations.
        pairwise: ``K (K - 1) / 2`` squared distances between re-simulations (``i < j``).
        to_target: ``K`` squared distances from each re-simulation to the target, or
            ``None`` when no target was given.
        n_failed: Re-simulations that failed (not in the lists above).
    """

    params: dict[str, float]
    seeds: list[int]
    embeddings: np.ndarray = field(repr=False)
    pairwise: list[float]
    to_target: list[float] | None
    n_failed: int = 0

    @property
    def floor(self) -> float:
        """Median distance between two realisations of θ: the distance a perfect model has."""
        return float(np.median(self.pairwise)) if self.pairwise else float("nan")

    @property
    def floor_q95(self) -> float:
        """95th percentile of the pairwise distances (a one-sided threshold for "within noise")."""
        return float(np.quantile(self.pairwise, 0.95)) if self.pairwise else float("nan")

    @property
    def gap(self) -> float | None:
        """Median distance from a re-simulation to the target (``None`` without a target)."""
        return float(np.median(self.to_target)) if self.to_target else None

    def log_std(self) -> float:
        """Standard deviation of ``log D``: the per-observation noise of a log objective.

        Taken over the distances to the target when there are at least two, else over the
        pairwise ones; ``nan`` when there are fewer than two distances.
        """
        values = self.to_target if self.to_target and len(self.to_target) >= 2 else self.pairwise
        if len(values) < 2:
            return float("nan")
        return float(np.std(np.log(np.asarray(values) + 1e-12), ddof=1))

    def summary(self) -> dict[str, Any]:
        """JSON-compatible numbers (for ``result.json`` and reports)."""
        return {
            "floor": self.floor,
            "floor_q95": self.floor_q95,
            "gap": self.gap,
            "ratio": (self.gap / self.floor) if self.gap is not None and self.floor > 0 else None,
            "log_std": self.log_std(),
            "n": len(self.seeds),
            "n_failed": self.n_failed,
            "seeds": list(self.seeds),
            "pairwise": [float(d) for d in self.pairwise],
            "to_target": None if self.to_target is None else [float(d) for d in self.to_target],
        }


def _embed_here(
    pipeline: Pipeline, params: Mapping[str, float], zetas: Sequence[Mapping[str, Any]], seeds: Sequence[int]
) -> list[np.ndarray | None]:
    """Every seed's clip made in this process (``None``: its simulation failed)."""
    # One batch call (the flag simulates it in parallel threads); each clip is embedded on
    # its own, so the floor is bit for bit what one-at-a-time evaluation measures.
    simulated = simulate_many(pipeline.simulator, [params] * len(seeds), [int(s) for s in seeds])
    return [
        None if trajectory is None else np.asarray(pipeline.embedder.embed(pipeline.renderer.render(trajectory, zeta)))
        for zeta, (trajectory, _) in zip(zetas, simulated, strict=True)
    ]


def measure_noise_floor(
    pipeline: Pipeline,
    params: Mapping[str, float],
    render_params: Mapping[str, Any] | Sequence[Mapping[str, Any]],
    *,
    seeds: Sequence[int],
    target_embedding: np.ndarray | None = None,
    embed_clips: ClipEmbedder | None = None,
) -> NoiseFloor:
    """Re-simulate ``params`` under each seed, render, embed, and measure the distances.

    Args:
        pipeline: Simulator, renderer and embedder.
        params: θ, physical values by name.
        render_params: ζ for every re-render, or one ζ per seed (render variation).
        seeds: Simulation seeds (at least two; see :func:`noise_seeds`).
        target_embedding: ``(D,)`` embedding of the target, to also measure the gap.
        embed_clips: Make the clips there, all at once (one ζ only; the same numbers).

    Returns:
        The :class:`NoiseFloor`; failed re-simulations are counted, not raised.

    Raises:
        ValueError: for fewer than two seeds or a ζ list of the wrong length.
        SimulationFailed: when fewer than two re-simulations succeed.
    """
    if len(seeds) < 2:
        raise ValueError(f"a noise floor needs at least two seeds, got {len(seeds)}")
    zetas = [render_params] * len(seeds) if isinstance(render_params, Mapping) else list(render_params)
    if len(zetas) != len(seeds):
        raise ValueError(f"{len(zetas)} render-parameter sets for {len(seeds)} seeds")
    made = (
        embed_clips([params] * len(seeds), [int(s) for s in seeds])
        if embed_clips is not None and isinstance(render_params, Mapping)
        else _embed_here(pipeline, params, zetas, seeds)
    )
    embeddings, used, failed = [], [], 0
    for seed, embedding in zip(seeds, made, strict=True):
        if embedding is None:  # a failed re-simulation is a property of θ and this seed
            failed += 1
            continue
        embeddings.append(embedding)
        used.append(int(seed))
    if len(embeddings) < 2:
        raise SimulationFailed(f"only {len(embeddings)} of {len(seeds)} re-simulations succeeded")
    stacked = np.stack(embeddings)
    pairwise = [squared_distance(stacked[i], stacked[j]) for i, j in itertools.combinations(range(len(used)), 2)]
    to_target = None if target_embedding is None else [squared_distance(e, target_embedding) for e in stacked]
    return NoiseFloor(
        params={k: float(v) for k, v in params.items()},
        seeds=used,
        embeddings=stacked,
        pairwise=pairwise,
        to_target=to_target,
        n_failed=failed,
    )
