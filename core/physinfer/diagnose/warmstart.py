"""Warm starts: refine around a chosen point instead of around the centre.

:func:`physinfer.refine.run_refinement` attaches the centre of ``[-1, 1]^D`` as its first
trial, and optimizers such as CMA-ES also centre their search there. An augmented model
must instead start where the baseline ended — the baseline's best θ with the effect
switched off — so that its budget is spent improving on the baseline, not re-finding it.
:class:`WarmStartOptimizer` wraps any optimizer and lets it work in coordinates ``z`` whose
centre is the warm start ``s``: per coordinate, ``x = s + z (1 - s)`` for ``z ≥ 0`` and
``x = s + z (1 + s)`` for ``z < 0``, a monotone map of ``[-1, 1]`` onto itself, so the whole
range stays reachable while the inner optimizer's own centre is the warm start. The first
attachment of the centre (the loop's first trial) is that point; on ``--resume`` the
logged trials map back to ``z`` exactly, so a resumed run replays as it ran.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from physinfer.roles import Optimizer, Trial


class WarmStartOptimizer(Optimizer):
    """An optimizer searching in coordinates centred on ``start``.

    Args:
        inner: The optimizer doing the work.
        start: ``(D,)`` warm-start point in ``[-1, 1]^D``.
    """

    def __init__(self, inner: Optimizer, start: np.ndarray) -> None:
        super().__init__(dim=inner.dim, seed=inner.seed, names=inner.names)
        start = np.asarray(start, dtype=float).reshape(-1)
        if start.shape != (inner.dim,):
            raise ValueError(f"warm start has {start.size} coordinates, the space {inner.dim}")
        self.inner = inner
        self.start = np.clip(start, -1.0, 1.0)
        self._first = True

    def to_x(self, z: np.ndarray) -> np.ndarray:
        """Inner coordinates ``z`` → space coordinates ``x`` (both ``(D,)`` in ``[-1, 1]``)."""
        z = np.clip(np.asarray(z, dtype=float), -1.0, 1.0)
        s = self.start
        return np.clip(np.where(z >= 0, s + z * (1.0 - s), s + z * (1.0 + s)), -1.0, 1.0)

    def to_z(self, x: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_x` (a coordinate whose half-range is empty maps to 0 there)."""
        x = np.clip(np.asarray(x, dtype=float), -1.0, 1.0)
        s = self.start
        up, down = np.maximum(1.0 - s, 1e-12), np.maximum(1.0 + s, 1e-12)
        return np.clip(np.where(x >= s, (x - s) / up, (x - s) / down), -1.0, 1.0)

    def _outer(self, trial: Trial) -> Trial:
        return Trial(trial.index, self.to_x(trial.x))

    def attach(self, x: np.ndarray) -> Trial:
        """Attach ``x`` (space coordinates); the loop's first centre trial is the warm start."""
        x = np.asarray(x, dtype=float)
        z = np.zeros(self.dim) if self._first and not np.any(x) else self.to_z(x)
        self._first = False
        return self._outer(self.inner.attach(z))

    def ask(self, n: int = 1) -> list[Trial]:
        """Proposals of the wrapped optimizer, in space coordinates."""
        self._first = False
        return [self._outer(t) for t in self.inner.ask(n)]

    def tell(self, index: int, value: float | None, sem: float | None = None) -> None:
        """Delegate to the wrapped optimizer."""
        self.inner.tell(index, value, sem)


def warm_start_factory(factory: Callable[..., Optimizer], start: np.ndarray) -> Callable[..., Optimizer]:
    """An optimizer factory like ``factory`` whose optimizers start at ``start``."""

    def build(**kwargs: Any) -> Optimizer:
        return WarmStartOptimizer(factory(**kwargs), start)

    return build
