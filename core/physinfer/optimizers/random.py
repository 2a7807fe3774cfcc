"""Uniform random search over ``[-1, 1]^D``: the baseline every optimizer must beat."""

from __future__ import annotations

import numpy as np

from physinfer.roles import Optimizer, Trial


class RandomOptimizer(Optimizer):
    """Independent uniform draws; ``tell`` only records.

    Args:
        dim: Number of parameters ``D``.
        seed: Seed of the draws.
        names: Parameter names (unused, for a uniform constructor).
    """

    def __init__(self, *, dim: int, seed: int = 0, names: list[str] | None = None) -> None:
        super().__init__(dim=dim, seed=seed, names=names)
        self._rng = np.random.default_rng(seed)
        self._next = 0
        self.values: dict[int, float | None] = {}

    def _new(self, x: np.ndarray) -> Trial:
        trial = Trial(self._next, np.asarray(x, dtype=float))
        self._next += 1
        return trial

    def ask(self, n: int = 1) -> list[Trial]:
        # One row per trial index, so a resumed run draws the same points as an uninterrupted one.
        return [self._new(np.random.default_rng([self.seed, self._next]).uniform(-1, 1, self.dim)) for _ in range(n)]

    def attach(self, x: np.ndarray) -> Trial:
        return self._new(x)

    def tell(self, index: int, value: float | None, sem: float | None = None) -> None:
        self.values[index] = value
