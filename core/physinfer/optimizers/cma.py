"""CMA-ES (pycma) over ``[-1, 1]^D``, started at the centre.

CMA-ES needs a value for every member of a generation, so a failed trial is told as
a penalty (the worst value seen, times two, plus one) rather than dropped.

A resumed run replays its logged trials through ``attach``/``tell`` without asking, but
pycma accepts one ``tell`` per ``ask``: a generation told without an ask since the last
one first draws (and drops) the ask the original run made, so the strategy's random
stream and state are those of the run that was interrupted; a generation cut in the middle
is asked again and the points already replayed from it are dropped, so the resumed run
continues with the next point of that generation.

pycma draws from numpy's global generator and seeds it when a strategy is made, which
would reset a library user's ``np.random`` state (and let the user's draws shift the
strategy's). Each optimizer keeps the generator state pycma sees as its own: every call
into pycma swaps it in and the caller's back out, so ``np.random`` is left as it was and
the strategy draws exactly the numbers it would alone (the same as before the swap was
added: recorded CMA results are unchanged).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from physinfer.roles import Optimizer, Trial


class CMAOptimizer(Optimizer):
    """Ask/tell wrapper of ``cma.CMAEvolutionStrategy`` with bounds ``[-1, 1]``.

    Args:
        dim: Number of parameters ``D``.
        seed: CMA-ES seed.
        names: Parameter names (unused).
        sigma0: Initial step size in normalised units.
        popsize: Population size (default: pycma's ``4 + 3 ln D``).
    """

    def __init__(
        self,
        *,
        dim: int,
        seed: int = 0,
        names: list[str] | None = None,
        sigma0: float = 0.4,
        popsize: int | None = None,
    ) -> None:
        import cma

        super().__init__(dim=dim, seed=seed, names=names)
        opts = {"bounds": [-1.0, 1.0], "seed": seed + 1, "verbose": -9}
        if popsize is not None:
            opts["popsize"] = popsize
        x0 = np.zeros(dim)
        if dim == 1:  # pycma refuses 1-D problems; optimise a padded 2-D one
            x0 = np.zeros(2)
        self._rng_state: dict[str, Any] | None = None  # the global state pycma sees
        with self._own_rng():  # pycma seeds np.random here
            self._es = cma.CMAEvolutionStrategy(x0, sigma0, opts)
        self._next = 0
        self._queue: list[np.ndarray] = []
        self._points: dict[int, np.ndarray] = {}
        self._done: dict[int, float | None] = {}
        self._worst = 0.0
        self._asked = False  # pycma's ask since its last tell

    @contextmanager
    def _own_rng(self) -> Iterator[None]:
        """Give pycma this optimizer's ``np.random`` state; restore the caller's after."""
        callers = np.random.get_state(legacy=False)
        if self._rng_state is not None:
            np.random.set_state(self._rng_state)
        try:
            yield
        finally:
            self._rng_state = np.random.get_state(legacy=False)
            np.random.set_state(callers)

    def _full(self, x: np.ndarray) -> np.ndarray:
        return x if self.dim > 1 else np.append(x, 0.0)

    def _new(self, x_full: np.ndarray) -> Trial:
        idx = self._next
        self._next += 1
        self._points[idx] = np.asarray(x_full, dtype=float)
        return Trial(idx, self._points[idx][: self.dim].copy())

    def ask(self, n: int = 1) -> list[Trial]:
        trials = []
        for _ in range(n):
            if not self._queue:
                with self._own_rng():
                    self._queue = list(self._es.ask())
                self._asked = True
                self._drop_replayed()
            trials.append(self._new(self._queue.pop(0)))
        return trials

    def _drop_replayed(self) -> None:
        """Drop from a fresh generation the points this generation's trials already are.

        A run resumed in the middle of a generation has replayed (attached) the points the
        original run took from this very ask; its next trial is the one after them, not
        their repetition. In an uninterrupted run no pending point equals a fresh sample.
        """
        taken = [x[: self.dim] for x in self._points.values()]
        self._queue = [
            q
            for q in self._queue
            if not any(np.allclose(q[: self.dim], t, rtol=0.0, atol=1e-12) for t in taken)
        ]

    def attach(self, x: np.ndarray) -> Trial:
        return self._new(self._full(np.asarray(x, dtype=float)))

    def tell(self, index: int, value: float | None, sem: float | None = None) -> None:
        if value is not None:
            self._worst = max(self._worst, value)
        self._done[index] = value
        popsize = self._es.popsize
        if len(self._done) >= popsize:
            ids = sorted(self._done)[:popsize]
            xs = [self._points.pop(i) for i in ids]
            fs = [self._done.pop(i) for i in ids]
            fs = [2 * self._worst + 1 if f is None else f for f in fs]
            with self._own_rng():
                if not self._asked:  # a replayed generation: the original run asked for it
                    self._es.ask()
                self._es.tell(xs, fs)
            self._asked = False
            self._queue = []  # the distribution moved: old proposals are stale
