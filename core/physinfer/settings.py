"""Typed settings from loose input: frozen dataclasses built from CLI strings or JSON.

Plugins describe their settings (render parameters ζ, simulator configurations) as frozen
dataclasses with a ``validate()`` method. Their values arrive from the command line as
strings (``--render-set image_size=120,160``), from JSON as numbers and lists, or from
Python; :func:`settings_from_mapping` converts each value to its field's annotated type,
refuses unknown keys, builds the dataclass and validates it, so that every mistake
surfaces as a :class:`~physinfer.errors.UserInputError` naming the key. The mixin
:class:`MappingSettings` gives a dataclass ``from_mapping`` and ``to_dict`` methods built on
it; :func:`check_range` and :func:`require` serve the ``validate()`` methods themselves.

Supported field types: ``bool``, ``int`` (whole numbers, also given as ``"3"`` or
``3.0``), ``float``, ``str`` (a path is taken as its string), fixed-length tuples such as
``tuple[float, float, float]`` (a list, or a comma-separated string), ``X | None`` (None
from ``None``, ``"none"``, ``"auto"`` or ``""``) and a scalar-or-tuple union such as
``int | tuple[int, int]``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from typing import Any, ClassVar, Protocol, TypeVar

from physinfer.errors import UserInputError

TRUE_WORDS = frozenset({"1", "true", "yes", "on"})
"""Strings read as ``True`` for a bool setting (case-insensitive)."""

FALSE_WORDS = frozenset({"0", "false", "no", "off"})
"""Strings read as ``False`` for a bool setting (case-insensitive)."""

NONE_WORDS = frozenset({"none", "auto", ""})
"""Strings read as ``None`` for an optional setting (case-insensitive)."""


class Validated(Protocol):
    """A settings dataclass: checks its own values."""

    def validate(self) -> None:
        """Raise :class:`UserInputError` for the first bad value."""


SettingsT = TypeVar("SettingsT", bound=Validated)

Converter = Callable[[Any], Any]


#: Seeds every command takes: numpy's legacy seeding, torch and the optimizers all accept these.
SEED_RANGE = (0, 2**32 - 1)


def check_seed(value: Any, option: str = "--seed") -> int:
    """Refuse a seed that is not a whole number from 0 to 2**32 - 1 (numpy refuses others).

    The one check of every command's seed: the CLI's error path runs it on each command's
    ``seed`` (:func:`physinfer.cli.common.handle_errors`), the library on its options'
    (:func:`physinfer.api.options.with_settings`).

    Raises:
        UserInputError: naming ``option``, the value and the range.
    """
    low, high = SEED_RANGE
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise UserInputError(f"{option} {value}: give a whole number from {low} to {high}")
    return value


#: Counts the commands' options take, by field name: ``(low, high, option, what)``. Above
#: ``high`` a command would take the machine's memory (two billion posterior samples) or
#: read more frames than any clip holds, or run for ever (``steps=10**20``); below ``low`` it
#: has nothing to do (``low`` None: the command's own check says what the least is).
COUNT_LIMITS: dict[str, tuple[int | None, int, str, str]] = {
    "embedder_frames": (1, 10_000, "--embedder-frames", "the frames an embedder reads"),
    "samples": (1, 1_000_000, "--samples", "posterior samples"),
    "steps": (1, 100_000, "--steps", "trials"),
    "effect_steps": (None, 100_000, "--effect-steps", "trials per model"),
    "floor_samples": (None, 10_000, "--floor-samples", "re-simulations"),
    "noise_samples": (None, 10_000, "--noise-samples", "re-simulations"),
    "seeds_per_trial": (None, 1_000, "--seeds-per-trial", "seeds per trial"),
    "select_top": (None, 10_000, "--select-top", "finalists"),
    "select_seeds": (None, 1_000, "--select-seeds", "seeds per finalist"),
    "batch_size": (None, 10_000, "--batch-size", "trials per step"),
    "calibration_runs": (None, 1_000, "--calibration-runs", "calibration refinements"),
    "workers": (None, 4_096, "--workers", "worker processes"),
    "max_epochs": (None, 1_000_000, "--max-epochs", "training epochs"),
    "patience": (None, 1_000_000, "--patience", "epochs"),
    "ensemble": (None, 100, "--ensemble", "flows"),
}


def check_counts(values: Any) -> None:
    """Refuse a count of :data:`COUNT_LIMITS` outside its range (``None``: the default).

    Args:
        values: A mapping of field names to values, or an options dataclass.

    Raises:
        UserInputError: naming the option, the value and the range.
    """
    get = values.get if isinstance(values, dict) else (lambda name: getattr(values, name, None))
    for name, (low, high, option, what) in COUNT_LIMITS.items():
        value = get(name)
        if value is None:
            continue
        whole = not isinstance(value, bool) and isinstance(value, int)
        if not whole or value > high or (low is not None and value < low):
            span = f"from {low:,} to at most {high:,}" if low is not None else f"of at most {high:,}"
            raise UserInputError(f"{option} {value!r}: give a whole number {span} ({what})")


def check_range(key: str, value: float, low: float, high: float) -> None:
    """Refuse a value outside ``[low, high]`` (or not finite).

    Raises:
        UserInputError: naming ``key``, the value and the allowed interval.
    """
    if not (math.isfinite(value) and low <= value <= high):
        raise UserInputError(f"{key}={value:g} is out of range; choose a value in [{low:g}, {high:g}]")


def require(checks: Iterable[tuple[bool, str]]) -> None:
    """Raise the message of the first failed check: ``validate()`` as a table of conditions.

    Args:
        checks: ``(condition, message)`` pairs, in the order they should be reported.

    Raises:
        UserInputError: with the first message whose condition is false.
    """
    for ok, message in checks:
        if not ok:
            raise UserInputError(message)


def whole_number(value: Any) -> int:
    """An int from an int-valued number or string (the CLI passes numbers as floats).

    Raises:
        ValueError: for a fraction, a bool (``light=true`` is no count) or text that is not
            a number.
    """
    number = parse_float(value)
    if not number.is_integer():
        raise ValueError(f"{value!r} is not a whole number")
    return int(number)


def parse_float(value: Any) -> float:
    """A float from a number or a numeric string; ``True``/``False`` are switches, not numbers.

    Raises:
        ValueError: for a bool or text that is not a number.
    """
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        raise ValueError("expected a number, not true/false")
    return float(value)


def parse_bool(value: Any) -> bool:
    """A bool from a word (:data:`TRUE_WORDS`, :data:`FALSE_WORDS`) or any Python value.

    Raises:
        ValueError: for a string that is none of the words.
    """
    if isinstance(value, str):
        word = value.lower()
        if word not in TRUE_WORDS | FALSE_WORDS:
            raise ValueError("expected true or false")
        return word in TRUE_WORDS
    return bool(value)


def parse_str(value: Any) -> str:
    """A string from a string or a path.

    Raises:
        ValueError: for anything else (a number, a list).
    """
    if not isinstance(value, (str, os.PathLike)):
        raise ValueError("expected a string")
    return os.fspath(value)


def converter_for(annotation: Any) -> Converter:
    """The function that converts a loose value to ``annotation`` (a field's resolved type).

    The converters raise ``ValueError`` or ``TypeError`` for a value they cannot convert.

    Raises:
        TypeError: for an annotation this module does not support (a programming error,
            reported when the settings are built, not a user mistake).
    """
    simple: dict[Any, Converter] = {bool: parse_bool, int: whole_number, float: parse_float, str: parse_str}
    if annotation in simple:
        return simple[annotation]
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is tuple and args and Ellipsis not in args:
        return _tuple_converter([converter_for(a) for a in args])
    if origin in (typing.Union, types.UnionType):
        options = [a for a in args if a is not type(None)]
        optional = len(options) < len(args)
        inner = converter_for(options[0]) if len(options) == 1 else _scalar_or_tuple(options)
        return _optional(inner) if optional else inner
    raise TypeError(f"no conversion for settings of type {annotation!r}")


def _tuple_converter(items: list[Converter]) -> Converter:
    def convert(value: Any) -> tuple[Any, ...]:
        parts = value.split(",") if isinstance(value, str) else list(value)
        if len(parts) != len(items):
            raise ValueError(f"expected {len(items)} comma-separated values")
        return tuple(item(part) for item, part in zip(items, parts, strict=True))

    return convert


def _optional(inner: Converter) -> Converter:
    def convert(value: Any) -> Any:
        if value is None or isinstance(value, str) and value.lower() in NONE_WORDS:
            return None
        return inner(value)

    return convert


def _scalar_or_tuple(options: list[Any]) -> Converter:
    """``A | tuple[...]``: a comma-separated string or a sequence is the tuple, else the scalar."""
    tuples = [a for a in options if typing.get_origin(a) is tuple]
    scalars = [a for a in options if typing.get_origin(a) is not tuple]
    if len(tuples) != 1 or len(scalars) != 1:
        raise TypeError(f"no conversion for settings of type {' | '.join(map(repr, options))}")
    as_tuple, as_scalar = converter_for(tuples[0]), converter_for(scalars[0])

    def convert(value: Any) -> Any:
        is_sequence = "," in value if isinstance(value, str) else isinstance(value, Iterable)
        return as_tuple(value) if is_sequence else as_scalar(value)

    return convert


@functools.cache
def field_converters(cls: type) -> Mapping[str, Converter]:
    """A converter per field of the dataclass ``cls``, from its resolved type hints (cached).

    Raises:
        TypeError: if ``cls`` is not a dataclass or a field's type is not supported.
    """
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    hints = typing.get_type_hints(cls)
    return types.MappingProxyType({f.name: converter_for(hints[f.name]) for f in dataclasses.fields(cls)})


def settings_from_mapping(
    cls: type[SettingsT], values: Mapping[str, Any] | None, *, noun: str = "setting", owner: str = ""
) -> SettingsT:
    """Build and validate the settings dataclass ``cls``; missing keys take their defaults.

    Args:
        cls: A dataclass with a ``validate()`` method.
        values: Field values, loose (strings, numbers, lists) or already typed; None is
            the same as an empty mapping.
        noun: What one key is called in messages, e.g. ``"render parameter"``.
        owner: Who the settings belong to, e.g. ``"flag"``, named in the unknown-key
            message (``"unknown flag render parameter 'zoom'; known keys: ..."``).

    Returns:
        The validated instance.

    Raises:
        UserInputError: an unknown key, a value of the wrong type (``"render parameter
            fov_deg='wide' has the wrong type (...)"``), or whatever ``validate()`` refuses.
        TypeError: ``cls`` has a field type this module cannot convert to.
    """
    values = dict(values or {})
    converters = field_converters(cls)
    unknown = sorted(set(values) - set(converters))
    if unknown:
        subject = " ".join(word for word in ("unknown", owner, noun) if word)
        raise UserInputError(f"{subject} {unknown[0]!r}; known keys: {', '.join(sorted(converters))}")
    typed = {}
    for key, value in values.items():
        try:
            typed[key] = converters[key](value)
        except (TypeError, ValueError) as exc:
            raise UserInputError(f"{noun} {key}={value!r} has the wrong type ({exc})") from None
    settings = cls(**typed)
    settings.validate()
    return settings


def settings_to_dict(settings: Any) -> dict[str, Any]:
    """The fields of a settings dataclass as a JSON-friendly dict (tuples become lists).

    :func:`settings_from_mapping` of the result gives the settings back.
    """
    return {
        name: list(value) if isinstance(value, tuple) else value
        for name, value in dataclasses.asdict(settings).items()
    }


class MappingSettings:
    """Mixin of a frozen settings dataclass: ``from_mapping`` and ``to_dict``.

    The class names its keys in messages with :attr:`settings_noun` and
    :attr:`settings_owner` (see :func:`settings_from_mapping`) and defines ``validate()``.

    Example::

        @dataclass(frozen=True)
        class GlowParams(MappingSettings):
            settings_noun: ClassVar[str] = "render parameter"
            settings_owner: ClassVar[str] = "glow"
            radius: float = 1.0

            def validate(self) -> None:
                check_range("radius", self.radius, 0.0, 10.0)
    """

    settings_noun: ClassVar[str] = "setting"
    settings_owner: ClassVar[str] = ""

    @classmethod
    def from_mapping(cls: type[SettingsT], values: Mapping[str, Any] | None) -> SettingsT:
        """Build and validate from a dict of loose values; missing keys take their defaults.

        Raises:
            UserInputError: an unknown key, a value of the wrong type or out of range; the
                message names the key.
        """
        return settings_from_mapping(
            cls, values, noun=cls.settings_noun, owner=cls.settings_owner  # type: ignore[attr-defined]
        )

    def to_dict(self) -> dict[str, Any]:
        """The settings as a JSON-friendly dict (tuples become lists)."""
        return settings_to_dict(self)
