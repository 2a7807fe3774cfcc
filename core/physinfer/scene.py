"""Scene settings: what the user knows of a phenomenon's set-up and physinfer does not infer.

A flag's size and how it is pinned, a hanging fabric's size and the fan level: settings
that change the physics (a flag twice as long flaps at about half the frequency in the
same wind) but are measured with a tape, not from the video. A phenomenon declares them
as :class:`SceneSetting` records in ``Phenomenon.scene_settings``; the user gives them as
``--scene-set NAME=VALUE`` (or ``scene_set={...}`` in Python). :func:`resolve_scene`
types and validates them — unknown names, values of the wrong type, out of range or not
among the choices are refused with one line naming the valid ones — and completes them
with the declared defaults.

Only a phenomenon that declares settings is passed a scene, and only when one is given:
its factories are called as ``make_simulator(effects, ..., scene=scene)`` and, when they
accept the keyword, ``make_renderer(scene=scene)``. Without ``--scene-set`` nothing
changes, so runs, datasets and estimators made before scenes existed stay valid.
:func:`bind_scene` returns the phenomenon record with its factories bound to a scene, so
code that builds simulators from the record (the diagnosis, dataset workers) builds the
scene's without knowing of it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from physinfer.errors import UserInputError
from physinfer.parameters import parse_assignments
from physinfer.registry import accepts_keyword

#: A complete, validated scene: every declared setting by name.
Scene = dict[str, Any]


@dataclass(frozen=True)
class SceneSetting:
    """One known, non-inferred setting of a phenomenon's scene.

    Attributes:
        name: Identifier used by ``--scene-set NAME=VALUE``.
        kind: ``"float"``, ``"int"`` or ``"choice"``.
        default: The value the phenomenon uses when the setting is not given (its
            simulator's default, so a scene of defaults simulates as no scene).
        bounds: ``(low, high)`` inclusive range of a number.
        choices: The allowed values of a ``"choice"``.
        unit: Unit of a number (``"m"``), shown in help and errors.
        help: One line saying what the setting is.
    """

    name: str
    kind: Literal["float", "int", "choice"]
    default: float | int | str
    bounds: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    unit: str = ""
    help: str = ""

    def __post_init__(self) -> None:
        if self.kind not in ("float", "int", "choice"):
            raise ValueError(
                f"scene setting {self.name}: kind must be float, int or choice, not {self.kind!r}"
            )
        if self.kind == "choice" and self.default not in self.choices:
            raise ValueError(
                f"scene setting {self.name}: default {self.default!r} is not among {self.choices}"
            )
        if self.kind != "choice" and self.bounds is not None:
            low, high = self.bounds
            if not low <= float(self.default) <= high:
                raise ValueError(
                    f"scene setting {self.name}: default {self.default} outside {self.bounds}"
                )

    def describe(self) -> str:
        """``flag_length (m, 0.5..4, default 1.5)`` or ``pinning (hoist|corners, default hoist)``."""
        if self.kind == "choice":
            return f"{self.name} ({'|'.join(self.choices)}, default {self.default})"
        unit = f"{self.unit}, " if self.unit else ""
        span = f"{self.bounds[0]:g}..{self.bounds[1]:g}, " if self.bounds else ""
        return f"{self.name} ({self.kind}, {unit}{span}default {self.default:g})"

    def coerce(self, value: Any) -> float | int | str:
        """``value`` (a command-line string or a Python value) as this setting's type, checked.

        Raises:
            UserInputError: a value of the wrong type, out of range, or not a choice.
        """
        if self.kind == "choice":
            text = str(value).strip() if isinstance(value, str) else value
            if text not in self.choices:
                raise UserInputError(
                    f"--scene-set {self.name}={value}: choose one of {', '.join(self.choices)}"
                )
            return text
        number = self._number(value)
        if self.bounds is not None and not self.bounds[0] <= number <= self.bounds[1]:
            unit = f" {self.unit}" if self.unit else ""
            raise UserInputError(
                f"--scene-set {self.name}={value}: out of range; give {self.bounds[0]:g} to "
                f"{self.bounds[1]:g}{unit}"
            )
        return number

    def _number(self, value: Any) -> float | int:
        kind = "an integer" if self.kind == "int" else "a number"
        if isinstance(value, bool):  # True is a switch, not a size
            raise UserInputError(f"--scene-set {self.name}={value}: give {kind}")
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise UserInputError(f"--scene-set {self.name}={value}: give {kind}") from None
        if not math.isfinite(number):
            raise UserInputError(f"--scene-set {self.name}={value}: give a finite number")
        if self.kind == "int":
            if number != int(number):
                raise UserInputError(f"--scene-set {self.name}={value}: give an integer")
            return int(number)
        return number

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``physinfer plugins --json``, docs)."""
        d = dataclasses.asdict(self)
        d["bounds"] = list(self.bounds) if self.bounds is not None else None
        d["choices"] = list(self.choices)
        return d


def parse_scene_set(items: Sequence[str]) -> dict[str, str]:
    """``--scene-set NAME=VALUE`` items as raw strings (typed by :func:`resolve_scene`).

    Raises:
        UserInputError: an item without ``=`` or a name given twice.
    """
    return parse_assignments(items, "--scene-set")


def resolve_scene(phenomenon: Any, given: Mapping[str, Any] | None) -> Scene | None:
    """The complete, validated scene of ``phenomenon`` for the settings ``given``.

    Args:
        phenomenon: A :class:`~physinfer.roles.Phenomenon` (its ``scene_settings``).
        given: Settings by name, strings or values; ``None`` or empty: no scene.

    Returns:
        Every declared setting (given ones typed, the rest at their defaults), or ``None``
        when nothing was given.

    Raises:
        UserInputError: the phenomenon declares no settings, an unknown name (the valid
            ones listed), or a bad value.
    """
    if not given:
        return None
    settings = scene_settings_of(phenomenon)
    if not settings:
        raise UserInputError(
            f"the phenomenon {phenomenon.name!r} has no scene settings (its plugin declares none); "
            "drop --scene-set"
        )
    unknown = sorted(set(given) - set(settings))
    if unknown:
        raise UserInputError(
            f"unknown scene setting(s) {', '.join(unknown)} for {phenomenon.name!r}; known: "
            + "; ".join(s.describe() for s in settings.values())
        )
    return {
        name: spec.coerce(given[name]) if name in given else spec.default
        for name, spec in settings.items()
    }


#: ``{name: (low, high)}``: numeric scene settings a dataset varies (``--scene-range``).
SceneRanges = dict[str, tuple[float, float]]


def parse_scene_ranges(phenomenon: Any, items: Sequence[str]) -> SceneRanges:
    """``--scene-range NAME=LOW:HIGH`` items, typed and validated against ``phenomenon``.

    A dataset made with ranges draws each simulation's setting from its range (see
    :func:`sample_scene`), so an estimator trained on it covers every scene in the box.

    Raises:
        UserInputError: a malformed item, an unknown or non-numeric setting, a range
            outside the setting's bounds or with ``LOW >= HIGH``.
    """
    raw = parse_assignments(items, "--scene-range")
    if not raw:
        return {}
    settings = scene_settings_of(phenomenon)
    unknown = sorted(set(raw) - set(settings))
    if not settings or unknown:
        known = "; ".join(s.describe() for s in settings.values()) or "none"
        raise UserInputError(
            f"--scene-range: unknown scene setting(s) {', '.join(unknown or sorted(raw))} for "
            f"{phenomenon.name!r}; known: {known}"
        )
    ranges: SceneRanges = {}
    for name, text in raw.items():
        spec = settings[name]
        parts = str(text).split(":")
        if spec.kind != "float" or len(parts) != 2:
            why = "only float settings can be ranged" if spec.kind != "float" else "give LOW:HIGH"
            raise UserInputError(f"--scene-range {name}={text}: {why}")
        try:
            low, high = (float(spec.coerce(part.strip())) for part in parts)
        except UserInputError as exc:  # coerce names --scene-set; say which option it was
            raise UserInputError(f"--scene-range {name}={text}: {str(exc).split(': ', 1)[-1]}") from None
        if not low < high:
            raise UserInputError(f"--scene-range {name}={text}: LOW must be below HIGH")
        ranges[name] = (low, high)
    return ranges


def sample_scene(rng: Any, ranges: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    """One draw of every ranged setting: log-uniform where ``LOW > 0`` (sizes: a 0.9-3 m
    range gives small and large flags alike), else uniform; independent per setting."""
    drawn: dict[str, float] = {}
    for name in sorted(ranges):
        low, high = ranges[name]
        if low > 0:
            drawn[name] = float(math.exp(rng.uniform(math.log(low), math.log(high))))
        else:
            drawn[name] = float(rng.uniform(low, high))
    return drawn


def scene_context(ranges: Mapping[str, Sequence[float]], scene: Mapping[str, Any]) -> list[float]:
    """The ranged settings of ``scene`` as an estimator's extra inputs (sorted by name; the
    log of positive ranges, where :func:`sample_scene` is uniform)."""
    return [
        math.log(float(scene[name])) if float(ranges[name][0]) > 0 else float(scene[name])
        for name in sorted(ranges)
    ]


def scene_settings_of(phenomenon: Any) -> dict[str, SceneSetting]:
    """The phenomenon's declared settings by name (empty for plugins that declare none)."""
    return {s.name: s for s in getattr(phenomenon, "scene_settings", ()) or ()}


def default_scene(phenomenon: Any) -> Scene:
    """Every declared setting at its default (``{}`` when none are declared)."""
    return {name: spec.default for name, spec in scene_settings_of(phenomenon).items()}


def same_scene(phenomenon: Any, a: Mapping[str, Any] | None, b: Mapping[str, Any] | None) -> bool:
    """Whether two scenes (``None``: the defaults) describe the same set-up."""
    defaults = default_scene(phenomenon)
    return {**defaults, **(a or {})} == {**defaults, **(b or {})}


def scene_text(scene: Mapping[str, Any] | None) -> str:
    """``flag_length=3, flag_height=2, pinning=hoist`` (``the default scene`` for none)."""
    if not scene:
        return "the default scene"
    return ", ".join(
        f"{k}={v:g}" if isinstance(v, (int, float)) else f"{k}={v}" for k, v in scene.items()
    )


def bind_scene(phenomenon: Any, scene: Scene | None) -> Any:
    """``phenomenon`` with ``make_simulator`` (and ``make_renderer`` where it accepts the
    keyword) bound to ``scene``; the record itself when ``scene`` is ``None``.

    The bound record keeps the ``duration_s`` keyword of its ``make_simulator`` and
    pickles to worker processes; :func:`scene_of` reads the scene back from it.
    """
    if scene is None:
        return phenomenon

    changes: dict[str, Any] = {
        "make_simulator": functools.partial(phenomenon.make_simulator, scene=dict(scene))
    }
    if accepts_keyword(phenomenon.make_renderer, "scene"):
        changes["make_renderer"] = functools.partial(phenomenon.make_renderer, scene=dict(scene))
    return dataclasses.replace(phenomenon, **changes)


def scene_of(phenomenon: Any) -> Scene | None:
    """The scene a record was bound to by :func:`bind_scene`, or ``None``."""
    factory = getattr(phenomenon, "make_simulator", None)
    if isinstance(factory, functools.partial):
        scene = factory.keywords.get("scene")
        return dict(scene) if scene is not None else None
    return None


class SceneRegistry:
    """A view of a registry whose ``phenomenon(plugin)`` is bound to a scene.

    For workflows that take a registry and build their pipelines themselves: everything
    else is the wrapped registry's.
    """

    def __init__(self, registry: Any, plugin: str, scene_set: Mapping[str, Any] | None) -> None:
        self._registry, self._plugin = registry, plugin
        self.scene = resolve_scene(registry.phenomenon(plugin), scene_set)

    def phenomenon(self, name: str) -> Any:
        """The phenomenon ``name``, bound to the scene when it is the scene's plugin."""
        record = self._registry.phenomenon(name)
        return bind_scene(record, self.scene) if name == self._plugin else record

    def __getattr__(self, name: str) -> Any:
        return getattr(self._registry, name)


def scene_remedy(phenomenon: Any, scene: Mapping[str, Any] | None) -> str:
    """The way forward for a scene no estimator covers: the commands that make one, and
    ``refine``, which measures without one."""
    name = getattr(phenomenon, "name", "PLUGIN")
    sets = " ".join(
        f"--scene-set {k}={v:g}" if isinstance(v, (int, float)) else f"--scene-set {k}={v}"
        for k, v in sorted((scene or {}).items())
    )
    return (
        f"for an interval, train one on clips of this scene: `physinfer dataset generate --plugin {name} "
        f"{sets} --sims 800,0,200 --renders-per-sim 1 --out DATA`, then `physinfer posterior train --plugin "
        f"{name} --data DATA --out mine.safetensors` and pass --posterior mine.safetensors; or measure it "
        f"with `physinfer refine --plugin {name} {sets}`, which searches without a posterior"
    )
