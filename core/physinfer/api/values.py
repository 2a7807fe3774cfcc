"""How the API reads and checks the values of its options: each scalar's type, assignments
given as a mapping or as ``NAME=VALUE`` strings, names, and the settings a command needs.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from physinfer.errors import UserInputError

#: ``{NAME: VALUE}`` or ``["NAME=VALUE", ...]``: how ``fix``, ``truth``, ``set`` ... are given.
Assignments = Mapping[str, Any] | Sequence[str]

#: What each scalar field type accepts, and what to say when a value is not one.
_SCALARS: dict[str, tuple[Any, str]] = {
    "int": (lambda v: isinstance(v, int) and not isinstance(v, bool), "a whole number"),
    "float": (
        lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v),
        "a finite number",
    ),
    "bool": (lambda v: isinstance(v, bool), "True or False"),
    "str": (lambda v: isinstance(v, str), "a string"),
    "Path": (lambda v: isinstance(v, (str, os.PathLike)), "a path"),
}


def check_types(options: Any) -> None:
    """Refuse a setting of the wrong type, naming its option: ``steps=True``, ``seed="seven"``,
    ``duration=float("nan")`` (a bool is no count and text no number, though Python would
    compute with either)."""
    for f in dataclasses.fields(options):
        kinds = [part.strip() for part in str(f.type).split("|")]
        optional = "None" in kinds
        scalar = [k for k in kinds if k != "None"]
        value = getattr(options, f.name)
        if value is None and optional:
            continue
        accepted = [_SCALARS[k] for k in scalar if k in _SCALARS]
        if len(accepted) != len(scalar):
            continue  # mappings, tuples and unions of them are checked where they are parsed
        if not any(ok(value) for ok, _ in accepted):
            wanted = " or ".join(what for _, what in accepted)
            option = "--" + f.name.replace("_", "-")
            raise UserInputError(f"{option} {value!r}: give {wanted}{' or leave it out' if optional else ''}")


def as_assignments(value: Assignments, what: str) -> tuple[str, ...]:
    """``{NAME: VALUE}`` or ``NAME=VALUE`` strings as the strings the CLI parses.

    Raises:
        UserInputError: anything else (say, a bare string, which would split into characters).
    """
    if isinstance(value, str):
        raise UserInputError(
            f"{what}: give {{NAME: VALUE}} or a list of 'NAME=VALUE' strings, not one string"
        )
    if isinstance(value, Mapping):
        return tuple(f"{name}={val}" for name, val in value.items())
    return tuple(str(item) for item in value)


def as_names(value: Sequence[str] | str, what: str) -> tuple[str, ...]:
    """A sequence of names (one name is accepted as itself, not split into characters)."""
    if isinstance(value, str):
        return (value,)
    if not all(isinstance(item, str) for item in value):
        raise UserInputError(f"{what}: give names (strings), got {list(value)!r}")
    return tuple(value)


def required(value: Path | str | None, field_name: str, what: str) -> Path:
    """``value`` as a path; a setting a command cannot run without.

    Raises:
        UserInputError: ``value`` is ``None`` (naming the setting and what to give).
    """
    if value is None:
        raise UserInputError(f"{field_name}: give {what}")
    return Path(value)
