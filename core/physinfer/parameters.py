"""Parameter specifications and spaces.

A :class:`ParameterSpec` is shaped like Ax's ``RangeParameterConfig`` (name, bounds,
scaling) plus a unit and a description. A :class:`ParameterSpace` is an ordered set of
specs that maps physical values to and from the normalised cube ``[-1, 1]^D`` in which
every optimizer works; the centre of the cube (all zeros) is the first trial of a
refinement, as in the paper.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from physinfer.errors import UserInputError

Scaling = Literal["linear", "log"]


class UnknownParameterError(UserInputError):
    """A parameter name (or ``--fix`` pattern) the space does not have.

    Attributes:
        name: The name or pattern as the user gave it; a caller that knows the phenomenon's
            effects can say which one it belongs to (:func:`physinfer.evaluation.naming_effects`).
    """

    def __init__(self, message: str, name: str) -> None:
        super().__init__(message)
        self.name = name

    def __reduce__(self) -> tuple:  # pickled across worker processes
        return (type(self), (str(self), self.name))


@dataclass(frozen=True)
class ParameterSpec:
    """One continuous physical parameter.

    Attributes:
        name: Identifier used on the command line (``--set name=value``) and in results.
        bounds: ``(low, high)`` in physical units, ``low < high``.
        unit: Unit string for display, e.g. ``"m/s"``; ``""`` for dimensionless.
        scaling: ``"linear"`` or ``"log"``; with ``"log"`` the normalised coordinate is
            linear in ``log(value)`` (bounds must then be positive).
        description: One line for humans.
        default: Physical value used when a simulation is asked for without this
            parameter; ``None`` means the centre of the normalised range.
    """

    name: str
    bounds: tuple[float, float]
    unit: str = ""
    scaling: Scaling = "linear"
    description: str = ""
    default: float | None = None

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ValueError` if the spec is inconsistent."""
        low, high = self.bounds
        if not self.name.isidentifier():
            raise ValueError(f"parameter name {self.name!r} must be a Python identifier")
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(f"parameter {self.name!r}: bounds {self.bounds} must be finite, low < high")
        if self.scaling not in ("linear", "log"):
            raise ValueError(f"parameter {self.name!r}: scaling must be 'linear' or 'log'")
        if self.scaling == "log" and low <= 0:
            raise ValueError(f"parameter {self.name!r}: log scaling needs positive bounds")
        if self.default is not None and not (low <= self.default <= high):
            raise ValueError(f"parameter {self.name!r}: default {self.default} outside {self.bounds}")

    def _warp(self, value: np.ndarray | float) -> np.ndarray:
        value = np.asarray(value, dtype=float)
        return np.log(value) if self.scaling == "log" else value

    def to_unit(self, value: np.ndarray | float) -> np.ndarray:
        """Map physical value(s) to ``[-1, 1]``."""
        low, high = self._warp(self.bounds[0]), self._warp(self.bounds[1])
        return 2.0 * (self._warp(value) - low) / (high - low) - 1.0

    def from_unit(self, u: np.ndarray | float) -> np.ndarray:
        """Map normalised coordinate(s) in ``[-1, 1]`` to physical values (clipped to bounds)."""
        u = np.clip(np.asarray(u, dtype=float), -1.0, 1.0)
        low, high = self._warp(self.bounds[0]), self._warp(self.bounds[1])
        warped = low + (u + 1.0) * 0.5 * (high - low)
        value = np.exp(warped) if self.scaling == "log" else warped
        return np.clip(value, self.bounds[0], self.bounds[1])

    @property
    def centre(self) -> float:
        """Physical value at the centre of the normalised range."""
        return float(self.from_unit(0.0))

    @property
    def default_value(self) -> float:
        """The default if given, else the centre."""
        return self.centre if self.default is None else float(self.default)

    def check(self, value: float) -> float:
        """Return ``value`` as float or raise :class:`UserInputError` naming the bounds."""
        value = float(value)
        low, high = self.bounds
        if not (math.isfinite(value) and low <= value <= high):
            raise UserInputError(
                f"{self.name}={value:g} is outside its bounds [{low:g}, {high:g}]"
                + (f" {self.unit}" if self.unit else "")
                + "; choose a value in that range."
            )
        return value

    def to_dict(self) -> dict:
        """JSON-ready description."""
        return {
            "name": self.name,
            "bounds": list(self.bounds),
            "unit": self.unit,
            "scaling": self.scaling,
            "description": self.description,
            "default": self.default,
        }


