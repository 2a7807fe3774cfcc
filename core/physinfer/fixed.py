"""Holding parameters fixed: refine a sub-space of θ with the rest at known values.

A user who knows some parameters (measured the fabric's weight, or accepts the material's
own stiffness) removes them from the search with ``--fix NAME=VALUE``. Fewer dimensions
pay twice: a Bayesian optimizer covers a 2-D space in 40 trials but not a 17-D one, and
weakly identifiable parameters (the flag's bending multipliers sit at the noise floor of
the embedding) no longer pull the fit towards the ends of their ranges. A name may be a
shell-style pattern (``bend_*=1``) matching several parameters.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from physinfer.errors import UserInputError
from physinfer.parameters import ParameterSpace, UnknownParameterError, parse_float_assignments
from physinfer.roles import Params, Simulator
from physinfer.types import Trajectory


def resolve_fixed(space: ParameterSpace, assignments: Iterable[str], what: str = "--fix") -> dict[str, float]:
    """Expand ``NAME=VALUE`` items (``NAME`` may hold ``*``, ``?``, ``[...]``) against ``space``.

    Args:
        space: The simulator's full parameter space.
        assignments: Command-line items, e.g. ``["bend_*=1", "area_weight=0.12"]``.
        what: The option's name, for error messages.

    Returns:
        Physical values by parameter name, in the space's order.

    Raises:
        UserInputError: for a malformed item, a pattern that matches nothing, a value out of
            bounds, or when every parameter would be fixed (nothing left to refine).
    """
    fixed: dict[str, float] = {}
    for pattern, value in parse_float_assignments(assignments, what).items():
        names = fnmatch.filter(space.names, pattern)
        if not names:
            raise UnknownParameterError(
                f"{what} {pattern}={value:g}: no parameter matches {pattern!r}; known parameters: "
                f"{', '.join(space.names)}",
                pattern,
            )
        for name in names:
            if name in fixed:  # two items (patterns) would set it; the later would silently win
                raise UserInputError(
                    f"{what} {pattern}={value:g}: {name} is already fixed at {fixed[name]:g} by another {what}; "
                    "fix each parameter once"
                )
            try:
                fixed[name] = space[name].check(value)
            except UserInputError as exc:
                raise UserInputError(f"{what} {pattern}={value:g}: {exc}") from None
    if fixed and len(fixed) == len(space):
        raise UserInputError(f"{what} fixes every parameter ({', '.join(space.names)}); leave at least one to refine")
    return {name: fixed[name] for name in space.names if name in fixed}


class FixedParameters(Simulator):
    """A simulator with some parameters held at fixed values and removed from θ.

    ``parameter_space`` lists only the free parameters (in their original order), so the
    optimizer searches a smaller cube; :meth:`simulate` adds the fixed values back.
    Other attributes are the wrapped simulator's.
    """

    def __init__(self, inner: Simulator, fixed: Mapping[str, float]) -> None:
        """Wrap ``inner``.

        Args:
            inner: The full simulator.
            fixed: Values by name, as returned by :func:`resolve_fixed`.
        """
        self.inner = inner
        self.fixed = dict(fixed)
        self.parameter_space = ParameterSpace(s for s in inner.parameter_space if s.name not in self.fixed)

    def simulate(self, params: Params, *, seed: int = 0) -> Trajectory:
        """Simulate the free ``params`` with the fixed values added."""
        return self.inner.simulate({**params, **self.fixed}, seed=seed)

    def simulate_batch(self, params: Sequence[Params], *, seeds: Sequence[int]) -> list[Trajectory]:
        """Batched :meth:`simulate` (keeps the wrapped simulator's batching)."""
        return self.inner.simulate_batch([{**p, **self.fixed} for p in params], seeds=seeds)

    def __getattr__(self, name: str) -> Any:
        # Only reached for attributes this wrapper lacks (grid sizes, frame rate, ...).
        return getattr(self.__dict__["inner"], name)


def split_fixed(simulator: Simulator) -> tuple[Simulator, dict[str, float]]:
    """The full simulator behind ``simulator`` and the values it holds fixed (``{}`` if none)."""
    if isinstance(simulator, FixedParameters):
        return simulator.inner, dict(simulator.fixed)
    return simulator, {}
