"""Small helpers shared by the SDN's settings dataclasses and torch code.

Settings are frozen dataclasses written to JSON (in weights files, caches and
checkpoints) and rebuilt from it; the device default is the same everywhere.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

import torch

from physinfer.devices import check_device
from physinfer.errors import UserInputError

T = TypeVar("T")


def settings_from_dict(cls: type[T], data: Mapping[str, Any]) -> T:
    """Build and validate a settings dataclass from its JSON form.

    Lists become tuples (JSON has no tuples); unknown keys are an error.

    Args:
        cls: A frozen dataclass with a ``validate()`` method.
        data: Its fields by name.

    Raises:
        UserInputError: unknown keys or invalid values.
    """
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = set(data) - names
    if unknown:
        raise UserInputError(f"unknown {cls.__name__} settings: {', '.join(sorted(unknown))}")
    obj = cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})
    try:
        obj.validate()  # type: ignore[attr-defined]
    except ValueError as exc:
        raise UserInputError(f"invalid {cls.__name__}: {exc}") from None
    return obj


def default_device() -> str:
    """``"cuda"`` when a GPU is visible, else ``"cpu"``."""
    return "cuda" if torch.cuda.is_available() else "cpu"


def resolve_device(device: str | torch.device | None) -> torch.device:
    """The given device, or :func:`default_device`.

    Raises:
        UserInputError: a device that is not a torch device or that this machine lacks.
    """
    return torch.device(check_device(str(device)) if device is not None else default_device())