@dataclass(frozen=True)
class ParameterSpace:
    """An ordered collection of :class:`ParameterSpec` with a normalisation to ``[-1, 1]^D``.

    Attributes:
        specs: The parameters, in the order of the normalised vector's coordinates.
    """

    specs: tuple[ParameterSpec, ...]
    _index: dict[str, int] = field(init=False, repr=False, compare=False)

    def __init__(self, specs: Iterable[ParameterSpec]) -> None:
        specs = tuple(specs)
        object.__setattr__(self, "specs", specs)
        object.__setattr__(self, "_index", {s.name: i for i, s in enumerate(specs)})
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ValueError` on duplicate names."""
        if len(self._index) != len(self.specs):
            names = [s.name for s in self.specs]
            dupes = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"duplicate parameter names: {dupes}")

    def __len__(self) -> int:
        return len(self.specs)

    def __iter__(self) -> Iterator[ParameterSpec]:
        return iter(self.specs)

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __getitem__(self, name: str) -> ParameterSpec:
        try:
            return self.specs[self._index[name]]
        except KeyError:
            raise UnknownParameterError(
                f"unknown parameter {name!r}; known parameters: {', '.join(self.names)}", name
            ) from None

    @property
    def names(self) -> list[str]:
        """Parameter names in coordinate order."""
        return [s.name for s in self.specs]

    def to_unit(self, params: Mapping[str, float]) -> np.ndarray:
        """Map a full physical parameter dict to a vector in ``[-1, 1]^D``, shape ``(D,)``."""
        return np.array([float(s.to_unit(params[s.name])) for s in self.specs])

    def from_unit(self, u: np.ndarray) -> dict[str, float]:
        """Map a vector of shape ``(D,)`` in ``[-1, 1]^D`` to physical values by name."""
        u = np.asarray(u, dtype=float).reshape(-1)
        if u.shape[0] != len(self.specs):
            raise ValueError(f"expected a vector of length {len(self.specs)}, got {u.shape[0]}")
        return {s.name: float(s.from_unit(x)) for s, x in zip(self.specs, u, strict=True)}

    def defaults(self) -> dict[str, float]:
        """Each parameter at its default value."""
        return {s.name: s.default_value for s in self.specs}

    def at_bounds(self, params: Mapping[str, float], tolerance: float = 1e-3) -> dict[str, str]:
        """The parameters of ``params`` on a bound of the space: ``{name: "lower" | "upper"}``.

        A fit that ends on a bound may have been stopped by it: the truth can lie beyond.
        A bound that is also the parameter's explicit default is skipped — an effect is
        switched off there (a gust intensity of 0), so ending on it is an answer, not a limit.
        ``tolerance`` is a share of the (normalised) range.
        """
        found = {}
        for spec in self.specs:
            if spec.name not in params:
                continue
            u = float(spec.to_unit(params[spec.name]))
            for side, edge, bound in (("lower", -1.0, spec.bounds[0]), ("upper", 1.0, spec.bounds[1])):
                if abs(u - edge) <= 2.0 * tolerance and spec.default != bound:
                    found[spec.name] = side
        return found

    def complete(self, partial: Mapping[str, float]) -> dict[str, float]:
        """Check ``partial`` (names and bounds) and fill the rest with defaults.

        Raises:
            UserInputError: for an unknown name or a value out of bounds.
        """
        for name in partial:
            self[name]  # raises with the list of known names
        full = self.defaults()
        full.update({name: self[name].check(value) for name, value in partial.items()})
        return full

    def sample(self, rng: np.random.Generator, n: int) -> list[dict[str, float]]:
        """Draw ``n`` parameter sets uniformly in the normalised cube (log-uniform for log specs)."""
        u = rng.uniform(-1.0, 1.0, size=(n, len(self.specs)))
        return [self.from_unit(row) for row in u]

    def merged(self, other: ParameterSpace) -> ParameterSpace:
        """This space followed by ``other``'s parameters (e.g. an effect's)."""
        return ParameterSpace(self.specs + other.specs)

    def to_dict(self) -> list[dict]:
        """JSON-ready description."""
        return [s.to_dict() for s in self.specs]

    @classmethod
    def from_dict(cls, items: Iterable[Mapping]) -> ParameterSpace:
        """Inverse of :meth:`to_dict`."""
        return cls(
            ParameterSpec(
                name=d["name"],
                bounds=(float(d["bounds"][0]), float(d["bounds"][1])),
                unit=d.get("unit", ""),
                scaling=d.get("scaling", "linear"),
                description=d.get("description", ""),
                default=d.get("default"),
            )
            for d in items
        )


def parse_assignments(items: Iterable[str], what: str = "--set") -> dict[str, str]:
    """Parse ``NAME=VALUE`` strings from the command line into a dict of raw strings.

    Raises:
        UserInputError: for an item without ``=``, with an empty name, or a name given
            twice (the last value would silently win).
    """
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise UserInputError(f"{what} expects NAME=VALUE, got {item!r}")
        name = name.strip()
        if name in out:
            raise UserInputError(
                f"{what} {name} is given twice ({name}={out[name]} and {name}={value.strip()}); give it once"
            )
        out[name] = value.strip()
    return out


def refuse_repeats(names: Iterable[str], option: str) -> None:
    """Refuse a name given twice to a repeatable option such as ``--effect``.

    Raises:
        UserInputError: naming the repeated name.
    """
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise UserInputError(f"{option} {name} is given twice; give it once")
        seen.add(name)


def parse_float_assignments(items: Iterable[str], what: str = "--set") -> dict[str, float]:
    """Like :func:`parse_assignments` but every value must be a number."""
    out: dict[str, float] = {}
    for name, value in parse_assignments(items, what).items():
        try:
            out[name] = float(value)
        except ValueError:
            raise UserInputError(f"{what} {name}={value!r}: value is not a number") from None
        if not np.isfinite(out[name]):
            raise UserInputError(f"{what} {name}={value}: give a finite number")
    return out
