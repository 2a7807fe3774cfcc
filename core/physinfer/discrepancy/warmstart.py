"""Warm starts: refine around a chosen point instead of around the centre.

:func:`physinfer.loop.run_refinement` attaches the centre of ``[-1, 1]^D`` as its first
trial, and optimizers such as CMA-ES also centre their search there. An augmented model
must instead start where the baseline ended — the baseline's best θ with the effect
switched off — so that its budget is spent improving on the baseline, not re-finding it.
:class:`WarmStartOptimizer` wraps any optimizer and lets it work in coordinates ``z`` whose
centre ``c`` is the warm start ``s`` held inside ``[-0.5, 0.5]``: per coordinate,
``x = c + z (1 - c)`` for ``z ≥ 0`` and ``x = c + z (1 + c)`` for ``z < 0``, a monotone map of
``[-1, 1]`` onto itself, so the whole range stays reachable while the inner optimizer's own
centre is at (or near) the warm start. The first trial is the warm start itself (attached
at its ``z``); on ``--resume`` the logged trials map back to ``z`` exactly, so a resumed run
replays as it ran.

Why the centre is held inside: a warm start often sits on a bound — an effect is off at its
parameter's low bound, and a misspecified baseline's best fit pushes a parameter to its
limit to mimic the missing term (the pendulum's damping at 0.6 1/s standing in for drag).
Centred exactly there, one half of the inner range would collapse onto the bound: half of
the inner optimizer's proposals would repeat the bound in that coordinate, and a search for
"less damping, more drag" would rarely be proposed (seen on a hidden-drag pendulum target:
26 of the drag model's 32 trials sat at maximal damping, 24 with the drag exactly off).
With ``|c| ≤ 0.5`` each half of the inner range still covers at least a quarter of the
parameter's range.

A search box ``[lo, hi]`` (per coordinate, inside ``[-1, 1]``) narrows the search: the same
map then sends ``[-1, 1]`` onto ``[lo, hi]`` (``x = c + z (hi - c)`` for ``z ≥ 0``,
``x = c + z (c - lo)`` for ``z < 0``), with the centre held in the box's middle half. A
refinement started from an amortized posterior searches the region its samples cover for
the parameters the video determines (:func:`physinfer.posterior.refined.search_box`) and the
whole range for the others. Without a box the map is the one above, bit for bit.

``extra`` points (space coordinates) are proposed before the inner optimizer's own, one per
asked trial, after the warm start: a diagnosis hands an effect's search the points along
the ridge it shares with the base parameters (:mod:`physinfer.discrepancy.ridge`), so that
the search does not keep to the basin of the warm start. They are attached to the inner
optimizer (Ax counts them among its initial design). A resumed run replays them as logged
trials, and those already logged are not proposed again. Without ``extra`` nothing changes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from physinfer.roles import Optimizer, Trial

#: The map's centre stays within ``[-CENTRE_LIMIT, CENTRE_LIMIT]`` (see the module docstring).
CENTRE_LIMIT = 0.5


class WarmStartOptimizer(Optimizer):
    """An optimizer searching in coordinates centred on ``start`` (held inside ``±CENTRE_LIMIT``).

    Args:
        inner: The optimizer doing the work.
        start: ``(D,)`` warm-start point in ``[-1, 1]^D``; the first trial.
        box: ``(lo, hi)``, each ``(D,)`` with ``-1 ≤ lo < hi ≤ 1``: the region searched
            (default: all of ``[-1, 1]^D``).
        extra: ``(D,)`` points in ``[-1, 1]^D`` proposed, in order, before the inner
            optimizer's own (held inside the box).
    """

    def __init__(
        self,
        inner: Optimizer,
        start: np.ndarray,
        box: tuple[np.ndarray, np.ndarray] | None = None,
        extra: Sequence[np.ndarray] = (),
    ) -> None:
        super().__init__(dim=inner.dim, seed=inner.seed, names=inner.names)
        start = np.asarray(start, dtype=float).reshape(-1)
        if start.shape != (inner.dim,):
            raise ValueError(f"warm start has {start.size} coordinates, the space {inner.dim}")
        lo, hi = (-np.ones(inner.dim), np.ones(inner.dim)) if box is None else box
        self.lo = np.clip(np.asarray(lo, dtype=float).reshape(-1), -1.0, 1.0)
        self.hi = np.clip(np.asarray(hi, dtype=float).reshape(-1), -1.0, 1.0)
        if self.lo.shape != (inner.dim,) or self.hi.shape != (inner.dim,) or np.any(self.hi <= self.lo):
            raise ValueError(f"a search box needs {inner.dim} coordinates with lo < hi")
        self.inner = inner
        self.start = np.clip(start, self.lo, self.hi)
        margin = (1.0 - CENTRE_LIMIT) / 2.0 * (self.hi - self.lo)  # 0.5 on [-1, 1]
        self.centre = np.clip(self.start, self.lo + margin, self.hi - margin)
        self._first = True
        # Each extra point as the map sends it back: what a logged trial holds on resume.
        self._extra = [self.to_x(self.to_z(np.clip(np.asarray(p, dtype=float).reshape(-1), self.lo, self.hi)))
                       for p in extra]  # fmt: skip

    def to_x(self, z: np.ndarray) -> np.ndarray:
        """Inner coordinates ``z`` → space coordinates ``x`` (both ``(D,)`` in ``[-1, 1]``)."""
        z = np.clip(np.asarray(z, dtype=float), -1.0, 1.0)
        c, lo, hi = self.centre, self.lo, self.hi
        return np.clip(np.where(z >= 0, c + z * (hi - c), c + z * (c - lo)), lo, hi)

    def to_z(self, x: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_x` (a point outside the box maps to the box's edge)."""
        c, lo, hi = self.centre, self.lo, self.hi
        x = np.clip(np.asarray(x, dtype=float), lo, hi)
        return np.clip(np.where(x >= c, (x - c) / (hi - c), (x - c) / (c - lo)), -1.0, 1.0)

    def _outer(self, trial: Trial) -> Trial:
        return Trial(trial.index, self.to_x(trial.x))

    def attach(self, x: np.ndarray) -> Trial:
        """Attach ``x`` (space coordinates); the loop's first centre trial is the warm start."""
        x = np.asarray(x, dtype=float)
        first = self._first
        z = self.to_z(self.start if first and not np.any(x) else x)
        self._first = False
        if not first and self._extra and np.allclose(x, self._extra[0], rtol=0.0, atol=1e-9):
            self._extra.pop(0)  # a resumed run's logged extra point: not proposed again
        return self._outer(self.inner.attach(z))

    def ask(self, n: int = 1) -> list[Trial]:
        """The extra points not yet tried, then proposals of the wrapped optimizer, in space coordinates."""
        self._first = False
        trials = []
        while self._extra and len(trials) < n:
            trials.append(self._outer(self.inner.attach(self.to_z(self._extra.pop(0)))))
        if len(trials) < n:
            trials += [self._outer(t) for t in self.inner.ask(n - len(trials))]
        return trials

    def tell(self, index: int, value: float | None, sem: float | None = None) -> None:
        """Delegate to the wrapped optimizer."""
        self.inner.tell(index, value, sem)


def warm_start_factory(
    factory: Callable[..., Optimizer],
    start: np.ndarray,
    box: tuple[np.ndarray, np.ndarray] | None = None,
    extra: Sequence[np.ndarray] = (),
) -> Callable[..., Optimizer]:
    """An optimizer factory like ``factory`` whose optimizers start at ``start`` (search
    ``box`` and propose ``extra`` first, when given)."""

    def build(**kwargs: Any) -> Optimizer:
        return WarmStartOptimizer(factory(**kwargs), start, box, extra)

    return build
